"""The generalized rigid body on so(N), N = 3..10: observed orders of Strang splitting (one
planar rotation per pair i < j), the isospectral midpoint and its triple jump against heyoka,
and the Casimirs over a long Strang run (BENCHMARKS.md, "The generalized rigid body").

    python -m benchmarks.generalized_rigid_body [--sizes 3 4 5 6 7 8 9 10] [--steps 10000]
    python -m benchmarks.generalized_rigid_body --report

Mass matrix J = linspace(1, 2.2, N); two random initial conditions (seed 0), the error at
t = 1 for h = 0.1, 0.05, 0.025 against heyoka at its default tolerance (machine epsilon); the
Casimirs of so(N) (`so(N).casimirs`: $\\tfrac12(-1)^k\\mathrm{tr}\\,M^{2k}$, the Pfaffian for the last of an
even N) over `--steps` Strang steps of h = 0.05, the
largest change relative to each Casimir's value.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import integrators as it
import liepoisson as lp

from ._report import add_output_arguments, saved_results, write_json

NAME = "generalized_rigid_body"
METHODS = {
    "Strang": lambda body, h: it.splitting.Strang(body, h),
    "IsospectralMidpoint": lambda body, h: it.IsospectralMidpoint(body, h, tol=1e-14),
    "IsospectralTripleJump": lambda body, h: it.IsospectralTripleJump(body, h, tol=1e-14),
}


def measure(N: int, steps: int) -> dict:
    body = lp.systems.GeneralizedRigidBody(np.linspace(1.0, 2.2, N))
    y0 = np.random.default_rng(0).normal(size=(2, body.dim))
    row: dict = {"N": N, "dim": body.dim, "orders": {}}
    start = time.perf_counter()
    for name, make in METHODS.items():
        conv = it.convergence(lambda h, make=make: make(body, h), body, y0, t_final=1.0, hs=[0.1, 0.05, 0.025])
        row["orders"][name] = conv.order
    ys = np.asarray(it.splitting.Strang(body, 0.05).rollout(y0[0], steps, save_every=steps // 10))
    c = np.asarray(body.casimirs(ys))
    row["casimir_relative"] = float((np.abs(c - c[0]) / np.abs(c[0])).max())
    row["seconds"] = time.perf_counter() - start
    return row


def report(results: list[dict]) -> None:
    print("N   dim   Strang  IsoMidpoint  IsoTripleJump   Casimirs over the Strang run   seconds")
    for r in results:
        o = r["orders"]
        print(f"{r['N']:<3d} {r['dim']:<5d} {o['Strang']:6.2f}  {o['IsospectralMidpoint']:11.2f}  "
              f"{o['IsospectralTripleJump']:13.2f}   {r['casimir_relative']:28.1e}   {r['seconds']:7.1f}")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=list(range(3, 11)))
    parser.add_argument("--steps", type=int, default=10000)
    add_output_arguments(parser, NAME)
    args = parser.parse_args(argv)
    if args.report:
        report(saved_results(args.out))
        return
    results = []
    for N in args.sizes:
        results.append(measure(N, args.steps))
        report(results)
    write_json(args.out, args, results)


if __name__ == "__main__":
    main()
