r"""Time to the paper's figure, per experiment: today's recipe against the second-order
optimisers that run inside JAX.

    python -m benchmarks.time_to_figure [--experiments E1 ... E6] [--out FILE.json]
    python -m benchmarks.time_to_figure --report   # the table of the saved results

For each experiment, its data (as `python -m paper` builds them) and its model, fitted twice
from the same weights:

- **old**: the recipe of `python -m paper` (quick profile): Adam as the paper (E1-E4), then
  SciPy's L-BFGS-B, a host loop that calls a compiled value-and-gradient once per evaluation
  (E5: L-BFGS-B from the random start, inputs and outputs normalised); E6's G-LPNet by SciPy
  BFGS with the warm start.
- **new**: the same first stage, then optax's L-BFGS compiled inside JAX in chunks of
  iterations (`learn.OptaxLBFGS`); E6's 18 weights by Levenberg-Marquardt
  (`learn.LevenbergMarquardt`, a lineax Cholesky per step) with the warm start.

The figure is the paper's training loss (the MSE the paper reports for the experiment). The
clock runs from the call of `learn.fit` (compilation included); `learn.fit`'s callback (every
Adam chunk, quasi-Newton iteration and Levenberg-Marquardt step) notes when the training loss
first reaches the figure, and the fit stops there. A recipe that does not reach it within its
iterations (the `--full` profile's) reports its time and its best loss. Run it alone on the
machine: both recipes are timed by the wall clock.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from collections.abc import Callable
from typing import Any

import numpy as np

import integrators as it
import learn
import liepoisson as lp
from paper import e1_rigid_body as e1
from paper import e2_rigid_body_many as e2
from paper import e3_extended_pendulum as e3
from paper import e4_charged_particle as e4
from paper import e5_kirchhoff as e5
from paper import e6_glpnet_rigid_body as e6
from paper._registry import EXPERIMENTS

from ._report import add_output_arguments, saved_results, write_json

H = 0.1
PI0 = np.array([1 / np.sqrt(2), -1 / np.sqrt(2), 1.0])


@dataclasses.dataclass(frozen=True)
class Case:
    """An experiment's data, model and fit settings, and its two recipes (optimiser stages)."""

    data: Callable[[], Any]
    model: Callable[[], Any]
    fit: dict
    old: tuple
    new: tuple
    old_name: str
    new_name: str


def _cases() -> dict[str, Case]:
    rb = lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0))
    q1, q2, q3, q4 = (m.PROFILES["quick"] for m in (e1, e2, e3, e4))
    full1, full2, full3, full5 = (m.PROFILES["full"] for m in (e1, e2, e3, e5))
    adam1 = learn.Adam(q1.epochs, learning_rate=1e-3, final_learning_rate=q1.final_learning_rate)
    adam2 = learn.Adam(q2.epochs, learning_rate=1e-3, final_learning_rate=1e-4)
    adam3 = learn.Adam(q3.epochs, learning_rate=1e-3, final_learning_rate=1e-5)
    adam4 = learn.Adam(q4.epochs, learning_rate=1e-3, final_learning_rate=1e-5, batch_size=q4.batch_size)
    kirchhoff = lp.systems.Kirchhoff(inertia=(1.0, 2.0, 1.0), mass=(1.0, 2.0, 1.0))
    charged = lp.systems.ChargedParticle()
    pendulum = lp.systems.ExtendedPendulum()
    q6 = e6.PROFILES["quick"]
    lbfgsb, lbfgs = "SciPy L-BFGS-B", "optax L-BFGS (in JAX)"
    return {
        "E1": Case(
            lambda: it.ground_truth(rb, PI0, h=H, n_steps=999),
            lambda: learn.LPNet(rb, hidden=(16, 16, 16), activation="sigmoid", key=0),
            {"validation_fraction": 0.2, "seed": 0},
            (adam1, learn.KeepIfBetter(learn.ScipyLBFGSB(full1.refine_iterations))),
            (adam1, learn.KeepIfBetter(learn.OptaxLBFGS(full1.refine_iterations))), f"Adam, {lbfgsb}", f"Adam, {lbfgs}",
        ),
        "E2": Case(
            lambda: it.ground_truth(
                rb, PI0 + np.random.default_rng(e2.DATA_SEED).uniform(-0.1, 0.1, size=(20, 3)), h=H, n_steps=200,
                seed=e2.DATA_SEED),
            lambda: learn.LPNet(rb, hidden=(32, 32, 32), activation="sigmoid", key=0),
            {"validation_fraction": 0.2, "seed": 0},
            (adam2, learn.KeepIfBetter(learn.ScipyLBFGSB(full2.refine_iterations))),
            (adam2, learn.KeepIfBetter(learn.OptaxLBFGS(full2.refine_iterations))), f"Adam, {lbfgsb}", f"Adam, {lbfgs}",
        ),
        "E3": Case(
            lambda: it.ground_truth(pendulum, e3.INITIAL_CONDITIONS, h=H, n_steps=999),
            lambda: learn.LPNet(pendulum, hidden=e3.HIDDEN, activation="sigmoid", key=0,
                                parametrisation=learn.TestFlowParametrisation(pendulum)),
            {"validation_fraction": 0.5, "seed": 0},
            (adam3, learn.KeepIfBetter(learn.ScipyLBFGSB(full3.refine_iterations))),
            (adam3, learn.KeepIfBetter(learn.OptaxLBFGS(full3.refine_iterations))), f"Adam, {lbfgsb}", f"Adam, {lbfgs}",
        ),
        "E4": Case(
            lambda: it.ground_truth(charged, e4.Y0, h=H, n_steps=q4.n_points - 1),
            lambda: learn.LPNet(charged, hidden=e4.HIDDEN, activation="sigmoid", key=0,
                                parametrisation=learn.TestFlowParametrisation(charged)),
            {"validation_fraction": 0.2, "seed": 0},
            (adam4, learn.KeepIfBetter(learn.ScipyLBFGSB(1000))),
            (adam4, learn.KeepIfBetter(learn.OptaxLBFGS(1000))), f"Adam, {lbfgsb}", f"Adam, {lbfgs}",
        ),
        "E5": Case(
            lambda: it.ground_truth(
                kirchhoff,
                np.array([1.0, 1.0, 1.0, -1.0, 1.0, 2.0])
                + np.random.default_rng(e5.DATA_SEED).uniform(-0.1, 0.1, size=(full5.n_trajectories, 6)),  # 500, as measured
                h=H, n_steps=100, seed=e5.DATA_SEED),
            lambda: learn.LPNet(kirchhoff, hidden=e5.HIDDEN, activation="sigmoid", key=0,
                                parametrisation=learn.TestFlowParametrisation(kirchhoff)),
            {"validation_fraction": 0.2, "seed": 0, "normalise": True},
            (learn.KeepIfBetter(learn.ScipyLBFGSB(full5.refine_iterations)),),
            (learn.KeepIfBetter(learn.OptaxLBFGS(full5.refine_iterations)),), lbfgsb, lbfgs,
        ),
        "E6": Case(
            lambda: it.ground_truth(rb, np.random.default_rng(e6.DATA_SEED).uniform(-2.0, 2.0, size=(50, 3)), h=H,
                                    n_steps=20, seed=e6.DATA_SEED),
            lambda: learn.GLPNet(rb, n_modules=6, key=0),
            {"validation_fraction": 0.0, "seed": 0},
            (learn.KeepIfBetter(learn.WarmStart(learn.ScipyBFGS(q6.max_iter))),),
            (learn.KeepIfBetter(learn.WarmStart(learn.LevenbergMarquardt(200))),), "SciPy BFGS, warm start",
            "Levenberg-Marquardt (lineax), warm start",
        ),
    }


