// exid — estimator `gains_ls` (gains_ls.cpp): the plugin class, shared by its sources (not
// installed). gains_ls.cpp: the plugin, its parameters, the solution and its details;
// gains_ls_fit.cpp: the per-group sums of one pass and Levenberg-Marquardt on them.
#pragma once

#include <Eigen/Core>
#include <chrono>
#include <map>
#include <string>
#include <tuple>
#include <vector>

#include "exid/estimators/common.hpp"
#include "exid/interfaces.hpp"

namespace exid::gains_ls {

using exid::estimators::RowAccumulator;

class GainsLs : public exid::Estimator {
 public:
  static constexpr const char* kName = "gains_ls";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "the recorded torque's own columns (differential's drive_gains dK, coulomb_load FcL) with "
      "the base parameters, the recorded torque in the measurement only: tau = (w theta + p) / "
      "(1 + a phi), Levenberg-Marquardt on per-group sums of one pass; no errors-in-variables "
      "bias";

  static std::vector<exid::ParamDecl> params();

  explicit GainsLs(const exid::ParamSet& p);

  exid::EstimatorSpecs specs() const override {
    exid::EstimatorSpecs s;
    s.streams = true;  // one pass, per-joint sums
    return s;
  }

  exid::Estimate estimate(const exid::ObservationModel& model, const exid::Dataset& data,
                          const exid::Prior* prior, const exid::RunContext& ctx) override;

 private:
  void split(const exid::ObservationModel& model);

  void setPrior(const exid::ObservationModel& model);
  bool hasPrior() const { return sd_.size() > 0; }

  // Per group of rows (equation, torque column, a): the sums of u u^T, u = [w, p, tau].
  struct Group {
    int eq = 0;
    int k = -1;    // its torque column (index in gain_cols_); -1: none (g = 1)
    double a = 0;  // g = 1 / (1 + a phi_k)
  };
  struct Sums {
    std::vector<Group> groups;
    std::vector<RowAccumulator> acc;
    std::map<std::tuple<int, int, int>, std::size_t> index;  // (eq, k, a) -> group
    std::map<int, std::size_t> rows_of_col;                  // torque column -> its rows
    std::map<int, int> eq_of_col;                            // torque column -> its equation
    std::map<int, long> rows_of_eq;                          // equation -> its rows
    long m = 0;
  };

  Sums accumulate(const exid::ObservationModel& model, const exid::Dataset& data,
                  const exid::RunContext& ctx) const;

  struct Fit {
    Eigen::VectorXd theta, phi;  // other base parameters; torque columns' (dK, FcL)
    double rss = 0.0;            // the data's residual sum of squares
    double objective = 0.0;      // rss + the prior's weighted pseudo-residuals
    double noise = 0.0;          // the noise std the prior was weighed with (0: no prior)
    int noise_rounds = 0;        // fits to the noise std's fixed point
    double noise_floor = 0.0;    // its floor; floored: the floor was used
    bool floored = false;
    Eigen::MatrixXd H;  // Gauss-Newton matrix of (theta, phi), the prior's included
    int iterations = 0;
    std::string stop;
    bool converged = false;
    double gradient_norm = 0.0;  // ||d objective / d(theta, phi)|| at the end
    double gn_fraction = 0.0;    // the part of the objective a Gauss-Newton step would remove
    bool first_order = false;    // the first-order test holds there
    // the starts (first: the one LM ran from in every later round of the prior's noise)
    struct Start {
      double shift = 0;           // of every torque column's parameter from the first start
      Eigen::VectorXd phi0, phi;  // where it started and ended
      double objective = 0, rss = 0, gn_fraction = 0;
      int iterations = 0;
      bool first_order = false, admissible = true;
      bool degenerate = false;  // a load term at |FcL| >= 0.9 (refused unless every start is)
    };
    std::vector<Start> starts;
    int best = 0;  // the kept start
  };

  // The shift of start i from the first: 0, -s, +s, -s/2, +s/2, -2s, +2s.
  double shiftOf(int i) const {
    static const double kMul[] = {0.0, -1.0, 1.0, -0.5, 0.5, -2.0, 2.0};
    return kMul[i] * spread_;
  }

  Eigen::VectorXd thetaAt(const Sums& S, const std::vector<Eigen::MatrixXd>& G,
                          const Eigen::VectorXd& phi) const;

  void multiStart(const Sums& S, const std::vector<Eigen::MatrixXd>& G, double noise,
                  Fit* fp) const;

  // Whether every group's 1 + a phi_k is positive (the recorded torque keeps its sign).
  static bool admissible(const Sums& S, const Eigen::VectorXd& phi) {
    for (const Group& g : S.groups)
      if (g.k >= 0 && !(1.0 + g.a * phi[g.k] > 0.0)) return false;
    return true;
  }

  double evaluate(const Sums& S, const std::vector<Eigen::MatrixXd>& G, const Eigen::VectorXd& th,
                  const Eigen::VectorXd& phi, double noise, Eigen::VectorXd* grad,
                  Eigen::MatrixXd* H, double* data_rss = nullptr, int only_eq = -1) const;

  Fit solve(const Sums& S) const;

  void linearStart(const Sums& S, const std::vector<Eigen::MatrixXd>& G, Fit* f) const;

  void iterate(const Sums& S, const std::vector<Eigen::MatrixXd>& G, double noise, Fit* fp) const;

  exid::Estimate finish(const exid::ObservationModel& model, const Sums& S, const Fit& f,
                        std::chrono::steady_clock::time_point t0) const;

  exid::estimators::LsSolution solution(const exid::ObservationModel& model, const Sums& S,
                                        const Fit& f, exid::Json* per_eq) const;

  Eigen::MatrixXd covariance(const Sums& S, const Fit& f, int p, const Eigen::MatrixXd& Hinv,
                             const Eigen::MatrixXd& T, exid::Json* per_eq) const;

  void describeTorqueColumns(const exid::ObservationModel& model,
                             const exid::estimators::LsSolution& s, const Fit& f,
                             exid::Json* dp) const;

  std::string startName(const Fit& f, int i) const;

  void describeStarts(const exid::ObservationModel& model, const Fit& f, exid::Json* dp) const;

  int max_iter_;
  double xtol_, gtol_;
  int starts_;
  double spread_;
  int chunk_;
  double rank_tol_;
  std::vector<double> prior_std_, prior_mean_;  // as given
  Eigen::VectorXd mu_, sd_;                     // the gain prior per gain column (empty: none)
  std::vector<int> gain_cols_, other_cols_;     // base columns: torque columns', others'
  std::vector<bool> is_gain_;                   // per torque column: dK (else FcL)
};

}  // namespace exid::gains_ls
