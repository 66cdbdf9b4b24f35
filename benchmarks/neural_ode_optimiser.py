"""The neural ODE peer's optimiser: SciPy's BFGS against its L-BFGS-B (50 correction pairs) on
W6's training data (the Suslov problem, full profile, noise 0), one hidden-layer shape, a fixed
number of iterations each: the training loss reached and the wall time (compilation included).

    python -m benchmarks.neural_ode_optimiser [--methods BFGS L-BFGS-B] [--iterations 100]
        [--hidden 64 64] [--out benchmarks/results/neural_ode_optimiser.json]

SciPy's BFGS updates its dense inverse Hessian by two n x n matrix products a step (O(n^3) in the
n weights); L-BFGS-B keeps 50 pairs of vectors (O(50 n)). `paper._neural_ode` fits with the
latter (docs/conventions.md, "Peers").
"""

from __future__ import annotations

import argparse
import time

import equinox as eqx
import jax
import numpy as np

import learn
from benchmarks._report import default_out, write_json
from paper import _neural_ode
from paper import w6_nonholonomic as w6

METHODS = {"BFGS": learn.ScipyBFGS, "L-BFGS-B": learn.ScipyLBFGSB}


def run(method: str, iterations: int, hidden: tuple[int, ...]) -> dict:
    """One fit of the neural ODE of shape `hidden` to W6's Suslov data by `method`."""
    P = w6.PROFILES["full"]
    data = w6.observations(w6.systems()["Suslov"], P, 0.0)
    states = np.concatenate(data.states)
    rates = np.concatenate([np.diff(y, axis=0) / np.diff(t)[:, None] for y, t in zip(data.states, data.times)])
    net = learn.NeuralODE(data.system, hidden=hidden, activation="tanh", key=0,
                          input_scaling=(tuple(states.mean(0)), tuple(np.maximum(states.std(0), 1e-12))),
                          output_scaling=((0.0,) * states.shape[1], tuple(np.maximum(rates.std(0), 1e-12))))
    solver = METHODS[method](iterations, rtol=_neural_ode.RTOL)
    start = time.perf_counter()
    _, record = learn.fit(net, data, optimiser=learn.KeepIfBetter(solver), validation_fraction=0.0, seed=0,
                          progress=False)
    seconds = time.perf_counter() - start
    weights = sum(int(np.size(w)) for w in jax.tree_util.tree_leaves(eqx.filter(net, eqx.is_inexact_array)))
    return {"method": method, "hidden": list(hidden), "iterations": int(record.stages[-1].iterations),
            "train_loss": float(record.train_loss), "seconds": seconds, "weights": weights}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--methods", nargs="+", default=list(METHODS), choices=list(METHODS))
    parser.add_argument("--iterations", type=int, default=100)
    parser.add_argument("--hidden", type=int, nargs="+", default=[64, 64])
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)
    rows = []
    for method in args.methods:
        row = run(method, args.iterations, tuple(args.hidden))
        print(f"{method}: {row['iterations']} iterations, training loss {row['train_loss']:.3e}, "
              f"{row['seconds']:.1f} s", flush=True)
        rows.append(row)
    write_json(args.out or default_out("neural_ode_optimiser"), args, rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
