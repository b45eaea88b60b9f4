// Experiment `rosbag2` with several bags (`paths`): each bag read, segmented, split and filtered
// on its own, the bags the parts of one dataset (DatasetFacts::parts), and nothing downstream
// spanning two of them: the integral model's windows, filtered_ls's filters, trims and
// decimation, the inspection's derivatives; the estimators that simulate or shift along one
// recording refuse, naming the bags.

#include "exid/recording.hpp"
#include "rosbag2_test_util.hpp"

using namespace rbtest;

namespace {

// The recording as joint-state messages in the robot's order, joint 1 turned by q1_offset_rad
// (the PUMA 560's first axis is vertical: the torques stay those of the turned motion), stamps
// from `epoch`.
std::vector<Msg> stateMessages(double q1_offset_rad, std::int64_t epoch) {
  const Recording& r = recording();
  std::vector<Msg> out;
  for (int k = 0; k < r.d.size(); ++k) {
    std::vector<double> pos, eff;
    for (int j = 0; j < r.d.dof(); ++j) {
      pos.push_back(r.d.q(k, j) + (j == 0 ? q1_offset_rad : 0.0));
      eff.push_back(r.d.tau(k, j));
    }
    const std::int64_t ns = epoch + (r.ns[static_cast<std::size_t>(k)] - kEpoch);
    out.push_back({"/joint_states", ns + 1000000, jointState(ns, r.names, pos, {}, eff)});
  }
  return out;
}

struct TwoBags {
  fs::path first, second;
};

// Bag 1 (SQLite) the recording; bag 2 (MCAP, zstd) recorded an hour later, turned by 0.8 rad.
const TwoBags& twoBags() {
  static const TwoBags b = [] {
    TwoBags out;
    BagSpec s1;
    s1.storage = "sqlite3";
    s1.types = {{"/joint_states", "sensor_msgs/msg/JointState"}};
    s1.msgs = stateMessages(0.0, kEpoch);
    out.first = writeBag(tmpDir() / "part_one", s1);
    BagSpec s2 = s1;
    s2.storage = "mcap";
    s2.compression = "zstd";
    s2.msgs = stateMessages(0.8, kEpoch + 3600LL * 1000000000LL);
    out.second = writeBag(tmpDir() / "part_two", s2);
    return out;
  }();
  return b;
}

// The experiment with its own parameters (no `path`).
exid::Dataset readWith(const std::string& params) {
  auto e = exid_test::create<exid::Experiment>("rosbag2", "{" + params + "}");
  return e->run(mtest::robot("puma560"), nullptr, mtest::context());
}

std::string bothPaths() {
  return "paths: [" + twoBags().first.string() + ", " + twoBags().second.string() + "]";
}

std::string errorWith(const std::string& params) {
  try {
    readWith(params);
  } catch (const exid::Error& e) {
    return e.what();
  }
  return "(no error)";
}

// Every element of A within rel times B's largest of B (the parts' times are shifted: their
// differences round differently).
bool near(const Eigen::MatrixXd& A, const Eigen::MatrixXd& B, double rel) {
  return A.rows() == B.rows() && A.cols() == B.cols() &&
         (A - B).cwiseAbs().maxCoeff() <= rel * B.cwiseAbs().maxCoeff();
}

// Rows of b stacked under those of a.
exid::Rows stacked(const exid::Rows& a, const exid::Rows& b) {
  exid::Rows r = a;
  r.W.conservativeResize(a.W.rows() + b.W.rows(), Eigen::NoChange);
  r.W.bottomRows(b.W.rows()) = b.W;
  r.y.conservativeResize(a.y.size() + b.y.size());
  r.y.tail(b.y.size()) = b.y;
  return r;
}

}  // namespace

