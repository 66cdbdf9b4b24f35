r"""The error of `learn.StreamOperator`'s orders at a given cost (BENCHMARKS.md, "Fluids from
data"): Euler's equations on the sphere (Zeitlin's model at the Laplacian's spectrum, N = 16),
a random field with every degree (W8's training field, unit harmonic norm: one eddy turnover
is t = 1) run to t = 1 in `n` equal steps per interval of 0.1, against heyoka's Taylor method
at machine precision; the cost is the midpoints (each one stage iteration to 1e-13) per eddy
turnover. Beside the three orders, Yoshida's triple jump of the midpoint
(`integrators.IsospectralTripleJump`), the order-4 composition the library had before.

    python -m benchmarks.stream_operator_orders [--N 16]
    python -m benchmarks.stream_operator_orders --report
    python -m benchmarks.stream_operator_orders --w8-limit
    python -m benchmarks.stream_operator_orders --step-bias --N 32 --composition Suzuki --fit-step 0.15 --cg-rtol 1e-4 \
        --se-rtol 1e-2
    python -m benchmarks.stream_operator_orders --step-bias --N 32 --composition Yoshida6 --fit-step 0.075 \
        --se-from benchmarks/results/stream_operator_orders_step_bias_N32_Suzuki_0.15.json
    python -m benchmarks.stream_operator_orders --step-bias --N 32 --truth rotating --composition Yoshida6 \
        --fit-step 0.15
    python -m benchmarks.stream_operator_orders --step-bias --N 32 --truth rotating --composition Yoshida6 \
        --fit-step 0.075 --se-from benchmarks/results/stream_operator_orders_step_bias_N32_rotating_Yoshida6_0.15.json

`--w8-limit`: what the step's error does to a fit, W8's limit (the quasi-geostrophic family,
F from 0) on W8's Euler data at N = 16, noise 1e-3 (the quick profile's condition), at order 2
with steps of at most 0.05 eddy turnovers and at orders 4 and 6 with one step an interval
(0.15): F with its standard error, |F|/SE, the fit's time and the field error at one eddy
turnover (`benchmarks/results/stream_operator_orders_w8_limit.json`).

`--step-bias`: the same for W8's learned spectrum per degree at the full profile's sizes: fitted
to the clean training snapshots from the truth, its deviation is the step's bias, reported over
the standard errors the fit has at noise 1e-3 (`step_bias`). `--truth rotating`: on the rotating
sphere, with the rotation, steps of at most `fit_step` times $1/(2\Omega)$ (W8's
`Condition.max_step`): `--fit-step 0.15` is the 0.075 eddy turnovers the full profile had there
before. Computed with standard errors (no `--se-from`), the fit's own estimate of the bias,
`learn.StreamOperatorFit.step_bias`, is printed and saved beside it (`estimated_bias`).

`--courant`: why W8's steps shorten above N = 32 (`paper.w8_fluids.Condition.max_step`): the
full profile's composition over one interval of 0.15 eddy turnovers (W8's longest) from W8's
first Euler training field, at N = 32 and 64, in 1, 2 and 4 steps against 16 (order 6: their
own error is about 1e-8 of the 4 steps'), and at each size's `max_step`:

    python -m benchmarks.stream_operator_orders --courant

`--se-solves`: what the standard errors' solves cost and how exact they are (`se_solves`): W8's
Euler training data at noise 1e-3, fitted without standard errors, then the profiled
Gauss-Newton matrix (`learn._training._stream_fit._profiled`, what `fit_stream_operator` does
after its last iteration) at each `--se-rtols` tolerance and each `--se-coarse-degrees`
preconditioner (`fit_stream_operator`'s `se_coarse_degree`; 0: none), its CPU time (the
preconditioner's coarse block included) and conjugate gradient steps, and the standard errors'
largest relative deviation from those at the tightest tolerance without a preconditioner:

    python -m benchmarks.stream_operator_orders --se-solves --N 32 --composition Suzuki --fit-step 0.15 \
        --se-rtols 1e-3 1e-2 1e-6 --se-coarse-degrees 0 5
"""

from __future__ import annotations

import argparse

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import learn
from integrators import IsospectralTripleJump, ground_truth
from liepoisson.systems import Zeitlin

