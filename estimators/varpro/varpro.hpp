// exid — estimator `varpro` (varpro.cpp): the plugin class, shared by its sources (not
// installed). varpro.cpp: the plugin, its parameters and the estimate's details;
// varpro_search.cpp: the grid of the globalisation and Levenberg-Marquardt on log(eta);
// varpro_evaluate.cpp: one fit at given nonlinear parameters (one streamed pass over the data).
#pragma once

#include <Eigen/Core>
#include <chrono>
#include <memory>
#include <string>
#include <vector>

#include "exid/eigen_instances.hpp"
#include "exid/estimators/common.hpp"
#include "exid/interfaces.hpp"
#include "exid/signal.hpp"

namespace exid::varpro {

using exid::estimators::RowAccumulator;

// A kept Householder factor F = Q [R; 0] (F k x f, k >= f) in the compact WY form
// Q = H_1 ... H_f = I - V T V^T (V k x f unit lower trapezoidal, T f x f upper triangular: the
// forward accumulation of LAPACK's dlarft), so that applying Q^T to a few columns is two
// matrix products instead of f rank-one updates (varpro_evaluate.cpp).
struct KeptFactor {
  Eigen::MatrixXd V, T, R;
  void compute(const Eigen::MatrixXd& F);
  // X <- Q^T X (X: k rows)
  void applyTransposeTo(Eigen::MatrixXd* X, Eigen::MatrixXd* work) const;
};

// One equation's factor rows from its kept factor of F (F's columns at fcols) and its other
// columns X (k x x; xcols: their columns among nc, the last one y's, = nc; k - f >= x): Q_F^T X,
// the part below R_F factored in place, into acc as [R_F, (Q_F^T X)_top; 0, R_X]: rows with
// the Gram matrix of the equation's rows (varpro_evaluate.cpp).
void emitEquation(RowAccumulator* acc, const KeptFactor& qf, const std::vector<int>& fcols,
                  Eigen::MatrixXd* Xp, const std::vector<int>& xcols, Eigen::Index nc,
                  Eigen::MatrixXd* Ep);

// One kept equation's other columns: X = [the columns of Xall non-zero in its rows, y], each
// row of X one of `rows`; *xcols their columns among nc (colmap of Xall's column, then y's:
// nc), as emitEquation takes them (varpro_evaluate.cpp).
void gatherEquation(const Eigen::MatrixXd& Xall, const std::vector<int>& colmap,
                    const Eigen::VectorXd& y, const std::vector<Eigen::Index>& rows,
                    Eigen::Index nc, Eigen::MatrixXd* Xp, std::vector<int>* xcols);

class VarPro : public exid::Estimator {
 public:
  static constexpr const char* kName = "varpro";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "variable projection: the linear parameters by least squares for given nonlinear ones "
      "(Stribeck velocities, smoothing widths), those by Levenberg-Marquardt with exact "
      "derivatives; standard deviations of all parameters";

  static std::vector<exid::ParamDecl> params();

  explicit VarPro(const exid::ParamSet& p);

  exid::EstimatorSpecs specs() const override {
    exid::EstimatorSpecs s;
    s.streams = true;  // one pass per evaluation, in chunks
    return s;
  }

  exid::Estimate estimate(const exid::ObservationModel& model, const exid::Dataset& data,
                          const exid::Prior* prior, const exid::RunContext& ctx) override;

 private:
  // The fit at one set of nonlinear parameters.
  struct Eval {
    Eigen::VectorXd eta, theta;
    double rss = 0.0;
    double yy = 0.0;                  // ||y||^2
    Eigen::MatrixXd R;                // (p + L + 1)^2 triangular factor of [W D y]
    Eigen::MatrixXd JtJ;              // q x q (Kaufman), in lambda = log(eta)
    Eigen::VectorXd Jtr;              // q
    Eigen::MatrixXd Theta;            // L x q: V = D Theta = d(W theta)/d lambda
    exid::estimators::LsSolution ls;  // (without its statistics: solve(.., true))
    long m = 0;
  };