TEST(Rosbag2Parts, SeveralBagsAreThePartsOfOneDataset) {
  const std::string extra = "differentiate_cutoff_hz: 20";
  const exid::Dataset a = readBag(twoBags().first, extra);
  const exid::Dataset b = readBag(twoBags().second, extra);
  const exid::Dataset d = readWith(bothPaths() + ", " + extra);
  ASSERT_EQ(d.size(), a.size() + b.size());
  ASSERT_EQ(d.facts.parts.size(), 2u);
  EXPECT_EQ(d.facts.parts[0].source, a.source);
  EXPECT_EQ(d.facts.parts[1].source, b.source);
  // each part exactly its bag read alone (filtered and trimmed on its own)
  EXPECT_EQ(d.q.topRows(a.size()), a.q);
  EXPECT_EQ(d.q.bottomRows(b.size()), b.q);
  EXPECT_EQ(d.qdd.bottomRows(b.size()), b.qdd);
  EXPECT_EQ(d.tau.bottomRows(b.size()), b.tau);
  EXPECT_EQ(d.t.head(a.size()), a.t);
  // part 2 starts one time step after part 1 ends (each bag's times start at its first sample)
  const double step = a.t[1] - a.t[0];
  EXPECT_NEAR(d.t[a.size()] - d.t[a.size() - 1], step, 1e-9);
  EXPECT_DOUBLE_EQ(d.facts.parts[1].t_from_s, d.t[a.size()]);
  for (int k = 1; k < d.size(); ++k) ASSERT_GT(d.t[k], d.t[k - 1]);
  const exid::Json& parts = *d.meta.find("parts");
  ASSERT_EQ(parts.size(), 2u);
  EXPECT_NEAR(parts.at(1).find("time_shift_s")->asDouble(), d.t[a.size()] - b.t[0], 1e-12);
  EXPECT_EQ(parts.at(1).find("meta")->find("storage")->asString(), "mcap");
  EXPECT_EQ(d.meta.find("samples")->asInt(), d.size());
  // partRanges finds the two bags among the times, also of a slice
  const auto ranges = exid::partRanges(d.t, d.facts);
  ASSERT_EQ(ranges.size(), 2u);
  EXPECT_EQ(ranges[1].begin, a.size());
  EXPECT_EQ(ranges[1].part, 1);
  const exid::Dataset tail = exid::sliceDataset(d, a.size() + 10, d.size());
  ASSERT_EQ(exid::partRanges(tail.t, tail.facts).size(), 1u);
  EXPECT_EQ(exid::partRanges(tail.t, tail.facts)[0].part, 1);
  // one bag alone is one recording, as before
  EXPECT_TRUE(a.facts.parts.empty());
}

TEST(Rosbag2Parts, PathOrPathsAndTheirMistakes) {
  std::string e = errorWith("joint_states_topic: /joint_states");
  EXPECT_NE(e.find("no bag: give path (one bag) or paths (several)"), std::string::npos) << e;
  e = errorWith("path: " + twoBags().first.string() + ", " + bothPaths());
  EXPECT_NE(e.find("both path and paths are given"), std::string::npos) << e;
  e = errorWith("paths: [" + twoBags().first.string() + ", " + twoBags().first.string() + "]");
  EXPECT_NE(e.find("is given twice (entries 1 and 2)"), std::string::npos) << e;
  // the same signals in every part: a bag with velocities beside one without cannot be joined
  e = errorWith(bothPaths() + ", resample_hz: 100");
  EXPECT_EQ(e, "(no error)");  // each bag resampled on its own is fine
  exid::Dataset one = readBag(twoBags().first);
  exid::Dataset two = readBag(twoBags().second);
  two.qd = two.q;
  try {
    exid::joinParts({one, two}, "test");
    ADD_FAILURE() << "joined parts with different signals";
  } catch (const exid::Error& x) {
    EXPECT_NE(std::string(x.what()).find("part 2"), std::string::npos) << x.what();
    EXPECT_NE(std::string(x.what()).find("every part needs the same"), std::string::npos);
  }
  // a joined dataset is not resampled across its boundary
  const exid::Dataset d = readWith(bothPaths());
  try {
    exid::resampleUniform(d, 100.0, "test");
    ADD_FAILURE() << "resampled across two recordings";
  } catch (const exid::Error& x) {
    EXPECT_NE(std::string(x.what()).find("2 separate recordings"), std::string::npos) << x.what();
  }
}

