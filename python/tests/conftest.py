"""Fixtures for the fmrh Python package's tests: containers and a dataset built by the fmrh
command line (FMRH_BIN, default the repository's target/release/fmrh) from the bundled DEMs,
and `fmrh extract` read back as the reference."""
import json
import os
import pathlib
import subprocess

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
BIN = os.environ.get("FMRH_BIN", str(ROOT / "target" / "release" / "fmrh"))
SRTM = ROOT / "data" / "srtm3-pyhgtmap"


def fmrh_cli(*args):
    if not os.path.exists(BIN):
        pytest.fail(f"the fmrh binary is missing at {BIN}: `cargo build --release` (or set FMRH_BIN)")
    run = subprocess.run([BIN, *map(str, args)], capture_output=True, text=True)
    if run.returncode != 0:
        raise AssertionError(f"fmrh {' '.join(map(str, args))} failed: {run.stderr}")
    return run.stdout


def extract(path, out, window=None):
    """`fmrh extract` of `window` ("c0,r0,c1,r1", inclusive) as a float32 array."""
    args = ["extract", "-q", path, "-o", out]
    if window:
        args += ["--window", window]
    fmrh_cli(*args)
    meta = json.loads(pathlib.Path(str(out).replace(".f32", ".json")).read_text())
    return np.fromfile(out, dtype="<f4").reshape(meta["height"], meta["width"])


@pytest.fixture(scope="session")
def n43(tmp_path_factory):
    d = tmp_path_factory.mktemp("n43")
    out = d / "n43e006.fmrh"
    fmrh_cli("build", "-q", SRTM / "N43E006.hgt.gz", "-o", out)
    return out


@pytest.fixture(scope="session")
def dataset(tmp_path_factory):
    d = tmp_path_factory.mktemp("ds")
    out = d / "n43"
    fmrh_cli("dataset", "build", "-q", "--seam", "first",
             SRTM / "N43E006.hgt.gz", SRTM / "N43E007.hgt.gz", "-o", out)
    return out


@pytest.fixture(scope="session")
def puget(tmp_path_factory):
    """Puget Sound 1k as the README builds it."""
    d = tmp_path_factory.mktemp("ps1k")
    out = d / "ps1k.fmrh"
    png = ROOT / "data" / "puget-sound-1k" / "ps_height_1k.png"
    fmrh_cli("build", "-q", png, "--z-scale", "0.1", "--spacing", "160", "-o", out)
    return out


class RangeHandler(__import__("http.server").server.BaseHTTPRequestHandler):
    """Serves files of `self.server.root` as an object store does: `Range` (one range, a
    suffix, or several as multipart/byteranges), an ETag from the file's size and mtime, and
    `If-Match` answered 412 when the file changed."""

    def log_message(self, *args):
        pass

    def _file(self):
        path = pathlib.Path(self.server.root) / self.path.lstrip("/").split("?")[0]
        if not path.is_file():
            self.send_error(404)
            return None, None
        st = path.stat()
        return path, f'"{st.st_size:x}-{st.st_mtime_ns:x}"'

    def do_HEAD(self):
        path, etag = self._file()
        if path:
            self.send_response(200)
            self.send_header("Content-Length", str(path.stat().st_size))
            self.send_header("ETag", etag)
            self.send_header("Accept-Ranges", "bytes")
            self.end_headers()

    def do_GET(self):
        path, etag = self._file()
        if not path:
            return
        if self.headers.get("If-Match") not in (None, etag):
            self.send_error(412)
            return
        data = path.read_bytes()
        n = len(data)
        spec = self.headers.get("Range", "")
        if not spec.startswith("bytes="):
            self.send_response(200)
            self.send_header("Content-Length", str(n))
            self.send_header("ETag", etag)
            self.end_headers()
            self.wfile.write(data)
            return
        spans = []
        for part in spec[len("bytes="):].split(","):
            a, b = part.strip().split("-")
            if a == "":
                start, end = max(0, n - int(b)), n - 1
            else:
                start, end = int(a), min(n - 1, int(b)) if b else n - 1
            if start >= n or start > end:
                continue
            spans.append((start, end))
        if not spans:
            self.send_response(416)
            self.send_header("Content-Range", f"bytes */{n}")
            self.end_headers()
            return
        self.send_response(206)
        self.send_header("ETag", etag)
        if len(spans) == 1:
            start, end = spans[0]
            self.send_header("Content-Range", f"bytes {start}-{end}/{n}")
            self.send_header("Content-Length", str(end - start + 1))
            self.end_headers()
            self.wfile.write(data[start:end + 1])
            return
        boundary = "fmrhtestboundary"
        body = b"".join(
            f"--{boundary}\r\nContent-Type: application/octet-stream\r\n"
            f"Content-Range: bytes {s}-{e}/{n}\r\n\r\n".encode() + data[s:e + 1] + b"\r\n"
            for s, e in spans
        ) + f"--{boundary}--\r\n".encode()
        self.send_header("Content-Type", f"multipart/byteranges; boundary={boundary}")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)


@pytest.fixture(scope="session")
def http_root(tmp_path_factory):
    """`(directory, base URL)`: files put in the directory are served with byte ranges."""
    import http.server
    import threading

    root = tmp_path_factory.mktemp("www")
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), RangeHandler)
    server.root = str(root)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield root, f"http://127.0.0.1:{server.server_address[1]}"
    server.shutdown()


@pytest.fixture(scope="session")
def s3_env():
    """An S3 server (moto) on a free port, its address and test credentials in this
    process's environment, which Dask's worker processes inherit: fmrh's S3 reader and boto3
    both read AWS_ENDPOINT_URL."""
    import socket
    import sys
    import time

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    server = subprocess.Popen([sys.executable, "-m", "moto.server", "-H", "127.0.0.1", "-p", str(port)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 30
    while True:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            break
        except OSError:
            if server.poll() is not None or time.time() > deadline:
                server.kill()
                pytest.fail("moto's S3 server did not start (pip install 'moto[server]')")
            time.sleep(0.1)
    env = {
        "AWS_ENDPOINT_URL": f"http://127.0.0.1:{port}",
        "AWS_ACCESS_KEY_ID": "test",
        "AWS_SECRET_ACCESS_KEY": "test",
        "AWS_REGION": "us-east-1",
        "AWS_DEFAULT_REGION": "us-east-1",
    }
    saved = {k: os.environ.get(k) for k in env}
    os.environ.update(env)
    yield env
    for k, v in saved.items():
        if v is None:
            os.environ.pop(k, None)
        else:
            os.environ[k] = v
    server.kill()
    server.wait()
