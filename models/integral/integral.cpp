// exid — observation model `integral` (energy model, paper eqn 2): one row per time window
// [t1, t2]:
//   int_{t1}^{t2} tau_m^T qdm dt = (h(t2) - h(t1)) pi
//                                  + sum_j Fc_j int |qdm_j| dt + Fv_j int qdm_j^2 dt
//                                  + OFF_j (qm_j(t2) - qm_j(t1))
// with h the energy regressor (exid::energyRegressor, kinetic + potential, joint coordinates
// q = T qm + q0, qd = T qdm) and, per drive, 1/2 Ia_j qdm_j^2 for the rotor inertia column.
// The power is the same in both coordinate sets: tau_m^T qdm = (T^T tau)^T qdm = tau^T qd.
// Integrals use the trapezoid rule or composite Simpson (non-uniform spacing; an odd last
// interval is integrated with the quadratic through its last three samples). Needs q, qd, tau.
#include <fmt/format.h>

#include <Eigen/Core>
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include "exid/drive.hpp"
#include "exid/dynamics.hpp"
#include "exid/error.hpp"
#include "exid/interfaces.hpp"
#include "exid/models/model_common.hpp"

namespace {

using exid::models::requireSignal;

struct Window {
  int a = 0, b = 0;       // first and last sample
  std::vector<double> w;  // quadrature weights of samples a..b
};

class IntegralModel : public exid::ObservationModel {
 public:
  static constexpr const char* kName = "integral";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "energy model int tau^T qd dt = (h(t2) - h(t1)) pi + friction work, one row per time window "
      "(paper eqn 2); short or long windows, trapezoid or Simpson quadrature; needs q, qd, tau";

  static std::vector<exid::ParamDecl> params() {
    return {
        exid::param_string("window", std::string("short"),
                           "short: windows of window_s seconds; long: every window starts at the "
                           "first sample and ends every window_s seconds",
                           {"short", "long"}),
        exid::param_double("window_s", 0.5, "s",
                           "window length (short) or spacing of the window ends (long)", 0.0,
                           std::nullopt, true),
        exid::param_string("overlap", std::string("disjoint"),
                           "disjoint: consecutive windows share only an end sample (long: ends "
                           "window_s apart); sliding: a window starts (long: ends) at every sample",
                           {"disjoint", "sliding"}),
        exid::param_bool("friction", true,
                         "identify Coulomb and viscous friction from their work: columns "
                         "int |qdm_j| dt and int qdm_j^2 dt"),
        exid::param_bool("subtract_friction", false,
                         "with friction: false, subtract the work of the robot's own friction "
                         "(Fc sign(qdm) + Fv qdm, + OFF unless offset is identified) from the "
                         "measurement (the paper's measured friction)"),
        exid::param_bool("rotor_inertia", true,
                         "identify the rotor inertia Ia_j: energy column 1/2 qdm_j^2"),
        exid::param_bool("offset", false,
                         "identify a torque offset OFF_j: column qm_j(t2) - qm_j(t1)"),
        exid::param_string("quadrature", std::string("simpson"),
                           "trapezoid (error O(dt^2)) or composite Simpson for uneven spacing "
                           "(O(dt^4); odd last interval by the quadratic through its last three "
                           "samples)",
                           {"trapezoid", "simpson"}),
    };
  }

  explicit IntegralModel(const exid::ParamSet& p)
      : long_(p.getString("window") == "long"),
        window_s_(p.getDouble("window_s")),
        sliding_(p.getString("overlap") == "sliding"),
        simpson_(p.getString("quadrature") == "simpson"),
        subtract_(p.getBool("subtract_friction")) {
    cols_.rotor_inertia = p.getBool("rotor_inertia");
    cols_.coulomb = p.getBool("friction");
    cols_.viscous = p.getBool("friction");
    cols_.offset = p.getBool("offset");
    exid::check(!(subtract_ && cols_.coulomb),
                p.context +
                    ": subtract_friction: true needs friction: false (friction is either "
                    "identified or subtracted, not both)");
  }

  std::vector<std::string> fullNames() const override {
    return exid::parameterNames(robot(), cols_);
  }
  Eigen::VectorXd fullNominal() const override { return exid::parameterValues(robot(), cols_); }
  exid::ModelSpecs specs() const override {
    exid::ModelSpecs sp;
    sp.per_sample = false;  // a row integrates over a window of samples
    sp.required_signals = {"q", "qd", "tau"};
    return sp;
  }

