"""A dataset built on a Dask cluster: one container per tile, built on the workers, put at
the destination, and published by one manifest written last (``docs/distributed-build.md``).

::

    from dask.distributed import Client
    import fmrh.dask

    client = Client("scheduler:8786")            # or a LocalCluster
    fmrh.dask.build_dataset("layout.csv", "s3://dem/srtm1/", client, seam="first")

The phases (``fmrh::distributed`` in the Rust crate):

1. **Scan** (workers, one task a tile): each DEM read once for its size, georeference and
   border lines. The scans stay on the workers; the client gathers their descriptions only
   (a few hundred bytes each).
2. **Plan** (the client): every tile's place, file name and shared edges. Nothing is read.
3. **Build** (workers, one task a tile): the tile's own scan and its neighbours' (Dask
   moves them between workers) settle its shared edges; the container is built into the
   worker's temporary directory, then put at the destination: moved into the directory, or
   uploaded to S3 under the dataset's prefix.
4. **Publish** (the client), once every tile is in: the adjacent-cluster tables from the
   tiles' edge lists, and the manifest, put last. It is the commit point: before it the
   destination's old dataset (if any) is what every reader sees, unchanged; after it the
   new one. Files of the old state that the new one does not name are removed last.

A failure anywhere (a worker dying, a bad tile, a strict seam disagreement) raises here
after the files already put for the new state are removed; the old dataset stays readable
and unchanged. The result equals ``fmrh dataset build`` of the same tiles, byte for byte.
"""

import json as _json
import os as _os
import shutil as _shutil
import tempfile as _tempfile

from . import _fmrh
from ._fmrh import InvalidArgumentError
from .dataset import _tiles

__all__ = ["build_dataset"]


class _Destination:
    """Where a dataset goes: a directory (every worker must see it: one machine, or a shared
    file system), or ``s3://bucket/prefix/`` (credentials and ``AWS_ENDPOINT_URL`` from the
    environment, on the client and the workers alike)."""

    def __init__(self, out):
        out = str(out)
        self.s3 = out.startswith("s3://")
        if self.s3:
            rest = out[len("s3://"):]
            bucket, _, prefix = rest.partition("/")
            if not bucket:
                raise InvalidArgumentError(f"{out}: an S3 destination is s3://bucket/prefix/")
            self.bucket = bucket
            self.prefix = prefix.strip("/") + "/" if prefix.strip("/") else ""
            self.url = f"s3://{bucket}/{self.prefix}"
        else:
            self.path = _os.path.abspath(out)
            self.url = self.path

    def spec(self):
        """What a worker needs to put a file here (picklable)."""
        if self.s3:
            return ("s3", self.bucket, self.prefix)
        return ("dir", self.staging, None)

    def exists(self):
        """Whether a dataset is there now (its manifest)."""
        if self.s3:
            try:
                _s3().head_object(Bucket=self.bucket, Key=self.prefix + "MANIFEST")
                return True
            except _s3().exceptions.ClientError:
                return False
        return _os.path.exists(_os.path.join(self.path, "MANIFEST"))

    def prepare(self, replace):
        """Where the workers put tiles: the dataset's directory itself when it exists (new
        names, unseen until the manifest names them), else a staging directory beside it,
        renamed into place once published."""
        if self.s3:
            return
        if replace:
            self.staging = self.path
        else:
            if _os.path.exists(self.path):
                raise InvalidArgumentError(f"{self.path} exists and is not an fmrh dataset")
            parent = _os.path.dirname(self.path) or "."
            self.staging = _tempfile.mkdtemp(prefix=".fmrh-dataset-", dir=parent)

    def remove(self, names):
        """Removes the files `names` (those put for a state that was not published, or an
        old state's no longer named)."""
        for name in names:
            if self.s3:
                _s3().delete_object(Bucket=self.bucket, Key=self.prefix + name)
            else:
                try:
                    _os.remove(_os.path.join(self.staging, name))
                except FileNotFoundError:
                    pass

    def publish(self, plan, replace):
        """Writes the manifest and returns what was published. The commit point is here
        for S3 (the manifest's PUT) and for a dataset replaced in place (its manifest's
        commit); a new directory is committed by :meth:`finish`."""
        if not self.s3:
            manifest = _os.path.join(self.staging, "MANIFEST")
            out = _json.loads(_fmrh.distributed_publish(plan, self.staging, manifest, replace))
            if not replace:
                _fsync_dir(self.staging)
            return out
        with _tempfile.TemporaryDirectory(prefix="fmrh-manifest-") as tmp:
            manifest = _os.path.join(tmp, "MANIFEST")
            if replace:
                _s3().download_file(self.bucket, self.prefix + "MANIFEST", manifest)
            out = _json.loads(_fmrh.distributed_publish(plan, self.url, manifest, replace))
            # One PUT: S3 replaces an object whole, so readers see the old manifest or the new.
            _s3().upload_file(manifest, self.bucket, self.prefix + "MANIFEST")
        return out


    def finish(self, replace):
        """A new directory's commit point: the staging directory renamed to the dataset's
        name, complete."""
        if not self.s3 and not replace:
            _os.rename(self.staging, self.path)
            _fsync_dir(_os.path.dirname(self.path) or ".")


