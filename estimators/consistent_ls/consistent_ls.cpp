// exid — estimator `consistent_ls`: (weighted) least squares of the base parameters with the
// STANDARD parameters behind them physically consistent by construction.
//
//   theta_b = K pi(z),  pi(z): per body the log-Cholesky map of the pseudo-inertia (J = U U^T,
//   U upper triangular with exp on the diagonal: mass > 0, inertia about the COM positive
//   definite, triangle inequalities), rotor inertias and friction coefficients Ia, Fc, Fv >= 0
//   (scaled, bound-constrained), offsets and any other column free (scaled);
//   minimise ||F_w K pi(z) - f_y||^2 (+ prior)
// where [F_w f_y] is the QR-compressed factor of the (noise-normalised) rows [W y] stacked with
// the prior's pseudo-observations, so one evaluation costs O(p * n_full), not O(rows). NLopt
// (LD_LBFGS by default) with exact gradients, then a Levenberg-Marquardt polish with the exact
// Jacobian. The prior's scale is fixed or chosen on the identification data (blocked
// cross-validation or evidence, exid/estimators/prior_scale.hpp). See docs/consistent.md.
#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <Eigen/QR>
#include <Eigen/SVD>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <nlopt.hpp>
#include <optional>

#include "exid/drive.hpp"
#include "exid/error.hpp"
#include "exid/estimators/common.hpp"
#include "exid/estimators/consistent.hpp"
#include "exid/estimators/prior_scale.hpp"
#include "exid/interfaces.hpp"
#include "exid/io.hpp"

namespace {

using exid::Json;
using exid::estimators::RowAccumulator;
using exid::estimators::Vec10;

std::vector<double> toStd(const Eigen::VectorXd& v) { return {v.data(), v.data() + v.size()}; }

/// The map z -> full standard parameter vector (model.fullNames() order).
// Implausible results are warnings: the consistent fit's residual above this many times the
// unconstrained one (noise alone moves it by a few percent), a body's mass this many times off
// the robot description's (heavier only: a body the motion barely excites often comes out light).
constexpr double kResidualRatioWarn = 1.2;
constexpr double kMassRatioWarn = 10.0;

class StandardMap {
 public:
  StandardMap(const std::vector<std::string>& names, const Eigen::VectorXd& nominal)
      : nfull_(static_cast<int>(names.size())) {
    std::map<int, std::array<int, 10>> groups;
    std::vector<int> group_of(names.size(), -1);
    for (std::size_t i = 0; i < names.size(); ++i) {
      int k = -1;
      int body = -1;
      // two-letter prefixes first ("MX1" before "M1")
      for (int pass = 0; pass < 2 && k < 0; ++pass) {
        for (int c = 0; c < 10; ++c) {
          const std::string pre = exid::kInertialNames[c];
          if (static_cast<int>(pre.size()) != 2 - pass) continue;
          if (names[i].size() > pre.size() && names[i].compare(0, pre.size(), pre) == 0) {
            const std::string rest = names[i].substr(pre.size());
            if (rest.find_first_not_of("0123456789") == std::string::npos && rest[0] != '0') {
              k = c;
              body = std::stoi(rest);
              break;
            }
          }
        }
      }
      if (k >= 0) {
        auto it = groups.find(body);
        if (it == groups.end()) {
          std::array<int, 10> a;
          a.fill(-1);
          it = groups.emplace(body, a).first;
        }
        it->second[static_cast<std::size_t>(k)] = static_cast<int>(i);
      }
    }
    std::vector<bool> used(names.size(), false);
    for (const auto& [body, idx] : groups) {
      bool complete = true;
      for (int v : idx) complete = complete && v >= 0;
      if (!complete) continue;
      bodies_.push_back(idx);
      body_numbers_.push_back(body);
      for (int v : idx) used[static_cast<std::size_t>(v)] = true;
    }
    for (std::size_t i = 0; i < names.size(); ++i) {
      if (used[i]) continue;
      scalars_.push_back(static_cast<int>(i));
      // rotor inertia and friction coefficients are >= 0; offsets are free
      nonneg_.push_back(exid::isDriveParameterName(names[i]) && names[i].rfind("OFF", 0) != 0);
      const double v = std::abs(nominal(static_cast<Eigen::Index>(i)));
      scale_.push_back(v > 0 && std::isfinite(v) ? v : 1.0);
    }
    nz_ = 10 * static_cast<int>(bodies_.size()) + static_cast<int>(scalars_.size());
    // Lower bound on log U_kk: keeps J strictly positive definite by a margin ~ (1e-5)^2 of the
    // body's own size (log-Cholesky reaches the semi-definite boundary only at -inf, where the
    // optimiser would crawl and rounding would break the strict inequalities).
    for (const auto& idx : bodies_) {
      Vec10 p;
      for (int k = 0; k < 10; ++k) p(k) = nominal(idx[static_cast<std::size_t>(k)]);
      const double tr = exid::estimators::pseudoInertia(p).trace();
      diag_floor_.push_back(
          std::log(1e-5 * std::sqrt(std::max(std::isfinite(tr) ? tr : 0.0, 1e-6))));
    }
  }

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

  void lowerBounds(std::vector<double>* lb) const {
    lb->assign(static_cast<std::size_t>(nz_), -HUGE_VAL);
    for (int b = 0; b < numBodies(); ++b)
      for (int k = 0; k < 4; ++k)
        (*lb)[static_cast<std::size_t>(10 * b + k)] = diag_floor_[static_cast<std::size_t>(b)];
    for (int s = 0; s < numScalars(); ++s)
      if (nonneg(s)) (*lb)[static_cast<std::size_t>(zOfScalar(s))] = 0.0;
  }

