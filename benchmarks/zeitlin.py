r"""The isospectral midpoint method on Zeitlin's model: milliseconds a step beside the time of
one N x N complex matrix product measured in the same run, their ratio, the fixed-point
iterations a step, and the Casimirs tr W^k (k = 2..4), the spectrum and the energy over a long
run (BENCHMARKS.md, "Zeitlin's model").

    python -m benchmarks.zeitlin [--sizes 16 32 64 128 256 512] [--drift-N 64] [--drift-steps 10000]
    python -m benchmarks.zeitlin --report

Protocol (quflow's, Cifani, Viviani & Modin 2023, so that the two codes compare): the initial
vorticity is a random field (`Zeitlin.random_state`, degrees <= 10, unit L2 norm), the step
quflow's `estimate_stepsize`, $h = 0.1\pi\hbar/\|P\|_2$ in physical time, and the stopping
tolerance of the stage iteration quflow's default, $\sqrt{\varepsilon}\,(h/\hbar)\,
\|W_0\|_\infty$, the same norm (the largest row sum) and the same rule: a step is accepted
when an iteration moves the stage by at most that (ours relative to $\|W\|_\infty$ of the
step's start, hence `tol` $= \sqrt{\varepsilon}\,h/\hbar$). One thread
(`--xla_cpu_multi_thread_eigen=false`, `OPENBLAS_NUM_THREADS=1`), like the quflow figures it is
compared with. The
matrix product is `A @ B` of two dense complex128 matrices, compiled, the fastest of repeats;
a step is timed in a long run (`steady_step_seconds`: the first steps, whose start has no
history, left out), iterating until the tolerance is met; the iterations a step are the mean
and the most over the first 200 steps (`iterations_needed`).
"""

from __future__ import annotations

import os

os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1")
# The LU of the Cayley transform runs in LAPACK (OpenBLAS): its worker threads, left spinning
# after each call, slowed the matrix products that follow (BENCHMARKS.md, "Zeitlin's model");
# one thread for it too.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import integrators as it
import liepoisson as lp

from ._report import add_output_arguments, saved_results, write_json

NAME = "zeitlin"


def matmul_seconds(N: int, min_seconds: float = 0.2, repeats: int = 5) -> float:
    """The fastest wall time of one compiled complex128 N x N product."""
    rng = np.random.default_rng(0)
    A = jnp.asarray(rng.normal(size=(N, N)) + 1j * rng.normal(size=(N, N)))
    B = jnp.asarray(rng.normal(size=(N, N)) + 1j * rng.normal(size=(N, N)))

    @jax.jit
    def many(A, B, k):
        return jax.lax.fori_loop(0, k, lambda _, X: (A @ X) * 0.5, B)

    many(A, B, 1).block_until_ready()
    k = 1
    while True:
        start = time.perf_counter()
        many(A, B, k).block_until_ready()
        if time.perf_counter() - start >= min_seconds or k >= 1 << 16:
            break
        k *= 2
    best = min(_timed(lambda: many(A, B, k).block_until_ready()) for _ in range(repeats))
    return best / k


def _timed(fn) -> float:
    start = time.perf_counter()
    fn()
    return time.perf_counter() - start


@eqx.filter_jit
def advance(method: it.IsospectralMidpoint, c, n_steps: jax.Array):
    """`n_steps` (a traced integer: one program for every count) steps of `method` on its
    carried state `c` (the matrix and the stage history)."""
    return jax.lax.fori_loop(0, n_steps, lambda _, c: method.step_carry(c), c)


def steady_step_seconds(method: it.IsospectralMidpoint, y0: np.ndarray, min_seconds: float = 1.0,
                        repeats: int = 3) -> float:
    """The wall time of one step in a long run: timed from a carried state already 10 steps
    in (the iteration's start extrapolated from the history, as in every step but the first
    three), the fastest of `repeats` runs of at least `min_seconds`."""
    c = advance(method, method.carry(jnp.asarray(y0)), jnp.asarray(10))  # compiles

    def run(n: int) -> float:
        return _timed(lambda: jax.block_until_ready(advance(method, c, jnp.asarray(n))))

    n = 1
    seconds = run(n)
    while seconds < min_seconds and n < 1 << 16:
        n = max(n + 1, int(n * min(10.0, 1.2 * min_seconds / max(seconds, 1e-6))))
        seconds = run(n)
    return min(seconds, *(run(n) for _ in range(repeats - 1))) / n


