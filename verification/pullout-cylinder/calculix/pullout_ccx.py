#!/usr/bin/env python3
"""Pull-out of an open-ended cylinder (Sze, Liu & Lo 2004 §3.5) in CalculiX, octant model,
displacement control of the pulled point. Writes the ccx input, runs ccx and prints the load and
the displacements at Sze's tabulated W_A. Requires the `ccx` executable (Debian calculix-ccx).

Usage: pullout_ccx.py [--grid NU NV] [--layers NT] [--material svk|neo-hooke] [--workdir DIR]

Axis x, the pulled generator along z (th = 0), th = 90 deg at +y; symmetry planes y = 0
(th = 0), z = 0 (th = 90 deg) and x = 0 (mid-length), the end x = L/2 free. A = (0, 0, R),
the points 90 deg from the load, (0, R, 0) at mid-length and (L/2, R, 0) on the free end, are
compared with Sze's B and C respectively (README: the assignment); U is their radial (y)
displacement. The radial displacement of A is prescribed on all
three layers of the thickness; the summed z reaction there is the octant's share of the pull,
P = 4 R_z.
"""
import argparse
import os
import sys

sys.dont_write_bytecode = True  # no __pycache__ beside the shared module
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..",
                                "calculix"))
from ccx_cylinder import (LAWS, CylinderMesh, parse_dat, run_ccx,  # noqa: E402
                          write_displacement_step, write_mesh, write_nset)

R, L, H = 4.953, 10.35, 0.094
E, NU = 10.5e6, 0.3125
P_MAX = 40000.0
# P/P_max, W_A, -U_B, -U_C (Sze 2004, §3.5).
REF = [(0.025, 0.819, 0.864, 0.872), (0.05, 1.260, 1.471, 1.493), (0.075, 1.527, 1.901, 1.946),
       (0.10, 1.707, 2.217, 2.293), (0.15, 1.936, 2.641, 2.792), (0.20, 2.079, 2.904, 3.106),
       (0.25, 2.180, 3.087, 3.310), (0.30, 2.257, 3.227, 3.452), (0.35, 2.321, 3.342, 3.556),
       (0.40, 2.376, 3.443, 3.632), (0.45, 2.425, 3.539, 3.688), (0.50, 2.473, 3.653, 3.718),
       (0.525, 2.543, 4.061, 3.580), (0.55, 2.577, 4.171, 3.518), (0.60, 2.618, 4.274, 3.452),
       (0.65, 2.648, 4.338, 3.410), (0.70, 2.672, 4.385, 3.378), (0.75, 2.692, 4.423, 3.353),
       (0.80, 2.710, 4.455, 3.332), (0.85, 2.726, 4.483, 3.313), (0.90, 2.741, 4.508, 3.297),
       (0.95, 2.755, 4.530, 3.283), (1.00, 2.768, 4.551, 3.269)]
W_END = REF[-1][1]


