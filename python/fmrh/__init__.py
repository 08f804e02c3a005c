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

import builtins as _builtins
import json as _json
import os as _os
import operator as _operator
from typing import NamedTuple as _NamedTuple

from . import _fmrh, dataset
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
    "Overview",
    "Edit",
    "build",
    "dataset",
    "FmrhError",
    "CorruptError",
    "BusyError",
    "InputError",
    "IoError",
    "InvalidArgumentError",
    "format_version",
]


class Overview(_NamedTuple):
    """A window of the surface at an error level's own resolution (:meth:`Terrain.read_overview`)."""

    heights: "object"
    """float32 array ``(rows, columns)``: every ``stride``-th sample of the window."""
    stride: int
    """Samples of the terrain between two of its points."""
    max_error: float
    """The largest measured error of the blocks drawn, in height units."""
    transform: "tuple | None"
    """The affine 6-tuple of the strided grid, or ``None`` without a georeference."""


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


def _cameras(path, n):
    """The cameras of a path: ``n`` = 6, ``((ex, ey, ez), (tx, ty, tz))`` pairs; ``n`` = 5,
    ``(lat, lon, height, heading, pitch)``; from a list or a CSV of ``n`` numbers a line."""
    if isinstance(path, (str, _os.PathLike)):
        rows = []
        # `open` here is fmrh.open.
        with _builtins.open(path, encoding="utf-8") as f:
            for k, line in enumerate(f, 1):
                line = line.strip()
                if not line or line.startswith("#"):
                    continue
                try:
                    v = [float(p) for p in line.split(",")]
                except ValueError:
                    if k == 1:
                        continue  # the header
                    raise InvalidArgumentError(f"{path}: line {k}: expected {n} numbers") from None
                if len(v) != n:
                    raise InvalidArgumentError(f"{path}: line {k}: expected {n} numbers, got {len(v)}")
                rows.append(v)
    else:
        try:
            rows = list(path)
        except TypeError:
            raise InvalidArgumentError(f"path {path!r}: expected a list of cameras or a CSV file") from None
    if n == 5:
        return [_pose(r) for r in rows]
    out = []
    for p in rows:
        if isinstance(p, list) and len(p) == 6:
            p = (p[:3], p[3:])
        try:
            eye, target = p
        except (TypeError, ValueError):
            raise InvalidArgumentError(f"camera {p!r}: expected (eye, target)") from None
        out.append((_point(eye, "eye"), _point(target, "target")))
    return out


