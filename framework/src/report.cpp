#include "exid/report.hpp"

#include <fmt/format.h>

#include <Eigen/SVD>
#include <cmath>

#include "exid/io.hpp"
#include "exid/runner.hpp"

namespace exid {

Report::Report(const StudyConfig& cfg, std::filesystem::path out_dir)
    : cfg_(cfg), dir_(std::move(out_dir)) {}

void Report::model(const ObservationModel& m) {
  const BaseParameters& b = m.base();
  std::string s = fmt::format("## Observation model `{}`\n\n{} full parameters, {} base parameters "
                              "(QR with column pivoting over random samples, tolerance {:g}).\n\n"
                              "| base parameter | expression |\n|---|---|\n",
                              m.pluginName(), b.numFull(), b.rank(), b.tolerance);
  for (int i = 0; i < b.rank(); ++i)
    s += fmt::format("| {} | {} |\n", b.names[static_cast<std::size_t>(i)], b.expressions[static_cast<std::size_t>(i)]);
  sections_.push_back(s);
}

void Report::excitation(const Samples& initial, const Samples& optimal, const OptimizerResult& r,
                        const ObservationModel& m) {
  (void)initial;
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(m.design(optimal));
  std::string s = fmt::format(
      "## Excitation\n\nCriterion `{}`: {:.6g} -> {:.6g} in {} iterations, {} evaluations, {:.3g} s "
      "({}).\nLargest constraint violation at the optimum: {:.3g}.\n\nSingular values of the base "
      "design matrix W at the optimum (cond(W) = sigma_max / sigma_min = {:.6g}):\n\n",
      cfg_.criterion ? cfg_.criterion->type : "?", r.criterion_initial, r.criterion_final,
      r.iterations, r.evaluations, r.wall_s, r.stop_reason, r.max_violation,
      svd.singularValues()(0) / svd.singularValues()(svd.singularValues().size() - 1));
  s += "```\n";
  for (Eigen::Index i = 0; i < svd.singularValues().size(); ++i)
    s += fmt::format("{:.6g}{}", svd.singularValues()(i), (i + 1) % 8 == 0 ? "\n" : " ");
  s += "\n```\n\nTables: `trajectory_initial.csv`, `trajectory_optimal.csv`, `criterion_history.csv`.\n";
  sections_.push_back(s);
}

void Report::identification(const Estimate& e, const Eigen::VectorXd& nominal, bool simulated) {
  std::string s = fmt::format(
      "## Identification\n\n{} rows, cond(W) = {:.6g}, residual RMS = {:.6g}, sigma = {:.6g}.\n\n"
      "| parameter | estimate | std | %std | {} |\n|---|---|---|---|---|\n",
      e.rows, e.cond_W, e.residual_rms, e.sigma, simulated ? "true" : "nominal");
  CsvTable t;
  t.columns = {"index", "value", "std", "rel_std_percent", simulated ? "true" : "nominal"};
  t.data.resize(e.value.size(), 5);
  for (Eigen::Index i = 0; i < e.value.size(); ++i) {
    const double sd = e.std.size() > i ? e.std(i) : NAN;
    const double rel = e.value(i) != 0 ? 100.0 * sd / std::abs(e.value(i)) : NAN;
    s += fmt::format("| {} | {:.6g} | {:.3g} | {:.3g} | {:.6g} |\n", e.names[static_cast<std::size_t>(i)],
                     e.value(i), sd, rel, nominal(i));
    t.data.row(i) << static_cast<double>(i), e.value(i), sd, rel, nominal(i);
  }
  std::string csv = "name," + toCsv(t);
  // prepend names column
  std::string named = "name,index,value,std,rel_std_percent," + std::string(simulated ? "true" : "nominal") + "\n";
  for (Eigen::Index i = 0; i < e.value.size(); ++i)
    named += fmt::format("{},{},{},{},{},{}\n", e.names[static_cast<std::size_t>(i)], i, e.value(i),
                         t.data(i, 2), t.data(i, 3), t.data(i, 4));
  files_.emplace_back("parameters.csv", named);
  if (e.history_t.size() > 0) {
    CsvTable h;
    h.columns = {"t"};
    for (const auto& n : e.names) h.columns.push_back(n);
    for (const auto& n : e.names) h.columns.push_back("P_" + n);
    h.data.resize(e.history_t.size(), 1 + 2 * e.value.size());
    h.data.col(0) = e.history_t;
    h.data.middleCols(1, e.value.size()) = e.history_value;
    h.data.middleCols(1 + e.value.size(), e.value.size()) = e.history_pdiag;
    files_.emplace_back("estimate_history.csv", toCsv(h));
    s += "\nEstimate history (recursive): `estimate_history.csv`.\n";
  }
  sections_.push_back(s);
}

void Report::validation(const Rows& rows, const Eigen::VectorXd& predicted, const Json& v) {
  (void)predicted;
  std::string s = fmt::format("## Validation\n\n{} rows; relative error ||y - y_hat|| / ||y|| = {:.4g}.\n\n"
                              "| equation | RMS error | relative |\n|---|---|---|\n",
                              rows.y.size(), v.find("relative_error")->asDouble());
  const Json* rms = v.find("rms_per_joint");
  const Json* rel = v.find("relative_error_per_joint");
  for (std::size_t i = 0; rms && i < rms->size(); ++i)
    s += fmt::format("| {} | {:.4g} | {:.4g} |\n", i + 1, rms->at(i).asDouble(), rel->at(i).asDouble());
  s += "\nMeasured vs predicted: `validation.csv`.\n";
  sections_.push_back(s);
}

void Report::write(const Json& summary) {
  if (dir_.empty()) return;
  for (const auto& [name, text] : files_) writeFileAtomic(dir_ / name, text);
  std::string md = fmt::format("# {}\n\n", cfg_.report.title.empty() ? "exid study: " + cfg_.name : cfg_.report.title);
  md += fmt::format("Configuration hash `{}`; resolved study in `study.resolved.yaml`; machine-readable "
                    "results in `summary.json`.\n\n",
                    cfg_.hash());
  md += briefTable(summary) + "\n";
  for (const auto& s : sections_) md += s + "\n";
  writeFileAtomic(dir_ / "report.md", md);
}

}  // namespace exid
