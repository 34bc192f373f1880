#!/usr/bin/env python3
"""Compare a slit annular plate run (results.json) with Sze, Liu & Lo (2004) §3.3.

Usage: python3 compare.py OUT_DIR/results.json
The run lands on every tabulated load level (`stops`); per level, the vertical deflections
W_A (inner radius) and W_B (outer radius) of the loaded side of the slit against Sze's.
Exit status 1 if a level is missing.
"""
import json
import sys

# q/q_max, W_A, W_B (Sze 2004, §3.3; 10 x 80 S4R).
REF = [(0.025, 1.305, 1.789), (0.05, 2.455, 3.370), (0.075, 3.435, 4.720), (0.10, 4.277, 5.876),
       (0.125, 5.007, 6.872), (0.15, 5.649, 7.736), (0.20, 6.725, 9.160), (0.25, 7.602, 10.288),
       (0.30, 8.340, 11.213), (0.35, 8.974, 11.992), (0.40, 9.529, 12.661),
       (0.45, 10.023, 13.247), (0.50, 10.468, 13.768), (0.55, 10.876, 14.240),
       (0.60, 11.257, 14.674), (0.65, 11.620, 15.081), (0.70, 11.970, 15.469),
       (0.75, 12.310, 15.842), (0.80, 12.642, 16.202), (0.85, 12.966, 16.550),
       (0.90, 13.282, 16.886), (0.95, 13.590, 17.212), (1.00, 13.891, 17.528)]


def main(path):
    doc = json.load(open(path))
    steps = {round(s["load_factor"], 9): s["monitors"] for s in doc["steps"] if s.get("converged")}
    print(f"status: {doc['status']}, {len(steps)} converged steps")
    print("| q/q_max | W_A (Sze) | W_A (ours) | err | W_B (Sze) | W_B (ours) | err |")
    print("|---|---|---|---|---|---|---|")
    worst, missing = 0.0, 0
    for lam, wa, wb in REF:
        m = steps.get(round(lam, 9))
        if m is None:
            print(f"| {lam} | {wa} | (not reached) | | {wb} | | |")
            missing += 1
            continue
        a, b = m["A"]["displacement"][2], m["B"]["displacement"][2]
        ea, eb = a / wa - 1, b / wb - 1
        worst = max(worst, abs(ea), abs(eb))
        print(f"| {lam} | {wa:.3f} | {a:.3f} | {100 * ea:+.2f} % | {wb:.3f} | {b:.3f} "
              f"| {100 * eb:+.2f} % |")
    print(f"largest error over the levels reached: {100 * worst:.2f} %")
    return 1 if missing else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
