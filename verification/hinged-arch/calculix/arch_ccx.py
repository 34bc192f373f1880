#!/usr/bin/env python3
"""The hinged roof's cross-section as a plane-strain shallow arch (`../case.toml`) in CalculiX:
a strip of the cylindrical panel between two symmetry planes across the axis, hinged on the
straight edge, with the crown line pushed down by displacement control through the limit point
and the minimum. Writes the ccx input, runs ccx and prints the load per unit width and its
extremes; with --ours, a shelldsa results.json of the case beside it. Requires the `ccx`
executable (Debian package calculix-ccx).

Usage: arch_ccx.py [--grid N [N ...]] [--layers NT [NT ...]] [--width B]
                   [--material svk|neo-hooke] [--poisson NU] [--ours RESULTS_JSON] [--workdir DIR]

Mesh as `../../calculix/ccx_cylinder.py`: N C3D20R bricks along the half arc, 2 across the strip
of width B, NT through the thickness. Axis y, crown along z: symmetry planes x = 0 (the crown
line) and y = 0, y = B (the strip's sides). The straight edge at th = 0.1 rad is hinged as the
shell is: the thickness average of the displacement on each line through the thickness there
is held (`CylinderMesh.section_average`), the section free to turn and warp (holding the
mid-surface nodes alone is a point support of the section, whose local compliance grows as the
bricks through the thickness are refined). u_z = -30 t on every node of the crown line, all
layers. The summed z reaction divided by B is the half arch's load per unit width.
"""
import argparse
import json
import os
import sys
import tomllib

sys.dont_write_bytecode = True  # no __pycache__ beside the shared module
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..",
                                "calculix"))
from ccx_cylinder import (LAWS, CylinderMesh, parse_dat, run_ccx,  # noqa: E402
                          write_displacement_step, write_mesh, write_nset)
from paths import extrema  # noqa: E402

R, H = 2540.0, 12.7
E = 3102.75
HALF_ANGLE_DEG = 5.729577951308232  # 0.1 rad
W_END = 30.0                        # the crown's u_z is -W_END * time
DT = 0.01                           # output every 0.3 of deflection
REPORT = [1.5, 3, 4.5, 6, 7.5, 9, 10.5, 12, 13.5, 15, 16.5, 18, 19.5, 21, 22.5, 24, 25.5, 27, 28.5, 30]


def write_input(path, n, nt, width, law, poisson):
    m = CylinderMesh(R, H, [0, 0, 1], [1, 0, 0], [0, 1, 0], (0.0, HALF_ANGLE_DEG),
                     (0.0, width), n, 2, nt)
    ie, je = m.ni - 1, m.nj - 1
    with open(path, "w") as f:
        f.write(f"*HEADING\nplane-strain arch (the hinged roof's section), {law}\n")
        write_mesh(f, m, E, poisson, law)
        write_nset(f, "SYMX", m.line(i=0))
        write_nset(f, "SIDES", m.line(j=0) + m.line(j=m.nj - 1))
        write_nset(f, "CROWN", m.line(i=0))
        write_nset(f, "CROWNMID", [m.nid(0, 0, nt)])
        f.write("*BOUNDARY\nSYMX, 1, 1\nSIDES, 2, 2\n")
        # the hinge: the section's mean displacement held (u_y is held on the sides already)
        for j in range(m.nj):
            terms = m.section_average(ie, j)
            for d in (1, 2, 3):
                if d == 2 and j in (0, je):
                    continue
                items = [f"{node}, {d}, {c:.12g}" for node, c in terms]
                f.write(f"*EQUATION\n{len(items)}\n")
                for k in range(0, len(items), 4):
                    f.write(", ".join(items[k:k + 4]) + "\n")
        # output at every DT of the time (0.3 of deflection), the case's stops among them
        times = [round(k * DT, 9) for k in range(1, int(round(1 / DT)) + 1)]
        write_displacement_step(f, times, "CROWN", 3, -W_END, DT / 2, DT,
                                [("CROWN", "RF", True), ("CROWNMID", "U", False)])


