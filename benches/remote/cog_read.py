#!/usr/bin/env python3
"""Reads chosen tiles of a COG through GDAL's /vsicurl/, as a COG client does: open the URL,
then read each tile (level, column, row) with ReadBlock. Prints the seconds it took, open
included, as JSON. Used by benches/remote.rs (issue 17) for the comparison only: fmrh never
links GDAL. Usage: cog_read.py URL TILES_JSON (a list of [level, tx, ty]; level 0 is the full
resolution, level l the (l-1)-th overview)."""
import json
import sys
import time

from osgeo import gdal

gdal.UseExceptions()
# Do not list the "directory" on open: a COG client reads the one file.
gdal.SetConfigOption("GDAL_DISABLE_READDIR_ON_OPEN", "EMPTY_DIR")
gdal.SetConfigOption("CPL_VSIL_CURL_ALLOWED_EXTENSIONS", ".tif")
# No cache shared between runs of this process (each run is a fresh process anyway).
gdal.SetConfigOption("VSI_CACHE", "FALSE")

url, tiles = sys.argv[1], json.loads(sys.argv[2])
start = time.perf_counter()
ds = gdal.Open("/vsicurl/" + url)
band = ds.GetRasterBand(1)
for level, tx, ty in tiles:
    b = band if level == 0 else band.GetOverview(level - 1)
    b.ReadBlock(tx, ty)
print(json.dumps({"seconds": time.perf_counter() - start}))
