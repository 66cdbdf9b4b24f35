r"""SciPy's L-BFGS-B loop with NumPy's BLAS on all cores against one thread (what
`learn.ScipyLBFGSB` does since issue 29): wall time per iteration of E5's LPNet and baseline.

    python -m benchmarks.blas_threads [--iterations 200] [--trajectories 250 500] [--out FILE.json]
    python -m benchmarks.blas_threads --report   # the table of the saved results

E5's data (`python -m paper run E5`: heyoka trajectories of 100 steps, 80/20 split) and its two
networks (`learn.PlusAffine` around the MLP 6x64 sigmoid) in an LPNet and in the MLP baseline,
`--iterations` full-batch L-BFGS-B iterations from the random start (normalised). "all cores":
the BLAS pool as NumPy starts it; "one thread": inside `threadpoolctl.threadpool_limits(1,
"blas")`. Between two gradients, L-BFGS-B's host update calls BLAS on vectors of the 21,638
parameters; a multi-threaded OpenBLAS pool then spins on the cores that XLA's next gradient
needs. The final training losses of both settings are printed beside the times: the setting
changes the order of BLAS sums, so they may differ in their last digits. Run it alone on the
machine (times are wall-clock).
"""

from __future__ import annotations

import argparse
import contextlib
import time
from unittest import mock

import numpy as np

import integrators as it
import learn
import liepoisson as lp
from learn._solvers import _quasi_newton
from paper import e5_kirchhoff as e5

from ._report import add_output_arguments, saved_results, write_json

MODELS = ("lpnet", "baseline")


def _model(kind: str, system) -> learn.AbstractLearnedMap:
    if kind == "lpnet":
        return learn.LPNet(system, network=e5.network(), parametrisation=learn.TestFlowParametrisation(system))
    return learn.MLPBaseline(system, network=e5.network())


def run(kind: str, threads: str, iterations: int, data, system) -> dict:
    # "all": the limit `learn` sets is replaced by a context that does nothing.
    patch = (mock.patch.object(_quasi_newton, "threadpool_limits", lambda **_: contextlib.nullcontext())
             if threads == "all" else contextlib.nullcontext())
    with patch:
        start = time.perf_counter()
        _, record = learn.fit(_model(kind, system), data, optimiser=learn.KeepIfBetter(learn.ScipyLBFGSB(iterations)),
                              validation_fraction=0.2, seed=0, normalise=True, progress=False)
        wall = time.perf_counter() - start
    row = {"model": kind, "blas_threads": threads, "trajectories": int(data.states.shape[0]),
           "iterations": iterations, "wall_time_s": wall, "train_loss": record.train_loss}
    print(f"{kind}, {row['trajectories']} trajectories, BLAS on {threads}: {iterations} iterations in {wall:.1f} s "
          f"({wall / iterations * 1e3:.0f} ms each), train loss {record.train_loss:.6g}", flush=True)
    return row


def report(results: list[dict]) -> str:
    lines = [("| model | trajectories | BLAS on all cores [ms/it] | BLAS on one thread [ms/it] | speed-up "
              "| train loss (all / one) |"), "|---|---|---|---|---|---|"]
    for kind in MODELS:
        for n in sorted({r["trajectories"] for r in results}):
            by = {r["blas_threads"]: r for r in results if r["model"] == kind and r["trajectories"] == n}
            if set(by) != {"all", "one"}:
                continue
            ms = {k: r["wall_time_s"] / r["iterations"] * 1e3 for k, r in by.items()}
            lines.append(f"| {kind} | {n} | {ms['all']:.0f} | {ms['one']:.0f} | {ms['all'] / ms['one']:.2f}x "
                         f"| {by['all']['train_loss']:.4g} / {by['one']['train_loss']:.4g} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.blas_threads", description=__doc__.splitlines()[0])
    parser.add_argument("--iterations", type=int, default=200)
    parser.add_argument("--trajectories", type=int, nargs="+", default=[250, 500])
    add_output_arguments(parser, "blas_threads")
    args = parser.parse_args(argv)
    if args.report:
        print(report(saved_results(args.out)))
        return
    if args.iterations < 1:
        parser.error(f"--iterations must be a positive integer; got {args.iterations}")
    if min(args.trajectories) < 5:
        parser.error(f"--trajectories must be at least 5 (an 80/20 split); got {args.trajectories}")
    system = lp.systems.Kirchhoff(inertia=(1.0, 2.0, 1.0), mass=(1.0, 2.0, 1.0))
    y0 = np.array([1.0, 1.0, 1.0, -1.0, 1.0, 2.0])
    results = []
    for n in args.trajectories:
        y0s = y0 + np.random.default_rng(e5.DATA_SEED).uniform(-0.1, 0.1, size=(n, 6))
        data = it.ground_truth(system, y0s, h=0.1, n_steps=100, seed=e5.DATA_SEED)
        for kind in MODELS:
            # A first short fit compiles the loss, so that neither timed setting pays for it.
            learn.fit(_model(kind, system), data, optimiser=learn.KeepIfBetter(learn.ScipyLBFGSB(2)), validation_fraction=0.2,
                      seed=0, normalise=True, progress=False)
            for threads in ("all", "one"):
                results.append(run(kind, threads, args.iterations, data, system))
                write_json(args.out, args, results)  # an interrupted run keeps what it measured
    print(report(results))


if __name__ == "__main__":
    main()
