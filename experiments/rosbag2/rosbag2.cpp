// exid — experiment `rosbag2`: a ROS 2 recording read from its bag folder (metadata.yaml and
// SQLite .db3 or MCAP files) without a ROS installation. sensor_msgs/msg/JointState gives q
// (position), tau (effort) and optionally qd (velocity), by joint name; an optional
// geometry_msgs/msg/WrenchStamped topic gives the wrench, linearly interpolated at the joint-state
// times. Time: the messages' header stamps (or the bag's receive stamps), in seconds after the
// first joint-state sample. Segment, split, signs, gaps and the accounting of every message
// dropped or cut follow the csv experiment (docs/experiments.md); the filter steps (resampling,
// a known delay, the differentiating filter, trim, decimation) are the data layer's
// RecordingPipeline (exid/recording.hpp), the csv experiment's too.
#include <fmt/format.h>
#include <fmt/ranges.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <functional>
#include <numeric>
#include <set>
#include <string>
#include <vector>

#include "bag.hpp"
#include "exid/error.hpp"
#include "exid/floating_base.hpp"
#include "exid/interfaces.hpp"
#include "exid/recording.hpp"
#include "exid/recording_stats.hpp"
#include "exid/segment.hpp"
#include "exid/signal.hpp"

namespace {

namespace fs = std::filesystem;
namespace rb = exid::rosbag2;

constexpr const char* kJointStateType = "sensor_msgs/msg/JointState";
constexpr const char* kWrenchType = "geometry_msgs/msg/WrenchStamped";
constexpr const char* kImuType = "sensor_msgs/msg/Imu";

/// One reading of a bag by the rosbag2 experiment, stage by stage (Rosbag2Experiment::run):
/// the robot's joints, the bag's topics, the messages, their order in time, gaps, the segment,
/// the wrench's time range, the dataset and its meta.
class BagReading {
 public:
  BagReading(const exid::ParamSet& P, const std::string& path, const exid::RobotModel& robot,
             const exid::RunContext& ctx)
      : P_(P),
        robot_(robot),
        n_(robot.dof()),
        stop_([stop = ctx.cancelled, deadline = ctx.deadline] {
          return deadline.expired() || (stop && stop());
        }) {
    fs::path dir = path;
    if (dir.is_relative() && !ctx.study_dir.empty()) dir = ctx.study_dir / dir;
    dir_ = dir;
    bagname_ = dir.string();
  }

  const std::string& bagname() const { return bagname_; }

  exid::Dataset read() {
    resolveJoints();
    openBag();
    readAllMessages();
    checkMessages();
    orderByTime();
    timeAxis();
    checkSteps();
    selectSegment();
    matchWrenchRange();
    for (Aux& a : aux_) matchAuxRange(&a);
    exid::Dataset d = fillDataset();
    // The filter steps (exid/recording.hpp), the wrench, the IMU and the contacts matched at the
    // resampled times (the base motion and the contacts then go through the filter as the
    // pipeline takes them).
    exid::RecordingPipeline steps(exid::RecordingSteps::fromParams(P_), pre_ + bagname_);
    d = steps.resample(std::move(d));
    interpolateWrench(&d);
    floatingSignals(&d);
    d = steps.filter(steps.compensateDelay(std::move(d)));
    describe(steps, &d);
    return d;
  }

 private:
  struct Js {
    std::int64_t ns;
    long long msg;  // 1-based index among the topic's messages (bag order)
  };
  struct Wr {
    std::int64_t ns;
    long long msg;
    double v[6];
  };
  // A topic of stamped six-vectors matched at the joint-state times as the wrench is: the
  // base's IMU (gyro xyz, accelerometer xyz, in the IMU frame) or a contact's wrench.
  struct Aux {
    std::string topic, key, label;  // key: the parameter naming it; label: "imu", "contact1"
    bool imu = false;
    std::vector<Wr> msgs;
    std::vector<double> t;  // s after t0_
    double med = 0.0;
    long long count = 0, bad = 0, dup = 0;
    int outside = 0;
  };

  // The robot's joints and their names in the messages; the conversion of their values (signs,
  // scales, offsets, currents: exid/recording.hpp).
  void resolveJoints() {
    const int n = n_;
    names_ = P_.getStrings("joint_names");
    if (names_.empty()) {
      for (int j = 0; j < robot_.dof(); ++j)  // measured coordinates (a closed chain's actuated)
        names_.push_back(
            robot_.bodies[static_cast<std::size_t>(robot_.actuatedJoint(j))].joint_name);
    } else {
      exid::check(static_cast<int>(names_.size()) == n,
                  fmt::format("{}joint_names: expected {} names (one per joint of robot '{}', in "
                              "its order), found {}",
                              pre_, n, robot_.name, names_.size()));
    }
    for (std::size_t a = 0; a < names_.size(); ++a) {
      exid::check(!names_[a].empty(),
                  fmt::format("{}joint {} of robot '{}' has no name; give joint_names", pre_, a + 1,
                              robot_.name));
      for (std::size_t b = 0; b < a; ++b)
        exid::check(names_[a] != names_[b],
                    fmt::format("{}joint_names: '{}' is named twice (joints {} and {}); each joint "
                                "needs its own name",
                                pre_, names_[a], b + 1, a + 1));
    }
    conv_ = exid::SignalConversion::fromParams(
        P_, n, robot_.hasTransmission() ? robot_.transmission : Eigen::MatrixXd(),
        "experiment 'rosbag2'");
  }