from ._report import add_output_arguments, default_out, saved_results, write_json

NAME = "stream_operator_orders"
STEPS = (1, 2, 3, 4, 6)  # steps per interval of 0.1
COMPOSITIONS = {2: None, 4: "Suzuki", 6: "Yoshida6"}  # by order: learn.StreamOperator's composition
CG_MAX_STEPS = 200  # fit_stream_operator's default cg_max_steps


def measure(N: int) -> list[dict]:
    jax.config.update("jax_enable_x64", True)
    system = Zeitlin(N)
    y0 = system.random_state(100, lmax=N - 1, decay=0.5)  # W8's first training field
    exact = ground_truth(system, y0, 1.0, 1, progress=False).states[0, -1]
    roll = eqx.filter_jit(lambda m, y, n: m.rollout_intervals(y, jnp.full(10, 0.1), n))
    results = []
    for composition in COMPOSITIONS.values():
        model = learn.StreamOperator(system, composition=composition, tol=1e-13, iterations=16)
        for n in STEPS:
            y = np.asarray(roll(model, jnp.asarray(y0), n))[-1]
            results.append({"method": f"order {model.order}", "midpoints_per_tau": 10 * n * len(model.substeps),
                            "error": float(np.linalg.norm(y - exact) / np.linalg.norm(exact))})
    for n in STEPS:
        method = IsospectralTripleJump(system, 0.1 / n, tol=1e-13)
        y = np.asarray(method.rollout(y0, 10 * n))[-1]
        results.append({"method": "triple jump", "midpoints_per_tau": 30 * n,
                        "error": float(np.linalg.norm(y - exact) / np.linalg.norm(exact))})
    return results


def w8_limit() -> list[dict]:
    import tempfile
    import time
    from pathlib import Path

    from paper import w8_fluids as w8

    results = []
    for order, fit_step in ((2, 0.05), (4, 0.15), (6, 0.15)):
        P = w8.PROFILES["quick"].replace(composition=COMPOSITIONS[order], fit_step=fit_step)
        condition = w8.Condition(16, w8.TRUTHS["Euler"], 1e-3, P)
        with tempfile.TemporaryDirectory() as folder:
            condition.folder = Path(folder)
            data = condition.data  # written and read back before the clock starts
            start = time.perf_counter()
            fitted = w8.LimitModel(P.lm_iterations).fit(condition, data)
            seconds = time.perf_counter() - start
            starts, reference = condition.test
            forecast = fitted.predict(starts, condition.step, reference.shape[1] - 1)
        error = np.linalg.norm(forecast - reference, axis=-1) / np.linalg.norm(reference, axis=-1)
        results.append({"order": order, "fit_step": fit_step, "F": fitted.parameters, "z": fitted.z,
                        "fit_seconds": seconds, "error_at_tau": float(error[:, condition.steps].mean())})
        print(f"order {order}, steps <= {fit_step} tau: {fitted.parameters}, |F|/SE {fitted.z:.3g}, fit {seconds:.0f} s, "
              f"field error at tau {results[-1]['error_at_tau']:.3g}", flush=True)
    return results


