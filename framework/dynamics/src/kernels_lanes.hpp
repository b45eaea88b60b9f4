// exid — the torque regressor of several samples at once: one sample per vector lane (a structure
// of arrays), so that the latency-bound 3-vector recursions of the forward pass run on 4 samples
// (AVX) or 2 (SSE2) per instruction instead of 1 (docs/dynamics.md §6).
//
// Written once for a lane type T (double: one sample; a GCC vector of 2 or 4 doubles) and
// compiled in kernels_portable.cpp (double, and 2 lanes in the baseline's SSE2 registers) and
// kernels_lanes_avx.cpp (4 lanes in AVX registers). Every lane executes the same sequence of
// IEEE additions, subtractions and multiplications, never contracted into fused multiply-adds
// (those sources compile with -ffp-contract=off and without FMA), and the joint sines and
// cosines are exid's own (exid/fmath.hpp, in vector lanes exid/fmath_kernels.hpp): every lane
// width, and every CPU, gives the same bits.
//
// Each including source defines EXID_LANES_NS (the namespace of its copy) and EXID_LANES_KERNEL
// (the attributes of its entry point) first. Everything here has internal linkage. Not a public
// header.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>

#include "exid/fmath.hpp"
#include "exid/fmath_kernels.hpp"
#include "rigid_body.hpp"

#if !defined(EXID_LANES_NS) || !defined(EXID_LANES_KERNEL)
#error "define EXID_LANES_NS and EXID_LANES_KERNEL before including kernels_lanes.hpp"
#endif

// (a 4-double vector passed by value between these internal functions: no ABI crosses here)
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wpsabi"
#endif