  // A topic named by parameter `key` must be in the bag, of `type`, serialized as CDR.
  void checkTopic(const std::string& topic, const char* key, const char* type) const {
    auto topicList = [&] {
      std::vector<std::string> v;
      for (const rb::TopicInfo& t : bag_.topics) v.push_back(t.name + " (" + t.type + ")");
      return v.empty() ? std::string("none") : fmt::format("{}", fmt::join(v, ", "));
    };
    exid::check(!topic.empty(), fmt::format("{}{}: empty topic name", pre_, key));
    const rb::TopicInfo* t = bag_.topic(topic);
    exid::check(t != nullptr,
                fmt::format("{}{}: {} = '{}': no such topic in the bag (topics: "
                            "{})",
                            pre_, bag_.metadata_file.string(), key, topic, topicList()));
    exid::check(t->type == type,
                fmt::format("{}{}: {} = '{}' has type '{}', expected {}", pre_,
                            bag_.metadata_file.string(), key, topic, t->type, type));
    exid::check(t->serialization_format == "cdr",
                fmt::format("{}{}: topic '{}': serialization_format '{}', expected cdr", pre_,
                            bag_.metadata_file.string(), topic, t->serialization_format));
  }

  // The bag and its topics.
  void openBag() {
    try {
      bag_ = rb::openBag(dir_, &opened_as_);
    } catch (const exid::Error& e) {
      throw exid::Error(pre_ + e.what());
    }
    js_topic_ = P_.getString("joint_states_topic");
    w_topic_ = P_.getString("wrench_topic");
    checkTopic(js_topic_, "joint_states_topic", kJointStateType);
    with_wrench_ = !w_topic_.empty();
    if (with_wrench_) {
      checkTopic(w_topic_, "wrench_topic", kWrenchType);
      exid::check(w_topic_ != js_topic_, fmt::format("{}wrench_topic and joint_states_topic are "
                                                     "both '{}'",
                                                     pre_, w_topic_));
    }
    // a floating base's signals: the IMU on its base link, the contacts' wrenches
    const std::string imu = P_.getString("imu_topic");
    const std::vector<std::string> contacts = P_.getStrings("contact_topics");
    if (!imu.empty() || !contacts.empty())
      exid::check(robot_.floating_base,
                  fmt::format("{}imu_topic and contact_topics give a floating base's signals; "
                              "robot '{}' has a fixed base",
                              pre_, robot_.name));
    if (!imu.empty()) {
      checkTopic(imu, "imu_topic", kImuType);
      const std::vector<double> pose = P_.getDoubles("imu_pose_xyz_rpy");
      exid::check(pose.size() == 6,
                  fmt::format("{}imu_pose_xyz_rpy: the IMU's frame in the base link's frame "
                              "(x y z [m] roll pitch yaw [rad]) is required with imu_topic: "
                              "expected 6 values, found {} (exid does not assume the IMU sits at "
                              "the base origin)",
                              pre_, pose.size()));
      for (double v : pose)
        exid::check(std::isfinite(v),
                    fmt::format("{}imu_pose_xyz_rpy: {} is not a finite number", pre_, v));
      imu_pose_ = exid::poseFromXyzRpy(pose.data());
      Aux a;
      a.topic = imu;
      a.key = "imu_topic";
      a.label = "imu";
      a.imu = true;
      aux_.push_back(a);
    } else {
      exid::check(P_.getDoubles("imu_pose_xyz_rpy").empty(),
                  fmt::format("{}imu_pose_xyz_rpy is given without imu_topic", pre_));
    }
    for (std::size_t c = 0; c < contacts.size(); ++c) {
      const std::string key = fmt::format("contact_topics[{}]", c);
      checkTopic(contacts[c], key.c_str(), kWrenchType);
      Aux a;
      a.topic = contacts[c];
      a.key = key;
      a.label = fmt::format("contact{}", c + 1);
      aux_.push_back(a);
    }
    std::set<std::string> used = {js_topic_};
    if (with_wrench_) used.insert(w_topic_);
    for (const Aux& a : aux_)
      exid::check(used.insert(a.topic).second,
                  fmt::format("{}{} = '{}' is a topic already used by this experiment (each of "
                              "joint_states_topic, wrench_topic, imu_topic and contact_topics "
                              "names its own)",
                              pre_, a.key, a.topic));
  }

  Aux* auxOf(const std::string& topic) {
    for (Aux& a : aux_)
      if (a.topic == topic) return &a;
    return nullptr;
  }

  // A bad message: an error, or (drop_bad_messages) counted and kept as an example.
  void bad(const std::string& topic, long long k, const std::string& where, const std::string& why,
           long long* counter) {
    const std::string msg = fmt::format("{}{}: topic '{}', message {}{}: {}", pre_, bagname_, topic,
                                        k, where.empty() ? std::string() : " (" + where + ")", why);
    if (!drop_) throw exid::Error(msg + " (set drop_bad_messages: true to drop such messages)");
    ++*counter;
    if (bad_examples_.size() < 10) bad_examples_.push_back(exid::Json(msg));
  }

  // Read the messages.
  void readAllMessages() {
    header_time_ = P_.getString("time") == "header";
    use_vel_ = P_.getBool("use_velocity");
    drop_ = P_.getBool("drop_bad_messages");
    std::set<std::string> wanted = with_wrench_ ? std::set<std::string>{js_topic_, w_topic_}
                                                : std::set<std::string>{js_topic_};
    for (const Aux& a : aux_) wanted.insert(a.topic);
    try {
      unsigned long count = 0;
      rb::readMessages(
          bag_, wanted,
          [&](const rb::RawMessage& m) {
            // (a long bag: a stop request is honoured while it is read)
            if ((++count & 1023u) == 0 && stop_())
              throw exid::Error("stopped while reading the bag");
            if (*m.topic == js_topic_)
              onJointState(m);
            else if (with_wrench_ && *m.topic == w_topic_)
              onWrench(m);
            else
              onAux(auxOf(*m.topic), m);
          },
          &census_);
    } catch (const exid::Error& e) {
      const std::string w = e.what();
      if (w.rfind(pre_, 0) == 0) throw;
      throw exid::Error(pre_ + w);
    }
  }

  // Per robot joint: its index in a message with these names (-1: absent), cached while the
  // names repeat.
  void mapJointNames(const std::vector<std::string>& msg_names) {
    if (msg_names == cache_names_) return;
    cache_names_ = msg_names;
    cache_idx_.assign(static_cast<std::size_t>(n_), -1);
    for (int j = 0; j < n_; ++j)
      for (std::size_t i = 0; i < msg_names.size(); ++i)
        if (msg_names[i] == names_[static_cast<std::size_t>(j)]) {
          cache_idx_[static_cast<std::size_t>(j)] = static_cast<int>(i);
          break;
        }
  }