def read_path(text, width):
    """[(W, q)] from the .dat text: W = -u_z of the crown, q = -R_z / width."""
    w, q = {}, {}
    for (what, _, t), rows in parse_dat(text).items():
        if what == "displacements":
            w[t] = -list(rows.values())[0][2]
        elif what.startswith("total force"):
            q[t] = -rows[0][2] / width
    return [(0.0, 0.0)] + [(w[t], q[t]) for t in sorted(w) if t in q]


def ours_path(path):
    """[(W, q)] of a shelldsa results.json of ../case.toml (the strip's width read from it)."""
    doc = json.load(open(path))
    pts = [(0.0, 0.0)]
    for s in doc["steps"]:
        if s.get("converged"):
            pts.append((-s["monitors"]["A"]["displacement"][2],
                        -sum(s["reactions"].values()) / ours_width()))
    return pts


def ours_width():
    """The strip's width in ../case.toml (`surface.length`)."""
    here = os.path.dirname(os.path.abspath(__file__))
    with open(os.path.join(here, "..", "case.toml"), "rb") as f:
        lo, hi = tomllib.load(f)["surface"]["length"]
    return hi - lo


def at(pts, w):
    for (w0, q0), (w1, q1) in zip(pts, pts[1:]):
        if w0 <= w <= w1 + 1e-9 and w1 > w0:
            return q0 + (w - w0) / (w1 - w0) * (q1 - q0)
    return None


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--grid", nargs="+", type=int, default=[256])
    ap.add_argument("--layers", nargs="+", type=int, default=[2, 4, 6],
                    help="bricks through the thickness")
    ap.add_argument("--width", type=float, default=None,
                    help="the strip's width (default 512 / N: bricks of about the arc spacing)")
    ap.add_argument("--material", choices=LAWS, default="neo-hooke")
    ap.add_argument("--poisson", type=float, default=0.3)
    ap.add_argument("--ours", help="a shelldsa results.json of ../case.toml, for a column")
    ap.add_argument("--workdir", default="out/hinged-arch-ccx")
    ap.add_argument("--timeout", type=float, default=1200.0)
    args = ap.parse_args()
    os.makedirs(args.workdir, exist_ok=True)
    ours = ours_path(args.ours) if args.ours else None
    for n, nt in [(n, nt) for n in args.grid for nt in args.layers]:
        width = args.width if args.width else 512.0 / n
        job = f"arch_{n}x{nt}_{args.material}_nu{args.poisson:g}"
        write_input(os.path.join(args.workdir, job + ".inp"), n, nt, width, args.material,
                    args.poisson)
        text, rc = run_ccx(args.workdir, job, args.timeout)
        pts = read_path(text, width)
        print(f"\n{n} x 2 x {nt} C3D20R (width {width:g}), {args.material}, "
              f"nu = {args.poisson:g}, ccx exit {rc}, {len(pts) - 1} output points")
        lim, mn = extrema(pts)
        rows = [("limit", lim), ("minimum", mn)]
        ol, om = extrema(ours) if ours else (None, None)
        for (name, v), o in zip(rows, (ol, om)):
            if v is None:
                print(f"{name}: not reached")
                continue
            line = f"{name}: q = {v[1]:.5f} at W = {v[0]:.3f}"
            if o is not None:
                line += f"; ours {o[1]:.5f} at {o[0]:.3f} ({100 * (o[1] / v[1] - 1):+.2f} %)"
            print(line)
        print("| W | ccx q |" + (" ours | ours / ccx - 1 |" if ours else ""))
        print("|---|---|" + ("---|---|" if ours else ""))
        worst = 0.0
        for w in REPORT:
            q = at(pts, w)
            if q is None:
                continue
            row = f"| {w:g} | {q:.5f} |"
            if ours and at(ours, w) is not None:
                qo = at(ours, w)
                worst = max(worst, abs(qo / q - 1))
                row += f" {qo:.5f} | {100 * (qo / q - 1):+.2f} % |"
            print(row)
        if ours:
            print(f"largest |q_ours / q_ccx - 1| at these W: {100 * worst:.2f} %")
        with open(os.path.join(args.workdir, job + "_path.txt"), "w") as f:
            f.write("# W q (load per unit width of the half arch)\n")
            for w, q in pts:
                f.write(f"{w:.6f} {q:.8f}\n")
        sys.stdout.flush()


if __name__ == "__main__":
    main()
