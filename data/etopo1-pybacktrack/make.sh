#!/usr/bin/env bash
# Rebuilds etopo1-bed-0.5deg.tif from the ETOPO1 grid pybacktrack 1.5.0 ships (PyPI), exactly
# as provenance.json says: every 5th sample of every 5th row, columns rotated to start at
# -180 degrees. Needs pip, unzip, numpy and gdal-bin (gdal_translate). Not run by the tests.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cd "$work"
pip download -q --no-deps pybacktrack==1.5.0
unzip -q pybacktrack-1.5.0-py3-none-any.whl 'pybacktrack/bundle_data/topography/ETOPO1_0.1.grd'
gdal_translate -q -of ENVI pybacktrack/bundle_data/topography/ETOPO1_0.1.grd src.raw
python3 - <<'PY'
import numpy as np
a = np.fromfile('src.raw', dtype='<f4').reshape(1801, 3601)
k = np.arange(721)
np.ascontiguousarray(a[::5][:, (5 * k + 1800) % 3600]).tofile('out.raw')
open('out.hdr', 'w').write("""ENVI
samples = 721
lines = 361
bands = 1
header offset = 0
file type = ENVI Standard
data type = 4
interleave = bsq
byte order = 0
map info = {Geographic Lat/Lon, 1, 1, -180.25, 90.25, 0.5, 0.5, WGS-84}
""")
PY
gdal_translate -q -of GTiff -co COMPRESS=DEFLATE -co PREDICTOR=3 -co ZLEVEL=9 -co TILED=NO out.raw "$here/etopo1-bed-0.5deg.tif"
sha256sum "$here/etopo1-bed-0.5deg.tif"