// The integral model's windows and filtered_ls's filters, trims and decimation stay within each
// bag: the joined data's rows are exactly the two bags' rows, one after the other.
TEST(Rosbag2Parts, NoRowSpansTwoBags) {
  auto robot = mtest::robot("puma560");
  const std::string extra = "differentiate_cutoff_hz: 20";
  const exid::Dataset a = readBag(twoBags().first, extra);
  const exid::Dataset b = readBag(twoBags().second, extra);
  const exid::Dataset d = readWith(bothPaths() + ", " + extra);
  const exid::RunContext ctx = mtest::context();
  {
    auto m = mtest::model("integral", "{window_s: 0.5, window: long}", robot);
    const exid::Rows ra = m->rows(a, ctx), rb = m->rows(b, ctx), rd = m->rows(d, ctx);
    const exid::Rows ab = stacked(ra, rb);
    ASSERT_EQ(rd.W.rows(), ab.W.rows());
    EXPECT_TRUE(near(rd.W, ab.W, 1e-12));  // long windows: each part's from its first sample
    EXPECT_TRUE(near(rd.y, ab.y, 1e-12));
  }
  {
    auto m =
        mtest::model("differential", "{rotor_inertia: true, viscous: true, coulomb: true}", robot);
    auto est = exid_test::create<exid::Estimator>("filtered_ls", "{cutoff_hz: 8, decimation: 3}");
    const exid::Dataset ra = readBag(twoBags().first), rb = readBag(twoBags().second);
    const exid::Dataset rd = readWith(bothPaths());
    const exid::Rows fa = est->validationRows(*m, ra, ctx), fb = est->validationRows(*m, rb, ctx);
    const exid::Rows fd = est->validationRows(*m, rd, ctx);
    const exid::Rows ab = stacked(fa, fb);
    ASSERT_EQ(fd.W.rows(), ab.W.rows());
    EXPECT_TRUE(near(fd.W, ab.W, 1e-10));
    EXPECT_TRUE(near(fd.y, ab.y, 1e-10));
    // the estimate says it processed two recordings and counts both bags' trimmed edges
    const exid::Estimate e = est->estimate(*m, rd, nullptr, ctx);
    EXPECT_EQ(e.details.find("recordings")->asInt(), 2);
    EXPECT_EQ(e.details.find("trimmed_samples")->asInt(),
              4 * e.details.find("trimmed_samples_each_end")->asInt());
    // the trim warning counts every bag's ends: not below 10 % of the samples, above it said
    EXPECT_LT(e.details.find("trimmed_percent")->asDouble(), 10.0);
    EXPECT_EQ(e.details.find("warnings"), nullptr);
    auto wide =
        exid_test::create<exid::Estimator>("filtered_ls", "{cutoff_hz: 8, trim_edges: 150}");
    const exid::Estimate w = wide->estimate(*m, rd, nullptr, ctx);
    ASSERT_NE(w.details.find("warnings"), nullptr);
    const std::string text = w.details.find("warnings")->at(0).asString();
    EXPECT_NE(text.find("discards 600 of the " + std::to_string(rd.size())), std::string::npos)
        << text;
  }
}

