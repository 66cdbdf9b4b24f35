"""Memory and time probe of `learn.fit_stream_operator` at N = 64, 128 (issue 65): Euler's
equations on the sphere (Zeitlin's model) observed at uneven times with noise 1e-3 of the field,
a spectrum per degree fitted with one start per trajectory. Not a test: run it under
`/usr/bin/time -v` for the peak RSS.

    PYTHONPATH=. /usr/bin/time -v python benchmarks/stream_operator_probe.py --N 64

Prints each stage's wall time (compilation included) and the identified spectrum's error.
"""

from __future__ import annotations

import argparse
import time

import equinox as eqx
import jax.numpy as jnp
import numpy as np

import learn
from integrators import Observations, add_field_noise
from liepoisson.systems import Zeitlin


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--N", type=int, default=64)
    parser.add_argument("--trajectories", type=int, default=2)
    parser.add_argument("--snapshots", type=int, default=6)
    parser.add_argument("--iterations", type=int, default=10, help="Levenberg-Marquardt iterations at most")
    parser.add_argument("--no-standard-errors", action="store_true")
    args = parser.parse_args()
    N = args.N
    system = Zeitlin(N)
    start = time.perf_counter()
    rng = np.random.default_rng(0)
    times = [np.concatenate([[0.0], np.cumsum(rng.uniform(0.02, 0.05, args.snapshots - 1))])
             for _ in range(args.trajectories)]
    truth = learn.StreamOperator(system, "degree", tol=1e-12, iterations=12)
    roll = eqx.filter_jit(lambda m, y, d: m.rollout_intervals(y, d))
    clean = []
    for j, t in enumerate(times):
        y0 = system.random_state(j, lmax=min(N - 1, 20), decay=0.5)
        clean.append(np.asarray(roll(truth, jnp.asarray(y0), jnp.asarray(np.diff(t)))))
    data = add_field_noise(Observations(system, times, clean), 1e-3, seed=1)
    moved = np.mean([np.linalg.norm(c[-1] - c[0]) / np.linalg.norm(c[0]) for c in clean])
    print(f"N = {N} (dimension {system.dim}): {args.trajectories} trajectories of {args.snapshots} snapshots, "
          f"fields moved {moved:.2f} of their norm; data made in {time.perf_counter() - start:.1f} s", flush=True)
    l = np.arange(1, N)
    guess = -(l * (l + 1.0)) * (1 + 0.2 * np.sin(l))  # a wrong start, the gauge (degree 1) at the truth's
    guess[0] = -2.0
    model = learn.StreamOperator(system, learn.DegreeSpectrum(guess), tol=1e-10, iterations=6)
    start = time.perf_counter()
    fit = learn.fit_stream_operator(model, data, iterations=args.iterations, rtol=1e-8, standard_errors=False,
                                    progress=True)
    elapsed = time.perf_counter() - start
    print(f"Levenberg-Marquardt: {elapsed:.1f} s (compilation included)", flush=True)
    if not args.no_standard_errors:
        start = time.perf_counter()
        fit = learn.fit_stream_operator(fit.model, data, iterations=1, rtol=1e-8, starts=fit.starts, progress=True)
        print(f"one more iteration and the standard errors: {time.perf_counter() - start:.1f} s", flush=True)
    true = -(l * (l + 1.0))
    error = np.abs(fit.values - true) / np.abs(true)
    z = np.abs(fit.values - true)[1:] / fit.standard_errors[1:]
    print(f"fit: {fit.iterations} iterations ({fit.stopped}), noise {fit.noise:.3g}; "
          f"largest relative error of the spectrum {error.max():.3g}; largest |error|/SE {np.nanmax(z):.3g}",
          flush=True)


if __name__ == "__main__":
    main()
