"""fmrh: multiresolution terrain storage, from Python.

Open a container file, a dataset directory, or either by ``http(s)://`` or ``s3://`` URL,
and read its samples as numpy arrays, exactly as stored (voids are NaN)::

    import fmrh
    with fmrh.open("n43e006.fmrh") as t:
        print(t.shape, t.crs, t.bounds, t.vertical_datum)
        heights = t.read()                      # float32, shape (rows, columns)
        corner = t.read(window=(0, 0, 256, 128)) # (col_off, row_off, width, height)

The georeference follows rasterio's habits: ``transform`` is the affine 6-tuple
``(a, b, c, d, e, f)`` mapping a pixel's corner ``(col, row)`` to ``(a*col + b*row + c,
d*col + e*row + f)`` (``rasterio.Affine(*t.transform)``), ``bounds`` is ``(left, bottom,
right, top)``, ``res`` is ``(x, y)`` pixel sizes. Errors are exceptions of this module
(``CorruptError`` carries the broken invariant, e.g. ``"I-9"``), with the CLI's messages.
"""

import json as _json

from . import _fmrh
from ._fmrh import (
    BusyError,
    CorruptError,
    FmrhError,
    InputError,
    InvalidArgumentError,
    IoError,
    format_version,
)

__all__ = [
    "open",
    "Terrain",
    "FmrhError",
    "CorruptError",
    "BusyError",
    "InputError",
    "IoError",
    "InvalidArgumentError",
    "format_version",
]


def _window(window):
    """``(col_off, row_off, width, height)`` from a tuple or a rasterio ``Window``."""
    if window is None:
        return None
    if all(hasattr(window, k) for k in ("col_off", "row_off", "width", "height")):
        parts = (window.col_off, window.row_off, window.width, window.height)
    else:
        try:
            parts = tuple(window)
        except TypeError:
            raise InvalidArgumentError(
                f"window {window!r}: expected (col_off, row_off, width, height) or a rasterio Window"
            ) from None
    if len(parts) != 4 or any(int(p) != p for p in parts):
        raise InvalidArgumentError(
            f"window {window!r}: expected four whole numbers (col_off, row_off, width, height)"
        )
    return tuple(int(p) for p in parts)


def _point(p, name):
    """``(x, y, z)`` floats from any three numbers."""
    try:
        xyz = tuple(float(v) for v in p)
    except (TypeError, ValueError):
        xyz = ()
    if len(xyz) != 3:
        raise InvalidArgumentError(f"{name} {p!r}: expected three numbers (x, y, z)")
    return xyz


class Terrain:
    """An open container or dataset (see :func:`open`). Use it in a ``with`` block, or call
    :meth:`close`; a closed terrain raises :class:`FmrhError` when used."""

    def __init__(self, inner):
        self._t = inner
        self._info = _json.loads(inner.info_json())

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    def __repr__(self):
        state = "closed" if self.closed else "open"
        return f"<fmrh.Terrain {self._t.location!r} {self.shape[1]}x{self.shape[0]} {state}>"

    def close(self):
        """Closes the terrain; reads already running finish."""
        self._t.close()

    @property
    def closed(self):
        """Whether :meth:`close` was called."""
        return self._t.closed

    @property
    def shape(self):
        """``(rows, columns)`` of samples."""
        return self._t.shape

    @property
    def width(self):
        """Samples along a row."""
        return self._t.shape[1]

    @property
    def height(self):
        """Samples down a column."""
        return self._t.shape[0]

    @property
    def crs(self):
        """The CRS as the data names it (``"EPSG:4326"``, or WKT), or ``None``."""
        g = self._t.georeference
        return g[4] if g else None

    @property
    def transform(self):
        """The affine 6-tuple ``(a, b, c, d, e, f)`` from a pixel's corner to CRS
        coordinates (rasterio's ``Affine``), or ``None`` without a georeference."""
        g = self._t.georeference
        if not g:
            return None
        ox, oy, sx, sy, _ = g
        # fmrh places a sample at its centre; rasterio's transform maps the cell's corner.
        return (sx, 0.0, ox - sx / 2.0, 0.0, sy, oy - sy / 2.0)

    @property
    def res(self):
        """``(x, y)`` pixel sizes in CRS units (positive), or ``None``."""
        g = self._t.georeference
        return (abs(g[2]), abs(g[3])) if g else None

    @property
    def bounds(self):
        """``(left, bottom, right, top)`` in CRS units, or ``None``."""
        t = self.transform
        if t is None:
            return None
        a, _, c, _, e, f = t
        xs = (c, c + a * self.width)
        ys = (f, f + e * self.height)
        return (min(xs), min(ys), max(xs), max(ys))

    @property
    def nodata(self):
        """Always ``None``: voids are NaN in every array fmrh gives."""
        return None

    @property
    def vertical_datum(self):
        """What the heights are above: ``egm96``, ``egm2008``, ``ellipsoid`` or ``unknown``."""
        return self._t.vertical_datum

    @property
    def levels(self):
        """The error levels, finest first: each a dict with ``threshold``, ``max_error`` (the
        largest measured error of its blocks, in height units) and ``blocks``."""
        return [dict(level) for level in self._info["error_levels"]]

    def info(self):
        """The terrain's description as a dict (kind, size, georeference, datum, height
        range, error levels, transaction id, format version)."""
        return _json.loads(self._t.info_json())

    def scene(self, eye, target, tau=1.0, *, fov=None, viewport=None, mode="view"):
        """The blocks a camera at ``eye`` looking at ``target`` (``(x, y, z)`` in the
        terrain's world frame: metres east, north, up from sample (0, 0), as ``fmrh scene
        --eye/--target`` take them) needs within ``tau`` pixels of error: a list of dicts,
        each with ``rect`` (``(col0, row0, col1, row1)``, inclusive samples), ``level``,
        ``tile`` (a dataset's), ``error`` (measured, height units), ``screen_error``
        (pixels), ``stride`` (samples between grid points), ``spacing_m``, ``width``,
        ``height`` and ``heights`` (float32 ``(height, width)``). ``fov`` is the vertical
        field of view in degrees, ``viewport`` ``(width, height)`` in pixels, ``mode``
        ``"view"`` (each block meets ``tau`` where it is seen) or ``"uniform"``."""
        return self._t.scene(_point(eye, "eye"), _point(target, "target"), float(tau),
                             None if fov is None else float(fov),
                             None if viewport is None else tuple(map(int, viewport)), mode)

    def verify(self, full=False):
        """Checks every numbered invariant of the format (``full``: also recomputes every
        error from the blocks, and every cut and adjacency) and returns the report as a dict,
        as ``fmrh verify --json`` prints it: ``valid``, and one entry per invariant in
        ``checks`` (a dataset's: its own and each tile's). A failed check is reported, not
        raised; a file that cannot be read at all raises."""
        return _json.loads(self._t.verify_json(bool(full)))

    def read(self, window=None):
        """Samples as a float32 array of shape ``(height, width)``, voids NaN, exactly as
        stored: the whole terrain, or ``window`` as ``(col_off, row_off, width, height)`` or
        a rasterio ``Window``. The GIL is released while fmrh reads and decodes."""
        return self._t.read(_window(window))


def open(location):
    """Opens a container file, a dataset directory, or either by URL (``http(s)://``,
    ``s3://``) as a :class:`Terrain`. Raises :class:`IoError` when it cannot be read,
    :class:`CorruptError` or :class:`InputError` when it is not a usable terrain."""
    return Terrain(_fmrh.open(str(location)))
