// The CI excitation matrix (examples/matrix/ci_excitation.yaml): every criterion x optimiser on
// two robots. Every cell finishes, improves its own criterion, and its final cond(W)
// stays within 1.25 x the baseline (tests/regression/ci_excitation_baseline.csv; regenerate
// after an intended change with EXID_UPDATE_BASELINE=1).
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <sstream>

#include "baseline.hpp"
#include "exid/io.hpp"
#include "exid/matrix.hpp"
#include "exid_test.hpp"

namespace fs = std::filesystem;

using exid_test::labelledColumn;

TEST(CiExcitation, EveryCriterionAndOptimiserImprovesAndNothingRegresses) {
  const fs::path src = exid_test::sourceDir();
  const fs::path out = fs::path(EXID_BINARY_DIR) / "ci_excitation";
  fs::remove_all(out);
  exid::MatrixSpec spec =
      exid::loadMatrix(src / "examples/matrix/ci_excitation.yaml", exid_test::registry());
  exid::MatrixOptions opt;
  opt.out_dir = out;
  opt.jobs = 2;
  opt.write_cell_files = false;
  exid::MatrixRunSummary s = exid::runMatrix(spec, exid_test::registry(), opt);
  EXPECT_EQ(s.ok, s.total) << s.failed << " failed, " << s.timeout << " timeout";
  const fs::path db = out / "results.sqlite";
  const std::vector<std::string> keys = {"robot", "excitation.criterion", "optimizer"};
  auto j0 = labelledColumn(exid::matrixTable(db, keys, {}, "excitation.criterion_initial").csv);
  auto j1 = labelledColumn(exid::matrixTable(db, keys, {}, "excitation.criterion_final").csv);
  auto final_ = labelledColumn(exid::matrixTable(db, keys, {}, "excitation.cond_W_final").csv);
  std::cout << exid::matrixTable(db, {"robot", "excitation.criterion"}, {"optimizer"},
                                 "excitation.cond_W_final")
                   .markdown;
  ASSERT_EQ(final_.size(), spec.cells.size());
  // Each optimiser improves its own criterion (log_det need not lower cond(W)).
  for (const auto& [k, v] : j1) EXPECT_LT(v, j0[k]) << k << ": no improvement of the criterion";
  const fs::path baseline = src / "tests/regression/ci_excitation_baseline.csv";
  if (std::getenv("EXID_UPDATE_BASELINE")) {
    exid_test::writeBaseline(baseline, "cond_W_final", final_);
    std::cout << "baseline written to " << baseline << "\n";
    return;
  }
  ASSERT_TRUE(fs::exists(baseline)) << baseline;
  auto base = labelledColumn(exid_test::readText(baseline));
  ASSERT_EQ(base.size(), final_.size());
  for (const auto& [k, v] : base) {
    ASSERT_TRUE(final_.count(k)) << "cell missing: " << k;
    EXPECT_LE(final_[k], 1.25 * v + 1e-9) << k << ": cond(W) " << final_[k] << " vs baseline " << v;
  }
}
