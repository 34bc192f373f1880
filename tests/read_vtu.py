#!/usr/bin/env python3
"""Independent reader for the files tests/vtu.rs writes: reads them with meshio (VTU) and the
Python standard library's XML parser (PVD) and compares everything with DIR/expected.json.

Usage: python3 tests/read_vtu.py DIR
       python3 tests/read_vtu.py --dump FILE...

The second form (used by tests/shell_output.rs, which makes its own assertions) reads each FILE
and prints one JSON object to stdout: for a .vtu, meshio's view
  {"points": [[x, y, z], ...], "cells": [{"type": t, "connectivity": [[...], ...]}, ...],
   "point_data": {name: [[c0, c1, ...], ...]}, "cell_data": {name: [[c0, ...], ...]}}
(one row per point or cell, cell blocks concatenated); for a .pvd, the standard library's XML
view {"entries": [{"time": t, "file": f}, ...]}, every referenced file also read by meshio.
The result is {FILE: view, ...}. Every float is a JSON *string* holding Python's repr of it
(the shortest text that round-trips), so the reader on the other side can parse it exactly.

expected.json:
  {"vtu": [{"file": "grid.vtu",
            "points": [[x, y, z], ...],
            "cells": [{"type": "quad", "connectivity": [[...], ...]}, ...],   # meshio blocks in order
            "point_data": {"name": {"n_components": k, "values": [flat]}, ...},
            "cell_data":  {"name": {"n_components": k, "values": [flat]}, ...}}, ...],
   "pvd": [{"file": "series.pvd", "entries": [{"time": t, "file": "step.vtu"}, ...]}, ...]}

Floats are compared bit for bit (the writer promises round-trip precision). Exits 1 on the first
mismatch, 2 if meshio cannot be imported.
"""

import json
import os
import sys
import xml.etree.ElementTree as ET

try:
    import meshio
    import numpy as np
except ImportError as e:  # pragma: no cover
    print(f"read_vtu.py: cannot import meshio/numpy ({e}); run `pip install meshio`")
    sys.exit(2)


def fail(msg):
    print(f"read_vtu.py: MISMATCH: {msg}")
    sys.exit(1)


def same_bits(got, want, what):
    got = np.ascontiguousarray(np.asarray(got, dtype=np.float64)).ravel()
    want = np.ascontiguousarray(np.asarray(want, dtype=np.float64)).ravel()
    if got.shape != want.shape:
        fail(f"{what}: {got.size} values read, {want.size} expected")
    diff = np.nonzero(got.view(np.uint64) != want.view(np.uint64))[0]
    if diff.size:
        k = diff[0]
        fail(f"{what}: value {k} read as {got[k]!r}, expected {want[k]!r} ({diff.size} differ)")
    return got.size


def check_arrays(kind, got, want, count, what):
    """got: name -> ndarray (point data) or name -> list of per-block ndarrays (cell data)."""
    got = got or {}
    if set(got) != set(want):
        fail(f"{what}: {kind} arrays {sorted(got)} read, {sorted(want)} expected")
    n = 0
    for name, spec in want.items():
        arr = got[name]
        if kind == "cell":
            arr = np.concatenate([np.asarray(b).reshape(len(b), -1) for b in arr])
        arr = np.asarray(arr)
        k = spec["n_components"]
        tuples = arr.shape[0]
        comps = 1 if arr.ndim == 1 else int(np.prod(arr.shape[1:]))
        if (tuples, comps) != (count, k):
            fail(f"{what}: {kind} array {name!r} has shape {arr.shape}, expected ({count}, {k})")
        n += same_bits(arr, spec["values"], f"{what}: {kind} array {name!r}")
    return n


