r"""`liepoisson.internals.harmonic_multiplier` (a learned stream operator's $L^{-1}$, once per
stage iteration of every midpoint of a fit) before and after its diagonals were grouped.

    python -m benchmarks.harmonic_multiplier [--sizes 32 64 128] [--repeats 300]
    python -m benchmarks.harmonic_multiplier --report   # the table of the saved results

"before" is the former implementation, copied here: every diagonal's basis padded to
`(N, N)` and the real and imaginary parts in separate products (four passes over $N^3$
numbers a call). "after" reads each group's bases once a way (`MULTIPLIER_GROUPS`). Per call,
after a warm-up: one field; four fields under `vmap` (a fit's trajectories); the reverse pass
of the four (a fit's transposed rollouts). And what a fit waits on: at N = 64, four random
fields of rms 1 rolled over ten intervals of 0.1 in four Yoshida6 steps each (W8's N = 64
step), the rollouts' primal and one conjugate-gradient step of the standard errors (a
linearised pass forward and its transpose), with the operator of either implementation.

Wall-clock times; the machine may be shared (say so when quoting them).
"""

from __future__ import annotations

import argparse
import time

import jax
import jax.numpy as jnp
import numpy as np

import learn
import learn._models._stream_operator as stream_module
import liepoisson as lp
from liepoisson._quantized_sphere import harmonic_basis, harmonics_to_matrix
from liepoisson.internals import harmonic_multiplier

from ._report import add_output_arguments, saved_results, write_json


def former_harmonic_multiplier(W, multiplier):
    """The implementation before the groups (every basis padded to (N, N))."""
    W = jnp.asarray(W)
    N = W.shape[-1]
    m = np.arange(N)[:, None]
    k = np.arange(N)[None, :]
    valid = k < N - m
    rows, cols = np.where(valid, k, 0), np.where(valid, k + m, 0)
    basis = np.zeros((N, N, N))
    for mm, V in enumerate(harmonic_basis(N)):
        basis[mm, : N - mm, : N - mm] = V
    l = m + k
    plus, minus = np.where(valid, l * l + l + m, 0), np.where(valid, l * l + l - m, 0)
    sign = (-1.0) ** np.arange(N)
    multiplier = jnp.asarray(multiplier)
    d = jnp.where(valid, W[rows, cols], 0.0)
    zr = jnp.einsum("mkj,mk->mj", basis, jnp.real(d))
    zi = jnp.einsum("mkj,mk->mj", basis, jnp.imag(d))
    s = sign[:, None] / N
    c_re = s * zi * jnp.where(valid, multiplier[plus], 0.0)
    c_im = -s * zr * jnp.where(valid, multiplier[minus], 0.0)
    out_re = -sign[:, None] * jnp.einsum("mkj,mj->mk", basis, c_im)
    out_im = sign[:, None] * jnp.einsum("mkj,mj->mk", basis, c_re)
    out = jax.lax.complex(out_re, out_im)
    U = jnp.zeros((N, N), dtype=jnp.complex128).at[rows[valid], cols[valid]].set(out[valid])
    strict = jnp.triu(U, 1)
    return U - jnp.conj(strict.T)


def per_call(f, *args, repeats: int) -> float:
    """Seconds a call, after a warm-up call."""
    jax.block_until_ready(f(*args))
    begin = time.perf_counter()
    for _ in range(repeats):
        jax.block_until_ready(f(*args))
    return (time.perf_counter() - begin) / repeats


def calls(N: int, repeats: int) -> list[dict]:
    rng = np.random.default_rng(N)
    Ws = jnp.stack([jnp.asarray(harmonics_to_matrix(rng.normal(size=N * N), N)) for _ in range(4)])
    mu = jnp.asarray(rng.normal(size=N * N))
    rows = []
    for what, make in (
        ("one field", lambda f: (jax.jit(lambda W: f(W, mu)), Ws[0])),
        ("four fields (vmap)", lambda f: (jax.jit(jax.vmap(lambda W: f(W, mu))), Ws)),
        ("four fields, reverse pass", lambda f: (jax.jit(
            lambda Ws: jax.vjp(jax.vmap(lambda W: f(W, mu)), Ws)[1](Ws)[0]), Ws)),
    ):
        before, after = (per_call(*make(f), repeats=repeats) for f in (former_harmonic_multiplier, harmonic_multiplier))
        rows.append({"N": N, "what": what, "before_s": before, "after_s": after})
        print(f"N = {N}, {what}: {before * 1e3:.3g} ms -> {after * 1e3:.3g} ms", flush=True)
    return rows


def fit_pass(repeats: int) -> list[dict]:
    N, substeps = 64, 4
    system = lp.systems.Zeitlin(N)
    rng = np.random.default_rng(0)
    starts = jnp.asarray(rng.normal(size=(4, N * N)))
    intervals = jnp.full((4, 10), 0.1)
    model = learn.StreamOperator(system, "degree", composition="Yoshida6", iterations=6)

    def rollouts(S):
        return jax.vmap(lambda s, dt: model.rollout_intervals(s, dt, substeps))(S, intervals)

    @jax.jit
    def cg_step(S, V):
        _, forward = jax.linearize(rollouts, S)
        return jax.linear_transpose(forward, S)(forward(V))[0]

    primal = jax.jit(rollouts)
    rows = {}
    for label, f in (("before", former_harmonic_multiplier), ("after", harmonic_multiplier)):
        stream_module.harmonic_multiplier = f
        try:
            jax.clear_caches()
            rows[label] = (per_call(primal, starts, repeats=repeats), per_call(cg_step, starts, starts, repeats=repeats))
        finally:
            stream_module.harmonic_multiplier = harmonic_multiplier
    out = []
    for i, what in enumerate(("W8's rollouts at N = 64, primal", "... one CG step (linearised forward + transpose)")):
        out.append({"N": N, "what": what, "before_s": rows["before"][i], "after_s": rows["after"][i]})
        print(f"{what}: {rows['before'][i]:.3g} s -> {rows['after'][i]:.3g} s", flush=True)
    return out


def report(results: list[dict]) -> str:
    lines = ["| N | call | before | after | speed-up |", "|---|---|---|---|---|"]
    for row in results:
        b, a = row["before_s"], row["after_s"]
        unit, scale = ("s", 1.0) if b > 0.1 else ("ms", 1e3)
        lines.append(f"| {row['N']} | {row['what']} | {b * scale:.3g} {unit} | {a * scale:.3g} {unit} | {b / a:.2f}x |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.harmonic_multiplier",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[32, 64, 128])
    parser.add_argument("--repeats", type=int, default=300, help="calls timed per case")
    parser.add_argument("--fit-repeats", type=int, default=3, help="rollouts timed per case")
    add_output_arguments(parser, "harmonic_multiplier")
    args = parser.parse_args(argv)
    if args.report:
        print(report(saved_results(args.out)))
        return
    jax.config.update("jax_enable_x64", True)
    results = [row for N in args.sizes for row in calls(N, args.repeats)]
    if args.fit_repeats > 0:
        results += fit_pass(args.fit_repeats)
    write_json(args.out, args, results)
    print(report(results))


if __name__ == "__main__":
    main()
