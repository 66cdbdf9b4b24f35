r"""Nonholonomic systems (the Suslov problem, the Chaplygin sleigh): heyoka's ground truth, and
the classical integrators' observed orders, constraint and energy over long runs, and cost a
step (BENCHMARKS.md, "Nonholonomic systems").

    python -m benchmarks.nonholonomic [--steps 100000] [--h 0.1] [--learned-noise 0 1e-3]
    python -m benchmarks.nonholonomic --report

Protocol: the Suslov problem with I = (1, 2, 3) and a = (1, 1, 1) (not an eigenvector of the
inertia), the Chaplygin sleigh with m = 1, I = 1, a = 0.5; the initial momentum (1.5, -1, 2)
projected onto the constraint (`LiePoissonDAlembert.project`). heyoka at tolerance eps to
t = 200: the largest relative energy drift and relative constraint. Each integrator (RK4, the
implicit midpoint rule, GaussLegendre4): the observed order from the errors at t = 5 against
heyoka at h = 0.2, 0.1, 0.05 (log2 of successive ratios), then `--steps` steps of `--h`: the
largest relative energy error, its value at the end (drift), the largest relative constraint,
and the microseconds a step (compiled rollout, the second of two runs).

Learned (`--learned-noise`): `learn.DAlembertMap` on each system's body velocities, 100
trajectories x 20 steps of 0.1 from |Pi| = 1 (projected), Gaussian noise of the given fraction
of the velocities' RMS size, fitted by `learn.fit` with 200 Levenberg-Marquardt steps on the
trajectory loss (`integrators.Observations` of the velocities, starts fitted); 12 held-out
starts rolled out to t = 200 against heyoka: the true energy's largest relative error, the
relative error of the state at t = 200 (the asymptotic steady rotation; mean and largest), the
constraint; for the sleigh, lifted from the identity, the speed and the heading at t = 200
(the asymptotic straight line). Beside it `learn.NeuralODE` (two hidden layers of 16) fitted to the same data by
500 BFGS iterations.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import integrators as it
import liepoisson as lp

from ._report import add_output_arguments, saved_results, write_json

NAME = "nonholonomic"
METHODS = {"RK4": (it.RK4, 4), "implicit midpoint": (it.ImplicitMidpoint, 2), "GaussLegendre4": (it.GaussLegendre4, 4)}


def systems() -> dict[str, lp.systems.LiePoissonDAlembert]:
    return {"Suslov": lp.systems.suslov((1.0, 2.0, 3.0), (1.0, 1.0, 1.0)),
            "Chaplygin sleigh": lp.systems.chaplygin_sleigh(1.0, 1.0, 0.5)}


def initial_state(system) -> np.ndarray:
    return np.asarray(system.project(np.array([1.5, -1.0, 2.0])))


def _energy_errors(system, states: np.ndarray) -> tuple[float, float]:
    energy = np.asarray(system.hamiltonian(states))
    rel = np.abs(energy - energy[..., :1]) / np.abs(energy[..., :1])
    return float(np.max(rel)), float(np.max(rel[..., -1]))


def measure_ground_truth(system, t_end: float = 200.0, h: float = 0.1) -> dict:
    y0 = initial_state(system)
    kwargs = {"g0": np.eye(3).reshape(1, 9)} if system.group is not None and system.group.size == 9 else {}
    start = time.perf_counter()
    truth = it.ground_truth(system, y0[None], h, round(t_end / h), **kwargs)
    seconds = time.perf_counter() - start
    energy_max, _ = _energy_errors(system, truth.states)
    return {"t_end": t_end, "energy_drift": energy_max,
            "constraint": float(np.max(np.asarray(system.relative_constraint(truth.states)))), "seconds": seconds,
            "final_velocity": np.asarray(system.body_velocity(truth.states[0, -1])).tolist()}


def measure_method(system, name: str, steps: int, h: float) -> dict:
    cls, nominal = METHODS[name]
    y0 = initial_state(system)
    reference = it.ground_truth(system, y0[None], 5.0, 1).states[0, -1]
    hs = (0.2, 0.1, 0.05)
    errors = [float(np.linalg.norm(np.asarray(cls(system, dt).rollout(y0, round(5.0 / dt)))[-1] - reference))
              for dt in hs]
    orders = [float(np.log2(errors[k] / errors[k + 1])) for k in range(len(hs) - 1)]
    method = cls(system, h)
    method.rollout(y0, steps, save_every=max(1, steps // 1000))  # compiled
    start = time.perf_counter()
    states = np.asarray(method.rollout(y0, steps, save_every=max(1, steps // 1000)))
    seconds = time.perf_counter() - start
    energy_max, energy_end = _energy_errors(system, states)
    return {"method": name, "nominal_order": nominal, "h_orders": list(hs), "errors_t5": errors,
            "observed_orders": orders, "steps": steps, "h": h, "energy_max": energy_max, "energy_end": energy_end,
            "constraint": float(np.max(np.asarray(system.relative_constraint(states)))),
            "us_per_step": 1e6 * seconds / steps}


def measure_learned(name: str, noise: float, seed: int = 0) -> list[dict]:
    """The learned map and the neural ODE on the body velocities of `name` (module docstring)."""
    import jax

    import learn

    system = systems()[name]
    rng = np.random.default_rng(seed)
    # H = mu^T M^-1 mu / 2 with mu = M xi: the true energy of a velocity is xi^T M xi / 2
    M = np.linalg.inv(np.asarray(jax.hessian(lambda y: system.hamiltonian(y))(np.zeros(system.dim))))

    def starts(n):
        y = rng.normal(size=(n, system.dim))
        return np.asarray(system.project(y / np.linalg.norm(y, axis=1, keepdims=True)))

    def energy(x):
        return 0.5 * np.einsum("...a,ab,...b->...", x, M, x)

    xi = np.asarray(system.body_velocity(it.ground_truth(system, starts(100), 0.1, 20).states))
    rms = float(np.sqrt(np.mean(np.sum(xi**2, axis=-1))))
    noisy = xi + noise * rms * np.random.default_rng(seed + 1).normal(size=xi.shape)
    data = it.Observations(system, 0.1 * np.arange(21), list(noisy))
    z0 = starts(12)
    sleigh = system.group is not None and system.group.size == 9
    g0 = np.tile(np.eye(3).reshape(1, 9), (12, 1)) if sleigh else None
    truth = it.ground_truth(system, z0, 0.1, 2000, **({"g0": g0} if sleigh else {}))
    test = np.asarray(system.body_velocity(truth.states))
    out = []
    for label, model, optimiser in (
            ("DAlembertMap", learn.DAlembertMap(system, key=seed, h=0.1), learn.LevenbergMarquardt(200)),
            ("neural ODE", learn.NeuralODE(system, hidden=(16, 16), key=seed, h=0.1),
             learn.QuasiNewton(500, "bfgs"))):
        start = time.perf_counter()
        fitted, _ = learn.fit(model, data, optimiser=optimiser, validation_fraction=0.0, progress=False)
        seconds = time.perf_counter() - start
        row = {"system": name, "model": label, "noise": noise, "fit_seconds": seconds}
        try:
            if sleigh and isinstance(fitted, learn.DAlembertMap):
                g, pred = fitted.lifted_rollout(g0, test[:, 0], 2000)
                pose, true_pose = lp.systems.sleigh_pose(np.asarray(g)[:, -1]), lp.systems.sleigh_pose(
                    truth.configurations[:, -1])
                turn = np.abs(np.angle(np.exp(1j * (pose[:, 0] - true_pose[:, 0]))))
                row |= {"heading_error_max_rad": float(np.max(turn)),
                        "heading_error_max_rel": float(np.max(turn / np.abs(true_pose[:, 0]))),
                        "speed_error_max_rel": float(np.max(np.abs(np.asarray(pred)[:, -1, 1] - test[:, -1, 1])
                                                            / np.abs(test[:, -1, 1])))}
            else:
                pred = np.stack([np.asarray(fitted.rollout(x, 2000)) for x in test[:, 0]])
        except it.RolloutDivergedError as err:  # a diverging baseline: reported as such
            out.append(row | {"diverged": str(err)[:200]})
            continue
        pred = np.asarray(pred)
        final = np.linalg.norm(pred[:, -1] - test[:, -1], axis=-1) / np.linalg.norm(test[:, -1], axis=-1)
        C = system.constraints
        out.append(row | {
            "energy_max": float(np.max(np.abs(energy(pred) - energy(test)) / energy(test))),
            "final_state_max": float(np.max(final)), "final_state_mean": float(np.mean(final)),
            "constraint": float(np.max(np.abs(pred @ C.T) / np.linalg.norm(pred, axis=-1, keepdims=True)
                                       / np.linalg.norm(C, axis=1)))})
    return out


def report(results: dict) -> None:
    learned = results.get("learned", [])
    if learned:
        print("| system | learned | noise | fit [s] | true energy, max rel. error to t = 200 | state at t = 200, "
              "max (mean) rel. error | constraint | sleigh: speed, heading at t = 200 |")
        print("|---|---|---|---|---|---|---|---|")
        for r in learned:
            head = f"| {r.get('system', 'Suslov')} | {r['model']} | {r['noise']:g} | {r['fit_seconds']:.0f}"
            if "diverged" in r:
                print(f"{head} | diverged | | | |")
                continue
            sleigh = (f"{r['speed_error_max_rel']:.1e}, {r['heading_error_max_rad']:.1e} rad "
                      f"({r['heading_error_max_rel']:.1e} of the turn)" if "speed_error_max_rel" in r else "")
            print(f"{head} | {r['energy_max']:.2e} | {r['final_state_max']:.2e} ({r['final_state_mean']:.2e}) | "
                  f"{r['constraint']:.2e} | {sleigh} |")
        print()
    for name, r in results.items():
        if name == "learned":
            continue
        truth = r.get("ground_truth")
        if truth:
            print(f"{name}: heyoka to t = {truth['t_end']:g}: energy drift {truth['energy_drift']:.2e}, constraint "
                  f"{truth['constraint']:.2e}, final body velocity {np.round(truth['final_velocity'], 6).tolist()}")
        print("| method | observed orders (h = 0.2 / 0.1 / 0.05) | steps x h | max energy error | energy error at the "
              "end | max constraint | us a step |")
        print("|---|---|---|---|---|---|---|")
        for m in r.get("methods", []):
            orders = " / ".join(f"{o:.2f}" for o in m["observed_orders"])
            print(f"| {m['method']} | {orders} (nominal {m['nominal_order']}) | {m['steps']} x {m['h']:g} | "
                  f"{m['energy_max']:.2e} | {m['energy_end']:.2e} | {m['constraint']:.2e} | {m['us_per_step']:.1f} |")
        print()


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=100_000)
    parser.add_argument("--h", type=float, default=0.1)
    parser.add_argument("--learned-noise", type=float, nargs="*", default=[],
                        help="fit the learned map and the neural ODE at these noise levels (e.g. 0 1e-3)")
    add_output_arguments(parser, NAME)
    args = parser.parse_args(argv)
    if args.report:
        report(saved_results(args.out))
        return
    results: dict = {}
    if args.learned_noise:
        results["learned"] = [row for name in systems() for noise in args.learned_noise
                              for row in measure_learned(name, noise)]
        report({"learned": results["learned"]})
    for name, system in systems().items() if args.steps else ():
        results[name] = {"ground_truth": measure_ground_truth(system), "methods": []}
        for method in METHODS:
            results[name]["methods"].append(measure_method(system, method, args.steps, args.h))
            report({name: results[name]})
    write_json(args.out, args, results)
    report(results)


if __name__ == "__main__":
    main()
