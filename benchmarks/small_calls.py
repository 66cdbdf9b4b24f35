r"""Small calls a user waits on: `learn.latent_momenta` and rollouts of many lengths, before and
after they were compiled once (issue: scoring 51 held-out flights of different lengths).

    python -m benchmarks.small_calls [--lengths 50] [--repeats 200] [--out benchmarks/results/small_calls.json]
    python -m benchmarks.small_calls --report   # the table of the saved results

On the rigid body (inertia (1, 2, 3)) with a G-LPNet (default modules, `key=0`, h = 0.1) and
`integrators.splitting.Strang`:

- `latent_momenta` of one 3-vector and of 51 (a batch), per call after a warm-up: "before" is
  the former implementation (20 Newton steps in a Python loop, op by op), copied here;
- `--lengths` rollouts of one initial state, each of another length (`n_steps` from 20 to 1000,
  as flights of different durations), `rollout` on both maps and `lifted_rollout` on the
  G-LPNet: wall time of all of them from a cold start and the XLA compilations they triggered
  (JAX's `backend_compile` events). "before" is the former implementation (`jax.lax.scan` of
  `n_steps // save_every` steps, the length a constant of the program), copied here;
- one long rollout (100 trajectories, 10^4 steps saved every 10), warm, to show the pieces
  cost nothing at run time.

Wall-clock times; the machine may be shared (say so when quoting them).
"""

from __future__ import annotations

import argparse
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import integrators as it
import learn
import liepoisson as lp
from integrators.internals import counted_compilations, traced_h
from liepoisson import vmap_samples

from ._report import add_output_arguments, saved_results, write_json


# -- the implementations replaced (commit 46d8bf6; tests/test_small_calls.py compares with them) --
def former_latent_momenta(model, xi, iterations=20):
    xi = jnp.asarray(xi, dtype=jnp.float64)
    dim = model.system.dim
    if xi.ndim < 1 or xi.shape[-1] != dim or not bool(jnp.all(jnp.isfinite(xi))):
        raise ValueError(f"xi must be finite body velocities of shape (..., {dim}); got shape {xi.shape}")
    flat = xi.reshape(-1, dim)
    grad = jax.vmap(model.body_velocity)
    hess = jax.vmap(jax.jacfwd(model.body_velocity))
    mu = jnp.zeros_like(flat)
    for _ in range(iterations):
        mu = mu - jnp.einsum("sij,sj->si", jnp.linalg.pinv(hess(mu)), grad(mu) - flat)
    return mu.reshape(xi.shape)


@eqx.filter_jit
def _former_rollout_compiled(step_map, y0, n_saved, save_every):
    step = vmap_samples(step_map.step_carry)
    uncarry = vmap_samples(step_map.uncarry)
    if isinstance(save_every, int) and save_every == 1:

        def body(c, _):
            c = step(c)
            return c, uncarry(c)

    else:

        def body(c, _):
            c = jax.lax.fori_loop(0, save_every, lambda _, z: step(z), c)
            return c, uncarry(c)

    _, ys = jax.lax.scan(body, vmap_samples(step_map.carry)(y0), None, length=n_saved)
    return jnp.concatenate([y0[:, None], jnp.swapaxes(ys, 0, 1)], axis=1)


def former_rollout(m, y0, n_steps, save_every=1, check=True):
    """The former `rollout` (the states returned as they are, non-finite ones too, with
    `check=False`)."""
    y0 = np.asarray(y0, dtype=np.float64)
    every = 1 if save_every == 1 else jnp.asarray(save_every, dtype=jnp.int32)
    out = _former_rollout_compiled(traced_h(m), jnp.asarray(y0.reshape(-1, m.system.dim)), n_steps // save_every,
                                   every)
    if check:
        it.RaiseIfNonfinite().check(m, out, save_every)
    return out[0] if y0.ndim == 1 else out


@eqx.filter_jit
def former_lifted_compiled(step_map, g0, y0, n_saved, save_every):
    step = jax.vmap(step_map.lifted_step)

    def body(gy, _):
        gy = jax.lax.fori_loop(0, save_every, lambda _, z: step(*z), gy) if save_every > 1 else step(*gy)
        return gy, gy

    _, (gs, ys) = jax.lax.scan(body, (g0, y0), None, length=n_saved)
    return (jnp.concatenate([g0[:, None], jnp.swapaxes(gs, 0, 1)], axis=1),
            jnp.concatenate([y0[:, None], jnp.swapaxes(ys, 0, 1)], axis=1))


