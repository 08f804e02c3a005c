"""fmrh.build, fmrh.dataset.build/add and Terrain.edit: a container built from Python equals
one `fmrh build` makes with the same options (samples and levels), the progress callback
hears each phase from 0 to its total, a dataset built from Python reads like `fmrh dataset
build`'s, a tile added lands where it was put, and an edit commits every replacement at once
on a clean exit and none on an exception (the file's bytes unchanged), with bad patches,
bad options and a second writer raising the package's exceptions."""
import json
import shutil

import numpy as np
import pytest

import fmrh
from conftest import SRTM, extract, fmrh_cli


def test_build_equals_the_cli_and_reports_progress(tmp_path):
    src = SRTM / "N43E006.hgt.gz"
    calls = []
    made = fmrh.build(src, tmp_path / "py.fmrh", block_size=129, thresholds=[0, 5, 50],
                      progress=lambda phase, done, total: calls.append((phase, done, total)))
    fmrh_cli("build", "-q", src, "-o", tmp_path / "cli.fmrh", "--block-size", "129",
             "--thresholds", "0,5,50")
    with fmrh.open(tmp_path / "py.fmrh") as a, fmrh.open(tmp_path / "cli.fmrh") as b:
        assert np.array_equal(a.read().view(np.uint32), b.read().view(np.uint32))
        assert a.levels == b.levels
        assert [l["threshold"] for l in a.levels] == [0, 5, 50]
        assert a.info()["block_size"] == 129
    assert made["file_length"] == (tmp_path / "py.fmrh").stat().st_size
    assert [l["threshold"] for l in made["error_levels"]] == [0, 5, 50]
    # Each phase is heard starting at 0 and ending at its total, never past it.
    phases = {}
    for phase, done, total in calls:
        phases.setdefault(phase, []).append((done, total))
    assert len(phases) >= 2, calls
    for phase, seen in phases.items():
        assert seen[0][0] == 0 and seen[-1][0] == seen[-1][1], (phase, seen)
        assert all(0 <= d <= t for d, t in seen), (phase, seen)
        assert [d for d, _ in seen] == sorted(d for d, _ in seen), (phase, seen)


def test_build_refuses_bad_options_and_existing_files(tmp_path):
    src = SRTM / "N43E006.hgt.gz"
    out = tmp_path / "x.fmrh"
    with pytest.raises(fmrh.InvalidArgumentError, match='unknown option "blocksize"'):
        fmrh.build(src, out, blocksize=129)
    with pytest.raises(fmrh.InvalidArgumentError, match="block_size"):
        fmrh.build(src, out, block_size="big")
    with pytest.raises(fmrh.InvalidArgumentError, match="block size"):
        fmrh.build(src, out, block_size=100)
    with pytest.raises(fmrh.InvalidArgumentError, match="payloads_alone"):
        fmrh.build(src, out, payloads_alone=1)
    with pytest.raises(fmrh.IoError):
        fmrh.build(tmp_path / "missing.hgt", out)
    assert not out.exists()
    fmrh.build(src, out)
    before = out.read_bytes()
    with pytest.raises(fmrh.FmrhError, match="exists"):
        fmrh.build(src, out, block_size=33)
    assert out.read_bytes() == before
    fmrh.build(src, out, block_size=33, overwrite=True)
    assert out.read_bytes() != before


def test_a_progress_callback_that_raises_is_raised_after_the_build(tmp_path):
    def fails(phase, done, total):
        raise KeyError("stop")

    with pytest.raises(KeyError, match="stop"):
        fmrh.build(SRTM / "N43E006.hgt.gz", tmp_path / "x.fmrh", progress=fails)


