// exid — the instruction sets the hot dynamics kernels are compiled for, and which one runs
// (docs/dynamics.md §6). The torque and energy regressors, the RNEA inverse dynamics, the
// regressors' vector-Jacobian products and GramAccumulator run one copy of their kernels, chosen
// once per process from the CPU: AVX2 + FMA where the CPU has both (optimised x86-64 builds),
// the portable copy (the build's baseline instruction set) otherwise. The environment
// variable EXID_ISA=portable|avx2 (read at the first call) forces one; the functions here let
// tests and benchmarks compare them in one process. Not installed.
#pragma once

#include <vector>

#include "exid/export.hpp"
#include "exid/robot_model.hpp"

namespace exid {

enum class Isa { Portable, Avx2 };

/// "portable" or "avx2" (the names EXID_ISA takes).
EXID_API const char* isaName(Isa isa);
/// The copies this build has and this CPU can run, portable first.
EXID_API std::vector<Isa> availableIsas();
/// The copy in use.
EXID_API Isa activeIsa();
/// Uses `isa` from now on, in every thread (throws exid::Error when not available). For tests and
/// benchmarks: not to be called while another thread runs a kernel.
EXID_API void setActiveIsa(Isa isa);

/// Where torqueRegressors (exid/dynamics.hpp) computes several samples at once with the portable
/// kernels: two in the baseline's vector registers (SSE2 on x86-64), or four in AVX registers where
/// the build has that copy and the CPU runs it (the default then). Both give the same bits as the
/// portable torqueRegressor, on every CPU.
enum class Lanes { Baseline, Avx };
/// "baseline" or "avx".
EXID_API const char* lanesName(Lanes lanes);
/// The lane copies this build has and this CPU can run, baseline first.
EXID_API std::vector<Lanes> availableLanes();
/// The lane copy in use.
EXID_API Lanes activeLanes();
/// Uses `lanes` from now on (throws exid::Error when not available); as setActiveIsa.
EXID_API void setActiveLanes(Lanes lanes);

/// The kernels whose operations kernelFlops() counts.
enum class Kernel {
  TorqueRegressor,
  InverseDynamics,
  EnergyRegressor,
  TorqueRegressorVjp,
  EnergyRegressorVjp
};

/// Floating-point operations of one call of a kernel on `model`, counted from the source: every
/// +, -, * and / the code executes (an FMA is two), walking the same joint structure as the
/// kernel (joint types, ancestors, which fixed transforms are the identity); the joints' sines
/// and cosines (exid's own, exid/fmath.hpp) apart.
struct FlopCount {
  double flops = 0;         ///< +, -, *, / of the rigid-body algorithm
  int sincos = 0;           ///< sines and cosines (one of each per revolute joint angle)
  double sincos_flops = 0;  ///< their +, -, *: the fewest any angle takes (|q| <= pi/4), each pair
};
EXID_API FlopCount kernelFlops(const RobotModel& model, Kernel kernel);

}  // namespace exid
