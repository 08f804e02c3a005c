"""The height error of a terrain-RGB tile set against its source, for benches/terrain_rgb_export.rs.

Usage: python3 tile_error.py SOURCE.tif ENCODING TILES
  SOURCE.tif  the float32 GeoTIFF both tile makers read (rasterio opens it)
  ENCODING    mapbox or terrarium
  TILES       dir:PATH (PATH/z/x/y.png, y from the north) or mbtiles:PATH (TMS rows)

For every pixel of every tile whose centre lies on the data, the decoded height is compared
with the source at the pixel's centre: the centre's longitude and latitude (Web Mercator),
taken into the source's CRS by GDAL (rasterio.warp.transform), and the source interpolated
bilinearly between its four nearest sample centres (rio-rgbify's scheme, GDAL's bilinear;
fmrh draws each cell as two triangles, so this also counts the two schemes' difference in
steep cells). So a second figure, free of any interpolation scheme: how far a pixel lies
outside the range of its cell's four samples (0 for any interpolation of the data itself).
Prints one JSON object: per zoom, the tiles, pixels compared, max, mean and 99th percentile
of |error| against bilinear, and the max and 99th percentile outside the cell's range.
"""
import io
import json
import math
import os
import sqlite3
import sys

import numpy as np
import rasterio
from PIL import Image
from rasterio.warp import transform as warp

src_path, encoding, tiles_arg = sys.argv[1], sys.argv[2], sys.argv[3]


def tiles():
    kind, path = tiles_arg.split(":", 1)
    if kind == "dir":
        for z in sorted(os.listdir(path)):
            if not z.isdigit():
                continue
            for x in os.listdir(os.path.join(path, z)):
                for name in os.listdir(os.path.join(path, z, x)):
                    y = name.split(".")[0]
                    with open(os.path.join(path, z, x, name), "rb") as f:
                        yield int(z), int(x), int(y), f.read()
    else:
        con = sqlite3.connect(path)
        for z, x, row, data in con.execute("select zoom_level, tile_column, tile_row, tile_data from tiles"):
            yield z, x, (1 << z) - 1 - row, data


with rasterio.open(src_path) as src:
    heights = src.read(1).astype(np.float64)
    nodata = src.nodata
    inverse = ~src.transform
    crs = src.crs
h, w = heights.shape
valid = np.isfinite(heights) if nodata is None else np.isfinite(heights) & (heights != nodata)

stats = {}
for z, x, y, data in tiles():
    img = np.asarray(Image.open(io.BytesIO(data)).convert("RGBA")).astype(np.float64)
    size = img.shape[0]
    n = (1 << z) * size
    j, i = np.mgrid[0:size, 0:size]
    gx = (x * size + i + 0.5) / n
    gy = (y * size + j + 0.5) / n
    lon = gx * 360.0 - 180.0
    lat = np.degrees(np.arctan(np.sinh(math.pi * (1 - 2 * gy))))
    if crs.to_epsg() == 4326:
        ex, ny = lon.ravel(), lat.ravel()
    else:
        ex, ny = warp("EPSG:4326", crs, lon.ravel(), lat.ravel())
    ex, ny = np.asarray(ex), np.asarray(ny)
    # Fractional sample coordinates, 0 at the first sample's centre.
    c = inverse.a * ex + inverse.b * ny + inverse.c - 0.5
    r = inverse.d * ex + inverse.e * ny + inverse.f - 0.5
    on = (c >= 0) & (c <= w - 1) & (r >= 0) & (r <= h - 1)
    c0 = np.clip(np.floor(c).astype(np.int64), 0, w - 2)
    r0 = np.clip(np.floor(r).astype(np.int64), 0, h - 2)
    fc, fr = c - c0, r - r0
    corners = [(r0, c0), (r0, c0 + 1), (r0 + 1, c0), (r0 + 1, c0 + 1)]
    for rr, cc in corners:
        on &= valid[rr, cc]
    v = ((1 - fc) * (1 - fr) * heights[r0, c0] + fc * (1 - fr) * heights[r0, c0 + 1]
         + (1 - fc) * fr * heights[r0 + 1, c0] + fc * fr * heights[r0 + 1, c0 + 1])
    px = img.reshape(-1, 4)
    if encoding == "mapbox":
        got = -10000.0 + (px[:, 0] * 65536 + px[:, 1] * 256 + px[:, 2]) * 0.1
    else:
        got = px[:, 0] * 256 + px[:, 1] + px[:, 2] / 256 - 32768
    err = np.abs(got - v)[on]
    cell = np.stack([heights[rr, cc] for rr, cc in corners])
    outside = np.maximum(np.maximum(cell.min(axis=0) - got, got - cell.max(axis=0)), 0.0)[on]
    s = stats.setdefault(z, {"tiles": 0, "errors": [], "outside": []})
    s["tiles"] += 1
    if err.size:
        s["errors"].append(err)
        s["outside"].append(outside)

out = {}
for z in sorted(stats):
    e = np.concatenate(stats[z]["errors"]) if stats[z]["errors"] else np.zeros(0)
    o = np.concatenate(stats[z]["outside"]) if stats[z]["outside"] else np.zeros(0)
    out[z] = {
        "outside_max": float(o.max()) if o.size else 0.0,
        "outside_p99": float(np.percentile(o, 99)) if o.size else 0.0,
        "tiles": stats[z]["tiles"],
        "pixels": int(e.size),
        "max": float(e.max()) if e.size else 0.0,
        "mean": float(e.mean()) if e.size else 0.0,
        "p99": float(np.percentile(e, 99)) if e.size else 0.0,
    }
print(json.dumps(out))
