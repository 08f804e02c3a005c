#!/usr/bin/env python3
"""Makes the issue-16 scale input: an 8 x 8 mosaic of 4097 x 4097 tiles (32769^2 = 1.07e9
samples) from the Puget Sound 4k DEM in ../shared/data, mirrored so that neighbours share
their edge rows and columns exactly (SRTM's layout).

The 4096^2 source gets one more row and column (the mirror of row and column 4094), then
tile (i, j) is that 4097^2 image flipped east-west when i is odd and north-south when j is
odd: the last column of tile i is then the first of tile i + 1. Only the four flips are
written (4 x 67 MB); the layout names each of them 16 times. Nothing here is committed: the
output goes to the directory given (default /tmp/fmrh-scale).

Usage: python3 benches/dataset/make_mosaic.py [OUT_DIR] [TILES_PER_SIDE]
"""
import json
import os
import sys

import numpy as np

here = os.path.dirname(os.path.abspath(__file__))
src = os.path.join(here, "../../../shared/data/puget-sound-4k-jpg/ps_height_4k_jpg.f32")
out = sys.argv[1] if len(sys.argv) > 1 else "/tmp/fmrh-scale"
n = int(sys.argv[2]) if len(sys.argv) > 2 else 8
os.makedirs(out, exist_ok=True)

p = np.fromfile(src, dtype="<f4").reshape(4096, 4096)
p = np.vstack([p, p[4094:4095, :]])
p = np.hstack([p, p[:, 4094:4095]])
assert p.shape == (4097, 4097)
for fx in (0, 1):
    for fy in (0, 1):
        t = p[:, ::-1] if fx else p
        t = t[::-1, :] if fy else t
        name = f"puget-{fx}{fy}"
        np.ascontiguousarray(t, dtype="<f4").tofile(os.path.join(out, name + ".f32"))
        with open(os.path.join(out, name + ".json"), "w") as f:
            json.dump(
                {
                    "width": 4097,
                    "height": 4097,
                    "f32_file": name + ".f32",
                    "nodata_in_f32": None,
                    "units": "metres",
                    "spacing_m": [40.0, 40.0],
                    "source": "Puget Sound 4k (../shared/data/puget-sound-4k-jpg), mirrored for the issue-16 mosaic",
                },
                f,
            )
with open(os.path.join(out, "layout.csv"), "w") as f:
    f.write("# path,col0,row0: an %d x %d mosaic of mirrored Puget Sound 4k tiles\n" % (n, n))
    for j in range(n):
        for i in range(n):
            f.write(f"puget-{i % 2}{j % 2}.f32,{4096 * i},{4096 * j}\n")
print(f"{out}/layout.csv: {n * n} tiles, {4096 * n + 1}^2 = {(4096 * n + 1) ** 2:.3e} samples")
