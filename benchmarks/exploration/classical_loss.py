"""The state loss (one-step MSE) of classical splittings of the exact H on the benchmark's
training pairs (40 ICs x 50 steps of h = 0.1, seed 0): what a learned map's loss compares with.

    python -m benchmarks.exploration.classical_loss --system SYSTEM [--methods Strang TripleJump Yoshida6] [--out FILE]

Writes the losses to `--out` (default `benchmarks/results/exploration/classical_loss_SYSTEM.json`).
"""

from __future__ import annotations

import argparse

import numpy as np

import integrators as it
from benchmarks._report import write_json
from benchmarks.exploration.common import (
    SYSTEMS,
    H,
    add_out_option,
    add_system_option,
    initial_conditions,
    out_path,
    training_data,
)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.exploration.classical_loss",
                                     description=__doc__.splitlines()[0])
    add_system_option(parser)
    parser.add_argument("--methods", nargs="+", default=["Strang", "TripleJump", "Yoshida6"],
                        choices=[m.__name__ for m in it.splitting.METHODS], help="splitting methods of the exact H")
    add_out_option(parser)
    args = parser.parse_args(argv)
    system = SYSTEMS[args.system]()
    y_train, _ = initial_conditions(system.dim, 0)
    X0, X1 = training_data(system, y_train, 0).pairs()
    losses = {}
    for name in args.methods:
        method = getattr(it.splitting, name)(system, H)
        losses[name] = float(np.mean((np.asarray(method.rollout(X0, 1))[:, -1] - X1) ** 2))
        print(name, "mse", losses[name])
    write_json(out_path(args, f"classical_loss_{args.system}"), args, {"state_mse": losses})


if __name__ == "__main__":
    main()
