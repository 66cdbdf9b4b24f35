"""How far the held-out trajectories (10 ICs, t = 200) pass from the training states of
recipes.py (40 ICs x 50 pairs at h = 0.1), and with more ICs (`--extra-ics`, default 360:
10x the data), per seed.

    python -m benchmarks.exploration.coverage [--system so4] [--seeds 0 1 2] [--extra-ics 360] [--out FILE]

Writes the distances to `--out` (default `benchmarks/results/exploration/coverage_SYSTEM.json`).
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.spatial import cKDTree

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
    parser = argparse.ArgumentParser(prog="python -m benchmarks.exploration.coverage",
                                     description=__doc__.splitlines()[0])
    add_system_option(parser, default="so4")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--extra-ics", type=int, default=360, help="training ICs added for the dense data")
    add_out_option(parser)
    args = parser.parse_args(argv)
    system = SYSTEMS[args.system]()
    n = system.dim
    rows = []
    for seed in args.seeds:
        y_train, y_test = initial_conditions(n, seed)
        pts = np.asarray(training_data(system, y_train, seed).states).reshape(-1, n)
        tree = cKDTree(pts)
        Y = np.asarray(it.ground_truth(system, y_test, h=H, n_steps=2000, seed=seed, progress=False).states)
        d, _ = tree.query(Y.reshape(-1, n))
        d = d.reshape(Y.shape[:2])
        dtr, _ = tree.query(pts, k=2)
        print(f"seed {seed}: NN distance inside training set median {np.median(dtr[:, 1]):.3f}; held-out long "
              f"trajectories: median {np.median(d):.3f}, max per IC {np.round(d.max(1), 2)}, max |y| "
              f"{np.abs(Y).max():.2f} vs train {np.abs(pts).max():.2f}")
        dense = initial_conditions(n, seed, args.extra_ics)[0][40:]
        dd = training_data(system, dense, seed)
        tree2 = cKDTree(np.concatenate([pts, np.asarray(dd.states).reshape(-1, n)]))
        d2, _ = tree2.query(Y.reshape(-1, n))
        print(f"   with dense data: median {np.median(d2):.3f}, max {d2.max():.2f}")
        rows.append({"seed": seed, "nn_distance_training_median": np.median(dtr[:, 1]),
                     "held_out_distance_median": np.median(d), "held_out_distance_max_per_ic": d.max(1),
                     "max_abs_state_held_out": np.abs(Y).max(), "max_abs_state_training": np.abs(pts).max(),
                     "dense_held_out_distance_median": np.median(d2), "dense_held_out_distance_max": d2.max()})
    write_json(out_path(args, f"coverage_{args.system}"), args, {"extra_ics": args.extra_ics, "seeds": rows})


if __name__ == "__main__":
    main()
