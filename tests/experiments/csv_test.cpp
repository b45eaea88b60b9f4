// Experiment `csv`: reads back exactly what the runner writes (exid::datasetTable), and bad
// files give clear errors naming the file, the line and the column.
#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <thread>
#include <vector>

#include "../models/model_test_util.hpp"
#include "exid/io.hpp"
#include "exid/runner.hpp"

namespace {

namespace fs = std::filesystem;

fs::path tmpDir() {
  fs::path p = fs::temp_directory_path() / ("exid_csv_test_" + std::to_string(::getpid()));
  fs::create_directories(p);
  return p;
}

fs::path writeText(const std::string& name, const std::string& text) {
  const fs::path p = tmpDir() / name;
  std::ofstream(p) << text;
  return p;
}

exid::Dataset readCsv(const fs::path& file, const std::string& extra = "",
                      std::shared_ptr<const exid::RobotModel> r = nullptr) {
  if (!r) r = mtest::robot("puma560");
  auto e = exid_test::create<exid::Experiment>(
      "csv", "{file: " + file.string() + (extra.empty() ? "" : ", " + extra) + "}");
  return e->run(r, nullptr, mtest::context());
}

std::string errorOf(const fs::path& file, const std::string& extra = "") {
  try {
    readCsv(file, extra);
  } catch (const exid::Error& e) {
    return e.what();
  }
  return "(no error)";
}

// Six joints, header of a two-joint-short file etc.
std::string header(int n, bool t = true) {
  std::string h = t ? "t" : "";
  for (const char* p : {"q", "tau"})
    for (int j = 1; j <= n; ++j) h += (h.empty() ? "" : ",") + std::string(p) + std::to_string(j);
  return h + "\n";
}
std::string row(double t, int n, double v, bool with_t = true) {
  std::string s = with_t ? std::to_string(t) : "";
  for (int c = 0; c < 2 * n; ++c) s += (s.empty() ? "" : ",") + std::to_string(v + 0.01 * c);
  return s + "\n";
}

TEST(Csv, ReadsBackWhatTheRunnerWritesExactly) {
  auto r = mtest::robot("puma560");
  const exid::Dataset d = mtest::simulate(
      r,
      "{duration_s: 1, wrench: true, payload_mass_kg: 1.5, noise_q_rad: 1e-3, noise_tau_Nm: 0.1}");
  const fs::path f = tmpDir() / "experiment.csv";
  exid::writeCsvAtomic(f, exid::datasetTable(d));
  const exid::Dataset b = readCsv(f);
  ASSERT_EQ(b.size(), d.size());
  EXPECT_EQ(b.t, d.t);
  EXPECT_EQ(b.q, d.q);
  EXPECT_EQ(b.qd, d.qd);
  EXPECT_EQ(b.qdd, d.qdd);
  EXPECT_EQ(b.tau, d.tau);
  EXPECT_EQ(b.wrench, d.wrench);
  EXPECT_EQ(b.source, f.string());
}

TEST(Csv, AbsentSignalsStayAbsent) {
  auto r = mtest::robot("puma560");
  const exid::Dataset d = mtest::simulate(r, "{duration_s: 0.5, output_qd_qdd: false}");
  const fs::path f = tmpDir() / "q_tau_only.csv";
  exid::writeCsvAtomic(f, exid::datasetTable(d));
  const exid::Dataset b = readCsv(f);
  EXPECT_FALSE(b.hasVelocity());
  EXPECT_FALSE(b.hasAcceleration());
  EXPECT_FALSE(b.hasWrench());
  EXPECT_EQ(b.tau, d.tau);
}

TEST(Csv, SegmentSignOffsetAndNoTimeColumn) {
  std::string text = header(6, false);
  for (int k = 0; k < 10; ++k) text += row(0, 6, k, false);
  const fs::path f = writeText("no_t.csv", text);
  const exid::Dataset d = readCsv(f,
                                  "sample_period_s: 0.1, t_start_s: 0.2, t_end_s: 0.5, "
                                  "sign: [1, -1, 1, 1, 1, 1], offset_rad: [0, 0.5, 0, 0, 0, 0]");
  ASSERT_EQ(d.size(), 4);  // t = 0.2, 0.3, 0.4, 0.5
  EXPECT_NEAR(d.t[0], 0.2, 1e-12);
  EXPECT_NEAR(d.q(0, 0), 2.0, 1e-12);
  EXPECT_NEAR(d.q(0, 1), -2.01 + 0.5, 1e-12);
  EXPECT_NEAR(d.tau(0, 1), -(2.0 + 0.07), 1e-12);
}

TEST(Csv, TorqueFromCurrents) {
  std::string text = "t,q1,q2,q3,q4,q5,q6,i1,i2,i3,i4,i5,i6\n";
  text += "0,0,0,0,0,0,0,1,2,3,4,5,6\n0.01,0,0,0,0,0,0,1,1,1,1,1,1\n";
  const fs::path f = writeText("currents.csv", text);
  const exid::Dataset d =
      readCsv(f, "torque_from: current, torque_constants_Nm_per_A: [10, 20, 30, 40, 50, 60]");
  EXPECT_NEAR(d.tau(0, 2), 90.0, 1e-12);
  EXPECT_NEAR(d.tau(1, 5), 60.0, 1e-12);
  EXPECT_NE(errorOf(f, "torque_from: current").find("torque_constants_Nm_per_A: expected 6"),
            std::string::npos);
}

TEST(Csv, UnsortedTimeNamesTheLine) {
  std::string text = "# a comment line\n" + header(6);
  text += row(0.0, 6, 1) + row(0.01, 6, 1) + row(0.005, 6, 1);
  const fs::path f = writeText("unsorted.csv", text);
  const std::string e = errorOf(f);
  std::printf("%s\n", e.c_str());
  EXPECT_NE(e.find(f.string()), std::string::npos) << e;
  EXPECT_NE(e.find("line 5"), std::string::npos) << e;
  EXPECT_NE(e.find("strictly increase"), std::string::npos) << e;
}

TEST(Csv, NanIsAnErrorOrDropped) {
  std::string text = header(6) + row(0.0, 6, 1) + row(0.01, 6, 1);
  text += "0.02,1,2,3,nan,5,6,1,2,3,4,5,6\n";
  text += "0.03,1,2,3,4,5,6,1,2,3,4,,6\n";
  text += row(0.04, 6, 1);
  const fs::path f = writeText("nan.csv", text);
  const std::string e = errorOf(f);
  std::printf("%s\n", e.c_str());
  EXPECT_NE(e.find("line 4"), std::string::npos) << e;
  EXPECT_NE(e.find("'q4'"), std::string::npos) << e;
  EXPECT_NE(e.find("drop_bad_rows"), std::string::npos) << e;
  const exid::Dataset d = readCsv(f, "drop_bad_rows: true");
  EXPECT_EQ(d.size(), 3);
  EXPECT_EQ(d.meta.find("dropped_rows")->asInt(), 2);
}

TEST(Csv, MissingColumnAndWrongJointCount) {
  std::string text = "t,q1,q2,q3,q4,q5,tau1,tau2,tau3,tau4,tau5\n0,1,2,3,4,5,1,2,3,4,5\n";
  const fs::path five = writeText("five.csv", text);
  std::string e = errorOf(five);
  std::printf("%s\n", e.c_str());
  EXPECT_NE(e.find(five.string()), std::string::npos) << e;
  EXPECT_NE(e.find("wrong joint count"), std::string::npos) << e;
  EXPECT_NE(e.find("expected q1..q6"), std::string::npos) << e;

  const fs::path noq = writeText("noq.csv", "t,tau1,tau2,tau3,tau4,tau5,tau6\n0,1,2,3,4,5,6\n");
  e = errorOf(noq);
  std::printf("%s\n", e.c_str());
  EXPECT_NE(e.find("missing column 'q1'"), std::string::npos) << e;

  const fs::path partw =
      writeText("partial_wrench.csv", "t,q1,q2,q3,q4,q5,q6,fx,fy,fz\n0,1,2,3,4,5,6,1,2,3\n");
  e = errorOf(partw);
  std::printf("%s\n", e.c_str());
  EXPECT_NE(e.find("mx, my, mz"), std::string::npos) << e;

  const fs::path ragged = writeText("ragged.csv", header(6) + "0,1,2\n");
  e = errorOf(ragged);
  std::printf("%s\n", e.c_str());
  EXPECT_NE(e.find(":2:"), std::string::npos) << e;
}

TEST(Csv, MissingFile) {
  const std::string e = errorOf(tmpDir() / "does_not_exist.csv");
  EXPECT_NE(e.find("cannot open"), std::string::npos) << e;
}

}  // namespace

