"""E1's protocol on any system of benchmarks/any_algebra.py: one trajectory of 1000 points at
h = 0.1 (80/20 split), an LPNet 3x16 trained by Adam then L-BFGS-B, rolled out 10,000 steps from
the trajectory's end point (on the training orbit, as in E1).

    python -m benchmarks.exploration.one_trajectory --system SYSTEM [--adam 20000] [--lbfgs 5000]
        [--seeds 0] [--out FILE]

Prints per seed the train / validation loss and the max relative energy error of the rollout;
writes them to `--out` (default
`benchmarks/results/exploration/one_trajectory_SYSTEM_adamN_lbfgsM.json`). The IC: E1's
Pi0 = (1/sqrt2, -1/sqrt2, 1) for the rigid body, else uniform in [-1, 1]^dim (numpy seed 0).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import integrators as it
import learn
from benchmarks._report import write_json
from benchmarks.exploration.common import (
    SYSTEMS,
    H,
    add_out_option,
    add_system_option,
    lpnet,
    out_path,
)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.exploration.one_trajectory",
                                     description=__doc__.splitlines()[0])
    add_system_option(parser)
    parser.add_argument("--adam", type=int, default=20_000, help="Adam epochs")
    parser.add_argument("--lbfgs", type=int, default=5000, help="L-BFGS-B iterations after Adam (0: none)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    add_out_option(parser)
    args = parser.parse_args(argv)
    system = SYSTEMS[args.system]()
    y0 = (np.array([2**-0.5, -(2**-0.5), 1.0]) if args.system == "rigid_body"
          else np.random.default_rng(0).uniform(-1, 1, size=system.dim))
    data = it.ground_truth(system, y0[None], h=H, n_steps=999, progress=False)
    end = np.asarray(data.states)[:, -1]
    rows = []
    for seed in args.seeds:
        stages = [learn.Adam(args.adam)] + ([learn.KeepIfBetter(learn.ScipyLBFGSB(args.lbfgs))] if args.lbfgs else [])
        t0 = time.perf_counter()
        net, rec = learn.fit(lpnet(system, key=seed), data, optimiser=stages, seed=seed, progress=False)
        seconds = time.perf_counter() - t0
        row = it.compare({"lpnet": net}, system, end, t_final=1000.0, n_outputs=500).rows[0]
        print(f"{args.system} one trajectory, Adam {args.adam} + L-BFGS-B {args.lbfgs}, seed {seed}: loss "
              f"{rec.train_loss:.2e} / val {rec.val_loss:.2e}, max energy error over 10,000 steps "
              f"{row.energy_error_max:.2e}, {seconds:.0f} s", flush=True)
        rows.append({"seed": seed, "train_loss": rec.train_loss, "val_loss": rec.val_loss,
                     "energy_error_max_10000_steps": row.energy_error_max, "fit_s": seconds})
    write_json(out_path(args, f"one_trajectory_{args.system}_adam{args.adam}_lbfgs{args.lbfgs}"), args,
               {"seeds": rows})


if __name__ == "__main__":
    main()
