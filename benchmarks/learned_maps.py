"""Rollout throughput of every step map, learned and classical, measured in one run.

    python -m benchmarks.learned_maps [--n-traj 1000] [--n-steps 10000] [--repeats 3]
                                      [--out benchmarks/results/learned_maps.json]

Prints, for the rigid body I = diag(1, 2, 3) at h = 0.1 and `n_traj` trajectories x `n_steps`
steps: wall time, trajectory-steps per second, the cost of a step relative to one Strang step,
XLA's flop count of one step, the achieved flop rate, and that rate as a fraction of the
machine's float64 matmul rate (a 2000 x 2000 numpy matmul, measured in the same run). The
networks are untrained: the cost of a step does not depend on the weights. Writes the table
to `--out` (JSON).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import jax
import numpy as np

import integrators as it
import learn
import liepoisson as lp
from benchmarks._report import default_out, write_json


def _timed(fn, repeats: int = 3) -> float:
    jax.block_until_ready(fn())  # compile and warm up
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        best = min(best, time.perf_counter() - t0)
    return best


def machine_flop_rate(n: int = 2000, repeats: int = 5) -> float:
    """float64 flop/s of a large numpy matmul (2 n^3 flops), the best of `repeats`."""
    a = np.random.default_rng(0).normal(size=(n, n))
    b = np.random.default_rng(1).normal(size=(n, n))
    return 2.0 * n**3 / _timed(lambda: a @ b, repeats)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.learned_maps", description=__doc__.splitlines()[0])
    parser.add_argument("--n-traj", type=int, default=1000)
    parser.add_argument("--n-steps", type=int, default=10_000)
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per map after a warm-up (the best counts)")
    parser.add_argument("--out", type=Path, default=default_out("learned_maps"), help="JSON file written")
    args = parser.parse_args(argv)
    system = lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0))
    h = 0.1
    y0 = np.random.default_rng(0).uniform(-1.25, 1.25, size=(args.n_traj, 3))
    maps = {
        "Strang": it.splitting.Strang(system, h),
        "LieTrotter": it.splitting.LieTrotter(system, h),
        "TripleJump": it.splitting.TripleJump(system, h),
        "Suzuki": it.splitting.Suzuki(system, h),
        "McLachlan4": it.splitting.McLachlan4(system, h),
        "Yoshida6": it.splitting.Yoshida6(system, h),
        "RK4": it.RK4(system, h),
        "ImplicitMidpoint": it.ImplicitMidpoint(system, h),
        "Exact (elliptic)": it.ExactFlow(system, h),
        # Untrained weights: the cost of a step does not depend on their values.
        "LPNet 3x16": learn.LPNet(system, hidden=(16, 16, 16), key=0, h=h),
        "MLP baseline 3x16": learn.MLPBaseline(system, hidden=(16, 16, 16), key=0, h=h),
        "G-LPNet 6 modules": learn.GLPNet(system, n_modules=6, key=0, h=h),
        "G-LPNet 6 sym.": learn.GLPNet(system, n_modules=6, key=0, h=h, method=it.splitting.Strang),
    }
    peak = machine_flop_rate()
    work = args.n_traj * args.n_steps
    times = {name: _timed(lambda m=m: m.rollout(y0, args.n_steps, save_every=args.n_steps), args.repeats)
             for name, m in maps.items()}
    print(f"rigid body, {args.n_traj} trajectories x {args.n_steps} steps, jitted lax.scan + vmap, float64; "
          f"machine: {peak / 1e9:.1f} GFLOP/s (2000x2000 numpy matmul, same run)")
    print(f"{'method':20s} {'wall [s]':>9s} {'traj-steps/s':>13s} {'cost/Strang':>12s} "
          f"{'flops/step':>11s} {'GFLOP/s':>8s} {'% of matmul':>12s} {'exact flows':>12s}")
    rows = []
    for name, m in maps.items():
        t, cost = times[name], m.cost()
        rate = cost.flops * work / t
        print(f"{name:20s} {t:9.3f} {work / t:13.3e} {t / times['Strang']:12.2f} {cost.flops:11.0f} "
              f"{rate / 1e9:8.3f} {100 * rate / peak:11.2f}% {cost.exact_flows:12d}")
        rows.append({"method": name, "wall_s": t, "trajectory_steps_per_s": work / t,
                     "cost_per_strang": t / times["Strang"], "flops_per_step": cost.flops, "gflops_per_s": rate / 1e9,
                     "fraction_of_matmul": rate / peak, "exact_flows": cost.exact_flows})
    write_json(args.out, args, {"system": "RigidBody(inertia=(1, 2, 3))", "h": h, "matmul_gflops_per_s": peak / 1e9,
                                "rows": rows})


if __name__ == "__main__":
    main()