namespace exid::detail::EXID_LANES_NS {
namespace {

typedef double Lane4 __attribute__((vector_size(32)));
typedef double Lane2 __attribute__((vector_size(16)));
typedef long long LaneInt4 __attribute__((vector_size(32)));  // lane masks and bit patterns
typedef long long LaneInt2 __attribute__((vector_size(16)));

template <class T>
struct LaneTraits;
template <>
struct LaneTraits<double> {
  static constexpr int kWidth = 1;
  static double get(double x, int) { return x; }
  static void set(double& x, int, double v) { x = v; }
  static double broadcast(double v) { return v; }
};
template <>
struct LaneTraits<Lane4> {
  static constexpr int kWidth = 4;
  using Int = LaneInt4;
  static double get(const Lane4& x, int l) { return x[l]; }
  static void set(Lane4& x, int l, double v) { x[l] = v; }
  static Lane4 broadcast(double v) { return Lane4{v, v, v, v}; }
};

template <>
struct LaneTraits<Lane2> {
  static constexpr int kWidth = 2;
  using Int = LaneInt2;
  static double get(const Lane2& x, int l) { return x[l]; }
  static void set(Lane2& x, int l, double v) { x[l] = v; }
  static Lane2 broadcast(double v) { return Lane2{v, v}; }
};

// Lanes 0 .. lanes - 1 from src[0 .. lanes - 1] (consecutive samples of one input column), the
// lanes past them repeating the last: one vector load when every lane is a sample (built lane
// by lane in memory, the vector would be read back through a stalled store forwarding).
template <class T>
inline T loadLanes(const double* src, int lanes) {
  T v;
  if (lanes == LaneTraits<T>::kWidth) {
    std::memcpy(&v, src, sizeof(T));
    return v;
  }
  for (int l = 0; l < LaneTraits<T>::kWidth; ++l)
    LaneTraits<T>::set(v, l, src[l < lanes ? l : lanes - 1]);
  return v;
}

// The first `lanes` lanes of v to dst[0 .. lanes - 1] (consecutive samples of one output
// column): one vector store when every lane is a sample.
template <class T>
inline void storeLanes(double* dst, const T& v, int lanes) {
  if (lanes == LaneTraits<T>::kWidth) {
    std::memcpy(dst, &v, sizeof(T));
    return;
  }
  for (int l = 0; l < lanes; ++l) dst[l] = LaneTraits<T>::get(v, l);
}

// Two vectors' lanes interleaved as the indices say (0 .. W-1: a's lanes, W .. 2W-1: b's): GCC's
// and clang's spelling of one shuffle.
template <int I0, int I1, int I2, int I3>
inline Lane4 shuffle4(const Lane4& a, const Lane4& b) {
#if defined(__clang__)
  return __builtin_shufflevector(a, b, I0, I1, I2, I3);
#else
  return __builtin_shuffle(a, b, LaneInt4{I0, I1, I2, I3});
#endif
}
template <int I0, int I1>
inline Lane2 shuffle2(const Lane2& a, const Lane2& b) {
#if defined(__clang__)
  return __builtin_shufflevector(a, b, I0, I1);
#else
  return __builtin_shuffle(a, b, LaneInt2{I0, I1});
#endif
}

// Lane l of rows[0 .. m - 1] to dst[stride l .. stride l + m - 1] for every lane l (a block of
// whole lanes): the m x W block transposed in registers, four rows (AVX) or two (SSE2) at a time,
// and written with one vector store per lane and group of rows, where a store of each lane
// alone would extract every element and compute its address.
inline void storeTransposed(const double* rows, int m, double* dst, long) {
  std::memcpy(dst, rows, sizeof(double) * static_cast<std::size_t>(m));
}
inline void storeTransposed(const Lane2* rows, int m, double* dst, long stride) {
  int i = 0;
  for (; i + 2 <= m; i += 2) {
    const Lane2 r0 = shuffle2<0, 2>(rows[i], rows[i + 1]);
    const Lane2 r1 = shuffle2<1, 3>(rows[i], rows[i + 1]);
    std::memcpy(dst + i, &r0, sizeof(Lane2));
    std::memcpy(dst + stride + i, &r1, sizeof(Lane2));
  }
  if (i < m) {
    dst[i] = rows[i][0];
    dst[stride + i] = rows[i][1];
  }
}
inline void storeTransposed(const Lane4* rows, int m, double* dst, long stride) {
  int i = 0;
  for (; i + 4 <= m; i += 4) {
    const Lane4 t0 = shuffle4<0, 4, 2, 6>(rows[i], rows[i + 1]);      // a0 b0 a2 b2
    const Lane4 t1 = shuffle4<1, 5, 3, 7>(rows[i], rows[i + 1]);      // a1 b1 a3 b3
    const Lane4 t2 = shuffle4<0, 4, 2, 6>(rows[i + 2], rows[i + 3]);  // c0 d0 c2 d2
    const Lane4 t3 = shuffle4<1, 5, 3, 7>(rows[i + 2], rows[i + 3]);  // c1 d1 c3 d3
    const Lane4 r0 = shuffle4<0, 1, 4, 5>(t0, t2), r1 = shuffle4<0, 1, 4, 5>(t1, t3);
    const Lane4 r2 = shuffle4<2, 3, 6, 7>(t0, t2), r3 = shuffle4<2, 3, 6, 7>(t1, t3);
    std::memcpy(dst + i, &r0, sizeof(Lane4));
    std::memcpy(dst + stride + i, &r1, sizeof(Lane4));
    std::memcpy(dst + 2 * stride + i, &r2, sizeof(Lane4));
    std::memcpy(dst + 3 * stride + i, &r3, sizeof(Lane4));
  }
  if (i + 2 <= m) {
    const Lane4 u0 = shuffle4<0, 4, 2, 6>(rows[i], rows[i + 1]);  // lane 0's pair, lane 2's
    const Lane4 u1 = shuffle4<1, 5, 3, 7>(rows[i], rows[i + 1]);  // lane 1's, lane 3's
    const Lane2 p0 = {u0[0], u0[1]}, p1 = {u1[0], u1[1]}, p2 = {u0[2], u0[3]}, p3 = {u1[2], u1[3]};
    std::memcpy(dst + i, &p0, sizeof(Lane2));
    std::memcpy(dst + stride + i, &p1, sizeof(Lane2));
    std::memcpy(dst + 2 * stride + i, &p2, sizeof(Lane2));
    std::memcpy(dst + 3 * stride + i, &p3, sizeof(Lane2));
    i += 2;
  }
  if (i < m)
    for (int l = 0; l < 4; ++l) dst[stride * l + i] = rows[i][l];
}

// sin and cos of each lane: the bits of exid::fmath::sincos for that lane's value, computed for
// all lanes at once (exid/fmath_kernels.hpp) unless a lane is beyond the vector path's range
// (|q| >= 2^20 pi/2, inf, NaN: every lane then goes through the scalar function)
inline void laneSincos(double x, double& s, double& c) { exid::fmath::sincos(x, &s, &c); }
template <class T>
inline void laneSincos(const T& x, T& s, T& c) {
  using Tr = LaneTraits<T>;
  using I = typename Tr::Int;
  if (!exid::fmath::kernels::anyBeyondMedium<T, I, Tr::kWidth>(x)) {
    exid::fmath::kernels::sincosVector<T, I, Tr::kWidth>(x, s, c);
    return;
  }
  for (int l = 0; l < Tr::kWidth; ++l) {
    double s1, c1;
    exid::fmath::sincos(Tr::get(x, l), &s1, &c1);
    Tr::set(s, l, s1);
    Tr::set(c, l, c1);
  }
}

template <class T>
struct L3 {
  T c[3];
};
template <class T>
struct LS {  // spatial motion vector {angular, linear}
  L3<T> w, v;
};
template <class T>
struct LR {  // rotation, column-major: m[r + 3 c]
  T m[9];
};

template <class T>
inline L3<T> add(const L3<T>& a, const L3<T>& b) {
  return {{a.c[0] + b.c[0], a.c[1] + b.c[1], a.c[2] + b.c[2]}};
}
template <class T>
inline L3<T> cross(const L3<T>& a, const L3<T>& b) {
  return {{a.c[1] * b.c[2] - a.c[2] * b.c[1], a.c[2] * b.c[0] - a.c[0] * b.c[2],
           a.c[0] * b.c[1] - a.c[1] * b.c[0]}};
}
// R^T x
template <class T>
inline L3<T> rtMul(const LR<T>& R, const L3<T>& x) {
  L3<T> o;
  for (int i = 0; i < 3; ++i)
    o.c[i] = R.m[3 * i] * x.c[0] + R.m[3 * i + 1] * x.c[1] + R.m[3 * i + 2] * x.c[2];
  return o;
}
// R x
template <class T>
inline L3<T> rMul(const LR<T>& R, const L3<T>& x) {
  L3<T> o;
  for (int i = 0; i < 3; ++i) o.c[i] = R.m[i] * x.c[0] + R.m[i + 3] * x.c[1] + R.m[i + 6] * x.c[2];
  return o;
}
// the symmetric 3 x 3 g[0..5] (XX XY XZ YY YZ ZZ; constants or lanes) times x (symMul in
// rigid_body.hpp)
template <class G, class T>
inline L3<T> symMul(const G* g, const L3<T>& x) {
  return {{g[0] * x.c[0] + g[1] * x.c[1] + g[2] * x.c[2],
           g[1] * x.c[0] + g[3] * x.c[1] + g[4] * x.c[2],
           g[2] * x.c[0] + g[4] * x.c[1] + g[5] * x.c[2]}};
}
// the motion transform parent -> child (the child's pose (R, p) in the parent)
template <class T>
inline LS<T> xMotion(const LR<T>& R, const L3<T>& p, const LS<T>& m) {
  return {rtMul(R, m.w), rtMul(R, add(m.v, cross(m.w, p)))};
}
template <class T>
inline L3<T> constant3(const V3& x) {
  using Tr = LaneTraits<T>;
  return {{Tr::broadcast(x[0]), Tr::broadcast(x[1]), Tr::broadcast(x[2])}};
}

template <class T>
inline L3<T> sub(const L3<T>& a, const L3<T>& b) {
  return {{a.c[0] - b.c[0], a.c[1] - b.c[1], a.c[2] - b.c[2]}};
}
template <class T>
inline T dot3(const L3<T>& a, const L3<T>& b) {
  return a.c[0] * b.c[0] + a.c[1] * b.c[1] + a.c[2] * b.c[2];
}
// dot(S, m) for a constant S: S.w . m.w + S.v . m.v
template <class T>
inline T dotS(const SV& S, const LS<T>& m) {
  return (S.w[0] * m.w.c[0] + S.w[1] * m.w.c[1] + S.w[2] * m.w.c[2]) +
         (S.v[0] * m.v.c[0] + S.v[1] * m.v.c[1] + S.v[2] * m.v.c[2]);
}
// dotCrm(S, b, c) = c . (S x b) (motion cross) for a constant S
template <class T>
inline T dotCrmS(const SV& S, const LS<T>& b, const LS<T>& c) {
  const L3<T> sw = constant3<T>(S.w), sv = constant3<T>(S.v);
  return dot3(c.w, cross(sw, b.w)) + dot3(c.v, add(cross(sw, b.v), cross(sv, b.w)));
}
// the force transform child -> parent: {R f.w + p x (R f.v), R f.v}
template <class T>
inline LS<T> xForceT(const LR<T>& R, const L3<T>& p, const LS<T>& f) {
  const L3<T> fv = rMul(R, f.v);
  return {add(rMul(R, f.w), cross(p, fv)), fv};
}
template <class T>
inline void addTo(LS<T>& a, const LS<T>& b) {
  a.w = add(a.w, b.w);
  a.v = add(a.v, b.v);
}
template <class T>
inline L3<T> scale(const T& s, const L3<T>& x) {
  return {{s * x.c[0], s * x.c[1], s * x.c[2]}};
}
// Newton-Euler wrench of a body with parameters g (ten lanes, pi order) and kinematics (w, wd,
// ao): the operations of newtonEuler (rigid_body.hpp) and of inverseDynamicsImpl's.
template <class T>
inline LS<T> newtonEulerL(const T* g, const L3<T>& w, const L3<T>& wd, const L3<T>& ao) {
  const L3<T> hl = {{g[6], g[7], g[8]}};
  const L3<T> wh = cross(w, hl);
  const L3<T> Iwd = symMul(g, wd), Iw = symMul(g, w);
  const L3<T> a1 = cross(w, Iw), a2 = cross(hl, ao), b1 = cross(wd, hl), b2 = cross(w, wh);
  LS<T> f;
  for (int r = 0; r < 3; ++r) {
    f.w.c[r] = Iwd.c[r] + a1.c[r] + a2.c[r];
    f.v.c[r] = g[9] * ao.c[r] + b1.c[r] + b2.c[r];
  }
  return f;
}

// The workspace of `width` lanes in d.lane_ws (aligned for T): per joint R, p, v, a, ao, the
// base pose (R0, p0), the body force f, the parent's motion and acceleration carried into the
// body's frame (xv, xa) and the adjoints of the reverse pass (vb, ab; wb, wdb, aob); per ancestor
// pair the subspace s and its adjoint sb.
template <class T>
struct LaneWork {
  LR<T>* R;
  L3<T>* p;
  LS<T>* v;
  LS<T>* a;
  L3<T>* ao;
  LR<T>* R0;
  L3<T>* p0;
  LS<T>* f;
  LS<T>* s;
  LS<T>* xv;
  LS<T>* xa;
  LS<T>* vb;
  LS<T>* ab;
  L3<T>* wb;
  L3<T>* wdb;
  L3<T>* aob;
  LS<T>* sb;
  T* tq;   // four lane vectors per joint (the VJPs' gradients: tq[j + n r], r < 4)
  T* col;  // ten lane vectors per joint (a body's ten regressor columns, row i of column c at
           // col[n c + i], before storeTransposed)
};
template <class T>
inline LaneWork<T> laneWork(DynamicsData& d) {
  const std::size_t n = static_cast<std::size_t>(d.n), P = d.anc_idx.size();
  constexpr std::size_t kPerJoint =
      9 + 3 + 6 + 6 + 3 + 9 + 3 + 6 + 6 + 6 + 6 + 6 + 3 + 3 + 3 + 4 + 10;
  const std::size_t words = kPerJoint * n + 12 * P;  // lanes of T
  const std::size_t need = words * (sizeof(T) / sizeof(double)) + alignof(T) / sizeof(double);
  if (d.lane_ws.size() < need) d.lane_ws.assign(need, 0.0);
  auto addr = reinterpret_cast<std::uintptr_t>(d.lane_ws.data());
  addr = (addr + alignof(T) - 1) & ~static_cast<std::uintptr_t>(alignof(T) - 1);
  T* base = reinterpret_cast<T*>(addr);
  LaneWork<T> w;
  w.R = reinterpret_cast<LR<T>*>(base);
  w.p = reinterpret_cast<L3<T>*>(base + 9 * n);
  w.v = reinterpret_cast<LS<T>*>(base + 12 * n);
  w.a = reinterpret_cast<LS<T>*>(base + 18 * n);
  w.ao = reinterpret_cast<L3<T>*>(base + 24 * n);
  w.R0 = reinterpret_cast<LR<T>*>(base + 27 * n);
  w.p0 = reinterpret_cast<L3<T>*>(base + 36 * n);
  w.f = reinterpret_cast<LS<T>*>(base + 39 * n);
  w.xv = reinterpret_cast<LS<T>*>(base + 45 * n);
  w.xa = reinterpret_cast<LS<T>*>(base + 51 * n);
  w.vb = reinterpret_cast<LS<T>*>(base + 57 * n);
  w.ab = reinterpret_cast<LS<T>*>(base + 63 * n);
  w.wb = reinterpret_cast<L3<T>*>(base + 69 * n);
  w.wdb = reinterpret_cast<L3<T>*>(base + 72 * n);
  w.aob = reinterpret_cast<L3<T>*>(base + 75 * n);
  w.tq = base + 78 * n;
  w.col = base + 82 * n;
  w.s = reinterpret_cast<LS<T>*>(base + kPerJoint * n);
  w.sb = reinterpret_cast<LS<T>*>(base + kPerJoint * n + 6 * P);
  return w;
}

// The forward pass of the samples k0 .. k0 + lanes - 1 (the lanes past the last repeat it; a
// null qd or qdd: zero, at rest):
// every joint's pose in its parent (R, p), and with `velocity` its body's spatial velocity v,
// with `acceleration` also its acceleration a (gravity as the base's acceleration) and the
// classical acceleration of its origin ao. The same operations, in the same order, as the
// portable forward pass (kernels.hpp).
template <class T>
inline void lanesForward(const RobotModel& model, DynamicsData& d, const LaneWork<T>& ws, int k0,
                         int lanes, const double* q, const double* qd, const double* qdd, long ldx,
                         bool acceleration) {
  using Tr = LaneTraits<T>;
  const int n = d.n;
  const L3<T> g0 = {{Tr::broadcast(-model.gravity[0]), Tr::broadcast(-model.gravity[1]),
                     Tr::broadcast(-model.gravity[2])}};
  const T zero = Tr::broadcast(0.0);
  for (int j = 0; j < n; ++j) {
    const JointC& c = d.J[static_cast<std::size_t>(j)];
    const T qj = loadLanes<T>(q + k0 + ldx * j, lanes);
    const T qdj = qd ? loadLanes<T>(qd + k0 + ldx * j, lanes) : zero;
    const T qddj = acceleration && qdd ? loadLanes<T>(qdd + k0 + ldx * j, lanes) : zero;
    LR<T>& R = ws.R[j];
    L3<T>& p = ws.p[j];
    if (c.revolute) {
      T sq, cq;
      laneSincos(qj, sq, cq);
      LR<T> M;
      for (int r = 0; r < 3; ++r) {
        M.m[r] = c.Rpre(r, 0) * cq + c.Rpre(r, 1) * sq;
        M.m[r + 3] = c.Rpre(r, 1) * cq - c.Rpre(r, 0) * sq;
        M.m[r + 6] = Tr::broadcast(c.Rpre(r, 2));
      }
      if (c.post_R_id) {
        R = M;
      } else {
        for (int col = 0; col < 3; ++col)
          for (int r = 0; r < 3; ++r)
            R.m[r + 3 * col] = M.m[r] * c.Rpost(0, col) + M.m[r + 3] * c.Rpost(1, col) +
                               M.m[r + 6] * c.Rpost(2, col);
      }
      for (int r = 0; r < 3; ++r) {
        if (c.post_p_zero)
          p.c[r] = Tr::broadcast(c.ppre[r]);
        else
          p.c[r] =
              c.ppre[r] + (M.m[r] * c.ppost[0] + M.m[r + 3] * c.ppost[1] + M.m[r + 6] * c.ppost[2]);
      }
    } else {
      for (int i = 0; i < 9; ++i) R.m[i] = Tr::broadcast(c.Rfix(i % 3, i / 3));
      for (int r = 0; r < 3; ++r) p.c[r] = c.pfix[r] + c.Rpre(r, 2) * qj;
    }
    const int par = c.parent;
    LS<T>& xv = ws.xv[j];
    if (par >= 0)
      xv = xMotion(R, p, ws.v[par]);
    else
      xv = {{{zero, zero, zero}}, {{zero, zero, zero}}};
    LS<T> u;
    for (int r = 0; r < 3; ++r) {
      u.w.c[r] = c.S.w[r] * qdj;
      u.v.c[r] = c.S.v[r] * qdj;
    }
    LS<T>& v = ws.v[j];
    v.w = add(xv.w, u.w);
    v.v = add(xv.v, u.v);
    if (!acceleration) continue;
    const LS<T> a0 = {{{zero, zero, zero}}, g0};
    LS<T>& xa = ws.xa[j];
    xa = xMotion(R, p, par >= 0 ? ws.a[par] : a0);
    // crm(v, u) = {v.w x u.w, v.w x u.v + v.v x u.w}
    const L3<T> cw = cross(v.w, u.w);
    const L3<T> cv = add(cross(v.w, u.v), cross(v.v, u.w));
    LS<T>& a = ws.a[j];
    for (int r = 0; r < 3; ++r) {
      a.w.c[r] = xa.w.c[r] + c.S.w[r] * qddj + cw.c[r];
      a.v.c[r] = xa.v.c[r] + c.S.v[r] * qddj + cv.c[r];
    }
    ws.ao[j] = add(a.v, cross(v.w, v.v));
  }
}

// The samples T's width at a time: each block's forward pass (lanesForward), then
// body(ws, k0, lanes) on it; the lanes past the last sample repeat it.
template <class T, class Body>
inline void forLaneBlocks(const RobotModel& model, DynamicsData& d, int count, const double* q,
                          const double* qd, const double* qdd, long ldx, bool acceleration,
                          Body&& body) {
  constexpr int W = LaneTraits<T>::kWidth;
  const LaneWork<T> ws = laneWork<T>(d);
  for (int k0 = 0; k0 < count; k0 += W) {
    const int lanes = count - k0 < W ? count - k0 : W;
    lanesForward(model, d, ws, k0, lanes, q, qd, qdd, ldx, acceleration);
    body(ws, k0, lanes);
  }
}

// The ancestors' subspaces in every body's frame (s[anc_off[j]] is the joint's own), after
// lanesForward (ancestorSubspacesImpl in kernels.hpp).
template <class T>
inline void laneSubspaces(const DynamicsData& d, const LaneWork<T>& ws) {
  for (int j = 0; j < d.n; ++j) {
    const JointC& c = d.J[static_cast<std::size_t>(j)];
    const int oj = d.anc_off[static_cast<std::size_t>(j)];
    ws.s[oj].w = constant3<T>(c.S.w);
    ws.s[oj].v = constant3<T>(c.S.v);
    const int par = c.parent;
    if (par < 0) continue;
    const int op = d.anc_off[static_cast<std::size_t>(par)];
    const int cnt = d.anc_off[static_cast<std::size_t>(j) + 1] - oj;
    for (int t = 1; t < cnt; ++t) ws.s[oj + t] = xMotion(ws.R[j], ws.p[j], ws.s[op + t - 1]);
  }
}

// Torque regressors of `count` samples (see Kernels in kernel_table.hpp for the layout), T's
// width at a time; the lanes past the last sample repeat it and are not written.
template <class T>
inline void torqueRegressorsImpl(const RobotModel& model, DynamicsData& d, int count,
                                 const double* q, const double* qd, const double* qdd, long ldx,
                                 double* Y, long ldY, long strideY) {
  using Tr = LaneTraits<T>;
  const int n = d.n;
  forLaneBlocks<T>(
      model, d, count, q, qd, qdd, ldx, true, [&](const LaneWork<T>& ws, int k0, int lanes) {
        laneSubspaces(d, ws);
        // the rows: body j's ten columns, one row per ancestor i of j (pairRow in rigid_body.hpp)
        for (int j = 0; j < n; ++j) {
          const int oj = d.anc_off[static_cast<std::size_t>(j)];
          const int cnt = d.anc_off[static_cast<std::size_t>(j) + 1] - oj;
          const L3<T>& w = ws.v[j].w;
          const L3<T>& wd = ws.a[j].w;
          const L3<T>& ao = ws.ao[j];
          // a block of whole lanes: the ten columns' rows gathered in ws.col, then written a
          // column at a time, transposed (every row of a column: its ancestors' and the zeros)
          const bool whole = lanes == Tr::kWidth;
          for (int t = d.off_off[static_cast<std::size_t>(j)];
               t < d.off_off[static_cast<std::size_t>(j) + 1]; ++t) {
            const int i = d.off_idx[static_cast<std::size_t>(t)];
            if (whole) {
              for (int col = 0; col < 10; ++col) ws.col[n * col + i] = Tr::broadcast(0.0);
              continue;
            }
            for (int l = 0; l < lanes; ++l)
              for (int col = 0; col < 10; ++col)
                Y[strideY * (k0 + l) + ldY * (10 * j + col) + i] = 0.0;
          }
          for (int t = 0; t < cnt; ++t) {
            const int i = d.anc_idx[static_cast<std::size_t>(oj + t)];
            const L3<T>& sw = ws.s[oj + t].w;
            const L3<T>& sv = ws.s[oj + t].v;
            const L3<T> x = cross(sw, w);
            T out[10];
            out[0] = sw.c[0] * wd.c[0] + x.c[0] * w.c[0];
            out[1] = sw.c[0] * wd.c[1] + sw.c[1] * wd.c[0] + x.c[0] * w.c[1] + x.c[1] * w.c[0];
            out[2] = sw.c[0] * wd.c[2] + sw.c[2] * wd.c[0] + x.c[0] * w.c[2] + x.c[2] * w.c[0];
            out[3] = sw.c[1] * wd.c[1] + x.c[1] * w.c[1];
            out[4] = sw.c[1] * wd.c[2] + sw.c[2] * wd.c[1] + x.c[1] * w.c[2] + x.c[2] * w.c[1];
            out[5] = sw.c[2] * wd.c[2] + x.c[2] * w.c[2];
            const L3<T> hc = add(add(cross(ao, sw), cross(sv, wd)), cross(cross(sv, w), w));
            out[6] = hc.c[0];
            out[7] = hc.c[1];
            out[8] = hc.c[2];
            out[9] = sv.c[0] * ao.c[0] + sv.c[1] * ao.c[1] + sv.c[2] * ao.c[2];
            if (whole) {
              for (int col = 0; col < 10; ++col) ws.col[n * col + i] = out[col];
              continue;
            }
            for (int l = 0; l < lanes; ++l) {
              double* Yi = Y + strideY * (k0 + l) + ldY * 10 * j + i;
              for (int col = 0; col < 10; ++col) Yi[ldY * col] = Tr::get(out[col], l);
            }
          }
          if (whole)
            for (int col = 0; col < 10; ++col)
              storeTransposed(ws.col + n * col, n, Y + strideY * k0 + ldY * (10 * j + col),
                              strideY);
        }
      });
}

// Inverse dynamics (RNEA) of `count` samples: sample k's q_j at q[k + ldx j] (likewise qd, qdd),
// its tau_j at tau[k + ldt j]; parameters pi (10 per body, pi order) or, when null, the
// model's. The same operations, in the same order, as the portable RNEA (kernels.hpp:
// newtonEuler and the backward pass of rigid_body.hpp).
template <class T>
inline void inverseDynamicsImpl(const RobotModel& model, DynamicsData& d, int count,
                                const double* q, const double* qd, const double* qdd, long ldx,
                                const double* pi, double* tau, long ldt) {
  const int n = d.n;
  forLaneBlocks<T>(
      model, d, count, q, qd, qdd, ldx, true, [&](const LaneWork<T>& ws, int k0, int lanes) {
        for (int j = 0; j < n; ++j) {  // newtonEuler(g, kin)
          const double* g =
              pi ? pi + 10 * j : model.bodies[static_cast<std::size_t>(j)].inertia.data();
          const L3<T>& w = ws.v[j].w;
          const L3<T>& wd = ws.a[j].w;
          const L3<T>& ao = ws.ao[j];
          const V3 h(g[6], g[7], g[8]);
          const double m = g[9];
          const L3<T> hl = constant3<T>(h);
          const L3<T> wh = cross(w, hl);
          const L3<T> Iwd = symMul(g, wd), Iw = symMul(g, w);
          const L3<T> a1 = cross(w, Iw), a2 = cross(hl, ao), b1 = cross(wd, hl), b2 = cross(w, wh);
          LS<T>& f = ws.f[j];
          for (int r = 0; r < 3; ++r) {
            f.w.c[r] = Iwd.c[r] + a1.c[r] + a2.c[r];
            f.v.c[r] = m * ao.c[r] + b1.c[r] + b2.c[r];
          }
        }
        for (int j = n - 1; j >= 0; --j) {
          const JointC& c = d.J[static_cast<std::size_t>(j)];
          const LS<T>& f = ws.f[j];
          // dot(S, f) = S.w . f.w + S.v . f.v
          const T t = (c.S.w[0] * f.w.c[0] + c.S.w[1] * f.w.c[1] + c.S.w[2] * f.w.c[2]) +
                      (c.S.v[0] * f.v.c[0] + c.S.v[1] * f.v.c[1] + c.S.v[2] * f.v.c[2]);
          storeLanes(tau + k0 + ldt * j, t, lanes);
          const int par = c.parent;
          if (par < 0) continue;
          // xForceT(R, p, f) = {R f.w + p x (R f.v), R f.v}, added to the parent's force
          const LR<T>& R = ws.R[j];
          const L3<T>& p = ws.p[j];
          const L3<T> fv = rMul(R, f.v), Rfw = rMul(R, f.w);
          const L3<T> pf = cross(p, fv);
          LS<T>& fp = ws.f[par];
          for (int r = 0; r < 3; ++r) {
            fp.w.c[r] = fp.w.c[r] + (Rfw.c[r] + pf.c[r]);
            fp.v.c[r] = fp.v.c[r] + fv.c[r];
          }
        }
      });
}

// Energy regressors of `count` samples: sample k's kinetic row (1 x 10n) at kinetic[k + ldk c],
// its potential row likewise. The same operations, in the same order, as the portable
// energyRegressor (kernels.hpp).
template <class T>
inline void energyRegressorsImpl(const RobotModel& model, DynamicsData& d, int count,
                                 const double* q, const double* qd, long ldx, double* kinetic,
                                 double* potential, long ldk) {
  const int n = d.n;
  const V3& g = model.gravity;
  // the potential row's first six entries of every body are zero: each such column written
  // once over all the samples (contiguous), not four lanes at a time beside the others
  for (int j = 0; j < n; ++j)
    for (int c = 0; c < 6; ++c) std::fill_n(potential + ldk * (10 * j + c), count, 0.0);
  forLaneBlocks<T>(
      model, d, count, q, qd, nullptr, ldx, false, [&](const LaneWork<T>& ws, int k0, int lanes) {
        for (int j = 0; j < n; ++j) {
          const L3<T>& w = ws.v[j].w;
          const L3<T>& vl = ws.v[j].v;
          T K[10];
          K[0] = 0.5 * w.c[0] * w.c[0];
          K[1] = w.c[0] * w.c[1];
          K[2] = w.c[0] * w.c[2];
          K[3] = 0.5 * w.c[1] * w.c[1];
          K[4] = w.c[1] * w.c[2];
          K[5] = 0.5 * w.c[2] * w.c[2];
          const L3<T> hc = cross(vl, w);
          K[6] = hc.c[0];
          K[7] = hc.c[1];
          K[8] = hc.c[2];
          K[9] = 0.5 * (vl.c[0] * vl.c[0] + vl.c[1] * vl.c[1] + vl.c[2] * vl.c[2]);
          // base pose of body j
          const int par = d.J[static_cast<std::size_t>(j)].parent;
          LR<T>& R0 = ws.R0[j];
          L3<T>& p0 = ws.p0[j];
          if (par >= 0) {
            const LR<T>& Rp = ws.R0[par];
            const LR<T>& R = ws.R[j];
            for (int col = 0; col < 3; ++col)
              for (int r = 0; r < 3; ++r)
                R0.m[r + 3 * col] = Rp.m[r] * R.m[3 * col] + Rp.m[r + 3] * R.m[1 + 3 * col] +
                                    Rp.m[r + 6] * R.m[2 + 3 * col];
            const L3<T> Rpp = rMul(Rp, ws.p[j]);
            p0 = add(ws.p0[par], Rpp);
          } else {
            R0 = ws.R[j];
            p0 = ws.p[j];
          }
          T U[4];
          for (int i = 0; i < 3; ++i)  // -(R0^T g)
            U[i] = -(R0.m[3 * i] * g[0] + R0.m[3 * i + 1] * g[1] + R0.m[3 * i + 2] * g[2]);
          U[3] = -(g[0] * p0.c[0] + g[1] * p0.c[1] + g[2] * p0.c[2]);
          double* Kr = kinetic + k0 + ldk * 10 * j;
          double* Ur = potential + k0 + ldk * 10 * j;
          for (int c = 0; c < 10; ++c) storeLanes(Kr + ldk * c, K[c], lanes);
          for (int c = 0; c < 4; ++c) storeLanes(Ur + ldk * (6 + c), U[c], lanes);
        }
      });
}

// The RNEA's backward pass with per-sample parameters g (10 lanes per body; after lanesForward at
// acceleration): every joint's torque into tau[j] (lanes), the body forces into ws.f.
template <class T, class Params>
inline void laneRneaBackward(const DynamicsData& d, const LaneWork<T>& ws, Params&& params,
                             T* tau) {
  const int n = d.n;
  for (int j = 0; j < n; ++j) {
    T g[10];
    params(j, g);
    ws.f[j] = newtonEulerL(g, ws.v[j].w, ws.a[j].w, ws.ao[j]);
  }
  for (int j = n - 1; j >= 0; --j) {
    const JointC& c = d.J[static_cast<std::size_t>(j)];
    tau[j] = dotS(c.S, ws.f[j]);
    if (c.parent >= 0) addTo(ws.f[c.parent], xForceT(ws.R[j], ws.p[j], ws.f[j]));
  }
}

// The reverse pass (reversePassImpl in kernels.hpp) from the adjoints in ws (wb, wdb, aob, vb,
// ab, and sb with `subspaces`) to the gradients in q, qd, qdd of each joint (lanes; null: not
// kept). `acceleration`: the kinematics' adjoints include the accelerations'.
template <class T>
inline void laneReverse(const DynamicsData& d, const LaneWork<T>& ws, int k0, int lanes,
                        const double* qd, long ldx, bool acceleration, bool subspaces, T* gq,
                        T* gqd, T* gqdd) {
  const T zero = LaneTraits<T>::broadcast(0.0);
  for (int j = d.n - 1; j >= 0; --j) {
    const JointC& c = d.J[static_cast<std::size_t>(j)];
    const SV& S = c.S;
    const LS<T>& v = ws.v[j];
    LS<T>& vb = ws.vb[j];
    LS<T>& ab = ws.ab[j];
    T dq = zero, dqd = zero, dqdd = zero;
    if (acceleration) {
      ab.w = add(ab.w, ws.wdb[j]);
      ab.v = add(ab.v, ws.aob[j]);
      vb.w = add(vb.w, add(ws.wb[j], cross(v.v, ws.aob[j])));
      vb.v = add(vb.v, cross(ws.aob[j], v.w));
      dqdd = dotS(S, ab);
      const T qdj = loadLanes<T>(qd + k0 + ldx * j, lanes);
      const L3<T> uw = scale(qdj, constant3<T>(S.w)), uv = scale(qdj, constant3<T>(S.v));
      vb.w = add(vb.w, add(cross(uw, ab.w), cross(uv, ab.v)));
      vb.v = add(vb.v, cross(uw, ab.v));
      const LS<T> ub = {add(cross(ab.w, v.w), cross(ab.v, v.v)), cross(ab.v, v.w)};
      dqd = dqd + dotS(S, ub);
      dq = dq - dotCrmS(S, ws.xa[j], ab);
    } else {
      vb.w = add(vb.w, ws.wb[j]);
    }
    dqd = dqd + dotS(S, vb);
    dq = dq - dotCrmS(S, ws.xv[j], vb);
    const int par = c.parent;
    const int oj = d.anc_off[static_cast<std::size_t>(j)];
    const int cnt = d.anc_off[static_cast<std::size_t>(j) + 1] - oj;
    if (subspaces)
      for (int k = 1; k < cnt; ++k) dq = dq - dotCrmS(S, ws.s[oj + k], ws.sb[oj + k]);
    if (par >= 0) {
      const LR<T>& R = ws.R[j];
      const L3<T>& p = ws.p[j];
      addTo(ws.vb[par], xForceT(R, p, vb));
      if (acceleration) addTo(ws.ab[par], xForceT(R, p, ab));
      if (subspaces) {
        const int op = d.anc_off[static_cast<std::size_t>(par)];
        for (int k = 1; k < cnt; ++k) addTo(ws.sb[op + k - 1], xForceT(R, p, ws.sb[oj + k]));
      }
    }
    if (gq) gq[j] = dq;
    if (gqd) gqd[j] = dqd;
    if (gqdd) gqdd[j] = dqdd;
  }
}

template <class T>
inline void clearLaneAdjoints(const DynamicsData& d, const LaneWork<T>& ws, bool subspaces) {
  const T zero = LaneTraits<T>::broadcast(0.0);
  const L3<T> z3 = {{zero, zero, zero}};
  for (int j = 0; j < d.n; ++j) {
    ws.vb[j] = {z3, z3};
    ws.ab[j] = {z3, z3};
    ws.wb[j] = z3;
    ws.wdb[j] = z3;
    ws.aob[j] = z3;
  }
  if (subspaces)
    for (std::size_t t = 0; t < d.anc_idx.size(); ++t) ws.sb[t] = {z3, z3};
}

// The gradients of <Gk_k, kinetic_k> + <Gu_k, potential_k> (energyRegressorsImpl's rows) in q_k
// (gq, may be null) and qd_k (gqd) of `count` samples: sample k's Gk at Gk[k + ldg c], c < 10n,
// likewise Gu; its gradients at gq[k + ldo j], gqd[k + ldo j]. The operations of the portable
// energyRegressorVjp (kernels.hpp) in every lane.
template <class T>
inline void energyRegressorVjpsImpl(const RobotModel& model, DynamicsData& d, int count,
                                    const double* q, const double* qd, long ldx, const double* Gk,
                                    const double* Gu, long ldg, double* gq, double* gqd, long ldo) {
  const int n = d.n;
  forLaneBlocks<T>(model, d, count, q, qd, nullptr, ldx, false,
                   [&](const LaneWork<T>& ws, int k0, int lanes) {
                     // the kinetic part: reverse mode through the velocity recursion
                     clearLaneAdjoints(d, ws, false);
                     for (int j = 0; j < n; ++j) {
                       T g[10];
                       for (int c = 0; c < 10; ++c)
                         g[c] = loadLanes<T>(Gk + k0 + ldg * (10 * j + c), lanes);
                       const L3<T> h = {{g[6], g[7], g[8]}};
                       const L3<T>& w = ws.v[j].w;
                       const L3<T>& vl = ws.v[j].v;
                       ws.vb[j].w = add(symMul(g, w), cross(h, vl));
                       ws.vb[j].v = add(cross(w, h), scale(g[9], vl));
                     }
                     T* tq = ws.tq;
                     T* gv = ws.tq + n;
                     laneReverse<T>(d, ws, k0, lanes, qd, ldx, false, false, tq, gv, nullptr);
                     if (gqd)
                       for (int j = 0; j < n; ++j) storeLanes(gqd + k0 + ldo * j, gv[j], lanes);
                     if (!gq) return;
                     // the potential part: <Gu, potential> = U(q; pi = Gu), whose gradient is the
                     // gravity torque (the RNEA at rest with parameters Gu)
                     lanesForward(model, d, ws, k0, lanes, q, nullptr, nullptr, ldx, true);
                     laneRneaBackward(
                         d, ws,
                         [&](int j, T* g) {
                           for (int c = 0; c < 10; ++c)
                             g[c] = loadLanes<T>(Gu + k0 + ldg * (10 * j + c), lanes);
                         },
                         gv);
                     for (int j = 0; j < n; ++j)
                       storeLanes(gq + k0 + ldo * j, gv[j] + tq[j], lanes);
                   });
}

// The gradients of <G_k, Y_k> (torqueRegressorsImpl's n x 10n regressor) in q_k, qd_k and qdd_k
// of `count` samples: sample k's G at G + k strideG with leading dimension ldG; its gradients at
// gq[k + ldo j] (likewise gqd, gqdd; null: not kept). The operations of the portable
// torqueRegressorVjp (kernels.hpp) in every lane.
template <class T>
inline void torqueRegressorVjpsImpl(const RobotModel& model, DynamicsData& d, int count,
                                    const double* q, const double* qd, const double* qdd, long ldx,
                                    const double* G, long ldG, long strideG, double* gq,
                                    double* gqd, double* gqdd, long ldo) {
  using Tr = LaneTraits<T>;
  const int n = d.n;
  forLaneBlocks<T>(model, d, count, q, qd, qdd, ldx, true,
                   [&](const LaneWork<T>& ws, int k0, int lanes) {
                     laneSubspaces(d, ws);
                     clearLaneAdjoints(d, ws, true);
                     for (int j = 0; j < n; ++j) {
                       const int oj = d.anc_off[static_cast<std::size_t>(j)];
                       const int cnt = d.anc_off[static_cast<std::size_t>(j) + 1] - oj;
                       const L3<T>& w = ws.v[j].w;
                       const L3<T>& wd = ws.a[j].w;
                       const L3<T>& ao = ws.ao[j];
                       for (int t = 0; t < cnt; ++t) {
                         const int i = d.anc_idx[static_cast<std::size_t>(oj + t)];
                         T g[10];
                         for (int c = 0; c < 10; ++c) {
                           const double* src = G + strideG * k0 + i + ldG * (10 * j + c);
                           for (int l = 0; l < Tr::kWidth; ++l)
                             Tr::set(g[c], l, src[strideG * (l < lanes ? l : lanes - 1)]);
                         }
                         // pairKinGrad (rigid_body.hpp): the gradient of s^T NE(g, k) in (w, wd,
                         // ao)
                         const L3<T> h = {{g[6], g[7], g[8]}};
                         const L3<T>& sw = ws.s[oj + t].w;
                         const L3<T>& sv = ws.s[oj + t].v;
                         ws.wdb[j] = add(ws.wdb[j], add(symMul(g, sw), cross(h, sv)));
                         ws.aob[j] = add(ws.aob[j], add(cross(sw, h), scale(g[9], sv)));
                         const L3<T> e1 = cross(symMul(g, w), sw);
                         const L3<T> e2 = symMul(g, cross(sw, w));
                         const L3<T> e3 = cross(h, cross(sv, w));
                         const L3<T> e4 = cross(cross(w, h), sv);
                         ws.wb[j] = add(ws.wb[j], add(add(add(e1, e2), e3), e4));
                         if (t > 0) ws.sb[oj + t] = newtonEulerL(g, w, wd, ao);
                       }
                     }
                     T *a = ws.tq, *b = ws.tq + n, *c = ws.tq + 2 * n;
                     laneReverse<T>(d, ws, k0, lanes, qd, ldx, true, true, a, b, c);
                     for (int j = 0; j < n; ++j) {
                       if (gq) storeLanes(gq + k0 + ldo * j, a[j], lanes);
                       if (gqd) storeLanes(gqd + k0 + ldo * j, b[j], lanes);
                       if (gqdd) storeLanes(gqdd + k0 + ldo * j, c[j], lanes);
                     }
                   });
}

}  // namespace
}  // namespace exid::detail::EXID_LANES_NS
