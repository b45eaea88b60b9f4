// exid — a study's report: report.md with the results of each stage, and the CSV tables
// behind it (parameters.csv, estimate_history.csv). Built stage by stage by the runner.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "exid/config.hpp"
#include "exid/interfaces.hpp"
#include "exid/summary.hpp"
#include "plot.hpp"

namespace exid {

class Report {
 public:
  Report(const StudyConfig& cfg, std::filesystem::path out_dir);
  void model(const ObservationModel& m);
  void excitation(const Samples& initial, const Samples& optimal, const OptimizerResult& r,
                  const ObservationModel& m);
  /// Appended to the excitation section: with torque limits (tau_max not empty) the optimal
  /// trajectory's predicted torques over their limits (plot, largest ratio, the margin); with an
  /// export (exported: excitation.export of summary.json, or null) where it went and its check.
  void excitationLimits(const Samples& optimal, const Eigen::MatrixXd& tau,
                        const Eigen::VectorXd& tau_max, double margin, const Json* exported);
  /// Appended to the excitation section with collision avoidance: the smallest distance over the
  /// checked pairs at every design sample of the optimal trajectory (plot), the margin, the
  /// pairs checked and excluded.
  void excitationCollision(const Samples& optimal, const Eigen::VectorXd& min_distance,
                           const StudySummary::Excitation& x);
  void identification(const Estimate& e, const Eigen::VectorXd& nominal, bool simulated);
  void validation(const Rows& rows, const Eigen::VectorXd& predicted,
                  const StudySummary::Validation& v);
  /// Writes report.md, report.html, the plots (gnuplot, SVG + PNG, data as CSV) and the
  /// tables, each atomically. Returns what the report says about missing plots ("" if none).
  std::string write(const StudySummary& summary);

 private:
  const StudyConfig& cfg_;
  std::filesystem::path dir_;
  std::vector<std::string> sections_;  // markdown; "@@PLOTS:<section index>@@" placeholders
  std::vector<std::pair<std::size_t, PlotSpec>> plots_;     // section index, plot
  std::vector<std::pair<std::string, std::string>> files_;  // name, content
  std::vector<std::string> joint_names_;  // the robot's, per measured coordinate (excitation)
};

}  // namespace exid
