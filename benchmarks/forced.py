"""Forced Lie-Poisson systems (issue: bodies in air): `integrators.ForcedSplitting`'s observed order
against heyoka, the energy along the forces' flow, and the cost of a step, for a racquet-like
body with quadratic air drag and for a vehicle with drag on rotation and translation
(BENCHMARKS.md, "Forced systems: drag in the body frame").

    python -m benchmarks.forced [--steps 2000]
    python -m benchmarks.forced --report

Bodies: `Forced(RigidBody((1, 1.9, 2.1)), QuadraticDrag(D))`, D with an off-diagonal term, from
spins of ~10 rad/s about the intermediate axis (|Pi| loses ~15% a second, as tossed bodies in
air); `Forced(Kirchhoff(), [QuadraticDrag on rotation, QuadraticDrag on translation])`. Orders
from the error at t = 1 for h = 0.02, 0.01, 0.005 against heyoka at machine epsilon
(`integrators.convergence`); the energy's largest increase over `--steps` Strang steps of h = 0.3
with the body's exact flow as the conservative piece (it never increases: the forces' flow is a
discrete gradient); ms a step by `integrators.step_timing`.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import integrators as it
import liepoisson as lp

from ._report import add_output_arguments, saved_results, write_json

NAME = "forced"
D_BODY = [[0.02, 0.005, 0.0], [0.005, 0.03, 0.0], [0.0, 0.0, 0.025]]


def systems() -> dict[str, tuple[lp.systems.Forced, np.ndarray]]:
    S = lp.systems
    body = S.Forced(S.RigidBody((1.0, 1.9, 2.1)), S.QuadraticDrag(D_BODY))
    vehicle = S.Forced(S.Kirchhoff(), [S.QuadraticDrag(0.05, indices=(0, 1, 2)),
                                       S.QuadraticDrag([0.1, 0.2, 0.3], indices=(3, 4, 5))])
    return {"racquet, quadratic drag": (body, np.array([[0.2, 19.0, 0.4], [-0.3, -15.0, 0.2]])),
            "vehicle, drag on rotation and translation": (vehicle, np.array([[0.3, 1.0, 0.2, 0.5, -0.2, 1.0]]))}


def measure(name: str, system: lp.systems.Forced, y0: np.ndarray, steps: int) -> dict:
    start = time.perf_counter()
    out = {"system": name}
    for method in (it.splitting.Strang, it.splitting.TripleJump):
        conv = it.convergence(lambda h, m=method: it.ForcedSplitting(system, h, m), system, y0, t_final=1.0,
                              hs=[0.02, 0.01, 0.005])
        out[f"{method.__name__} order"] = conv.order
        out[f"{method.__name__} error at h = 0.005"] = float(np.max(conv.errors[-1]))
        timing = it.step_timing(it.ForcedSplitting(system, 0.01, method), y0[0])
        out[f"{method.__name__} ms a step"] = 1e3 * timing.seconds_per_step
    if isinstance(system.conservative, lp.systems.RigidBody):
        terms = [lp.systems.FreeRigidBodyTerm(system.conservative.inertia)]
        step = it.ForcedSplitting(system, 0.3, it.splitting.Strang, terms=terms)
        H = np.asarray(system.hamiltonian(step.rollout(y0[0], steps)))
        out["largest energy increase a step (relative)"] = float(np.max(np.diff(H) / H[:-1]))
        out["energy left after the run"] = float(H[-1] / H[0])
    out["seconds"] = time.perf_counter() - start
    return out


def report(results: list[dict]) -> None:
    for r in results:
        print(r["system"])
        for k, v in r.items():
            if k != "system":
                print(f"  {k:<45s} {v:.4g}")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000)
    add_output_arguments(parser, NAME)
    args = parser.parse_args(argv)
    if args.report:
        report(saved_results(args.out))
        return
    results = [measure(name, system, y0, args.steps) for name, (system, y0) in systems().items()]
    report(results)
    write_json(args.out, args, results)


if __name__ == "__main__":
    main()
