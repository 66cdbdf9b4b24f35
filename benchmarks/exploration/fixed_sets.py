"""Which held-out orbits meet the fixed set of each reversing symmetry: a reversible map has no
secular energy drift on an orbit that meets Fix(R) (a symmetric orbit), and may drift on one
that does not.

    python -m benchmarks.exploration.fixed_sets --system SYSTEM [--seeds 0 1 2] [--n-steps 10000]
        [--threshold 0.05] [--out FILE]

The benchmark's held-out ICs (recipes.py: 10, uniform in [-1, 1]^dim after the 40 training
ICs) integrated by heyoka over `--n-steps` steps of h = 0.1; per R = diag(r) of
`liepoisson.systems.reversing_symmetries`, the minimum over the orbit of the distance to
Fix(R) = {y : the flipped components vanish}, relative to the orbit's mean |y|. Writes the
distances to `--out` (default `benchmarks/results/exploration/fixed_sets_SYSTEM.json`).
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
)
from liepoisson.systems import reversing_symmetries


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.exploration.fixed_sets",
                                     description=__doc__.splitlines()[0])
    add_system_option(parser)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--n-steps", type=int, default=10_000)
    parser.add_argument("--threshold", type=float, default=0.05, help="a distance below this meets Fix(R)")
    add_out_option(parser)
    args = parser.parse_args(argv)
    system = SYSTEMS[args.system]()
    rows = []
    for seed in args.seeds:
        _, y_test = initial_conditions(system.dim, seed)
        y = np.asarray(it.ground_truth(system, y_test, h=H, n_steps=args.n_steps, seed=seed, progress=False).states)
        for r in reversing_symmetries(system):
            flipped = r < 0
            d = np.linalg.norm(y[..., flipped], axis=-1).min(axis=1) / np.linalg.norm(y, axis=-1).mean(axis=1)
            meets = int(np.sum(d < args.threshold))
            print(f"{args.system} seed {seed} R = {r.astype(int).tolist()}: distance to Fix(R) per IC "
                  + " ".join(f"{v:.3f}" for v in d) + f"; {meets}/{len(d)} below {args.threshold}", flush=True)
            rows.append({"seed": seed, "R": r.astype(int).tolist(), "distance_per_ic": d, "meets": meets})
    write_json(out_path(args, f"fixed_sets_{args.system}"), args, {"rows": rows})


if __name__ == "__main__":
    main()
