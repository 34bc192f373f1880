#!/usr/bin/env python3
"""Compare a pull-out run (results.json) with Sze, Liu & Lo (2004) §3.5.

Usage: python3 compare.py OUT_DIR/results.json
The run lands on every tabulated W_A (displacement control). Per level: the computed load
P/P_max (from the reaction at A, octant: P = 4 R) against Sze's, W_A at Sze's load (linear
interpolation between converged steps), and -U_B, -U_C at that load.
"""
import json
import sys

P_MAX = 40000.0
# P/P_max, W_A, -U_B, -U_C (Sze 2004 Table for §3.5).
REF = [(0.025, 0.819, 0.864, 0.872), (0.05, 1.260, 1.471, 1.493), (0.075, 1.527, 1.901, 1.946),
       (0.10, 1.707, 2.217, 2.293), (0.15, 1.936, 2.641, 2.792), (0.20, 2.079, 2.904, 3.106),
       (0.25, 2.180, 3.087, 3.310), (0.30, 2.257, 3.227, 3.452), (0.35, 2.321, 3.342, 3.556),
       (0.40, 2.376, 3.443, 3.632), (0.45, 2.425, 3.539, 3.688), (0.50, 2.473, 3.653, 3.718),
       (0.525, 2.543, 4.061, 3.580), (0.55, 2.577, 4.171, 3.518), (0.60, 2.618, 4.274, 3.452),
       (0.65, 2.648, 4.338, 3.410), (0.70, 2.672, 4.385, 3.378), (0.75, 2.692, 4.423, 3.353),
       (0.80, 2.710, 4.455, 3.332), (0.85, 2.726, 4.483, 3.313), (0.90, 2.741, 4.508, 3.297),
       (0.95, 2.755, 4.530, 3.283), (1.00, 2.768, 4.551, 3.269)]


def main(path):
    doc = json.load(open(path))
    rows = [(0.0, 0.0, 0.0, 0.0)]
    for s in doc["steps"]:
        if not s.get("converged"):
            continue
        m = s["monitors"]
        p = 4.0 * list(s["reactions"].values())[0] / P_MAX
        rows.append((p, m["A"]["displacement"][2], -m["B"]["along"], -m["C"]["along"]))
    print(f"status: {doc['status']}, {len(rows) - 1} converged steps")
    print("| P/P_max (Sze) | P/P_max at Sze's W_A (ours) | W_A (Sze) | W_A (ours) | err "
          "| -U_B (Sze) | (ours) | err | -U_C (Sze) | (ours) | err |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    worst = [0.0, 0.0, 0.0, 0.0]
    by_w = {round(r[1], 6): r[0] for r in rows}
    for p_ref, w_ref, b_ref, c_ref in REF:
        p_at_w = by_w.get(round(w_ref, 6))
        # The first crossing of Sze's load on the computed path (P grows with W_A here).
        hit = None
        for r0, r1 in zip(rows, rows[1:]):
            if (r0[0] - p_ref) * (r1[0] - p_ref) <= 0 and r0[0] != r1[0]:
                t = (p_ref - r0[0]) / (r1[0] - r0[0])
                hit = [a + t * (b - a) for a, b in zip(r0, r1)]
                break
        ps = f"{p_at_w:.4f}" if p_at_w is not None else "-"
        if hit is None:
            print(f"| {p_ref} | {ps} | {w_ref} | (load not reached) | | {b_ref} | | | {c_ref} | | |")
            continue
        errs = [hit[1] / w_ref - 1, hit[2] / b_ref - 1, hit[3] / c_ref - 1]
        if p_at_w is not None:
            worst[3] = max(worst[3], abs(p_at_w / p_ref - 1))
        for k in range(3):
            worst[k] = max(worst[k], abs(errs[k]))
        print(f"| {p_ref} | {ps} | {w_ref:.3f} | {hit[1]:.3f} | {100 * errs[0]:+.2f} % "
              f"| {b_ref:.3f} | {hit[2]:.3f} | {100 * errs[1]:+.2f} % "
              f"| {c_ref:.3f} | {hit[3]:.3f} | {100 * errs[2]:+.2f} % |")
    print(f"largest errors: W_A {100 * worst[0]:.2f} %, -U_B {100 * worst[1]:.2f} %, "
          f"-U_C {100 * worst[2]:.2f} %; load at equal W_A {100 * worst[3]:.2f} %")


if __name__ == "__main__":
    main(sys.argv[1])