  // What is wrong with a joint-state message's values for our joints ("" when nothing).
  std::string jointStateProblem(const rb::JointStateMsg& s) const {
    const std::size_t nn = s.name.size();
    auto lenProblem = [&](const std::vector<double>& v, const char* field) {
      return v.size() == nn ? std::string()
                            : fmt::format("{} has {} values for {} names", field, v.size(), nn);
    };
    std::string why = lenProblem(s.position, "position");
    if (why.empty()) why = lenProblem(s.effort, "effort");
    if (why.empty() && use_vel_) why = lenProblem(s.velocity, "velocity");
    if (why.empty())
      for (int j = 0; j < n_ && why.empty(); ++j) {
        const std::size_t i = static_cast<std::size_t>(cache_idx_[static_cast<std::size_t>(j)]);
        if (!std::isfinite(s.position[i]) || !std::isfinite(s.effort[i]) ||
            (use_vel_ && !std::isfinite(s.velocity[i])))
          why = fmt::format("non-finite value for joint '{}'", s.name[i]);
      }
    return why;
  }

  void onJointState(const rb::RawMessage& m) {
    const int n = n_;
    const long long k = ++js_msgs_;
    const std::string where = fmt::format("topic '{}', message {}, {}", js_topic_, k, m.where);
    const rb::JointStateMsg s = rb::decodeJointState(m.data, m.size, where);
    mapJointNames(s.name);
    const long long present =
        std::count_if(cache_idx_.begin(), cache_idx_.end(), [](int i) { return i >= 0; });
    if (present == 0) {  // another publisher's joints (e.g. a gripper's)
      ++js_other_;
      if (js_found_names_.empty()) js_found_names_ = s.name;
      return;
    }
    ++js_seq_;
    if (present < n) {
      std::vector<std::string> missing;
      for (int j = 0; j < n; ++j)
        if (cache_idx_[static_cast<std::size_t>(j)] < 0)
          missing.push_back(names_[static_cast<std::size_t>(j)]);
      throw exid::Error(fmt::format(
          "{}{}: {}: no joint {} of robot '{}' (names in the message: {}); give "
          "joint_names (the message's name of each robot joint, in the robot's order)",
          pre_, bagname_, where, fmt::join(missing, ", "), robot_.name, fmt::join(s.name, ", ")));
    }
    const std::string why = jointStateProblem(s);
    const std::int64_t ns = header_time_ ? s.stamp.ns() : m.receive_ns;
    if (!why.empty()) {
      bad(js_topic_, k, m.where, why, &js_bad_);
      dropped_ns_.push_back(ns);  // its place in time: the step across it is no gap
      return;
    }
    js_.push_back({ns, k});
    for (int j = 0; j < n; ++j) {
      const std::size_t i = static_cast<std::size_t>(cache_idx_[static_cast<std::size_t>(j)]);
      qv_.push_back(s.position[i]);
      tauv_.push_back(s.effort[i]);
      if (use_vel_) qdv_.push_back(s.velocity[i]);
    }
  }

  void onWrench(const rb::RawMessage& m) {
    const long long k = ++wr_msgs_;
    const std::string where = fmt::format("topic '{}', message {}, {}", w_topic_, k, m.where);
    const rb::WrenchStampedMsg w = rb::decodeWrenchStamped(m.data, m.size, where);
    Wr r{header_time_ ? w.stamp.ns() : m.receive_ns,
         k,
         {w.force[0], w.force[1], w.force[2], w.torque[0], w.torque[1], w.torque[2]}};
    for (double x : r.v)
      if (!std::isfinite(x)) return bad(w_topic_, k, m.where, "non-finite value", &wr_bad_);
    wr_.push_back(r);
  }

  void onAux(Aux* a, const rb::RawMessage& m) {
    const long long k = ++a->count;
    const std::string where = fmt::format("topic '{}', message {}, {}", a->topic, k, m.where);
    Wr r{0, k, {0, 0, 0, 0, 0, 0}};
    std::int64_t stamp = 0;
    if (a->imu) {
      const rb::ImuMsg u = rb::decodeImu(m.data, m.size, where);
      stamp = u.stamp.ns();
      for (int c = 0; c < 3; ++c) {
        r.v[c] = u.angular_velocity[c];
        r.v[3 + c] = u.linear_acceleration[c];
      }
    } else {
      const rb::WrenchStampedMsg w = rb::decodeWrenchStamped(m.data, m.size, where);
      stamp = w.stamp.ns();
      for (int c = 0; c < 3; ++c) {
        r.v[c] = w.force[c];
        r.v[3 + c] = w.torque[c];
      }
    }
    r.ns = header_time_ ? stamp : m.receive_ns;
    for (double x : r.v)
      if (!std::isfinite(x)) return bad(a->topic, k, m.where, "non-finite value", &a->bad);
    a->msgs.push_back(r);
  }

  void checkMessages() const {
    exid::check(js_msgs_ > 0,
                fmt::format("{}{}: no message on topic '{}' (metadata.yaml lists {} "
                            "messages)",
                            pre_, bagname_, js_topic_, bag_.topic(js_topic_)->message_count));
    exid::check(js_seq_ > 0 || js_other_ == 0,
                fmt::format("{}{}: topic '{}': no message names any joint of robot '{}' ({}); "
                            "names found: {}. Give joint_names (the message's name of each robot "
                            "joint, in the robot's order)",
                            pre_, bagname_, js_topic_, robot_.name, fmt::join(names_, ", "),
                            fmt::join(js_found_names_, ", ")));
    exid::check(!js_.empty(), fmt::format("{}{}: topic '{}': every one of its {} messages was "
                                          "dropped ({} bad)",
                                          pre_, bagname_, js_topic_, js_msgs_, js_bad_));
    if (with_wrench_)
      exid::check(wr_msgs_ > 0,
                  fmt::format("{}{}: no message on wrench_topic '{}'", pre_, bagname_, w_topic_));
    for (const Aux& a : aux_)
      exid::check(a.count > 0,
                  fmt::format("{}{}: no message on {} '{}'", pre_, bagname_, a.key, a.topic));
  }

