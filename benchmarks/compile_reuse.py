"""Compilation reuse across step sizes: the first and the second step size of a study.

    python -m benchmarks.compile_reuse [--n-traj 100] [--long-steps 10000] [--fit-modules 12] [--fit-iterations 100]
                                       [--out benchmarks/results/compile_reuse.json]

Rollouts, Poisson defects and quasi-Newton losses take the step size h (and the spacing of the
saved outputs) as traced arguments, so a study over several h compiles once per map and
structure. Prints, for Kirchhoff (se(3)*, the W1 study's setting: 100 trajectories, 25 outputs
to t = 100, 1000 saved states over 10^4 steps), the wall time of each call at h = 0.1 (compile
+ run) and then at h = 0.2 (run only, if the compiled program is reused), and the same for a
symmetric G-LPNet fit (12 modules, `method=Strang`, BFGS, 100 iterations with the identity
warm start). Writes the table to `--out` (JSON).
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


def _timed(fn) -> float:
    t0 = time.perf_counter()
    jax.block_until_ready(fn())
    return time.perf_counter() - t0


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.compile_reuse", description=__doc__.splitlines()[0])
    parser.add_argument("--n-traj", type=int, default=100, help="trajectories of the rollouts")
    parser.add_argument("--long-steps", type=int, default=10_000, help="steps of the long rollout (saved every 10)")
    parser.add_argument("--fit-modules", type=int, default=12, help="modules of the G-LPNet (its compile time)")
    parser.add_argument("--fit-iterations", type=int, default=100, help="BFGS iterations of the G-LPNet fit")
    parser.add_argument("--out", type=Path, default=default_out("compile_reuse"), help="JSON file written")
    args = parser.parse_args(argv)
    system = lp.systems.Kirchhoff(inertia=(1.0, 2.0, 1.0), mass=(1.0, 2.0, 1.0))  # W1's
    centre = np.array([1.0, 1.0, 1.0, -1.0, 1.0, 2.0])
    y0 = centre + np.random.default_rng(0).uniform(-0.1, 0.1, size=(args.n_traj, 6))
    table = []
    print("| call | h = 0.1 (s) | h = 0.2 (s) |")
    print("|---|---|---|")
    for cls in (it.splitting.Strang, it.splitting.Yoshida6, it.RK4, it.ImplicitMidpoint):
        rows = []
        for h in (0.1, 0.2):
            m = cls(system, h)
            n = round(100.0 / h)
            rows.append((_timed(lambda m=m, n=n: m.rollout(y0, n, save_every=n // 25)),
                         _timed(lambda m=m: m.rollout(y0, args.long_steps, save_every=10)),
                         _timed(lambda m=m: m.poisson_defect(y0[:50])),
                         _timed(lambda m=m: np.asarray(m.cost().flops))))
        long = "10^4" if args.long_steps == 10_000 else str(args.long_steps)
        for k, what in enumerate(("compare rollout (25 outputs)", f"long rollout ({long} steps)", "Poisson defect",
                                  "flop count")):
            print(f"| {cls.__name__} {what} | {rows[0][k]:.2f} | {rows[1][k]:.2f} |")
            table.append({"call": f"{cls.__name__} {what}", "h_0.1_s": rows[0][k], "h_0.2_s": rows[1][k]})
    data_y0 = centre + np.random.default_rng(1).uniform(-0.1, 0.1, size=(50, 6))
    fits = []
    for h in (0.1, 0.2):
        data = it.ground_truth(system, data_y0, h=h, n_steps=20, seed=0, progress=False)
        t0 = time.perf_counter()
        learn.fit(learn.GLPNet(system, n_modules=args.fit_modules, key=0, method=it.splitting.Strang), data,
                  optimiser=learn.KeepIfBetter(learn.WarmStart(learn.ScipyBFGS(args.fit_iterations))), validation_fraction=0.0,
                  progress=False)
        fits.append(time.perf_counter() - t0)
    what = f"G-LPNet (sym., {args.fit_modules} modules) BFGS fit, {args.fit_iterations} iterations"
    print(f"| {what} | {fits[0]:.2f} | {fits[1]:.2f} |")
    table.append({"call": what, "h_0.1_s": fits[0], "h_0.2_s": fits[1]})
    write_json(args.out, args, {"system": "Kirchhoff(inertia=(1, 2, 1), mass=(1, 2, 1))", "rows": table})


if __name__ == "__main__":
    main()