  exid::Rows fullRows(const exid::Dataset& d, const exid::RunContext&) const override {
    const int n = robot().dof();
    const std::string who = "model 'integral'";
    requireSignal(d, d.q, "q", n, who);
    requireSignal(d, d.qd, "qd", n, who);
    requireSignal(d, d.tau, "tau", n, who);
    exid::Samples s;
    s.t = d.t;
    s.q = d.q;
    s.qd = d.qd;
    // (each part of a dataset made of several recordings has its own windows: none spans two)
    std::vector<Window> win;
    for (const exid::PartRange& pr : exid::partRanges(d.t, d.facts)) {
      const int lo = pr.begin, hi = pr.end;
      const std::string part =
          d.facts.parts.size() < 2
              ? who + " (dataset " + d.source + ")"
              : fmt::format("{} (part {}: {})", who, pr.part + 1,
                            d.facts.parts[static_cast<std::size_t>(pr.part)].source);
      for (Window w : windows(d.t.segment(lo, hi - lo), part)) {
        w.a += lo;
        w.b += lo;
        win.push_back(std::move(w));
      }
    }
    exid::Rows r;
    r.W = designFromWindows(s, win);
    // Power per sample.
    const int K = d.size();
    Eigen::VectorXd p(K);
    for (int k = 0; k < K; ++k) {
      double pk = d.tau.row(k).dot(d.qd.row(k));
      if (subtract_)
        for (int j = 0; j < n; ++j) pk -= frictionTorque(j, d.qd(k, j)) * d.qd(k, j);
      p[k] = pk;
    }
    const int R = static_cast<int>(win.size());
    r.y.resize(R);
    for (int i = 0; i < R; ++i) {
      const Window& w = win[static_cast<std::size_t>(i)];
      double acc = 0.0;
      for (int k = w.a; k <= w.b; ++k) acc += w.w[static_cast<std::size_t>(k - w.a)] * p[k];
      r.y[i] = acc;
    }
    r.equation.assign(static_cast<std::size_t>(R), 0);
    r.numEquations = 1;
    r.t.resize(static_cast<std::size_t>(R));
    for (int i = 0; i < R; ++i)
      r.t[static_cast<std::size_t>(i)] = d.t[win[static_cast<std::size_t>(i)].b];
    r.equation_names = {"energy of a window [J] (t: its end)"};
    return r;
  }

  Eigen::MatrixXd fullDesign(const exid::Samples& s) const override {
    exid::models::requireSamples(s, robot().dof(), false, "model 'integral'");
    return designFromWindows(s, windows(s.t, "model 'integral' (trajectory samples)"));
  }

  void fullDesignVjp(const exid::Samples& s, const Eigen::MatrixXd& dW,
                     exid::Samples* grad) const override {
    const exid::RobotModel& Rb = robot();
    const int n = Rb.dof(), K = s.size(), P = exid::numParameters(Rb, cols_), nd = cols_.count();
    const int ni = Rb.numInertialParameters();  // (the tree's bodies; a closed chain's too)
    const std::vector<Window> win = windows(s.t, "model 'integral' (trajectory samples)");
    const int R = static_cast<int>(win.size());
    exid::check(dW.rows() == R && dW.cols() == P,
                fmt::format("model 'integral': fullDesignVjp: dW is {} x {} (expected {} x {})",
                            dW.rows(), dW.cols(), R, P));
    exid::models::zeroGrad(s, grad);
    // Adjoint of the per-sample energy rows (h columns) and of the friction integrands.
    Eigen::MatrixXd dE = Eigen::MatrixXd::Zero(K, P);  // columns: inertial, Ia, OFF used
    Eigen::MatrixXd dF = Eigen::MatrixXd::Zero(K, P);  // columns: Fc, Fv used
    for (int i = 0; i < R; ++i) {
      const Window& w = win[static_cast<std::size_t>(i)];
      dE.row(w.b) += dW.row(i);
      dE.row(w.a) -= dW.row(i);
      for (int k = w.a; k <= w.b; ++k)
        dF.row(k) += w.w[static_cast<std::size_t>(k - w.a)] * dW.row(i);
    }
    auto data = exid::makeDynamicsData(Rb);
    Eigen::VectorXd qm, qdm, q, qd, gq, gqd;
    // the energies' VJPs of every sample at once (energyRegressorVjps: several samples per
    // vector register, the bits of one at a time), in the tree's coordinates
    Eigen::MatrixXd Qj, QDj, GQ, GQD;
    for (int k = 0; k < K; ++k) {
      qm = s.q.row(k).transpose();
      qdm = s.qd.row(k).transpose();
      exid::measuredToJoint(Rb, qm, qdm, qdm, &q, &qd, nullptr);
      if (k == 0) {
        Qj.resize(K, q.size());
        QDj.resize(K, qd.size());
      }
      Qj.row(k) = q.transpose();
      QDj.row(k) = qd.transpose();
    }
    if (K > 0)
      exid::energyRegressorVjps(Rb, *data, Qj, QDj, dE.leftCols(ni), dE.leftCols(ni), &GQ, &GQD);
    for (int k = 0; k < K; ++k) {
      qm = s.q.row(k).transpose();
      qdm = s.qd.row(k).transpose();
      gq = GQ.row(k).transpose();
      gqd = GQD.row(k).transpose();
      exid::jointGradientToMeasured(Rb, qm, qdm, qdm, &gq, &gqd, nullptr);
      for (int j = 0; j < n; ++j) {
        int c = ni + nd * j;
        const double v = qdm[j];
        if (cols_.rotor_inertia) gqd[j] += dE(k, c++) * v;
        if (cols_.coulomb) gqd[j] += dF(k, c++) * exid::coulombSign(v);
        if (cols_.viscous) gqd[j] += dF(k, c++) * 2.0 * v;
        if (cols_.offset) gq[j] += dE(k, c++);
      }
      grad->q.row(k) = gq.transpose();
      grad->qd.row(k) = gqd.transpose();
    }
  }

