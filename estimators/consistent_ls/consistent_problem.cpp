// exid — estimator `consistent_ls`: the consistent problem (see consistent_problem.hpp): the map
// z -> standard parameters and its derivatives, the objective for NLopt, the start point, the
// linearised covariance and the physical checks.
#include "consistent_problem.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <nlopt.hpp>

#include "exid/drive.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/io.hpp"

namespace exid::consistent_ls {

// Implausible results are warnings: the consistent fit's residual above this many times the
// unconstrained one (noise alone moves it by a few percent), a body's mass this many times off
// the robot description's (heavier only: a body the motion barely excites often comes out light).
constexpr double kResidualRatioWarn = 1.2;
constexpr double kMassRatioWarn = 10.0;

StandardMap::StandardMap(const std::vector<std::string>& names, const Eigen::VectorXd& nominal)
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
          // (body 0: the base link of a floating-base robot, XX0 ... M0)
          if (rest.find_first_not_of("0123456789") == std::string::npos &&
              (rest[0] != '0' || rest == "0")) {
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
    diag_floor_.push_back(std::log(1e-5 * std::sqrt(std::max(std::isfinite(tr) ? tr : 0.0, 1e-6))));
  }
}

void StandardMap::lowerBounds(std::vector<double>* lb) const {
  lb->assign(static_cast<std::size_t>(nz_), -HUGE_VAL);
  for (int b = 0; b < numBodies(); ++b)
    for (int k = 0; k < 4; ++k)
      (*lb)[static_cast<std::size_t>(10 * b + k)] = diag_floor_[static_cast<std::size_t>(b)];
  for (int s = 0; s < numScalars(); ++s)
    if (nonneg(s)) (*lb)[static_cast<std::size_t>(zOfScalar(s))] = 0.0;
}

Eigen::VectorXd StandardMap::pi(const Eigen::VectorXd& z) const {
  Eigen::VectorXd out = Eigen::VectorXd::Zero(nfull_);
  for (int b = 0; b < numBodies(); ++b) {
    const Vec10 p = exid::estimators::logCholeskyToInertial(z.segment<10>(10 * b));
    for (int k = 0; k < 10; ++k) out(bodyIndices(b)[static_cast<std::size_t>(k)]) = p(k);
  }
  for (int s = 0; s < numScalars(); ++s)
    out(scalarIndex(s)) = scale_[static_cast<std::size_t>(s)] * z(zOfScalar(s));
  return out;
}

Eigen::MatrixXd StandardMap::jacobian(const Eigen::VectorXd& z) const {
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

Eigen::VectorXd StandardMap::vjp(const Eigen::VectorXd& z, const Eigen::VectorXd& g) const {
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

Eigen::VectorXd StandardMap::fromStandard(const Eigen::VectorXd& pi, double eig_floor,
                                          int* projected) const {
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

double StandardMap::eigFloor(const Eigen::VectorXd& pi) const {
  double big = 0.0;
  for (int b = 0; b < numBodies(); ++b) {
    Vec10 p;
    for (int k = 0; k < 10; ++k) p(k) = pi(bodyIndices(b)[static_cast<std::size_t>(k)]);
    big = std::max(big, exid::estimators::pseudoInertia(p).trace());
  }
  return std::max(1e-8 * big, 1e-12);
}

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

}  // namespace exid::consistent_ls
