"""Cylinder-sector meshes for CalculiX (ccx) reference runs, and reading ccx's .dat output.

The shell is meshed as `nt` layers of 20-node reduced-integration bricks (C3D20R) through the
thickness (default one: the element CalculiX itself expands an S8R shell into), written out here
so that every boundary condition is stated on the nodes it acts on (mid-surface only for a
hinge, all layers where a rotation is held as well).

Node grid: i = 0 .. 2 nu along the arc, j = 0 .. 2 nv along the axis, k = 0 .. 2 nt through the
thickness (inner face to outer face; k = nt is the mid-surface). Position
    X = (R + (k / (2 nt) - 1/2) h) (cos(th) e1 + sin(th) e2) + s a,
th = th0 + (th1 - th0) i / (2 nu), s = s0 + (s1 - s0) j / (2 nv). Serendipity elements have no
node where i and j are both odd, and nodes between the bricks' faces (odd k) only where i and j
are both even.
"""
import math
import os
import re
import subprocess


class CylinderMesh:
    def __init__(self, radius, thickness, e1, e2, axis, theta, length, nu, nv, nt=1):
        self.r, self.h = radius, thickness
        self.e1, self.e2, self.a = e1, e2, axis
        self.theta, self.length = theta, length
        self.nu, self.nv, self.nt = nu, nv, nt
        self.ni, self.nj, self.nk = 2 * nu + 1, 2 * nv + 1, 2 * nt + 1

    def exists(self, i, j, k):
        if not (0 <= i < self.ni and 0 <= j < self.nj and 0 <= k < self.nk):
            return False
        if i % 2 == 1 and j % 2 == 1:
            return False
        return k % 2 == 0 or (i % 2 == 0 and j % 2 == 0)

    def nid(self, i, j, k):
        assert self.exists(i, j, k), (i, j, k)
        return 1 + i + self.ni * (j + self.nj * k)

    def coords(self, i, j, k):
        th = math.radians(self.theta[0] + (self.theta[1] - self.theta[0]) * i / (self.ni - 1))
        s = self.length[0] + (self.length[1] - self.length[0]) * j / (self.nj - 1)
        rk = self.r + (k / (self.nk - 1) - 0.5) * self.h
        return [rk * (math.cos(th) * p + math.sin(th) * q) + s * c
                for p, q, c in zip(self.e1, self.e2, self.a)]

    def nodes(self):
        return [(i, j, k) for k in range(self.nk) for j in range(self.nj) for i in range(self.ni)
                if self.exists(i, j, k)]

    def elements(self):
        # C3D20 order: corners 1-4 (inner face), 5-8 (outer face), mid-edges 9-12 (inner),
        # 13-16 (outer), 17-20 (through the thickness). Local (xi, eta, zeta) = (arc, axis,
        # radius); the corner order is reversed where that frame is left-handed.
        cross = [self.e1[1] * self.e2[2] - self.e1[2] * self.e2[1],
                 self.e1[2] * self.e2[0] - self.e1[0] * self.e2[2],
                 self.e1[0] * self.e2[1] - self.e1[1] * self.e2[0]]
        right = sum(c * a for c, a in zip(cross, self.a)) > 0
        out = []
        for t in range(self.nt):
            k0 = 2 * t
            for b in range(self.nv):
                for a in range(self.nu):
                    i0, j0 = 2 * a, 2 * b
                    c = [(i0, j0), (i0 + 2, j0), (i0 + 2, j0 + 2), (i0, j0 + 2)]
                    m = [(i0 + 1, j0), (i0 + 2, j0 + 1), (i0 + 1, j0 + 2), (i0, j0 + 1)]
                    if not right:
                        c = [c[0], c[3], c[2], c[1]]
                        m = [m[3], m[2], m[1], m[0]]
                    ids = ([self.nid(i, j, k0) for i, j in c]
                           + [self.nid(i, j, k0 + 2) for i, j in c]
                           + [self.nid(i, j, k0) for i, j in m]
                           + [self.nid(i, j, k0 + 2) for i, j in m]
                           + [self.nid(i, j, k0 + 1) for i, j in c])
                    out.append(ids)
        return out

    def section_average(self, i, j):
        """[(node, weight)]: the thickness average of a field on the line (i, j) through the
        thickness, as the bricks interpolate it (Simpson's weights per brick where the line has
        a node between the faces, the trapezoid where it has none); the weights sum to 1."""
        w = {}
        for t in range(self.nt):
            k0 = 2 * t
            if self.exists(i, j, k0 + 1):
                parts = ((k0, 1.0 / 6.0), (k0 + 1, 4.0 / 6.0), (k0 + 2, 1.0 / 6.0))
            else:
                parts = ((k0, 0.5), (k0 + 2, 0.5))
            for k, c in parts:
                w[k] = w.get(k, 0.0) + c / self.nt
        return [(self.nid(i, j, k), c) for k, c in sorted(w.items())]

    def line(self, i=None, j=None, layers=None, skip_j=()):
        """Node ids on the grid line i = const or j = const, on the given node layers k (all
        by default)."""
        pts = []
        if i is not None:
            pts = [(i, jj) for jj in range(self.nj) if jj not in skip_j]
        else:
            pts = [(ii, j) for ii in range(self.ni)]
        ks = range(self.nk) if layers is None else layers
        return [self.nid(p, q, k) for p, q in pts for k in ks if self.exists(p, q, k)]


