"""Building Lie algebras of any size: the matrix algebras so(N) and u(N) up to N = 64 (time,
memory, a first bracket and coadjoint flow), and `LieAlgebra.from_matrices` of so(4..7), whose
structure constants are checked and whose Casimirs are searched (BENCHMARKS.md, "Matrix Lie
algebras").

    python -m benchmarks.matrix_algebras [--sizes 8 16 32 64] [--from-matrices 4 5 6 7]
    python -m benchmarks.matrix_algebras --report

Memory is the peak of Python allocations during the construction (`tracemalloc`: numpy's
arrays included, XLA's buffers not) and the growth of the process's resident set over the
construction and the first operations (which includes XLA's compiled programs).
"""

from __future__ import annotations

import argparse
import time
import tracemalloc

import numpy as np

import liepoisson as lp

from ._report import add_output_arguments, saved_results, write_json

NAME = "matrix_algebras"


def _so_basis(N: int) -> np.ndarray:
    basis = []
    for i in range(N):
        for j in range(i + 1, N):
            E = np.zeros((N, N))
            E[i, j], E[j, i] = 1.0, -1.0
            basis.append(E)
    return np.array(basis)


def _rss() -> int:
    """The resident set of this process in bytes (Linux: /proc/self/statm), 0 elsewhere."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * 4096
    except OSError:
        return 0


def measure_matrix(family: str, N: int) -> dict:
    rss = _rss()
    tracemalloc.start()
    start = time.perf_counter()
    g = getattr(lp, family)(N)
    build = time.perf_counter() - start
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    rng = np.random.default_rng(0)
    x, y = rng.normal(size=(2, g.dim))
    start = time.perf_counter()
    np.asarray(g.bracket(x, y))
    np.asarray(g.coadjoint_flow(x, 0.1, y))
    first_ops = time.perf_counter() - start
    return {"family": family, "N": N, "dim": g.dim, "build_seconds": build, "build_peak_bytes": peak,
            "first_operations_seconds": first_ops, "rss_growth_bytes": _rss() - rss}


def measure_from_matrices(N: int) -> dict:
    basis = _so_basis(N)
    tracemalloc.start()
    start = time.perf_counter()
    try:
        g = lp.LieAlgebra.from_matrices(basis, f"so{N}")
        outcome = f"{g.n_casimirs} Casimirs"
    except ValueError as err:
        outcome = f"ValueError: {str(err)[:90]}..."
    seconds = time.perf_counter() - start
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return {"N": N, "dim": len(basis), "seconds": seconds, "peak_bytes": peak, "outcome": outcome}


def report(results: dict) -> None:
    print("algebra   dim     build ms   build peak MB   first bracket + flow s   RSS growth MB")
    for r in results["matrix"]:
        print(f"{r['family']}({r['N']})".ljust(9) + f" {r['dim']:<7d} {1e3 * r['build_seconds']:8.2f}   "
              f"{r['build_peak_bytes'] / 1e6:12.2f}   {r['first_operations_seconds']:22.2f}   "
              f"{r['rss_growth_bytes'] / 1e6:12.1f}")
    print("LieAlgebra.from_matrices of so(N) (checks of the constants, Casimir search):")
    for r in results["from_matrices"]:
        print(f"  so({r['N']}) dim {r['dim']}: {r['seconds']:.2f} s, peak {r['peak_bytes'] / 1e6:.1f} MB, {r['outcome']}")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[8, 16, 32, 64])
    parser.add_argument("--from-matrices", type=int, nargs="*", default=[4, 5, 6, 7])
    add_output_arguments(parser, NAME)
    args = parser.parse_args(argv)
    if args.report:
        report(saved_results(args.out))
        return
    results = {"matrix": [measure_matrix(f, N) for f in ("so", "u") for N in args.sizes],
               "from_matrices": [measure_from_matrices(N) for N in args.from_matrices]}
    write_json(args.out, args, results)
    report(results)


if __name__ == "__main__":
    main()
