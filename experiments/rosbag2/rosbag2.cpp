// exid — experiment `rosbag2`: a ROS 2 recording read from its bag folder (metadata.yaml and
// SQLite .db3 or MCAP files) without a ROS installation. sensor_msgs/msg/JointState gives q
// (position), tau (effort) and optionally qd (velocity), by joint name; an optional
// geometry_msgs/msg/WrenchStamped topic gives the wrench, linearly interpolated at the joint-state
// times. Time: the messages' header stamps (or the bag's receive stamps), in seconds after the
// first joint-state sample. Segment, split, signs, gaps and the accounting of every message
// dropped or cut follow the csv experiment (docs/experiments.md).
#include <fmt/format.h>
#include <fmt/ranges.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <numeric>
#include <set>
#include <string>
#include <vector>

#include "bag.hpp"
#include "exid/error.hpp"
#include "exid/inspect.hpp"
#include "exid/interfaces.hpp"
#include "exid/segment.hpp"

namespace {

namespace fs = std::filesystem;
namespace rb = exid::rosbag2;

constexpr const char* kJointStateType = "sensor_msgs/msg/JointState";
constexpr const char* kWrenchType = "geometry_msgs/msg/WrenchStamped";

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
        param_path("path", std::nullopt,
                   "the bag folder (metadata.yaml and its .db3 or .mcap files; relative paths: to "
                   "the study file)"),
        param_string("joint_states_topic", std::string("/joint_states"),
                     "topic of sensor_msgs/msg/JointState messages"),
        param_string("wrench_topic", std::string(),
                     "topic of geometry_msgs/msg/WrenchStamped messages (fx fy fz mx my mz, "
                     "interpolated linearly at the joint-state times); empty: no wrench"),
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
        param_doubles("sign", std::vector<double>{}, "",
                      "per joint +1 or -1, applied to q, qd and tau of that joint; empty: all +1"),
        param_double("resample_hz", 0.0, "Hz",
                     "> 0: the segment is linearly interpolated onto a uniform grid at this rate "
                     "(uneven stamps are then accepted; a gap longer than max_gap_ratio times "
                     "the median step is still an error); 0: the stamps must be uniform",
                     0.0),
        param_double("max_gap_ratio", 1.5, "",
                     "a time step longer than this times the median step (a gap), or shorter "
                     "than its inverse (uneven stamps), is an error naming the messages",
                     1.0, std::nullopt, true),
    };
    const auto segment = exid::segmentParams("joint-state sample");
    p.insert(p.end(), segment.begin(), segment.end());
    return p;
  }

  explicit Rosbag2Experiment(const exid::ParamSet& p) : P_(p) {}

  exid::Dataset run(std::shared_ptr<const exid::RobotModel> robot, const exid::Samples*,
                    const exid::RunContext& ctx) override {
    exid::check(robot != nullptr, "experiment 'rosbag2': no robot");
    const int n = robot->dof();
    fs::path dir = P_.getString("path");
    if (dir.is_relative() && !ctx.study_dir.empty()) dir = ctx.study_dir / dir;
    const std::string bagname = dir.string();
    const std::string pre = "experiment 'rosbag2': ";

    // The robot's joints and their names in the messages.
    std::vector<std::string> names = P_.getStrings("joint_names");
    if (names.empty()) {
      for (const exid::Body& b : robot->bodies) names.push_back(b.joint_name);
    } else {
      exid::check(static_cast<int>(names.size()) == n,
                  fmt::format("{}joint_names: expected {} names (one per joint of robot '{}', in "
                              "its order), found {}",
                              pre, n, robot->name, names.size()));
    }
    for (std::size_t a = 0; a < names.size(); ++a) {
      exid::check(!names[a].empty(),
                  fmt::format("{}joint {} of robot '{}' has no name; give joint_names", pre, a + 1,
                              robot->name));
      for (std::size_t b = 0; b < a; ++b)
        exid::check(names[a] != names[b],
                    fmt::format("{}joint_names: '{}' is named twice (joints {} and {}); each joint "
                                "needs its own name",
                                pre, names[a], b + 1, a + 1));
    }
    std::vector<double> sign = P_.getDoubles("sign");
    if (sign.empty()) sign.assign(static_cast<std::size_t>(n), 1.0);
    exid::check(
        static_cast<int>(sign.size()) == n,
        fmt::format("{}sign: expected {} values (one per joint), found {}", pre, n, sign.size()));
    for (int j = 0; j < n; ++j)
      exid::check(
          sign[static_cast<std::size_t>(j)] == 1.0 || sign[static_cast<std::size_t>(j)] == -1.0,
          fmt::format("{}sign: joint {}: expected +1 or -1, found {}", pre, j + 1,
                      sign[static_cast<std::size_t>(j)]));

    // The bag and its topics.
    const rb::BagInfo bag = [&] {
      try {
        return rb::readMetadata(dir);
      } catch (const exid::Error& e) {
        throw exid::Error(pre + e.what());
      }
    }();
    const std::string js_topic = P_.getString("joint_states_topic");
    const std::string w_topic = P_.getString("wrench_topic");
    auto topicList = [&] {
      std::vector<std::string> v;
      for (const rb::TopicInfo& t : bag.topics) v.push_back(t.name + " (" + t.type + ")");
      return v.empty() ? std::string("none") : fmt::format("{}", fmt::join(v, ", "));
    };
    auto checkTopic = [&](const std::string& topic, const char* key, const char* type) {
      exid::check(!topic.empty(), fmt::format("{}{}: empty topic name", pre, key));
      const rb::TopicInfo* t = bag.topic(topic);
      exid::check(t != nullptr,
                  fmt::format("{}{}: {} = '{}': no such topic in the bag (topics: "
                              "{})",
                              pre, bag.metadata_file.string(), key, topic, topicList()));
      exid::check(t->type == type,
                  fmt::format("{}{}: {} = '{}' has type '{}', expected {}", pre,
                              bag.metadata_file.string(), key, topic, t->type, type));
      exid::check(t->serialization_format == "cdr",
                  fmt::format("{}{}: topic '{}': serialization_format '{}', expected cdr", pre,
                              bag.metadata_file.string(), topic, t->serialization_format));
    };
    checkTopic(js_topic, "joint_states_topic", kJointStateType);
    const bool with_wrench = !w_topic.empty();
    if (with_wrench) {
      checkTopic(w_topic, "wrench_topic", kWrenchType);
      exid::check(w_topic != js_topic,
                  fmt::format("{}wrench_topic and joint_states_topic are both '{}'", pre, w_topic));
    }

    // Read the messages.
    const bool header_time = P_.getString("time") == "header";
    const bool use_vel = P_.getBool("use_velocity");
    const bool drop = P_.getBool("drop_bad_messages");
    struct Js {
      std::int64_t ns;
      long long msg;  // 1-based index among the topic's messages (bag order)
    };
    std::vector<Js> js;
    std::vector<double> qv, qdv, tauv;  // n per sample
    struct Wr {
      std::int64_t ns;
      long long msg;
      double v[6];
    };
    std::vector<Wr> wr;
    long long js_msgs = 0, js_other = 0, js_seq = 0, js_bad = 0, wr_msgs = 0, wr_bad = 0;
    std::vector<std::int64_t> dropped_ns;     // stamps of joint-state messages dropped as bad
    std::vector<std::string> js_found_names;  // names of the first message without our joints
    exid::Json bad_examples = exid::Json::array();
    std::vector<std::string> cache_names;
    std::vector<int> cache_idx;  // per robot joint: its index in the message
    auto bad = [&](const std::string& topic, long long k, const std::string& where,
                   const std::string& why, long long* counter) {
      const std::string msg =
          fmt::format("{}{}: topic '{}', message {}{}: {}", pre, bagname, topic, k,
                      where.empty() ? std::string() : " (" + where + ")", why);
      if (!drop) throw exid::Error(msg + " (set drop_bad_messages: true to drop such messages)");
      ++*counter;
      if (bad_examples.size() < 10) bad_examples.push_back(exid::Json(msg));
    };
    const std::set<std::string> wanted =
        with_wrench ? std::set<std::string>{js_topic, w_topic} : std::set<std::string>{js_topic};
    try {
      rb::readMessages(bag, wanted, [&](const rb::RawMessage& m) {
        if (*m.topic == js_topic) {
          const long long k = ++js_msgs;
          const std::string where = fmt::format("topic '{}', message {}, {}", js_topic, k, m.where);
          const rb::JointStateMsg s = rb::decodeJointState(m.data, m.size, where);
          if (s.name != cache_names) {
            cache_names = s.name;
            cache_idx.assign(static_cast<std::size_t>(n), -1);
            for (int j = 0; j < n; ++j)
              for (std::size_t i = 0; i < s.name.size(); ++i)
                if (s.name[i] == names[static_cast<std::size_t>(j)]) {
                  cache_idx[static_cast<std::size_t>(j)] = static_cast<int>(i);
                  break;
                }
          }
          const long long present =
              std::count_if(cache_idx.begin(), cache_idx.end(), [](int i) { return i >= 0; });
          if (present == 0) {  // another publisher's joints (e.g. a gripper's)
            ++js_other;
            if (js_found_names.empty()) js_found_names = s.name;
            return;
          }
          ++js_seq;
          if (present < n) {
            std::vector<std::string> missing;
            for (int j = 0; j < n; ++j)
              if (cache_idx[static_cast<std::size_t>(j)] < 0)
                missing.push_back(names[static_cast<std::size_t>(j)]);
            throw exid::Error(fmt::format(
                "{}{}: {}: no joint {} of robot '{}' (names in the message: {}); give "
                "joint_names (the message's name of each robot joint, in the robot's order)",
                pre, bagname, where, fmt::join(missing, ", "), robot->name,
                fmt::join(s.name, ", ")));
          }
          const std::size_t nn = s.name.size();
          auto lenProblem = [&](const std::vector<double>& v, const char* field) {
            return v.size() == nn
                       ? std::string()
                       : fmt::format("{} has {} values for {} names", field, v.size(), nn);
          };
          std::string why = lenProblem(s.position, "position");
          if (why.empty()) why = lenProblem(s.effort, "effort");
          if (why.empty() && use_vel) why = lenProblem(s.velocity, "velocity");
          if (why.empty())
            for (int j = 0; j < n && why.empty(); ++j) {
              const std::size_t i =
                  static_cast<std::size_t>(cache_idx[static_cast<std::size_t>(j)]);
              if (!std::isfinite(s.position[i]) || !std::isfinite(s.effort[i]) ||
                  (use_vel && !std::isfinite(s.velocity[i])))
                why = fmt::format("non-finite value for joint '{}'", s.name[i]);
            }
          const std::int64_t ns = header_time ? s.stamp.ns() : m.receive_ns;
          if (!why.empty()) {
            bad(js_topic, k, m.where, why, &js_bad);
            dropped_ns.push_back(ns);  // its place in time: the step across it is no gap
            return;
          }
          js.push_back({ns, k});
          for (int j = 0; j < n; ++j) {
            const std::size_t i = static_cast<std::size_t>(cache_idx[static_cast<std::size_t>(j)]);
            qv.push_back(s.position[i]);
            tauv.push_back(s.effort[i]);
            if (use_vel) qdv.push_back(s.velocity[i]);
          }
        } else {
          const long long k = ++wr_msgs;
          const std::string where = fmt::format("topic '{}', message {}, {}", w_topic, k, m.where);
          const rb::WrenchStampedMsg w = rb::decodeWrenchStamped(m.data, m.size, where);
          Wr r{header_time ? w.stamp.ns() : m.receive_ns,
               k,
               {w.force[0], w.force[1], w.force[2], w.torque[0], w.torque[1], w.torque[2]}};
          for (double x : r.v)
            if (!std::isfinite(x)) return bad(w_topic, k, m.where, "non-finite value", &wr_bad);
          wr.push_back(r);
        }
      });
    } catch (const exid::Error& e) {
      const std::string w = e.what();
      if (w.rfind(pre, 0) == 0) throw;
      throw exid::Error(pre + w);
    }
    exid::check(js_msgs > 0,
                fmt::format("{}{}: no message on topic '{}' (metadata.yaml lists {} "
                            "messages)",
                            pre, bagname, js_topic, bag.topic(js_topic)->message_count));
    exid::check(js_seq > 0 || js_other == 0,
                fmt::format("{}{}: topic '{}': no message names any joint of robot '{}' ({}); "
                            "names found: {}. Give joint_names (the message's name of each robot "
                            "joint, in the robot's order)",
                            pre, bagname, js_topic, robot->name, fmt::join(names, ", "),
                            fmt::join(js_found_names, ", ")));
    exid::check(!js.empty(), fmt::format("{}{}: topic '{}': every one of its {} messages was "
                                         "dropped ({} bad)",
                                         pre, bagname, js_topic, js_msgs, js_bad));
    if (with_wrench)
      exid::check(wr_msgs > 0,
                  fmt::format("{}{}: no message on wrench_topic '{}'", pre, bagname, w_topic));

    // Order by time; a repeated stamp is a bad message (the later one).
    long long js_reordered = 0, js_dup = 0, wr_dup = 0;
    std::vector<std::size_t> order(js.size());
    std::iota(order.begin(), order.end(), std::size_t{0});
    for (std::size_t i = 1; i < js.size(); ++i) js_reordered += js[i].ns < js[i - 1].ns;
    std::stable_sort(order.begin(), order.end(),
                     [&](std::size_t a, std::size_t b) { return js[a].ns < js[b].ns; });
    std::vector<std::size_t> keep;  // indices into js, by time, no repeated stamp
    for (std::size_t i : order) {
      if (!keep.empty() && js[i].ns == js[keep.back()].ns) {
        bad(js_topic, js[i].msg, "",
            fmt::format("its time stamp {} ns repeats that of message {}", js[i].ns,
                        js[keep.back()].msg),
            &js_dup);
        continue;
      }
      keep.push_back(i);
    }
    if (with_wrench) {
      std::stable_sort(wr.begin(), wr.end(), [](const Wr& a, const Wr& b) { return a.ns < b.ns; });
      std::vector<Wr> u;
      for (const Wr& w : wr) {
        if (!u.empty() && w.ns == u.back().ns) {
          bad(w_topic, w.msg, "",
              fmt::format("its time stamp {} ns repeats that of message {}", w.ns, u.back().msg),
              &wr_dup);
          continue;
        }
        u.push_back(w);
      }
      wr = std::move(u);
    }

    // Time in seconds after the first joint-state sample: the difference in integer nanoseconds
    // first (an epoch stamp in double seconds would keep only a quarter microsecond), then one
    // correctly rounded division (5 s is 5.0, not 5 * 1e-9 * 1e9).
    const std::int64_t t0 = js[keep.front()].ns;
    std::vector<double> tk(keep.size());
    for (std::size_t i = 0; i < keep.size(); ++i)
      tk[i] = static_cast<double>(js[keep[i]].ns - t0) / 1e9;

    // Position of each sample among the publisher's messages in time, dropped ones included:
    // a step across a dropped message spans two periods and is no gap.
    std::sort(dropped_ns.begin(), dropped_ns.end());
    std::vector<long long> pos(keep.size());
    for (std::size_t i = 0; i < keep.size(); ++i)
      pos[i] = static_cast<long long>(i) +
               (std::lower_bound(dropped_ns.begin(), dropped_ns.end(), js[keep[i]].ns) -
                dropped_ns.begin());

    // Gaps and uneven stamps.
    const double ratio = P_.getDouble("max_gap_ratio");
    const bool resample = P_.getDouble("resample_hz") > 0.0;
    auto median = [](std::vector<double> v) {
      std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
      return v[v.size() / 2];
    };
    if (tk.size() >= 3) {
      std::vector<double> steps(tk.size() - 1);
      for (std::size_t i = 1; i < tk.size(); ++i)
        steps[i - 1] = (tk[i] - tk[i - 1]) / static_cast<double>(pos[i] - pos[i - 1]);
      const double med = median(steps);
      for (std::size_t i = 0; i < steps.size(); ++i)
        exid::check(
            steps[i] <= ratio * med && (resample || steps[i] >= med / ratio),
            fmt::format("{}{}: topic '{}', message {} (t = {} s): time step {} s against "
                        "a median step of {} s after message {}: {} (a filter, "
                        "derivatives and energy integrals need a uniform rate); cut the "
                        "recording there with t_start_s/t_end_s{} (max_gap_ratio = {})",
                        pre, bagname, js_topic, js[keep[i + 1]].msg, tk[i + 1], steps[i], med,
                        js[keep[i]].msg, steps[i] > med ? "a gap" : "uneven time stamps",
                        steps[i] > med ? "" : ", or resample it (resample_hz)", ratio));
    }

    // Segment and split, as the csv experiment.
    const double span = tk.back();
    const double step_tol = tk.size() > 1 ? 0.5 * span / static_cast<double>(tk.size() - 1) : 0.0;
    const exid::RecordingSegment seg =
        exid::resolveSegment(P_, span, step_tol, pre, bagname, "joint-state sample");
    const double ts = seg.t_start_s, te = seg.t_end_s;
    const std::string& part = seg.part;
    const double lo = seg.lo_s;
    const double hi = seg.hi_s;
    std::vector<std::size_t> sel;  // indices into keep / tk
    int in_segment = 0;
    for (std::size_t i = 0; i < keep.size(); ++i) {
      const double rel = tk[i];
      if (rel < ts) continue;
      if (te > 0.0 && rel > te) break;
      ++in_segment;
      if (rel < lo || (part == "identification" && rel >= hi)) continue;
      sel.push_back(i);
    }
    exid::check(!sel.empty(),
                fmt::format("{}{}: no joint-state sample in the segment [{}, {}] s after the first "
                            "sample (the recording spans {} s)",
                            pre, bagname, lo, part == "none" ? te : hi, span));
    const int in_part = static_cast<int>(sel.size());

    // The wrench: linear interpolation at each sample's time between the two wrench messages
    // around it; samples outside the wrench's time range are cut (counted); a gap in the wrench
    // around a sample is an error (nothing is invented across it).
    std::vector<double> tw;  // wrench times, s after t0
    int outside_wrench = 0;
    double wr_med = 0.0;
    if (with_wrench) {
      exid::check(!wr.empty(), fmt::format("{}{}: topic '{}': every one of its {} messages was "
                                           "dropped",
                                           pre, bagname, w_topic, wr_msgs));
      for (const Wr& w : wr) tw.push_back(static_cast<double>(w.ns - t0) / 1e9);
      if (tw.size() >= 2) {
        std::vector<double> st(tw.size() - 1);
        for (std::size_t i = 1; i < tw.size(); ++i) st[i - 1] = tw[i] - tw[i - 1];
        wr_med = median(st);
      }
      std::vector<std::size_t> inside;
      for (std::size_t i : sel)
        if (tk[i] >= tw.front() && tk[i] <= tw.back()) inside.push_back(i);
      outside_wrench = static_cast<int>(sel.size() - inside.size());
      sel = std::move(inside);
      exid::check(!sel.empty(),
                  fmt::format("{}{}: no joint-state sample of the segment lies within the time "
                              "range of wrench_topic '{}' ([{}, {}] s after the first joint-state "
                              "sample)",
                              pre, bagname, w_topic, tw.front(), tw.back()));
    }

    // Fill the dataset.
    const int K = static_cast<int>(sel.size());
    exid::Dataset d;
    d.t.resize(K);
    d.q.resize(K, n);
    d.tau.resize(K, n);
    if (use_vel) d.qd.resize(K, n);
    for (int k = 0; k < K; ++k) {
      const std::size_t i = sel[static_cast<std::size_t>(k)];
      const std::size_t s = keep[i];
      d.t[k] = tk[i];
      for (int j = 0; j < n; ++j) {
        const double sg = sign[static_cast<std::size_t>(j)];
        const std::size_t at = s * static_cast<std::size_t>(n) + static_cast<std::size_t>(j);
        d.q(k, j) = sg * qv[at];
        d.tau(k, j) = sg * tauv[at];
        if (use_vel) d.qd(k, j) = sg * qdv[at];
      }
    }
    // Resampling on request: linear interpolation of every signal onto a uniform grid.
    const double rs_hz = P_.getDouble("resample_hz");
    int resampled_from = 0;
    if (rs_hz > 0.0) {
      resampled_from = K;
      d = exid::resampleUniform(d, rs_hz, fmt::format("{}{}", pre, bagname));
    }
    if (with_wrench) {
      d.wrench.resize(d.size(), 6);
      std::size_t w = 0;
      for (Eigen::Index k = 0; k < d.size(); ++k) {
        const double t = d.t[k];
        while (w + 2 < tw.size() && tw[w + 1] <= t) ++w;
        if (tw.size() == 1) {  // a single wrench message: only a sample at its very time
          for (int c = 0; c < 6; ++c) d.wrench(k, c) = wr[0].v[c];
          continue;
        }
        const double len = tw[w + 1] - tw[w];
        exid::check(
            len <= ratio * wr_med,
            fmt::format("{}{}: wrench_topic '{}': a gap of {} s between messages {} and {} "
                        "(median step {} s) around the joint-state sample at t = {} s: the "
                        "wrench is not interpolated across it; cut the segment there "
                        "(t_start_s/t_end_s; max_gap_ratio = {})",
                        pre, bagname, w_topic, len, wr[w].msg, wr[w + 1].msg, wr_med, t, ratio));
        const double a = (t - tw[w]) / len;
        for (int c = 0; c < 6; ++c) d.wrench(k, c) = (1.0 - a) * wr[w].v[c] + a * wr[w + 1].v[c];
      }
    }

    d.source = bagname;
    exid::Json& m = d.meta;
    m["simulated"] = false;
    m["file"] = bagname;
    m["storage"] = bag.storage;
    {
      std::vector<std::string> files;
      for (const fs::path& f : bag.files) files.push_back(f.filename().string());
      m["storage_files"] = exid::Json(files);
    }
    m["joint_states_topic"] = js_topic;
    if (with_wrench) {
      m["wrench_topic"] = w_topic;
      m["wrench_matching"] =
          "linear interpolation at the joint-state times between the two wrench messages around "
          "each; joint-state samples outside the wrench's time range are cut "
          "(accounting.outside_wrench_range)";
    }
    m["time"] = header_time ? "header stamps" : "receive stamps";
    m["time_origin_ns"] = static_cast<long long>(t0);
    m["joint_names"] = exid::Json(names);
    m["samples"] = d.size();
    m["segment_s"] = exid::Json(std::vector<double>{ts, te});
    if (part != "none") m["split"] = seg.splitMeta(in_segment, in_part);
    m["recording_span_s"] = span;
    {
      // Timing of the segment's samples (as the csv experiment's meta.recording).
      std::vector<double> raw;
      std::vector<int> row;
      for (std::size_t i : sel) {
        raw.push_back(static_cast<double>(js[keep[i]].ns - t0));
        row.push_back(static_cast<int>(std::min<long long>(pos[i], 2000000000LL)));
      }
      exid::Json R = exid::Json::object();
      R["file"] = bagname;
      R["rows"] = static_cast<long long>(raw.size());
      exid::Json t = exid::samplingStats(raw, 1e-9, row, ratio);
      t["source"] = fmt::format("{} of topic '{}'",
                                header_time ? "header stamps" : "receive stamps", js_topic);
      R["timing"] = t;
      m["recording"] = R;
    }
    // Where the messages went: every one dropped or cut is counted.
    {
      exid::Json& a = m["accounting"];
      a["joint_state_messages"] = js_msgs;
      a["other_joints_messages"] = js_other;
      a["dropped_bad_messages"] = js_bad;
      a["dropped_repeated_stamps"] = js_dup;
      a["reordered_messages"] = js_reordered;
      a["outside_segment"] = static_cast<int>(keep.size()) - in_segment;
      if (part != "none") a["other_part_of_split"] = in_segment - in_part;
      if (with_wrench) {
        a["outside_wrench_range"] = outside_wrench;
        a["wrench_messages"] = wr_msgs;
        a["wrench_dropped_bad_messages"] = wr_bad;
        a["wrench_dropped_repeated_stamps"] = wr_dup;
      }
      a["segment_samples"] = K;
      if (resampled_from > 0) {
        a["resampled_from"] = resampled_from;
        a["resampled_to"] = d.size();
        a["resample_hz"] = rs_hz;
      }
      a["samples_used"] = d.size();
      exid::Json w = exid::Json::array();
      if (js_bad + js_dup > 0)
        w.push_back(exid::Json(fmt::format(
            "{}{}: {} of {} messages of topic '{}' dropped ({} bad, {} repeated stamps; "
            "drop_bad_messages)",
            pre, bagname, js_bad + js_dup, js_msgs, js_topic, js_bad, js_dup)));
      if (wr_bad + wr_dup > 0)
        w.push_back(exid::Json(fmt::format(
            "{}{}: {} of {} messages of topic '{}' dropped ({} bad, {} repeated stamps; "
            "drop_bad_messages)",
            pre, bagname, wr_bad + wr_dup, wr_msgs, w_topic, wr_bad, wr_dup)));
      if (outside_wrench > 0)
        w.push_back(exid::Json(
            fmt::format("{}{}: {} joint-state samples of the segment lie outside the time range of "
                        "wrench_topic '{}' and were cut",
                        pre, bagname, outside_wrench, w_topic)));
      if (bad_examples.size() > 0) a["dropped_examples"] = bad_examples;
      if (w.size() > 0) m["warnings"] = w;
    }
    std::vector<std::string> sig = {"q"};
    if (use_vel) sig.push_back("qd");
    sig.push_back("tau");
    if (with_wrench) sig.push_back("wrench");
    m["signals"] = exid::Json(sig);
    ctx.report(1.0, fmt::format("{} samples from {}", d.size(), bagname));
    return d;
  }

 private:
  exid::ParamSet P_;
};

}  // namespace

EXID_REGISTER_PLUGIN(Rosbag2Experiment)