def former_lifted_rollout(m, g0, y0, n_steps, save_every=1):
    G, Y = jnp.asarray(g0)[None], jnp.asarray(y0)[None]
    gs, ys = former_lifted_compiled(traced_h(m), G, Y, n_steps // save_every, save_every)
    bad = ~(jnp.all(jnp.isfinite(ys), axis=(1, 2)) & jnp.all(jnp.isfinite(gs), axis=(1, 2)))
    if bool(jnp.any(bad)):
        raise FloatingPointError("diverged")
    return gs[0], ys[0]


# -- measuring -------------------------------------------------------------------------------------
def per_call(fn, repeats: int) -> float:
    """Median wall time of `fn()` after one warm-up call [s]."""
    jax.block_until_ready(fn())
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(fn())
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def many_lengths(fn, lengths) -> tuple[float, int]:
    """`(seconds, compilations)` of `fn(n)` for every `n` in `lengths`, from a cold start."""
    with counted_compilations() as seen:
        start = time.perf_counter()
        for n in lengths:
            jax.block_until_ready(fn(int(n)))
        wall = time.perf_counter() - start
    return wall, seen["compilations"]


def _compilations(n: int) -> str:
    return f"{n} compilation" if n == 1 else f"{n} compilations"


def report(results: dict) -> str:
    lines = ["| call | before | after | speed-up |", "|---|---|---|---|"]
    for row in results["latent_momenta"]:
        b, a = row["before_s"], row["after_s"]
        lines.append(f"| `latent_momenta`, {row['what']}, per call | {b * 1e3:.3g} ms | {a * 1e3:.3g} ms "
                     f"| {b / a:.0f}x |")
    for row in results["lengths"]:
        b, a = row["before_s"], row["after_s"]
        lines.append(f"| {row['what']}: {row['n']} lengths, cold | {b:.2f} s, {_compilations(row['before_compilations'])} "
                     f"| {a:.2f} s, {_compilations(row['after_compilations'])} | {b / a:.0f}x |")
    for row in results["long"]:
        b, a = row["before_s"], row["after_s"]
        lines.append(f"| {row['what']}, warm | {b:.3f} s | {a:.3f} s | {b / a:.2f}x |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.small_calls", description=__doc__.splitlines()[0])
    parser.add_argument("--lengths", type=int, default=50, help="rollouts, each of another length")
    parser.add_argument("--repeats", type=int, default=200, help="calls timed for latent_momenta (after)")
    add_output_arguments(parser, "small_calls")
    args = parser.parse_args(argv)
    if args.report:
        print(report(saved_results(args.out)))
        return
    jax.config.update("jax_enable_x64", True)
    body = lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0))
    net = learn.GLPNet(body, key=0, h=0.1)
    strang = it.splitting.Strang(body, h=0.1)
    rng = np.random.default_rng(0)
    xi1, xi51 = rng.normal(size=3), rng.normal(size=(51, 3))

    rows = []
    for what, xi in (("one 3-vector", xi1), ("51 3-vectors", xi51)):
        before = per_call(lambda xi=xi: former_latent_momenta(net, xi), max(5, args.repeats // 20))
        after = per_call(lambda xi=xi: learn.latent_momenta(net, xi), args.repeats)
        rows.append({"what": what, "before_s": before, "after_s": after})
        print(f"latent_momenta, {what}: {before * 1e3:.3g} ms -> {after * 1e3:.3g} ms", flush=True)

    lengths = rng.choice(np.arange(20, 1001), size=args.lengths, replace=False)
    y0, g0 = np.array([0.3, -0.5, 0.8]), np.array([0.0, 0.0, 0.0, 1.0])
    calls = [
        ("`Strang.rollout`", lambda n: former_rollout(strang, y0, n), lambda n: strang.rollout(y0, n)),
        ("`GLPNet.rollout`", lambda n: former_rollout(net, y0, n), lambda n: net.rollout(y0, n)),
        ("`GLPNet.lifted_rollout`", lambda n: former_lifted_rollout(net, g0, y0, n),
         lambda n: net.lifted_rollout(g0, y0, n)),
    ]
    by_length = []
    for what, before_fn, after_fn in calls:
        before, before_compiled = many_lengths(before_fn, lengths)
        after, after_compiled = many_lengths(after_fn, lengths)
        by_length.append({"what": what, "n": len(lengths), "before_s": before, "before_compilations": before_compiled,
                          "after_s": after, "after_compilations": after_compiled})
        print(f"{what}, {len(lengths)} lengths: {before:.2f} s ({before_compiled} compilations) -> {after:.2f} s "
              f"({after_compiled} compilations)", flush=True)

    y0s = np.array([0.3, -0.5, 0.8]) + rng.uniform(-0.1, 0.1, size=(100, 3))
    long = []
    for what, m in (("`Strang.rollout`", strang), ("`GLPNet.rollout`", net)):
        before = per_call(lambda m=m: former_rollout(m, y0s, 10_000, 10), 3)
        after = per_call(lambda m=m: m.rollout(y0s, 10_000, save_every=10), 3)
        long.append({"what": f"{what}, 100 trajectories, 10^4 steps saved every 10", "before_s": before,
                     "after_s": after})
        print(f"{what} long: {before:.3f} s -> {after:.3f} s", flush=True)

    results = {"system": "RigidBody(inertia=(1, 2, 3))", "glpnet": "GLPNet(body, key=0, h=0.1)",
               "lengths": by_length, "latent_momenta": rows, "long": long}
    print(report(results))
    write_json(args.out, args, results)


if __name__ == "__main__":
    main()