def step_bias(N: int, composition: str | None, fit_step: float, se_from: str | None, cg_rtol: float,
              se_rtol: float, truth: str = "Euler") -> dict:
    r"""The step's bias of W8's learned spectrum per degree (W8's `truth`, its full-profile
    training fields and clock at size `N`; on the rotating truth the rotation too, and steps of
    W8's `Condition.max_step`, `fit_step` times $1/(2\Omega)$): the fit on the CLEAN snapshots
    from the truth, whose deviation is the bias, over the standard errors at noise 1e-3 (the
    clean fit's, scaled from its residual noise to 1e-3's noise; or read from `se_from`, an
    earlier run's results: they hardly depend on the step)."""
    import time

    import integrators as it
    from paper import w8_fluids as w8

    P = w8.PROFILES["full"].replace(composition=composition, fit_step=fit_step)
    condition = w8.Condition(N, w8.TRUTHS[truth], 1e-3, P)
    rotation = condition.truth.rotation
    clean = np.asarray(w8._rollouts(condition.truth.model(condition.system),
                                    jnp.asarray(condition._fields(w8.TRAIN_SEED, P.n_train)),
                                    jnp.asarray(np.diff(condition.clock)), P.fine))
    data = it.Observations(condition.system, [condition.clock] * P.n_train, list(clean))
    sigma = it.add_field_noise(data, 1e-3, seed=w8.NOISE_SEED).metadata["noise_std"]
    true = condition.truth.degree_values(N)
    model = learn.StreamOperator(condition.system, learn.DegreeSpectrum(true, reference_degree=N - 1),
                                 rotation=rotation, composition=composition, tol=w8.MODEL_TOL, iterations=6)
    start = time.perf_counter()
    fit = learn.fit_stream_operator(model, data, max_step=condition.max_step, iterations=3, rtol=1e-14,
                                    chi2_tol=0.0, cg_rtol=cg_rtol, standard_errors=se_from is None, se_rtol=se_rtol,
                                    progress=True)
    seconds = time.perf_counter() - start
    if se_from is None:
        se = np.asarray(fit.standard_errors) / fit.noise * sigma
        rotation_se = None if rotation is None else float(fit.rotation_standard_error) / fit.noise * sigma
    else:
        saved = saved_results(se_from)[-1]
        se, rotation_se = np.asarray(saved["standard_errors"]), saved.get("rotation_standard_error")
    bias = np.asarray(fit.values) - true
    z = np.abs(bias[:-1]) / se[:-1]  # the last degree is the gauge's reference (not fitted)
    words = ""
    if rotation is not None:
        rotation_bias = float(fit.rotation) - rotation
        words = f"; rotation's bias/SE {abs(rotation_bias) / rotation_se:.2g}"
    print(f"N = {N}, {truth}, {composition or 'midpoint'}, steps <= {condition.max_step:.4g} ({fit.substeps} an "
          f"interval): bias/SE at noise 1e-3 by degree {np.array2string(z, precision=2, max_line_width=150)}; max "
          f"{z.max():.3g} at degree {int(np.argmax(z)) + 1}{words}; fit {seconds:.0f} s", flush=True)
    result = {"N": N, "truth": truth, "composition": composition, "fit_step": fit_step,
              "max_step": condition.max_step, "substeps": fit.substeps, "bias": bias.tolist(),
              "standard_errors": se.tolist(), "z": z.tolist(), "fit_seconds": seconds}
    if rotation is not None:
        result.update(rotation_bias=rotation_bias, rotation_standard_error=rotation_se)
    if se_from is None:  # the fit's own estimate of the same bias (learn.StreamOperatorFit.step_bias)
        estimate = np.asarray(fit.step_bias)
        worst = int(np.argmax(np.abs(bias[:-1])))
        print(f"  the fit's estimate of it (step_bias): by degree "
              f"{np.array2string(np.abs(estimate[:-1]) / se[:-1], precision=2, max_line_width=150)}; at degree "
              f"{worst + 1} {estimate[worst]:.3g} against the bias {bias[worst]:.3g}"
              + ("" if rotation is None else f"; rotation {fit.rotation_step_bias:.3g} against {rotation_bias:.3g}"),
              flush=True)
        result.update(estimated_bias=estimate.tolist(),
                      **({} if rotation is None else {"estimated_rotation_bias": fit.rotation_step_bias}))
    return result


