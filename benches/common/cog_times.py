#!/usr/bin/env python3
"""Times scenes read from a local COG through GDAL, as a COG client reads them: open the file,
then read each chosen tile (level, column, row) with ReadBlock, decoded. For each scene, warm
(the best of REPS runs, the file in the page cache) and cold (the file's pages dropped with
posix_fadvise(DONTNEED) before each of REPS runs, the best of them). Every run opens the
dataset afresh, so GDAL's block cache holds nothing of the last. Used by
benches/scenes_vs_cog.rs (issue 44) for the comparison only: fmrh never links GDAL.

Usage: cog_times.py COG SCENES_JSON REPS, where SCENES_JSON is a file holding a list of
scenes, each a list of [level, tx, ty] (level 0 the full resolution, level l the (l-1)-th
overview). Prints a JSON list of {"warm": seconds, "cold": seconds}, one per scene."""
import json
import os
import sys
import time

from osgeo import gdal

gdal.UseExceptions()
gdal.SetConfigOption("GDAL_DISABLE_READDIR_ON_OPEN", "EMPTY_DIR")

path, scenes_file, reps = sys.argv[1], sys.argv[2], int(sys.argv[3])
with open(scenes_file) as f:
    scenes = json.load(f)


def drop_cache():
    fd = os.open(path, os.O_RDONLY)
    try:
        os.posix_fadvise(fd, 0, 0, os.POSIX_FADV_DONTNEED)
    finally:
        os.close(fd)


def run(tiles):
    start = time.perf_counter()
    ds = gdal.Open(path)
    band = ds.GetRasterBand(1)
    n = 0
    for level, tx, ty in tiles:
        b = band if level == 0 else band.GetOverview(level - 1)
        n += len(b.ReadBlock(tx, ty))
    seconds = time.perf_counter() - start
    ds = None
    assert n > 0 or not tiles
    return seconds


out = []
for tiles in scenes:
    run(tiles)  # warm the file and GDAL's code paths
    warm = min(run(tiles) for _ in range(reps))
    cold = []
    for _ in range(reps):
        drop_cache()
        cold.append(run(tiles))
    out.append({"warm": warm, "cold": min(cold)})
print(json.dumps(out))
