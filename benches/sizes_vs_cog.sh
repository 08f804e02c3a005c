#!/usr/bin/env bash
# File size on every DEM in ../shared/data: raw f32, the .fmrh fmrh builds (lossless), and a
# Cloud-Optimized GeoTIFF of the same samples made the standard way (DEFLATE, horizontal
# differencing predictor 2, or 3 for floats, overviews AUTO), as issue 15 asks:
#
#   gdal_translate -of COG -co COMPRESS=DEFLATE -co PREDICTOR=2|3 -co OVERVIEWS=AUTO
#
# GDAL (gdal-bin) is used here only, for the comparison; fmrh never links it. The COG is made
# from the same .f32 fmrh reads (through an ENVI header), so both hold identical samples.
#
#   bash benches/sizes_vs_cog.sh [OUT.csv]      (needs ../shared/data, gdal-bin, a release build)
set -euo pipefail
cd "$(dirname "$0")/.."
command -v gdal_translate >/dev/null || { echo "needs gdal-bin (apt-get install gdal-bin)"; exit 1; }
cargo build --release -q
fmrh=target/release/fmrh
out_csv=${1:-}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
rows=()
printf '%-28s %12s %12s %12s %8s %8s %8s\n' dem raw_f32 fmrh cog fmrh/raw cog/raw fmrh/cog
for json in ../shared/data/*/*.json; do
  case "$json" in *provenance*) continue ;; esac
  f32="${json%.json}.f32"
  [ -f "$f32" ] || continue
  name=$(basename "${json%.json}")
  read -r w h < <(python3 -c "import json,sys; d=json.load(open(sys.argv[1])); print(d['width'], d['height'])" "$json")
  nodata=$(python3 -c "import json,sys; d=json.load(open(sys.argv[1])); print('nan' if d.get('nodata_count') else '')" "$json")
  cp "$f32" "$tmp/$name.bin"
  # An ENVI header: GDAL reads the raw little-endian f32 as it is.
  printf 'ENVI\nsamples = %s\nlines = %s\nbands = 1\nheader offset = 0\nfile type = ENVI Standard\ndata type = 4\ninterleave = bsq\nbyte order = 0\n' "$w" "$h" > "$tmp/$name.hdr"
  nd=()
  [ -n "$nodata" ] && nd=(-a_nodata nan)
  # Integer-valued sources keep their type in a COG (as a GIS user would store them).
  int=$(python3 - "$f32" <<'PY'
import sys, array, math
a = array.array('f'); a.frombytes(open(sys.argv[1], 'rb').read())
vals = [v for v in a if not math.isnan(v)]
print('Int16' if vals and all(v == int(v) and -32768 <= v <= 32767 for v in vals) else 'Float32')
PY
)
  if [ "$int" = Int16 ]; then
    gdal_translate -q -ot Int16 ${nodata:+-a_nodata -32768} -of COG -co COMPRESS=DEFLATE -co PREDICTOR=2 -co OVERVIEWS=AUTO "$tmp/$name.bin" "$tmp/$name.tif"
  else
    gdal_translate -q "${nd[@]}" -of COG -co COMPRESS=DEFLATE -co PREDICTOR=3 -co OVERVIEWS=AUTO "$tmp/$name.bin" "$tmp/$name.tif"
  fi
  $fmrh build "$json" -o "$tmp/$name.fmrh" -q --spacing 1 >/dev/null 2>&1
  raw=$(stat -c %s "$f32"); fm=$(stat -c %s "$tmp/$name.fmrh"); cog=$(stat -c %s "$tmp/$name.tif")
  printf '%-28s %12d %12d %12d %8.3f %8.3f %8.2f\n' "$name" "$raw" "$fm" "$cog" \
    "$(echo "$fm/$raw" | bc -l)" "$(echo "$cog/$raw" | bc -l)" "$(echo "$fm/$cog" | bc -l)"
  rows+=("$name,$raw,$fm,$cog,$int")
  rm -f "$tmp/$name".*
done
if [ -n "$out_csv" ]; then
  { echo "dem,raw_f32_bytes,fmrh_bytes,cog_bytes,cog_type"; printf '%s\n' "${rows[@]}"; } > "$out_csv"
fi
