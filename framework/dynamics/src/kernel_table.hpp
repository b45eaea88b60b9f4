// exid — the table of the hot kernels' entry points, one per instruction set (kernels.hpp,
// kernels_portable.cpp, kernels_avx2.cpp), and the one in use (isa.cpp). Not installed.
#pragma once

#include "exid/dynamics.hpp"
#include "exid/isa.hpp"

namespace exid::detail {

/// Entry points of one copy of the kernels; the arguments are checked by the callers
/// (dynamics.cpp, dynamics_vjp.cpp, gram.cpp). Matrices are column-major with leading dimension
/// ld; null gradient outputs are skipped.
struct Kernels {
  Isa isa;
  void (*torqueRegressor)(const RobotModel&, DynamicsData&, const double* q, const double* qd,
                          const double* qdd, double* Y, long ld);
  void (*inverseDynamics)(const RobotModel&, DynamicsData&, const double* q, const double* qd,
                          const double* qdd, const double* pi, double* tau);
  void (*energyRegressor)(const RobotModel&, DynamicsData&, const double* q, const double* qd,
                          double* kinetic, double* potential);
  void (*torqueRegressorVjp)(const RobotModel&, DynamicsData&, const double* q, const double* qd,
                             const double* qdd, const double* G, long ld, double* gq, double* gqd,
                             double* gqdd);
  void (*energyRegressorVjp)(const RobotModel&, DynamicsData&, const double* q, const double* qd,
                             const double* Gk, const double* Gu, double* gq, double* gqd);
  /// GramAccumulator's block update (gram.cpp): acc[i][j] += sum_r B[r][i] B[r][j], j <= i < m,
  /// r < k; B row-major with ldb = m rounded up to a multiple of 4, zero-padded, and acc rows
  /// with room for ldb entries past the diagonal block's start.
  void (*gram)(double* acc, int ld, const double* B, int ldb, int k, int m);
};

const Kernels& portableKernels();

/// The kernels of several samples at once (kernels_lanes.hpp), one sample per vector lane. Every
/// copy gives the same bits as the portable one-sample kernel for each sample.
/// torqueRegressors: sample k's q_j at q[k + ldx j] (likewise qd, qdd), its n x 10n regressor
/// at Y + k strideY with leading dimension ldY.
using TorqueRegressorsFn = void (*)(const RobotModel&, DynamicsData&, int count, const double* q,
                                    const double* qd, const double* qdd, long ldx, double* Y,
                                    long ldY, long strideY);
/// inverseDynamics (RNEA): sample k's tau_j at tau[k + ldt j]; pi as Kernels::inverseDynamics.
using InverseDynamicsLanesFn = void (*)(const RobotModel&, DynamicsData&, int count,
                                        const double* q, const double* qd, const double* qdd,
                                        long ldx, const double* pi, double* tau, long ldt);
/// energyRegressors: sample k's kinetic and potential rows at kinetic[k + ldk c] and
/// potential[k + ldk c], c < 10n.
using EnergyRegressorsFn = void (*)(const RobotModel&, DynamicsData&, int count, const double* q,
                                    const double* qd, long ldx, double* kinetic, double* potential,
                                    long ldk);
/// torqueRegressorVjps: sample k's G (n x 10n, leading dimension ldG) at G + k strideG, its
/// gradients at gq[k + ldo j] (likewise gqd, gqdd; null: not computed).
using TorqueRegressorVjpsFn = void (*)(const RobotModel&, DynamicsData&, int count, const double* q,
                                       const double* qd, const double* qdd, long ldx,
                                       const double* G, long ldG, long strideG, double* gq,
                                       double* gqd, double* gqdd, long ldo);
/// energyRegressorVjps: sample k's Gk and Gu at Gk[k + ldg c], Gu[k + ldg c], c < 10n; its
/// gradients at gq[k + ldo j], gqd[k + ldo j] (null: not computed).
using EnergyRegressorVjpsFn = void (*)(const RobotModel&, DynamicsData&, int count, const double* q,
                                       const double* qd, long ldx, const double* Gk,
                                       const double* Gu, long ldg, double* gq, double* gqd,
                                       long ldo);
struct LaneKernels {
  Lanes lanes;
  TorqueRegressorsFn torqueRegressors;
  InverseDynamicsLanesFn inverseDynamics;
  EnergyRegressorsFn energyRegressors;
  TorqueRegressorVjpsFn torqueRegressorVjps;
  EnergyRegressorVjpsFn energyRegressorVjps;
};
/// Two samples at once in the baseline's registers (SSE2).
const LaneKernels* portableLaneKernels();
/// Four samples at once in AVX registers; null when the build has no such copy (it does not
/// check the CPU).
const LaneKernels* avxLaneKernels();
/// Null when the build has no AVX2 copy (not x86-64, or not GCC/Clang).
const Kernels* avx2Kernels();

/// The portable Gram block update (Kernels::gram's layout) compiled for AVX without FMA: the same
/// bits as the portable one; null when the build has no such copy.
using GramFn = void (*)(double* acc, int ld, const double* B, int ldb, int k, int m);
GramFn avxLanesGram();
GramFn portableGram();
/// The gram update gramUpdate runs: the active copy's when it is not the portable one, else
/// the AVX lanes' where the CPU has AVX (and the lane copy in use is AVX), else the portable.
GramFn activeGram();

/// The copy in use (EXID_ISA, else the best the CPU runs; setActiveIsa).
const Kernels& kernels();

/// The lane copy in use (setActiveLanes); null when the kernels in use are not the portable ones
/// (theirs run sample by sample then).
const LaneKernels* activeLanes();

}  // namespace exid::detail
