#include "report.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

#include "exid/eigen_instances.hpp"
#include "exid/io.hpp"
#include "exid/runner.hpp"
#include "figures.hpp"

namespace exid {

Report::Report(const StudyConfig& cfg, std::filesystem::path out_dir)
    : cfg_(cfg), dir_(std::move(out_dir)) {}

void Report::model(const ObservationModel& m) {
  const BaseParameters& b = m.base();
  std::string s = fmt::format(
      "## Observation model `{}`\n\n{} full parameters, {} base parameters "
      "(QR with column pivoting over random samples, tolerance {:g}).\n\n"
      "| base parameter | expression |\n|---|---|\n",
      m.pluginName(), b.numFull(), b.rank(), b.tolerance);
  for (int i = 0; i < b.rank(); ++i)
    s += fmt::format("| {} | {} |\n", b.names[static_cast<std::size_t>(i)],
                     b.expressions[static_cast<std::size_t>(i)]);
  sections_.push_back(s);
}

namespace {
std::vector<double> vec(const Eigen::VectorXd& v) {
  return std::vector<double>(v.data(), v.data() + v.size());
}

// The robot's joint names, one per measured coordinate (empty when they do not match).
std::vector<std::string> jointNames(const RobotModel& robot, int dof) {
  std::vector<std::string> n;  // the measured coordinates' (a closed chain's actuated joints)
  for (int j = 0; j < robot.dof(); ++j)
    n.push_back(robot.bodies[static_cast<std::size_t>(robot.actuatedJoint(j))].joint_name);
  if (static_cast<int>(n.size()) != dof) n.clear();
  return n;
}
}  // namespace

void Report::excitation(const Samples& initial, const Samples& optimal, const OptimizerResult& r,
                        const ObservationModel& m) {
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(m.design(optimal));
  Eigen::JacobiSVD<Eigen::MatrixXd> svd0(m.design(initial));
  const std::size_t sec = sections_.size();
  joint_names_ = jointNames(m.robot(), optimal.dof());
  for (int j = 0; j < optimal.dof(); ++j) {
    PlotSpec p;
    p.name = fmt::format("trajectory_joint{}", j + 1);
    p.title =
        fmt::format("Starting and optimal trajectories, {}", jointLabel("joint ", j, joint_names_));
    p.xlabel = "t [s]";
    p.ylabel = fmt::format("q{} [rad or m]", j + 1);
    p.x_column = "t_s";
    p.series.push_back(plotLine("starting", vec(initial.t), vec(initial.q.col(j)), "lines"));
    p.series.push_back(plotLine("optimal", vec(optimal.t), vec(optimal.q.col(j)), "lines"));
    plots_.emplace_back(sec, p);
  }
  if (!r.history_value.empty()) {
    PlotSpec p;
    p.name = "criterion_history";
    p.title = "Criterion during the optimisation";
    p.xlabel = "wall time [s]";
    p.ylabel = "criterion";
    p.log_y = true;
    p.series.push_back(plotLine("criterion", r.history_t_s, r.history_value, "linespoints"));
    plots_.emplace_back(sec, p);
  }
  {
    PlotSpec p;
    p.name = "singular_values";
    p.title = "Singular values of the base regressor W";
    p.xlabel = "index";
    p.ylabel = "sigma";
    p.log_y = true;
    std::vector<double> idx;
    for (Eigen::Index i = 0; i < svd.singularValues().size(); ++i)
      idx.push_back(static_cast<double>(i + 1));
    p.series.push_back(plotLine("starting", idx, vec(svd0.singularValues()), "linespoints"));
    p.series.push_back(plotLine("optimal", idx, vec(svd.singularValues()), "linespoints"));
    plots_.emplace_back(sec, p);
  }
  std::string s = fmt::format(
      "## Excitation\n\nCriterion `{}`: {:.6g} -> {:.6g} in {} iterations, {} evaluations, {:.3g} "
      "s "
      "({}).\nLargest constraint violation at the optimum: {:.3g}.\n\nSingular values of the base "
      "design matrix W at the optimum (cond(W) = sigma_max / sigma_min = {:.6g}):\n\n",
      cfg_.criterion ? cfg_.criterion->type : "?", r.criterion_initial, r.criterion_final,
      r.iterations, r.evaluations, r.wall_s, stopReasonText(r), r.max_violation,
      svd.singularValues()(0) / svd.singularValues()(svd.singularValues().size() - 1));
  s += "```\n";
  for (Eigen::Index i = 0; i < svd.singularValues().size(); ++i)
    s += fmt::format("{:.6g}{}", svd.singularValues()(i), (i + 1) % 8 == 0 ? "\n" : " ");
  s += "\n```\n\nTables: `trajectory_initial.csv`, `trajectory_optimal.csv`, "
       "`criterion_history.csv`.\n";
  sections_.push_back(s);
}

void Report::excitationLimits(const Samples& optimal, const Eigen::MatrixXd& tau,
                              const Eigen::VectorXd& tau_max, double margin, const Json* exported) {
  if (sections_.empty()) return;
  const std::size_t sec = sections_.size() - 1;
  std::string& s = sections_.back();
  if (tau_max.size() == tau.cols() && tau.rows() == optimal.size()) {
    PlotSpec p = torqueRatioPlot(
        "torque_ratio", "Predicted torque over its limit, optimal trajectory (design samples)",
        optimal.t, tau, tau_max, margin, joint_names_);
    double worst = 0.0;
    for (Eigen::Index j = 0; j < tau.cols(); ++j)
      worst = std::max(worst, (tau.col(j) / tau_max(j)).cwiseAbs().maxCoeff());
    plots_.emplace_back(sec, p);
    s += fmt::format(
        "\nTorque limits: |tau_j| <= {:.3g} tau_max,j at every design sample (the robot's full "
        "model, nominal parameters); largest |tau_j| / tau_max,j at the optimum: {:.4f}.\n",
        margin, worst);
  }
  if (exported && exported->isObject()) {
    const Json* dir = exported->find("dir");
    const Json* rate = exported->find("rate_Hz");
    const Json* periods = exported->find("periods");
    s += fmt::format(
        "\nExported for execution into `{}` at {:g} Hz, {} period(s) "
        "(trajectory.csv, trajectory.params.yaml, joint_trajectory.yaml; plots of q, "
        "qd and tau / tau_max there). Check of the written file against the robot's "
        "limits at that rate:\n\n| limit | joint | t [s] | value | limit | margin | "
        "ratio |\n|---|---|---|---|---|---|---|\n",
        dir ? dir->asString() : "?", rate ? rate->asDouble() : 0.0, periods ? periods->asInt() : 0);
    const Json* check = exported->find("check");
    const Json* worst = check ? check->find("worst") : nullptr;
    if (worst)
      for (const auto& [what, w] : worst->items()) {
        const Json* checked = w.find("checked");
        if (!checked || !checked->asBool()) {
          s += fmt::format("| {} | - | - | - | none | - | - |\n", what);
          continue;
        }
        const double m = w.find("margin")->asDouble();
        const Json* pair = w.find("pair");
        const Json* joint = w.find("joint");
        s += fmt::format("| {} | {} | {:.4f} | {:.6g} | {:.6g} | {:.6g}{} | {:.4f} |\n", what,
                         pair ? pair->asString() : std::to_string(joint ? joint->asInt() : 0),
                         w.find("t_s")->asDouble(), w.find("value")->asDouble(),
                         w.find("limit")->asDouble(), m, m < 0 ? " **violated**" : "",
                         w.find("ratio")->asDouble());
      }
    if (const Json* rest = exported->find("rest_note"); rest && rest->isString()) {
      s += "\n### The exported trajectory is not at rest at its ends\n\n";
      std::istringstream lines(rest->asString());
      for (std::string l; std::getline(lines, l);)
        if (!l.empty()) s += "- " + l + "\n";
    }
  }
}

void Report::excitationCollision(const Samples& optimal, const Eigen::VectorXd& dmin,
                                 const StudySummary::Excitation& x) {
  if (sections_.empty() || !x.distance_margin_m) return;
  const std::size_t sec = sections_.size() - 1;
  const double margin = *x.distance_margin_m;
  if (dmin.size() == optimal.size() && optimal.size() > 0) {
    PlotSpec p;
    p.name = "min_distance";
    p.title = "Smallest distance over the checked pairs, optimal trajectory (design samples)";
    p.xlabel = "t [s]";
    p.ylabel = "distance [m]";
    p.series.push_back(plotLine("minimum distance", vec(optimal.t), vec(dmin), "lines"));
    p.limits.push_back({margin, fmt::format("design margin {:g} m", margin), "#e67e22"});
    p.limits.push_back({0.0, "contact", "#c0392b"});
    plots_.emplace_back(sec, p);
  }
  sections_.back() += fmt::format(
      "\nCollision avoidance: signed distance >= {:.3g} m for {} pairs at every design sample "
      "(docs/excitation.md §12); smallest distance {:.4g} m at the initial trajectory, {:.4g} m "
      "at the optimum ({}). Not checked: {}.\n",
      margin, x.collision_pairs, x.min_distance_initial_m.value_or(NAN),
      x.min_distance_final_m.value_or(NAN), x.min_distance_pair,
      x.collision_excluded.empty() ? std::string("none")
                                   : fmt::format("{}", fmt::join(x.collision_excluded, "; ")));
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
    s += fmt::format("| {} | {:.6g} | {:.3g} | {:.3g} | {:.6g} |\n",
                     e.names[static_cast<std::size_t>(i)], e.value(i), sd, rel, nominal(i));
    t.data.row(i) << static_cast<double>(i), e.value(i), sd, rel, nominal(i);
  }
  if (e.nonlinear.size() > 0) {  // fitted with the linear ones (varpro)
    s += "\nNonlinear parameters, fitted with the linear ones:\n\n| parameter | estimate | std |\n"
         "|---|---|---|\n";
    for (Eigen::Index k = 0; k < e.nonlinear.size(); ++k)
      s += fmt::format("| {} | {:.6g} | {:.3g} |\n",
                       static_cast<std::size_t>(k) < e.nonlinear_names.size()
                           ? e.nonlinear_names[static_cast<std::size_t>(k)]
                           : std::string("?"),
                       e.nonlinear(k), e.nonlinear_std.size() > k ? e.nonlinear_std(k) : NAN);
  }
  std::string csv = "name," + toCsv(t);
  // prepend names column
  std::string named =
      "name,index,value,std,rel_std_percent," + std::string(simulated ? "true" : "nominal") + "\n";
  for (Eigen::Index i = 0; i < e.value.size(); ++i)
    named += fmt::format("{},{},{},{},{},{}\n", e.names[static_cast<std::size_t>(i)], i, e.value(i),
                         t.data(i, 2), t.data(i, 3), t.data(i, 4));
  files_.emplace_back("parameters.csv", named);
  // The estimate's covariance (base x base), named: what a next excitation design adds as the
  // information already known (excitation.information.earlier_study).
  if (e.covariance.rows() == e.value.size() && e.covariance.cols() == e.value.size() &&
      e.value.size() > 0) {
    std::string cov = "name";
    for (const auto& n : e.names) cov += "," + n;
    cov += "\n";
    for (Eigen::Index i = 0; i < e.covariance.rows(); ++i) {
      cov += e.names[static_cast<std::size_t>(i)];
      for (Eigen::Index j = 0; j < e.covariance.cols(); ++j)
        cov += fmt::format(",{:.17g}", e.covariance(i, j));
      cov += "\n";
    }
    files_.emplace_back("covariance.csv", cov);
  }
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
    s +=
        "\nEstimate history (recursive): `estimate_history.csv`; bands are +-2 sigma, sigma_i(t) = "
        "sigma * sqrt(P_ii(t)).\n";
    const Eigen::Index shown = std::min<Eigen::Index>(e.value.size(), 8);
    for (Eigen::Index i = 0; i < shown; ++i) {
      PlotSpec p;
      p.name = fmt::format("estimate_{}", i + 1);
      p.title = fmt::format("Estimate of {} against time", e.names[static_cast<std::size_t>(i)]);
      p.xlabel = "t [s]";
      p.ylabel = e.names[static_cast<std::size_t>(i)];
      std::vector<double> lo, hi;
      for (Eigen::Index k = 0; k < e.history_t.size(); ++k) {
        const double sd = e.sigma * std::sqrt(std::max(0.0, e.history_pdiag(k, i)));
        lo.push_back(e.history_value(k, i) - 2 * sd);
        hi.push_back(e.history_value(k, i) + 2 * sd);
      }
      p.series.push_back(plotBand("+-2 sigma", vec(e.history_t), lo, hi));
      p.series.push_back(
          plotLine("estimate", vec(e.history_t), vec(e.history_value.col(i)), "lines"));
      p.series.push_back(plotLine(simulated ? "true" : "nominal",
                                  {e.history_t(0), e.history_t(e.history_t.size() - 1)},
                                  {nominal(i), nominal(i)}, "lines"));
      plots_.emplace_back(sections_.size(), p);
    }
    if (e.value.size() > shown)
      s += fmt::format("\n(Plots of the first {} of {} parameters; all are in the CSV.)\n", shown,
                       e.value.size());
  }
  sections_.push_back(s);
}

