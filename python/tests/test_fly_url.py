"""Terrain.fly and reading by URL: every frame of a flight along the shipped camera path is
the scene Terrain.scene gives for its camera (blocks and heights bit for bit), decoding only
the blocks that entered the view; and a container and a dataset served over HTTP with byte
ranges read, describe themselves and answer scenes exactly as the local files do, read-only."""
import shutil

import numpy as np
import pytest

import fmrh
from conftest import ROOT, SRTM, fmrh_cli

PATH = ROOT / "tests" / "paths" / "n43e007-low-pass.csv"


@pytest.fixture(scope="module")
def n43e007(tmp_path_factory):
    out = tmp_path_factory.mktemp("e7") / "n43e007.fmrh"
    fmrh_cli("build", "-q", SRTM / "N43E007.hgt.gz", "-o", out)
    return out


def same_block(a, b):
    return (a["rect"] == b["rect"] and a["level"] == b["level"] and a["error"] == b["error"]
            and np.array_equal(a["heights"].view(np.uint32), b["heights"].view(np.uint32)))


def test_each_frame_is_the_scene_and_only_new_blocks_are_loaded(n43e007):
    cameras = []
    for line in PATH.read_text().splitlines()[1::25]:
        v = [float(x) for x in line.split(",")]
        cameras.append((v[:3], v[3:]))
    with fmrh.open(n43e007) as t:
        frames = list(t.fly(cameras, tau=1.0))
        assert len(frames) == len(cameras)
        held, loaded, visible = set(), 0, 0
        for (eye, target), frame in zip(cameras, frames):
            scene = t.scene(eye, target, 1.0)
            assert len(frame["blocks"]) == len(scene)
            assert all(same_block(a, b) for a, b in zip(frame["blocks"], scene))
            keys = set(frame["keys"])
            assert set(frame["evicted"]) == held - keys
            assert len(frame["loaded"]) == len(keys - held)
            held = keys
            loaded += len(frame["loaded"])
            visible += len(frame["blocks"])
        assert loaded < visible
        # The CSV as `fmrh fly --path` reads it gives every camera of the file.
        assert sum(1 for _ in t.fly(PATH)) == len(PATH.read_text().splitlines()) - 1
        with pytest.raises(fmrh.InvalidArgumentError):
            list(t.fly([((0, 0, 1),)]))


def test_a_container_and_a_dataset_read_by_url(n43, dataset, http_root):
    root, base = http_root
    shutil.copy(n43, root / "n43.fmrh")
    shutil.copytree(dataset, root / "ds")
    for local, url in [(n43, f"{base}/n43.fmrh"), (dataset, f"{base}/ds/")]:
        with fmrh.open(local) as a, fmrh.open(url) as b:
            assert b.shape == a.shape and b.transform == a.transform and b.levels == a.levels
            assert np.array_equal(b.read().view(np.uint32), a.read().view(np.uint32))
            w = (1100, 17, 101, 300)
            assert np.array_equal(b.read(w).view(np.uint32), a.read(w).view(np.uint32))
            eye, target = (30000.0, -20000.0, 9000.0), (50000.0, 60000.0, 0.0)
            sa, sb = a.scene(eye, target, 2.0), b.scene(eye, target, 2.0)
            assert sa and all(same_block(x, y) for x, y in zip(sa, sb)) and len(sa) == len(sb)
            with pytest.raises(fmrh.InvalidArgumentError, match="read-only"):
                b.edit()
    with pytest.raises(fmrh.IoError, match="404"):
        fmrh.open(f"{base}/missing.fmrh")