def se_solves(N: int, composition: str | None, fit_step: float, rtols: list[float],
              coarse_degrees: tuple[int, ...] = (0,)) -> list[dict]:
    """The standard errors' solves at each of `rtols` and `coarse_degrees` (module docstring,
    `--se-solves`), of the fitted inverse eigenvalues (their relative deviations are those of
    the eigenvalues')."""
    import time

    import integrators as it
    from learn._training import _stream_fit as fitting
    from paper import w8_fluids as w8

    P = w8.PROFILES["full"].replace(composition=composition, fit_step=fit_step)
    condition = w8.Condition(N, w8.TRUTHS["Euler"], 1e-3, P)
    clean = np.asarray(w8._rollouts(condition.truth.model(condition.system),
                                    jnp.asarray(condition._fields(w8.TRAIN_SEED, P.n_train)),
                                    jnp.asarray(np.diff(condition.clock)), P.fine))
    data = it.add_field_noise(it.Observations(condition.system, [condition.clock] * P.n_train, list(clean)), 1e-3,
                              seed=w8.NOISE_SEED)
    true = -np.arange(1, N) * np.arange(2, N + 1.0)
    model = learn.StreamOperator(condition.system, learn.DegreeSpectrum(true, reference_degree=N - 1),
                                 composition=composition, tol=w8.MODEL_TOL, iterations=6)
    fit = learn.fit_stream_operator(model, data, max_step=fit_step * condition.tau, iterations=P.lm_iterations,
                                    standard_errors=False, progress=True)
    fitted = eqx.tree_at(lambda m: m.h, fit.model, None, is_leaf=lambda v: v is None)
    padded, starts = fitting._padded(data), jnp.asarray(fit.starts)
    state = fitting._linearisation(fitted, starts, padded, fit.substeps, None)
    counts = jnp.sum(padded.mask, axis=1)
    results = []
    jax.block_until_ready(fitting._profiled(fitted, starts, padded, state.J_theta, state.A, counts, fit.substeps,
                                            jnp.asarray(0.5), CG_MAX_STEPS))  # compiled once for the timings
    for rtol, degree in sorted(((r, d) for r in rtols for d in coarse_degrees), key=lambda rd: (-rd[0], -rd[1])):
        if degree:  # compiled once for the timings
            jax.block_until_ready(fitting._profiled(fitted, starts, padded, state.J_theta[..., :4], state.A[:4, :4],
                                                    counts, fit.substeps, jnp.asarray(0.5), CG_MAX_STEPS, degree))
        wall, cpu = time.perf_counter(), time.process_time()
        profiled, steps, _ = fitting._profiled(fitted, starts, padded, state.J_theta, state.A, counts, fit.substeps,
                                            jnp.asarray(rtol), CG_MAX_STEPS, degree)
        variances = np.diag(fit.noise**2 * np.linalg.inv(np.asarray(profiled)))
        # of the fitted inverse eigenvalues, degrees 1..N - 2 (the gauge's reference N - 1 is held)
        se = np.where(variances >= 0, np.sqrt(np.abs(variances)), np.nan)
        results.append({"N": N, "composition": composition, "fit_step": fit_step, "rtol": rtol, "coarse_degree": degree,
                        "wall_seconds": time.perf_counter() - wall, "cpu_seconds": time.process_time() - cpu,
                        "steps": np.asarray(steps).tolist(), "inverse_standard_errors": se.tolist()})
    tightest = np.asarray(results[-1]["inverse_standard_errors"])
    for r in results:
        deviation = np.abs(np.asarray(r["inverse_standard_errors"]) / tightest - 1.0)
        r["deviation_max"], r["deviation_median"] = float(deviation.max()), float(np.median(deviation))
        r["deviation_degree"] = int(np.argmax(deviation)) + 1
        print(f"se_rtol {r['rtol']:g}, se_coarse_degree {r['coarse_degree']}: {r['cpu_seconds']:.0f} s CPU ({r['wall_seconds']:.0f} s wall), "
              f"{sum(r['steps'])} CG steps ({min(r['steps'])}-{max(r['steps'])} a column); standard errors "
              f"within {r['deviation_max']:.1e} of rtol {min(rtols):g}'s (degree {r['deviation_degree']}; "
              f"median {r['deviation_median']:.1e})", flush=True)
    return results


