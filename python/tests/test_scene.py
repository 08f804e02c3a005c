"""Terrain.scene: the blocks a camera needs are those `fmrh scene --json` lists for the same
camera, tolerance, field of view, viewport and mode (level, rectangle, measured and screen
errors, in the same order), each block's heights are the stored samples at its grid points,
and bad arguments raise the package's exceptions."""
import json

import numpy as np
import pytest

import fmrh
from conftest import fmrh_cli

EYE, TARGET = (20000, 180000, 6000), (80000, 80000, 500)


def cli_scene(path, *extra):
    out = fmrh_cli("scene", path, "--eye", ",".join(map(str, EYE)), "--target",
                   ",".join(map(str, TARGET)), "--json", *extra)
    return json.loads(out)["blocks"]


@pytest.mark.parametrize("tau,kwargs,extra", [
    (1.0, {}, ["--tau", "1"]),
    (4.0, {"mode": "uniform"}, ["--tau", "4", "--mode", "uniform"]),
    (0.5, {"fov": 45, "viewport": (800, 600)}, ["--tau", "0.5", "--fov", "45", "--viewport", "800x600"]),
])
def test_scene_equals_the_cli(puget, tau, kwargs, extra):
    want = cli_scene(puget, *extra)
    with fmrh.open(puget) as t:
        got = t.scene(EYE, TARGET, tau, **kwargs)
        full = t.read()
    assert len(got) == len(want) > 10
    for g, w in zip(got, want):
        assert g["level"] == w["level"]
        assert g["rect"] == (w["col0"], w["row0"], w["col1"], w["row1"])
        assert g["error"] == pytest.approx(w["error"], rel=1e-6)
        assert g["screen_error"] == pytest.approx(w["screen_error"], rel=1e-9)
        assert g["screen_error"] <= tau + 1e-9
        c0, r0, c1, r1 = g["rect"]
        s = g["stride"]
        assert g["heights"].dtype == np.float32
        assert g["heights"].shape == (g["height"], g["width"])
        # A block's grid points are stored samples.
        assert np.array_equal(g["heights"], full[r0:r1 + 1:s, c0:c1 + 1:s])


def test_bad_scene_arguments_raise(puget):
    with fmrh.open(puget) as t:
        with pytest.raises(fmrh.InvalidArgumentError, match="mode"):
            t.scene(EYE, TARGET, 1.0, mode="sideways")
        with pytest.raises(fmrh.FmrhError):
            t.scene(EYE, TARGET, -1.0)
        with pytest.raises(fmrh.FmrhError):
            t.scene(EYE, EYE, 1.0)
        with pytest.raises(fmrh.InvalidArgumentError, match="eye"):
            t.scene((1, 2), TARGET)
        with pytest.raises(fmrh.InvalidArgumentError, match="target"):
            t.scene(EYE, "north")


def test_a_camera_on_the_globe_equals_the_cli(n43):
    """Terrain.scene_geo is `fmrh scene --eye-geo --look`, and a flight of globe cameras
    gives each one's scene."""
    out = fmrh_cli("scene", n43, "--eye-geo", "43.3,6.2,6000", "--look", "40,-25", "--tau", "2", "--json")
    want = json.loads(out)["blocks"]
    with fmrh.open(n43) as t:
        got = t.scene_geo(43.3, 6.2, 6000, 40, -25, tau=2)
        assert len(got) == len(want) > 10
        for g, w in zip(got, want):
            assert g["level"] == w["level"]
            assert g["rect"] == (w["col0"], w["row0"], w["col1"], w["row1"])
            assert g["screen_error"] == pytest.approx(w["screen_error"], rel=1e-9)
        poses = [(43.3, 6.2 + 0.01 * i, 6000, 40, -25) for i in range(6)]
        frames = list(t.fly(poses, 2, geo=True))
        assert len(frames) == 6
        for pose, frame in zip(poses, frames):
            scene = t.scene_geo(*pose, tau=2)
            assert [b["rect"] for b in frame["blocks"]] == [b["rect"] for b in scene]
            assert all(np.array_equal(a["heights"], b["heights"]) for a, b in zip(frame["blocks"], scene))
        assert sum(len(f["loaded"]) for f in frames) < sum(len(f["blocks"]) for f in frames)
        with pytest.raises(fmrh.InvalidArgumentError, match="lat, lon"):
            t.scene_geo(43.3, 6.2, "high")