  // Order by time; a repeated stamp is a bad message (the later one).
  void orderByTime() {
    std::vector<std::size_t> order(js_.size());
    std::iota(order.begin(), order.end(), std::size_t{0});
    for (std::size_t i = 1; i < js_.size(); ++i) js_reordered_ += js_[i].ns < js_[i - 1].ns;
    std::stable_sort(order.begin(), order.end(),
                     [&](std::size_t a, std::size_t b) { return js_[a].ns < js_[b].ns; });
    for (std::size_t i : order) {
      if (!keep_.empty() && js_[i].ns == js_[keep_.back()].ns) {
        bad(js_topic_, js_[i].msg, "",
            fmt::format("its time stamp {} ns repeats that of message {}", js_[i].ns,
                        js_[keep_.back()].msg),
            &js_dup_);
        continue;
      }
      keep_.push_back(i);
    }
    if (with_wrench_) {
      std::stable_sort(wr_.begin(), wr_.end(),
                       [](const Wr& a, const Wr& b) { return a.ns < b.ns; });
      std::vector<Wr> u;
      for (const Wr& w : wr_) {
        if (!u.empty() && w.ns == u.back().ns) {
          bad(w_topic_, w.msg, "",
              fmt::format("its time stamp {} ns repeats that of message {}", w.ns, u.back().msg),
              &wr_dup_);
          continue;
        }
        u.push_back(w);
      }
      wr_ = std::move(u);
    }
    for (Aux& a : aux_) {
      std::stable_sort(a.msgs.begin(), a.msgs.end(),
                       [](const Wr& x, const Wr& y) { return x.ns < y.ns; });
      std::vector<Wr> u;
      for (const Wr& w : a.msgs) {
        if (!u.empty() && w.ns == u.back().ns) {
          bad(a.topic, w.msg, "",
              fmt::format("its time stamp {} ns repeats that of message {}", w.ns, u.back().msg),
              &a.dup);
          continue;
        }
        u.push_back(w);
      }
      a.msgs = std::move(u);
    }
  }

  void timeAxis() {
    // Time in seconds after the first joint-state sample: the difference in integer nanoseconds
    // first (an epoch stamp in double seconds would keep only a quarter microsecond), then one
    // correctly rounded division (5 s is 5.0, not 5 * 1e-9 * 1e9).
    t0_ = js_[keep_.front()].ns;
    tk_.resize(keep_.size());
    for (std::size_t i = 0; i < keep_.size(); ++i)
      tk_[i] = static_cast<double>(js_[keep_[i]].ns - t0_) / 1e9;
    // Position of each sample among the publisher's messages in time, dropped ones included:
    // a step across a dropped message spans two periods and is no gap.
    std::sort(dropped_ns_.begin(), dropped_ns_.end());
    pos_.resize(keep_.size());
    for (std::size_t i = 0; i < keep_.size(); ++i)
      pos_[i] = static_cast<long long>(i) +
                (std::lower_bound(dropped_ns_.begin(), dropped_ns_.end(), js_[keep_[i]].ns) -
                 dropped_ns_.begin());
  }

  static double median(std::vector<double> v) {
    std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
    return v[v.size() / 2];
  }

  // Gaps and uneven stamps.
  void checkSteps() {
    ratio_ = P_.getDouble("max_gap_ratio");
    const bool resample = P_.getDouble("resample_hz") > 0.0;
    if (tk_.size() < 3) return;
    std::vector<double> steps(tk_.size() - 1);
    for (std::size_t i = 1; i < tk_.size(); ++i)
      steps[i - 1] = (tk_[i] - tk_[i - 1]) / static_cast<double>(pos_[i] - pos_[i - 1]);
    const double med = median(steps);
    for (std::size_t i = 0; i < steps.size(); ++i)
      exid::check(
          steps[i] <= ratio_ * med && (resample || steps[i] >= med / ratio_),
          fmt::format("{}{}: topic '{}', message {} (t = {} s): time step {} s against "
                      "a median step of {} s after message {}: {} (a filter, "
                      "derivatives and energy integrals need a uniform rate); {}",
                      pre_, bagname_, js_topic_, js_[keep_[i + 1]].msg, tk_[i + 1], steps[i], med,
                      js_[keep_[i]].msg, steps[i] > med ? "a gap" : "uneven time stamps",
                      stepAdvice(steps[i], med, resample)));
  }

  // What makes a step outside max_gap_ratio acceptable, naming the keys that do it.
  std::string stepAdvice(double step, double med, bool resample) const {
    const std::string cut = "or cut the recording there with t_start_s/t_end_s";
    if (step < med)  // uneven stamps: resampling accepts them
      return fmt::format(
          "resample_hz > 0 puts the samples on a uniform grid and accepts uneven "
          "stamps, {}",
          cut);
    const double need = std::ceil(100.0 * step / med) / 100.0;
    return fmt::format(
        "{}max_gap_ratio: {:g} (now {:g}) bridges this gap by linear "
        "interpolation, {}",
        resample ? "" : "resample_hz > 0 with ", need, ratio_, cut);
  }

  // Segment and split, as the csv experiment.
  void selectSegment() {
    span_ = tk_.back();
    const double step_tol =
        tk_.size() > 1 ? 0.5 * span_ / static_cast<double>(tk_.size() - 1) : 0.0;
    seg_ = exid::resolveSegment(P_, span_, step_tol, pre_, bagname_, "joint-state sample");
    const double ts = seg_.t_start_s, te = seg_.t_end_s;
    const std::string& part = seg_.part;
    const double lo = seg_.lo_s;
    const double hi = seg_.hi_s;
    for (std::size_t i = 0; i < keep_.size(); ++i) {
      const double rel = tk_[i];
      if (rel < ts) continue;
      if (te > 0.0 && rel > te) break;
      ++in_segment_;
      if (rel < lo || (part == "identification" && rel >= hi)) continue;
      sel_.push_back(i);
    }
    exid::check(!sel_.empty(),
                fmt::format("{}{}: no joint-state sample in the segment [{}, {}] s after the first "
                            "sample (the recording spans {} s)",
                            pre_, bagname_, lo, part == "none" ? te : hi, span_));
    in_part_ = static_cast<int>(sel_.size());
  }

