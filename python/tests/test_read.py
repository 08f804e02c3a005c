"""fmrh.open and Terrain.read: the samples equal `fmrh extract`'s bit for bit (whole, and
windows at every edge and corner, of a container and of a dataset), the georeference follows
rasterio's conventions, the levels carry their measured errors, reads run on several
threads at once, and bad input raises the package's exceptions with the CLI's messages."""
import collections
import concurrent.futures

import numpy as np
import pytest

import fmrh
from conftest import extract


def same(a, b):
    """Equal bit for bit, NaN voids included."""
    assert a.dtype == np.float32 and a.shape == b.shape
    assert np.array_equal(a.view(np.uint32), b.astype(np.float32).view(np.uint32))


def test_whole_container_equals_extract(n43, tmp_path):
    with fmrh.open(n43) as t:
        assert t.shape == (1201, 1201)
        same(t.read(), extract(n43, tmp_path / "all.f32"))


@pytest.mark.parametrize("window", [
    (0, 0, 1, 1), (1200, 1200, 1, 1), (0, 1200, 1201, 1), (1200, 0, 1, 1201),
    (1100, 17, 101, 300), (3, 1150, 640, 51), (600, 600, 65, 65),
])
def test_windows_at_edges_equal_extract(n43, tmp_path, window):
    c, r, w, h = window
    want = extract(n43, tmp_path / "w.f32", f"{c},{r},{c + w - 1},{r + h - 1}")
    with fmrh.open(n43) as t:
        same(t.read(window=window), want)
        # A rasterio Window (anything with col_off, row_off, width, height) reads the same.
        Window = collections.namedtuple("Window", "col_off row_off width height")
        same(t.read(Window(*window)), want)


def test_dataset_equals_extract(dataset, tmp_path):
    with fmrh.open(dataset) as t:
        assert t.shape == (1201, 2401)
        assert t.info()["kind"] == "dataset"
        same(t.read(), extract(dataset, tmp_path / "ds.f32"))
        same(t.read((1150, 500, 100, 20)), extract(dataset, tmp_path / "dw.f32", "1150,500,1249,519"))


def test_georeference_follows_rasterio(n43):
    with fmrh.open(n43) as t:
        assert t.crs == "EPSG:4326"
        a, b, c, d, e, f = t.transform
        step = 1 / 1200
        assert (b, d) == (0.0, 0.0)
        assert a == pytest.approx(step) and e == pytest.approx(-step)
        # Sample (0, 0)'s centre is 6° E, 44° N; the transform maps its cell's corner.
        assert c == pytest.approx(6 - step / 2) and f == pytest.approx(44 + step / 2)
        left, bottom, right, top = t.bounds
        assert (left, bottom, right, top) == pytest.approx((6 - step / 2, 43 - step / 2, 7 + step / 2, 44 + step / 2))
        assert t.res == pytest.approx((step, step))
        assert t.nodata is None
        assert t.vertical_datum == "egm96"


def test_levels_carry_measured_errors(n43):
    with fmrh.open(n43) as t:
        levels = t.levels
        assert levels[0]["threshold"] == 0 and levels[0]["max_error"] == 0
        assert len(levels) > 3
        for lv in levels:
            assert 0 <= lv["max_error"] <= lv["threshold"] + 1e-9 and lv["blocks"] > 0
        thresholds = [lv["threshold"] for lv in levels]
        assert thresholds == sorted(thresholds)


def test_reads_from_several_threads(n43):
    with fmrh.open(n43) as t:
        windows = [(i * 50, i * 40, 300, 200) for i in range(16)]
        alone = [t.read(w) for w in windows]
        with concurrent.futures.ThreadPoolExecutor(4) as pool:
            together = list(pool.map(t.read, windows))
        for a, b in zip(alone, together):
            same(a, b)


def test_bad_input_raises_the_package_exceptions(n43, tmp_path):
    with pytest.raises(fmrh.IoError, match="No such file"):
        fmrh.open(tmp_path / "missing.fmrh")
    junk = tmp_path / "junk.fmrh"
    junk.write_bytes(b"not a container" * 100)
    with pytest.raises(fmrh.FmrhError):
        fmrh.open(junk)
    damaged = tmp_path / "damaged.fmrh"
    raw = bytearray(n43.read_bytes())
    # Inside the payloads (the middle of the file): a block's checksum fails on read.
    middle = len(raw) // 2
    raw[middle:middle + 8] = b"\xff" * 8
    damaged.write_bytes(bytes(raw))
    with pytest.raises(fmrh.CorruptError) as err:
        with fmrh.open(damaged) as t:
            t.read()
    assert err.value.invariant == "I-9"
    assert "corrupt container: I-9 violated" in str(err.value)
    t = fmrh.open(n43)
    with pytest.raises(fmrh.InvalidArgumentError, match="outside the data"):
        t.read((1200, 0, 2, 1))
    with pytest.raises(fmrh.InvalidArgumentError):
        t.read((0, 0, 0, 5))
    with pytest.raises(fmrh.InvalidArgumentError):
        t.read((0, 0, 1.5, 5))
    with pytest.raises(fmrh.InvalidArgumentError):
        t.read("0,0,1,1")
    t.close()
    assert t.closed
    with pytest.raises(fmrh.FmrhError, match="closed"):
        t.read()


def test_verify_reports_as_the_cli(n43, dataset, tmp_path):
    import json
    from conftest import fmrh_cli
    for path in (n43, dataset):
        with fmrh.open(path) as t:
            fast = t.verify()
            full = t.verify(full=True)
        assert fast["valid"] and full["valid"]
        assert (fast["mode"], full["mode"]) == ("fast", "full")
        cli = json.loads(fmrh_cli("verify", "--full", "--json", path))
        assert [c.get("id") for c in full.get("checks", [])] == [c.get("id") for c in cli.get("checks", [])]
    # A damaged payload: reported by its invariant, not raised.
    raw = bytearray(n43.read_bytes())
    middle = len(raw) // 2
    raw[middle:middle + 8] = b"\xff" * 8
    damaged = tmp_path / "damaged.fmrh"
    damaged.write_bytes(bytes(raw))
    with fmrh.open(damaged) as t:
        report = t.verify()
    assert not report["valid"]
    failed = [c["id"] for c in report["checks"] if c["status"] == "failed"]
    assert failed == ["I-9"], failed