  Eigen::VectorXd pi(const Eigen::VectorXd& z) const {
    Eigen::VectorXd out = Eigen::VectorXd::Zero(nfull_);
    for (int b = 0; b < numBodies(); ++b) {
      const Vec10 p = exid::estimators::logCholeskyToInertial(z.segment<10>(10 * b));
      for (int k = 0; k < 10; ++k) out(bodyIndices(b)[static_cast<std::size_t>(k)]) = p(k);
    }
    for (int s = 0; s < numScalars(); ++s)
      out(scalarIndex(s)) = scale_[static_cast<std::size_t>(s)] * z(zOfScalar(s));
    return out;
  }

  /// dpi/dz (n_full x nz).
  Eigen::MatrixXd jacobian(const Eigen::VectorXd& z) const {
    Eigen::MatrixXd Jz = Eigen::MatrixXd::Zero(nfull_, nz_);
    for (int b = 0; b < numBodies(); ++b) {
      const Eigen::Matrix<double, 10, 10> J =
          exid::estimators::logCholeskyJacobian(z.segment<10>(10 * b));
      for (int k = 0; k < 10; ++k)
        Jz.block(bodyIndices(b)[static_cast<std::size_t>(k)], 10 * b, 1, 10) = J.row(k);
    }
    for (int s = 0; s < numScalars(); ++s)
      Jz(scalarIndex(s), zOfScalar(s)) = scale_[static_cast<std::size_t>(s)];
    return Jz;
  }

  /// g_z = (dpi/dz)^T g_pi.
  Eigen::VectorXd vjp(const Eigen::VectorXd& z, const Eigen::VectorXd& g) const {
    Eigen::VectorXd out(nz_);
    for (int b = 0; b < numBodies(); ++b) {
      Vec10 gb;
      for (int k = 0; k < 10; ++k) gb(k) = g(bodyIndices(b)[static_cast<std::size_t>(k)]);
      out.segment<10>(10 * b) = exid::estimators::logCholeskyVjp(z.segment<10>(10 * b), gb);
    }
    for (int s = 0; s < numScalars(); ++s)
      out(zOfScalar(s)) = scale_[static_cast<std::size_t>(s)] * g(scalarIndex(s));
    return out;
  }

  /// z of the nearest consistent point to a full standard vector (bodies: eigenvalues of J
  /// raised to eig_floor; non-negative scalars clamped at 0).
  Eigen::VectorXd fromStandard(const Eigen::VectorXd& pi, double eig_floor, int* projected) const {
    Eigen::VectorXd z(nz_);
    int count = 0;
    for (int b = 0; b < numBodies(); ++b) {
      Vec10 p;
      for (int k = 0; k < 10; ++k) p(k) = pi(bodyIndices(b)[static_cast<std::size_t>(k)]);
      bool proj = false;
      z.segment<10>(10 * b) = exid::estimators::logCholeskyFromInertial(p, eig_floor, &proj);
      count += proj ? 1 : 0;
    }
    for (int s = 0; s < numScalars(); ++s) {
      double v = pi(scalarIndex(s)) / scale_[static_cast<std::size_t>(s)];
      if (nonneg(s) && v < 0) {
        v = 0;
        ++count;
      }
      z(zOfScalar(s)) = v;
    }
    if (projected) *projected = count;
    return z;
  }

