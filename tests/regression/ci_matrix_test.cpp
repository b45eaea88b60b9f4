// The CI matrix (examples/matrix/ci.yaml): every shipped model x estimator on two robots, two
// seeds. Every cell must finish ok, and each cell's tracked metrics must not regress beyond the
// stated tolerance against tests/regression/ci_matrix_baseline.csv:
//   param_rel_err <= 1.25 * baseline + 1e-6      (the relative error of the identified parameters)
//   validation_rel_err, residual_rms likewise when tracked.
// Regenerate the baseline (after an intended change) with EXID_UPDATE_BASELINE=1.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
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

TEST(CiMatrix, AllCellsFinishAndNoTrackedMetricRegresses) {
  const fs::path src = exid_test::sourceDir();
  const fs::path out = fs::path(EXID_BINARY_DIR) / "ci_matrix";
  fs::remove_all(out);
  exid::MatrixSpec spec = exid::loadMatrix(src / "examples/matrix/ci.yaml", exid_test::registry());
  exid::MatrixOptions opt;
  opt.out_dir = out;
  opt.jobs = 2;
  opt.write_cell_files = false;
  exid::MatrixRunSummary s = exid::runMatrix(spec, exid_test::registry(), opt);
  EXPECT_EQ(s.ok, s.total) << s.failed << " failed, " << s.timeout << " timeout";

  exid::MatrixTable t = exid::matrixTable(
      out / "results.sqlite", {"robot", "model", "estimator", "seed"}, {}, "param_rel_err");
  std::cout << exid::matrixTable(out / "results.sqlite", {"robot", "model"}, {"estimator"},
                                 "param_rel_err")
                   .markdown;
  const std::map<std::string, double> current = exid_test::labelledColumn(t.csv);
  ASSERT_EQ(current.size(), spec.cells.size());
  const fs::path baseline = src / "tests/regression/ci_matrix_baseline.csv";
  if (std::getenv("EXID_UPDATE_BASELINE")) {
    exid_test::writeBaseline(baseline, "param_rel_err", current);
    std::cout << "baseline written to " << baseline << "\n";
    return;
  }
  ASSERT_TRUE(std::filesystem::exists(baseline)) << baseline;
  int compared = 0;
  for (const auto& [label, base] : exid_test::labelledColumn(exid_test::readText(baseline))) {
    auto it = current.find(label);
    ASSERT_NE(it, current.end()) << "cell missing: " << label;
    EXPECT_LE(it->second, 1.25 * base + 1e-6)
        << label << ": param_rel_err " << it->second << " vs baseline " << base;
    ++compared;
  }
  EXPECT_EQ(compared, static_cast<int>(spec.cells.size()));
}
