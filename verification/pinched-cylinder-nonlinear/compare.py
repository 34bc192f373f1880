#!/usr/bin/env python3
"""Compare a pinched-cylinder run (results.json) with Sze, Liu & Lo (2004) §3.6.

Usage: python3 compare.py OUT_DIR/results.json
The run follows the path by arc length. Per level of Sze's table: every crossing of that load
on the computed path (W_A = -u_z at A, U_B = -u_y at B, interpolated linearly between
converged steps), the one nearest Sze's W_A and its error. Then the path's snaps: each load
maximum, W_A there, and the load of the minimum after it.
"""
import json
import sys

# P/P_max, -W_A, U_B (Sze 2004, §3.6).
REF = [(0.05, 9.561, -0.233), (0.075, 15.648, -0.922), (0.10, 23.164, -2.391),
       (0.125, 29.375, -3.872), (0.15, 36.208, -2.154), (0.175, 51.499, 6.792),
       (0.20, 56.373, 10.448), (0.25, 61.877, 14.905), (0.30, 65.498, 17.979),
       (0.35, 68.229, 20.365), (0.40, 70.424, 22.321), (0.45, 72.204, 23.916),
       (0.50, 73.790, 25.381), (0.55, 75.139, 26.631), (0.60, 76.331, 27.735),
       (0.65, 77.472, 28.843), (0.70, 78.451, 29.772), (0.75, 79.339, 30.604),
       (0.80, 80.218, 31.471), (0.85, 81.045, 32.299), (0.90, 81.766, 32.989),
       (0.95, 82.435, 33.619), (1.00, 83.102, 34.272)]


def main(path):
    doc = json.load(open(path))
    path_ = [(0.0, 0.0, 0.0)]
    for s in doc["steps"]:
        if not s.get("converged"):
            continue
        m = s["monitors"]
        path_.append((s["load_factor"], -m["A"]["displacement"][2], -m["B"]["displacement"][1]))
    print(f"status: {doc['status']}, {len(path_) - 1} converged steps")
    print("| P/P_max | W_A (Sze) | W_A at every crossing (ours) | nearest: err | U_B (Sze) "
          "| U_B there | err |")
    print("|---|---|---|---|---|---|---|")
    for lam, wa, ub in REF:
        hits = []
        for a, b in zip(path_, path_[1:]):
            if (a[0] - lam) * (b[0] - lam) <= 0 and a[0] != b[0]:
                t = (lam - a[0]) / (b[0] - a[0])
                hits.append((a[1] + t * (b[1] - a[1]), a[2] + t * (b[2] - a[2])))
        if not hits:
            print(f"| {lam} | {wa} | (not reached) | | {ub} | | |")
            continue
        w, u = min(hits, key=lambda h: abs(h[0] - wa))
        every = ", ".join(f"{h[0]:.2f}" for h in hits)
        print(f"| {lam} | {wa:.3f} | {every} | {100 * (w / wa - 1):+.2f} % | {ub:.3f} | {u:.3f} "
              f"| {100 * (u - ub) / max(abs(ub), 1.0):+.2f} % |")
    print("snaps (W_A at the load maximum: P/P_max there -> at the minimum after it):")
    snaps, i = [], 1
    while i < len(path_) - 1:
        if path_[i - 1][0] < path_[i][0] > path_[i + 1][0]:
            j = i + 1
            while j < len(path_) - 1 and not path_[j - 1][0] > path_[j][0] < path_[j + 1][0]:
                j += 1
            snaps.append(f"{path_[i][1]:.1f}: {path_[i][0]:.3f} -> {path_[j][0]:.3f}")
            i = j
        i += 1
    print("  " + "; ".join(snaps) if snaps else "  none")


if __name__ == "__main__":
    main(sys.argv[1])