  // The wrench: linear interpolation at each sample's time between the two wrench messages
  // around it; samples outside the wrench's time range are cut (counted); a gap in the wrench
  // around a sample is an error (nothing is invented across it).
  void matchWrenchRange() {
    if (!with_wrench_) return;
    exid::check(!wr_.empty(), fmt::format("{}{}: topic '{}': every one of its {} messages was "
                                          "dropped",
                                          pre_, bagname_, w_topic_, wr_msgs_));
    for (const Wr& w : wr_) tw_.push_back(static_cast<double>(w.ns - t0_) / 1e9);
    if (tw_.size() >= 2) {
      std::vector<double> st(tw_.size() - 1);
      for (std::size_t i = 1; i < tw_.size(); ++i) st[i - 1] = tw_[i] - tw_[i - 1];
      wr_med_ = median(st);
    }
    std::vector<std::size_t> inside;
    for (std::size_t i : sel_)
      if (tk_[i] >= tw_.front() && tk_[i] <= tw_.back()) inside.push_back(i);
    outside_wrench_ = static_cast<int>(sel_.size() - inside.size());
    sel_ = std::move(inside);
    exid::check(!sel_.empty(),
                fmt::format("{}{}: no joint-state sample of the segment lies within the time "
                            "range of wrench_topic '{}' ([{}, {}] s after the first joint-state "
                            "sample)",
                            pre_, bagname_, w_topic_, tw_.front(), tw_.back()));
  }

  // An IMU's or a contact's topic, as the wrench's: samples outside its time range are cut
  // (counted); none left is an error.
  void matchAuxRange(Aux* ap) {
    Aux& a = *ap;
    exid::check(!a.msgs.empty(), fmt::format("{}{}: topic '{}': every one of its {} messages was "
                                             "dropped",
                                             pre_, bagname_, a.topic, a.count));
    for (const Wr& w : a.msgs) a.t.push_back(static_cast<double>(w.ns - t0_) / 1e9);
    if (a.t.size() >= 2) {
      std::vector<double> st(a.t.size() - 1);
      for (std::size_t i = 1; i < a.t.size(); ++i) st[i - 1] = a.t[i] - a.t[i - 1];
      a.med = median(st);
    }
    std::vector<std::size_t> inside;
    for (std::size_t i : sel_)
      if (tk_[i] >= a.t.front() && tk_[i] <= a.t.back()) inside.push_back(i);
    a.outside = static_cast<int>(sel_.size() - inside.size());
    sel_ = std::move(inside);
    exid::check(!sel_.empty(),
                fmt::format("{}{}: no joint-state sample of the segment lies within the time "
                            "range of {} '{}' ([{}, {}] s after the first joint-state sample)",
                            pre_, bagname_, a.key, a.topic, a.t.front(), a.t.back()));
  }

  // An IMU's or a contact's six values at each sample's time (linear interpolation between the
  // two messages around it; a gap around a sample is an error, as for the wrench).
  Eigen::MatrixXd interpolateAux(const Aux& a, const Eigen::VectorXd& tt) const {
    Eigen::MatrixXd out(tt.size(), 6);
    std::size_t w = 0;
    for (Eigen::Index k = 0; k < tt.size(); ++k) {
      const double t = tt[k];
      if (a.t.size() == 1) {
        for (int c = 0; c < 6; ++c) out(k, c) = a.msgs[0].v[c];
        continue;
      }
      while (w + 2 < a.t.size() && a.t[w + 1] <= t) ++w;
      const double len = a.t[w + 1] - a.t[w];
      exid::check(len <= ratio_ * a.med,
                  fmt::format("{}{}: {} '{}': a gap of {} s between messages {} and {} (median "
                              "step {} s) around the joint-state sample at t = {} s: it is not "
                              "interpolated across it; cut the segment there (t_start_s/t_end_s; "
                              "max_gap_ratio = {})",
                              pre_, bagname_, a.key, a.topic, len, a.msgs[w].msg, a.msgs[w + 1].msg,
                              a.med, t, ratio_));
      const double f = (t - a.t[w]) / len;
      for (int c = 0; c < 6; ++c) out(k, c) = (1.0 - f) * a.msgs[w].v[c] + f * a.msgs[w + 1].v[c];
    }
    return out;
  }

  // The base motion from the IMU (gyro and accelerometer in its frame; the angular acceleration
  // the gyro's central difference; exid::baseMotionFromImu removes the accelerometer's lever
  // arm) and the contacts' wrenches, at the samples' times.
  void floatingSignals(exid::Dataset* dp) const {
    exid::Dataset& d = *dp;
    int contacts = 0;
    for (const Aux& a : aux_) contacts += a.imu ? 0 : 1;
    if (contacts > 0) d.contact.resize(d.size(), 6 * contacts);
    int c = 0;
    for (const Aux& a : aux_) {
      const Eigen::MatrixXd v = interpolateAux(a, d.t);
      if (!a.imu) {
        d.contact.middleCols(6 * c++, 6) = v;
        continue;
      }
      exid::check(d.size() >= 3,
                  fmt::format("{}{}: {} samples are too few to differentiate the gyro of "
                              "imu_topic '{}' (at least 3)",
                              pre_, bagname_, d.size(), a.topic));
      const Eigen::MatrixXd gyro = v.leftCols(3);
      const Eigen::MatrixXd alpha = exid::centralFirstDerivative(d.t, gyro);
      d.base.resize(d.size(), 9);
      for (Eigen::Index k = 0; k < d.size(); ++k)
        d.base.row(k) =
            exid::baseMotionFromImu(imu_pose_, gyro.row(k).transpose(), alpha.row(k).transpose(),
                                    v.row(k).tail(3).transpose())
                .transpose();
    }
  }