def setting(N: int, seed: int = 0) -> tuple[lp.systems.Zeitlin, np.ndarray, float, float]:
    """`(system, y0, h, tol)` of the protocol (module docstring)."""
    z = lp.systems.Zeitlin(N)
    y0 = z.random_state(seed)
    W0 = np.asarray(z.algebra.matrix(y0))
    P0 = np.asarray(z.stream_matrix(W0))
    h = 0.1 * np.pi * z.hbar / np.linalg.norm(P0, 2)
    # quflow's sqrt(eps) (h / hbar) ||W0||_inf, relative to ||W||_inf (the isospectral methods' norm)
    return z, y0, float(h), float(np.sqrt(np.finfo(np.float64).eps) * h / z.hbar)


def measure_size(N: int) -> dict:
    z, y0, h, tol = setting(N)
    method = it.IsospectralMidpoint(z, h, tol=tol)
    mean, most = method.iterations_needed(y0, n_steps=200)
    product = matmul_seconds(N)
    step = steady_step_seconds(method, y0)
    return {"N": N, "dim": z.dim, "h": h, "tol": tol, "product_ms": product * 1e3, "step_ms": step * 1e3,
            "products_per_step": step / product, "iterations_mean": mean, "iterations_max": most}


def measure_drift(N: int, steps: int, save: int = 100) -> dict:
    z, y0, h, tol = setting(N)
    method = it.IsospectralMidpoint(z, h, tol=tol)
    start = time.perf_counter()
    ys = np.asarray(method.rollout(y0, steps, save_every=save))
    seconds = time.perf_counter() - start
    W = np.asarray(z.algebra.matrix(ys))
    iW = 1j * W
    traces = []
    P = iW
    for _ in range(2, 5):
        P = P @ iW
        traces.append(np.real(np.trace(P, axis1=-2, axis2=-1)))
    traces = np.stack(traces, axis=-1)  # tr (iW)^k, k = 2..4, (n_saved, 3)
    spectrum = np.linalg.eigvalsh(iW)
    scale = np.array([np.sum(np.abs(spectrum[0]) ** k) for k in (2, 3, 4)])
    energy = np.asarray(z.hamiltonian(ys))
    return {
        "N": N, "steps": steps, "h": h, "t_final": steps * h, "tol": tol, "seconds": seconds,
        "casimir_relative": (np.abs(traces - traces[0]).max(axis=0) / np.abs(traces[0])).tolist(),
        "casimir_scaled": (np.abs(traces - traces[0]).max(axis=0) / scale).tolist(),
        "spectrum_relative": float(np.abs(spectrum - spectrum[0]).max() / np.abs(spectrum[0]).max()),
        "energy_relative": float(np.abs(energy - energy[0]).max() / abs(energy[0])),
        "energy_relative_last": float(abs(energy[-1] - energy[0]) / abs(energy[0])),
    }


def report(results: dict) -> None:
    print("N     dim      h          product ms   step ms    products/step  iterations a step (mean, max)")
    for r in results["sizes"]:
        print(f"{r['N']:<5d} {r['dim']:<8d} {r['h']:.3e}  {r['product_ms']:10.4f}  {r['step_ms']:9.4f}  "
              f"{r['products_per_step']:13.1f}  {r['iterations_mean']:.2f}, {r['iterations_max']:d}")
    d = results.get("drift")
    if d:
        rel = ", ".join(f"{v:.1e}" for v in d["casimir_relative"])
        scaled = ", ".join(f"{v:.1e}" for v in d["casimir_scaled"])
        print(f"N = {d['N']}, {d['steps']} steps of h = {d['h']:.3e} (t = {d['t_final']:.3g}, {d['seconds']:.1f} s): "
              f"tr(iW)^k, k = 2..4, relative change {rel} (scaled by sum |lambda|^k: {scaled}); spectrum "
              f"{d['spectrum_relative']:.1e}; energy max {d['energy_relative']:.1e}, last {d['energy_relative_last']:.1e}")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[16, 32, 64, 128, 256, 512])
    parser.add_argument("--drift-N", type=int, default=64)
    parser.add_argument("--drift-steps", type=int, default=10000)
    add_output_arguments(parser, NAME)
    args = parser.parse_args(argv)
    if args.report:
        report(saved_results(args.out))
        return
    results: dict = {"sizes": []}
    for N in args.sizes:
        results["sizes"].append(measure_size(N))
        report(results)
    if args.drift_steps:
        results["drift"] = measure_drift(args.drift_N, args.drift_steps)
    write_json(args.out, args, results)
    report(results)


if __name__ == "__main__":
    main()
