// Regression baselines of the CI matrices: one value per cell label, stored as CSV
// ("label",value) and read back from a matrix table's single-column CSV.
#pragma once

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>

#include "exid/io.hpp"

namespace exid_test {

/// label -> value from a CSV whose rows are `"label",value` (header line first).
inline std::map<std::string, double> labelledColumn(const std::string& csv) {
  std::map<std::string, double> out;
  std::istringstream in(csv);
  std::string line;
  std::getline(in, line);  // header
  while (std::getline(in, line)) {
    const auto comma = line.rfind(',');
    std::string label = line.substr(0, comma);
    label.erase(std::remove(label.begin(), label.end(), '"'), label.end());
    const std::string v = line.substr(comma + 1);
    out[label] = v.empty() ? NAN : std::stod(v);
  }
  return out;
}

inline std::string readText(const std::filesystem::path& p) {
  std::ifstream in(p);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

/// Writes a baseline (full precision) with the given value column name.
inline void writeBaseline(const std::filesystem::path& file, const std::string& metric,
                          const std::map<std::string, double>& values) {
  std::string text = "cell," + metric + "\n";
  for (const auto& [k, v] : values) {
    std::ostringstream os;
    os.precision(17);
    os << v;
    text += "\"" + k + "\"," + os.str() + "\n";
  }
  exid::writeFileAtomic(file, text);
}

}  // namespace exid_test
