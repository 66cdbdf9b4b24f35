r"""E5 with and without the affine part fixed (`learn.PlusAffine`): the training loss along
L-BFGS-B and the energy error of the prediction.

    python -m benchmarks.affine_part [--iterations 2000] [--networks plain plus] [--out FILE.json]
    python -m benchmarks.affine_part --report   # the table of the saved results

E5's data and LPNet (`python -m paper run E5 --full`: 500 heyoka trajectories, MLP 6x64
sigmoid, state loss, inputs and outputs normalised, full-batch L-BFGS-B from the random
start), with the network either the MLP alone (`plain`, E5 until issue 29) or
`learn.PlusAffine` around it (`plus`, E5 now). The training loss is noted at every iteration
(`learn.fit`'s callback); the energy error is E5's: the largest relative energy error over the
100-step prediction from $\Pi = (1, 1, 1)$, $p = (-1, 1, 2)$ against heyoka. Run it alone on
the machine (times are wall-clock).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import integrators as it
import learn
import liepoisson as lp
from paper import e5_kirchhoff as e5
from paper._evaluate import measure_rollout

from ._report import add_output_arguments, saved_results, write_json

CHECKPOINTS = (250, 500, 1000, 1500, 2000, 3000, 5000)


def network(kind: str) -> learn.AbstractNetwork:
    mlp = learn.AffineMLP(6, 6, e5.HIDDEN, "sigmoid", key=0)
    return learn.PlusAffine(mlp) if kind == "plus" else mlp


def run(kind: str, iterations: int, data, system, reference) -> dict:
    losses: dict[int, float] = {}

    def note(p: learn.Progress) -> None:
        if p.iteration in CHECKPOINTS or p.iteration == iterations:
            losses.setdefault(p.iteration, p.train_loss)

    model = learn.LPNet(system, network=network(kind), parametrisation=learn.TestFlowParametrisation(system))
    start = time.perf_counter()
    net, record = learn.fit(model, data, optimiser=learn.KeepIfBetter(learn.ScipyLBFGSB(iterations)), validation_fraction=0.2,
                            seed=0, normalise=True, progress=False, callback=note)
    wall = time.perf_counter() - start
    metrics = measure_rollout(net, record, system, reference.states)["metrics"]
    row = {"network": kind, "iterations": iterations, "wall_time_s": wall, "train_loss": record.train_loss,
           "val_loss": record.val_loss, "energy_rel_err_max": metrics["energy_rel_err_max"],
           "train_loss_at": {str(k): v for k, v in sorted(losses.items())}}
    print(f"{kind}: {iterations} iterations in {wall:.0f} s, train {record.train_loss:.3g}, "
          f"val {record.val_loss:.3g}, energy {metrics['energy_rel_err_max']:.3%}", flush=True)
    return row


def report(results: list[dict]) -> str:
    points = sorted({int(k) for r in results for k in r["train_loss_at"]})
    lines = ["| network | " + " | ".join(f"loss at {k}" for k in points) + " | max energy error | time [s] |",
             "|---" * (len(points) + 3) + "|"]
    for r in results:
        at = r["train_loss_at"]
        cells = [f"{at[str(k)]:.2e}" if str(k) in at else "" for k in points]
        name = "MLP (E5 until issue 29)" if r["network"] == "plain" else "PlusAffine(MLP) (E5 now)"
        lines.append(f"| {name} | " + " | ".join(cells) + f" | {r['energy_rel_err_max']:.3%} | {r['wall_time_s']:.0f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.affine_part", description=__doc__.splitlines()[0])
    parser.add_argument("--iterations", type=int, default=2000)
    parser.add_argument("--networks", nargs="+", choices=("plain", "plus"), default=["plain", "plus"])
    add_output_arguments(parser, "affine_part")
    args = parser.parse_args(argv)
    if args.report:
        print(report(saved_results(args.out)))
        return
    if args.iterations < 1:
        parser.error(f"--iterations must be a positive integer; got {args.iterations}")
    system = lp.systems.Kirchhoff(inertia=(1.0, 2.0, 1.0), mass=(1.0, 2.0, 1.0))
    y0 = np.array([1.0, 1.0, 1.0, -1.0, 1.0, 2.0])
    y0s = y0 + np.random.default_rng(e5.DATA_SEED).uniform(-0.1, 0.1, size=(e5.PROFILES["full"].n_trajectories, 6))
    data = it.ground_truth(system, y0s, h=0.1, n_steps=100, seed=e5.DATA_SEED)
    reference = it.ground_truth(system, y0, h=0.1, n_steps=e5.PREDICTION_STEPS)
    results = []
    for kind in args.networks:
        results.append(run(kind, args.iterations, data, system, reference))
        write_json(args.out, args, results)  # after each network: an interrupted run keeps what it measured
    print(report(results))


if __name__ == "__main__":
    main()
