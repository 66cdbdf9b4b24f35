"""Cost per step of the six axis orderings of Strang on the rigid body: maps of equal work must
measure equal.

    python -m benchmarks.strang_orderings [--out benchmarks/results/strang_orderings.json]

The rigid body I = diag(1, 2, 3) splits into three pieces; Strang's six orderings each apply
five exact sub-flows per step and have the same XLA flop count. Each is timed as W1 times it
(`integrators.step_timing`, the timing of `integrators.compare`): the fastest of `--repeats`
compiled rollouts of W1's 100 held-out initial conditions at h = 0.1, each at least
`--min-seconds` long. Prints each ordering's seconds per step and flops against the default
ordering's, and whether they lie within 1.25x of each other (exit status 1 if not); writes the
same to a JSON file with the machine's load average before and after.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import platform
import sys
from pathlib import Path

import jax
import numpy as np

import integrators as it
import liepoisson as lp

TOLERANCE = 1.25  # the largest ratio of two costs allowed between maps of equal work


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.strang_orderings", description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("benchmarks") / "results" / "strang_orderings.json")
    parser.add_argument("--h", type=float, default=0.1)
    parser.add_argument("--n-traj", type=int, default=100, help="initial conditions stepped together (W1: 100)")
    parser.add_argument("--outputs", type=int, default=25, help="states saved per timed rollout (W1: 25)")
    parser.add_argument("--min-seconds", type=float, default=0.05, help="shortest timed rollout")
    parser.add_argument("--repeats", type=int, default=5, help="timed rollouts per ordering (the fastest counts)")
    args = parser.parse_args(argv)

    body = lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0))
    y0s = np.random.default_rng(110).uniform(-1.25, 1.25, size=(args.n_traj, 3))  # W1's test set
    load_before = os.getloadavg()
    rows = []
    for ordering in itertools.permutations(range(3)):
        strang = it.splitting.Strang(body, args.h, ordering=ordering)
        timing = it.step_timing(strang, y0s, min_seconds=args.min_seconds, repeats=args.repeats,
                                outputs=args.outputs)
        rows.append({
            "ordering": "".join(str(k + 1) for k in ordering),
            "seconds_per_step": timing.seconds_per_step,
            "flops_per_step": strang.cost().flops,
            "n_steps": timing.n_steps,
            "run_seconds": list(timing.run_seconds),
        })
    load_after = os.getloadavg()
    default = rows[0]
    for r in rows:
        r["cost_vs_default"] = r["seconds_per_step"] / default["seconds_per_step"]
        r["flops_vs_default"] = r["flops_per_step"] / default["flops_per_step"]
    costs = [r["seconds_per_step"] for r in rows]
    spread = max(costs) / min(costs)
    within = spread <= TOLERANCE

    print(f"Strang orderings, rigid body I = (1, 2, 3), h = {args.h:g}, {args.n_traj} trajectories "
          f"(load average {load_before[0]:.2f} before, {load_after[0]:.2f} after)")
    print("| ordering | s / step | cost / default | flops / default | steps per run |")
    print("|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['ordering']} | {r['seconds_per_step']:.3g} | {r['cost_vs_default']:.3f} | "
              f"{r['flops_vs_default']:.2f} | {r['n_steps']} |")
    print(f"largest / smallest cost: {spread:.3f} ({'within' if within else 'NOT within'} {TOLERANCE}x)")

    result = {
        "command": " ".join(["python -m benchmarks.strang_orderings", *(sys.argv[1:] if argv is None else argv)]),
        "system": "RigidBody(inertia=(1.0, 2.0, 3.0))",
        "h": args.h,
        "n_trajectories": args.n_traj,
        "outputs": args.outputs,
        "min_seconds": args.min_seconds,
        "repeats": args.repeats,
        "load_average_before": list(load_before),
        "load_average_after": list(load_after),
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count(), "jax": jax.__version__},
        "rows": rows,
        "largest_over_smallest": spread,
        "tolerance": TOLERANCE,
        "within_tolerance": within,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1) + "\n")
    print(f"-> {args.out}")
    return 0 if within else 1


if __name__ == "__main__":
    raise SystemExit(main())
