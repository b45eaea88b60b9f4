// A dataset's facts (what an experiment tells the models and estimators, typed) travel with its
// samples: every slice, window, resampling and materialised stream keeps them, and summary.json
// shows them under experiment.meta with the keys it always had.
#include <gtest/gtest.h>

#include <memory>

#include "exid/data.hpp"
#include "exid/json.hpp"

namespace {

exid::Dataset fourSamples() {
  exid::Dataset d;
  d.t = Eigen::VectorXd::LinSpaced(4, 0.0, 0.3);
  d.q = Eigen::MatrixXd::Random(4, 2);
  d.tau = Eigen::MatrixXd::Random(4, 2);
  d.source = "four samples";
  exid::PlantTruth p;
  p.drive_terms = false;
  p.payload.mass_kg = 1.5;
  p.payload.com_m = Eigen::Vector3d(0.0, 0.0, 0.1);
  p.recorded_torque_gain = {0.9};
  d.facts.simulated = p;
  d.facts.payload_part_from_t_s = 0.2;
  return d;
}

void expectSameFacts(const exid::Dataset& d, const char* how) {
  ASSERT_TRUE(d.facts.simulated) << how;
  EXPECT_FALSE(d.facts.simulated->drive_terms) << how;
  EXPECT_EQ(d.facts.simulated->payload.mass_kg, 1.5) << how;
  EXPECT_EQ(d.facts.simulated->recorded_torque_gain, std::vector<double>{0.9}) << how;
  ASSERT_TRUE(d.facts.payload_part_from_t_s) << how;
  EXPECT_EQ(*d.facts.payload_part_from_t_s, 0.2) << how;
}

TEST(DatasetFacts, TravelWithEverySliceWindowAndResampling) {
  const exid::Dataset d = fourSamples();
  expectSameFacts(exid::sliceDataset(d, 1, 3), "sliceDataset");
  expectSameFacts(exid::resampleUniform(d, 20.0, "test"), "resampleUniform");
  expectSameFacts(exid::materialize(d), "materialize");
  exid::SampleWindow w(d);
  expectSameFacts(w.span(0, 2), "SampleWindow");
}

TEST(DatasetFacts, RecordedDataAreNotSimulated) {
  const exid::Dataset d;  // as csv and rosbag2 leave them
  EXPECT_FALSE(d.facts.simulated);
  EXPECT_FALSE(d.facts.payload_part_from_t_s);
  exid::Json meta = exid::Json::object();
  exid::describeFacts(d.facts, &meta);
  ASSERT_TRUE(meta.find("simulated"));
  EXPECT_FALSE(meta.find("simulated")->asBool());
  EXPECT_EQ(meta.find("payload"), nullptr);
  EXPECT_EQ(meta.find("payload_part_from_t_s"), nullptr);
}

TEST(DatasetFacts, SummaryMetaShowsThemUnderTheirKeys) {
  const exid::Dataset d = fourSamples();
  exid::Json meta = exid::Json::object();
  exid::describeFacts(d.facts, &meta);
  EXPECT_TRUE(meta.find("simulated")->asBool());
  EXPECT_FALSE(meta.find("drive_terms")->asBool());
  EXPECT_EQ(meta.find("payload")->find("mass_kg")->asDouble(), 1.5);
  EXPECT_EQ(meta.find("payload")->find("com_m")->at(2).asDouble(), 0.1);
  EXPECT_EQ(meta.find("payload")->find("inertia_com_kg_m2")->size(), 6u);
  EXPECT_EQ(meta.find("recorded_torque_gain")->at(0).asDouble(), 0.9);
  EXPECT_EQ(meta.find("drive_torque_gain"), nullptr);  // none given: no key
  EXPECT_EQ(meta.find("payload_part_from_t_s")->asDouble(), 0.2);
}

}  // namespace
