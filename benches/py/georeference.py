"""Writes a raw float32 grid as a georeferenced float32 GeoTIFF, for benches that feed the
same raster to fmrh and to a GDAL-based tool (benches/terrain_rgb_export.rs).

Usage: python3 georeference.py IN.f32 WIDTH HEIGHT EPSG WEST NORTH DX DY OUT.tif
(WEST, NORTH: the outer corner of the north-west sample's cell; DX, DY: the steps east and
south, in the CRS's units.)
"""
import sys

import numpy as np
import rasterio
from rasterio.transform import from_origin

src, w, h, epsg, west, north, dx, dy, out = sys.argv[1:]
w, h = int(w), int(h)
data = np.fromfile(src, dtype="<f4").reshape(h, w)
with rasterio.open(out, "w", driver="GTiff", width=w, height=h, count=1, dtype="float32",
                   crs=f"EPSG:{epsg}", transform=from_origin(float(west), float(north), float(dx), float(dy)),
                   tiled=True, compress="deflate") as dst:
    dst.write(data, 1)
