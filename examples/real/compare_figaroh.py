#!/usr/bin/env python3
"""Compares exid's TX40 base parameters (summary.json of examples/real/tx40_*.yaml) with
FIGAROH's published ones (results/TX40_bp_5.csv), parameter by parameter, on the joint side.

Usage: compare_figaroh.py SUMMARY.json TX40_bp_5.csv [ols|wls]   (plain Python 3, prints Markdown)

exid's drive parameters live on the MOTORS (measured coordinates); FIGAROH's on the joints with
extra coupling terms for motor 6. Mapping (N = [32, 32, 45, -48, 45, 32]):
  fv_i = N_i^2 Fv_i, fs_i = |N_i| Fc_i, off_i = N_i OFF_i, Ia_i = N_i^2 Ia_i   (i = 1..4)
  Ia5 = 45^2 Ia5 + 32^2 Ia6, fv5 = 45^2 Fv5 + 32^2 Fv6, fs5 = 45 Fc5, off5 = 45 OFF5 + 32 OFF6
  Iam6 = 32^2 Ia6, fvm6 = 32^2 Fv6, fsm6 = 32 Fc6, fv6 = 32^2 Fv6 (exid has no separate joint-6
  friction), off6 = 32 OFF6.
Standard deviations of sums are combined as if independent (summary.json has no covariance).
The rigid-body base parameters have the same regrouping in both (same MDH geometry), matched by
FIGAROH's expression below.
"""
import csv
import json
import math
import sys

N = [32, 32, 45, -48, 45, 32]
RIGID = {  # exid name -> start of FIGAROH's expression
    "ZZ1R": "Izz1 + 1.0*Ia1", "XX2R": "Ixx2 - 1.0*Iyy2", "XY2R": "Ixy2", "XZ2R": "Ixz2 - 0.225",
    "YZ2R": "Iyz2", "ZZ2R": "Izz2 + 1.0*Ia2", "MX2R": "mx2 + ", "MY2": "my2",
    "XX3R": "Ixx3 - 1.0*Iyy3", "XY3": "Ixy3", "XZ3R": "Ixz3", "YZ3": "Iyz3", "ZZ3R": "Izz3 + 1.0*Iyy4",
    "MX3R": "mx3", "MY3R": "my3 - 1.0*mz4", "XX4R": "Ixx4 - 1.0*Iyy4", "XY4": "Ixy4", "XZ4": "Ixz4",
    "YZ4": "Iyz4", "ZZ4R": "Izz4 + 1.0*Iyy5", "MX4R": "mx4", "MY4R": "my4 + 1.0*mz5",
    "XX5R": "Ixx5 - 1.0*Iyy5", "XY5": "Ixy5", "XZ5": "Ixz5", "YZ5": "Iyz5", "ZZ5R": "Izz5 + 1.0*Iyy6",
    "MX5R": "mx5", "MY5R": "my5 - 1.0*mz6", "XX6R": "Ixx6 - 1.0*Iyy6", "XY6": "Ixy6", "XZ6": "Ixz6",
    "YZ6": "Iyz6", "ZZ6": "Izz6", "MX6": "mx6", "MY6": "my6",
}


def main():
    summary, published = sys.argv[1], sys.argv[2]
    which = sys.argv[3] if len(sys.argv) > 3 else "ols"
    ours = {p["name"]: (p["value"], p["std"]) for p in json.load(open(summary))["identification"]["parameters"]}
    pub = {}
    for row in csv.reader(open(published)):
        if not row or not row[1].strip():
            continue
        v, r = (float(row[1]), float(row[2])) if which == "ols" else (float(row[3]), float(row[4]))
        pub[row[0].strip()] = (v, abs(v) * r / 100.0, r)

    def lin(terms):  # sum of c * ours[name]
        v = sum(c * ours[n][0] for c, n in terms if n in ours)
        s = math.sqrt(sum((c * ours[n][1]) ** 2 for c, n in terms if n in ours))
        return v, s

    rows = []
    for name, start in RIGID.items():
        key = next(k for k in pub if k == start or k.startswith(start))
        rows.append((name, key, lin([(1, name)])))
    for i in range(4):
        j = i + 1
        rows.append((f"{N[i]}^2 Fv{j}", f"fv{j}", lin([(N[i] ** 2, f"Fv{j}")])))
        rows.append((f"{abs(N[i])} Fc{j}", f"fs{j}", lin([(abs(N[i]), f"Fc{j}")])))
        rows.append((f"{N[i]} OFF{j}", f"off{j}", lin([(N[i], f"OFF{j}")])))
        if j >= 3:
            rows.append((f"{N[i]}^2 Ia{j}", f"Ia{j}", lin([(N[i] ** 2, f"Ia{j}")])))
    rows.append(("45^2 Ia5 + 32^2 Ia6", "Ia5", lin([(2025, "Ia5"), (1024, "Ia6")])))
    rows.append(("45^2 Fv5 + 32^2 Fv6", "fv5", lin([(2025, "Fv5"), (1024, "Fv6")])))
    rows.append(("45 Fc5", "fs5", lin([(45, "Fc5")])))
    rows.append(("45 OFF5 + 32 OFF6", "off5", lin([(45, "OFF5"), (32, "OFF6")])))
    rows.append(("32^2 Fv6", "fv6", lin([(1024, "Fv6")])))
    rows.append(("(none)", "fs6", (0.0, 0.0)))
    rows.append(("32 OFF6", "off6", lin([(32, "OFF6")])))
    rows.append(("32^2 Ia6", "Iam6", lin([(1024, "Ia6")])))
    rows.append(("32^2 Fv6", "fvm6", lin([(1024, "Fv6")])))
    rows.append(("32 Fc6", "fsm6", lin([(32, "Fc6")])))

    print(f"| exid (joint side) | FIGAROH {which.upper()} | exid value | exid %std | FIGAROH value | FIGAROH %std | diff / combined std | well identified (both < 5 %) |")
    print("|---|---|---|---|---|---|---|---|")
    agree = total = 0
    for ours_name, key, (v, s) in rows:
        pv, ps, pr = pub[key]
        rel = 100 * s / abs(v) if v else float("inf")
        comb = math.hypot(s, ps)
        z = abs(v - pv) / comb if comb > 0 else float("inf")
        well = rel < 5 and pr < 5
        if well:
            total += 1
            agree += z <= 1
        print(f"| {ours_name} | {key[:40]} | {v:.5g} | {rel:.2f} | {pv:.5g} | {pr:.2f} | {z:.2f} | {'yes' if well else ''} |")
    print(f"\nWell-identified in both: {total}; within one combined std: {agree}")


if __name__ == "__main__":
    main()
