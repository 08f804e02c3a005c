"""Terrain.read with max_error or level, and Terrain.read_overview: every real sample is
within the chosen level's measured error of `fmrh extract`'s (plus the rounding to float32),
the bound reached is the level's own measured error, a bound of 0 reads the stored samples,
the overview is every stride-th sample of the full read with a transform that places it,
windows at edges read the same surface as the whole, and bad bounds raise."""
import numpy as np
import pytest

import fmrh
from conftest import extract


def within(approx, exact, bound):
    """Every sample where `exact` is real is within `bound` (+ float32 rounding)."""
    real = ~np.isnan(exact)
    a, e = approx[real].astype(np.float64), exact[real].astype(np.float64)
    slack = np.maximum(np.abs(a), np.abs(e)) * np.finfo(np.float32).eps
    off = np.abs(a - e)
    assert np.all(off <= bound + slack), f"{off.max()} past {bound}"
    return off.max() if off.size else 0.0


def test_each_level_reads_within_its_measured_error(n43, tmp_path):
    exact = extract(n43, tmp_path / "all.f32")
    with fmrh.open(n43) as t:
        levels = t.levels
        assert len(levels) > 3
        for i, level in enumerate(levels):
            got = t.read(level=i)
            assert got.dtype == np.float32 and got.shape == exact.shape
            reached = within(got, exact, level["max_error"])
            # The measured error is a bound the surface reaches: nothing is left unused.
            assert reached == pytest.approx(level["max_error"], abs=1e-3)
            # A bound between two thresholds reads the finer level, within the bound.
            assert np.array_equal(t.read(max_error=level["threshold"]).view(np.uint32), got.view(np.uint32))
        # Bound 0 is the stored samples, voids aside (a level fills them with its surface).
        zero = t.read(max_error=0)
        real = ~np.isnan(exact)
        assert np.array_equal(zero[real].view(np.uint32), exact[real].view(np.uint32))


def test_overview_is_every_stride_th_sample_and_placed(n43):
    with fmrh.open(n43) as t:
        coarsest = len(t.levels) - 1
        window = (17, 40, 1000, 700)
        full = t.read(window, level=coarsest)
        o = t.read_overview(window, level=coarsest)
        assert isinstance(o, fmrh.Overview)
        assert o.stride > 1 and (o.stride & (o.stride - 1)) == 0
        assert o.max_error <= t.levels[coarsest]["threshold"]
        assert np.array_equal(o.heights.view(np.uint32), full[::o.stride, ::o.stride].view(np.uint32))
        # The overview's transform puts point (i, j) on sample (17 + i·s, 40 + j·s)'s centre.
        a, _, c, _, e, f = o.transform
        ta, _, tc, _, te, tf = t.transform
        for i, j in [(0, 0), (3, 5), (o.heights.shape[1] - 1, o.heights.shape[0] - 1)]:
            x, y = c + a * (i + 0.5), f + e * (j + 0.5)
            col, row = 17 + i * o.stride, 40 + j * o.stride
            assert (x, y) == pytest.approx((tc + ta * (col + 0.5), tf + te * (row + 0.5)))


@pytest.mark.parametrize("window", [(0, 0, 1, 1), (1200, 1200, 1, 1), (0, 1170, 1201, 31), (1190, 3, 11, 1198)])
def test_windows_read_the_surface_of_the_whole(n43, window):
    with fmrh.open(n43) as t:
        bound = t.levels[-3]["threshold"]
        whole = t.read(max_error=bound)
        c, r, w, h = window
        part = t.read(window, max_error=bound)
        assert np.array_equal(part.view(np.uint32), whole[r:r + h, c:c + w].view(np.uint32))


def test_a_dataset_reads_within_the_bound(dataset, tmp_path):
    exact = extract(dataset, tmp_path / "ds.f32")
    with fmrh.open(dataset) as t:
        for bound in [0.0, 10.0, 100.0, 400.0]:
            got = t.read(max_error=bound)
            within(got, exact, t.read_overview(max_error=bound).max_error)
            within(got, exact, bound)


def test_bad_bounds_raise(n43):
    with fmrh.open(n43) as t:
        for bad in [-1, float("nan"), "x", [1]]:
            with pytest.raises(fmrh.InvalidArgumentError, match="max_error"):
                t.read(max_error=bad)
        for bad in [-1, len(t.levels), 1.5, True, "0"]:
            with pytest.raises(fmrh.InvalidArgumentError, match="level"):
                t.read(level=bad)
        with pytest.raises(fmrh.InvalidArgumentError, match="not both"):
            t.read(max_error=1, level=0)
        with pytest.raises(fmrh.InvalidArgumentError, match="needs max_error"):
            t.read_overview()
        with pytest.raises(fmrh.InvalidArgumentError, match="outside the data"):
            t.read((1200, 0, 2, 1), max_error=5)
        assert t.read(level=np.int64(1)).shape == (1201, 1201)