def _pose(p):
    """``(lat, lon, height, heading, pitch)`` floats."""
    try:
        pose = tuple(float(v) for v in p)
    except (TypeError, ValueError):
        pose = ()
    if len(pose) != 5:
        raise InvalidArgumentError(f"camera {p!r}: expected (lat, lon, height, heading, pitch)")
    return pose


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

    def edit(self):
        """Starts an edit (a local container or dataset): use it as ``with t.edit() as txn:
        txn.replace(col, row, heights)``. Every replacement is written in one commit when
        the block ends, or none if it raises (see :class:`Edit`). After the commit this
        terrain reads the new state."""
        return Edit(self, self._t.edit())

    def _reopen(self):
        """Reads the terrain's latest state from now on (after this process committed)."""
        fresh = _fmrh.open(self._t.location)
        old, self._t = self._t, fresh
        self._info = _json.loads(fresh.info_json())
        old.close()

    def scene_geo(self, lat, lon, height, heading=0.0, pitch=-30.0, tau=1.0, *, fov=None,
                  viewport=None, mode="view"):
        """The blocks a camera on the globe needs, as ``fmrh scene --eye-geo`` gives them:
        at ``lat``, ``lon`` (degrees), ``height`` metres above the WGS 84 ellipsoid, looking
        along ``heading`` (degrees clockwise from north) and ``pitch`` (degrees above the
        horizontal, negative looking down). The data must be on a geographic grid. Blocks
        are dicts as :meth:`scene` gives them."""
        pose = _pose((lat, lon, height, heading, pitch))
        return self._t.scene_geo(*pose, float(tau), None if fov is None else float(fov),
                                 None if viewport is None else tuple(map(int, viewport)), mode)

    def fly(self, path, tau=1.0, *, geo=False, fov=None, viewport=None, mode="view"):
        """Flies a camera along ``path`` and yields one frame a camera, as ``fmrh fly``
        replays a path: each frame's scene is :meth:`scene`'s for that camera, but only the
        blocks that entered the view are read and decoded; the others are the arrays given
        before. ``path`` is a list of ``(eye, target)`` pairs or the path of a CSV with one
        camera a line, ``eye_x,eye_y,eye_z,target_x,target_y,target_z`` (a header line is
        skipped), as ``fmrh fly --path`` reads. With ``geo``, the cameras are on the globe:
        ``(lat, lon, height, heading, pitch)`` tuples or such a CSV (``fmrh fly --geo``), as
        :meth:`scene_geo` takes one. The next frame is prepared on a thread of its own while
        the caller works on this one.

        Each frame is a dict: ``index``; ``blocks``, the scene's blocks (dicts as
        :meth:`scene` gives), in scene order; ``loaded``, those that entered the view;
        ``evicted``, the keys ``(tile, level, x, y)`` of the last frame's blocks that left
        it; ``keys``, every block's key in order; ``max_screen_error`` (pixels) and
        ``schedule_ns``."""
        cameras = _cameras(path, 5 if geo else 6)
        fly = self._t.fly_geo if geo else self._t.fly
        flight = fly(cameras, float(tau), None if fov is None else float(fov),
                     None if viewport is None else tuple(map(int, viewport)), mode)
        held = {}
        try:
            for frame in flight:
                for key, block in frame["loaded"]:
                    held[key] = block
                for key in frame["evicted"]:
                    held.pop(key, None)
                frame["loaded"] = [block for _, block in frame["loaded"]]
                frame["blocks"] = [held[k] for k in frame["keys"]]
                yield frame
        finally:
            flight.close()

    def verify(self, full=False):
        """Checks every numbered invariant of the format (``full``: also recomputes every
        error from the blocks, and every cut and adjacency) and returns the report as a dict,
        as ``fmrh verify --json`` prints it: ``valid``, and one entry per invariant in
        ``checks`` (a dataset's: its own and each tile's). A failed check is reported, not
        raised; a file that cannot be read at all raises."""
        return _json.loads(self._t.verify_json(bool(full)))

    def read(self, window=None, *, max_error=None, level=None):
        """Samples as a float32 array of shape ``(height, width)``: the whole terrain, or
        ``window`` as ``(col_off, row_off, width, height)`` or a rasterio ``Window``.

        Without ``max_error`` (or ``level``) the samples are exactly as stored, voids NaN.
        With ``max_error`` (height units), the surface the coarsest error level within it
        draws, evaluated at every sample of the window (upsampled by the triangulation the
        errors were measured with): every real sample within ``max_error`` of its stored
        height (plus the rounding to float32), voids filled with the surface's height,
        samples no tile covers NaN. ``level`` (an index into :attr:`levels`) reads that
        level. :meth:`read_overview` gives the same surface at the level's own resolution.
        The GIL is released while fmrh reads and decodes."""
        bound = self._bound(max_error, level)
        if bound is None:
            return self._t.read(_window(window))
        heights, _, _ = self._t.read_within(_window(window), bound, False)
        return heights

    def read_overview(self, window=None, *, max_error=None, level=None):
        """The surface :meth:`read` gives with ``max_error`` (or ``level``), at the level's
        own resolution: every ``stride``-th sample of the window along rows and columns
        from its north-west sample, ``stride`` being the finest among the blocks drawn (so
        no detail they hold is lost). Returns an :class:`Overview` ``(heights, stride,
        max_error, transform)``: ``max_error`` the largest measured error of those blocks
        (at most the bound), ``transform`` the affine of the strided grid (``None`` without
        a georeference)."""
        bound = self._bound(max_error, level)
        if bound is None:
            raise InvalidArgumentError("read_overview needs max_error or level")
        win = _window(window)
        heights, error, stride = self._t.read_within(win, bound, True)
        col, row = (win[0], win[1]) if win else (0, 0)
        transform = None
        t = self.transform
        if t is not None:
            a, _, c, _, e, f = t
            # Sample (col, row)'s centre, less half a strided cell.
            cx, cy = c + a * (col + 0.5), f + e * (row + 0.5)
            sa, se = a * stride, e * stride
            transform = (sa, 0.0, cx - sa / 2.0, 0.0, se, cy - se / 2.0)
        return Overview(heights, stride, error, transform)

    def _bound(self, max_error, level):
        """The error bound ``read`` and ``read_overview`` cut at, or ``None`` for exact."""
        if max_error is not None and level is not None:
            raise InvalidArgumentError("give max_error or level, not both")
        if level is not None:
            levels = self._info["error_levels"]
            try:
                i = None if isinstance(level, bool) else _operator.index(level)
            except TypeError:
                i = None
            if i is None or not 0 <= i < len(levels):
                raise InvalidArgumentError(
                    f"level {level!r}: expected a whole number from 0 to {len(levels) - 1}"
                )
            return float(levels[i]["threshold"])
        if max_error is None:
            return None
        try:
            bound = float(max_error)
        except (TypeError, ValueError):
            raise InvalidArgumentError(f"max_error {max_error!r}: expected a number >= 0") from None
        if not bound >= 0.0:
            raise InvalidArgumentError(f"max_error {max_error!r}: expected a number >= 0")
        return bound


