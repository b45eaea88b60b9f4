#!/usr/bin/env python3
"""Starting trajectories of the paper's experiments as CSV files for the `pointwise` trajectory
(init: csv). Each file has t, q1..q5, qd1..qd5 and qdd1..qdd5; the pointwise trajectory takes
the accelerations qdd (u_k = (qd(t_{k+1}) - qd(t_k)) / dt, which reproduces qd exactly at the
samples) and X_0 from the first row. Angles in MRROC++ measured coordinates (absolute angles for
joints 2-4, rad). Pure Python (no numpy).

  exp2_start.csv  experiment 2: cubic splines for joints 1 and 2, a cosine for joint 3,
                  300 points, dt = 32 ms (the paper: "spline polynomials for the first and
                  second joints and the cosine function for the third joint", 300 points).
  exp4_start.csv  experiment 4: the paper's section 4 load-identification start q1..q5,
                  alpha = 2 pi i / (K - 1), K = 200, dt = 32 ms, read as DEGREES; see README.md
                  for the joint-2 convention.

Run: python3 make_starts.py  (writes next to this file).
"""
import math
import os

HERE = os.path.dirname(os.path.abspath(__file__))
DEG = math.pi / 180.0
# Rest (and centre) positions, measured coordinates: q1 = 0, q2 = -90 deg (lower arm vertical),
# q3 = 7.5 deg and q4 = 1 deg (centres of their absolute ranges), q5 = 0.
REST = [0.0, -90.0 * DEG, 7.5 * DEG, 1.0 * DEG, 0.0]


def write(name, t, q, qd, dt):
    K, n = len(t), len(q[0])
    qdd = []
    for k in range(K):
        nxt = qd[k + 1] if k + 1 < K else qd[k]
        qdd.append([(nxt[j] - qd[k][j]) / dt for j in range(n)] if k + 1 < K else qdd[-1][:])
    cols = ["t"] + [f"q{j+1}" for j in range(n)] + [f"qd{j+1}" for j in range(n)] + [f"qdd{j+1}" for j in range(n)]
    with open(os.path.join(HERE, name), "w") as f:
        f.write(",".join(cols) + "\n")
        for k in range(K):
            row = [t[k]] + q[k] + qd[k] + qdd[k]
            f.write(",".join(f"{x:.17g}" for x in row) + "\n")


def hermite(knots_t, knots_q, t):
    """Cubic Hermite spline with Catmull-Rom slopes, zero slope at both ends: q, qd at t."""
    n = len(knots_t)
    m = [0.0] * n
    for i in range(1, n - 1):
        m[i] = (knots_q[i + 1] - knots_q[i - 1]) / (knots_t[i + 1] - knots_t[i - 1])
    i = min(n - 2, max(0, next((k for k in range(n - 1) if t < knots_t[k + 1]), n - 2)))
    h = knots_t[i + 1] - knots_t[i]
    s = (t - knots_t[i]) / h
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    d00, d10, d01, d11 = 6 * s**2 - 6 * s, 3 * s**2 - 4 * s + 1, -6 * s**2 + 6 * s, 3 * s**2 - 2 * s
    q = h00 * knots_q[i] + h10 * h * m[i] + h01 * knots_q[i + 1] + h11 * h * m[i + 1]
    qd = (d00 * knots_q[i] + d10 * h * m[i] + d01 * knots_q[i + 1] + d11 * h * m[i + 1]) / h
    return q, qd


def exp2(amplitude_deg=2.0):
    K, dt = 300, 0.032
    T = (K - 1) * dt
    kt = [T * i / 4 for i in range(5)]
    k1 = [REST[0] + amplitude_deg * DEG * a for a in (0.0, 1.0, -0.5, 0.8, 0.0)]
    k2 = [REST[1] + amplitude_deg * DEG * a for a in (0.0, -0.6, 0.9, -0.3, 0.0)]
    w3 = 2 * math.pi / T
    t, q, qd = [], [], []
    for k in range(K):
        tk = k * dt
        a1, v1 = hermite(kt, k1, tk)
        a2, v2 = hermite(kt, k2, tk)
        a3 = REST[2] + amplitude_deg * DEG * (math.cos(w3 * tk) - 1.0)
        v3 = -amplitude_deg * DEG * w3 * math.sin(w3 * tk)
        t.append(tk)
        q.append([a1, a2, a3, REST[3], REST[4]])
        qd.append([v1, v2, v3, 0.0, 0.0])
    write("exp2_start.csv", t, q, qd, dt)


def exp4(q2_offset_deg=-90.0):
    """Paper section 4 (degrees). q2 of the paper is taken from the vertical: MRROC++ q2 (from the
    horizontal, lower arm up at -90 deg) = paper q2 + q2_offset_deg; q3, q4 as given (absolute,
    from the horizontal), q1, q5 as given."""
    K, dt = 200, 0.032
    da = 2 * math.pi / ((K - 1) * dt)  # d alpha / dt
    pi = math.pi

    def sig(a):
        q = [12 - 0.7 * math.cos(0.4 * pi + 1.7 * a) + 0.8 * math.sin(0.1 * pi + 0.8 * a),
             4 + 1.8 * math.cos(0.4 * pi + 1.7 * a) + 1.3 * math.cos(0.1 * pi + 0.3 * a) + q2_offset_deg,
             8 + math.cos(0.45 * pi + 1.4 * a) + 0.4 * math.sin(0.4 * pi + 0.4 * a) + 0.7 * math.sin(0.8 * pi + 0.6 * a),
             -13 - 1.2 * math.sin(0.45 * pi + 1.7 * a) + 1.8 * math.cos(0.15 * pi + 0.7 * a),
             -9 + 2.6 * math.cos(0.15 * pi + 2 * a) - 1.1 * math.sin(0.45 * pi + 0.2 * a)]
        dq = [0.7 * 1.7 * math.sin(0.4 * pi + 1.7 * a) + 0.8 * 0.8 * math.cos(0.1 * pi + 0.8 * a),
              -1.8 * 1.7 * math.sin(0.4 * pi + 1.7 * a) - 1.3 * 0.3 * math.sin(0.1 * pi + 0.3 * a),
              -1.4 * math.sin(0.45 * pi + 1.4 * a) + 0.4 * 0.4 * math.cos(0.4 * pi + 0.4 * a) + 0.7 * 0.6 * math.cos(0.8 * pi + 0.6 * a),
              -1.2 * 1.7 * math.cos(0.45 * pi + 1.7 * a) - 1.8 * 0.7 * math.sin(0.15 * pi + 0.7 * a),
              -2.6 * 2 * math.sin(0.15 * pi + 2 * a) - 1.1 * 0.2 * math.cos(0.45 * pi + 0.2 * a)]
        return [x * DEG for x in q], [x * DEG * da for x in dq]

    t, q, qd = [], [], []
    for i in range(K):
        a = 2 * pi * i / (K - 1)
        qq, vv = sig(a)
        t.append(i * dt)
        q.append(qq)
        qd.append(vv)
    write("exp4_start.csv", t, q, qd, dt)


if __name__ == "__main__":
    exp2()
    exp4()