  /// A floor for the eigenvalues of the pseudo-inertias: relative to the largest body.
  double eigFloor(const Eigen::VectorXd& pi) const {
    double big = 0.0;
    for (int b = 0; b < numBodies(); ++b) {
      Vec10 p;
      for (int k = 0; k < 10; ++k) p(k) = pi(bodyIndices(b)[static_cast<std::size_t>(k)]);
      big = std::max(big, exid::estimators::pseudoInertia(p).trace());
    }
    return std::max(1e-8 * big, 1e-12);
  }

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

double nloptObjective(unsigned n, const double* x, double* grad, void* data) {
  auto* P = static_cast<Problem*>(data);
  if (P->ctx && P->ctx->shouldStop()) throw nlopt::forced_stop();
  const Eigen::Map<const Eigen::VectorXd> z(x, n);
  Eigen::VectorXd g;
  const double f = P->value(z, grad ? &g : nullptr);
  if (grad) Eigen::Map<Eigen::VectorXd>(grad, n) = g;
  return std::isfinite(f) ? f : HUGE_VAL;
}

nlopt::algorithm algorithmFromName(const std::string& a) {
  if (a == "LD_LBFGS") return nlopt::LD_LBFGS;
  if (a == "LD_SLSQP") return nlopt::LD_SLSQP;
  if (a == "LD_MMA") return nlopt::LD_MMA;
  if (a == "LD_TNEWTON_PRECOND_RESTART") return nlopt::LD_TNEWTON_PRECOND_RESTART;
  return nlopt::LD_VAR2;
}

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
                  bool std_prior, Problem* P, Eigen::VectorXd* dinv, const char* name) {
  if (std_prior) {
    *dinv = lin.used_prior->standard_std.cwiseInverse();
    exid::check(dinv->allFinite(),
                fmt::format("{}: prior_on: standard needs every standard prior std > 0 (give "
                            "prior.absolute_std > 0)",
                            name));
    const Eigen::MatrixXd& Fd = lin.weighted.factor();  // (p+1) x (p+1), last row: the residual
    P->A.resize(p + 1 + nfull, nfull);
    P->A.topRows(p + 1) = Fd.leftCols(p) * K;
    P->A.bottomRows(nfull) = dinv->asDiagonal();
    P->b.resize(p + 1 + nfull);
    P->b.head(p + 1) = Fd.col(p);
    P->b.tail(nfull) = dinv->cwiseProduct(lin.used_prior->standard_value);
  } else {
    P->A = lin.Fw * K;
    P->b = lin.fy;
  }
}

/// The start point (start: nominal, unconstrained or best; best compares f at both).
StartPoint startPoint(const StandardMap& map, Problem& P, const Eigen::MatrixXd& K,
                      const Eigen::VectorXd& theta_unc, const Eigen::VectorXd& pi0,
                      const Eigen::VectorXd& dinv, bool std_prior, const std::string& start) {
  StartPoint st;
  const double floor = map.eigFloor(pi0);
  const Eigen::VectorXd z_nom = map.fromStandard(pi0, floor, &st.projected_nominal);
  st.z0 = z_nom;
  // The unconstrained solution completed with the nominal values: pi_u = pi0 + dpi, K dpi =
  // theta_u - K pi0, dpi of least norm (standard prior: least D^-1-weighted norm, which makes
  // pi_u the linear problem's own minimiser, so f_unc below is the same objective's value).
  Eigen::VectorXd dpi;
  if (std_prior) {
    const Eigen::MatrixXd KD = K * dinv.cwiseInverse().asDiagonal();
    dpi = dinv.cwiseInverse().asDiagonal() *
          KD.completeOrthogonalDecomposition().solve(theta_unc - K * pi0);
  } else {
    dpi = K.completeOrthogonalDecomposition().solve(theta_unc - K * pi0);
  }
  st.pi_unc = pi0 + dpi;
  if (start != "nominal") {
    const Eigen::VectorXd z_unc = map.fromStandard(st.pi_unc, floor, &st.projected_unc);
    if (start == "unconstrained" || P.value(z_unc, nullptr) < P.value(z_nom, nullptr)) {
      st.z0 = z_unc;
      st.started = "unconstrained";
    }
  }
  return st;
}

/// Linearised covariance of theta = K pi(z), the variables at an active bound held fixed:
/// Cov = J_b (J_z^T A^T A J_z)^+ J_b^T, J_z = dpi/dz, J_b = K J_z.
Eigen::MatrixXd linearisedCovariance(const StandardMap& map, const Problem& P,
                                     const Eigen::MatrixXd& K, const Eigen::VectorXd& z,
                                     const Eigen::VectorXd& pi, const std::vector<double>& lb,
                                     int* lin_rank) {
  Eigen::MatrixXd Jz = map.jacobian(z);
  {
    Eigen::VectorXd g = map.vjp(z, 2.0 * (P.A.transpose() * (P.A * pi - P.b)));
    for (int k = 0; k < map.nz(); ++k)
      if (std::isfinite(lb[static_cast<std::size_t>(k)]) &&
          z(k) <= lb[static_cast<std::size_t>(k)] && g(k) >= 0.0)
        Jz.col(k).setZero();
  }
  const Eigen::MatrixXd Jb = K * Jz;
  const Eigen::MatrixXd JA = P.A * Jz;
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(JA, Eigen::ComputeThinV);
  const Eigen::VectorXd sv = svd.singularValues();
  Eigen::VectorXd sinv2 = Eigen::VectorXd::Zero(sv.size());
  *lin_rank = 0;
  for (Eigen::Index i = 0; i < sv.size(); ++i)
    if (sv(0) > 0 && sv(i) > 1e-9 * sv(0)) {
      sinv2(i) = 1.0 / (sv(i) * sv(i));
      ++*lin_rank;
    }
  const Eigen::MatrixXd JV = Jb * svd.matrixV();
  Eigen::MatrixXd cov = JV * sinv2.asDiagonal() * JV.transpose();
  cov = 0.5 * (cov + cov.transpose());
  return cov;
}

/// Per body of the consistent standard parameters: mass, COM and the physical checks; all_ok:
/// every pseudo-inertia positive definite and every non-negative scalar >= 0.
Json bodyChecks(const StandardMap& map, const Eigen::VectorXd& pi, bool* all_ok) {
  Json bodies = Json::array();
  *all_ok = true;
  for (int b = 0; b < map.numBodies(); ++b) {
    Vec10 pb;
    for (int k = 0; k < 10; ++k) pb(k) = pi(map.bodyIndices(b)[static_cast<std::size_t>(k)]);
    const exid::InertiaCheck chk = exid::checkPhysical(pb, 0.0);
    const double lmin = exid::estimators::pseudoInertiaMinEigenvalue(pb);
    *all_ok = *all_ok && lmin > 0;
    Json jb = Json::object();
    jb["body"] = map.bodyNumber(b);
    jb["mass"] = pb(9);
    jb["com"] = Json(std::vector<double>{pb(6) / pb(9), pb(7) / pb(9), pb(8) / pb(9)});
    jb["pseudo_inertia_min_eigenvalue"] = lmin;
    jb["check"] = chk.ok ? std::string("ok") : chk.rule;
    bodies.push_back(jb);
  }
  for (int s = 0; s < map.numScalars(); ++s)
    if (map.nonneg(s)) *all_ok = *all_ok && pi(map.scalarIndex(s)) >= 0.0;
  return bodies;
}

/// A consistent fit the data disagree with is no result to trust silently: say so, with the
/// likely causes (these reach summary.json's warnings).
Json plausibilityWarnings(const StandardMap& map, const Eigen::VectorXd& pi,
                          const Eigen::VectorXd& nom, double rms_c, double rms_u,
                          const char* name) {
  Json w = Json::array();
  const double ratio = rms_u > 0 ? rms_c / rms_u : 1.0;
  if (ratio > kResidualRatioWarn)
    w.push_back(Json(fmt::format(
        "{}: the physically consistent fit leaves a residual {:.2f} times the unconstrained "
        "fit's ({:.4g} against {:.4g}): the data ask for a physically impossible model. "
        "Likely causes: a torque of the opposite sign to the joint (tau_scale: -1 for it; "
        "`exid inspect` checks each joint), a wrong transmission or torque scale, "
        "unmodelled friction, or a delay between position and torque",
        name, ratio, rms_c, rms_u)));
  for (int b = 0; b < map.numBodies(); ++b) {
    const double m_est = pi(map.bodyIndices(b)[9]), m_nom = nom(map.bodyIndices(b)[9]);
    if (m_nom > 0 && std::isfinite(m_nom) && m_est > kMassRatioWarn * m_nom)
      w.push_back(Json(fmt::format(
          "{}: body {} has a mass of {:.4g} kg against {:.4g} kg in the robot description "
          "(more than {:g} times heavier): the masses of a chain are identified only through "
          "the torques they cause, so a mass this far off usually means a torque of the "
          "opposite sign (tau_scale: -1 for it), a wrong torque scale or transmission, or a "
          "body the motion does not excite",
          name, map.bodyNumber(b), m_est, m_nom, kMassRatioWarn)));
  }
  return w;
}

/// standard_parameters.csv in the run's folder (exid export writes them into a URDF); a file
/// that cannot be written is left out.
void writeStandardCsv(const exid::RunContext& ctx, const std::vector<std::string>& full_names,
                      const Eigen::VectorXd& pi, Json& d) {
  if (ctx.out_dir.empty()) return;
  std::string csv = "name,value\n";
  for (Eigen::Index i = 0; i < pi.size(); ++i)
    csv += fmt::format("{},{:.17g}\n", full_names[static_cast<std::size_t>(i)], pi(i));
  try {
    exid::writeFileAtomic(ctx.out_dir / "standard_parameters.csv", csv);
    d["standard_parameters_csv"] = "standard_parameters.csv";
  } catch (const std::exception&) {
  }
}

class ConsistentLs : public exid::Estimator {
 public:
  static constexpr const char* kName = "consistent_ls";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "least squares of the base parameters with physically consistent standard parameters behind "
      "them (log-Cholesky pseudo-inertia per body, Ia/Fc/Fv >= 0), per-equation weights, optional "
      "prior (scale fixed, or by blocked cross-validation or evidence); NLopt with exact "
      "gradients + Levenberg-Marquardt polish";