void Report::validation(const Rows& rows, const Eigen::VectorXd& predicted,
                        const StudySummary::Validation& v) {
  const std::size_t sec = sections_.size();
  for (int eq = 0; eq < rows.numEquations; ++eq)
    plots_.emplace_back(sec, validationPlot(rows, predicted, eq));
  {
    Eigen::VectorXd res = rows.y - predicted;
    const double lo = res.minCoeff(), hi = res.maxCoeff();
    const int bins = 40;
    const double w = hi > lo ? (hi - lo) / bins : 1.0;
    std::vector<double> centers(bins), counts(bins, 0.0);
    for (int b = 0; b < bins; ++b) centers[static_cast<std::size_t>(b)] = lo + (b + 0.5) * w;
    for (Eigen::Index r = 0; r < res.size(); ++r) {
      int b = static_cast<int>((res(r) - lo) / w);
      counts[static_cast<std::size_t>(std::clamp(b, 0, bins - 1))] += 1;
    }
    PlotSpec p;
    p.name = "residual_histogram";
    p.title = "Validation residuals y - y_hat";
    p.xlabel = "residual";
    p.ylabel = "count";
    p.series.push_back(plotLine("residuals", centers, counts, "boxes"));
    plots_.emplace_back(sec, p);
  }
  std::string s = fmt::format(
      "## Validation\n\n{} rows; relative error ||y - y_hat|| / ||y|| = {:.4g}.\n\n"
      "| equation | RMS error | relative |\n|---|---|---|\n",
      rows.y.size(), v.relative_error);
  for (std::size_t i = 0; i < v.rms_per_joint.size(); ++i)
    s += fmt::format("| {}{} | {:.4g} | {:.4g} |\n", i + 1,
                     i < rows.equation_names.size() ? ": " + rows.equation_names[i] : "",
                     v.rms_per_joint[i], v.relative_error_per_joint[i]);
  s += "\nMeasured vs predicted: `validation.csv`.\n";
  sections_.push_back(s);
}

