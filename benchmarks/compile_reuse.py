"""Compilation reuse across step sizes: the first and the second step size of a study.

    python benchmarks/compile_reuse.py

Rollouts, Poisson defects and quasi-Newton losses take the step size h (and the spacing of the
saved outputs) as traced arguments, so a study over several h compiles once per map and
structure. Prints, for Kirchhoff (se(3)*, the W1 study's setting: 100 trajectories, 25 outputs
to t = 100, 1000 saved states over 10^4 steps), the wall time of each call at h = 0.1 (compile
+ run) and then at h = 0.2 (run only, if the compiled program is reused), and the same for a
symmetric G-LPNet fit (12 modules, BFGS, 100 iterations with the identity warm start).
"""

from __future__ import annotations

import time

import jax
import numpy as np

import integrators as it
import learn
import liepoisson as lp


def _timed(fn) -> float:
    t0 = time.perf_counter()
    jax.block_until_ready(fn())
    return time.perf_counter() - t0


def main() -> None:
    system = lp.systems.Kirchhoff(inertia=(1.0, 2.0, 1.0), mass=(1.0, 2.0, 1.0))  # W1's
    centre = np.array([1.0, 1.0, 1.0, -1.0, 1.0, 2.0])
    y0 = centre + np.random.default_rng(0).uniform(-0.1, 0.1, size=(100, 6))
    print("| call | h = 0.1 (s) | h = 0.2 (s) |")
    print("|---|---|---|")
    for cls in (it.splitting.Strang, it.splitting.Yoshida6, it.RK4, it.ImplicitMidpoint):
        rows = []
        for h in (0.1, 0.2):
            m = cls(system, h)
            n = round(100.0 / h)
            rows.append((_timed(lambda m=m, n=n: m.rollout(y0, n, save_every=n // 25)),
                         _timed(lambda m=m: m.rollout(y0, 10_000, save_every=10)),
                         _timed(lambda m=m: m.poisson_defect(y0[:50])),
                         _timed(lambda m=m: np.asarray(m.cost().flops))))
        for k, what in enumerate(("compare rollout (25 outputs)", "long rollout (10^4 steps)", "Poisson defect", "flop count")):
            print(f"| {cls.__name__} {what} | {rows[0][k]:.2f} | {rows[1][k]:.2f} |")
    data_y0 = centre + np.random.default_rng(1).uniform(-0.1, 0.1, size=(50, 6))
    fits = []
    for h in (0.1, 0.2):
        data = it.ground_truth(system, data_y0, h=h, n_steps=20, seed=0)
        t0 = time.perf_counter()
        learn.fit(learn.GLPNet(system, n_modules=12, key=0, method=it.splitting.Strang), data,
                  optimiser=learn.QuasiNewton(100, "bfgs", warm_start=True), validation_fraction=0.0, progress=False)
        fits.append(time.perf_counter() - t0)
    print(f"| G-LPNet (sym., 12 modules) BFGS fit, 100 iterations | {fits[0]:.2f} | {fits[1]:.2f} |")


if __name__ == "__main__":
    main()