  static std::vector<exid::ParamDecl> params() {
    return {
        exid::param_string(
            "weighting", std::string("equation"),
            "equation: each equation's rows divided by its residual std (wls, Gautier); "
            "none: one std for all rows (OLS)",
            {"equation", "none"}),
        exid::param_double("prior_scale", 1.0, "",
                           "with prior_scale_selection: none, every prior standard deviation "
                           "is multiplied by this",
                           0.0, std::nullopt, true),
        exid::param_string(
            "prior_on", std::string("standard"),
            "standard: the prior acts on the standard parameters inside the consistent fit "
            "(||D^-1 (pi - pi0)||^2, D = the prior's standard deviations; needs a prior from the "
            "robot, otherwise base is used); base: on the base parameters only (K pi), the "
            "standard parameters are then any consistent completion",
            {"standard", "base"}),
        exid::param_string(
            "prior_scale_selection", std::string("none"),
            "none: prior_scale as given; cv: blocked cross-validation on the identification "
            "samples (cv_blocks contiguous blocks) over a log grid in prior_scale_range; "
            "evidence: type-II maximum likelihood (MacKay) of the scale and a common noise "
            "variance. Both on the weighted linear (prior-regularised) problem",
            {"none", "cv", "evidence"}),
        exid::param_int("cv_blocks", 5,
                        "contiguous blocks of samples for prior_scale_selection: cv", 2.0, 1000.0),
        exid::param_doubles("prior_scale_range", std::vector<double>{0.01, 100.0}, "",
                            "[lo, hi] of the scales searched by prior_scale_selection (cv: 8 "
                            "log-spaced candidates per decade)",
                            2, 2),
        exid::param_string(
            "algorithm", std::string("LD_LBFGS"),
            "NLopt algorithm (exact gradients); none: Levenberg-Marquardt only",
            {"LD_LBFGS", "LD_SLSQP", "LD_MMA", "LD_TNEWTON_PRECOND_RESTART", "none"}),
        exid::param_int("max_evaluations", 3000, "NLopt evaluations (each O(p n_full))", 1.0, 1e8),
        exid::param_int("polish_iterations", 300,
                        "Levenberg-Marquardt iterations after NLopt (0: none)", 0.0, 1e6),
        exid::param_string(
            "start", std::string("best"),
            "nominal: the robot description projected to consistency; unconstrained: "
            "the (prior-regularised) least-squares solution completed with the nominal "
            "values and projected; best: whichever fits better",
            {"nominal", "unconstrained", "best"}),
        exid::param_int("chunk_samples", 4096, "samples per chunk passed to the model", 1.0, 1e9),
        exid::param_int("max_equations", 1000, "refuse more distinct equations than this", 1.0,
                        1e6),
        exid::estimators::rankToleranceParam(),
    };
  }

