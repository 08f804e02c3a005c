#!/usr/bin/env python3
"""Packs NGA's EGM96 15-minute geoid grid (WW15MGH.DAC) into ww15mgh.i16.zlib, which
src/geoid.rs embeds.

WW15MGH.DAC: 721 rows (90 N to 90 S) of 1440 big-endian int16 geoid heights in
centimetres (0 E eastwards, 15' apart). Output: the same values as little-endian int16
residuals of the gradient predictor (west + north - north-west; the west neighbour alone
on row 0, the north neighbour alone in column 0, 0 for the first value), deflated (zlib,
level 9). Run: python3 pack.py WW15MGH.DAC
"""
import array
import sys
import zlib

ROWS, COLS = 721, 1440
raw = open(sys.argv[1], "rb").read()
assert len(raw) == ROWS * COLS * 2, "WW15MGH.DAC is 2,076,480 bytes"
a = array.array("h")
a.frombytes(raw)
if sys.byteorder == "little":
    a.byteswap()  # the file is big-endian
out = array.array("h")
for r in range(ROWS):
    for c in range(COLS):
        v = a[r * COLS + c]
        if r == 0 and c == 0:
            pred = 0
        elif r == 0:
            pred = a[c - 1]
        elif c == 0:
            pred = a[(r - 1) * COLS]
        else:
            pred = a[r * COLS + c - 1] + a[(r - 1) * COLS + c] - a[(r - 1) * COLS + c - 1]
        out.append(v - pred)
if sys.byteorder == "big":
    out.byteswap()
open("ww15mgh.i16.zlib", "wb").write(zlib.compress(out.tobytes(), 9))