  // The selected samples, converted (signs, scales, offsets, currents).
  exid::Dataset fillDataset() {
    const int n = n_;
    K_ = static_cast<int>(sel_.size());
    exid::Dataset d;
    d.t.resize(K_);
    d.q.resize(K_, n);
    d.tau.resize(K_, n);
    if (use_vel_) d.qd.resize(K_, n);
    Eigen::VectorXd tau;
    for (int k = 0; k < K_; ++k) {
      const std::size_t i = sel_[static_cast<std::size_t>(k)];
      const std::size_t s = keep_[i];
      d.t[k] = tk_[i];
      const std::size_t row = s * static_cast<std::size_t>(n);
      for (int j = 0; j < n; ++j) {
        const std::size_t at = row + static_cast<std::size_t>(j);
        d.q(k, j) = conv_.q(j, qv_[at]);
        if (use_vel_) d.qd(k, j) = conv_.qd(j, qdv_[at]);
      }
      conv_.torque(&tauv_[row], nullptr, &tau);
      d.tau.row(k) = tau.transpose();
    }
    return d;
  }

  void interpolateWrench(exid::Dataset* dp) const {
    if (!with_wrench_) return;
    exid::Dataset& d = *dp;
    d.wrench.resize(d.size(), 6);
    std::size_t w = 0;
    for (Eigen::Index k = 0; k < d.size(); ++k) {
      const double t = d.t[k];
      while (w + 2 < tw_.size() && tw_[w + 1] <= t) ++w;
      if (tw_.size() == 1) {  // a single wrench message: only a sample at its very time
        for (int c = 0; c < 6; ++c) d.wrench(k, c) = conv_.wrench(c, wr_[0].v[c]);
        continue;
      }
      const double len = tw_[w + 1] - tw_[w];
      exid::check(len <= ratio_ * wr_med_,
                  fmt::format("{}{}: wrench_topic '{}': a gap of {} s between messages {} and {} "
                              "(median step {} s) around the joint-state sample at t = {} s: the "
                              "wrench is not interpolated across it; cut the segment there "
                              "(t_start_s/t_end_s; max_gap_ratio = {})",
                              pre_, bagname_, w_topic_, len, wr_[w].msg, wr_[w + 1].msg, wr_med_, t,
                              ratio_));
      const double a = (t - tw_[w]) / len;
      for (int c = 0; c < 6; ++c)
        d.wrench(k, c) = conv_.wrench(c, (1.0 - a) * wr_[w].v[c] + a * wr_[w + 1].v[c]);
    }
  }

  // Every topic of the bag: type, messages, span, rate, publishers (when metadata.yaml lists
  // their QoS profiles) and what exid made of it (meta.topics; exid inspect lists them).
  exid::Json topicsMeta() const {
    exid::Json out = exid::Json::array();
    for (const auto& [name, tc] : census_) {
      exid::Json t = exid::Json::object();
      t["topic"] = name;
      t["type"] = tc.type;
      t["messages"] = tc.messages;
      const double span = static_cast<double>(tc.last_ns - tc.first_ns) / 1e9;
      t["span_s"] = span;
      if (tc.messages >= 2 && span > 0) t["rate_hz"] = static_cast<double>(tc.messages - 1) / span;
      const rb::TopicInfo* info = bag_.topic(name);
      // (metadata.yaml's count, else the storage's: an MCAP channel's or a SQLite topic's)
      if (info && info->publishers >= 0)
        t["publishers"] = info->publishers;
      else if (tc.publishers >= 0)
        t["publishers"] = tc.publishers;
      std::string used = name == js_topic_                  ? "joint states"
                         : with_wrench_ && name == w_topic_ ? "wrench"
                                                            : "not used";
      for (const Aux& a : aux_)
        if (a.topic == name) used = a.imu ? "imu (base motion)" : a.label + " (contact wrench)";
      t["used_as"] = used;
      out.push_back(std::move(t));
    }
    return out;
  }

  // Timing of the segment's samples (as the csv experiment's meta.recording).
  exid::Json recordingMeta() const {
    std::vector<double> raw;
    std::vector<int> row;
    for (std::size_t i : sel_) {
      raw.push_back(static_cast<double>(js_[keep_[i]].ns - t0_));
      row.push_back(static_cast<int>(std::min<long long>(pos_[i], 2000000000LL)));
    }
    exid::Json R = exid::Json::object();
    R["file"] = bagname_;
    R["rows"] = static_cast<long long>(raw.size());
    exid::Json t = exid::samplingStats(raw, 1e-9, row, ratio_);
    t["source"] = fmt::format("{} of topic '{}'", header_time_ ? "header stamps" : "receive stamps",
                              js_topic_);
    R["timing"] = t;
    return R;
  }