def _fsync_dir(path):
    fd = _os.open(path, _os.O_RDONLY)
    try:
        _os.fsync(fd)
    finally:
        _os.close(fd)


def _s3():
    import boto3

    return boto3.client("s3")


def _scan(path, options):
    return _fmrh.distributed_scan(path, options)


def _description(scan):
    return scan[1]


def _build_and_put(plan, index, path, scans, options, spec):
    """On a worker: builds tile `index` into a temporary file, then puts it at the
    destination under its planned name. Returns what the build reported."""
    name = _json.loads(plan)["files"][index]
    scans = {k: v[0] for k, v in scans.items()}
    with _tempfile.TemporaryDirectory(prefix="fmrh-tile-") as tmp:
        local = _os.path.join(tmp, name)
        built = _json.loads(_fmrh.distributed_build_tile(plan, index, path, scans, local, options))
        kind, where, prefix = spec
        if kind == "s3":
            _s3().upload_file(local, where, prefix + name)
        else:
            target = _os.path.join(where, name)
            # A temporary name, then a rename: the planned name is whole or absent.
            part = target + ".part"
            _shutil.copyfile(local, part)
            with open(part, "rb+") as f:
                _os.fsync(f.fileno())
            _os.replace(part, target)
    built["name"] = name
    return built


def build_dataset(tiles, out, client=None, *, seam="strict", progress=None, **build_options):
    """Builds the dataset of ``tiles`` at ``out`` on the Dask cluster of ``client`` (the
    default client when ``None``): one container a tile, built on the workers.

    ``tiles`` is a layout CSV (``path,col0,row0`` a line, as ``fmrh dataset build --layout``
    reads), a list of ``(path, col0, row0)``, or a list of paths placed by their
    georeferences. Every path must be readable by every worker. ``out`` is a directory
    (seen by every worker) or ``s3://bucket/prefix/``. An existing dataset there is
    replaced by one manifest commit: its readers see the old dataset or the new. ``seam``
    and ``build_options`` are :func:`fmrh.dataset.build`'s. ``progress(phase, done,
    total)`` hears the tiles scanned and built.

    Returns the summary: ``tiles`` (each ``name``, ``file_length``,
    ``seam_samples_changed``), ``manifest_bytes``, ``txn_id``, ``superseded`` (the old
    state's files, removed)."""
    from dask.distributed import as_completed, get_client

    client = client or get_client()
    # Absolute paths: a worker's working directory need not be this one.
    inputs = [(_os.path.abspath(p), at) for p, at in _tiles(tiles)]
    if not inputs:
        raise InvalidArgumentError("a dataset needs at least one tile")
    options = {k: v for k, v in build_options.items() if v is not None}
    dest = _Destination(out)
    replace = dest.exists()
    taken = _fmrh.tile_files(dest.url if dest.s3 else dest.path) if replace else []
    tell = progress or (lambda *a: None)

    # 1. Scan, on the workers; only the descriptions come back.
    scans = client.map(_scan, [str(p) for p, _ in inputs], options=options, pure=False)
    descriptions = []
    for i, d in enumerate(client.gather(client.map(_description, scans, pure=False))):
        descriptions.append(d)
        tell("scanning tiles", i + 1, len(inputs))
    # 2. Plan, here.
    plan = _fmrh.distributed_plan([(str(p), at, d) for (p, at), d in zip(inputs, descriptions)],
                                  options, seam, taken)
    planned = _json.loads(plan)
    shared, files = planned["shared"], planned["files"]
    dest.prepare(replace)
    # 3. Build, on the workers, each tile with its neighbours' scans.
    builds = []
    for i, (path, _) in enumerate(inputs):
        needed = {i} | {b if a == i else a for a, b, _ in shared if i in (a, b)}
        builds.append(client.submit(_build_and_put, plan, i, str(path),
                                    {k: scans[k] for k in needed}, options, dest.spec(),
                                    pure=False))
    built = [None] * len(builds)
    index = {f.key: i for i, f in enumerate(builds)}
    try:
        for n, future in enumerate(as_completed(builds), 1):
            built[index[future.key]] = future.result()
            tell("building tiles", n, len(builds))
        # 4. Publish: the manifest, last.
        tell("publishing", 0, 1)
        published = dest.publish(plan, replace)
    except BaseException:
        client.cancel(builds)
        dest.remove(files)
        if not dest.s3 and not replace:
            _shutil.rmtree(dest.staging, ignore_errors=True)
        raise
    finally:
        client.cancel(scans)
    dest.finish(replace)
    dest.remove(published["superseded"])
    tell("publishing", 1, 1)
    return {"tiles": built, **published}
