"""The xarray backend: ``xr.open_dataset("x.fmrh", engine="fmrh")`` opens a container, a
dataset directory or a URL as an ``xarray.Dataset`` with one variable, ``height``
(``(y, x)``, float32, NaN voids), read lazily: only the windows that are indexed are read
and decoded (and with ``chunks=``, one window a Dask chunk).

Coordinates ``x`` and ``y`` are the sample centres in the terrain's CRS (for a geographic
CRS, longitude and latitude in degrees), and the CRS and affine transform are recorded as
rioxarray expects them: a ``spatial_ref`` coordinate with ``crs_wkt`` and ``GeoTransform``,
named by the variable's ``grid_mapping``; so ``.sel()`` by coordinates and ``.rio`` work.

``level=`` (an index into ``Terrain.levels``) or ``max_error=`` (height units) reads the
surface the coarsest error level within the bound draws instead of the stored samples, still
one value a sample (see ``Terrain.read``): every real sample within the bound, from the
coarse blocks only.
"""

import threading

import numpy as np
import xarray as xr
from xarray.backends import BackendArray, BackendEntrypoint
from xarray.core import indexing

import fmrh


class _HeightArray(BackendArray):
    """A terrain's heights as xarray's lazily indexed array: each basic index becomes one
    ``Terrain.read`` of the window it spans."""

    def __init__(self, terrain, max_error, level):
        self.terrain = terrain
        self.shape = terrain.shape
        self.dtype = np.dtype("float32")
        self.max_error = max_error
        self.level = level

    def __getitem__(self, key):
        return indexing.explicit_indexing_adapter(
            key, self.shape, indexing.IndexingSupport.BASIC, self._read)

    def _read(self, key):
        """The samples ``key`` (a tuple of an int or a slice per axis) picks: one read of
        the window spanning them, then sliced."""
        picks, drop = [], []
        for k, n in zip(key, self.shape):
            if isinstance(k, (int, np.integer)):
                i = int(k) + n if k < 0 else int(k)
                picks.append(range(i, i + 1))
                drop.append(True)
            else:
                picks.append(range(*k.indices(n)))
                drop.append(False)
        rows, cols = picks
        if len(rows) == 0 or len(cols) == 0:
            out = np.empty((len(rows), len(cols)), np.float32)
        else:
            r0, c0 = min(rows[0], rows[-1]), min(cols[0], cols[-1])
            h, w = max(rows[0], rows[-1]) - r0 + 1, max(cols[0], cols[-1]) - c0 + 1
            block = self.terrain.read((c0, r0, w, h), max_error=self.max_error, level=self.level)
            # The first pick is the window's first (a positive step) or last (a negative
            # one) row or column; the step walks from there to the other end.
            out = block[rows[0] - r0::rows.step, cols[0] - c0::cols.step]
        if drop[0] and drop[1]:
            return out[0, 0]
        if drop[0]:
            return out[0]
        if drop[1]:
            return out[:, 0]
        return out


def _wkt(crs):
    """The CRS as WKT (what rioxarray reads), through pyproj when it is there."""
    if crs is None:
        return None
    try:
        import pyproj
    except ImportError:
        return crs
    return pyproj.CRS.from_user_input(crs).to_wkt()


def open_terrain_dataset(location, *, level=None, max_error=None, drop_variables=None):
    """The ``xarray.Dataset`` of the terrain at ``location`` (see the module's docs)."""
    terrain = fmrh.open(location)
    if level is not None or max_error is not None:
        terrain._bound(max_error, level)  # check now, not at the first read
    rows, cols = terrain.shape
    data = indexing.LazilyIndexedArray(_HeightArray(terrain, max_error, level))
    attrs = {"vertical_datum": terrain.vertical_datum, "fmrh_kind": terrain.info()["kind"]}
    if level is not None:
        attrs["fmrh_level"] = int(level)
        attrs["fmrh_max_error"] = float(terrain.levels[int(level)]["max_error"])
    elif max_error is not None:
        attrs["fmrh_max_error_bound"] = float(max_error)
    variables = {}
    coords = {}
    t = terrain.transform
    if t is not None:
        a, _, c, _, e, f = t
        coords["x"] = ("x", c + a * (np.arange(cols) + 0.5), {"axis": "X"})
        coords["y"] = ("y", f + e * (np.arange(rows) + 0.5), {"axis": "Y"})
        wkt = _wkt(terrain.crs)
        ref_attrs = {"GeoTransform": " ".join(repr(float(v)) for v in (c, a, 0.0, f, 0.0, e))}
        if wkt:
            ref_attrs["crs_wkt"] = wkt
            ref_attrs["spatial_ref"] = wkt
        coords["spatial_ref"] = ((), np.int64(0), ref_attrs)
        attrs["grid_mapping"] = "spatial_ref"
    variables["height"] = xr.Variable(("y", "x"), data, attrs)
    ds = xr.Dataset(variables, coords=coords)
    if drop_variables:
        ds = ds.drop_vars([v for v in drop_variables if v in ds.variables])
    ds.set_close(terrain.close)
    return ds


class FmrhBackendEntrypoint(BackendEntrypoint):
    """``engine="fmrh"``: fmrh containers, dataset directories and their URLs."""

    description = "Open fmrh multiresolution terrain (containers, datasets, URLs) lazily"
    url = "https://github.com/fmrh/fmrh"
    open_dataset_parameters = ("filename_or_obj", "drop_variables", "level", "max_error")

    def open_dataset(self, filename_or_obj, *, drop_variables=None, level=None, max_error=None):
        return open_terrain_dataset(str(filename_or_obj), level=level, max_error=max_error,
                                    drop_variables=drop_variables)

    def guess_can_open(self, filename_or_obj):
        try:
            name = str(filename_or_obj)
        except Exception:
            return False
        return name.endswith(".fmrh")
