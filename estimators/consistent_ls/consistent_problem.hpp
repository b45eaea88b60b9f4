// exid — estimator `consistent_ls` (consistent_ls.cpp): the consistent problem, shared by its
// sources (not installed): the map z -> standard parameters (log-Cholesky per body, scaled
// scalars), the objective ||A pi(z) - b||^2, its start, the linearised covariance and the
// physical checks. consistent_problem.cpp defines them; consistent_ls.cpp is the estimator.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cmath>
#include <map>
#include <nlopt.hpp>
#include <optional>
#include <string>
#include <vector>

#include "exid/estimators/common.hpp"
#include "exid/estimators/consistent.hpp"
#include "exid/interfaces.hpp"

namespace exid::consistent_ls {

using exid::Json;
using exid::estimators::RowAccumulator;
using exid::estimators::Vec10;

inline std::vector<double> toStd(const Eigen::VectorXd& v) {
  return {v.data(), v.data() + v.size()};
}

/// The map z -> full standard parameter vector (model.fullNames() order).
class StandardMap {
 public:
  StandardMap(const std::vector<std::string>& names, const Eigen::VectorXd& nominal);

  int nz() const { return nz_; }
  int nfull() const { return nfull_; }
  int numBodies() const { return static_cast<int>(bodies_.size()); }
  int bodyNumber(int b) const { return body_numbers_[static_cast<std::size_t>(b)]; }
  const std::array<int, 10>& bodyIndices(int b) const {
    return bodies_[static_cast<std::size_t>(b)];
  }
  int numScalars() const { return static_cast<int>(scalars_.size()); }
  bool nonneg(int s) const { return nonneg_[static_cast<std::size_t>(s)]; }
  int scalarIndex(int s) const { return scalars_[static_cast<std::size_t>(s)]; }
  int zOfScalar(int s) const { return 10 * numBodies() + s; }

  void lowerBounds(std::vector<double>* lb) const;
  Eigen::VectorXd pi(const Eigen::VectorXd& z) const;
  /// dpi/dz (n_full x nz).
  Eigen::MatrixXd jacobian(const Eigen::VectorXd& z) const;
  /// g_z = (dpi/dz)^T g_pi.
  Eigen::VectorXd vjp(const Eigen::VectorXd& z, const Eigen::VectorXd& g) const;
  /// z of the nearest consistent point to a full standard vector (bodies: eigenvalues of J
  /// raised to eig_floor; non-negative scalars clamped at 0).
  Eigen::VectorXd fromStandard(const Eigen::VectorXd& pi, double eig_floor, int* projected) const;
  /// A floor for the eigenvalues of the pseudo-inertias: relative to the largest body.
  double eigFloor(const Eigen::VectorXd& pi) const;

 private:
  int nfull_ = 0, nz_ = 0;
  std::vector<std::array<int, 10>> bodies_;
  std::vector<int> body_numbers_;
  std::vector<int> scalars_;
  std::vector<bool> nonneg_;
  std::vector<double> scale_;
  std::vector<double> diag_floor_;
};

/// f(z) = ||A pi(z) - b||^2.
struct Problem {
  const StandardMap* map = nullptr;
  Eigen::MatrixXd A;  // (p+1) x n_full: F_w K (standard prior: + n_full rows D^-1)
  Eigen::VectorXd b;
  long evaluations = 0;
  double best_f = HUGE_VAL;
  Eigen::VectorXd best_z;
  const exid::RunContext* ctx = nullptr;