namespace {

// A 6-joint file: t (in the given unit, or none), q and tau columns, `rows` rows at `period_s`.
fs::path uniformFile(const std::string& name, int rows, double period_s, bool with_t = true,
                     double t_factor = 1.0) {
  std::string s = header(6, with_t);
  for (int k = 0; k < rows; ++k) {
    const double t = k * period_s;
    std::string line = with_t ? fmt::format("{}", t * t_factor) : "";
    for (int j = 0; j < 6; ++j)
      line += (line.empty() ? "" : ",") + fmt::format("{}", 0.3 * std::sin(1.3 * t + j));
    for (int j = 0; j < 6; ++j) line += "," + fmt::format("{}", 2.0 * std::cos(0.7 * t + j) + j);
    s += line + "\n";
  }
  return writeText(name, s);
}

}  // namespace

TEST(CsvSignals, NoTimeColumnAndNoSamplePeriodIsAnErrorNamingBothWaysOut) {
  const fs::path f = uniformFile("no_t.csv", 50, 0.005, false);
  const std::string m = errorOf(f);
  for (const char* what :
       {"no time column 't'", "sample_period_s", "time_column", "does not guess"})
    EXPECT_NE(m.find(what), std::string::npos) << what << ": " << m;
  // with the period: t = row * period, exactly the file's rate (200 Hz here, not an assumed 100)
  const exid::Dataset d = readCsv(f, "sample_period_s: 0.005");
  EXPECT_DOUBLE_EQ(d.t[49], 49 * 0.005);
  EXPECT_EQ(d.meta.find("sample_period_s")->asDouble(), 0.005);
}

