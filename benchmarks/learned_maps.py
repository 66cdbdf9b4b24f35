"""Cost of learned maps against classical splitting, measured in one run.

    python benchmarks/learned_maps.py [--n-traj 1000] [--n-steps 10000]

Prints the rollout throughput (trajectory-steps per second) of an LPNet (3x16), a G-LPNet
(6 modules) and the classical `Strang` splitting of the rigid body for `n_traj` trajectories x
`n_steps` steps, and the cost of one step of each relative to one Strang step. The networks
are untrained: the cost of a step does not depend on the weights.
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np

import integrators as it
import learn
import liepoisson as lp


def _timed(fn, repeats: int = 3) -> float:
    jax.block_until_ready(fn())  # compile and warm up
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        best = min(best, time.perf_counter() - t0)
    return best


def main(argv=None) -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--n-traj", type=int, default=1000)
    parser.add_argument("--n-steps", type=int, default=10_000)
    args = parser.parse_args(argv)
    system = lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0))
    h = 0.1
    y0 = np.random.default_rng(0).uniform(-1.25, 1.25, size=(args.n_traj, 3))
    # Untrained weights: the cost of a step does not depend on their values.
    lpnet = learn.LPNet(system, hidden=(16, 16, 16), key=0, h=h)
    glpnet = learn.GLPNet(system, n_modules=6, key=0, h=h)
    strang = it.splitting.Strang(system, h=h)

    work = args.n_traj * args.n_steps
    rows = []
    t_strang = _timed(lambda: strang.rollout(y0, args.n_steps))
    for name, fn in (
        ("Strang (classical)", None),
        ("LPNet 3x16", lambda: lpnet.rollout(y0, args.n_steps)),
        ("G-LPNet 6 modules", lambda: glpnet.rollout(y0, args.n_steps)),
    ):
        t = t_strang if fn is None else _timed(fn)
        rows.append((name, t, work / t, t / t_strang))
    print(f"rigid body, {args.n_traj} trajectories x {args.n_steps} steps, jitted lax.scan + vmap, float64")
    print(f"{'method':22s} {'wall time [s]':>14s} {'traj-steps/s':>14s} {'cost / Strang step':>20s} "
          f"{'XLA flops/step':>15s} {'exact flows':>12s}")
    for (name, t, rate, rel), m in zip(rows, (strang, lpnet, glpnet)):
        cost = m.cost()
        print(f"{name:22s} {t:14.3f} {rate:14.3e} {rel:20.2f} {cost.flops:15.0f} {cost.exact_flows:12d}")


if __name__ == "__main__":
    main()