  // Where the messages went: every one dropped or cut is counted (a = meta.accounting).
  void accounting(const exid::RecordingPipeline& steps, exid::Json& a, exid::Json& m) const {
    a["joint_state_messages"] = js_msgs_;
    a["other_joints_messages"] = js_other_;
    a["dropped_bad_messages"] = js_bad_;
    a["dropped_repeated_stamps"] = js_dup_;
    a["reordered_messages"] = js_reordered_;
    a["outside_segment"] = static_cast<int>(keep_.size()) - in_segment_;
    if (seg_.part != "none") a["other_part_of_split"] = in_segment_ - in_part_;
    if (with_wrench_) {
      a["outside_wrench_range"] = outside_wrench_;
      a["wrench_messages"] = wr_msgs_;
      a["wrench_dropped_bad_messages"] = wr_bad_;
      a["wrench_dropped_repeated_stamps"] = wr_dup_;
    }
    for (const Aux& x : aux_) {
      a[x.label + "_messages"] = x.count;
      a[x.label + "_dropped_bad_messages"] = x.bad;
      a[x.label + "_dropped_repeated_stamps"] = x.dup;
      a["outside_" + x.label + "_range"] = x.outside;
    }
    a["segment_samples"] = K_;
    exid::Json w = exid::Json::array();
    for (const Aux& x : aux_) {
      if (x.bad + x.dup > 0)
        w.push_back(exid::Json(fmt::format(
            "{}{}: {} of {} messages of topic '{}' dropped ({} bad, {} repeated stamps; "
            "drop_bad_messages)",
            pre_, bagname_, x.bad + x.dup, x.count, x.topic, x.bad, x.dup)));
      if (x.outside > 0)
        w.push_back(
            exid::Json(fmt::format("{}{}: {} joint-state samples of the segment lie "
                                   "outside the time range of {} '{}' and were cut",
                                   pre_, bagname_, x.outside, x.key, x.topic)));
    }
    if (js_bad_ + js_dup_ > 0)
      w.push_back(exid::Json(
          fmt::format("{}{}: {} of {} messages of topic '{}' dropped ({} bad, {} repeated stamps; "
                      "drop_bad_messages)",
                      pre_, bagname_, js_bad_ + js_dup_, js_msgs_, js_topic_, js_bad_, js_dup_)));
    if (wr_bad_ + wr_dup_ > 0)
      w.push_back(exid::Json(
          fmt::format("{}{}: {} of {} messages of topic '{}' dropped ({} bad, {} repeated stamps; "
                      "drop_bad_messages)",
                      pre_, bagname_, wr_bad_ + wr_dup_, wr_msgs_, w_topic_, wr_bad_, wr_dup_)));
    if (outside_wrench_ > 0)
      w.push_back(exid::Json(
          fmt::format("{}{}: {} joint-state samples of the segment lie outside the time range of "
                      "wrench_topic '{}' and were cut",
                      pre_, bagname_, outside_wrench_, w_topic_)));
    steps.account(&a, &w);
    if (bad_examples_.size() > 0) a["dropped_examples"] = bad_examples_;
    if (w.size() > 0) m["warnings"] = w;
    // what was skipped without being wrong: said, not warned about
    exid::Json notes = exid::Json::array();
    if (js_other_ > 0)
      notes.push_back(exid::Json(fmt::format(
          "{} of {} messages of topic '{}' name none of the robot's joints (another publisher, "
          "e.g. a gripper's): skipped",
          js_other_, js_msgs_, js_topic_)));
    if (notes.size() > 0) m["notes"] = notes;
  }

  void describe(const exid::RecordingPipeline& steps, exid::Dataset* dp) const {
    exid::Dataset& d = *dp;
    d.source = bagname_;
    exid::Json& m = d.meta;
    m["file"] = bagname_;
    m["storage"] = bag_.storage;
    m["opened_as"] = opened_as_;
    {
      std::vector<std::string> files;
      for (const fs::path& f : bag_.files) files.push_back(f.filename().string());
      m["storage_files"] = exid::Json(files);
    }
    m["joint_states_topic"] = js_topic_;
    if (with_wrench_) {
      m["wrench_topic"] = w_topic_;
      m["wrench_matching"] =
          "linear interpolation at the joint-state times between the two wrench messages around "
          "each; joint-state samples outside the wrench's time range are cut "
          "(accounting.outside_wrench_range)";
    }
    for (const Aux& a : aux_) {
      if (a.imu) {
        m["imu_topic"] = a.topic;
        m["base_motion"] =
            "from imu_topic: angular_velocity and linear_acceleration interpolated linearly at "
            "the joint-state times, the angular acceleration their central difference in time, "
            "the accelerometer's lever arm removed (exid::baseMotionFromImu, imu_pose_xyz_rpy); "
            "samples outside the IMU's time range are cut (accounting.outside_imu_range)";
      }
    }
    if (!P_.getStrings("contact_topics").empty())
      m["contact_topics"] = exid::Json(P_.getStrings("contact_topics"));
    m["time"] = header_time_ ? "header stamps" : "receive stamps";
    m["torque_from"] = P_.getString("torque_from");
    m["time_origin_ns"] = static_cast<long long>(t0_);
    m["joint_names"] = exid::Json(names_);
    m["samples"] = d.size();
    m["segment_s"] = exid::Json(std::vector<double>{seg_.t_start_s, seg_.t_end_s});
    if (seg_.part != "none") m["split"] = seg_.splitMeta(in_segment_, in_part_);
    m["recording_span_s"] = span_;
    m["recording"] = recordingMeta();
    m["topics"] = topicsMeta();
    accounting(steps, m["accounting"], m);
    steps.describe(&m);
    std::vector<std::string> sig = {"q"};
    if (use_vel_) sig.push_back("qd");
    sig.push_back("tau");
    if (with_wrench_) sig.push_back("wrench");
    if (d.hasBase()) sig.push_back("base");
    if (d.hasContact()) sig.push_back("contact");
    m["signals"] = exid::Json(sig);
  }

  const exid::ParamSet& P_;
  const exid::RobotModel& robot_;
  const int n_;
  const std::function<bool()> stop_;  // the run's stop request (polled while reading)
  const std::string pre_ = "experiment 'rosbag2': ";
  fs::path dir_;
  std::string opened_as_;  // what the path named (rb::openBag)
  rb::Census census_;      // every topic of the bag, counted while it is read
  std::string bagname_;
  std::vector<std::string> names_;
  exid::SignalConversion conv_;
  rb::BagInfo bag_;
  std::string js_topic_, w_topic_;
  bool with_wrench_ = false, header_time_ = false, use_vel_ = false, drop_ = false;
  // the messages
  std::vector<Js> js_;
  std::vector<double> qv_, qdv_, tauv_;  // n per sample
  std::vector<Wr> wr_;
  long long js_msgs_ = 0, js_other_ = 0, js_seq_ = 0, js_bad_ = 0, wr_msgs_ = 0, wr_bad_ = 0;
  std::vector<std::int64_t> dropped_ns_;     // stamps of joint-state messages dropped as bad
  std::vector<std::string> js_found_names_;  // names of the first message without our joints
  exid::Json bad_examples_ = exid::Json::array();
  std::vector<std::string> cache_names_;
  std::vector<int> cache_idx_;  // per robot joint: its index in the message
  // in time
  long long js_reordered_ = 0, js_dup_ = 0, wr_dup_ = 0;
  std::vector<std::size_t> keep_;  // indices into js_, by time, no repeated stamp
  std::int64_t t0_ = 0;
  std::vector<double> tk_;
  std::vector<long long> pos_;
  double ratio_ = 0;
  // the segment and the wrench
  double span_ = 0;
  exid::RecordingSegment seg_;
  std::vector<std::size_t> sel_;  // indices into keep_ / tk_
  int in_segment_ = 0, in_part_ = 0;
  std::vector<double> tw_;  // wrench times, s after t0_
  int outside_wrench_ = 0;
  double wr_med_ = 0.0;
  std::vector<Aux> aux_;  // the IMU first (if any), then the contacts in order
  exid::Pose imu_pose_;
  // the dataset
  int K_ = 0;
};

class Rosbag2Experiment : public exid::Experiment {
 public:
  static constexpr const char* kName = "rosbag2";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "recorded data from a ROS 2 bag folder (SQLite or MCAP): JointState (by joint name) gives "
      "q, tau and optionally qd, WrenchStamped the wrench; header stamps as time";

