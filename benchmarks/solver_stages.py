r"""The library's own solver stages beside optimistix's behind the same interface
(`learn.Optimistix`): wall time, compilation included, and the loss reached.

    python -m benchmarks.solver_stages [--iterations 1000] [--steps 50] [--out FILE.json]
    python -m benchmarks.solver_stages --report   # the table of the saved results

Two problems, each fitted from the same start by both:

- **E6 (pairs, BFGS).** E6's data (50 rigid-body trajectories of 20 steps, h = 0.1) and its
  G-LPNet (6 modules, 18 weights) from its identity-activation fit (`--iterations` SciPy BFGS
  iterations with the warm start: the start both share); then `--iterations` more of
  `learn.ScipyBFGS` (SciPy, the loop on the host) against
  `learn.Optimistix(optx.BFGS(rtol=0, atol=0))` (the whole solve compiled).
- **W2 (observations, Levenberg-Marquardt).** W2's rigid body, 30 trajectories x 21
  observations, noise 1e-3, the quadratic G-LPNet (TripleJump) on whole trajectories with
  fitted starts (6 weights and 90 start components), from its one-step fit; `--steps` steps of
  `learn.LevenbergMarquardt` (the block Jacobian, lineax Cholesky, the loop on the host)
  against `learn.Optimistix(optx.LevenbergMarquardt(rtol=1e-12, atol=1e-12))`.

Each timed fit starts with every compiled function dropped (compilation included in both).
Run it alone on the machine (times are wall-clock).
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np
import optimistix as optx

import integrators as it
import learn
import liepoisson as lp
from integrators.splitting import TripleJump
from learn._solvers import _compiled
from paper import w2_observations as w2

from ._report import add_output_arguments, saved_results, write_json


def _timed(model, data, optimiser, **fit) -> dict:
    """One fit from `model`, compilation included (every compiled function dropped first)."""
    _compiled._CACHE.clear()
    jax.clear_caches()
    start = time.perf_counter()
    _, record = learn.fit(model, data, optimiser=optimiser, progress=False, validation_fraction=0.0, seed=0, **fit)
    stage = record.stages[-1]
    return {"wall_time_s": time.perf_counter() - start, "start_loss": stage.details["train_loss_before"],
            "train_loss": record.train_loss, "iterations": stage.iterations, "kept": stage.kept}


def e6(iterations: int) -> list[dict]:
    system = lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0))
    y0s = np.random.default_rng(6).uniform(-2.0, 2.0, size=(50, 3))
    data = it.ground_truth(system, y0s, h=0.1, n_steps=20, seed=6, progress=False)
    start, _ = learn.fit(learn.GLPNet(system, n_modules=6, key=0), data,
                              optimiser=learn.KeepIfBetter(learn.WarmStart(learn.ScipyBFGS(iterations))),
                              validation_fraction=0.0, seed=0, progress=False)
    rows = []
    for name, stage in [("SciPy BFGS (learn.ScipyBFGS)", learn.KeepIfBetter(learn.ScipyBFGS(iterations))),
                        ("optimistix BFGS (learn.Optimistix)",
                         learn.KeepIfBetter(learn.Optimistix(optx.BFGS(rtol=0.0, atol=0.0), max_steps=iterations)))]:
        row = {"problem": "E6 G-LPNet, pairs", "solver": name, **_timed(start, data, stage)}
        print(row, flush=True)
        rows.append(row)
    return rows


def w2_observations(steps: int) -> list[dict]:
    protocol = w2.protocols()["rigid body"]
    data = w2.observations(protocol, 1e-3, "regular")
    terms = learn.RidgeTerms(3, 3, key=0, activation="identity", linear_term=False, bias=False)
    net = learn.GLPNet(protocol.system, terms=terms, method=TripleJump)
    first, _ = learn.fit(net, data, loss=learn.TrajectoryLoss(window=1, latent=False),
                              optimiser=learn.KeepIfBetter(learn.LevenbergMarquardt(200)), validation_fraction=0.0, progress=False)
    rows = []
    for name, stage in [("learn.LevenbergMarquardt (host loop, block Jacobian)", learn.KeepIfBetter(learn.LevenbergMarquardt(steps, 0.0))),
                        ("optimistix LevenbergMarquardt (learn.Optimistix)",
                         learn.KeepIfBetter(learn.Optimistix(optx.LevenbergMarquardt(rtol=1e-12, atol=1e-12), max_steps=steps)))]:
        row = {"problem": "W2 G-LPNet, observations", "solver": name,
               **_timed(first, data, stage, loss=learn.TrajectoryLoss())}
        print(row, flush=True)
        rows.append(row)
    return rows


def report(rows: list[dict]) -> str:
    lines = ["| problem | solver | iterations | wall time [s] | train loss (start -> end) |", "|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['problem']} | {r['solver']} | {r['iterations']} | {r['wall_time_s']:.2f} | "
                     f"{r['start_loss']:.4g} -> {r['train_loss']:.4g} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.solver_stages", description=__doc__.splitlines()[0])
    parser.add_argument("--iterations", type=int, default=1000, help="BFGS iterations on E6")
    parser.add_argument("--steps", type=int, default=50, help="Levenberg-Marquardt steps on W2")
    add_output_arguments(parser, "solver_stages")
    args = parser.parse_args(argv)
    if args.report:
        print(report(saved_results(args.out)))
        return
    rows = e6(args.iterations) + w2_observations(args.steps)
    print(report(rows))
    write_json(args.out, args, rows)


if __name__ == "__main__":
    main()
