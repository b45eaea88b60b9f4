#include "figures.hpp"

#include <fmt/format.h>

#include <algorithm>

namespace exid {

std::string jointLabel(const std::string& prefix, int j, const std::vector<std::string>& names) {
  const auto i = static_cast<std::size_t>(j);
  const std::string base = fmt::format("{}{}", prefix, j + 1);
  std::string compact = base;  // "joint 2" is not named by "joint2"
  compact.erase(std::remove(compact.begin(), compact.end(), ' '), compact.end());
  return i < names.size() && !names[i].empty() && names[i] != base && names[i] != compact
             ? fmt::format("{} ({})", base, names[i])
             : base;
}

PlotSpec validationPlot(const Rows& rows, const Eigen::VectorXd& predicted, int eq) {
  const bool timed = rows.t.size() == static_cast<std::size_t>(rows.y.size());
  const std::string what = static_cast<std::size_t>(eq) < rows.equation_names.size()
                               ? rows.equation_names[static_cast<std::size_t>(eq)]
                               : fmt::format("equation {}", eq + 1);
  PlotSpec p;
  p.name = fmt::format("validation_equation{}", eq + 1);
  p.title = fmt::format("Validation on held-out data: {}", what);
  p.xlabel = timed ? "t [s]" : "sample";
  p.x_column = timed ? "t_s" : "sample";
  p.ylabel = static_cast<std::size_t>(eq) < rows.equation_names.size()
                 ? what
                 : "y (torque [N m], wrench or energy)";
  p.lower_ylabel = "measured - predicted";
  std::vector<double> x, ym, yp, res;
  for (Eigen::Index r = 0; r < rows.y.size(); ++r) {
    const int e = rows.equation.empty() ? 0 : rows.equation[static_cast<std::size_t>(r)];
    if (e != eq) continue;
    x.push_back(timed ? rows.t[static_cast<std::size_t>(r)] : static_cast<double>(x.size()));
    ym.push_back(rows.y(r));
    yp.push_back(predicted(r));
    res.push_back(rows.y(r) - predicted(r));
  }
  PlotSeries m{"measured", x, ym, "lines", {}, {}, "#9ecae1", 5.0, 0};
  PlotSeries q{"predicted", x, yp, "lines", {}, {}, "#c0392b", 1.2, 0};
  PlotSeries d{"residual", x, res, "lines", {}, {}, "#2c3e50", 1.0, 1};
  p.series = {m, q, d};
  return p;
}

PlotSpec torqueRatioPlot(const std::string& name, const std::string& title,
                         const Eigen::VectorXd& t, const Eigen::MatrixXd& tau,
                         const Eigen::VectorXd& tau_max, double margin,
                         const std::vector<std::string>& joint_labels) {
  PlotSpec p;
  p.name = name;
  p.title = title;
  p.xlabel = "t [s]";
  p.ylabel = "tau / tau_max";
  p.x_column = "t_s";
  const std::vector<double> x(t.data(), t.data() + t.size());
  for (Eigen::Index j = 0; j < tau.cols() && j < tau_max.size(); ++j) {
    PlotSeries s;
    s.title = jointLabel("tau", static_cast<int>(j), joint_labels);
    s.x = x;
    s.y.resize(static_cast<std::size_t>(tau.rows()));
    for (Eigen::Index k = 0; k < tau.rows(); ++k)
      s.y[static_cast<std::size_t>(k)] = tau(k, j) / tau_max(j);
    p.series.push_back(std::move(s));
  }
  for (double sign : {1.0, -1.0})
    p.limits.push_back({sign, sign > 0 ? "+tau_max" : "-tau_max", "#c0392b"});
  if (margin > 0 && margin < 1)
    for (double sign : {1.0, -1.0})
      p.limits.push_back(
          {sign * margin,
           fmt::format("{}{:g} tau_max (design margin)", sign > 0 ? "+" : "-", margin), "#e67e22"});
  return p;
}

}  // namespace exid
