// exid — the lane kernels (torque regressors, RNEA, energy regressors) of four samples at once in
// AVX registers (kernels_lanes.hpp). framework/CMakeLists.txt compiles this source alone with -mavx
// -ffp-contract=off (no FMA), so its lanes give the same bits as the portable copy's
// (kernels_portable.cpp); dynamics.cpp runs it where the CPU has AVX. The entry point is flattened
// (all it calls, Eigen's accessors included, is inlined into it) and has internal linkage: the only
// symbol this object defines is exid::detail::avxLaneKernels() and avxLanesGram() (ctest
// dynamics.isa_symbols checks it with nm). The Gram block update (gram_block.hpp) is here too, for
// the same reason. Built where EXID_KERNELS_AVX2 (CMakeLists.txt): optimised builds without
// sanitizers, on x86-64.
#if defined(__AVX__) && !defined(__FMA__)

#define EXID_LANES_NS avx_lanes
#define EXID_LANES_KERNEL __attribute__((flatten))
#include "kernel_table.hpp"
#include "kernels_lanes.hpp"
#define EXID_GRAM_NS avx_lanes
#include "gram_block.hpp"

namespace exid::detail {

namespace avx_lanes {
namespace {
EXID_LANES_KERNEL void torqueRegressors(const RobotModel& model, DynamicsData& d, int count,
                                        const double* q, const double* qd, const double* qdd,
                                        long ldx, double* Y, long ldY, long strideY) {
  torqueRegressorsImpl<Lane4>(model, d, count, q, qd, qdd, ldx, Y, ldY, strideY);
}
EXID_LANES_KERNEL void inverseDynamics(const RobotModel& model, DynamicsData& d, int count,
                                       const double* q, const double* qd, const double* qdd,
                                       long ldx, const double* pi, double* tau, long ldt) {
  inverseDynamicsImpl<Lane4>(model, d, count, q, qd, qdd, ldx, pi, tau, ldt);
}
EXID_LANES_KERNEL void energyRegressors(const RobotModel& model, DynamicsData& d, int count,
                                        const double* q, const double* qd, long ldx,
                                        double* kinetic, double* potential, long ldk) {
  energyRegressorsImpl<Lane4>(model, d, count, q, qd, ldx, kinetic, potential, ldk);
}
EXID_LANES_KERNEL void torqueRegressorVjps(const RobotModel& model, DynamicsData& d, int count,
                                           const double* q, const double* qd, const double* qdd,
                                           long ldx, const double* G, long ldG, long strideG,
                                           double* gq, double* gqd, double* gqdd, long ldo) {
  torqueRegressorVjpsImpl<Lane4>(model, d, count, q, qd, qdd, ldx, G, ldG, strideG, gq, gqd, gqdd,
                                 ldo);
}
EXID_LANES_KERNEL void energyRegressorVjps(const RobotModel& model, DynamicsData& d, int count,
                                           const double* q, const double* qd, long ldx,
                                           const double* Gk, const double* Gu, long ldg, double* gq,
                                           double* gqd, long ldo) {
  energyRegressorVjpsImpl<Lane4>(model, d, count, q, qd, ldx, Gk, Gu, ldg, gq, gqd, ldo);
}
const LaneKernels kLanes = {Lanes::Avx,        &torqueRegressors,    &inverseDynamics,
                            &energyRegressors, &torqueRegressorVjps, &energyRegressorVjps};
EXID_LANES_KERNEL void gram(double* acc, int ld, const double* B, int ldb, int k, int m) {
  gramBlock(acc, ld, B, ldb, k, m);
}
}  // namespace
}  // namespace avx_lanes

const LaneKernels* avxLaneKernels() { return &avx_lanes::kLanes; }
GramFn avxLanesGram() { return &avx_lanes::gram; }

}  // namespace exid::detail

#else

#include "kernel_table.hpp"

namespace exid::detail {
const LaneKernels* avxLaneKernels() { return nullptr; }
GramFn avxLanesGram() { return nullptr; }
}  // namespace exid::detail

#endif