  // One Levenberg-Marquardt run and where it ended.
  struct Run {
    std::string origin;
    Eigen::VectorXd eta0, lambda;
    Eval cur;
    int evals = 0, iterations = 0;
    std::string stop;
    exid::Json trace = exid::Json::array();
    double gradient_norm = 0.0;  // ||d rss / d log(eta)||
    double gn_fraction = 0.0;    // the part of rss a Gauss-Newton step would remove
    bool exact = false;          // the fit is exact to rounding
    bool stationary = false;     // the first-order test holds
    bool singular = false;       // the joint problem [W V] is singular there
    // the column-scaled SVD of the joint problem (the covariance's)
    Eigen::MatrixXd M;
  };

  // The grid of the globalisation.
  struct Grid {
    Eigen::VectorXd best;  // lambda
    Eval best_eval;
    std::vector<std::vector<int>> groups;
    std::vector<double> multipliers;
    int evaluations = 0, singular = 0, sweeps = 0;
    int checks = 0;  // sweeps around the best end
    // the projected residual (Held::rss) against the whole evaluation at every point taken:
    // how many, and their largest difference relative to ||y||^2
    int projected_checked = 0;
    // and at each held rows' own point (which the screen never takes: its whole evaluation is
    // the grid's best so far), how many; their differences are in projected_difference too
    int held_checked = 0;
    double projected_difference = 0.0;
    long sample_stride = 1;  // points compared on every sample_stride-th sample
  };

  // varpro.cpp: the estimate's details
  exid::Estimate finish(const exid::ObservationModel& model, const std::vector<Run>& runs, int won,
                        const Grid& grid, std::chrono::steady_clock::time_point t0) const;
  void describeSearch(const std::vector<Run>& runs, int won, const Grid& grid, exid::Json* d) const;
  void describeConvergence(const std::vector<Run>& runs, const Run& run, const exid::Estimate& e,
                           std::chrono::steady_clock::time_point t0, exid::Json* d) const;

  // varpro_search.cpp: the globalisation and Levenberg-Marquardt
  std::string where(const Eigen::VectorXd& eta) const;
  std::vector<std::vector<int>> groups() const;
  Grid searchGrid(const exid::ObservationModel& model, const exid::Dataset& data,
                  const Eigen::VectorXd& lambda0, const Eval& at_study,
                  const exid::RunContext& ctx);
  void sweep(const exid::ObservationModel& model, const exid::Dataset& data,
             const Eigen::VectorXd& lambda0, Grid* gp, const exid::RunContext& ctx);
  void axisScan(const exid::ObservationModel& model, const exid::Dataset& data,
                const Eigen::VectorXd& centre, Grid* gp, const exid::RunContext& ctx);
  // The residual at points that move the columns of a few nonlinear parameters, the others
  // held (varpro_search.cpp): a point of the grid or a scan costs the model's rows and the
  // projection of the moved columns, not a whole evaluation.
  struct Held;
  // the eta the rows are built at: the model's parameters, and the delay if fitted
  Eigen::VectorXd heldEta(const Eigen::VectorXd& lambda) const {
    return delay_ ? etaOf(lambda) : Eigen::VectorXd(etaOf(lambda).head(q_model_));
  }
  // A point of the grid or a scan: taken (into *gp) when its residual is below the best so far,
  // the fit confirmed by a whole evaluation there (which also refuses a singular fit).
  void tryPoint(const exid::ObservationModel& model, const exid::Dataset& data, const Held& held,
                const Eigen::VectorXd& lambda, Grid* gp, const exid::RunContext& ctx) const;
  // The held rows' projected residual at their own point (lambda: the grid's best) against its
  // whole evaluation (gp->best_eval), into projected_difference.
  void checkHeld(const exid::ObservationModel& model, const exid::Dataset& data, const Held& held,
                 const Eigen::VectorXd& lambda, Grid* gp, const exid::RunContext& ctx) const;
  static exid::Dataset strided(const exid::Dataset& d, long stride);
  Run levenbergMarquardt(const exid::ObservationModel& model, const exid::Dataset& data,
                         Eigen::VectorXd lambda, Eval cur, const std::string& origin,
                         const exid::RunContext& ctx);
  void firstOrder(const exid::ObservationModel& model, Run* r) const;