def write_input(path, nu, nv, max_inc, law="svk", nt=1):
    m = CylinderMesh(R, H, [0, 0, 1], [0, 1, 0], [1, 0, 0], (0.0, 90.0), (0.0, L / 2), nu, nv,
                     nt)
    ie, je = m.ni - 1, m.nj - 1
    with open(path, "w") as f:
        f.write("*HEADING\npull-out of an open-ended cylinder, octant, displacement control\n")
        write_mesh(f, m, E, NU, law)
        write_nset(f, "SYMY", m.line(i=0))
        write_nset(f, "SYMZ", m.line(i=ie))
        write_nset(f, "SYMX", m.line(j=0))
        write_nset(f, "A", [m.nid(0, 0, k) for k in range(m.nk)])
        write_nset(f, "BC", [m.nid(ie, je, nt), m.nid(ie, 0, nt), m.nid(0, 0, nt)])
        f.write("*BOUNDARY\nSYMY, 2, 2\nSYMZ, 3, 3\nSYMX, 1, 1\n")
        # Sze's levels and a uniform set between them (the path, to interpolate at Sze's loads)
        times = sorted({round(r[1] / W_END, 10) for r in REF} | {n / 100 for n in range(1, 101)})
        write_displacement_step(f, times, "A", 3, W_END, max_inc / 2, max_inc,
                                [("A", "RF", True), ("BC", "U", False)])
    return m


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--grid", nargs=2, type=int, default=[24, 16], metavar=("NU", "NV"))
    ap.add_argument("--max-inc", type=float, default=0.01)
    ap.add_argument("--layers", type=int, default=1, help="bricks through the thickness")
    ap.add_argument("--material", choices=LAWS, default="svk",
                    help="the elastic law at finite strain (ccx_cylinder.write_mesh)")
    ap.add_argument("--workdir", default="out/pullout-ccx")
    ap.add_argument("--timeout", type=float, default=1800.0)
    args = ap.parse_args()
    os.makedirs(args.workdir, exist_ok=True)
    job = (f"pullout_{args.grid[0]}x{args.grid[1]}"
           + ("" if args.layers == 1 else f"x{args.layers}")
           + ("" if args.material == "svk" else "_neo"))
    m = write_input(os.path.join(args.workdir, job + ".inp"), args.grid[0], args.grid[1],
                    args.max_inc, args.material, args.layers)
    text, rc = run_ccx(args.workdir, job, args.timeout)
    ie, je = m.ni - 1, m.nj - 1
    end, mid, a = m.nid(ie, je, m.nt), m.nid(ie, 0, m.nt), m.nid(0, 0, m.nt)
    path = {}
    for (what, _, t), rows in parse_dat(text).items():
        row = path.setdefault(t, {})
        if what.startswith("total force"):
            row["P"] = 4.0 * rows[0][2] / P_MAX
        elif what == "displacements":
            row["W"], row["mid"], row["end"] = rows[a][2], -rows[mid][1], -rows[end][1]
    path = [r for _, r in sorted(path.items()) if len(r) == 4]
    print(f"{args.grid[0]} x {args.grid[1]} x {args.layers} C3D20R, {args.material}, "
          f"ccx exit {rc}, "
          f"{len(path)} outputs")
    print("Sze's -U_B against the 90-degree point at mid-length, -U_C against the one on the "
          "free end")
    print("| W_A | P/P_max (Sze) | ccx | error | -U_B (Sze) | ccx, mid-length | error "
          "| -U_C (Sze) | ccx, free end | error |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    by_w = {round(r["W"], 6): r for r in path}
    for p, w, ub, uc in REF:
        r = by_w.get(round(w, 6))
        if r is None:
            print(f"| {w} | {p} | (not reached) | | {ub} | | | {uc} | | |")
            continue
        print(f"| {w} | {p} | {r['P']:.4f} | {100 * (r['P'] - p) / p:+.1f} % | {ub} "
              f"| {r['mid']:.3f} | {100 * (r['mid'] - ub) / ub:+.1f} % | {uc} "
              f"| {r['end']:.3f} | {100 * (r['end'] - uc) / uc:+.1f} % |")
    print("\nAt Sze's load (linear interpolation on the path, first crossing):")
    print("| P/P_max | W_A (Sze) | ccx | error |\n|---|---|---|---|")
    pts = [{"P": 0.0, "W": 0.0}] + path
    for p, w, _, _ in REF:
        got = None
        for r0, r1 in zip(pts, pts[1:]):
            if r0["P"] <= p <= r1["P"] and r1["P"] > r0["P"]:
                got = r0["W"] + (p - r0["P"]) / (r1["P"] - r0["P"]) * (r1["W"] - r0["W"])
                break
        shown = f"{got:.3f} | {100 * (got - w) / w:+.1f} %" if got is not None else "- |"
        print(f"| {p} | {w} | {shown} |")
    with open(os.path.join(args.workdir, job + "_path.txt"), "w") as f:
        f.write("# W_A P/P_max -U(0, R, 0) (mid-length) -U(L/2, R, 0) (free end)\n")
        for r in path:
            f.write(f"{r['W']:.6f} {r['P']:.6f} {r['mid']:.6f} {r['end']:.6f}\n")


if __name__ == "__main__":
    main()
