"""The xarray backend (engine="fmrh"): a container and a dataset open lazily as a Dataset
whose `height` equals Terrain.read bit for bit (whole, and under every kind of basic index:
steps, negative steps, single rows and columns, Dask chunks); the coordinates are the sample
centres of the georeference, so `.sel()` by longitude and latitude picks the right sample;
rioxarray reads the CRS, transform and bounds fmrh gives; `level=` and `max_error=` read the
coarse surface Terrain.read gives for them; bad levels raise before anything is read."""
import numpy as np
import pytest
import rioxarray  # noqa: F401  (the .rio accessor)
import xarray as xr

import fmrh


def same(a, b):
    a, b = np.asarray(a, np.float32), np.asarray(b, np.float32)
    assert a.shape == b.shape
    assert np.array_equal(a.view(np.uint32), b.view(np.uint32))


def test_height_equals_read_under_every_index(n43):
    with fmrh.open(n43) as t:
        want = t.read()
    ds = xr.open_dataset(n43, engine="fmrh")
    h = ds.height
    assert h.dims == ("y", "x") and h.shape == want.shape and h.dtype == np.float32
    same(h.values, want)
    for rows, cols in [(slice(None, None, 3), slice(5, 100, 7)),
                       (slice(None, None, -2), slice(1200, 0, -5)),
                       (slice(7, 8), slice(None)),
                       (-1, slice(10, 20)),
                       (slice(100, 90, -1), 0),
                       (slice(5, 5), slice(None))]:
        same(h[rows, cols].values, want[rows, cols])
    same(h.isel(x=-1).values, want[:, -1])
    same(h.isel(y=3, x=4).values, want[3, 4])
    ds.close()


def test_coordinates_and_crs_as_rioxarray_expects(n43):
    with fmrh.open(n43) as t:
        want, transform, bounds = t.read(), t.transform, t.bounds
    h = xr.open_dataset(n43, engine="fmrh").height
    # Sample (col, row) is at 6 + col/1200 degrees east, 44 - row/1200 north.
    for col, row in [(0, 0), (600, 300), (1200, 1200), (17, 1100)]:
        v = h.sel(x=6 + col / 1200, y=44 - row / 1200, method="nearest")
        same(v.values, want[row, col])
    assert h.rio.crs.to_epsg() == 4326
    assert tuple(h.rio.transform())[:6] == pytest.approx(transform)
    assert h.rio.bounds() == pytest.approx(bounds)
    clipped = h.rio.clip_box(6.25, 43.25, 6.5, 43.5)
    assert clipped.shape[0] in (300, 301, 302) and clipped.shape[1] in (300, 301, 302)


def test_levels_and_bounds_read_the_coarse_surface(n43):
    with fmrh.open(n43) as t:
        coarse = t.read(level=5)
        within = t.read(max_error=50.0)
        levels = t.levels
    ds = xr.open_dataset(n43, engine="fmrh", level=5)
    same(ds.height.values, coarse)
    assert ds.height.attrs["fmrh_max_error"] == levels[5]["max_error"]
    same(xr.open_dataset(n43, engine="fmrh", max_error=50.0).height[100:200, 300:500].values,
         within[100:200, 300:500])
    with pytest.raises(fmrh.InvalidArgumentError, match="level"):
        xr.open_dataset(n43, engine="fmrh", level=99)
    with pytest.raises(fmrh.InvalidArgumentError, match="max_error"):
        xr.open_dataset(n43, engine="fmrh", max_error=-1)


def test_a_dataset_in_dask_chunks(dataset):
    with fmrh.open(dataset) as t:
        want = t.read()
    h = xr.open_dataset(dataset, engine="fmrh", chunks={"y": 500, "x": 700}).height
    assert h.chunks is not None
    same(h.values, want)
    assert float(h.mean(skipna=True)) == pytest.approx(float(np.nanmean(want.astype(np.float64))), rel=1e-6)