  exid::Json describe() const override {
    exid::Json j = exid::Json::object();
    j["equation"] =
        "int_{t1}^{t2} tau_m^T qdm dt = (h(t2) - h(t1)) pi + sum_j Fc_j int |qdm_j| dt + "
        "Fv_j int qdm_j^2 dt + OFF_j (qm_j(t2) - qm_j(t1)) (paper eqn 2)";
    j["energy"] =
        "h = kinetic + potential energy regressor in joint coordinates, plus 1/2 Ia_j qdm_j^2 per "
        "drive";
    j["window"] = long_ ? "long" : "short";
    j["window_s"] = window_s_;
    j["overlap"] = sliding_ ? "sliding" : "disjoint";
    j["quadrature"] = simpson_ ? "composite Simpson, non-uniform spacing (odd last interval: "
                                 "quadratic through its last three samples); O(dt^4)"
                               : "trapezoid rule; O(dt^2)";
    j["friction"] = cols_.coulomb ? "identified (Coulomb and viscous work columns)"
                                  : (subtract_ ? "subtracted (robot drive data)" : "ignored");
    j["rotor_inertia"] = cols_.rotor_inertia;
    j["offset"] = cols_.offset;
    j["equation_index"] = "0 for every window (one scalar equation)";
    return j;
  }

 protected:
  // Random states for base-parameter detection are spaced so that each window covers two
  // intervals: enough independent rows whatever window_s is.
  exid::Samples randomSamples(int count, std::uint64_t seed) const override {
    exid::Samples s = exid::ObservationModel::randomSamples(count, seed);
    s.t = Eigen::VectorXd::LinSpaced(count, 0.0, (count - 1) * window_s_ / 2.0);
    return s;
  }
  int baseSamples() const override {
    return std::max(200, 4 * exid::numParameters(robot(), cols_) + 20);
  }

 private:
  double frictionTorque(int j, double qdm) const {
    const auto& dr = robot().drives;
    const exid::Drive D =
        j < static_cast<int>(dr.size()) ? dr[static_cast<std::size_t>(j)] : exid::Drive{};
    const double sg = exid::coulombSign(qdm);
    return D.coulomb * sg + D.viscous * qdm + (cols_.offset ? 0.0 : D.offset);
  }

  // Quadrature weights over samples a..b.
  std::vector<double> weights(const Eigen::VectorXd& t, int a, int b) const {
    const int m = b - a;  // intervals
    std::vector<double> w(static_cast<std::size_t>(m + 1), 0.0);
    auto W = [&](int k) -> double& { return w[static_cast<std::size_t>(k - a)]; };
    if (!simpson_ || m < 2) {
      for (int k = a; k < b; ++k) {
        const double h = t[k + 1] - t[k];
        W(k) += 0.5 * h;
        W(k + 1) += 0.5 * h;
      }
      return w;
    }
    const int pairs = m / 2;
    for (int p = 0; p < pairs; ++p) {
      const int k = a + 2 * p;
      const double h0 = t[k + 1] - t[k], h1 = t[k + 2] - t[k + 1], hs = h0 + h1;
      W(k) += hs / 6.0 * (2.0 - h1 / h0);
      W(k + 1) += hs / 6.0 * hs * hs / (h0 * h1);
      W(k + 2) += hs / 6.0 * (2.0 - h0 / h1);
    }
    if (m % 2 == 1) {  // last interval [b-1, b] from the quadratic through b-2, b-1, b
      const double h0 = t[b - 1] - t[b - 2], h1 = t[b] - t[b - 1];
      W(b) += (2.0 * h1 * h1 + 3.0 * h0 * h1) / (6.0 * (h0 + h1));
      W(b - 1) += (h1 * h1 + 3.0 * h0 * h1) / (6.0 * h0);
      W(b - 2) -= h1 * h1 * h1 / (6.0 * h0 * (h0 + h1));
    }
    return w;
  }

