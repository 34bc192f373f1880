#!/usr/bin/env python3
"""Compare a cantilever-shear run (results.json) with Sze, Liu & Lo (2004) §3.1.

Usage: python3 compare.py OUT_DIR/results.json
Per load level: the tip's -u (along the strip) and w (vertical) against Sze's, which are
given to three decimals (a rounding of up to 0.0005); the error beyond that rounding, relative
to Sze's value. Exit status 1 if a level is missing.
"""
import json
import sys

# P/P_max, -u_tip, w_tip (Sze 2004, §3.1).
REF = [(0.05, 0.026, 0.663), (0.10, 0.103, 1.309), (0.15, 0.224, 1.922), (0.20, 0.381, 2.493),
       (0.25, 0.563, 3.015), (0.30, 0.763, 3.488), (0.35, 0.971, 3.912), (0.40, 1.184, 4.292),
       (0.45, 1.396, 4.631), (0.50, 1.604, 4.933), (0.55, 1.807, 5.202), (0.60, 2.002, 5.444),
       (0.65, 2.190, 5.660), (0.70, 2.370, 5.855), (0.75, 2.541, 6.031), (0.80, 2.705, 6.190),
       (0.85, 2.861, 6.335), (0.90, 3.010, 6.467), (0.95, 3.151, 6.588), (1.00, 3.286, 6.698)]
ROUNDING = 0.0005


def beyond(ours, ref):
    return max(abs(ours - ref) - ROUNDING, 0.0) / abs(ref)


def main(path):
    doc = json.load(open(path))
    steps = {round(s["load_factor"], 9): s["monitors"]["tip"]["displacement"]
             for s in doc["steps"] if s.get("converged")}
    print(f"status: {doc['status']}, {len(steps)} converged steps")
    print("| P/P_max | -u Sze | -u ours | beyond rounding | w Sze | w ours | beyond rounding |")
    print("|---|---|---|---|---|---|---|")
    worst, missing = [0.0, 0.0], 0
    for lam, u, w in REF:
        d = steps.get(round(lam, 9))
        if d is None:
            print(f"| {lam} | {u} | (not reached) | | {w} | | |")
            missing += 1
            continue
        eu, ew = beyond(-d[0], u), beyond(d[2], w)
        worst = [max(worst[0], eu), max(worst[1], ew)]
        print(f"| {lam} | {u:.3f} | {-d[0]:.4f} | {100 * eu:.2f} % | {w:.3f} | {d[2]:.4f} "
              f"| {100 * ew:.2f} % |")
    print(f"largest error beyond the table's rounding: -u {100 * worst[0]:.2f} %, "
          f"w {100 * worst[1]:.2f} %")
    return 1 if missing else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
