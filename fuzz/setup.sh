#!/usr/bin/env bash
# Installs what the fuzz targets need: cargo-fuzz (its version pinned, so every run builds the
# same way), then builds every target once. Run from anywhere; the targets build on stable.
set -euo pipefail
cd "$(dirname "$0")"
want=0.13.2
have=$(cargo fuzz --version 2>/dev/null | awk '{print $2}' || true)
if [ "$have" != "$want" ]; then
  cargo install cargo-fuzz --version "$want" --locked
fi
cargo fuzz build --sanitizer none -O
echo "fuzz: ready; see fuzz/README.md for how to run each target"