  double value(const Eigen::VectorXd& z, Eigen::VectorXd* grad) {
    ++evaluations;
    const Eigen::VectorXd r = A * map->pi(z) - b;
    const double f = r.squaredNorm();
    if (grad) *grad = map->vjp(z, 2.0 * (A.transpose() * r));
    if (std::isfinite(f) && f < best_f) {
      best_f = f;
      best_z = z;
    }
    return f;
  }
};

/// NLopt's objective: Problem::value at x (data: the Problem); a stopped run stops NLopt.
double nloptObjective(unsigned n, const double* x, double* grad, void* data);

/// The NLopt algorithm named by the parameter `algorithm`.
nlopt::algorithm algorithmFromName(const std::string& a);

/// The rows compressed per equation, and per block of samples and equation (for
/// cross-validation of the prior's scale).
struct EquationRows {
  std::map<int, RowAccumulator> acc;
  std::vector<std::map<int, RowAccumulator>> blocks;
};

/// The weighted linear problem ConsistentLs::estimate starts from: the noise-normalised rows,
/// the prior (its scale chosen), and their unconstrained least-squares solution.
struct LinearStage {
  std::map<int, RowAccumulator> acc;  // per equation, unweighted
  long m = 0;                         // rows
  RowAccumulator weighted;            // noise-normalised rows
  RowAccumulator total;               // weighted + the prior's pseudo-observations
  Json eq_table = Json::array();
  std::optional<exid::Prior> used_prior;
  Json scale_details = Json::object();
  exid::estimators::LsSolution unc;  // unconstrained solution of total
  Eigen::MatrixXd Fw;                // total's factor [Fw fy]
  Eigen::VectorXd fy;
};

/// The consistent problem's start: the nominal (or prior) standard parameters or the
/// unconstrained solution completed with them, projected to consistency.
struct StartPoint {
  Eigen::VectorXd z0, pi_unc;
  std::string started = "nominal";
  int projected_nominal = 0, projected_unc = 0;
};

/// The consistent problem: f(z) = ||A pi(z) - b||^2 with
///   prior on the base parameters:     A = F K,                  b = f      (F: data + prior)
///   prior on the standard parameters: A = [F_d K; D^-1],        b = [f_d; D^-1 pi0]
/// (F_d: data only, D = diag of the scaled standard prior std). In the linear problem both
/// give the same base parameters (K pi ~ N(K pi0, K D^2 K^T)); with the consistency
/// constraints, the standard form keeps each body near its prior instead of letting the
/// unidentifiable combinations wander off to satisfy them. dinv: D^-1 (standard prior).
void setObjective(const LinearStage& lin, const Eigen::MatrixXd& K, int p, int nfull,
                  bool std_prior, Problem* P, Eigen::VectorXd* dinv, const char* name);

/// The start point (start: nominal, unconstrained or best; best compares f at both).
StartPoint startPoint(const StandardMap& map, Problem& P, const Eigen::MatrixXd& K,
                      const Eigen::VectorXd& theta_unc, const Eigen::VectorXd& pi0,
                      const Eigen::VectorXd& dinv, bool std_prior, const std::string& start);

/// Linearised covariance of theta = K pi(z), the variables at an active bound held fixed:
/// Cov = J_b (J_z^T A^T A J_z)^+ J_b^T, J_z = dpi/dz, J_b = K J_z.
Eigen::MatrixXd linearisedCovariance(const StandardMap& map, const Problem& P,
                                     const Eigen::MatrixXd& K, const Eigen::VectorXd& z,
                                     const Eigen::VectorXd& pi, const std::vector<double>& lb,
                                     int* lin_rank);

/// Per body of the consistent standard parameters: mass, COM and the physical checks; all_ok:
/// every pseudo-inertia positive definite and every non-negative scalar >= 0.
Json bodyChecks(const StandardMap& map, const Eigen::VectorXd& pi, bool* all_ok);

/// A consistent fit the data disagree with is no result to trust silently: say so, with the
/// likely causes (these reach summary.json's warnings).
Json plausibilityWarnings(const StandardMap& map, const Eigen::VectorXd& pi,
                          const Eigen::VectorXd& nom, double rms_c, double rms_u, const char* name);

/// standard_parameters.csv in the run's folder (exid export writes them into a URDF); a file
/// that cannot be written is left out.
void writeStandardCsv(const exid::RunContext& ctx, const std::vector<std::string>& full_names,
                      const Eigen::VectorXd& pi, Json& d);

}  // namespace exid::consistent_ls
