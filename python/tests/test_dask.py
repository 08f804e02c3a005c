"""fmrh.dask.build_dataset on a LocalCluster of two worker processes: into a directory and
into an S3 server (moto), the dataset equals a single-machine `fmrh dataset build` of the
same tiles (every tile file and the manifest byte for byte; read back by `fmrh extract` and
`fmrh scene --json` over the S3 URL, sample for sample); a rebuild in place, in a directory
or on S3, is one manifest commit that removes the old state's files; and a build that fails on a worker (a strict
seam disagreement, found where the tile is built) leaves the old dataset unchanged, byte for
byte, with no file of the failed build left behind."""
import json
import os
import pathlib

import boto3
import numpy as np
import pytest
from dask.distributed import Client, LocalCluster

import fmrh
import fmrh.dask
from conftest import SRTM, extract, fmrh_cli

TILES = [SRTM / "N43E006.hgt.gz", SRTM / "N43E007.hgt.gz"]


@pytest.fixture(scope="module")
def client(s3_env):
    # The S3 environment first: the worker processes inherit it when they start.
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as c:
        assert len(c.scheduler_info()["workers"]) == 2
        yield c


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    out = tmp_path_factory.mktemp("ref") / "ds"
    fmrh_cli("dataset", "build", "-q", "--seam", "mean", *TILES, "-o", out)
    return out


def files(d):
    return {p.name: p.read_bytes() for p in pathlib.Path(d).iterdir()}


def test_into_a_directory_equals_the_cli_byte_for_byte(client, reference, tmp_path):
    heard = []
    out = tmp_path / "ds"
    summary = fmrh.dask.build_dataset([str(t) for t in TILES], out, client, seam="mean",
                                      progress=lambda *a: heard.append(a))
    assert summary["txn_id"] == 1 and len(summary["tiles"]) == 2
    assert files(out) == files(reference)
    assert ("building tiles", 2, 2) in heard and heard[-1] == ("publishing", 1, 1)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".fmrh")]


def test_a_rebuild_in_place_is_one_commit_and_a_failed_one_changes_nothing(client, reference, tmp_path):
    out = tmp_path / "ds"
    fmrh.dask.build_dataset(TILES, out, client, seam="first")
    with fmrh.open(out) as t:
        first_state = t.info()["txn_id"]
    before = files(out)
    # Strict: the real neighbours disagree on their shared edge. The disagreement is found
    # on a worker, building a tile: the build fails, and the old dataset stays as it was.
    with pytest.raises(fmrh.InvalidArgumentError, match="disagree"):
        fmrh.dask.build_dataset(TILES, out, client, seam="strict")
    assert files(out) == before
    with fmrh.open(out) as t:
        assert t.info()["txn_id"] == first_state and t.verify(full=True)["valid"]
    # A rebuild that succeeds: the next manifest state; the old tile files removed.
    summary = fmrh.dask.build_dataset(TILES, out, client, seam="mean")
    assert summary["txn_id"] == first_state + 1
    assert sorted(summary["superseded"]) == sorted(n for n in before if n != "MANIFEST")
    assert set(files(out)) == {"MANIFEST"} | {t["name"] for t in summary["tiles"]}
    with fmrh.open(out) as t, fmrh.open(reference) as r:
        assert t.verify(full=True)["valid"]
        assert np.array_equal(t.read().view(np.uint32), r.read().view(np.uint32))


def test_into_s3_reads_back_as_the_cli_build(client, reference, tmp_path, s3_env):
    s3 = boto3.client("s3")
    s3.create_bucket(Bucket="dem")
    url = "s3://dem/n43/"
    summary = fmrh.dask.build_dataset(TILES, url, client, seam="mean")
    keys = sorted(o["Key"] for o in s3.list_objects_v2(Bucket="dem")["Contents"])
    assert keys == sorted("n43/" + n for n in files(reference))
    for n, data in files(reference).items():
        assert s3.get_object(Bucket="dem", Key="n43/" + n)["Body"].read() == data, n
    assert summary["manifest_bytes"] == len(files(reference)["MANIFEST"])
    # Read back over the URL by the command line: samples and scenes as the local build's.
    same = lambda a, b: np.array_equal(a.view(np.uint32), b.view(np.uint32))
    window = "1100,200,1300,700"
    assert same(extract(url, tmp_path / "s3.f32", window), extract(reference, tmp_path / "local.f32", window))
    camera = ["--eye", "100000,-20000,9000", "--target", "100000,60000,0", "--tau", "2", "--json"]
    remote = json.loads(fmrh_cli("scene", url, *camera))
    local = json.loads(fmrh_cli("scene", reference, *camera))
    assert remote["blocks"] and remote["blocks"] == local["blocks"]
    with fmrh.open(url) as t, fmrh.open(reference) as r:
        assert same(t.read(), r.read())
    # A rebuild in place on S3: the manifest's next state, put last; the old objects removed.
    first = tmp_path / "first"
    fmrh_cli("dataset", "build", "-q", "--seam", "first", *TILES, "-o", first)
    again = fmrh.dask.build_dataset(TILES, url, client, seam="first")
    assert again["txn_id"] == 2
    assert sorted(again["superseded"]) == sorted(n for n in files(reference) if n != "MANIFEST")
    keys = sorted(o["Key"] for o in s3.list_objects_v2(Bucket="dem")["Contents"])
    assert keys == sorted(["n43/MANIFEST"] + ["n43/" + t["name"] for t in again["tiles"]])
    with fmrh.open(url) as t, fmrh.open(first) as r:
        assert t.info()["txn_id"] == 2
        assert same(t.read(), r.read())
