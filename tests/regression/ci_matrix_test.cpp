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

  // Current values per cell label.
  std::map<std::string, double> current;
  exid::MatrixTable t = exid::matrixTable(
      out / "results.sqlite", {"robot", "model", "estimator", "seed"}, {}, "param_rel_err");
  std::cout << exid::matrixTable(out / "results.sqlite", {"robot", "model"}, {"estimator"},
                                 "param_rel_err")
                   .markdown;
  // The table's CSV has the row label (quoted) and one value column.
  std::istringstream in(t.csv);
  std::string line;
  std::getline(in, line);  // header
  while (std::getline(in, line)) {
    auto comma = line.rfind(',');
    std::string label = line.substr(0, comma);
    label.erase(std::remove(label.begin(), label.end(), '"'), label.end());
    current[label] = line.substr(comma + 1).empty() ? NAN : std::stod(line.substr(comma + 1));
  }
  ASSERT_EQ(current.size(), spec.cells.size());
  const fs::path baseline = src / "tests/regression/ci_matrix_baseline.csv";
  if (std::getenv("EXID_UPDATE_BASELINE")) {
    std::string text = "cell,param_rel_err\n";
    for (const auto& [k, v] : current) {
      std::ostringstream os;
      os.precision(17);
      os << v;
      text += "\"" + k + "\"," + os.str() + "\n";
    }
    exid::writeFileAtomic(baseline, text);
    std::cout << "baseline written to " << baseline << "\n";
    return;
  }
  std::ifstream b(baseline);
  ASSERT_TRUE(b.good()) << baseline;
  std::getline(b, line);
  int compared = 0;
  while (std::getline(b, line)) {
    auto comma = line.rfind(',');
    std::string label = line.substr(0, comma);
    label.erase(std::remove(label.begin(), label.end(), '"'), label.end());
    const double base = std::stod(line.substr(comma + 1));
    auto it = current.find(label);
    ASSERT_NE(it, current.end()) << "cell missing: " << label;
    EXPECT_LE(it->second, 1.25 * base + 1e-6)
        << label << ": param_rel_err " << it->second << " vs baseline " << base;
    ++compared;
  }
  EXPECT_EQ(compared, static_cast<int>(spec.cells.size()));
}