// Every estimator that takes rows sample by sample identifies from the two bags through the
// study path; the ones that simulate or shift along one recording refuse, naming both bags.
TEST(Rosbag2Parts, EstimatorsOnSeveralBags) {
  auto study = [&](const std::string& estimator, const std::string& model) {
    const std::string text = "robot: {type: puma560}\nmodel: " + model +
                             "\nexperiment: {type: rosbag2, params: {" + bothPaths() +
                             ", differentiate_cutoff_hz: 20}}\nestimator: " + estimator + "\n";
    exid::StudyConfig cfg =
        exid::parseStudy(text, "parts_study.yaml", tmpDir(), exid_test::registry());
    return exid::runStudy(cfg, exid_test::registry(), exid::RunOptions());
  };
  const std::string differential =
      "{type: differential, params: {rotor_inertia: true, viscous: true, coulomb: true}}";
  for (const char* estimator : {"batch_ls", "wls", "consistent_ls", "rls", "filtered_ls"}) {
    SCOPED_TRACE(estimator);
    const exid::StudyResult r = study(fmt::format("{{type: {}}}", estimator), differential);
    ASSERT_TRUE(r.ok) << r.message;
    EXPECT_EQ(r.summary.find("experiment")->find("meta")->find("parts")->size(), 2u);
  }
  {
    const exid::StudyResult r =
        study("{type: batch_ls}", "{type: integral, params: {window_s: 0.05}}");
    ASSERT_TRUE(r.ok) << r.message;
  }
  const exid::Dataset d = readWith(bothPaths() + ", differentiate_cutoff_hz: 20");
  auto m = mtest::model("differential", "{}", mtest::robot("puma560"));
  for (const std::pair<std::string, std::string>& e :
       {std::pair<std::string, std::string>{"didim",
                                            "{loop: open, window_s: 0.2, output: position}"},
        {"iv", "{reference_file: " + csvOfRecording().string() +
                   ", kp_Nm_per_rad: [1, 1, 1, 1, 1, 1], kd_Nm_s_per_rad: [1, 1, 1, 1, 1, 1]}"},
        {"varpro", "{measurement_delay: true, measurement_delay_max_s: 0.02}"}}) {
    SCOPED_TRACE(e.first);
    auto est = exid_test::create<exid::Estimator>(e.first, e.second);
    try {
      est->estimate(*m, d, nullptr, mtest::context());
      ADD_FAILURE() << e.first << " estimated across two recordings";
    } catch (const exid::Error& x) {
      const std::string w = x.what();
      EXPECT_NE(w.find("the data is 2 separate recordings"), std::string::npos) << w;
      EXPECT_NE(w.find(twoBags().second.string()), std::string::npos) << w;
    }
  }
}

// The inspection derives velocities within each bag: bag 2's turn of 0.8 rad at the boundary
// is no velocity. It lists each bag with its timing and topics, in JSON and in text.
TEST(Rosbag2Parts, InspectionLooksAtEachBagOnItsOwn) {
  auto robot = mtest::robot("puma560");
  auto m = mtest::model("differential", "{}", robot);
  const exid::Dataset a = readBag(twoBags().first);
  const exid::Dataset d = readWith(bothPaths());
  const exid::RunContext ctx = mtest::context();
  const exid::Json ia = exid::inspectExperimentData(*robot, m.get(), a, ctx, "experiment");
  const exid::Json id = exid::inspectExperimentData(*robot, m.get(), d, ctx, "experiment");
  const double va = ia.find("joints")->at(0).find("velocity_max")->asDouble();
  const double vd = id.find("joints")->at(0).find("velocity_max")->asDouble();
  EXPECT_NEAR(vd, va, 1e-6 * va);  // a derivative across the boundary: 0.8 rad in 5 ms
  // clean data: no warning for one bag, none for two (the boundary is no gap, jump or jitter)
  EXPECT_EQ(ia.find("warnings")->size(), 0u) << ia.find("warnings")->dump();
  EXPECT_EQ(id.find("warnings")->size(), 0u) << id.find("warnings")->dump();
  const exid::Json& parts = *id.find("parts");
  ASSERT_EQ(parts.size(), 2u);
  EXPECT_EQ(parts.at(1).find("source")->asString(), d.facts.parts[1].source);
  EXPECT_TRUE(parts.at(1).find("recording") != nullptr);
  EXPECT_EQ(parts.at(1).find("topics")->size(), 1u);
  EXPECT_EQ(parts.at(0).find("accounting")->find("joint_state_messages")->asInt(), a.size());
  const std::string text = exid::inspectionText(id);
  EXPECT_NE(text.find("part 1: " + d.facts.parts[0].source), std::string::npos) << text;
  EXPECT_NE(text.find("part 2: " + d.facts.parts[1].source), std::string::npos) << text;
  EXPECT_NE(text.find("each recording on its own"), std::string::npos) << text;
}