LAWS = ("svk", "neo-hooke")


def write_mesh(f, mesh, young, poisson, law="svk"):
    """The nodes, the C3D20R elements and the material. `law`: "svk" (ccx's `*ELASTIC` under
    NLGEOM: St Venant-Kirchhoff, the second Piola-Kirchhoff stress linear in the Green-Lagrange
    strain) or "neo-hooke" (`*HYPERELASTIC, NEO HOOKE` with the same small-strain shear and bulk
    moduli: C10 = mu / 2, D1 = 2 / K). The two agree to first order in the strain and differ
    at the next."""
    f.write("*NODE, NSET=NALL\n")
    for i, j, k in mesh.nodes():
        x = mesh.coords(i, j, k)
        f.write(f"{mesh.nid(i, j, k)}, {x[0]:.12g}, {x[1]:.12g}, {x[2]:.12g}\n")
    f.write("*ELEMENT, TYPE=C3D20R, ELSET=EALL\n")
    for n, ids in enumerate(mesh.elements(), start=1):
        row = [n] + ids
        f.write(", ".join(str(v) for v in row[:16]) + ",\n")
        f.write(", ".join(str(v) for v in row[16:]) + "\n")
    f.write("*MATERIAL, NAME=MAT\n")
    if law == "svk":
        f.write(f"*ELASTIC\n{young:.10g}, {poisson:.10g}\n")
    elif law == "neo-hooke":
        mu = young / (2.0 * (1.0 + poisson))
        bulk = young / (3.0 * (1.0 - 2.0 * poisson))
        f.write(f"*HYPERELASTIC, NEO HOOKE\n{mu / 2.0:.10g}, {2.0 / bulk:.10g}\n")
    else:
        raise ValueError(f"law = {law!r}: expected one of {LAWS}")
    f.write("*SOLID SECTION, ELSET=EALL, MATERIAL=MAT\n")


def write_displacement_step(f, times, controlled, dof, value, first, max_inc, outputs):
    """One NLGEOM step that moves `controlled` (a node set) along `dof` to `value`, ramped over
    the step time 1, with output at `times` (a `*TIME POINTS` list named OUT): for each
    (set, quantity, totals) of `outputs`, a `*NODE PRINT` of that quantity."""
    f.write("*TIME POINTS, NAME=OUT\n")
    for k in range(0, len(times), 8):
        f.write(", ".join(f"{t:.10g}" for t in times[k:k + 8]) + "\n")
    f.write(f"*STEP, NLGEOM, INC=5000\n*STATIC\n{first:g}, 1.0, 1e-7, {max_inc:g}\n")
    f.write(f"*BOUNDARY\n{controlled}, {dof}, {dof}, {value:.10g}\n")
    for nset, quantity, totals in outputs:
        f.write(f"*NODE PRINT, NSET={nset}{', TOTALS=ONLY' if totals else ''}, "
                f"TIME POINTS=OUT\n{quantity}\n")
    f.write("*END STEP\n")


def write_nset(f, name, ids):
    f.write(f"*NSET, NSET={name}\n")
    ids = list(ids)
    for n in range(0, len(ids), 12):
        f.write(", ".join(str(v) for v in ids[n:n + 12]) + ",\n")


def run_ccx(workdir, job, timeout):
    """Runs `ccx JOB` in workdir (niced, one thread); returns the .dat text and ccx's exit code."""
    env = dict(os.environ, OMP_NUM_THREADS="1", CCX_NPROC_STIFFNESS="1",
               CCX_NPROC_EQUATION_SOLVER="1")
    with open(os.path.join(workdir, job + ".log"), "w") as log:
        proc = subprocess.run(["nice", "ccx", job], cwd=workdir, env=env, stdout=log,
                              stderr=subprocess.STDOUT, timeout=timeout)
    dat = os.path.join(workdir, job + ".dat")
    text = open(dat).read() if os.path.exists(dat) else ""
    return text, proc.returncode


def parse_dat(text):
    """ccx .dat blocks: {(quantity, set, time): {node: [values]}}; a TOTALS=ONLY sum is node 0."""
    out = {}
    key = None
    head = re.compile(r"^\s*(.+?) \(.*?\) for set (\S+) and time\s+(\S+)")
    for line in text.splitlines():
        m = head.match(line)
        if m:
            key = (m.group(1).strip(), m.group(2), float(m.group(3)))
            out[key] = {}
            continue
        if key is None or not line.strip():
            continue
        parts = line.split()
        if key[0].startswith("total"):     # TOTALS=ONLY: one row of sums, no node number
            out[key][0] = [float(v) for v in parts]
            key = None
            continue
        try:
            out[key][int(parts[0])] = [float(v) for v in parts[1:]]
        except ValueError:
            key = None
    return out