class Edit:
    """Replacements of a terrain's samples, committed atomically (:meth:`Terrain.edit`).

    Nothing is written before :meth:`commit`: :meth:`rollback`, an exception in the ``with``
    block, or dropping the edit leaves the terrain as it was. A crash during the commit
    leaves the old state or the new one, never a mix. While a container's edit lives it
    holds the file's writer lock: a second writer, in any process, is refused (raises).
    Readers go on reading the state they opened."""

    def __init__(self, terrain, inner):
        self._terrain = terrain
        self._e = inner
        self.committed = None

    def __enter__(self):
        return self

    def __exit__(self, kind, value, traceback):
        if self._e.ended_:
            return False
        if kind is None:
            self.commit()
        else:
            self.rollback()
        return False

    def replace(self, col, row, heights):
        """Replaces samples with ``heights`` (a 2-D float32 array, ``(rows, columns)``; NaN
        makes a void), its north-west sample at ``(col, row)``. The patch must lie inside
        the data; where patches overlap the later wins."""
        self._e.replace(int(col), int(row), heights)

    def commit(self):
        """Writes every replacement in one commit (durable when it returns) and returns what
        it did: ``txn_id`` (the new state), ``files``, ``blocks``, ``grids``."""
        self.committed = _json.loads(self._e.commit())
        self._terrain._reopen()
        return self.committed

    def rollback(self):
        """Drops every replacement; nothing is written."""
        self._e.rollback()


def _options(options):
    """The build options as the extension takes them: a dict, ``None`` values dropped."""
    return {k: v for k, v in options.items() if v is not None}


def build(src, out, *, overwrite=False, progress=None, **options):
    """Builds the container ``out`` from the DEM ``src`` (GeoTIFF, SRTM ``.hgt``, PNG, ASCII
    grids, DTED, USGS DEM, JPEG, or ``.f32`` + ``.json``), as ``fmrh build`` does, written
    so that it appears complete or not at all. Returns what was made (``file_length``,
    ``page_size``, ``max_error``, ``error_levels``).

    ``options`` are ``fmrh build``'s flags, ``-`` written ``_``: how to read (``format``,
    ``color_encoding``, ``z_scale``, ``z_offset``, ``nodata``, ``tile``, ``max_memory`` in
    bytes, ``max_samples_per_byte``, ``vertical_datum``, ``spacing`` in metres as DX or
    (DX, DY)) and how to build (``block_size``, ``thresholds`` (a list), ``precision``,
    ``page_size``, ``payloads_alone``, ``no_thin``). ``overwrite`` replaces an existing
    file (atomically). ``progress(phase, done, total)`` is called as each phase starts,
    advances (at most ten times a second) and ends; an exception it raises is raised when
    the build returns. The GIL is released while fmrh builds."""
    return _json.loads(_fmrh.build(str(src), str(out), _options(options), progress, bool(overwrite)))


def open(location):
    """Opens a container file, a dataset directory, or either by URL (``http(s)://``,
    ``s3://``) as a :class:`Terrain`. Raises :class:`IoError` when it cannot be read,
    :class:`CorruptError` or :class:`InputError` when it is not a usable terrain."""
    return Terrain(_fmrh.open(str(location)))
