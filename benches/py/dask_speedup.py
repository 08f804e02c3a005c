"""The distributed build's speed-up (issue 43): Puget Sound 4k (4096², ../shared/data) cut
into 16 tiles of 1025² that share their edges, built into a dataset by `fmrh dataset build
--layout` (one process) and by fmrh.dask.build_dataset on a LocalCluster of 1 and of 2
worker processes, side by side in one run, each result checked byte for byte against the
first. Each worker has one thread; RAYON_NUM_THREADS sets the threads fmrh itself uses per
tile build (1: the scaling of the cluster alone; unset: fmrh's own parallelism as well).

    python3 benches/py/dask_speedup.py [--fmrh target/release/fmrh] [--rounds 3]

Prints a table: seconds (median of the rounds) and the speed-up over one worker."""
import argparse
import json
import os
import pathlib
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[2]
SRC = ROOT.parent / "shared" / "data" / "puget-sound-4k-jpg" / "ps_height_4k_jpg.f32"


def files(d):
    return {p.name: p.read_bytes() for p in pathlib.Path(d).iterdir()}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--fmrh", default=str(ROOT / "target" / "release" / "fmrh"))
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    if not SRC.exists():
        sys.exit(f"{SRC} is missing: the bench needs ../shared/data")
    from dask.distributed import Client, LocalCluster

    import fmrh.dask

    work = pathlib.Path(tempfile.mkdtemp(prefix="fmrh-dask-bench-"))
    try:
        import numpy as np

        dem = np.fromfile(SRC, dtype="<f4").reshape(4096, 4096)
        spans = [(0, 1024), (1024, 2048), (2048, 3072), (3072, 4095)]
        layout = []
        for r0, r1 in spans:
            for c0, c1 in spans:
                out = work / f"t_{r0}_{c0}.f32"
                dem[r0:r1 + 1, c0:c1 + 1].astype("<f4").tofile(out)
                out.with_suffix(".json").write_text(json.dumps(
                    {"width": c1 - c0 + 1, "height": r1 - r0 + 1, "spacing_m": [40.0, 40.0]}))
                layout.append(f"{out.name},{c0},{r0}")
        (work / "layout.csv").write_text("\n".join(layout) + "\n")
        rows = []
        for threads in ["1", None]:
            env = dict(os.environ)
            if threads:
                env["RAYON_NUM_THREADS"] = threads
                os.environ["RAYON_NUM_THREADS"] = threads
            else:
                env.pop("RAYON_NUM_THREADS", None)
                os.environ.pop("RAYON_NUM_THREADS", None)
            label = f"RAYON_NUM_THREADS={threads or 'unset'}"
            times = {}
            ref = work / "ref"
            t = []
            for _ in range(args.rounds):
                shutil.rmtree(ref, ignore_errors=True)
                start = time.perf_counter()
                subprocess.run([args.fmrh, "dataset", "build", "-q", "--layout", str(work / "layout.csv"),
                                "-o", str(ref)], check=True, env=env)
                t.append(time.perf_counter() - start)
            times["fmrh dataset build (one process)"] = statistics.median(t)
            want = files(ref)
            for workers in [1, 2]:
                with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, Client(cluster) as client:
                    t = []
                    for _ in range(args.rounds):
                        out = work / f"dask{workers}"
                        shutil.rmtree(out, ignore_errors=True)
                        start = time.perf_counter()
                        fmrh.dask.build_dataset(work / "layout.csv", out, client)
                        t.append(time.perf_counter() - start)
                        assert files(out) == want, "the Dask build differs from fmrh dataset build"
                times[f"fmrh.dask, {workers} worker{'s' if workers > 1 else ''}"] = statistics.median(t)
            one = times["fmrh.dask, 1 worker"]
            for name, secs in times.items():
                rows.append((label, name, secs, one / secs))
        total = sum(len(v) for v in files(work / "ref").values())
        print(f"Puget Sound 4k as 16 tiles of 1025², dataset {total / 1e6:.1f} MB, "
              f"median of {args.rounds}, {os.cpu_count()} cores")
        print(f"| {'threads in fmrh':<24} | {'build':<34} | {'seconds':>8} | {'vs 1 worker':>11} |")
        print(f"|{'-' * 26}|{'-' * 36}|{'-' * 10}|{'-' * 13}|")
        for label, name, secs, speed in rows:
            print(f"| {label:<24} | {name:<34} | {secs:8.2f} | {speed:10.2f}x |")
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