namespace {

std::string htmlEscape(const std::string& s) {
  std::string o;
  for (char c : s) {
    if (c == '<')
      o += "&lt;";
    else if (c == '>')
      o += "&gt;";
    else if (c == '&')
      o += "&amp;";
    else
      o += c;
  }
  return o;
}

std::string inlineCode(const std::string& s) {
  std::string o, esc = htmlEscape(s);
  bool in = false;
  for (char c : esc) {
    if (c == '`') {
      o += in ? "</code>" : "<code>";
      in = !in;
    } else {
      o += c;
    }
  }
  if (in) o += "</code>";
  return o;
}

// Under an inline figure: its title and links to the files beside it (PNG, the data as CSV).
std::string figureCaption(const std::string& title, const std::string& svg,
                          const std::filesystem::path& dir) {
  std::string c = "<figcaption>" + htmlEscape(title);
  const std::string stem = svg.substr(0, svg.size() - 4);  // "plots/x" of "plots/x.svg"
  for (const char* ext : {".png", ".csv"})
    if (svg.size() > 4 && std::filesystem::exists(dir / (stem + ext)))
      c += fmt::format(" &middot; <a href=\"{0}{1}\">{2}</a>", htmlEscape(stem), ext,
                       std::string(ext) == ".png" ? "PNG" : "data (CSV)");
  return c + "</figcaption>";
}

constexpr int kFoldedTableRows = 24;

// Markdown (the subset the report uses) to self-contained HTML; images become inline SVG.
std::string toHtml(const std::string& md, const std::filesystem::path& dir,
                   const std::string& title) {
  std::string h =
      "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>" + htmlEscape(title) +
      "</title>\n<style>body{font-family:sans-serif;max-width:60em;margin:2em auto;padding:0 1em}"
      "table{border-collapse:collapse}td,th{border:1px solid #bbb;padding:2px 6px;font-size:90%}"
      "pre{background:#f4f4f4;padding:.5em;overflow:auto}svg{max-width:100%;height:auto}"
      "figure{margin:1em 0}figcaption{font-size:85%;color:#555}"
      ".verdict{padding:.3em .5em;border-radius:4px}.verdict-ok{background:#e3f4e6}"
      ".verdict-suspect{background:#fde2df}.verdict-none{background:#eee}</style>"
      "</head><body>\n";
  std::istringstream in(md);
  std::string line;
  bool table = false, pre = false, header_row = false;
  std::string tbl, tbl_head;  // the table being read, its header's cells and its rows
  int tbl_rows = 0;
  // A long table (the base parameters' expressions, the estimates of a large model) folded
  // under its size, so that the figures after it are not pages away.
  auto closeTable = [&] {
    tbl += "</table>\n";
    h += tbl_rows > kFoldedTableRows
             ? fmt::format(
                   "<details><summary>table of {} rows: {} (click to open)</summary>\n{}"
                   "</details>\n",
                   tbl_rows, tbl_head, tbl)
             : tbl;
    table = false;
  };
  while (std::getline(in, line)) {
    if (line.rfind("```", 0) == 0) {
      h += pre ? "</pre>\n" : "<pre>";
      pre = !pre;
      continue;
    }
    if (pre) {
      h += htmlEscape(line) + "\n";
      continue;
    }
    if (!line.empty() && line[0] == '|') {
      if (!table) {
        tbl = "<table>\n";
        tbl_rows = 0;
        table = true;
        header_row = true;
      }
      if (line.find("|---") == 0) continue;
      std::vector<std::string> cells;
      std::string cur;
      for (std::size_t i = 1; i < line.size(); ++i) {
        if (line[i] == '|' && line[i - 1] != '\\') {
          cells.push_back(cur);
          cur.clear();
        } else {
          cur += line[i];
        }
      }
      tbl += "<tr>";
      if (header_row) tbl_head.clear();
      for (auto& c : cells) {
        if (header_row) {
          const auto b = c.find_first_not_of(' '), e = c.find_last_not_of(' ');
          tbl_head += (tbl_head.empty() ? "" : ", ") +
                      inlineCode(b == std::string::npos ? "" : c.substr(b, e - b + 1));
        }
        tbl += (header_row ? "<th>" : "<td>") + inlineCode(c) + (header_row ? "</th>" : "</td>");
      }
      tbl += "</tr>\n";
      if (!header_row) ++tbl_rows;
      header_row = false;
      continue;
    }
    if (table) closeTable();
    if (line.rfind("![", 0) == 0) {
      auto a = line.find("](");
      auto b = line.rfind(')');
      std::string path = line.substr(a + 2, b - a - 2);
      std::ifstream svg(dir / path);
      std::string content((std::istreambuf_iterator<char>(svg)), std::istreambuf_iterator<char>());
      auto start = content.find("<svg");
      h += start == std::string::npos
               ? "<p>(missing picture " + htmlEscape(path) + ")</p>\n"
               : "<figure>" + content.substr(start) +
                     figureCaption(line.substr(2, a - 2), path, dir) + "</figure>\n";
      continue;
    }
    if (line.rfind("## Verdict: ", 0) == 0)
      h += fmt::format("<h2 class=\"verdict verdict-{}\">{}</h2>\n",
                       line.find("suspect") != std::string::npos ? "suspect"
                       : line.find(": ok") != std::string::npos  ? "ok"
                                                                 : "none",
                       inlineCode(line.substr(3)));
    else if (line.rfind("### ", 0) == 0)
      h += "<h3>" + inlineCode(line.substr(4)) + "</h3>\n";
    else if (line.rfind("## ", 0) == 0)
      h += "<h2>" + inlineCode(line.substr(3)) + "</h2>\n";
    else if (line.rfind("# ", 0) == 0)
      h += "<h1>" + inlineCode(line.substr(2)) + "</h1>\n";
    else if (line.rfind("- ", 0) == 0)
      h += "<li>" + inlineCode(line.substr(2)) + "</li>\n";
    else if (!line.empty())
      h += "<p>" + inlineCode(line) + "</p>\n";
  }
  if (table) closeTable();
  if (pre) h += "</pre>\n";
  return h + "</body></html>\n";
}

// The verdict first: what the results say of themselves (summary.json `verdict`).
std::string verdictSection(const StudySummary& summary) {
  if (summary.verdict == "suspect") {
    std::string md =
        "## Verdict: suspect\n\nThe study ran to the end, but its results fail checks of their own "
        "(summary.json `verdict`):\n\n";
    for (const auto& r : summary.verdict_reasons) md += "- " + r + "\n";
    return md + "\n";
  }
  if (summary.verdict == "ok")
    return "## Verdict: ok\n\nThe study ran to the end and its results pass their own checks "
           "(summary.json `verdict`; docs/study.md, \"The verdict\").\n\n";
  return fmt::format("## Verdict: not judged\n\nStatus `{}`: the results were not judged.\n\n",
                     summary.status);
}

}  // namespace