  std::vector<Window> windows(const Eigen::VectorXd& t, const std::string& who) const {
    const int K = static_cast<int>(t.size());
    for (int k = 1; k < K; ++k)
      exid::check(t[k] > t[k - 1],
                  fmt::format("{}: time must increase; sample {} has t = {} after {}", who, k + 1,
                              t[k], t[k - 1]));
    const double eps = 1e-9 * window_s_;
    std::vector<Window> out;
    auto add = [&](int a, int b) {
      Window w;
      w.a = a;
      w.b = b;
      w.w = weights(t, a, b);
      out.push_back(std::move(w));
    };
    if (!long_) {
      int a = 0, b = 0;
      while (a < K - 1) {
        if (b <= a) b = a + 1;
        while (b < K && t[b] - t[a] < window_s_ - eps) ++b;
        if (b >= K) break;
        add(a, b);
        a = sliding_ ? a + 1 : b;
      }
    } else {
      int level = 1;
      for (int b = 1; b < K; ++b) {
        if (sliding_) {
          if (t[b] - t[0] >= window_s_ - eps) add(0, b);
        } else if (t[b] - t[0] >= level * window_s_ - eps) {
          add(0, b);
          while (t[b] - t[0] >= level * window_s_ - eps) ++level;
        }
      }
    }
    exid::check(!out.empty(),
                fmt::format("{}: no complete window of {} s in {} samples spanning {} s (shorten "
                            "window_s)",
                            who, window_s_, K, K > 0 ? t[K - 1] - t[0] : 0.0));
    return out;
  }

  Eigen::MatrixXd designFromWindows(const exid::Samples& s, const std::vector<Window>& win) const {
    const exid::RobotModel& Rb = robot();
    const int n = Rb.dof(), K = s.size(), P = exid::numParameters(Rb, cols_), nd = cols_.count();
    const int ni = Rb.numInertialParameters();  // (the tree's bodies; a closed chain's too)
    // Per sample: energy part E (inertial, Ia, OFF columns) and friction integrands F.
    Eigen::MatrixXd E = Eigen::MatrixXd::Zero(K, P), F = Eigen::MatrixXd::Zero(K, P);
    auto data = exid::makeDynamicsData(Rb);
    Eigen::VectorXd qm, qdm, q, qd;
    // the energy regressors of a block of samples at once (exid::energyRegressors: several per
    // vector register, the bits of one at a time)
    constexpr int kBlock = 256;
    const int nt = ni / 10;  // the tree's joints (measuredToJoint's q)
    Eigen::MatrixXd Qb(kBlock, nt), QDb(kBlock, nt), kin(kBlock, ni), pot(kBlock, ni);
    for (int k = 0; k < K; ++k) {
      qm = s.q.row(k).transpose();
      qdm = s.qd.row(k).transpose();
      const int b = k % kBlock;
      exid::measuredToJoint(Rb, qm, qdm, qdm, &q, &qd, nullptr);
      Qb.row(b) = q.transpose();
      QDb.row(b) = qd.transpose();
      if (b == kBlock - 1 || k == K - 1) {
        const int cnt = b + 1, k0 = k - b;
        exid::energyRegressors(Rb, *data, Qb.topRows(cnt), QDb.topRows(cnt), kin.topRows(cnt),
                               pot.topRows(cnt));
        E.block(k0, 0, cnt, ni) = kin.topRows(cnt) + pot.topRows(cnt);
      }
      for (int j = 0; j < n; ++j) {
        int c = ni + nd * j;
        const double v = qdm[j];
        if (cols_.rotor_inertia) E(k, c++) = 0.5 * v * v;
        if (cols_.coulomb) F(k, c++) = std::abs(v);
        if (cols_.viscous) F(k, c++) = v * v;
        if (cols_.offset) E(k, c++) = qm[j];
      }
    }
    const int R = static_cast<int>(win.size());
    Eigen::MatrixXd W(R, P);
    for (int i = 0; i < R; ++i) {
      const Window& w = win[static_cast<std::size_t>(i)];
      W.row(i) = E.row(w.b) - E.row(w.a);
      for (int k = w.a; k <= w.b; ++k)
        W.row(i) += w.w[static_cast<std::size_t>(k - w.a)] * F.row(k);
    }
    return W;
  }

  bool long_;
  double window_s_;
  bool sliding_;
  bool simpson_;
  bool subtract_;
  exid::DriveColumns cols_;
};

}  // namespace

EXID_REGISTER_PLUGIN(IntegralModel)
