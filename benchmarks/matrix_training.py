"""Training an LPNet on a matrix algebra at size: one gradient of the state loss on Zeitlin's
model, N = 16 and 32 (dimension 256 and 1024), with the flows' exp(A) by the Taylor path of
`matrix_exponential` (what `learn.fit` compiles: the loss maps over pairs with `vmap_samples`)
and by `jax.scipy.linalg.expm` (a plain `vmap`: every Pade branch and every squaring is
evaluated under it); and the first-order parameter estimate `poisson_lstsq` in the eigenbasis
against the dense pseudo-inverse (BENCHMARKS.md, "Learned maps on matrix algebras").

    python -m benchmarks.matrix_training [--pairs 384]
    python -m benchmarks.matrix_training --report

The LPNet is W5's at the start of its fit (alpha affine in W, `hidden=()`, zero weights), at
quflow's step H, its scalings set from pairs (a state and the isospectral midpoint's step of
it); the fastest of 5 calls after compilation, the pairs passed as arguments. The dense pseudo-inverse is timed at N = 16 only (at N = 32 the tensor of 384
states alone is 3.2 GB).
"""

from __future__ import annotations

import argparse
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import integrators as it
import liepoisson as lp
from liepoisson._abstract_algebra import AbstractLieAlgebra
from paper.w5_zeitlin import lpnet_start

from ._report import add_output_arguments, saved_results, write_json

NAME = "matrix_training"


def _fastest(fn, *args, repeats: int = 5) -> float:
    jax.block_until_ready(fn(*args))
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(fn(*args))
        best = min(best, time.perf_counter() - start)
    return best


def measure(N: int, pairs: int) -> dict:
    system = lp.systems.Zeitlin(N)
    W = np.asarray(system.algebra.matrix(system.random_state(0)))
    H = float(0.1 * np.pi * system.hbar / np.linalg.norm(np.asarray(system.stream_matrix(W)), 2))  # quflow's step
    y0 = np.stack([system.random_state(100 + i) for i in range(pairs)])
    y1 = np.asarray(it.IsospectralMidpoint(system, H).rollout(y0, 1))[:, -1]
    model = lpnet_start(system, H).normalised(y0, y1, H)
    A = np.asarray(system.algebra.matrix(H * np.asarray(jax.vmap(model.alpha)(jnp.asarray(y0)))))
    params, static = eqx.partition(model, eqx.is_inexact_array)
    out = {"N": N, "dim": system.dim, "pairs": pairs, "h": H,
           "largest_norm_hA": float(np.abs(A).sum(axis=-2).max())}
    for name, vmap in (("taylor", lp.vmap_samples), ("jax_expm", jax.vmap)):
        def loss(p, y0, y1, vmap=vmap):
            return jnp.mean((vmap(eqx.combine(p, static).step)(y0) - y1) ** 2)

        out[f"gradient_ms_{name}"] = 1e3 * _fastest(jax.jit(jax.grad(loss)), params, jnp.asarray(y0), jnp.asarray(y1))
    v = (y1 - y0) / H
    out["lstsq_ms_eigenbasis"] = 1e3 * _fastest(lambda: system.poisson_lstsq(y0, v), repeats=3)
    if N <= 16:
        out["lstsq_ms_dense"] = 1e3 * _fastest(lambda: AbstractLieAlgebra.poisson_lstsq(system.algebra, y0, v),
                                               repeats=1)
    return out


def report(results: list[dict]) -> None:
    print("N   dim   pairs  max|hA|_1  gradient ms (Taylor / jax expm)  poisson_lstsq ms (eigenbasis / dense)")
    for r in results:
        dense = f"{r['lstsq_ms_dense']:.0f}" if "lstsq_ms_dense" in r else "not run"
        print(f"{r['N']:<3d} {r['dim']:<5d} {r['pairs']:<6d} {r['largest_norm_hA']:<10.3f} "
              f"{r['gradient_ms_taylor']:8.1f} / {r['gradient_ms_jax_expm']:8.1f}"
              f"{'':17s}{r['lstsq_ms_eigenbasis']:.0f} / {dense}")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=384)
    add_output_arguments(parser, NAME)
    args = parser.parse_args(argv)
    if args.report:
        report(saved_results(args.out))
        return
    results = [measure(N, args.pairs) for N in (16, 32)]
    report(results)
    write_json(args.out, args, results)


if __name__ == "__main__":
    main()