TEST(CsvSignals, TimeColumnByNameWithItsUnit) {
  // time in milliseconds in a column named 'stamp'
  std::string text = uniformFile("ms.csv", 40, 0.01, true, 1e3).string();
  std::ifstream in(text);
  std::string body((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  body.replace(0, 1, "stamp");
  const fs::path f = writeText("ms_named.csv", body);
  const exid::Dataset d = readCsv(f, "time_column: stamp, time_unit: ms");
  EXPECT_NEAR(d.t[10] - d.t[0], 0.1, 1e-12);
  EXPECT_EQ(d.meta.find("time_column")->asString(), "stamp");
  EXPECT_NE(errorOf(f).find("no time column 't'"), std::string::npos);
}

TEST(CsvSignals, TorqueScaleFlipsTheTorqueAloneAndQScaleConvertsUnits) {
  const fs::path f = uniformFile("scale.csv", 30, 0.01);
  const exid::Dataset a = readCsv(f);
  const exid::Dataset b =
      readCsv(f, "tau_scale: [-1, 1, 1, -1, 1, 2], q_scale: [0.0174532925, 1, 1, 1, 1, 1]");
  EXPECT_EQ(b.q.col(1), a.q.col(1));
  EXPECT_NEAR((b.q.col(0) - 0.0174532925 * a.q.col(0)).cwiseAbs().maxCoeff(), 0.0, 1e-15);
  EXPECT_EQ(b.tau.col(0), -a.tau.col(0));
  EXPECT_EQ(b.tau.col(3), -a.tau.col(3));
  EXPECT_EQ(b.tau.col(5), 2.0 * a.tau.col(5));
  EXPECT_EQ(b.tau.col(1), a.tau.col(1));
  EXPECT_NE(errorOf(f, "tau_scale: [1, 1]").find("tau_scale: expected 6 values"),
            std::string::npos);
  EXPECT_NE(errorOf(f, "tau_scale: [1, 1, 0, 1, 1, 1]").find("not a usable scale"),
            std::string::npos);
}

TEST(CsvSignals, ASegmentOutsideTheRecordingIsAnErrorNeverClamped) {
  const fs::path f = uniformFile("seg.csv", 101, 0.01);  // 0 .. 1 s
  EXPECT_EQ(readCsv(f, "t_end_s: 1.0").size(), 101);
  const std::string m = errorOf(f, "t_start_s: 0.5, t_end_s: 1.2");
  EXPECT_NE(m.find("t_end_s = 1.2 s is past the end of the recording"), std::string::npos) << m;
  EXPECT_NE(errorOf(f, "t_start_s: 1.5").find("after the end of the recording"), std::string::npos);
}

TEST(CsvSignals, GapsAndUnevenStampsAreRefusedNamingTheLine) {
  std::string s = header(6);
  for (int k = 0; k < 40; ++k) s += row(k < 20 ? 0.01 * k : 0.01 * k + 3.6, 6, 0.1);
  const std::string m = errorOf(writeText("gap.csv", s));
  EXPECT_NE(m.find("line 22 (data row 21)"), std::string::npos) << m;
  EXPECT_NE(m.find("a gap"), std::string::npos) << m;
  std::string u = header(6);
  for (int k = 0; k < 40; ++k) u += row(0.01 * k + (k == 10 ? 0.004 : 0.0), 6, 0.1);
  EXPECT_NE(errorOf(writeText("uneven.csv", u)).find("uneven time stamps"), std::string::npos);
}

TEST(CsvSignals, TrimmedSamplesAreCountedAndTheDefaultKeepsAShortSegment) {
  // 100 Hz, cut-off 2 Hz: the transient rule gives exactly 2 fs / fc = 100 samples at each end
  // (not 101 from a rate estimated a hair above 100 Hz); a 1000-sample segment caps the default
  // at 5 % of it at each end, so at most 10 % is discarded, and says so.
  const fs::path f = uniformFile("trim.csv", 1000, 0.01);
  const exid::Dataset d = readCsv(f, "differentiate_cutoff_hz: 2");
  const exid::Json& a = *d.meta.find("accounting");
  EXPECT_EQ(a.find("segment_samples")->asInt(), 1000);
  EXPECT_EQ(a.find("trimmed_edges")->asInt(), 100);
  EXPECT_EQ(a.find("samples_used")->asInt(), 900);
  EXPECT_NE(a.find("trim_rule")->asString().find("ceil(2 fs / fc) = 100 samples capped at 5 %"),
            std::string::npos)
      << a.find("trim_rule")->asString();
  EXPECT_EQ(d.meta.find("warnings"), nullptr);
  // a long segment: the transient rule itself, 100 at each end
  const exid::Dataset l =
      readCsv(uniformFile("trim_long.csv", 4000, 0.01), "differentiate_cutoff_hz: 2");
  EXPECT_EQ(l.meta.find("accounting")->find("trimmed_edges")->asInt(), 200);
  // an explicit trim discarding more than 10 % is a warning with the figures
  const exid::Dataset w = readCsv(f, "differentiate_cutoff_hz: 2, trim_edges: 80");
  ASSERT_NE(w.meta.find("warnings"), nullptr);
  EXPECT_NE(w.meta.find("warnings")
                ->at(0)
                .asString()
                .find("discards 160 of the segment's 1000 "
                      "samples (16.0 %"),
            std::string::npos)
      << w.meta.find("warnings")->at(0).asString();
}

TEST(CsvSignals, SplitPartsNeverShareASampleNorAFilterEdge) {
  const fs::path f = uniformFile("split.csv", 1000, 0.01);  // t = 0 .. 9.99 s
  const std::string filt = "differentiate_cutoff_hz: 4, filter_torque: true";
  const exid::Dataset a = readCsv(f, filt + ", split_part: identification, split_fraction: 0.65");
  const exid::Dataset b = readCsv(f, filt + ", split_part: validation, split_fraction: 0.65");
  const double cut = 0.65 * 9.99;
  EXPECT_LT(a.t[a.size() - 1], cut);
  EXPECT_GE(b.t[0], cut);
  const exid::Json& sa = *a.meta.find("split");
  EXPECT_EQ(sa.find("part")->asString(), "identification");
  EXPECT_DOUBLE_EQ(sa.find("split_at_s")->asDouble(), cut);
  EXPECT_EQ(sa.find("part_samples")->asInt(), 650);  // before the trim of its own edges
  EXPECT_EQ(b.meta.find("split")->find("part_samples")->asInt(), 350);
  EXPECT_EQ(a.meta.find("accounting")->find("other_part_of_split")->asInt(), 350);
  // The validation part's samples never reach the identification part through the filter:
  // change every sample after the split point and the identification data stay bit for bit.
  std::ifstream in(f);
  std::string line, text;
  int k = 0;
  while (std::getline(in, line)) {
    if (k > 0 && (k - 1) * 0.01 >= cut) {
      auto c = line.find(',');
      line = line.substr(0, c + 1) + "5" + line.substr(c + 2);  // q1's first digit replaced
    }
    text += line + "\n";
    ++k;
  }
  const fs::path g = writeText("split_changed.csv", text);
  const exid::Dataset a2 = readCsv(g, filt + ", split_part: identification, split_fraction: 0.65");
  EXPECT_EQ(a2.q, a.q);
  EXPECT_EQ(a2.qd, a.qd);
  EXPECT_EQ(a2.tau, a.tau);
  EXPECT_NE(readCsv(g, filt + ", split_part: validation, split_fraction: 0.65").q, b.q);
  // by time, and the errors
  EXPECT_EQ(readCsv(f, "split_part: validation, split_at_s: 4").size(), 600);
  EXPECT_NE(errorOf(f, "split_part: validation").find("exactly one of split_fraction"),
            std::string::npos);
  EXPECT_NE(errorOf(f, "split_part: validation, split_at_s: 12").find("not inside the segment"),
            std::string::npos);
  EXPECT_NE(errorOf(f, "split_fraction: 0.5").find("need split_part"), std::string::npos);
}

TEST(CsvSignals, ATextColumnNobodyUsesIsIgnoredAUsedOneIsAnError) {
  std::string s = "t,label," + header(6, false);
  for (int k = 0; k < 30; ++k)
    s += fmt::format("{},{},", 0.01 * k, k % 2 ? "run" : "hold") + row(0, 6, 0.1 * k, false);
  const fs::path f = writeText("labels.csv", s);
  EXPECT_EQ(readCsv(f).size(), 30);
  std::string bad = header(6);
  for (int k = 0; k < 30; ++k) bad += row(0.01 * k, 6, 0.1);
  bad.replace(bad.find("\n", bad.find("\n") + 1) + 1 + 9, 1, "x");  // a letter in row 2
  const std::string m = errorOf(writeText("text_in_q.csv", bad));
  EXPECT_NE(m.find("is not a number"), std::string::npos) << m;
  EXPECT_NE(m.find(":3:"), std::string::npos) << m;  // its line
}

TEST(CsvSignals, UnevenStampsAreResampledWhenAskedAndAGapStaysAnError) {
  // 200 rows at a nominal 100 Hz with a logger's jitter of +-30 % (refused by default).
  std::string s = header(6);
  for (int k = 0; k < 200; ++k) {
    const double t = 0.01 * k + (k % 2 ? 0.003 : 0.0);
    std::string line = fmt::format("{}", t);
    for (int j = 0; j < 6; ++j) line += fmt::format(",{}", 2.0 * t + j);  // q linear in t
    for (int j = 0; j < 6; ++j) line += fmt::format(",{}", -t);
    s += line + "\n";
  }
  const fs::path f = writeText("jitter.csv", s);
  EXPECT_NE(errorOf(f).find("resample_hz"), std::string::npos) << errorOf(f);
  const exid::Dataset d = readCsv(f, "resample_hz: 100");
  ASSERT_EQ(d.size(), 200);  // 0 .. 1.99 s at 100 Hz
  EXPECT_NEAR(d.t[57] - d.t[0], 0.57, 1e-12);
  // a signal linear in t is interpolated exactly
  for (int k = 0; k < d.size(); ++k) EXPECT_NEAR(d.q(k, 3), 2.0 * d.t[k] + 3, 1e-12);
  EXPECT_EQ(d.meta.find("accounting")->find("resampled_from")->asInt(), 200);
  EXPECT_EQ(d.meta.find("accounting")->find("resampled_to")->asInt(), 200);
  // a gap is never bridged
  std::string g = header(6);
  for (int k = 0; k < 40; ++k) g += row(k < 20 ? 0.01 * k : 0.01 * k + 3.6, 6, 0.1);
  EXPECT_NE(errorOf(writeText("gap2.csv", g), "resample_hz: 100").find("a gap"), std::string::npos);
}

TEST(CsvSignals, WrenchScaleActsOnTheWrenchAlone) {
  auto r = mtest::robot("puma560");
  const exid::Dataset d = mtest::simulate(r, "{duration_s: 0.5, wrench: true, payload_mass_kg: 1}");
  const fs::path f = tmpDir() / "wrench.csv";
  exid::writeCsvAtomic(f, exid::datasetTable(d));
  const exid::Dataset b = readCsv(f, "wrench_scale: [-1, 1, 1, 1, 1, 1000]");
  EXPECT_EQ(b.wrench.col(0), -d.wrench.col(0));
  EXPECT_EQ(b.wrench.col(5), 1000.0 * d.wrench.col(5));
  EXPECT_EQ(b.wrench.col(2), d.wrench.col(2));
  EXPECT_EQ(b.tau, d.tau);
  EXPECT_NE(errorOf(f, "wrench_scale: [1, 1]").find("expected 6 values"), std::string::npos);
}

TEST(CsvSignals, AResampleRateGivingAbsurdlyManySamplesIsRefused) {
  const fs::path f = uniformFile("resample_huge.csv", 50, 0.01);
  EXPECT_NE(errorOf(f, "resample_hz: 1e300").find("resample_hz = 1e+300 gives"), std::string::npos)
      << errorOf(f, "resample_hz: 1e300");
}

// ---- a recording streamed from its file (Experiment::stream)

TEST(CsvStream, WindowsOverAStreamGiveTheSamplesAndStatisticsOfTheWholeRead) {
  const fs::path f = uniformFile("stream.csv", 1000, 0.01);
  const std::string extra = "t_start_s: 0.5, t_end_s: 8";
  const exid::Dataset whole = readCsv(f, extra);
  auto e = exid_test::create<exid::Experiment>("csv", "{file: " + f.string() + ", " + extra + "}");
  const exid::Dataset s = e->stream(mtest::robot("puma560"), nullptr, mtest::context());
  ASSERT_TRUE(s.streamed());
  ASSERT_EQ(s.size(), whole.size());
  EXPECT_EQ(s.tFirst(), whole.t(0));
  EXPECT_EQ(s.tLast(), whole.t(whole.size() - 1));
  EXPECT_TRUE(s.hasTorque());
  EXPECT_FALSE(s.hasVelocity());
  EXPECT_FALSE(s.stream->passed());
  // overlapping windows, in order, as chunks with context ask for them
  exid::SampleWindow w(s);
  for (int b = 0; b < s.size(); b += 97) {
    const int lo = std::max(0, b - 13), hi = std::min(s.size(), b + 97 + 13);
    const exid::Dataset x = w.span(lo, hi);
    ASSERT_EQ(x.size(), hi - lo);
    EXPECT_EQ(x.t, whole.t.segment(lo, hi - lo));
    EXPECT_EQ(x.q, whole.q.middleRows(lo, hi - lo));
    EXPECT_EQ(x.tau, whole.tau.middleRows(lo, hi - lo));
  }
  EXPECT_TRUE(s.stream->passed());
  EXPECT_EQ(s.stream->meta().dump(), whole.meta.dump());
  EXPECT_NE(whole.meta.find("recording")->find("saturation"), nullptr);
  // behind the window is an error, never a wrong span
  EXPECT_THROW(w.span(0, 5), exid::Error);
  // another pass reads the same samples
  const exid::Dataset m = exid::materialize(s);
  EXPECT_EQ(m.t, whole.t);
  EXPECT_EQ(m.q, whole.q);
  EXPECT_EQ(m.tau, whole.tau);
}

// A pass in pieces (fetch in order, decode on any thread in any order, settle in order): the
// samples, the statistics and the collected samples of the whole read, whatever the pieces'
// sizes; comment and blank lines, dropped rows at pieces' edges, a segment, held rows (the
// statistics) and a bad value named by its file line.
TEST(CsvStream, PiecesDecodedOnThreadsGiveTheSamplesAndStatisticsOfTheWholeRead) {
  std::string text = "# a recording\n" + header(6);
  for (int k = 0; k < 700; ++k) {
    const double t = 0.01 * k;
    if (k % 97 == 5) text += "\n# note\n";
    std::string line = fmt::format("{}", t);
    // held positions for rows 300-305 (a frozen run)
    const double tq = (k >= 300 && k <= 305) ? 0.01 * 300 : t;
    for (int j = 0; j < 6; ++j) line += "," + fmt::format("{}", 0.3 * std::sin(1.3 * tq + j));
    for (int j = 0; j < 6; ++j)
      line += "," + (k % 61 == 7 && j == 2 ? std::string("nan")
                                           : fmt::format("{}", 2.0 * std::cos(0.7 * t + j)));
    text += line + "\n";
  }
  const fs::path f = writeText("pieces.csv", text);
  const std::string extra = "drop_bad_rows: true, t_start_s: 0.3";
  const exid::Dataset whole = readCsv(f, extra);
  ASSERT_GT(whole.size(), 600);
  for (int piece : {1, 7, 64, 5000}) {
    auto e =
        exid_test::create<exid::Experiment>("csv", "{file: " + f.string() + ", " + extra + "}");
    const exid::Dataset s = e->stream(mtest::robot("puma560"), nullptr, mtest::context());
    exid::DatasetStream& st = *s.stream;
    st.collectEvery(10);
    st.rewind();
    std::vector<std::unique_ptr<exid::DatasetStream::Piece>> pieces;
    for (int got = 0; got < s.size();) {
      pieces.push_back(st.fetch(piece));
      ASSERT_NE(pieces.back(), nullptr);
      ASSERT_GT(pieces.back()->count, 0);
      got += pieces.back()->count;
    }
    EXPECT_EQ(st.fetch(piece)->count, 0);
    // decoded on threads, the last pieces first
    std::vector<exid::Dataset> chunk(pieces.size());
    std::vector<std::thread> pool;
    for (int th = 0; th < 3; ++th)
      pool.emplace_back([&, th] {
        for (std::size_t i = pieces.size(); i-- > 0;)
          if (static_cast<int>(i % 3) == th) st.decode(*pieces[i], &chunk[i]);
      });
    for (auto& t : pool) t.join();
    EXPECT_FALSE(st.passed());
    int b = 0;
    for (std::size_t i = 0; i < pieces.size(); ++i) {
      const int n = chunk[i].size();
      ASSERT_EQ(n, pieces[i]->count);
      EXPECT_EQ(chunk[i].t, whole.t.segment(b, n)) << piece << " " << i;
      EXPECT_EQ(chunk[i].q, whole.q.middleRows(b, n));
      EXPECT_EQ(chunk[i].tau, whole.tau.middleRows(b, n));
      st.settle(*pieces[i], chunk[i]);
      b += n;
    }
    EXPECT_EQ(b, whole.size());
    EXPECT_TRUE(st.passed());
    EXPECT_EQ(st.meta().dump(), whole.meta.dump()) << piece;
    EXPECT_EQ(st.collected().t.size(), (whole.size() + 9) / 10);
    EXPECT_EQ(st.collected().t(3), whole.t(30));
  }
  EXPECT_EQ(whole.meta.find("recording")->find("frozen_rows")->find("rows")->asInt(), 5);
  EXPECT_GT(whole.meta.find("dropped_rows")->asInt(), 5);
  // a bad value (drop_bad_rows off) found by a decode names its file line
  auto e = exid_test::create<exid::Experiment>("csv", "{file: " + f.string() + "}");
  const exid::Dataset s = e->stream(mtest::robot("puma560"), nullptr, mtest::context());
  s.stream->rewind();
  auto p = s.stream->fetch(s.size());
  exid::Dataset d;
  try {
    s.stream->decode(*p, &d);
    ADD_FAILURE() << "no error";
  } catch (const exid::Error& err) {
    // data row 8 (k = 7) is file line 12: the comment, the header, the blank line and the note
    const std::string m = err.what();
    EXPECT_NE(m.find("line 12 (data row 8)"), std::string::npos) << m;
    EXPECT_NE(m.find("tau3"), std::string::npos) << m;
  }
}

TEST(CsvStream, ABadValueFoundWhileStreamingNamesItsLineAndDroppedRowsAreSkippedAlike) {
  std::string s = header(6);
  for (int k = 0; k < 300; ++k) s += row(0.01 * k, 6, 0.1 * std::sin(0.05 * k));
  const std::string good = s;
  // data row 200 (file line 201) loses its q3
  std::string bad;
  {
    std::istringstream in(good);
    std::string line;
    int l = 0;
    while (std::getline(in, line)) {
      if (++l == 202) {
        std::vector<std::string> cells;
        std::stringstream ls(line);
        std::string c;
        while (std::getline(ls, c, ',')) cells.push_back(c);
        cells[3] = "";
        line.clear();
        for (std::size_t i = 0; i < cells.size(); ++i) line += (i ? "," : "") + cells[i];
      }
      bad += line + "\n";
    }
  }
  const fs::path f = writeText("stream_bad.csv", bad);
  auto e = exid_test::create<exid::Experiment>("csv", "{file: " + f.string() + "}");
  const exid::Dataset d = e->stream(mtest::robot("puma560"), nullptr, mtest::context());
  ASSERT_TRUE(d.streamed());  // the scan reads the time stamps alone
  try {
    exid::materialize(d);
    ADD_FAILURE() << "no error";
  } catch (const exid::Error& err) {
    const std::string m = err.what();
    EXPECT_NE(m.find("line 202 (data row 201)"), std::string::npos) << m;
    EXPECT_NE(m.find("q3"), std::string::npos) << m;
  }
  // dropped: the scan decides on every used column, the passes skip the same row
  const std::string extra = "drop_bad_rows: true";
  const exid::Dataset whole = readCsv(f, extra);
  auto e2 = exid_test::create<exid::Experiment>("csv", "{file: " + f.string() + ", " + extra + "}");
  const exid::Dataset st =
      exid::materialize(e2->stream(mtest::robot("puma560"), nullptr, mtest::context()));
  EXPECT_EQ(whole.size(), 299);
  EXPECT_EQ(st.t, whole.t);
  EXPECT_EQ(st.q, whole.q);
  EXPECT_EQ(st.meta.dump(), whole.meta.dump());
}

// The scan before the first pass reads a large file in pieces on several threads: the samples,
// the meta and every error are those of the serial scan, with a time column or without, with
// comment and blank lines, CRLF line ends and no newline after the last row.
TEST(CsvStream, TheScanInPiecesGivesTheSerialScansSamplesMetaAndErrors) {
  auto without = [](const exid::Json& meta) {  // the meta without how the scan ran
    exid::Json m = exid::Json::object();
    for (const auto& [k, v] : meta.items())
      if (k != "scan") m[k] = v;
    return m.dump();
  };
  for (const bool with_t : {true, false}) {
    std::string text = "# a long recording\n" + header(6, with_t);
    const int K = 130000;  // about 15 MB: three pieces of 4 MB or more
    for (int k = 0; k < K; ++k) {
      if (k % 9973 == 17) text += "# note\n\n";
      std::string line = row(0.001 * k, 6, 0.1 * std::sin(0.001 * k), with_t);
      if (k % 7 == 3) line.pop_back(), line += "\r\n";  // (row() ends its line in '\n')
      if (k == K - 1) line.pop_back();                  // no newline after the last row
      text += line;
    }
    const fs::path f = writeText(with_t ? "long_t.csv" : "long_not.csv", text);
    const std::string period = with_t ? "" : "sample_period_s: 0.001, ";
    const exid::Dataset one = readCsv(f, period + "threads: 1");
    ASSERT_EQ(one.size(), K);
    EXPECT_EQ(one.meta.find("scan")->find("pieces")->asInt(), 1);
    for (int threads : {2, 3}) {
      const exid::Dataset d = readCsv(f, period + fmt::format("threads: {}", threads));
      EXPECT_GT(d.meta.find("scan")->find("pieces")->asInt(), 2) << threads;
      EXPECT_EQ(d.meta.find("scan")->find("threads")->asInt(), threads);
      EXPECT_EQ(d.t, one.t);
      EXPECT_EQ(d.q, one.q);
      EXPECT_EQ(d.tau, one.tau);
      EXPECT_EQ(without(d.meta), without(one.meta));
      auto e = exid_test::create<exid::Experiment>(
          "csv", "{file: " + f.string() + ", " + period + fmt::format("threads: {}}}", threads));
      const exid::Dataset s =
          exid::materialize(e->stream(mtest::robot("puma560"), nullptr, mtest::context()));
      EXPECT_EQ(s.t, one.t);
      EXPECT_EQ(without(s.meta), without(one.meta));
    }
    if (!with_t) continue;
    // a time that does not increase, then one that is text, in the last piece: the serial
    // scan's message, naming the line
    for (const std::string& bad : {std::string("0.5"), std::string("abc")}) {
      std::string t2 = text;
      const std::string key = "\n" + std::to_string(0.001 * (K - 10)) + ",";
      const std::size_t p = t2.find(key);
      ASSERT_NE(p, std::string::npos);
      t2.replace(p + 1, key.size() - 2, bad);
      const long line = std::count(t2.begin(), t2.begin() + static_cast<long>(p) + 1, '\n') + 1;
      const fs::path g = writeText("long_bad.csv", t2);
      const std::string serial = errorOf(g, "threads: 1");
      EXPECT_NE(serial.find(std::to_string(line)), std::string::npos) << serial;
      EXPECT_EQ(errorOf(g, "threads: 2"), serial);
    }
  }
}