  // varpro_evaluate.cpp: one fit at eta, the joint problem
  Eigen::MatrixXd jointMatrix(const exid::ObservationModel& model, const Eval& cur) const;
  static Eigen::VectorXd columnScale(const Eigen::MatrixXd& M);
  bool regular(const Eigen::MatrixXd& M) const;
  void setUp(const exid::ObservationModel& model, const exid::Dataset& data);
  Eigen::VectorXd etaOf(const Eigen::VectorXd& lambda) const;
  exid::Rows chunkRows(const exid::ObservationModel& model, exid::SampleWindow& window, int b,
                       int end, const Eigen::VectorXd& eta, Eigen::MatrixXd* D,
                       const exid::RunContext& ctx) const;
  // rank_checked: the caller tests the joint problem's regularity (regular(), which implies
  // W's at the same tolerance) and rejects the point otherwise: theta by back substitution in
  // R11 instead of the rank-revealing SVD (a theta that is not finite is refused as singular).
  Eval evaluate(const exid::ObservationModel& model, const exid::Dataset& data,
                const Eigen::VectorXd& lambda, const exid::RunContext& ctx,
                bool rank_checked = false) const;
  // The fixed columns' (those no nonlinear parameter moves) rows and per-equation factors, kept
  // from one evaluation to the next (varpro_evaluate.cpp: addChunk), and read by the grid's held
  // rows (varpro_search.cpp: Held); reset by setUp.
  struct FixedFactors {
    struct Equation {
      std::vector<Eigen::Index> rows;  // the chunk's rows of this equation
      std::vector<int> cols;           // F's columns (base) in these rows
      Eigen::MatrixXd F;               // k x f, as the rows gave it
      KeptFactor qr;                   // of F
    };
    struct Chunk {
      // in label order; each kept factor immutable once made (a new one replaces it), so that
      // the grid's held rows can share it (Held's parts)
      std::vector<std::shared_ptr<const Equation>> eqs;
      Eigen::VectorXd y;
      std::vector<int> equation;  // each row's label
      bool whole = false;         // every equation's F kept
      bool confirmed = false;     // and found again, with the same y, by a later evaluation
    };
    std::vector<Chunk> chunks;
    double bytes = 0.0;
  };
  void addChunk(RowAccumulator* acc, std::size_t chunk, const Eigen::MatrixXd& A,
                const Eigen::VectorXd& y, const std::vector<int>& equation, int p) const;
  void addChunkKept(RowAccumulator* acc, std::size_t chunk, const Eigen::MatrixXd& Xall,
                    const std::vector<int>& cols, Eigen::Index nc) const;
  bool fixedConfirmed(std::size_t chunks) const;
  exid::estimators::LsSolution solve(const exid::ObservationModel& model, const Eval& e,
                                     bool statistics) const;
  std::vector<std::string> names() const;

  int max_evals_;
  double xtol_, ftol_;
  int starts_;
  static constexpr int kGridSamples = 4000;
  // the held columns' rows kept for the grid's points at most (else whole evaluations)
  static constexpr double kHeldBytes = 128e6;
  static constexpr int kRounds = 6;  // checks around the best end, while one finds a lower point
  // x1/32 .. x32 in steps of sqrt(2), x1 left out (the centre)
  static constexpr double kAxisMultipliers[] = {0.03125,
                                                0.04419417382415922,
                                                0.0625,
                                                0.08838834764831845,
                                                0.125,
                                                0.1767766952966369,
                                                0.25,
                                                0.3535533905932738,
                                                0.5,
                                                0.7071067811865476,
                                                1.414213562373095,
                                                2.0,
                                                2.82842712474619,
                                                4.0,
                                                5.656854249492381,
                                                8.0,
                                                11.31370849898476,
                                                16.0,
                                                22.62741699796952,
                                                32.0};
  double gtol_;
  bool project_;  // grid_points: projected
  int chunk_;
  RowAccumulator::Method method_;
  exid::estimators::SolveOptions opt_;
  std::vector<exid::NonlinearParameter> nl_;
  std::vector<int> keep_, owner_, base_col_;  // per derivative column (the delay's: keep -1)
  int rejected_singular_ = 0;                 // trial steps where the fit was singular
  int rejected_bound_ = 0;                    // trial delays beyond measurement_delay_max_s
  int q_model_ = 0;                           // the model's nonlinear parameters (first in nl_)
  bool delay_ = false;
  double delay0_ = 0.0, delay_max_ = 0.0;
  double ts_ = 1.0;  // [s] the median sample period (the delay's lambda unit)
  int margin_ = 0;   // samples at each end without rows (measurement_delay)
  mutable std::shared_ptr<FixedFactors> fixed_;
};

}  // namespace exid::varpro
