"""Memory and time probe of `learn.fit_stream_operator` at N = 32 to 128 (issue 65): Euler's
equations on the sphere (Zeitlin's model) observed at uneven times with noise 1e-3 of the
field, a spectrum per degree fitted with one start per trajectory. The data are the model's
own map (`--composition`, one step per interval) at the true spectrum: the fit can reach the noise.
Not a test.

    PYTHONPATH=. python benchmarks/stream_operator_probe.py --N 64

Prints each Levenberg-Marquardt iteration (its solves' conjugate gradient steps and times, wall
and CPU: the CPU time of every thread, which a loaded machine does not inflate), the time spent
tracing and compiling (JAX's monitoring events, wall), the fit's wall and CPU time, its
iterations and final loss, the standard errors' time, the identified spectrum's error (over
the degrees the fields hold, `--lmax`, and over all), the peak RSS and the machine's load.
"""

from __future__ import annotations

import argparse
import os
import resource
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import learn
from integrators import Observations, add_field_noise
from liepoisson.systems import Zeitlin

_COMPILE_EVENTS = ("/jax/core/compile/jaxpr_trace_duration", "/jax/core/compile/jaxpr_to_mlir_module_duration",
                   "/jax/core/compile/backend_compile_duration")
compile_seconds = [0.0]


def _listener(event: str, duration: float, **kwargs) -> None:
    if event in _COMPILE_EVENTS:
        compile_seconds[0] += duration


def _load() -> str:
    return "load " + "/".join(f"{x:.1f}" for x in os.getloadavg())


def _timed(label: str, run):
    wall, cpu, compiled = time.perf_counter(), time.process_time(), compile_seconds[0]
    out = run()
    print(f"{label}: {time.perf_counter() - wall:.1f} s wall, {time.process_time() - cpu:.1f} s CPU, of which "
          f"{compile_seconds[0] - compiled:.1f} s wall tracing and compiling ({_load()})", flush=True)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--N", type=int, default=64)
    parser.add_argument("--trajectories", type=int, default=2)
    parser.add_argument("--snapshots", type=int, default=6)
    parser.add_argument("--lmax", type=int, default=20, help="the highest degree of the initial fields")
    parser.add_argument("--iterations", type=int, default=10, help="Levenberg-Marquardt iterations at most")
    parser.add_argument("--rtol", type=float, default=1e-8, help="the fit's rtol")
    parser.add_argument("--chi2-tol", type=float, default=0.01, help="the fit's chi2_tol (its default)")
    parser.add_argument("--composition", default=None,
                        help="the composition of midpoints of the model and of the truth (Suzuki, Yoshida6, ...; "
                             "default: one midpoint a step)")
    parser.add_argument("--no-standard-errors", action="store_true")
    args = parser.parse_args()
    jax.monitoring.register_event_duration_secs_listener(_listener)
    N = args.N
    system = Zeitlin(N)
    start = time.perf_counter()
    rng = np.random.default_rng(0)
    times = [np.concatenate([[0.0], np.cumsum(rng.uniform(0.02, 0.05, args.snapshots - 1))])
             for _ in range(args.trajectories)]
    truth = learn.StreamOperator(system, "degree", composition=args.composition, tol=1e-12, iterations=12)
    roll = eqx.filter_jit(lambda m, y, d: m.rollout_intervals(y, d))
    clean = []
    for j, t in enumerate(times):
        y0 = system.random_state(j, lmax=min(N - 1, args.lmax), decay=0.5)
        clean.append(np.asarray(roll(truth, jnp.asarray(y0), jnp.asarray(np.diff(t)))))
    data = add_field_noise(Observations(system, times, clean), 1e-3, seed=1)
    moved = np.mean([np.linalg.norm(c[-1] - c[0]) / np.linalg.norm(c[0]) for c in clean])
    print(f"N = {N} (dimension {system.dim}): {args.trajectories} trajectories of {args.snapshots} snapshots, "
          f"fields moved {moved:.2f} of their norm; data made in {time.perf_counter() - start:.1f} s ({_load()})",
          flush=True)
    l = np.arange(1, N)
    guess = -(l * (l + 1.0)) * (1 + 0.2 * np.sin(l))  # a wrong start, the gauge (degree 1) at the truth's
    guess[0] = -2.0
    model = learn.StreamOperator(system, learn.DegreeSpectrum(guess), composition=args.composition, tol=1e-10, iterations=6)
    fit = _timed("fit", lambda: learn.fit_stream_operator(model, data, iterations=args.iterations, rtol=args.rtol,
                                                          chi2_tol=args.chi2_tol, standard_errors=False,
                                                          progress=True))
    print(f"fit: {fit.iterations} iterations ({fit.stopped}), final loss {fit.losses[-1]:.6e} (noise^2 "
          f"{data.metadata['noise_std'] ** 2:.6e}), losses {' '.join(f'{v:.4e}' for v in fit.losses)}", flush=True)
    true = -(l * (l + 1.0))
    error = np.abs(fit.values - true) / np.abs(true)
    held = l <= args.lmax
    print(f"largest relative error of the spectrum: {error[held].max():.3g} over degrees <= {args.lmax}, "
          f"{error.max():.3g} over all", flush=True)
    if not args.no_standard_errors:
        fit = _timed("one more iteration and the standard errors",
                     lambda: learn.fit_stream_operator(fit.model, data, iterations=1, rtol=args.rtol,
                                                       chi2_tol=args.chi2_tol, starts=fit.starts, progress=True))
        with np.errstate(divide="ignore", invalid="ignore"):  # NaN where a standard error's solve failed
            z = (np.abs(fit.values - true) / fit.standard_errors)[1:]
        print(f"|error|/standard error: largest {np.nanmax(z[held[1:]]):.3g} over degrees <= {args.lmax}, "
              f"{np.nanmax(z):.3g} over all; noise {fit.noise:.3g}", flush=True)
    print(f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20:.2f} GB ({_load()})", flush=True)


if __name__ == "__main__":
    main()
