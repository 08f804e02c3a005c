#!/usr/bin/env bash
# The issue-16 scale benchmark, end to end: make the 8 x 8 mosaic of mirrored Puget Sound 4k
# tiles (1.07e9 samples) under $OUT (default /tmp/fmrh-scale; ~270 MB of inputs, never
# committed), build the dataset with `fmrh dataset build` under /usr/bin/time (build time and
# peak memory), then run benches/dataset_scale.rs on it (open, scenes against all-finest and
# traversal, a 600-frame fly-through). Needs ../shared and python3 with numpy.
set -euo pipefail
cd "$(dirname "$0")/../.."
OUT=${OUT:-/tmp/fmrh-scale}
python3 benches/dataset/make_mosaic.py "$OUT" 8
cargo build --release --quiet
rm -rf "$OUT/ds"
(cd "$OUT" && /usr/bin/time -v "$OLDPWD/target/release/fmrh" dataset build --quiet --layout layout.csv -o ds --json > build.json 2> build.time)
grep -E "Elapsed|Maximum resident" "$OUT/build.time"
python3 - "$OUT/build.json" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
print(f"built {len(d['tiles'])} tiles, {d['columns']} x {d['rows']} samples, {d['total_bytes']} bytes "
      f"(manifest {d['manifest_bytes']}), {d['shared_edges']} shared edges, in {d['build_time_s']:.1f} s")
PY
FMRH_SCALE_DATASET="$OUT/ds" cargo bench --bench dataset_scale
