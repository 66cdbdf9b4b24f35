r"""Nonholonomic systems (the Suslov problem, the Chaplygin sleigh): heyoka's ground truth, and
the classical integrators' observed orders, constraint and energy over long runs, and cost a
step (BENCHMARKS.md, "Nonholonomic systems").

    python -m benchmarks.nonholonomic [--steps 100000] [--h 0.1] [--methods METHOD ...]
    python -m benchmarks.nonholonomic --report

Protocol: the Suslov problem with I = (1, 2, 3) and a = (1, 1, 1) (not an eigenvector of the
inertia), the Chaplygin sleigh with m = 1, I = 1, a = 0.5; the initial momentum (1.5, -1, 2)
projected onto the constraint (`LiePoissonDAlembert.project`). heyoka at tolerance eps to
t = 200: the largest relative energy drift and relative constraint. Each integrator (RK4, the
implicit midpoint rule, GaussLegendre4, the discrete Lagrange-d'Alembert method and its
symmetric compositions by TripleJump and Yoshida6 (`ComposedLagrangeDAlembert`), whose node
momenta are `node_momentum` of their states and whose energy and constraint are those of their
`velocity`): the observed order from the errors at t = 5 against
heyoka at h = 0.2, 0.1, 0.05 (log2 of successive ratios), then `--steps` steps of `--h`: the
largest relative energy error, its value at the end (drift), the largest relative constraint,
and the microseconds a step (compiled rollout, the second of two runs).

The learned maps on the same systems (`learn.DAlembertMap`, a neural ODE) are study W6:
`python -m paper run W6 --full`.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import integrators as it
from integrators.splitting import Yoshida6
from paper.w6_nonholonomic import systems

from ._report import add_output_arguments, saved_results, write_json

NAME = "nonholonomic"
METHODS = {"RK4": (it.RK4, 4), "implicit midpoint": (it.ImplicitMidpoint, 2), "GaussLegendre4": (it.GaussLegendre4, 4),
           "discrete Lagrange-d'Alembert": (it.DiscreteLagrangeDAlembert, 2),
           "DLA, TripleJump": (it.ComposedLagrangeDAlembert, 4),
           "DLA, Yoshida6": (lambda system, h: it.ComposedLagrangeDAlembert(system, h, Yoshida6()), 6)}


def nodes(method, states: np.ndarray) -> np.ndarray:
    """The momenta at the nodes of `method`'s states: the states themselves, but for a
    staggered method (the discrete Lagrange-d'Alembert method and its compositions), whose state
    is the arriving momentum."""
    return np.asarray(method.node_momentum(states)) if isinstance(method, it.AbstractStaggeredStepMap) else states


def velocities(system, method, states: np.ndarray) -> np.ndarray:
    """The body velocities the method keeps admissible: $\nabla H$ of its states, or a
    staggered method's `velocity` (the discrete velocities; a composition's node velocities)."""
    if isinstance(method, it.AbstractStaggeredStepMap):
        return np.asarray(method.velocity(states))
    return np.asarray(system.body_velocity(states))


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
    errors = []
    for dt in hs:
        method = cls(system, dt)
        errors.append(float(np.linalg.norm(nodes(method, np.asarray(method.rollout(y0, round(5.0 / dt)))[-1])
                                           - reference)))
    orders = [float(np.log2(errors[k] / errors[k + 1])) for k in range(len(hs) - 1)]
    method = cls(system, h)
    method.rollout(y0, steps, save_every=max(1, steps // 1000))  # compiled
    start = time.perf_counter()
    states = np.asarray(method.rollout(y0, steps, save_every=max(1, steps // 1000)))
    seconds = time.perf_counter() - start
    # energy and constraint of the velocities each method keeps admissible, against H(y0)
    xi = velocities(system, method, states)
    M = system.kinetic_metric()
    energy = 0.5 * np.einsum("...a,ab,...b->...", xi, M, xi)
    rel = np.abs(energy / float(system.hamiltonian(y0)) - 1.0)
    C = system.constraints
    constraint = np.max(np.abs(xi @ C.T) / np.linalg.norm(C, axis=1), axis=-1) / np.linalg.norm(xi, axis=-1)
    return {"method": name, "nominal_order": nominal, "h_orders": list(hs), "errors_t5": errors,
            "observed_orders": orders, "steps": steps, "h": h, "energy_max": float(np.max(rel)),
            "energy_end": float(rel[-1]), "constraint": float(np.max(constraint)), "us_per_step": 1e6 * seconds / steps}


def report(results: dict) -> None:
    for name, r in results.items():
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
    parser.add_argument("--methods", nargs="*", default=list(METHODS), choices=list(METHODS), metavar="METHOD",
                        help=f"the integrators to measure (default all: {', '.join(METHODS)})")
    add_output_arguments(parser, NAME)
    args = parser.parse_args(argv)
    if args.report:
        report(saved_results(args.out))
        return
    results: dict = {}
    for name, system in systems().items():
        results[name] = {"ground_truth": measure_ground_truth(system), "methods": []}
        for method in args.methods:
            results[name]["methods"].append(measure_method(system, method, args.steps, args.h))
            report({name: results[name]})
    write_json(args.out, args, results)
    report(results)


if __name__ == "__main__":
    main()
