#!/usr/bin/env python3
"""Hinged cylindrical roof (Sze, Liu & Lo 2004 §3.8, h = 12.7) in CalculiX, for three readings
of the hinged-edge condition. Writes the ccx input, runs ccx (displacement control of the load
point through the limit point and the minimum) and prints the limit load, the minimum and
P/P_max at Sze's 36 deflections. Requires the `ccx` executable (Debian package calculix-ccx).

Usage: roof_ccx.py [--grid N [N ...]] [--edge a b c d] [--layers NT] [--load all|mid]
                   [--material svk|neo-hooke] [--ours RESULTS_JSON]

Quarter model as the shipped case.toml: axis y, crown along z, symmetry planes x = 0 (the crown
line) and y = 0 (mid-length), the straight edge at th = 0.1 rad hinged, the curved edge y = 254
free. Hinged-edge candidates:
  a  u_x = u_y = u_z = 0 on the mid-surface only (rotations free: Sze's statement)
  b  u_x = u_y = u_z = 0 on all nodes through the thickness (the rotation about the edge held)
  c  u_x = u_z = 0 on the mid-surface only, u_y (axial) free
  d  the thickness average of (u_x, u_y, u_z) held on each line through the thickness (the
     shell's hinge; the section free to turn and warp), with --layers bricks through the
     thickness. a holds the mid-surface nodes alone: a point support of the section, whose
     local compliance grows as bricks are added through the thickness, so a and d agree only
     at one brick, and only roughly.
"""
import argparse
import json
import os
import sys

sys.dont_write_bytecode = True  # no __pycache__ beside the shared modules
HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "..", "calculix"))
sys.path.insert(0, os.path.join(HERE, ".."))
from ccx_cylinder import (LAWS, CylinderMesh, parse_dat, run_ccx,  # noqa: E402
                          write_displacement_step, write_mesh, write_nset)
from compare import P_MAX, REF  # noqa: E402  (Sze's table and P_max, one copy)
from paths import extrema  # noqa: E402

R, HALF_L, H = 2540.0, 254.0, 12.7
E, NU = 3102.75, 0.3
HALF_ANGLE_DEG = 5.729577951308232  # 0.1 rad
W_END = 30.0                        # the load point's u_z is -W_END * time
DT_GRID = 0.01                      # output every 0.3 of deflection, besides Sze's deflections


def time_points():
    pts = {round(w / W_END, 9) for _, w in REF}
    pts |= {round(DT_GRID * n, 9) for n in range(1, int(round(1 / DT_GRID)) + 1)}
    return sorted(pts)


def write_input(path, n, edge, load, law="svk", nt=1):
    # e1 = z (the crown, th = 0), e2 = x, axis y: th in [0, 0.1 rad], s in [0, 254].
    if nt != 1 and edge != "d":
        raise ValueError(f"edge {edge} is written for one brick through the thickness")
    m = CylinderMesh(R, H, [0, 0, 1], [1, 0, 0], [0, 1, 0], (0.0, HALF_ANGLE_DEG),
                     (0.0, HALF_L), n, n, nt)
    ie = m.ni - 1
    dofs = (1, 3) if edge == "c" else (1, 2, 3)
    with open(path, "w") as f:
        f.write(f"*HEADING\nhinged roof h = 12.7, quarter model, edge {edge}, load {load}\n")
        write_mesh(f, m, E, NU, law)
        write_nset(f, "SYMX", m.line(i=0))
        write_nset(f, "SYMY", m.line(j=0))
        write_nset(f, "EDGEALL", m.line(i=ie))
        write_nset(f, "EDGEMID", m.line(i=ie, layers=(nt,)))
        layers = range(m.nk) if load == "all" else (nt,)
        write_nset(f, "LOADN", [m.nid(0, 0, k) for k in layers])
        write_nset(f, "LOADMID", [m.nid(0, 0, nt)])
        f.write("*BOUNDARY\nSYMX, 1, 1\nSYMY, 2, 2\n")
        if edge == "d":
            for j in range(m.nj):
                terms = m.section_average(ie, j)
                for d in dofs:
                    if d == 2 and j == 0:
                        continue  # u_y is held on the symmetry plane y = 0 already
                    items = [f"{node}, {d}, {c:.12g}" for node, c in terms]
                    f.write(f"*EQUATION\n{len(items)}\n")
                    for k in range(0, len(items), 4):
                        f.write(", ".join(items[k:k + 4]) + "\n")
        else:
            edge_set = "EDGEALL" if edge == "b" else "EDGEMID"
            for d in dofs:
                f.write(f"{edge_set}, {d}, {d}\n")
        if edge in ("a", "c"):
            # between mid-surface nodes (odd j) the mid-surface value is the faces' mean
            for j in range(1, m.nj, 2):
                lo, hi = m.nid(ie, j, 0), m.nid(ie, j, 2)
                for d in dofs:
                    f.write(f"*EQUATION\n2\n{hi}, {d}, 1.0, {lo}, {d}, 1.0\n")
        # Displacement control: u_z = -W_END * time on the load point (ramped over the step).
        write_displacement_step(f, time_points(), "LOADN", 3, -W_END, 0.005, DT_GRID,
                                [("LOADN", "RF", True), ("LOADMID", "U", False)])
    return m


