#!/usr/bin/env python3
"""Pinched semi-cylinder (Sze, Liu & Lo 2004 §3.7) in CalculiX, for four readings of the
longitudinal-edge condition. Writes the ccx input, runs ccx and prints 100 w at Sze's 25 load
levels against the table. Requires the `ccx` executable (Debian package calculix-ccx).

Usage: semi_cylinder_ccx.py [--grid NU NV] [--edge a b c d] [--workdir DIR]

Half model: the symmetry plane x = 0 through the crown generator, the half load P/2 at the crown
of the free end. Axis y, clamped end y = 0, longitudinal edge at (R, y, 0) whose shell normal
is x. Edge candidates:
  a  u_x = 0 and the rotation about the generator held (u_z equal on both faces)
  b  u_z = 0 on the mid-surface only (vertical support, free to slide horizontally and rotate)
  c  u_z = 0 on all layers (vertical support with the rotation about the generator held)
  d  u_x = u_z = 0 on the mid-surface (hinged)
"""
import argparse
import os
import sys

sys.dont_write_bytecode = True  # no __pycache__ beside the shared module
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..",
                                "calculix"))
from ccx_cylinder import CylinderMesh, parse_dat, run_ccx, write_mesh, write_nset  # noqa: E402

R, L, H = 1.016, 3.048, 0.03
E, NU = 2.0685e7, 0.3
P_MAX = 2000.0
# P/P_max and the load-point deflection in hundredths of the length unit (Sze 2004, §3.7).
REF = [(0.05, 5.421), (0.10, 16.100), (0.125, 22.195), (0.15, 27.657), (0.175, 32.700),
       (0.20, 37.582), (0.225, 42.633), (0.25, 48.537), (0.275, 56.355), (0.30, 66.410),
       (0.325, 79.810), (0.35, 94.669), (0.40, 113.704), (0.45, 124.751), (0.50, 132.653),
       (0.55, 138.920), (0.60, 144.185), (0.65, 148.770), (0.70, 152.863), (0.75, 156.584),
       (0.80, 160.015), (0.85, 163.211), (0.90, 166.200), (0.95, 168.973), (1.00, 171.505)]


def write_input(path, nu, nv, edge):
    # e1 = z (the crown, th = 0), e2 = x (the edge, th = 90 deg), axis y.
    m = CylinderMesh(R, H, [0, 0, 1], [1, 0, 0], [0, 1, 0], (0.0, 90.0), (0.0, L), nu, nv)
    ie = m.ni - 1
    with open(path, "w") as f:
        f.write("*HEADING\npinched semi-cylinder, half model, edge " + edge + "\n")
        write_mesh(f, m, E, NU)
        write_nset(f, "SYM", m.line(i=0))
        write_nset(f, "CLAMP", m.line(j=0))
        rows = [j for j in range(1, m.nj)]
        write_nset(f, "EDGEALL", [m.nid(ie, j, k) for j in rows for k in range(3)
                                  if m.exists(ie, j, k)])
        write_nset(f, "EDGEMID", [m.nid(ie, j, 1) for j in rows if m.exists(ie, j, 1)])
        write_nset(f, "LOADMID", [m.nid(0, m.nj - 1, 1)])
        f.write("*BOUNDARY\nSYM, 1, 1\nCLAMP, 1, 3\n")
        if edge in ("a", "d"):
            f.write("EDGEALL, 1, 1\n")
        if edge == "c":
            f.write("EDGEALL, 3, 3\n")
        if edge in ("b", "d"):
            f.write("EDGEMID, 3, 3\n")
        eqs = []
        for j in rows:
            lo, hi = m.nid(ie, j, 0), m.nid(ie, j, 2)
            if edge == "a":     # no rotation about the generator: equal u_z on both faces
                eqs.append(f"{hi}, 3, 1.0, {lo}, 3, -1.0")
            if edge in ("b", "d") and not m.exists(ie, j, 1):
                # mid-surface u_z = 0 between mid-surface nodes: the faces' mean
                eqs.append(f"{hi}, 3, 1.0, {lo}, 3, 1.0")
        for e in eqs:
            f.write("*EQUATION\n2\n" + e + "\n")
        f.write("*TIME POINTS, NAME=LEVELS\n")
        for n in range(0, len(REF), 8):
            f.write(", ".join(f"{p:g}" for p, _ in REF[n:n + 8]) + "\n")
        f.write("*STEP, NLGEOM, INC=2000\n*STATIC\n0.0125, 1.0, 1e-7, 0.025\n")
        # the half load, spread through the thickness as a consistent edge load (1/6, 2/3, 1/6)
        f.write("*CLOAD\n")
        jl = m.nj - 1
        for k, w in ((0, 1 / 6), (1, 2 / 3), (2, 1 / 6)):
            f.write(f"{m.nid(0, jl, k)}, 3, {-0.5 * P_MAX * w:.12g}\n")
        f.write("*NODE PRINT, NSET=LOADMID, TIME POINTS=LEVELS\nU\n*END STEP\n")
    return m


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--grid", nargs=2, type=int, default=[20, 40], metavar=("NU", "NV"))
    ap.add_argument("--edge", nargs="+", default=["a", "b", "c", "d"])
    ap.add_argument("--workdir", default="out/semi-cylinder-ccx")
    ap.add_argument("--timeout", type=float, default=1200.0)
    args = ap.parse_args()
    os.makedirs(args.workdir, exist_ok=True)
    for edge in args.edge:
        job = f"semi_{edge}_{args.grid[0]}x{args.grid[1]}"
        write_input(os.path.join(args.workdir, job + ".inp"), args.grid[0], args.grid[1], edge)
        text, rc = run_ccx(args.workdir, job, args.timeout)
        res = {}
        for (what, _, t), rows in parse_dat(text).items():
            if what == "displacements":
                res[round(t, 6)] = -100.0 * list(rows.values())[0][2]
        print(f"\nedge {edge}, {args.grid[0]} x {args.grid[1]} C3D20R, ccx exit {rc}")
        print("| P/P_max | 100 w (ccx) | Sze | error |\n|---|---|---|---|")
        for p, w in REF:
            got = res.get(round(p, 6))
            if got is None:
                print(f"| {p:g} | (not reached) | {w} | |")
            else:
                print(f"| {p:g} | {got:.3f} | {w} | {100 * (got - w) / w:+.2f} % |")
        sys.stdout.flush()


if __name__ == "__main__":
    main()