def test_dataset_build_and_add(tmp_path):
    a, b = SRTM / "N43E006.hgt.gz", SRTM / "N43E007.hgt.gz"
    summary = fmrh.dataset.build([a], tmp_path / "ds", seam="first")
    assert len(summary["tiles"]) == 1
    added = fmrh.dataset.add(tmp_path / "ds", b)
    assert added["shift"] == [0, 0] and added["commit"]["txn_id"] >= 1
    fmrh_cli("dataset", "build", "-q", "--seam", "first", a, b, "-o", tmp_path / "cli")
    with fmrh.open(tmp_path / "ds") as d, fmrh.open(tmp_path / "cli") as c:
        assert d.shape == c.shape == (1201, 2401)
        assert np.array_equal(d.read().view(np.uint32), c.read().view(np.uint32))
    # A layout CSV, as `fmrh dataset build --layout` reads it.
    shutil.copy(a, tmp_path / "a.hgt.gz")
    (tmp_path / "layout.csv").write_text("a.hgt.gz,0,0\na.hgt.gz,1200,0\n")
    laid = fmrh.dataset.build(tmp_path / "layout.csv", tmp_path / "laid", seam="first")
    assert laid["columns"] == 2401 and laid["rows"] == 1201
    with pytest.raises(fmrh.InvalidArgumentError, match="exists"):
        fmrh.dataset.build([a], tmp_path / "ds")
    with pytest.raises(fmrh.InvalidArgumentError, match="seam"):
        fmrh.dataset.build([a], tmp_path / "ds2", seam="loose")
    assert not (tmp_path / "ds2").exists()


def test_an_edit_commits_all_at_once_on_a_clean_exit(n43, tmp_path):
    path = tmp_path / "e.fmrh"
    shutil.copy(n43, path)
    with fmrh.open(path) as t:
        before = t.read()
        patch = np.full((30, 40), -7.5, np.float32)
        patch[3, 4] = np.nan
        with t.edit() as txn:
            txn.replace(100, 200, patch)
            txn.replace(1190, 1195, np.ones((6, 11), np.float32))
        assert txn.committed["files"] == 1 and txn.committed["blocks"] >= 2
        after = t.read()  # this terrain reads the committed state
    want = before.copy()
    want[200:230, 100:140] = patch
    want[1195:1201, 1190:1201] = 1
    assert np.array_equal(after.view(np.uint32), want.view(np.uint32))
    assert np.array_equal(extract(path, tmp_path / "e.f32").view(np.uint32), want.view(np.uint32))
    assert fmrh.open(path).verify(full=True)["valid"]


def test_an_edit_rolls_back_on_an_exception_and_bad_patches_raise(n43, tmp_path):
    path = tmp_path / "r.fmrh"
    shutil.copy(n43, path)
    original = path.read_bytes()
    with fmrh.open(path) as t:
        with pytest.raises(RuntimeError, match="changed my mind"):
            with t.edit() as txn:
                txn.replace(0, 0, np.zeros((10, 10), np.float32))
                raise RuntimeError("changed my mind")
        assert path.read_bytes() == original
        with t.edit() as txn:
            for bad, match in [
                (np.zeros((4, 4), np.float64), "float32"),
                (np.zeros(16, np.float32), "2-D"),
                ([[1.0, 2.0]], "float32"),
                (np.zeros((0, 3), np.float32), "no sample"),
                (np.full((2, 2), np.inf, np.float32), "finite"),
            ]:
                with pytest.raises(fmrh.InvalidArgumentError, match=match):
                    txn.replace(0, 0, bad)
            with pytest.raises(fmrh.InvalidArgumentError, match="outside|inside"):
                txn.replace(1200, 0, np.zeros((1, 2), np.float32))
            with pytest.raises(fmrh.InvalidArgumentError, match=">= 0"):
                txn.replace(-1, 0, np.zeros((1, 1), np.float32))
            # A second writer, while this edit holds the file, is refused.
            with pytest.raises(fmrh.FmrhError):
                fmrh.open(path).edit()
            txn.rollback()
        with pytest.raises(fmrh.FmrhError, match="ended"):
            txn.replace(0, 0, np.zeros((1, 1), np.float32))
    assert path.read_bytes() == original


def test_a_dataset_edit_crosses_tiles(dataset, tmp_path):
    ds = tmp_path / "ds"
    shutil.copytree(dataset, ds)
    with fmrh.open(ds) as t:
        before = t.read()
        with t.edit() as txn:
            txn.replace(1190, 10, np.full((5, 20), 3.0, np.float32))
        assert txn.committed["files"] == 2
        want = before.copy()
        want[10:15, 1190:1210] = 3.0
        assert np.array_equal(t.read().view(np.uint32), want.view(np.uint32))
        assert t.verify(full=True)["valid"]
