#!/usr/bin/env python3
"""Compare a thin hinged-roof run (results.json) with Sze, Liu & Lo (2004) §3.8, h = 6.35.

Usage: python3 compare.py OUT_DIR/results.json
The path turns in load twice (a maximum, then a minimum below zero) and in deflection twice
(the snap-back), so neither coordinate is a function of the other. Printed:
- the four turning points of each path, each the vertex of the parabola through the turning
  step and its two neighbours (in P against W at the load's extremes, in W against P at the
  deflection's), Sze's from his tabulated levels by the same construction;
- per tabulated point of Sze's, the distance to the computed path (a polyline through the
  converged steps) in the plane (W / W_END, P / P_MAX): within d % of the load scale and of the
  deflection scale at once.
"""
import json
import math
import os
import sys

sys.dont_write_bytecode = True  # no __pycache__ beside the shared module
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "calculix"))
from paths import vertex  # noqa: E402

P_MAX = 3000.0
# (P/P_max, -W) at the load point (Sze 2004 §3.8, isotropic, h = 6.35).
REF = [(0.0, 0.0), (0.0517, 1.846), (0.1182, 5.271), (0.1583, 8.257), (0.1837, 10.799),
       (0.1914, 11.904), (0.1953, 12.892), (0.1950, 13.752), (0.1901, 14.472),
       (0.1806, 15.050), (0.1671, 15.501), (0.1323, 16.145), (0.0923, 16.602),
       (0.0504, 16.915), (0.0083, 17.008), (-0.0312, 16.697), (-0.0622, 15.780),
       (-0.0739, 15.206), (-0.0861, 14.767), (-0.1001, 14.520), (-0.1142, 14.451),
       (-0.1247, 14.862), (-0.1288, 15.778), (-0.1271, 16.961), (-0.1196, 18.320),
       (-0.1055, 19.817), (-0.0825, 21.420), (-0.0484, 23.100), (-0.0006, 24.824),
       (0.0626, 26.565), (0.1427, 28.302), (0.2403, 30.023), (0.3559, 31.720),
       (0.4898, 33.388), (0.6417, 35.024), (0.8114, 36.626), (1.0313, 38.450)]
# The deflection scale of the distance: Sze's last tabulated deflection.
W_END = 38.45


def turning_points(path):
    """The path's turns, in order: (kind, W, P), `path` a list of (W, P)."""
    out = []
    for i in range(1, len(path) - 1):
        (w0, p0), (w1, p1), (w2, p2) = path[i - 1], path[i], path[i + 1]
        if (p1 - p0) * (p2 - p1) < 0:
            w, p = vertex(path, i)
            out.append(("load maximum" if p1 > p0 else "load minimum", w, p))
        if (w1 - w0) * (w2 - w1) < 0:
            p, w = vertex([(q, v) for v, q in path], i)
            out.append(("deflection maximum" if w1 > w0 else "deflection minimum", w, p))
    return out


def distance(point, path):
    """Smallest distance from `point` (W, P) to the polyline `path`, in the plane
    (W / W_END, P / 1)."""
    x, y = point[0] / W_END, point[1]
    best = math.inf
    for (wa, pa), (wb, pb) in zip(path, path[1:]):
        ax, ay, bx, by = wa / W_END, pa, wb / W_END, pb
        dx, dy = bx - ax, by - ay
        n2 = dx * dx + dy * dy
        t = 0.0 if n2 == 0 else max(0.0, min(1.0, ((x - ax) * dx + (y - ay) * dy) / n2))
        best = min(best, math.hypot(ax + t * dx - x, ay + t * dy - y))
    return best


def main(path):
    doc = json.load(open(path))
    ours = [(0.0, 0.0)]
    for s in doc["steps"]:
        if s.get("converged"):
            ours.append((-s["monitors"]["A"]["displacement"][2], s["load_factor"]))
    sze = [(w, p) for p, w in REF]
    print(f"status: {doc['status']}, {len(ours) - 1} converged steps")
    print("| turning point | Sze: -W | P/P_max | ours: -W | P/P_max | error W | error P "
          "(% of P_max) |")
    print("|---|---|---|---|---|---|---|")
    ts, to = turning_points(sze), turning_points(ours)
    for (k, ws, ps), (_, w, p) in zip(ts, to):
        print(f"| {k} | {ws:.3f} | {ps:.4f} | {w:.3f} | {p:.4f} | {100 * (w / ws - 1):+.2f} % "
              f"| {100 * (p - ps):+.2f} |")
    if [t[0] for t in ts] != [t[0] for t in to]:
        print("turning points differ in kind or order: Sze", [t[0] for t in ts], "ours",
              [t[0] for t in to])
    print("\n| -W (Sze) | P/P_max (Sze) | distance to our path (%) |")
    print("|---|---|---|")
    worst = 0.0
    for w, p in sze[1:]:
        d = 100 * distance((w, p), ours)
        worst = max(worst, d)
        print(f"| {w:.3f} | {p:.4f} | {d:.2f} |")
    print(f"largest distance {worst:.2f} % (of P_max and of W_END = {W_END} at once)")


if __name__ == "__main__":
    main(sys.argv[1])
