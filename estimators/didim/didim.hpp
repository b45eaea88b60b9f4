// exid — estimator `didim` (didim.cpp): the plugin class, shared by its sources (not
// installed). didim.cpp: the plugin, its parameters and the estimate's details;
// didim_simulation.cpp: the samples fitted, the closed-loop simulation and the least-squares
// starts; didim_lm.cpp: Levenberg-Marquardt, the gain prior and the starts.
#pragma once

#include <Eigen/Core>
#include <chrono>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "exid/estimators/closed_loop.hpp"
#include "exid/estimators/common.hpp"
#include "exid/interfaces.hpp"

namespace exid::didim {

using Eigen::MatrixXd;
using Eigen::VectorXd;

class Didim : public exid::Estimator {
 public:
  static constexpr const char* kName = "didim";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "output error (DIDIM): the closed-loop simulation (reference file, PD gains, CVODES) "
      "fitted to the measured torques or positions from the least-squares start; Jacobian from "
      "forward sensitivities, sigma from the Gauss-Newton matrix";

  static std::vector<exid::ParamDecl> params();

  explicit Didim(const exid::ParamSet& p);

  exid::EstimatorSpecs specs() const override { return {}; }  // the Jacobian held in memory

  exid::Estimate estimate(const exid::ObservationModel& model, const exid::Dataset& data_in,
                          const exid::Prior* prior, const exid::RunContext& ctx) override;

 private:
  struct Sim {
    VectorXd y;  // simulated output, sample-major
    MatrixXd J;  // d y / d theta (with sensitivities)
    double rss = 0.0;
    double prior_rss = 0.0;  // the gain prior's pseudo-observations
    double total() const { return rss + prior_rss; }
    // the simulation's paths (one per window; without sensitivities): an accepted trial's
    // sensitivities are taken along them (ClosedLoop::sensitivitiesAlong)
    std::vector<exid::estimators::ClosedLoop::Path> paths;
  };

  // One Levenberg-Marquardt run (one start): where it started, where it is with its last
  // simulation (with the sensitivities), and its state.
  struct Run {
    VectorXd x0, x;  // (theta, log eta, d): the start; the current point
    Sim cur;
    double sigma = 0.0;  // the noise std the gain prior's weight uses
    int round = 1;       // the prior's noise rounds
    // The second-order term sum r_i d2 y_i / dtheta2 of the residual's Hessian, by secant
    // updates (Dennis, Gay and Welsch, NL2SOL), and the last accepted step's pair
    MatrixXd Ssec;
    VectorXd g_prev, s_prev, Jr_prev_at_new;
    // At the current point: H = J^T J (+ the prior's), g = J^T r (+ the prior's), Hm = H + S
    // (or H), and the decrease the undamped model predicts, g^T Hm^-1 g (infinite where Hm is
    // not positive definite: no minimum claimed)
    MatrixXd H, Hm;
    VectorXd g;
    double undamped = 0.0;
    bool prepared = false;  // (H, Hm, g, undamped are those of x)
    // Levenberg-Marquardt's damping (relative to diag(J^T J)) and its growth after rejections
    double mu = 1e-3, nu = 2.0;
    // simulations: integrations of the state; jacobians: sensitivity passes (the first with its
    // own simulation, the others along an accepted trial's)
    int iterations = 0, sims = 1, jacobians = 1;
    std::string stop;      // why it stopped (empty: the iterations ran out)
    bool stopped = false;  // a stop test held
    exid::Json trace = exid::Json::array();
    // at its end (conclude): the first-order test
    bool first_order = false;
    double distance_std = std::numeric_limits<double>::infinity();
    double undamped_relative = std::numeric_limits<double>::infinity();
    std::string error;  // a start that could not be simulated
  };

  // The parameters the starts move, other than theta: the drive gains (dK) and load-dependent
  // Coulomb (FcL) columns, the model's nonlinear parameters (log eta), the delay.
  struct StartParam {
    int index = 0;  // in x
    int kind = 0;   // 0: log eta, 1: dK, 2: FcL, 3: delay
    std::string name;
  };
  struct Window {
    int start = 0;  // the recorded sample it starts from
    int first = 0;  // its first fitted sample's index in keep_t_
    int count = 0;  // fitted samples (start + 1 .. start + count)
  };

