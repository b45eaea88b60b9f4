// exid — the portable copy of the hot kernels (kernels.hpp), compiled for the build's baseline
// instruction set like the rest of the library; also the shared recursions of rigid_body.hpp
// that the other algorithms (wrench and payload regressors, derivatives, mass matrix) call.
#include <cmath>

#include "exid/fmath.hpp"

namespace exid::detail::portable {
namespace {
// sin and cos of every joint angle: exid's (exid/fmath.hpp), the same bits on every CPU
inline void sinCos(int n, const double* q, double* s, double* c) {
  for (int j = 0; j < n; ++j) {
    const double x = q[j];  // one load: s may alias q
    double sj, cj;
    exid::fmath::sincos(x, &sj, &cj);
    s[j] = sj;
    c[j] = cj;
  }
}
}  // namespace
}  // namespace exid::detail::portable

#define EXID_KERNEL_NS portable
#define EXID_KERNEL
#include "kernels.hpp"
#define EXID_LANES_NS portable
#define EXID_LANES_KERNEL
#include "kernels_lanes.hpp"
#define EXID_GRAM_NS portable
#include "gram_block.hpp"

namespace exid::detail {

namespace portable {
namespace {

// GramAccumulator's block update (gram_block.hpp; the compiler vectorises the inner loop with
// the baseline ISA).
void gram(double* acc, int ld, const double* B, int ldb, int k, int m) {
  gramBlock(acc, ld, B, ldb, k, m);
}

// One sample: the lane kernel on one lane (the same bits as every lane of the others).
void torqueRegressorOne(const RobotModel& model, DynamicsData& d, const double* q, const double* qd,
                        const double* qdd, double* Y, long ld) {
  torqueRegressorsImpl<double>(model, d, 1, q, qd, qdd, 1, Y, ld, 0);
}

void inverseDynamicsOne(const RobotModel& model, DynamicsData& d, const double* q, const double* qd,
                        const double* qdd, const double* pi, double* tau) {
  inverseDynamicsImpl<double>(model, d, 1, q, qd, qdd, 1, pi, tau, 1);
}

void energyRegressorOne(const RobotModel& model, DynamicsData& d, const double* q, const double* qd,
                        double* kinetic, double* potential) {
  energyRegressorsImpl<double>(model, d, 1, q, qd, 1, kinetic, potential, 1);
}

// Two samples at once: one SSE2 register each (four lanes in two registers each ran slower
// than one sample at a time: twice the registers' pressure).
void torqueRegressorsLanes(const RobotModel& model, DynamicsData& d, int count, const double* q,
                           const double* qd, const double* qdd, long ldx, double* Y, long ldY,
                           long strideY) {
  torqueRegressorsImpl<Lane2>(model, d, count, q, qd, qdd, ldx, Y, ldY, strideY);
}
void inverseDynamicsLanes(const RobotModel& model, DynamicsData& d, int count, const double* q,
                          const double* qd, const double* qdd, long ldx, const double* pi,
                          double* tau, long ldt) {
  inverseDynamicsImpl<Lane2>(model, d, count, q, qd, qdd, ldx, pi, tau, ldt);
}
void energyRegressorsLanes(const RobotModel& model, DynamicsData& d, int count, const double* q,
                           const double* qd, long ldx, double* kinetic, double* potential,
                           long ldk) {
  energyRegressorsImpl<Lane2>(model, d, count, q, qd, ldx, kinetic, potential, ldk);
}

void torqueRegressorVjpsLanes(const RobotModel& model, DynamicsData& d, int count, const double* q,
                              const double* qd, const double* qdd, long ldx, const double* G,
                              long ldG, long strideG, double* gq, double* gqd, double* gqdd,
                              long ldo) {
  torqueRegressorVjpsImpl<Lane2>(model, d, count, q, qd, qdd, ldx, G, ldG, strideG, gq, gqd, gqdd,
                                 ldo);
}
void energyRegressorVjpsLanes(const RobotModel& model, DynamicsData& d, int count, const double* q,
                              const double* qd, long ldx, const double* Gk, const double* Gu,
                              long ldg, double* gq, double* gqd, long ldo) {
  energyRegressorVjpsImpl<Lane2>(model, d, count, q, qd, ldx, Gk, Gu, ldg, gq, gqd, ldo);
}

void torqueRegressorVjpOne(const RobotModel& model, DynamicsData& d, const double* q,
                           const double* qd, const double* qdd, const double* G, long ld,
                           double* gq, double* gqd, double* gqdd) {
  torqueRegressorVjpsImpl<double>(model, d, 1, q, qd, qdd, 1, G, ld, 0, gq, gqd, gqdd, 1);
}
void energyRegressorVjpOne(const RobotModel& model, DynamicsData& d, const double* q,
                           const double* qd, const double* Gk, const double* Gu, double* gq,
                           double* gqd) {
  energyRegressorVjpsImpl<double>(model, d, 1, q, qd, 1, Gk, Gu, 1, gq, gqd, 1);
}

const LaneKernels kLanes = {Lanes::Baseline,           &torqueRegressorsLanes,
                            &inverseDynamicsLanes,     &energyRegressorsLanes,
                            &torqueRegressorVjpsLanes, &energyRegressorVjpsLanes};

// The one-sample torque regressor, RNEA, energy regressor and their VJPs are the lane kernels on
// one lane (the same bits as every lane of the others).
const Kernels kTable = {Isa::Portable,
                        &torqueRegressorOne,
                        &inverseDynamicsOne,
                        &energyRegressorOne,
                        &torqueRegressorVjpOne,
                        &energyRegressorVjpOne,
                        &gram};

}  // namespace
}  // namespace portable

const Kernels& portableKernels() { return portable::kTable; }

const LaneKernels* portableLaneKernels() { return &portable::kLanes; }

GramFn portableGram() { return &portable::gram; }

void forwardPass(const RobotModel& model, DynamicsData& d, const double* q, const double* qd,
                 const double* qdd, Level level, bool gravity) {
  portable::forwardPassImpl(model, d, q, qd, qdd, level, gravity);
}

void ancestorSubspaces(DynamicsData& d) { portable::ancestorSubspacesImpl(d); }

void rneaBackward(const RobotModel& model, DynamicsData& d, const double* pi, double* tau) {
  portable::rneaBackwardImpl(model, d, pi, tau);
}

void clearAdjoints(DynamicsData& d, bool subspaces) { portable::clearAdjointsImpl(d, subspaces); }

void reversePass(DynamicsData& d, const double* qd, Level level, bool subspaces, double* gq,
                 double* gqd, double* gqdd) {
  portable::reversePassImpl(d, qd, level, subspaces, gq, gqd, gqdd);
}

}  // namespace exid::detail
