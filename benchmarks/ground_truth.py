"""Ground truth: heyoka Taylor (ours) against SciPy DOP853 and SciPy BDF (the paper's ground
truth), rtol 1e-13 / atol 1e-14, on the same rigid-body initial conditions, in one run.

    python -m benchmarks.ground_truth [--n-traj 1000] [--scipy-subset 20] [--t-final 100] [--h 0.1]
                                      [--out benchmarks/results/ground_truth.json]

The SciPy integrators get the fastest right-hand side we can give them: heyoka `cfunc`s
compiled from the same symbolic ODE (`system.heyoka_system()`), and BDF the analytic Jacobian
(`hy.diff` of that right-hand side), so they are not slowed down by Python arithmetic or finite
differences. SciPy is run on the first `--scipy-subset` initial conditions and its time scaled
per trajectory to `--n-traj` (printed as such). Writes the figures to `--out` (JSON).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import integrators as it
import liepoisson as lp
from benchmarks._report import default_out, write_json


def scipy_rhs(system):
    """Compiled rhs and Jacobian from the system's symbolic ODE, as SciPy callables."""
    import heyoka as hy

    ys, rhs = zip(*system.heyoka_system())
    f = hy.cfunc(list(rhs), vars=list(ys))
    jac = hy.cfunc([hy.diff(r, v) for r in rhs for v in ys], vars=list(ys))
    n = system.dim
    return (lambda t, y: f(y)), (lambda t, y: jac(y).reshape(n, n))


def run_scipy(method, system, y0s, t_eval, rtol, atol):
    from scipy.integrate import solve_ivp

    fun, jac = scipy_rhs(system)
    kwargs = {"jac": jac} if method == "BDF" else {}
    out = np.empty((len(y0s), len(t_eval), system.dim))
    start = time.perf_counter()
    for i, y0 in enumerate(y0s):
        sol = solve_ivp(fun, (0.0, t_eval[-1]), y0, method=method, t_eval=t_eval, rtol=rtol, atol=atol, **kwargs)
        if not sol.success:
            raise RuntimeError(f"{method} failed on trajectory {i}: {sol.message}")
        out[i] = sol.y.T
    return out, time.perf_counter() - start


def casimir_drift(system, states):
    """max over trajectories and times of |C(t) - C(0)| / |C(0)| (C = |Pi|^2)."""
    C = np.asarray(system.casimirs(states))[..., 0]
    return float(np.max(np.abs(C - C[:, :1]) / np.abs(C[:, :1])))


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m benchmarks.ground_truth", description=__doc__.splitlines()[0])
    parser.add_argument("--n-traj", type=int, default=1000)
    parser.add_argument("--scipy-subset", type=int, default=20)
    parser.add_argument("--t-final", type=float, default=100.0)
    parser.add_argument("--h", type=float, default=0.1)
    parser.add_argument("--out", type=Path, default=default_out("ground_truth"), help="JSON file written")
    args = parser.parse_args(argv)

    system = lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0))
    y0s = np.random.default_rng(0).uniform(-2.0, 2.0, size=(args.n_traj, 3))
    n_steps = round(args.t_final / args.h)
    t_eval = args.h * np.arange(n_steps + 1)
    rtol, atol = 1e-13, 1e-14
    n_sub = min(args.scipy_subset, args.n_traj)
    print(f"rigid body I = diag(1, 2, 3), {args.n_traj} ICs uniform in [-2, 2]^3 (seed 0), "
          f"t = 0..{args.t_final}, output every h = {args.h}")

    start = time.perf_counter()
    it.taylor_integrator(system)  # compile (cached afterwards)
    t_compile = time.perf_counter() - start
    start = time.perf_counter()
    ours = it.ground_truth(system, y0s, h=args.h, n_steps=n_steps, progress=False)
    t_ours = time.perf_counter() - start
    t_ours_total = t_ours + t_compile
    drift_ours = casimir_drift(system, ours.states)
    drift_ours_sub = casimir_drift(system, ours.states[:n_sub])
    print(f"heyoka Taylor (tol = eps), loop over one integrator: {t_ours:.3f} s for {args.n_traj} "
          f"trajectories ({1e3 * t_ours / args.n_traj:.3f} ms each) + {t_compile:.2f} s compilation")

    # heyoka's ensemble mode (threads, one integrator copy per thread) for comparison
    import heyoka as hy

    ta = it.taylor_integrator(system)

    def gen(ta_copy, i):
        ta_copy.time = 0.0
        ta_copy.state[:] = y0s[i]
        return ta_copy

    start = time.perf_counter()
    hy.ensemble_propagate_grid(ta, t_eval, args.n_traj, gen)
    t_ensemble = time.perf_counter() - start
    print(f"heyoka ensemble_propagate_grid (threads): {t_ensemble:.3f} s "
          f"({t_ensemble / t_ours:.1f}x the loop)")

    results = {}
    scipy_runs = {}
    for method in ("DOP853", "BDF"):
        states, t = run_scipy(method, system, y0s[:n_sub], t_eval, rtol, atol)
        t_scaled = t * args.n_traj / n_sub
        err = float(np.max(np.abs(states - ours.states[:n_sub])))
        results[method] = (t_scaled, casimir_drift(system, states))
        scipy_runs[method] = {"seconds_subset": t, "seconds_scaled": t_scaled, "max_abs_diff_heyoka": err,
                              "casimir_drift": results[method][1]}
        print(f"SciPy {method} (rtol {rtol}, atol {atol}"
              f"{', analytic Jacobian' if method == 'BDF' else ''}): {t:.2f} s for {n_sub} "
              f"trajectories, scaled per trajectory to {args.n_traj}: {t_scaled:.1f} s; "
              f"max |y - y_heyoka| = {err:.2e}")

    print()
    print(f"{'method':<26}{'time, ' + str(args.n_traj) + ' traj [s]':>22}{'time ratio':>12}"
          f"{'rel. Casimir drift':>20}{'drift ratio':>13}")
    print(f"{'heyoka Taylor (ours)':<26}{t_ours:>22.3f}{1.0:>12.0f}{drift_ours:>20.2e}{1.0:>13.0f}")
    print(f"{'  incl. compilation':<26}{t_ours_total:>22.3f}")
    print(f"{'  on the SciPy subset':<26}{'':>22}{'':>12}{drift_ours_sub:>20.2e}")
    for method, (t, drift) in results.items():
        ratio_d = drift / max(drift_ours_sub, np.finfo(float).eps * 1e-3)
        print(f"{'SciPy ' + method + ' (scaled)':<26}{t:>22.1f}{t / t_ours:>12.0f}{drift:>20.2e}{ratio_d:>13.0f}")
    t_bdf, drift_bdf = results["BDF"]
    speed = t_bdf / t_ours_total
    better = drift_bdf / max(drift_ours_sub, drift_ours)
    verdict = "PASS" if speed >= 1000 and better >= 1000 else "FAIL"
    print(f"\nours vs BDF: {speed:.0f}x faster (including compilation), {better:.0f}x smaller "
          f"Casimir drift (ours over all {args.n_traj}) -> {verdict} (need >= 1000x both)")
    write_json(args.out, args, {
        "heyoka": {"seconds": t_ours, "compile_seconds": t_compile, "ensemble_seconds": t_ensemble,
                   "casimir_drift": drift_ours, "casimir_drift_scipy_subset": drift_ours_sub},
        "scipy": scipy_runs, "rtol": rtol, "atol": atol, "scipy_subset": n_sub,
        "speedup_vs_bdf_incl_compile": speed, "drift_ratio_bdf": better, "verdict": verdict,
    })


if __name__ == "__main__":
    main()
