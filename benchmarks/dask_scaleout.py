"""Scale-out on Dask: a chunked ground-truth ensemble written to HDF5 with 1 and 2 workers
(client peak memory, wall time, projection to N workers), and a sweep of trainings sequential
vs on a 2-worker LocalCluster.

    python -m benchmarks.dask_scaleout ground-truth [--n-traj 100000] [--outputs 1001] [--chunk-size 2000]
                                                    [--out benchmarks/results/dask_scaleout_ground_truth.json]
    python -m benchmarks.dask_scaleout sweep [--points 8] [--model lpnet|glpnet] [--epochs N]
                                             [--out benchmarks/results/dask_scaleout_sweep_MODEL.json]

Each configuration runs in a fresh subprocess, so that the client's peak resident memory
(`ru_maxrss`, imports included) is that run's alone. Writes every configuration's figures to
`--out` (JSON).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks._report import default_out, write_json

H = 0.01  # 1001 outputs: t = 0 .. 10


def _cluster(workers: int):
    import distributed

    cluster = distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                       dashboard_address=None)
    return cluster, distributed.Client(cluster)


def _peak_rss_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # Linux: KiB


def _transfer_s(client, shape) -> float:
    """Seconds for the client to receive one chunk (a float64 array of `shape`) from a worker."""
    import distributed

    times = []
    for _ in range(3):
        future = client.submit(np.ones, shape, pure=False)
        distributed.wait(future)
        start = time.perf_counter()
        future.result()
        times.append(time.perf_counter() - start)
        future.release()
    return float(np.median(times))


def child_ground_truth(workers: int, n_traj: int, outputs: int, chunk: int, path: str) -> dict:
    import integrators as it
    import liepoisson as lp

    body = lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0))
    y0 = np.random.default_rng(0).normal(size=(n_traj, 3))
    cluster, client = _cluster(workers) if workers else (None, None)
    try:
        if client is not None:  # start-up and the workers' compile, outside the timing
            it.ground_truth(body, y0[:2], H, 2, client=client, chunk_size=1)
        else:
            it.ground_truth(body, y0[:2], H, 2)
        start = time.perf_counter()
        it.save_ground_truth(path, body, y0, H, outputs - 1, client=client, chunk_size=chunk, progress=False)
        wall = time.perf_counter() - start
        transfer = _transfer_s(client, (chunk, outputs, 3)) if client is not None else 0.0
    finally:
        if client is not None:
            client.close()
            cluster.close()
    size = os.path.getsize(path)
    check = it.Trajectories.load(path, select=[0, n_traj - 1])
    ref = it.ground_truth(body, y0[[0, n_traj - 1]], H, outputs - 1)
    peak = _peak_rss_mib()
    # The two parts of the projection: one chunk's integration (on a worker: a ground truth of
    # that chunk in this process, the same compiled integrator and loop), and the client's
    # serial work per chunk (writing it into the HDF5 file, as save_ground_truth does).
    start = time.perf_counter()
    block = it.ground_truth(body, y0[:chunk], H, outputs - 1, progress=False).states
    compute = time.perf_counter() - start
    import h5py

    start = time.perf_counter()
    for _ in range(3):
        with h5py.File(path, "r+") as f:
            f["trajectories"][:chunk] = block
    write = (time.perf_counter() - start) / 3
    return {"workers": workers, "wall_s": wall, "client_peak_rss_mib": peak, "file_gib": size / 2**30,
            "n_chunks": -(-n_traj // chunk), "bitwise_equal_spot_check": bool(np.array_equal(check.states, ref.states)),
            "chunk_compute_s": compute, "chunk_write_s": write, "chunk_transfer_s": transfer}


def child_sweep(workers: int, points: int, epochs: int, out: str, model: str) -> dict:
    import integrators as it
    import learn
    import liepoisson as lp

    body = lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0))
    data = it.ground_truth(body, np.array([1 / np.sqrt(2), -1 / np.sqrt(2), 1.0]), 0.1, 999)  # E1's data
    grid = {"seed": list(range(points))}

    if model == "lpnet":  # E1's LPNet, Adam: batched matmuls that XLA spreads over the cores by itself
        def make(point):
            return learn.LPNet(body, hidden=(16, 16, 16), key=point["seed"])

        fit = {"epochs": epochs}
    else:  # E6's G-LPNet, BFGS (SciPy, one core): a step is a few small JAX calls
        def make(point):
            return learn.GLPNet(body, n_modules=6, key=point["seed"])

        fit = {"optimiser": learn.KeepIfBetter(learn.WarmStart(learn.ScipyBFGS(epochs))), "validation_fraction": 0.0}

    cluster, client = _cluster(workers) if workers else (None, None)
    try:
        start = time.perf_counter()
        result = learn.sweep(make, grid, data, out=out, client=client, progress=False, **fit)
        wall = time.perf_counter() - start
    finally:
        if client is not None:
            client.close()
            cluster.close()
    return {"workers": workers, "wall_s": wall, "val_loss": [r.metrics["val_loss"] for r in result],
            "fit_s": [r.metrics["wall_time_s"] for r in result]}


def _child(args: list[str]) -> dict:
    proc = subprocess.run([sys.executable, "-m", "benchmarks.dask_scaleout", "_child", *args],
                          capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        raise RuntimeError(proc.stderr[-3000:])
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.dask_scaleout", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="what", required=True)
    gt = sub.add_parser("ground-truth")
    gt.add_argument("--n-traj", type=int, default=100_000)
    gt.add_argument("--outputs", type=int, default=1001)
    gt.add_argument("--chunk-size", type=int, default=2000)
    gt.add_argument("--out", type=Path, default=default_out("dask_scaleout_ground_truth"), help="JSON file written")
    sw = sub.add_parser("sweep")
    sw.add_argument("--points", type=int, default=8)
    sw.add_argument("--model", choices=("lpnet", "glpnet"), default="lpnet")
    sw.add_argument("--epochs", type=int, default=3000, help="Adam epochs (lpnet), BFGS iterations (glpnet)")
    sw.add_argument("--out", type=Path, help="JSON file written (default benchmarks/results/dask_scaleout_sweep_MODEL.json)")
    child = sub.add_parser("_child")
    child.add_argument("spec")
    args = parser.parse_args(argv)

    if args.what == "_child":
        spec = json.loads(args.spec)
        fn = {"ground-truth": child_ground_truth, "sweep": child_sweep}[spec.pop("kind")]
        print(json.dumps(fn(**spec)))
        return
    print(f"{os.cpu_count()} CPU cores; each configuration in a fresh process")
    with tempfile.TemporaryDirectory(dir=".") as tmp:
        if args.what == "ground-truth":
            runs = []
            for workers in (1, 2):
                path = os.path.join(tmp, f"truth-{workers}.h5")
                r = _child([json.dumps({"kind": "ground-truth", "workers": workers, "n_traj": args.n_traj,
                                        "outputs": args.outputs, "chunk": args.chunk_size, "path": path})])
                os.remove(path)
                runs.append(r)
                print(f"{workers} worker(s): {r['wall_s']:.1f} s for {args.n_traj} x {args.outputs} outputs "
                      f"({r['n_chunks']} chunks, {r['file_gib']:.2f} GiB file); client peak RSS "
                      f"{r['client_peak_rss_mib']:.0f} MiB; spot check bitwise equal: {r['bitwise_equal_spot_check']}")
            t1, t2 = runs[0]["wall_s"], runs[1]["wall_s"]
            n_chunks = runs[0]["n_chunks"]
            compute = float(np.median([r["chunk_compute_s"] for r in runs]))
            serial = float(np.median([r["chunk_write_s"] + r["chunk_transfer_s"] for r in runs]))
            print(f"ratio 1 worker / 2 workers: {t1 / t2:.2f}")
            print(f"per chunk of {args.chunk_size} trajectories: integration {compute:.3f} s on one core; the client's "
                  f"serial work (receive from a worker + write to HDF5) {serial:.3f} s")
            print("projected wall time on N workers with cores of their own = n_chunks x max(integration / N, "
                  "client serial):")
            projected = {}
            for n in (1, 2, 4, 8, 16, 64):
                measured = {1: t1, 2: t2}.get(n)
                projected[n] = n_chunks * max(compute / n, serial)
                print(f"  N = {n}: {projected[n]:.1f} s"
                      + (f" (measured here {measured:.1f} s, workers sharing {os.cpu_count()} cores with the client "
                         "and scheduler)" if measured else ""))
            write_json(args.out, args, {"runs": runs, "ratio_1_over_2_workers": t1 / t2, "chunk_compute_s": compute,
                                        "chunk_client_serial_s": serial, "projected_wall_s_on_n_workers": projected})
        else:
            runs = []
            for workers in (0, 2):
                r = _child([json.dumps({"kind": "sweep", "workers": workers, "points": args.points,
                                        "epochs": args.epochs, "out": os.path.join(tmp, f"sweep-{workers}"),
                                        "model": args.model})])
                runs.append(r)
                where = "sequential (one process, no Dask)" if workers == 0 else f"LocalCluster, {workers} workers"
                what = f"{args.epochs} Adam epochs (LPNet 3x16)" if args.model == "lpnet" else \
                    f"{args.epochs} BFGS iterations (G-LPNet, 6 modules)"
                print(f"{where}: {r['wall_s']:.1f} s for {args.points} trainings of {what} "
                      f"(each fit {np.median(r['fit_s']):.1f} s median)")
            same = runs[0]["val_loss"] == runs[1]["val_loss"]
            print(f"ratio sequential / 2 workers: {runs[0]['wall_s'] / runs[1]['wall_s']:.2f}; "
                  f"same validation losses: {same}")
            out = args.out or default_out(f"dask_scaleout_sweep_{args.model}")
            write_json(out, args, {"runs": runs, "ratio_sequential_over_2_workers": runs[0]["wall_s"] / runs[1]["wall_s"],
                                   "same_validation_losses": same})


if __name__ == "__main__":
    main()
