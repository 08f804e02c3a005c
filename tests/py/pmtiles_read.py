"""Reads a PMTiles archive with the `pmtiles` package (protomaps' reference reader for
Python): every tile into OUT_DIR/z/x/y.bin, and the header and metadata as JSON on stdout.
Used by tests/pmtiles_python.rs to check fmrh's archives against a reader fmrh did not write.

Usage: python3 pmtiles_read.py ARCHIVE OUT_DIR
"""
import json
import os
import sys

from pmtiles.reader import MmapSource, Reader, all_tiles

archive, out_dir = sys.argv[1], sys.argv[2]
with open(archive, "rb") as f:
    source = MmapSource(f)
    reader = Reader(source)
    header = reader.header()
    metadata = reader.metadata()
    count = 0
    for (z, x, y), data in all_tiles(source):
        column = os.path.join(out_dir, str(z), str(x))
        os.makedirs(column, exist_ok=True)
        with open(os.path.join(column, f"{y}.bin"), "wb") as t:
            t.write(data)
        # The reader's own lookup by address finds the same bytes (one tile in 25: each
        # lookup walks the directories from the root, in Python).
        if count % 25 == 0:
            assert reader.get(z, x, y) == data, (z, x, y)
        count += 1
    plain = {k: (v.value if hasattr(v, "value") else v) for k, v in header.items()}
    print(json.dumps({"header": plain, "metadata": metadata, "tiles": count}))
