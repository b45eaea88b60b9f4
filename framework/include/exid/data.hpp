// exid — data that flows between stages: trajectory samples, recorded or simulated datasets,
// observation rows. Columns follow docs/conventions.md §1; all SI.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "exid/json.hpp"

namespace exid {

/// q, qd, qdd at sample times (a trajectory), K x n each, measured coordinates.
struct Samples {
  Eigen::VectorXd t;  // [s]
  Eigen::MatrixXd q, qd, qdd;
  int size() const { return static_cast<int>(t.size()); }
  int dof() const { return static_cast<int>(q.cols()); }
};

/// A recorded or simulated experiment. Absent signals are empty matrices (0 columns).
struct Dataset {
  Eigen::VectorXd t;           // [s], strictly increasing
  Eigen::MatrixXd q, qd, qdd;  // K x n, measured coordinates [rad or m, /s, /s^2]
  Eigen::MatrixXd tau;         // K x n [N m or N]
  Eigen::MatrixXd wrench;      // K x 6 fx fy fz mx my mz, sensor frame [N, N m]
  std::string source;          // file or generator, for messages
  Json meta = Json::object();  // what produced it (noise, seed, dropped rows, ...)

  int size() const { return static_cast<int>(t.size()); }
  int dof() const { return static_cast<int>(q.cols()); }
  bool hasVelocity() const { return qd.cols() > 0; }
  bool hasAcceleration() const { return qdd.cols() > 0; }
  bool hasTorque() const { return tau.cols() > 0; }
  bool hasWrench() const { return wrench.cols() > 0; }
  /// Samples view (copies q, qd, qdd).
  Samples samples() const { return {t, q, qd, qdd}; }
};

/// Observation rows of a model: W * theta ~= y. Columns are BASE parameters of the model.
struct Rows {
  Eigen::MatrixXd W;
  Eigen::VectorXd y;
  std::vector<int> equation;  // per row: which equation it is (joint index, wrench component,
                              // window), so estimators can weight per equation
  int numEquations = 1;       // distinct values in `equation`
  std::vector<double> t;      // per row: time of its sample [s] (a window: its end); may be empty
  std::vector<std::string> equation_names;  // per equation, e.g. "tau joint 2 (shoulder)"
};

}  // namespace exid