  // didim.cpp: the estimate and its details
  void describeResult(const Run& r, int best, const std::vector<Run>& runs, exid::Json check_json,
                      const exid::Dataset& data, std::chrono::steady_clock::time_point t0,
                      exid::Estimate* e) const;
  exid::Estimate finish(const exid::ObservationModel& model, const Sim& s, const VectorXd& x,
                        long m) const;
  exid::estimators::LsSolution solution(const exid::ObservationModel& model, const Sim& s,
                                        const VectorXd& x, long m, MatrixXd* C) const;
  void describeDelay(const VectorXd& x, const exid::Estimate& e, exid::Json* d) const;
  void describeGainPrior(const exid::ObservationModel& model, const exid::estimators::LsSolution& L,
                         const VectorXd& x, exid::Json* d) const;
  void describeMethod(exid::Json* d) const;
  static exid::estimators::ClosedLoop::Tolerances withSensitivities(
      exid::estimators::ClosedLoop::Tolerances t, const std::string& how);

  // didim_simulation.cpp: the samples, the simulation, the least-squares starts
  void chooseSamples(const exid::ObservationModel& model, const exid::Dataset& data, int n, int K,
                     const exid::RunContext& ctx);
  VectorXd firstStart(const exid::ObservationModel& model, const exid::Dataset& data,
                      const exid::RunContext& ctx) const;
  VectorXd startFit(const exid::ObservationModel& model, const exid::Rows& R,
                    const std::vector<int>& cols, const VectorXd& at) const;
  Sim simulate(const VectorXd& xv, const exid::Dataset& data, bool sens,
               const Sim* along = nullptr) const;
  exid::Json gradientCheck(const VectorXd& theta, const exid::Dataset& data, const Sim& s) const;

  // didim_lm.cpp: Levenberg-Marquardt, the gain prior, the starts
  void setPrior(const exid::ObservationModel& model);
  double priorRss(const VectorXd& x, double sigma) const;
  void priorTerms(const VectorXd& x, double sigma, Sim* s) const;
  Run startRun(const VectorXd& x, const exid::Dataset& data, double sigma) const;
  double noiseStd(const Sim& s) const;
  void record(Run* r, const Sim& s, double rho = 0.0, double damping = 0.0, int trials = 0) const;
  void prepare(Run* rp) const;
  void iterate(Run* rp, int limit, const exid::Dataset& data, const exid::RunContext& ctx) const;
  void conclude(Run* rp) const;
  std::vector<StartParam> startParams(const exid::ObservationModel& model) const;
  static double startMultiple(int i);
  double samplePeriod() const;
  VectorXd startPoint(const exid::ObservationModel& model, const exid::Dataset& data,
                      const exid::RunContext& ctx, const VectorXd& x0, int i) const;
  Run failedRun(const VectorXd& x, const std::string& error) const;
  std::string startName(int i) const;
  int multiStart(const exid::ObservationModel& model, const exid::Dataset& data,
                 const exid::RunContext& ctx, std::vector<Run>* runs) const;
  int lowest(const std::vector<Run>& runs, double sigma) const;
  void describeStarts(const std::vector<Run>& runs, int best, exid::Json* d) const;

  exid::ParamSet P_;
  bool position_;
  int max_iter_;
  double ftol_, xtol_, first_order_std_;
  exid::estimators::ClosedLoop::Tolerances tol_loop_;
  int check_;
  bool secant_;
  bool fit_nl_;
  std::vector<double> prior_std_, prior_mean_;
  bool delay_ = false;
  double delay0_ = 0.0, delay_max_ = 0.0;
  int L_ = 0, p_ = 0, D_ = 0;   // nonlinear parameters fitted; base parameters; the delay (0, 1)
  std::vector<int> prior_col_;  // the drive gains' base columns
  VectorXd prior_sd_, prior_mu_;
  double sigma_ = 0.0;        // the noise std the prior's weight used at the kept start
  long m_ = 0;                // outputs fitted
  double floor_sigma_ = 0.0;  // the floor of the prior weight's noise std
  int starts_ = 1, start_iter_ = 5;
  double spread_ = 0.25;
  std::vector<double> keep_t_;  // the times of the samples fitted
  bool open_ = false;           // loop: open
  double window_s_ = 0.0;
  std::vector<Window> windows_;
  int dropped_ = 0;  // samples left out (measurement_delay_max_s)
  mutable int rejected_bound_ = 0;
  std::unique_ptr<exid::estimators::ClosedLoop> loop_;
  std::vector<StartParam> sp_;  // the parameters the starts move (startParams)
  VectorXd y_;
  int nb_ = 0;  // a floating base's base rows fitted per sample after the joints' outputs
};

}  // namespace exid::didim
