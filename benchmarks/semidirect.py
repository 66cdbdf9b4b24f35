"""se(N) = so(N) x R^N as a matrix algebra, N = 3..6: Strang splitting's observed order against
heyoka and its Casimirs over a long run, for a rigid body in a fluid of N dimensions
(BENCHMARKS.md, "se(N): the semidirect product as matrices"); the same for the other
semidirect products (`--families saff uaff aff suaff spaff`: sl(N) x R^N, u(N) x C^N,
gl(N) x R^N, su(N) x C^N, sp(2N) x R^{2N}, `liepoisson.semidirect`).

    python -m benchmarks.semidirect [--families se] [--sizes 3 4 5 6] [--steps 10000]
    python -m benchmarks.semidirect --report

The Hamiltonian $H = \\tfrac12\\sum_a \\mu_a^2/w_a$, $w$ = linspace(1, 2, dim) (Kirchhoff's body
with a diagonal inertia, in the coordinates $(M_{ij}, p_i)$ of `liepoisson.se(N)`), as a
`LiePoissonSystem` split into its dim exactly solvable pieces; two random initial conditions
(seed 0), the error at t = 1 for h = 0.1, 0.05, 0.025 against heyoka at its default tolerance
(machine epsilon); the Casimirs ($|p|^2$ and those of the rotations about $p$) over `--steps`
Strang steps of h = 0.05, the largest change relative to each Casimir's value and to its scale
$|\\nabla C|\\,|\\mu|$.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import integrators as it
import liepoisson as lp

from ._report import add_output_arguments, saved_results, write_json

NAME = "semidirect"


def body(N: int, family: str = "se") -> lp.systems.LiePoissonSystem:
    g = lp.MatrixLieAlgebra(family, N)
    w = np.linspace(1.0, 2.0, g.dim)
    return lp.systems.LiePoissonSystem(g, lambda m, xp: sum(0.5 * m[a] ** 2 / w[a] for a in range(g.dim)))


def measure(N: int, steps: int, family: str = "se") -> dict:
    system = body(N, family)
    g = system.algebra
    y0 = np.random.default_rng(0).normal(size=(2, g.dim))
    start = time.perf_counter()
    conv = it.convergence(lambda h: it.splitting.Strang(system, h), system, y0, t_final=1.0, hs=[0.1, 0.05, 0.025])
    ys = np.asarray(it.splitting.Strang(system, 0.05).rollout(y0[0], steps, save_every=steps // 10))
    c = np.asarray(g.casimirs(ys))
    scale = np.linalg.norm(np.asarray(g.casimir_gradients(ys[0])), axis=-1) * np.linalg.norm(ys[0])
    change = np.abs(c - c[0])
    return {"N": N, "algebra": g.name, "dim": g.dim, "casimirs": g.n_casimirs, "order": conv.order,
            "casimir_relative": float((change / np.abs(c[0])).max(initial=0.0)),
            "casimir_scaled": float((change / scale).max(initial=0.0)), "seconds": time.perf_counter() - start}


def report(results: list[dict]) -> None:
    print("algebra  dim   Casimirs   Strang order   Casimir change (relative, scaled)   seconds")
    for r in results:
        print(f"{r.get('algebra', 'se' + str(r['N'])):<8s} {r['dim']:<5d} {r['casimirs']:<10d} {r['order']:12.3f}   "
              f"{r['casimir_relative']:.1e}, {r['casimir_scaled']:.1e}{'':>19} {r['seconds']:7.1f}")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--families", nargs="+", default=["se"], choices=list(lp.internals.SEMIDIRECT))
    parser.add_argument("--sizes", type=int, nargs="+", default=[3, 4, 5, 6])
    parser.add_argument("--steps", type=int, default=10000)
    add_output_arguments(parser, NAME)
    args = parser.parse_args(argv)
    if args.report:
        report(saved_results(args.out))
        return
    results = []
    for family in args.families:
        for N in args.sizes:
            results.append(measure(N, args.steps, family))
            report(results)
    write_json(args.out, args, results)


if __name__ == "__main__":
    main()
