// exid — sin, cos, exp and log that give the same bits on every CPU (docs/excitation.md §6).
//
// glibc's libm chooses its sin, cos, exp, log at load time by CPU (FMA/AVX2 variants or not);
// the variants may differ in the last bit, and a design study's forty SLSQP runs turn one bit
// into another basin. The excitation path (the kernels' joint sines and cosines, the Fourier
// series, the optimisers' logarithms and KS exponentials) calls these instead: fdlibm's
// algorithms (argument reduction by pi/2 or ln 2 in several exact pieces, minimax polynomials),
// written in plain double arithmetic and compiled without floating-point contraction
// (-ffp-contract=off on framework/base/src/fmath.cpp), so that every IEEE-754 machine rounds
// every step alike. Accuracy: below one unit in the last place
// (tests/unit/base/fmath_test.cpp compares them with libm over millions of arguments).
//
// sin and cos reduce |x| < 2^20 pi/2 (about 1.6e6 rad) themselves; beyond that (never a joint
// angle or a phase w l t of a design) they return libm's value, which may then differ by a bit
// between CPUs.
#pragma once

#include "exid/export.hpp"

namespace exid::fmath {

EXID_API double sin(double x);
EXID_API double cos(double x);
// s = sin x, c = cos x (one reduction for both)
EXID_API void sincos(double x, double* s, double* c);
EXID_API double exp(double x);
// natural logarithm: -inf at +-0, NaN below 0
EXID_API double log(double x);

}  // namespace exid::fmath
