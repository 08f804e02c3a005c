"""Datasets: a directory of tile containers placed by a manifest, as ``fmrh dataset build``
and ``fmrh dataset add`` make them. A dataset opens with :func:`fmrh.open` like a container."""

import json as _json
import os as _os

from . import _fmrh
from ._fmrh import InvalidArgumentError

__all__ = ["build", "add"]


def _tiles(tiles):
    """``[(path, (col0, row0) | None)]`` from paths, ``(path, col0, row0)`` tuples, or a
    layout CSV's path (``path,col0,row0`` a line, paths relative to the file)."""
    if isinstance(tiles, (str, _os.PathLike)) and str(tiles).endswith(".csv"):
        base = _os.path.dirname(_os.path.abspath(tiles))
        out = []
        with open(tiles, encoding="utf-8") as f:
            for n, line in enumerate(f, 1):
                line = line.strip()
                if not line or line.startswith("#"):
                    continue
                parts = [p.strip() for p in line.split(",")]
                if len(parts) != 3:
                    raise InvalidArgumentError(f"{tiles}: line {n}: expected path,col0,row0")
                try:
                    at = (int(parts[1]), int(parts[2]))
                except ValueError:
                    raise InvalidArgumentError(f"{tiles}: line {n}: col0 and row0 must be whole numbers") from None
                out.append((_os.path.join(base, parts[0]), at))
        return out
    if isinstance(tiles, (str, _os.PathLike)):
        raise InvalidArgumentError(f"tiles {tiles!r}: expected a list of tiles or a layout .csv")
    out = []
    for t in tiles:
        if isinstance(t, (str, _os.PathLike)):
            out.append((str(t), None))
        else:
            parts = tuple(t)
            if len(parts) != 3:
                raise InvalidArgumentError(f"tile {t!r}: expected a path or (path, col0, row0)")
            out.append((str(parts[0]), (int(parts[1]), int(parts[2]))))
    return out


def build(tiles, out, *, seam="strict", tile_size=None, progress=None, **options):
    """Builds the dataset ``out`` (a new directory) from ``tiles``: paths placed by their
    georeferences, ``(path, col0, row0)`` tuples (a layout: each tile's first sample in the
    dataset's grid), or the path of a layout CSV as ``fmrh dataset build --layout`` reads.
    Shared edges must agree unless ``seam`` is ``"first"`` or ``"mean"``; ``tile_size``
    cuts larger DEMs into tiles. ``options`` are :func:`fmrh.build`'s. The manifest is
    published last: ``out`` appears complete or not at all. Returns the summary
    (``tiles``, ``columns``, ``rows``, ``shared_edges``, ``manifest_bytes``,
    ``total_bytes``). ``progress(phase, done, total)`` hears each phase."""
    opts = {k: v for k, v in options.items() if v is not None}
    return _json.loads(_fmrh.dataset_build(_tiles(tiles), str(out), opts, seam,
                                           tile_size, progress))


def add(dataset, src, *, at=None, replace=False, seam=None, progress=None, **options):
    """Adds the DEM ``src`` to ``dataset`` as a new tile, at ``at = (col0, row0)`` or by its
    georeference, or (``replace``) replaces the tile of its place and size, in one manifest
    commit. ``seam`` defaults to the policy the dataset was built with. Returns
    ``{"commit": {"txn_id", "tiles"}, "shift": (cols, rows)}``: ``shift`` is how far the
    grid's origin moved when the tile lies west or north of it."""
    opts = {k: v for k, v in options.items() if v is not None}
    if at is not None:
        at = (int(at[0]), int(at[1]))
    return _json.loads(_fmrh.dataset_add(str(dataset), str(src), at, opts, seam,
                                         bool(replace), progress))