std::string Report::write(const StudySummary& summary) {
  if (dir_.empty()) return "";
  for (const auto& [name, text] : files_) writeFileAtomic(dir_ / name, text);
  // Plots, grouped under their sections.
  std::vector<std::string> plot_md(sections_.size() + 1);
  std::vector<std::string> missing;
  if (cfg_.report.plots) {
    for (const auto& [sec, spec] : plots_) {
      PlotOutcome o = drawPlot(spec, dir_);
      if (!o.svg.empty())
        plot_md[sec] += fmt::format("\n![{}]({})\n", spec.title, o.svg);
      else
        missing.push_back(fmt::format("`{}` ({}; data in `{}`)", spec.name, o.missing_why, o.csv));
    }
  } else if (!plots_.empty()) {
    missing.push_back(fmt::format("all {} plots (report.params.plots is false)", plots_.size()));
  }
  const std::string title =
      cfg_.report.title.empty() ? "exid study: " + cfg_.name : cfg_.report.title;
  std::string md = fmt::format("# {}\n\n", title);
  md += verdictSection(summary);
  md += "## Key figures\n\n" + briefTable(summary) + "\n";
  md += fmt::format(
      "Configuration hash `{}`; resolved study in `study.resolved.yaml`; machine-readable "
      "results in `summary.json`.\n\n",
      cfg_.hash());
  if (!summary.warnings.empty()) {
    md += "## Warnings\n\n";
    for (const auto& w : summary.warnings) md += "- " + w + "\n";
    md += "\n";
  }
  if (summary.robot && !summary.robot->notes.empty()) {
    md += "## Notes on the robot\n\n";
    for (const auto& n : summary.robot->notes) md += "- " + n + "\n";
    md += "\n";
  }
  for (std::size_t i = 0; i < sections_.size(); ++i) md += sections_[i] + plot_md[i] + "\n";
  std::string missing_text;
  if (!missing.empty()) {
    md += "## Missing plots\n\n";
    for (const auto& m : missing) md += "- " + m + "\n";
    missing_text = fmt::format("{} plot(s) not drawn: {}", missing.size(), missing.front());
  }
  writeFileAtomic(dir_ / "report.md", md);
  writeFileAtomic(dir_ / "report.html", toHtml(md, dir_, title));
  return missing_text;
}

}  // namespace exid