  static std::vector<exid::ParamDecl> params() {
    using namespace exid;
    std::vector<ParamDecl> p = {
        param_path("path", std::string(),
                   "the bag: its folder (metadata.yaml and its .db3 or .mcap files), one of its "
                   "storage files, or a bare .mcap / .db3 file (relative paths: to the study "
                   "file); give path or paths"),
        param_strings("paths", std::vector<std::string>{},
                      "several bags of one study (each as path), in order: each is read, "
                      "segmented, split and filtered on its own and becomes one part of the data "
                      "(no model or estimator filters, integrates or simulates across two); give "
                      "path or paths"),
        param_string("joint_states_topic", std::string("/joint_states"),
                     "topic of sensor_msgs/msg/JointState messages"),
        param_string("wrench_topic", std::string(),
                     "topic of geometry_msgs/msg/WrenchStamped messages (fx fy fz mx my mz, "
                     "interpolated linearly at the joint-state times); empty: no wrench"),
        param_string("imu_topic", std::string(),
                     "a floating base: topic of sensor_msgs/msg/Imu messages from an IMU rigidly "
                     "mounted on the base link; angular_velocity and linear_acceleration "
                     "(interpolated at the joint-state times) give the base motion (omega, alpha "
                     "= the gyro's central difference, f = a - g with the lever arm removed); the "
                     "orientation is not used; empty: none"),
        param_doubles("imu_pose_xyz_rpy", std::vector<double>{}, "m, rad",
                      "the IMU's frame in the base link's frame (x y z roll pitch yaw); required "
                      "with imu_topic"),
        param_strings("contact_topics", std::vector<std::string>{},
                      "a floating base: topics of geometry_msgs/msg/WrenchStamped, one per "
                      "contact of the model's contact_links, in that order: the wrench exerted "
                      "by the environment on the robot in the contact's sensor frame "
                      "(interpolated at the joint-state times)"),
        param_strings("joint_names", std::vector<std::string>{},
                      "per joint of the robot, in the robot's order: its name in the JointState "
                      "messages; empty: the robot's own joint names"),
        param_string("time", std::string("header"),
                     "header: the messages' header stamps; receive: the bag's receive time "
                     "stamps",
                     {"header", "receive"}),
        param_bool("use_velocity", false,
                   "JointState.velocity becomes qd (it must then hold one value per name); "
                   "false: no qd, estimators differentiate q"),
        param_bool("drop_bad_messages", false,
                   "drop joint-state or wrench messages with an empty or wrong-length effort / "
                   "position / velocity, non-finite values or a repeated time stamp (counted in "
                   "meta); false: such a message is an error naming it"),
        param_double("max_gap_ratio", 1.5, "",
                     "a time step longer than this times the median step (a gap), or shorter "
                     "than its inverse (uneven stamps), is an error naming the messages",
                     1.0, std::nullopt, true),
    };
    const auto conv = exid::signalConversionParams("JointState.effort values");
    p.insert(p.end(), conv.begin(), conv.end());
    const auto segment = exid::segmentParams("joint-state sample");
    p.insert(p.end(), segment.begin(), segment.end());
    const auto steps = exid::recordingStepParams();  // the filter steps, as csv's
    p.insert(p.end(), steps.begin(), steps.end());
    return p;
  }

  explicit Rosbag2Experiment(const exid::ParamSet& p) : P_(p) {}

  exid::Dataset run(std::shared_ptr<const exid::RobotModel> robot, const exid::Samples*,
                    const exid::RunContext& ctx) override {
    exid::check(robot != nullptr, "experiment 'rosbag2': no robot");
    std::vector<std::string> paths = P_.getStrings("paths");
    const std::string path = P_.getString("path");
    exid::check(path.empty() != paths.empty(),
                path.empty()
                    ? "experiment 'rosbag2': no bag: give path (one bag) or paths (several)"
                    : "experiment 'rosbag2': both path and paths are given: give path "
                      "(one bag) or paths (several), not both");
    if (paths.empty()) paths.push_back(path);
    for (std::size_t i = 0; i < paths.size(); ++i)
      for (std::size_t j = 0; j < i; ++j)
        exid::check(paths[i] != paths[j],
                    fmt::format("experiment 'rosbag2': paths: '{}' is given twice (entries {} and "
                                "{}): each bag once, or its samples would count twice",
                                paths[i], j + 1, i + 1));
    std::vector<exid::Dataset> parts;
    for (std::size_t i = 0; i < paths.size(); ++i) {
      BagReading reading(P_, paths[i], *robot, ctx);
      parts.push_back(reading.read());
      ctx.report(static_cast<double>(i + 1) / static_cast<double>(paths.size()),
                 fmt::format("{} samples from {}", parts.back().size(), reading.bagname()));
    }
    return exid::joinParts(std::move(parts), "experiment 'rosbag2'");
  }

 private:
  exid::ParamSet P_;
};

}  // namespace

EXID_REGISTER_PLUGIN(Rosbag2Experiment)
