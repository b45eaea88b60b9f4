// exid — samples and datasets as CSV tables (tables.hpp).
#include "exid/tables.hpp"

#include <string>
#include <vector>

namespace exid {

namespace {

std::vector<std::string> signalNames(const std::string& prefix, int n) {
  std::vector<std::string> out;
  for (int j = 1; j <= n; ++j) out.push_back(prefix + std::to_string(j));
  return out;
}

}  // namespace

CsvTable samplesTable(const Samples& s) {
  CsvTable t;
  const int n = s.dof();
  t.columns = {"t"};
  for (const char* p : {"q", "qd", "qdd"})
    for (auto& c : signalNames(p, n)) t.columns.push_back(c);
  t.data.resize(s.size(), 1 + 3 * n);
  t.data.col(0) = s.t;
  t.data.middleCols(1, n) = s.q;
  t.data.middleCols(1 + n, n) = s.qd;
  t.data.middleCols(1 + 2 * n, n) = s.qdd;
  return t;
}

CsvTable datasetTable(const Dataset& d) {
  CsvTable t;
  const int n = d.dof();
  std::vector<const Eigen::MatrixXd*> blocks;
  t.columns = {"t"};
  auto add = [&](const char* prefix, const Eigen::MatrixXd& m) {
    if (m.cols() == 0) return;
    for (auto& c : signalNames(prefix, static_cast<int>(m.cols()))) t.columns.push_back(c);
    blocks.push_back(&m);
  };
  add("q", d.q);
  add("qd", d.qd);
  add("qdd", d.qdd);
  add("tau", d.tau);
  if (d.hasWrench()) {
    for (const char* c : {"fx", "fy", "fz", "mx", "my", "mz"}) t.columns.push_back(c);
    blocks.push_back(&d.wrench);
  }
  if (d.hasBase()) {
    for (const char* c : {"base_omega_x", "base_omega_y", "base_omega_z", "base_alpha_x",
                          "base_alpha_y", "base_alpha_z", "base_f_x", "base_f_y", "base_f_z"})
      t.columns.push_back(c);
    blocks.push_back(&d.base);
  }
  if (d.hasContact()) {
    for (Eigen::Index c = 0; c < d.contact.cols() / 6; ++c)
      for (const char* k : {"fx", "fy", "fz", "mx", "my", "mz"})
        t.columns.push_back("contact" + std::to_string(c + 1) + "_" + k);
    blocks.push_back(&d.contact);
  }
  (void)n;
  t.data.resize(d.size(), static_cast<Eigen::Index>(t.columns.size()));
  t.data.col(0) = d.t;
  Eigen::Index c0 = 1;
  for (const auto* b : blocks) {
    t.data.middleCols(c0, b->cols()) = *b;
    c0 += b->cols();
  }
  return t;
}

}  // namespace exid
