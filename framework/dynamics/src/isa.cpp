// exid — which copy of the hot kernels runs (exid/isa.hpp, kernel_table.hpp), and their operation
// counts (kernelFlops).
#include "exid/isa.hpp"

#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "exid/error.hpp"
#include "exid/fmath_kernels.hpp"  // kSincosSmallFlops
#include "kernel_table.hpp"
#include "rigid_body.hpp"

namespace exid {

namespace {

bool cpuHasAvx() {
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx");
#else
  return false;
#endif
}

bool cpuHasAvx2() {
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
#else
  return false;
#endif
}

const detail::Kernels* table(Isa isa) {
  if (isa == Isa::Portable) return &detail::portableKernels();
  static const detail::Kernels* const avx2 = cpuHasAvx2() ? detail::avx2Kernels() : nullptr;
  return avx2;
}

// EXID_ISA (portable, avx2; auto: the best this CPU runs; unset or empty: portable, so that a
// study's numbers do not depend on the CPU it runs on). A copy that is unknown or not available
// here is said once on stderr and replaced by the best available.
const detail::Kernels* fromEnvironment() {
  const detail::Kernels* best = table(Isa::Avx2) ? table(Isa::Avx2) : table(Isa::Portable);
  const char* e = std::getenv("EXID_ISA");
  if (!e || !*e) return table(Isa::Portable);
  if (std::strcmp(e, "auto") == 0) return best;
  for (Isa isa : {Isa::Portable, Isa::Avx2})
    if (std::strcmp(e, isaName(isa)) == 0) {
      if (const detail::Kernels* k = table(isa)) return k;
      std::fprintf(stderr,
                   "exid: EXID_ISA=%s: not available on this CPU or in this build; using %s\n", e,
                   isaName(best->isa));
      return best;
    }
  std::fprintf(stderr, "exid: EXID_ISA=%s: unknown (portable, avx2 or auto); using %s\n", e,
               isaName(best->isa));
  return best;
}

std::atomic<const detail::Kernels*>& active() {
  static std::atomic<const detail::Kernels*> a{fromEnvironment()};
  return a;
}

const detail::LaneKernels* lanesTable(Lanes lanes) {
  if (lanes == Lanes::Baseline) return detail::portableLaneKernels();
  static const detail::LaneKernels* avx = cpuHasAvx() ? detail::avxLaneKernels() : nullptr;
  return avx;
}

std::atomic<const detail::LaneKernels*>& lanesInUse() {
  static std::atomic<const detail::LaneKernels*> a{
      lanesTable(Lanes::Avx) ? lanesTable(Lanes::Avx) : lanesTable(Lanes::Baseline)};
  return a;
}

}  // namespace

namespace detail {
const Kernels& kernels() { return *active().load(std::memory_order_relaxed); }

const LaneKernels* activeLanes() {
  if (kernels().isa != Isa::Portable) return nullptr;
  return lanesInUse().load(std::memory_order_relaxed);
}

GramFn activeGram() {
  if (kernels().isa != Isa::Portable) return kernels().gram;
  // the lane copy in use decides (the AVX one is only ever chosen where the CPU has AVX)
  return exid::activeLanes() == Lanes::Avx ? avxLanesGram() : portableGram();
}
}  // namespace detail

void gramUpdate(double* G, int ldg, const double* B, int ldb, int k, int m) {
  check(m >= 0 && k >= 0 && ldb >= ((m + 3) & ~3) && ldg >= ((m + 3) & ~3),
        "gramUpdate: leading dimensions below the sizes");
  if (m == 0 || k == 0) return;
  detail::activeGram()(G, ldg, B, ldb, k, m);
}

namespace detail {}  // namespace detail

const char* lanesName(Lanes lanes) { return lanes == Lanes::Avx ? "avx" : "baseline"; }

std::vector<Lanes> availableLanes() {
  std::vector<Lanes> out{Lanes::Baseline};
  if (lanesTable(Lanes::Avx)) out.push_back(Lanes::Avx);
  return out;
}

Lanes activeLanes() { return lanesInUse().load(std::memory_order_relaxed)->lanes; }

void setActiveLanes(Lanes lanes) {
  const detail::LaneKernels* f = lanesTable(lanes);
  check(f != nullptr, std::string("setActiveLanes: ") + lanesName(lanes) +
                          " is not available on this CPU or in this build");
  lanesInUse().store(f, std::memory_order_relaxed);
}

const char* isaName(Isa isa) { return isa == Isa::Avx2 ? "avx2" : "portable"; }

std::vector<Isa> availableIsas() {
  std::vector<Isa> out{Isa::Portable};
  if (table(Isa::Avx2)) out.push_back(Isa::Avx2);
  return out;
}

Isa activeIsa() { return detail::kernels().isa; }

void setActiveIsa(Isa isa) {
  const detail::Kernels* k = table(isa);
  check(k != nullptr, std::string("setActiveIsa: ") + isaName(isa) +
                          " is not available on this CPU or in this build");
  active().store(k, std::memory_order_relaxed);
}

// ---- operation counts, from the source of kernels.hpp and rigid_body.hpp ----
//
// Per helper (+, -, * each one; negation and copies none): cross 9, dot3 5, 3-vector sum 3,
// scalar * 3-vector 3, 3x3 * 3-vector 15, 3x3 * 3x3 45; xMotion and xForceT 42, crm 30,
// dot(SV) 11, dotCrm 41, symMul 15, newtonEuler 90, pairRow 86, pairKinGrad 144.

namespace {

using detail::Level;

constexpr double kXMotion = 42, kXForceT = 42, kCrm = 30, kDotSV = 11, kDotCrm = 41,
                 kNewtonEuler = 90, kPairRow = 86, kPairKinGrad = 144;

void forwardPassFlops(const DynamicsData& d, Level level, FlopCount& c) {
  for (const detail::JointC& J : d.J) {
    if (J.revolute) {
      c.sincos += 2;
      c.sincos_flops += fmath::kernels::kSincosSmallFlops;
      c.flops += 18;                      // the rotated columns of M
      if (!J.post_R_id) c.flops += 45;    // M Rpost
      if (!J.post_p_zero) c.flops += 18;  // ppre + M ppost
    } else {
      c.flops += 6;  // pfix + axis q
    }
    if (level == Level::Position) continue;
    if (J.parent >= 0) c.flops += kXMotion;
    c.flops += 6 + 6;  // u = S qd, v = xv + u
    if (level == Level::Velocity) continue;
    c.flops += kXMotion + 6 + kCrm + 12 + 12;  // xa, S qdd, crm(v, u), a, ao = a.v + w x v
  }
}

double ancestorPairs(const DynamicsData& d) { return static_cast<double>(d.anc_idx.size()); }

void rneaBackwardFlops(const DynamicsData& d, FlopCount& c) {
  for (const detail::JointC& J : d.J) {
    c.flops += kNewtonEuler + kDotSV;
    if (J.parent >= 0) c.flops += kXForceT + 6;
  }
}

void reversePassFlops(const DynamicsData& d, Level level, bool subspaces, FlopCount& c) {
  for (int j = 0; j < d.n; ++j) {
    const detail::JointC& J = d.J[static_cast<size_t>(j)];
    const double others =
        d.anc_off[static_cast<size_t>(j) + 1] - d.anc_off[static_cast<size_t>(j)] - 1;
    c.flops += level == Level::Acceleration ? 170 : 3;
    c.flops += 12 + kDotCrm + 1;  // dqd += dot(S, vb), dq -= dotCrm(S, xv, vb)
    if (subspaces) c.flops += others * (kDotCrm + 1);
    if (J.parent >= 0) {
      c.flops += kXForceT + 6;
      if (level == Level::Acceleration) c.flops += kXForceT + 6;
      if (subspaces) c.flops += others * (kXForceT + 6);
    }
  }
}

}  // namespace

FlopCount kernelFlops(const RobotModel& model, Kernel kernel) {
  DynamicsData d;
  detail::setup(model, d);
  const double n = d.n, P = ancestorPairs(d);
  FlopCount c;
  switch (kernel) {
    case Kernel::TorqueRegressor:
      forwardPassFlops(d, Level::Acceleration, c);
      c.flops += (P - n) * kXMotion + P * kPairRow;  // ancestorSubspaces, the rows
      break;
    case Kernel::InverseDynamics:
      forwardPassFlops(d, Level::Acceleration, c);
      rneaBackwardFlops(d, c);
      break;
    case Kernel::EnergyRegressor:
      forwardPassFlops(d, Level::Velocity, c);
      c.flops += n * (24 + 20);  // kinetic row; potential row (R^T g, g . p)
      for (const detail::JointC& J : d.J)
        if (J.parent >= 0) c.flops += 63;  // base pose from the parent's
      break;
    case Kernel::TorqueRegressorVjp:
      forwardPassFlops(d, Level::Acceleration, c);
      c.flops += (P - n) * kXMotion + P * kPairKinGrad + (P - n) * kNewtonEuler;
      reversePassFlops(d, Level::Acceleration, true, c);
      break;
    case Kernel::EnergyRegressorVjp:
      forwardPassFlops(d, Level::Velocity, c);
      c.flops += n * 42;  // kinetic adjoints
      reversePassFlops(d, Level::Velocity, false, c);
      forwardPassFlops(d, Level::Acceleration, c);  // the potential part: RNEA at rest
      rneaBackwardFlops(d, c);
      c.flops += n;
      break;
  }
  return c;
}

}  // namespace exid