class _Reached(Exception):
    pass


def time_to_figure(case: Case, stages: tuple, figure: float) -> dict[str, Any]:
    """Fit `case.model()` on `case.data()` with `stages` until the training loss reaches
    `figure`: `{"reached", "seconds", "stage", "iteration", "loss"}` (the time to the figure,
    or the whole fit's with its best loss)."""
    data = case.data()
    model = case.model()
    best = {"loss": np.inf, "stage": None, "iteration": None}
    start = time.perf_counter()

    def callback(p: learn.Progress) -> None:
        if p.train_loss < best["loss"]:
            best.update(loss=p.train_loss, stage=p.optimiser, iteration=p.iteration)
        if p.train_loss <= figure:
            raise _Reached

    try:
        _, record = learn.fit(model, data, optimiser=stages, progress=False, callback=callback, **case.fit)
    except _Reached:
        return {"reached": True, "seconds": time.perf_counter() - start, **best}
    seconds = time.perf_counter() - start
    return {"reached": bool(record.train_loss <= figure), "seconds": seconds, **best,
            "loss": min(best["loss"], record.train_loss)}


def table(results: dict) -> str:
    """The markdown table of `results` (as `main` saves them)."""
    header = ("| experiment | paper's training loss | old recipe | time to it [s] | new recipe | time to it [s] "
              "| old / new |")
    lines = [header, "|---|---|---|---|---|---|---|"]

    def cell(r):
        if not r["reached"]:
            return f"not reached ({r['seconds']:.0f} s, best {r['loss']:.2e})"
        return f"{r['seconds']:.1f} (in {r['stage']}, iteration {r['iteration']})"

    for exp_id, r in results.items():
        old, new = r["old"], r["new"]
        ratio = f"{old['seconds'] / new['seconds']:.2f}x" if old["reached"] and new["reached"] else "-"
        lines.append(f"| {exp_id} | {r['figure']:g} | {old['recipe']} | {cell(old)} | {new['recipe']} | {cell(new)} "
                     f"| {ratio} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.time_to_figure", description=__doc__.splitlines()[0])
    parser.add_argument("--experiments", nargs="+", default=["E1", "E2", "E3", "E4", "E5", "E6"])
    add_output_arguments(parser, "time_to_figure")
    args = parser.parse_args(argv)
    if args.report:
        print(table(saved_results(args.out)))
        return
    cases = _cases()
    results = {}
    for exp_id in args.experiments:
        case = cases[exp_id]
        figure = EXPERIMENTS[exp_id].paper_value("train_loss").value
        old = time_to_figure(case, case.old, figure)
        new = time_to_figure(case, case.new, figure)
        results[exp_id] = {"figure": figure, "old": {"recipe": case.old_name, **old},
                           "new": {"recipe": case.new_name, **new}}
        print(table(results).splitlines()[-1], flush=True)
        write_json(args.out, args, results)  # after each experiment: an interrupted run keeps what it measured
    print(table(results))
    print(f"results: {args.out}")


if __name__ == "__main__":
    main()
