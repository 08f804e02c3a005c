"""Fixtures for the fmrh Python package's tests: containers and a dataset built by the fmrh
command line (FMRH_BIN, default the repository's target/release/fmrh) from the bundled DEMs,
and `fmrh extract` read back as the reference."""
import json
import os
import pathlib
import subprocess

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
BIN = os.environ.get("FMRH_BIN", str(ROOT / "target" / "release" / "fmrh"))
SRTM = ROOT / "data" / "srtm3-pyhgtmap"


def fmrh_cli(*args):
    if not os.path.exists(BIN):
        pytest.fail(f"the fmrh binary is missing at {BIN}: `cargo build --release` (or set FMRH_BIN)")
    run = subprocess.run([BIN, *map(str, args)], capture_output=True, text=True)
    if run.returncode != 0:
        raise AssertionError(f"fmrh {' '.join(map(str, args))} failed: {run.stderr}")
    return run.stdout


def extract(path, out, window=None):
    """`fmrh extract` of `window` ("c0,r0,c1,r1", inclusive) as a float32 array."""
    args = ["extract", "-q", path, "-o", out]
    if window:
        args += ["--window", window]
    fmrh_cli(*args)
    meta = json.loads(pathlib.Path(str(out).replace(".f32", ".json")).read_text())
    return np.fromfile(out, dtype="<f4").reshape(meta["height"], meta["width"])


@pytest.fixture(scope="session")
def n43(tmp_path_factory):
    d = tmp_path_factory.mktemp("n43")
    out = d / "n43e006.fmrh"
    fmrh_cli("build", "-q", SRTM / "N43E006.hgt.gz", "-o", out)
    return out


@pytest.fixture(scope="session")
def dataset(tmp_path_factory):
    d = tmp_path_factory.mktemp("ds")
    out = d / "n43"
    fmrh_cli("dataset", "build", "-q", "--seam", "first",
             SRTM / "N43E006.hgt.gz", SRTM / "N43E007.hgt.gz", "-o", out)
    return out


@pytest.fixture(scope="session")
def puget(tmp_path_factory):
    """Puget Sound 1k as the README builds it."""
    d = tmp_path_factory.mktemp("ps1k")
    out = d / "ps1k.fmrh"
    png = ROOT / "data" / "puget-sound-1k" / "ps_height_1k.png"
    fmrh_cli("build", "-q", png, "--z-scale", "0.1", "--spacing", "160", "-o", out)
    return out