def check_vtu(d, spec):
    what = spec["file"]
    mesh = meshio.read(os.path.join(d, spec["file"]))
    n_points = len(spec["points"])
    if mesh.points.shape != (n_points, 3):
        fail(f"{what}: points shape {mesh.points.shape}, expected ({n_points}, 3)")
    nv = same_bits(mesh.points, spec["points"], f"{what}: point coordinates")

    blocks = [(b.type, b.data) for b in mesh.cells]
    want_blocks = spec["cells"]
    if [t for t, _ in blocks] != [b["type"] for b in want_blocks]:
        fail(f"{what}: cell blocks {[t for t, _ in blocks]}, expected {[b['type'] for b in want_blocks]}")
    n_cells = 0
    for (t, data), wb in zip(blocks, want_blocks):
        want = np.asarray(wb["connectivity"], dtype=np.int64)
        if data.shape != want.shape or not np.array_equal(data, want):
            fail(f"{what}: {t} connectivity\n{data}\nexpected\n{want}")
        n_cells += len(want)

    nv += check_arrays("point", mesh.point_data, spec["point_data"], n_points, what)
    nv += check_arrays("cell", mesh.cell_data, spec["cell_data"], n_cells, what)
    print(
        f"read_vtu.py: {what}: {n_points} points, {n_cells} cells "
        f"({', '.join(f'{len(b[1])} {b[0]}' for b in blocks)}), "
        f"{len(spec['point_data'])} point arrays, {len(spec['cell_data'])} cell arrays, "
        f"{nv} floats bit-identical"
    )


def check_pvd(d, spec):
    what = spec["file"]
    root = ET.parse(os.path.join(d, spec["file"])).getroot()
    if root.tag != "VTKFile" or root.get("type") != "Collection":
        fail(f"{what}: root is <{root.tag} type={root.get('type')!r}>, expected a VTKFile Collection")
    sets = root.findall("./Collection/DataSet")
    want = spec["entries"]
    if len(sets) != len(want):
        fail(f"{what}: {len(sets)} DataSet entries, expected {len(want)}")
    for k, (ds, w) in enumerate(zip(sets, want)):
        t = float(ds.get("timestep"))
        same_bits([t], [w["time"]], f"{what}: entry {k} timestep")
        if ds.get("file") != w["file"]:
            fail(f"{what}: entry {k} file {ds.get('file')!r}, expected {w['file']!r}")
        target = os.path.join(d, ds.get("file"))
        if not os.path.isfile(target):
            fail(f"{what}: entry {k} refers to missing {target}")
        meshio.read(target)  # every referenced file must be readable
    print(f"read_vtu.py: {what}: {len(sets)} time steps, times and files as expected, all readable")


def rows(arr, n):
    arr = np.asarray(arr, dtype=np.float64)
    return [[repr(float(x)) for x in row] for row in arr.reshape(n, -1)]


def dump_vtu(path):
    mesh = meshio.read(path)
    n_points = len(mesh.points)
    cells = [{"type": b.type, "connectivity": np.asarray(b.data).tolist()} for b in mesh.cells]
    n_cells = sum(len(b.data) for b in mesh.cells)
    point_data = {k: rows(v, n_points) for k, v in mesh.point_data.items()}
    cell_data = {
        k: rows(np.concatenate([np.asarray(b).reshape(len(b), -1) for b in v]), n_cells)
        for k, v in mesh.cell_data.items()
    }
    return {
        "points": rows(mesh.points, n_points),
        "cells": cells,
        "point_data": point_data,
        "cell_data": cell_data,
    }


def dump_pvd(path):
    root = ET.parse(path).getroot()
    if root.tag != "VTKFile" or root.get("type") != "Collection":
        fail(f"{path}: root is <{root.tag} type={root.get('type')!r}>, expected a VTKFile Collection")
    entries = []
    for ds in root.findall("./Collection/DataSet"):
        target = os.path.join(os.path.dirname(path), ds.get("file"))
        if not os.path.isfile(target):
            fail(f"{path}: entry refers to missing {target}")
        meshio.read(target)  # every referenced file must be readable
        entries.append({"time": repr(float(ds.get("timestep"))), "file": ds.get("file")})
    return {"entries": entries}


def dump(paths):
    out = {}
    for p in paths:
        out[p] = dump_pvd(p) if p.endswith(".pvd") else dump_vtu(p)
    json.dump(out, sys.stdout)


def main():
    if len(sys.argv) >= 3 and sys.argv[1] == "--dump":
        dump(sys.argv[2:])
        return
    if len(sys.argv) != 2:
        print(__doc__)
        sys.exit(2)
    d = sys.argv[1]
    with open(os.path.join(d, "expected.json")) as f:
        expected = json.load(f)
    for spec in expected["vtu"]:
        check_vtu(d, spec)
    for spec in expected.get("pvd", []):
        check_pvd(d, spec)
    print(f"read_vtu.py: OK ({len(expected['vtu'])} vtu, {len(expected.get('pvd', []))} pvd)")


if __name__ == "__main__":
    main()