def read_path(text):
    """[(W, P/P_max)] from the .dat text: W = -u_z of the mid-surface load node, P = -4 R_z."""
    w, p = {}, {}
    for (what, _, t), rows in parse_dat(text).items():
        if what == "displacements":
            w[t] = -list(rows.values())[0][2]
        elif what.startswith("total force"):
            p[t] = -4.0 * rows[0][2] / P_MAX
    return [(0.0, 0.0)] + [(w[t], p[t]) for t in sorted(w) if t in p]


def ours_path(path):
    doc = json.load(open(path))
    pts = {}
    for s in doc["steps"]:
        if s.get("converged"):
            w = -s["monitors"]["A"]["displacement"][2]
            pts[round(w, 6)] = -4.0 * list(s["reactions"].values())[0] / P_MAX
    return pts


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--grid", nargs="+", type=int, default=[16, 24])
    ap.add_argument("--edge", nargs="+", default=["a", "b", "c"])
    ap.add_argument("--layers", type=int, default=1,
                    help="bricks through the thickness (edge d only, for more than one)")
    ap.add_argument("--load", choices=["all", "mid"], default="all",
                    help="u_z prescribed on all three load-point nodes or the mid-surface one")
    ap.add_argument("--material", choices=LAWS, default="svk",
                    help="the elastic law at finite strain (ccx_cylinder.write_mesh)")
    ap.add_argument("--ours", help="a shelldsa results.json of the shipped case, for a column")
    ap.add_argument("--workdir", default="out/hinged-roof-ccx")
    ap.add_argument("--timeout", type=float, default=1200.0)
    args = ap.parse_args()
    os.makedirs(args.workdir, exist_ok=True)
    ours = ours_path(args.ours) if args.ours else None
    for n in args.grid:
        for edge in args.edge:
            job = (f"roof_{edge}_{n}x{n}" + ("" if args.layers == 1 else f"x{args.layers}")
                   + ("" if args.load == "all" else "_mid")
                   + ("" if args.material == "svk" else "_neo"))
            write_input(os.path.join(args.workdir, job + ".inp"), n, edge, args.load,
                        args.material, args.layers)
            text, rc = run_ccx(args.workdir, job, args.timeout)
            pts = read_path(text)
            print(f"\nedge {edge}, {n} x {n} x {args.layers} C3D20R, {args.material}, "
                  f"load-point u_z on "
                  f"{args.load}, ccx exit {rc}, {len(pts) - 1} output points, "
                  f"last -W {pts[-1][0]:.3f}")
            lim, mn = extrema(pts)
            for name, v, (p_ref, w_ref) in (("limit load", lim, (0.7421, 11.293)),
                                            ("minimum", mn, (0.1729, 19.852))):
                if v is None:
                    print(f"{name}: not reached")
                else:
                    print(f"{name}: {v[1]:.4f} at -W {v[0]:.3f}; Sze {p_ref} at {w_ref}: "
                          f"{100 * (v[1] / p_ref - 1):+.2f} %")
            by_w = {round(w, 6): p for w, p in pts}
            head = "| -W | Sze | ccx | ccx - Sze (% of P_max) |"
            print(head + (" ours | ours - ccx |" if ours else ""))
            print("|---|---|---|---|" + ("---|---|" if ours else ""))
            worst = worst_o = 0.0
            for p_ref, w_ref in REF:
                p = by_w.get(round(w_ref, 6))
                if p is None:
                    print(f"| {w_ref:.3f} | {p_ref:.4f} | (not reached) | |")
                    continue
                worst = max(worst, abs(p - p_ref))
                row = f"| {w_ref:.3f} | {p_ref:.4f} | {p:.4f} | {100 * (p - p_ref):+.2f} |"
                po = ours.get(round(w_ref, 6)) if ours else None
                if po is not None:
                    worst_o = max(worst_o, abs(po - p))
                    row += f" {po:.4f} | {100 * (po - p):+.2f} |"
                print(row)
            print(f"largest |P_ccx - P_Sze| at Sze's deflections: {100 * worst:.2f} % of P_max")
            if ours:
                print(f"largest |P_ours - P_ccx|: {100 * worst_o:.2f} % of P_max")
            sys.stdout.flush()


if __name__ == "__main__":
    main()
