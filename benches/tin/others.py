#!/usr/bin/env python3
"""The two TIN libraries benches/tin_compare.rs measures fmrh's RTIN against, run on the same
grid at the same max error: pymartini (mapbox/martini's RTIN) and pydelatin (mapbox/delatin's
greedy Delaunay insertion), both from PyPI (`pip install pymartini pydelatin numpy`).

  python3 others.py GRID.f32 SIDE MAX_ERROR OUT_DIR

GRID.f32 holds SIDE x SIDE little-endian float32 heights, row-major. For each library
writes OUT_DIR/NAME.mesh (u32 vertex count, u32 triangle count, then the vertices as f64
x, y pairs, then the triangles as u32 triples) and prints one JSON line: name, seconds,
vertices, triangles. The libraries' own error claims are not read: the bench measures.
"""
import json
import struct
import sys
import time

import numpy as np
import pydelatin
import pymartini

path, side, max_error, out = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), sys.argv[4]
grid = np.fromfile(path, dtype="<f4").reshape(side, side)


def write(name, vertices, triangles, seconds):
    vertices = np.asarray(vertices, dtype="<f8").reshape(-1, 2)
    triangles = np.asarray(triangles, dtype="<u4").reshape(-1, 3)
    with open(f"{out}/{name}.mesh", "wb") as f:
        f.write(struct.pack("<II", len(vertices), len(triangles)))
        f.write(vertices.tobytes())
        f.write(triangles.tobytes())
    print(json.dumps({"name": name, "seconds": seconds,
                      "vertices": len(vertices), "triangles": len(triangles)}))


# martini: a (2^k + 1)^2 grid, read row-major (as the JS library's `terrain[y * size + x]`),
# so vertices are (column, row). The array must be C-contiguous: pymartini reads its memory.
start = time.perf_counter()
martini = pymartini.Martini(side)
tile = martini.create_tile(np.ascontiguousarray(grid, dtype=np.float32))
vertices, triangles = tile.get_mesh(max_error)
seconds = time.perf_counter() - start
write("pymartini", vertices.reshape(-1, 2), triangles, seconds)

# delatin: vertices are (x, y, z) with y up: row = side - 1 - y (checked against z).
start = time.perf_counter()
d = pydelatin.Delatin(np.ascontiguousarray(grid), width=side, height=side, max_error=max_error)
vertices, triangles = d.vertices, d.triangles
seconds = time.perf_counter() - start
rows = side - 1 - vertices[:, 1]
assert np.all(grid[rows.astype(int), vertices[:, 0].astype(int)] == vertices[:, 2].astype(np.float32))
write("pydelatin", np.stack([vertices[:, 0], rows], axis=1), triangles, seconds)
