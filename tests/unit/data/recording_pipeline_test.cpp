// The filter steps of a recording (exid/recording.hpp): every sample a step drops is counted,
// the accounting adds up to the segment, a trim over 10 % of the segment is warned about and
// one below is not, and contradictory settings are refused before any data are read.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "exid/error.hpp"
#include "exid/recording.hpp"

namespace {

// A 2-joint segment of K samples at fs Hz: smooth positions, torques.
exid::Dataset segment(int K, double fs) {
  exid::Dataset d;
  d.t.resize(K);
  d.q.resize(K, 2);
  d.tau.resize(K, 2);
  for (int k = 0; k < K; ++k) {
    const double t = k / fs;
    d.t[k] = t;
    d.q(k, 0) = std::sin(2.0 * t);
    d.q(k, 1) = 0.5 * std::cos(3.0 * t);
    d.tau(k, 0) = 2.0 * std::sin(2.0 * t + 0.3);
    d.tau(k, 1) = std::cos(t);
  }
  d.source = "segment";
  return d;
}

std::int64_t get(const exid::Json& a, const char* key) { return a.find(key)->asInt(); }

TEST(RecordingPipeline, EveryDroppedSampleIsCounted) {
  exid::RecordingSteps s;
  s.resample_hz = 150.0;
  s.measurement_delay_s = 0.01;
  s.cutoff_hz = 10.0;
  s.filter_torque = true;
  s.decimation = 3;
  exid::RecordingPipeline p(s, "test");
  const exid::Dataset out = p.run(segment(1000, 200.0));
  const exid::RecordingStepsDone& done = p.done();
  EXPECT_EQ(done.segment_samples, 1000);
  EXPECT_EQ(done.resampled_from, 1000);
  EXPECT_EQ(done.resampled_to, 750);  // floor(4.995 s x 150 Hz) + 1
  EXPECT_GT(done.delay_front, 0);     // no positions 10 ms before the first sample
  EXPECT_EQ(done.grid_samples, done.resampled_to - done.delay_front - done.delay_back);
  EXPECT_EQ(done.trim, 30);  // ceil(2 x 150 / 10)
  EXPECT_EQ(out.size(), done.samples_used);
  EXPECT_EQ(out.qd.rows(), out.size());  // the filter's differences
  exid::Json a = exid::Json::object(), w = exid::Json::array();
  p.account(&a, &w);
  EXPECT_EQ(get(a, "trimmed_edges") + get(a, "decimated_away") + get(a, "samples_used"),
            done.grid_samples);
  EXPECT_EQ(get(a, "resampled_from"), 1000);
  EXPECT_EQ(w.size(), 0u);  // 60 of 740 samples trimmed: under 10 %
  exid::Json m = exid::Json::object();
  p.describe(&m);
  EXPECT_EQ(m.find("differentiated")->find("decimation")->asInt(), 3);
  EXPECT_EQ(m.find("measurement_delay")->find("dropped_samples_front")->asInt(), done.delay_front);
}

TEST(RecordingPipeline, ATrimOverATenthOfTheSegmentIsWarnedAbout) {
  exid::RecordingSteps s;
  s.cutoff_hz = 20.0;
  s.trim_edges = 30;  // 60 of 400 samples
  exid::RecordingPipeline p(s, "experiment 'x': rec.csv");
  (void)p.run(segment(400, 200.0));
  exid::Json a = exid::Json::object(), w = exid::Json::array();
  p.account(&a, &w);
  ASSERT_EQ(w.size(), 1u);
  EXPECT_NE(w.at(0).asString().find("experiment 'x': rec.csv: trim_edges = 30 discards 60"),
            std::string::npos)
      << w.at(0).asString();
  EXPECT_EQ(a.find("trim_rule"), nullptr);  // given, not the default
}

TEST(RecordingPipeline, NoStepLeavesTheSegmentAsItIs) {
  exid::RecordingPipeline p({}, "test");
  const exid::Dataset in = segment(50, 100.0);
  const exid::Dataset out = p.run(in);
  EXPECT_EQ(out.q, in.q);
  EXPECT_EQ(out.tau, in.tau);
  EXPECT_FALSE(out.hasVelocity());  // nothing differentiated without a cut-off
  exid::Json a = exid::Json::object(), w = exid::Json::array();
  p.account(&a, &w);
  EXPECT_EQ(get(a, "samples_used"), 50);
  EXPECT_EQ(get(a, "trimmed_edges"), 0);
  EXPECT_EQ(a.find("resampled_from"), nullptr);
  exid::Json m = exid::Json::object();
  p.describe(&m);
  EXPECT_EQ(m.find("differentiated"), nullptr);
  EXPECT_EQ(m.find("measurement_delay"), nullptr);
}

TEST(RecordingPipeline, ContradictorySettingsAreRefused) {
  exid::RecordingSteps s;
  s.decimation = 2;  // without the filter
  EXPECT_THROW(exid::RecordingPipeline(s, "test"), exid::Error);
  s.cutoff_hz = 10.0;  // with the filter, but the torque not filtered
  try {
    exid::RecordingPipeline p(s, "test");
    ADD_FAILURE() << "decimation without filter_torque was accepted";
  } catch (const exid::Error& e) {
    EXPECT_NE(std::string(e.what()).find("needs filter_torque"), std::string::npos) << e.what();
  }
  s.filter_torque = true;
  EXPECT_NO_THROW(exid::RecordingPipeline(s, "test"));
  exid::RecordingSteps nyq;
  nyq.cutoff_hz = 60.0;  // above the Nyquist frequency of 100 Hz data
  exid::RecordingPipeline p(nyq, "test");
  EXPECT_THROW(p.filter(segment(100, 100.0)), exid::Error);
}

}  // namespace