def courant(sizes: tuple[int, ...] = (32, 64)) -> list[dict]:
    """The step's error over one interval by size and step (module docstring, `--courant`)."""
    import math

    from paper import w8_fluids as w8

    jax.config.update("jax_enable_x64", True)
    P = w8.PROFILES["full"]
    results = []
    for N in sizes:
        condition = w8.Condition(N, w8.TRUTHS["Euler"], 1e-3, P)
        tau, y0 = condition.tau, jnp.asarray(condition._fields(w8.TRAIN_SEED, 1)[0])
        model = learn.StreamOperator(condition.system, composition=P.composition, tol=1e-13, iterations=16)
        interval = jnp.full(1, 0.15 * tau)
        roll = eqx.filter_jit(lambda m, y, dt, n: m.rollout_intervals(y, dt, n))
        reference = np.asarray(roll(model, y0, interval, 16))[-1]
        own = math.ceil(0.15 * tau / condition.max_step - 1e-12)
        for n in sorted({1, 2, 4, own}):
            y = np.asarray(roll(model, y0, interval, n))[-1]
            error = float(np.linalg.norm(y - reference) / np.linalg.norm(reference))
            results.append({"N": N, "steps": n, "step_over_tau": 0.15 / n, "max_step": n == own, "error": error})
            print(f"N = {N}, {n} step(s) of {0.15 / n:.4g} tau{' (its max_step)' if n == own else ''}: "
                  f"relative error {error:.2e}", flush=True)
    return results


def report(results: list[dict]) -> None:
    print("method        midpoints per tau: relative error at tau")
    for method in dict.fromkeys(r["method"] for r in results):
        rows = [r for r in results if r["method"] == method]
        print(f"{method:<13s} " + " | ".join(f"{r['midpoints_per_tau']}: {r['error']:.2e}" for r in rows))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--N", type=int, default=16)
    parser.add_argument("--w8-limit", action="store_true", help="the step's bias in W8's limit (module docstring)")
    parser.add_argument("--step-bias", action="store_true",
                        help="the step's bias of W8's learned spectrum per degree (module docstring)")
    parser.add_argument("--composition", default="Suzuki", help="--step-bias: the model's (None: the midpoint)")
    parser.add_argument("--truth", default="Euler", help="--step-bias: W8's truth (paper.w8_fluids.TRUTHS)")
    parser.add_argument("--fit-step", type=float, default=0.15, help="--step-bias: the longest step, eddy turnovers")
    parser.add_argument("--se-from", default=None, help="--step-bias: the standard errors of an earlier run's file")
    parser.add_argument("--cg-rtol", type=float, default=1e-8, help="--step-bias: fit_stream_operator's cg_rtol")
    parser.add_argument("--se-rtol", type=float, default=1e-3, help="--step-bias: fit_stream_operator's se_rtol")
    parser.add_argument("--courant", action="store_true", help="the step's error by size (module docstring)")
    parser.add_argument("--se-solves", action="store_true", help="the standard errors' solves (module docstring)")
    parser.add_argument("--se-rtols", type=float, nargs="+", default=[1e-3, 1e-2, 1e-6],
                        help="--se-solves: the tolerances (the tightest the reference)")
    parser.add_argument("--se-coarse-degrees", type=int, nargs="+", default=[0],
                        help="--se-solves: the preconditioners' degrees (0: none, the reference's)")
    add_output_arguments(parser, NAME)
    args = parser.parse_args(argv)
    if args.step_bias or args.se_solves:
        composition = None if args.composition == "None" else args.composition
        kind = "step_bias" if args.step_bias else "se_solves"
        truth = "" if args.truth == "Euler" else f"_{args.truth.replace(' ', '').replace('=', '')}"
        tag = f"{NAME}_{kind}_N{args.N}{truth}_{composition or 'midpoint'}_{args.fit_step:g}"
        out = args.out if args.out != default_out(NAME) else default_out(tag)
        if args.report:
            for r in saved_results(out):
                print(r)
        elif args.step_bias:
            write_json(out, args, [step_bias(args.N, composition, args.fit_step, args.se_from, args.cg_rtol,
                                             args.se_rtol, args.truth)])
        else:
            write_json(out, args, se_solves(args.N, composition, args.fit_step, args.se_rtols,
                                                  tuple(args.se_coarse_degrees)))
        return
    for flag, measured in (("courant", courant), ("w8_limit", w8_limit)):  # modes without options
        if getattr(args, flag):
            out = args.out if args.out != default_out(NAME) else default_out(f"{NAME}_{flag}")
            if args.report:
                for r in saved_results(out):
                    print(r)
            else:
                write_json(out, args, measured())
            return
    if args.report:
        report(saved_results(args.out))
        return
    results = measure(args.N)
    report(results)
    write_json(args.out, args, results)


if __name__ == "__main__":
    main()
