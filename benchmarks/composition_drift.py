"""Casimirs of a long composition of exact coadjoint flows on the matrix algebras: the largest
change relative to each Casimir's scale, in units of machine epsilon (BENCHMARKS.md, "Casimirs
of a long composition").

    python -m benchmarks.composition_drift [--flows 20000]
    python -m benchmarks.composition_drift --report

Each algebra at a small size; a random state (seed 0) moved by `--flows` flows
`_coadjoint_flow(alpha, 0.3, mu)` of random alpha (normal; times 0.02 on the non-compact
algebras, whose orbits are unbounded), composed in coordinates as a splitting method or a
learned map composes them; the change of each Casimir over the run divided by its scale
$|\\nabla C|\\,|\\mu|$ at the start. Every flow is exact up to round-off, so an unbiased composition
random-walks, about $\\sqrt{\\text{flows}}$ eps; a bias of one sign grows like the number of flows.
"""

from __future__ import annotations

import argparse

import jax
import numpy as np

import liepoisson as lp

from ._report import add_output_arguments, saved_results, write_json

NAME = "composition_drift"
EPS = float(np.finfo(np.float64).eps)


def casimir_change(g: lp.MatrixLieAlgebra, flows: int, seed: int, alpha_scale: float) -> np.ndarray:
    r"""The change of each Casimir of `g` over `flows` composed flows `_coadjoint_flow(alpha,
    0.3, mu)` from a random state, relative to its scale $|\nabla C|\,|\mu_0|$: the state, then
    the `flows` alpha (normal, times `alpha_scale`), drawn from `numpy.random.default_rng(seed)`
    (also tests/test_matrix_algebra.py's check that the composition has no rounding bias)."""
    rng = np.random.default_rng(seed)
    mu0 = rng.normal(size=g.dim)
    alphas = rng.normal(size=(flows, g.dim)) * alpha_scale

    @jax.jit
    def compose(mu0, alphas):
        return jax.lax.scan(lambda mu, a: (g._coadjoint_flow(a, np.asarray(0.3), mu), None), mu0, alphas)[0]

    mu1 = compose(mu0, alphas)
    c0, c1 = np.asarray(g.casimirs(mu0)), np.asarray(g.casimirs(mu1))
    scale = np.linalg.norm(np.asarray(g.casimir_gradients(mu0)), axis=-1) * np.linalg.norm(mu0)
    return np.abs(c1 - c0) / scale


def measure(g: lp.MatrixLieAlgebra, flows: int) -> dict:
    compact = g.family in ("so", "u", "su")
    change = casimir_change(g, flows, seed=0, alpha_scale=1.0 if compact else 0.02)
    return {"algebra": g.name, "flows": flows, "change_in_eps": (change / EPS).tolist()}


def report(results: list[dict]) -> None:
    print("algebra  flows   largest Casimir change / scale, in eps (each Casimir)")
    for r in results:
        print(f"{r['algebra']:<8s} {r['flows']:<7d} " + ", ".join(f"{v:.0f}" for v in r["change_in_eps"]))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--flows", type=int, default=20000)
    add_output_arguments(parser, NAME)
    args = parser.parse_args(argv)
    if args.report:
        report(saved_results(args.out))
        return
    algebras = [lp.so(4), lp.u(3), lp.su(3), lp.sp(2), lp.sl(3), lp.gl(3), lp.se(3)]
    results = [measure(g, args.flows) for g in algebras]
    report(results)
    write_json(args.out, args, results)


if __name__ == "__main__":
    main()