  explicit ConsistentLs(const exid::ParamSet& p)
      : weighting_(p.getString("weighting")),
        prior_on_(p.getString("prior_on")),
        algorithm_(p.getString("algorithm")),
        start_(p.getString("start")),
        scale_selection_(p.getString("prior_scale_selection")),
        scale_range_(p.getDoubles("prior_scale_range")),
        prior_scale_(p.getDouble("prior_scale")),
        cv_blocks_(static_cast<int>(p.getInt("cv_blocks"))),
        max_eval_(static_cast<int>(p.getInt("max_evaluations"))),
        polish_(static_cast<int>(p.getInt("polish_iterations"))),
        chunk_(static_cast<int>(p.getInt("chunk_samples"))),
        max_eq_(static_cast<int>(p.getInt("max_equations"))) {
    opt_.rank_tolerance = p.getDouble("rank_tolerance");
    exid::check(
        scale_range_.size() == 2 && scale_range_[0] > 0 && scale_range_[1] >= scale_range_[0] &&
            std::isfinite(scale_range_[1]),
        fmt::format("{}: prior_scale_range must be [lo, hi] with 0 < lo <= hi < inf", kName));
  }

  exid::EstimatorSpecs specs() const override { return exid::estimators::streamingSpecs(); }

  exid::Estimate estimate(const exid::ObservationModel& model, const exid::Dataset& data,
                          const exid::Prior* prior, const exid::RunContext& ctx) override {
    const auto t0 = std::chrono::steady_clock::now();
    const int p = model.numBase();
    const exid::BaseParameters& base = model.base();
    LinearStage lin = linearStage(model, data, prior, ctx);

    // ---- the consistent problem (setObjective)
    const StandardMap map(base.full_names, model.fullNominal());
    const int nfull = static_cast<int>(base.full_names.size());
    const bool std_prior = lin.used_prior && prior_on_ == "standard" &&
                           lin.used_prior->standard_value.size() == nfull &&
                           lin.used_prior->standard_std.size() == nfull;
    Problem P;
    P.map = &map;
    P.ctx = &ctx;
    Eigen::VectorXd dinv;  // D^-1 (standard prior)
    setObjective(lin, base.K, p, nfull, std_prior, &P, &dinv, kName);
    const Eigen::VectorXd pi0 = std_prior ? lin.used_prior->standard_value : model.fullNominal();
    StartPoint st = startPoint(map, P, base.K, lin.unc.theta, pi0, dinv, std_prior, start_);
    P.best_f = HUGE_VAL;
    const double f_start = P.value(st.z0, nullptr);
    const double f_unc = (P.A * st.pi_unc - P.b).squaredNorm();
    ctx.report(0.85, fmt::format("{}: optimising {} variables", kName, map.nz()));

    std::vector<double> lb;
    map.lowerBounds(&lb);
    for (int k = 0; k < map.nz(); ++k)
      st.z0(k) = std::max(st.z0(k), lb[static_cast<std::size_t>(k)]);
    const std::string stop = runNlopt(P, lb, st.z0);
    Eigen::VectorXd z = P.best_z.size() == map.nz() ? P.best_z : st.z0;
    const long nlopt_evals = P.evaluations;
    const int lm_iters = polishLm(P, lb, &z);
    if (ctx.shouldStop()) throw exid::Error(fmt::format("{}: stopped", kName));

    // ---- results
    const Eigen::VectorXd pi = map.pi(z);
    const Eigen::VectorXd theta = base.K * pi;
    const double f_final = (P.A * pi - P.b).squaredNorm();
    int lin_rank = 0;
    const Eigen::MatrixXd cov = linearisedCovariance(map, P, base.K, z, pi, lb, &lin_rank);

    double rss_c = 0.0, rss_u = 0.0;
    for (const auto& [eq, a] : lin.acc) {
      rss_c += a.residualSquared(theta);
      rss_u += a.residualSquared(lin.unc.theta);
    }
    const long m = lin.m;
    const double rms_c = std::sqrt(rss_c / static_cast<double>(m));
    const double rms_u = std::sqrt(rss_u / static_cast<double>(m));

    exid::estimators::LsSolution sol = lin.unc;
    sol.theta = theta;
    sol.covariance = cov;
    sol.std = cov.diagonal().cwiseMax(0.0).cwiseSqrt();
    sol.rss = f_final;
    sol.sigma2 = f_final / static_cast<double>(std::max<long>(1, lin.total.rows() - p));
    // (with the standard prior, f_final also holds the standard prior's terms)
    exid::Estimate e;
    exid::estimators::fillEstimate(&e, model, sol, rss_c, m);
    e.rows = m;
    Json& d = e.details;
    d["estimator"] = kName;
    d["weighting"] = weighting_;
    d["equations"] = lin.eq_table;
    d["covariance_definition"] =
        "linearised: J (J^T F^T F J)^+ J^T with J = K dpi/dz at the estimate (variables at an "
        "active "
        "bound fixed), F the factor of the noise-normalised rows" +
        std::string(prior ? " stacked with the prior" : "") +
        "; equals the unconstrained covariance when no constraint is active";
    d["residual_rms_unconstrained"] = rms_u;
    d["residual_rms_ratio"] = rms_u > 0 ? rms_c / rms_u : 1.0;
    // Distance from the unconstrained (prior-regularised) least-squares solution in units of its
    // covariance: sqrt((theta - theta_u)^T Cov_u^-1 (theta - theta_u)) = ||F_w (theta - theta_u)||.
    d["mahalanobis_from_unconstrained"] = (lin.Fw * (theta - lin.unc.theta)).norm();
    Json u = Json::object();
    u["value"] = Json(toStd(lin.unc.theta));
    u["std"] = Json(toStd(lin.unc.std));
    u["cost"] = f_unc;
    d["unconstrained"] = u;
    Json o = Json::object();
    o["algorithm"] = algorithm_;
    o["start"] = st.started;
    o["bodies_projected_at_start"] =
        st.started == "nominal" ? st.projected_nominal : st.projected_unc;
    o["cost_start"] = f_start;
    o["cost_final"] = f_final;
    o["cost_unconstrained"] = f_unc;
    o["nlopt_evaluations"] = Json(static_cast<long long>(nlopt_evals));
    o["nlopt_stop"] = stop;
    o["lm_iterations"] = lm_iters;
    o["variables"] = map.nz();
    o["linearised_rank"] = lin_rank;
    d["optimization"] = o;
    if (lin.used_prior) priorDetails(lin, theta, sol.std, pi, dinv, std_prior, nfull, d);

    // Consistent standard parameters (exid export writes them into a URDF).
    Json sp = Json::object();
    sp["names"] = Json(base.full_names);
    sp["values"] = Json(toStd(pi));
    d["standard_parameters"] = sp;
    bool all_ok = true;
    d["bodies"] = bodyChecks(map, pi, &all_ok);
    d["consistent"] = all_ok;
    {
      Json w = plausibilityWarnings(map, pi, model.fullNominal(), rms_c, rms_u, kName);
      if (w.size() > 0 && !d.find("warnings")) d["warnings"] = exid::Json::array();
      for (std::size_t i = 0; i < w.size(); ++i) d["warnings"].push_back(w.at(i));
    }
    d["samples"] = data.size();
    d["wall_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    writeStandardCsv(ctx, base.full_names, pi, d);
    ctx.report(1.0, fmt::format("{}: done", kName));
    return e;
  }

 private:
  /// The rows, per equation (and per block of samples and equation for cross-validation, when
  /// blocks > 0), compressed chunk by chunk.
  EquationRows compressRows(const exid::ObservationModel& model, const exid::Dataset& data,
                            const exid::RunContext& ctx, int blocks) const {
    const int p = model.numBase();
    const int n_samples = data.size();
    EquationRows out;
    std::map<int, RowAccumulator>& acc = out.acc;
    std::vector<std::map<int, RowAccumulator>>& block_acc = out.blocks;
    block_acc.resize(static_cast<std::size_t>(blocks));
    std::map<int, std::vector<int>> idx;
    std::vector<int> sample_of_row, order;
    exid::estimators::forEachChunk(
        model, data, chunk_, ctx, kName, 0.0, 0.8, [&](const exid::Rows& r, int begin, int end) {
          for (auto& [eq, v] : idx) v.clear();
          const bool labelled = r.equation.size() == static_cast<std::size_t>(r.y.size());
          if (blocks > 0) exid::estimators::rowTimeOrder(r, end - begin, &sample_of_row, &order);
          for (Eigen::Index i = 0; i < r.y.size(); ++i)
            idx[labelled ? r.equation[static_cast<std::size_t>(i)] : 0].push_back(
                static_cast<int>(i));
          exid::check(
              static_cast<int>(idx.size()) <= max_eq_,
              fmt::format("{}: the model labels more than max_equations = {} distinct equations",
                          kName, max_eq_));
          for (const auto& [eq, v] : idx) {
            if (v.empty()) continue;
            const auto n = static_cast<Eigen::Index>(v.size());
            exid::estimators::addEquationRows(r, v, eq, &acc);
            for (Eigen::Index k = 0; k < n && blocks > 0; ++k) {
              // contiguous blocks in time: sample s of n_samples -> block s * blocks / n_samples
              const long s =
                  begin + sample_of_row[static_cast<std::size_t>(v[static_cast<std::size_t>(k)])];
              const auto blk = static_cast<std::size_t>(
                  std::min<long>(blocks - 1, s * blocks / std::max(1, n_samples)));
              auto bt = block_acc[blk].find(eq);
              if (bt == block_acc[blk].end())
                bt = block_acc[blk]
                         .emplace(eq, RowAccumulator(p, RowAccumulator::Method::Qr, 64))
                         .first;
              bt->second.addRow(r.W.row(v[static_cast<std::size_t>(k)]),
                                r.y(v[static_cast<std::size_t>(k)]));
            }
          }
        });
    return out;
  }

  /// Each equation's residual std (weighting: equation) or one for all rows, floored so that
  /// exactly fitted data get finite weights; returns the rows divided by it (eq_table: the
  /// weights).
  RowAccumulator weightRows(const std::map<int, RowAccumulator>& acc, const RowAccumulator& all,
                            int p, bool has_prior, std::map<int, double>* sigma,
                            Json* eq_table) const {
    const long m = all.rows();
    int rank = 0;
    const Eigen::VectorXd theta_mn =
        exid::estimators::solveMinimumNorm(all, opt_.rank_tolerance, &rank);
    RowAccumulator weighted(p);
    double smax = 0.0;
    const double global = std::sqrt(std::max(0.0, all.residualSquared(theta_mn)) /
                                    static_cast<double>(std::max<long>(1, m - rank)));
    for (const auto& [eq, a] : acc) {
      double s = global;
      if (weighting_ == "equation") {
        const Eigen::VectorXd nrm = a.columnNorms();
        const double big = nrm.maxCoeff();
        int pe = 0;
        for (Eigen::Index j = 0; j < nrm.size(); ++j) pe += nrm(j) > 1e-12 * big ? 1 : 0;
        double dof = static_cast<double>(a.rows() - pe);
        if (dof <= 0)
          dof = static_cast<double>(a.rows()) * static_cast<double>(std::max<long>(1, m - rank)) /
                static_cast<double>(m);
        s = std::sqrt(std::max(0.0, a.residualSquared(theta_mn)) / std::max(dof, 1e-300));
      }
      (*sigma)[eq] = s;
      smax = std::max(smax, s);
    }
    // Floor: exactly fitted (noise-free) data must not get infinite weights.
    double yrms = all.factor().col(p).norm() / std::sqrt(static_cast<double>(std::max<long>(1, m)));
    const double floor =
        std::max(smax > 0 ? 1e-6 * smax : 0.0, (has_prior ? 1e-9 : 1e-12) * std::max(yrms, 1e-300));
    for (auto& [eq, s] : *sigma) {
      Json row = Json::object();
      row["equation"] = eq;
      row["rows"] = Json(static_cast<long long>(acc.at(eq).rows()));
      row["residual_std"] = s;
      s = std::max(s, floor);
      row["weight"] = 1.0 / s;
      eq_table->push_back(row);
      weighted.merge(acc.at(eq), 1.0 / s);
    }
    return weighted;
  }

  /// The prior, its scale fixed or chosen on the weighted rows (docs/consistent.md); details in
  /// scale_details.
  std::optional<exid::Prior> scalePrior(const exid::Prior& prior, bool select_cv,
                                        const std::vector<std::map<int, RowAccumulator>>& blocks,
                                        const std::map<int, double>& sigma,
                                        const RowAccumulator& weighted, int p,
                                        Json* scale_details) const {
    double scale = prior_scale_;
    (*scale_details)["method"] = "fixed";
    if (scale_selection_ != "none") {
      exid::estimators::PriorScaleChoice c;
      if (select_cv) {
        std::vector<RowAccumulator> folds;
        for (const auto& blk : blocks) {
          RowAccumulator f(p);
          for (const auto& [eq, a] : blk) f.merge(a, 1.0 / sigma.at(eq));
          folds.push_back(std::move(f));
        }
        c = exid::estimators::selectPriorScaleCv(
            folds, prior, exid::estimators::logGrid(scale_range_[0], scale_range_[1], 8), kName);
      } else {
        c = exid::estimators::selectPriorScaleEvidence(weighted, prior, scale_range_[0],
                                                       scale_range_[1], kName);
      }
      scale = c.scale;
      *scale_details = c.toJson();
      if (const std::string doubt = c.edgeText(kName); !doubt.empty())
        (*scale_details)["suspect"] = doubt;
    }
    (*scale_details)["scale"] = scale;
    return exid::estimators::scaledPrior(prior, scale);
  }

  /// The rows compressed per equation, noise-normalised, stacked with the prior: one factor, and
  /// its unconstrained least-squares solution.
  LinearStage linearStage(const exid::ObservationModel& model, const exid::Dataset& data,
                          const exid::Prior* prior, const exid::RunContext& ctx) const {
    const int p = model.numBase();
    const std::vector<std::string>& names = model.base().names;
    const bool select_cv = prior && scale_selection_ == "cv";
    EquationRows rows = compressRows(model, data, ctx, select_cv ? cv_blocks_ : 0);
    LinearStage lin;
    lin.acc = std::move(rows.acc);
    RowAccumulator all(p);
    for (const auto& [eq, a] : lin.acc) all.merge(a);
    lin.m = all.rows();
    if (!prior) {
      // Without a prior every base parameter must be identified by the data (the message names
      // the directions that are not); with one, they fall back to it.
      (void)exid::estimators::solveLeastSquares(all, names, opt_, kName);
    }
    std::map<int, double> sigma;
    lin.weighted = weightRows(lin.acc, all, p, prior != nullptr, &sigma, &lin.eq_table);
    if (prior)
      lin.used_prior =
          scalePrior(*prior, select_cv, rows.blocks, sigma, lin.weighted, p, &lin.scale_details);
    lin.total = lin.weighted;
    if (lin.used_prior) exid::estimators::addPriorRows(&lin.total, *lin.used_prior, kName);
    exid::estimators::SolveOptions uo = opt_;
    uo.unit_variance = true;
    if (prior) uo.rank_tolerance = 0.0;  // positive definite with the prior
    lin.unc = exid::estimators::solveLeastSquares(lin.total, names, uo, kName);
    const Eigen::MatrixXd& F = lin.total.factor();
    lin.Fw = F.leftCols(p);
    lin.fy = F.col(p);
    return lin;
  }

  /// NLopt from z0 (algorithm: none: not run); the best point is kept in P. Returns how it
  /// stopped.
  std::string runNlopt(Problem& P, const std::vector<double>& lb, const Eigen::VectorXd& z0) const {
    std::string stop = "not run";
    if (algorithm_ == "none") return stop;
    nlopt::opt o(algorithmFromName(algorithm_), static_cast<unsigned>(P.map->nz()));
    o.set_lower_bounds(lb);
    o.set_min_objective(nloptObjective, &P);
    o.set_maxeval(max_eval_);
    o.set_ftol_rel(1e-14);
    o.set_xtol_rel(1e-12);
    std::vector<double> x(z0.data(), z0.data() + z0.size());
    double fx = 0;
    try {
      const nlopt::result r = o.optimize(x, fx);
      stop = fmt::format("nlopt result {}", static_cast<int>(r));
    } catch (const nlopt::forced_stop&) {
      throw exid::Error(fmt::format("{}: stopped", kName));
    } catch (const std::exception& e) {
      stop = fmt::format("nlopt: {} (best point kept)", e.what());
    }
    return stop;
  }

  /// d["prior"]: the prior's details, its scale and where it acts.
  void priorDetails(const LinearStage& lin, const Eigen::VectorXd& theta,
                    const Eigen::VectorXd& theta_std, const Eigen::VectorXd& pi,
                    const Eigen::VectorXd& dinv, bool std_prior, int nfull, Json& d) const {
    d["prior"] = exid::estimators::priorDetails(*lin.used_prior, theta, theta_std);
    d["prior"]["scale"] = lin.scale_details;
    if (const exid::Json* doubt = lin.scale_details.find("suspect")) {
      if (!d.find("suspect")) d["suspect"] = exid::Json::array();
      d["suspect"].push_back(*doubt);
      if (!d.find("warnings")) d["warnings"] = exid::Json::array();
      d["warnings"].push_back(*doubt);
    }
    d["prior"]["on"] = std_prior ? "standard" : "base";
    if (std_prior) {
      // ||D^-1 (pi - pi0)||: the standard parameters' distance from the prior, in its std.
      d["prior"]["standard_mahalanobis"] =
          dinv.cwiseProduct(pi - lin.used_prior->standard_value).norm();
      d["prior"]["standard_parameters"] = nfull;
    } else if (prior_on_ == "standard") {
      d["prior"]["on_note"] =
          "prior_on: standard asked, but the prior has no standard parameters (from: study): "
          "it acts on the base parameters";
    }
  }
  /// Levenberg-Marquardt on r(z) = A pi(z) - b with the exact Jacobian A dpi/dz; variables with
  /// a lower bound stay feasible (projected steps, active bounds held). Returns the iterations.
  int polishLm(Problem& P, const std::vector<double>& lb, Eigen::VectorXd* z) const {
    if (polish_ <= 0) return 0;
    const StandardMap& map = *P.map;
    const int n = map.nz();
    double f = P.value(*z, nullptr);
    double lambda = 1e-6;
    int it = 0, small = 0;
    for (; it < polish_ && small < 3; ++it) {
      if (P.ctx && P.ctx->shouldStop()) break;
      const Eigen::VectorXd r = P.A * map.pi(*z) - P.b;
      const Eigen::MatrixXd Jr = P.A * map.jacobian(*z);
      const Eigen::VectorXd g = Jr.transpose() * r;
      std::vector<bool> fixed(static_cast<std::size_t>(n), false);
      for (int k = 0; k < n; ++k)
        fixed[static_cast<std::size_t>(k)] = std::isfinite(lb[static_cast<std::size_t>(k)]) &&
                                             (*z)(k) <= lb[static_cast<std::size_t>(k)] && g(k) > 0;
      Eigen::MatrixXd H = Jr.transpose() * Jr;
      const double hmax = std::max(H.diagonal().maxCoeff(), 1e-300);
      bool accepted = false;
      for (int tries = 0; tries < 30 && !accepted; ++tries) {
        Eigen::MatrixXd Hd = H;
        for (int k = 0; k < n; ++k) Hd(k, k) += lambda * (H(k, k) + 1e-12 * hmax);
        Eigen::VectorXd rhs = -g;
        for (int k = 0; k < n; ++k)
          if (fixed[static_cast<std::size_t>(k)]) {
            Hd.row(k).setZero();
            Hd.col(k).setZero();
            Hd(k, k) = 1.0;
            rhs(k) = 0.0;
          }
        const Eigen::VectorXd step = Hd.ldlt().solve(rhs);
        Eigen::VectorXd zn = *z + step;
        for (int k = 0; k < n; ++k) zn(k) = std::max(zn(k), lb[static_cast<std::size_t>(k)]);
        const double fn = P.value(zn, nullptr);
        if (std::isfinite(fn) && fn <= f) {
          small = (f - fn) <= 1e-12 * f ? small + 1 : 0;
          *z = zn;
          f = fn;
          lambda = std::max(lambda / 3.0, 1e-15);
          accepted = true;
        } else {
          lambda *= 4.0;
        }
      }
      if (!accepted) break;
    }
    return it;
  }

  std::string weighting_, prior_on_, algorithm_, start_, scale_selection_;
  std::vector<double> scale_range_;
  double prior_scale_;
  int cv_blocks_;
  int max_eval_, polish_, chunk_, max_eq_;
  exid::estimators::SolveOptions opt_;
};

}  // namespace

EXID_REGISTER_PLUGIN(ConsistentLs)
