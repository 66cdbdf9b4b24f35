r"""The isospectral midpoint method on Zeitlin's model beside quflow's (BENCHMARKS.md, "Zeitlin's
model"): milliseconds a step, the fixed-point iterations a step, the Casimirs' drift over a long
run and the state's difference from a run at a quarter of the step, for quflow's `isomp` (its
default and with compensated summation, `compsum=True`) and the library's
`integrators.IsospectralMidpoint` (its default and `integrators.Compensated` of it); the unit of time one
OpenBLAS ZGEMM of the same size, measured in the same run.

    taskset -c 0 python -m benchmarks.zeitlin [--sizes 64 128 256 512] [--casimir-N 64] [--casimir-steps 10000]
    taskset -c 0 python -m benchmarks.zeitlin --sizes --casimir-steps 0 --drift-N 32 --drift-steps 1000000
    python -m benchmarks.zeitlin --report

quflow is not on PyPI: its source tree (klasmodin/quflow, measured at b42eede) is looked for at
`$QUFLOW_PATH`, default `../quflow` beside this repository (the folder holding its `quflow/`
package), and numba (`pip install -e ".[bench]"`) must be installed. Only what `isomp` needs is
imported from it, without its package `__init__` (graphics, HDF5 and spherical transforms:
`load_quflow`); without it the quflow columns are skipped with a one-line message and the
library's are measured alone.

Protocol (issue 64): the initial matrix quflow's `shr2mat(random_shr(lmax=10, seed=42))`
(rebuilt here without quflow: `initial_state`; checked against quflow's when it is there), the
step $h = 0.25\hbar$ in physical time for both (the library's `h` is quflow's `dt`), each code
with its default tolerance. One process, one thread: the process is pinned to one CPU before
XLA starts (XLA sizes its thread pool by the CPUs it may run on; its flag
`--xla_cpu_multi_thread_eigen=false` alone left its products on two threads), OpenBLAS, numba
and OpenMP limited to one thread by their variables below, and the threads that did the work
of a product are counted (`busy_threads`). The four codes and the ZGEMM are timed in turns,
`--repeats` rounds, the fastest of each kept, so that a load shared with other processes falls
on all of them alike; each timed block starts from a state already 10 steps in.
"""

from __future__ import annotations

import os
import sys

# One thread for everything (set before NumPy, SciPy, numba and JAX load their libraries).
for _variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")
os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false")
if __name__ == "__main__" and hasattr(os, "sched_setaffinity"):
    # XLA's CPU client sizes its thread pool by the CPUs this process may use, when it starts
    # (after this line): one CPU, one thread. `taskset -c K` chooses which; otherwise the first.
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})

import argparse
import importlib
import time
import types
import warnings
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import integrators as it
import liepoisson as lp

from ._report import add_output_arguments, saved_results, write_json

NAME = "zeitlin"
#: quflow's source tree (the folder holding its `quflow` package): `$QUFLOW_PATH`, else beside
#: this repository.
QUFLOW_PATH = Path(os.environ.get("QUFLOW_PATH", Path(__file__).resolve().parents[2] / "quflow"))
METHODS = ("quflow", "quflow compsum", "library", "library compensated")


# -- quflow, from its source ---------------------------------------------------------------------------
def load_quflow(path: str | os.PathLike = QUFLOW_PATH) -> tuple[types.SimpleNamespace | None, str]:
    """`(quflow, "")` with `isomp`, `shr2mat`, `random_shr` and `hbar` of quflow's source tree at
    `path`, or `(None, why)`. Its package `__init__` imports graphics (matplotlib, cartopy),
    HDF5 files and spherical transforms (ducc0) that `isomp` does not need: the package is
    registered empty and the modules `isomp` needs are imported from it, with its file I/O
    (the basis cache on disk: the basis is computed) and its transforms stubbed."""
    root = Path(path)
    if not (root / "quflow" / "integrators" / "isospectral.py").is_file():
        return None, f"quflow not found at {root} (set QUFLOW_PATH to the folder holding its quflow/ package)"
    try:
        import numba  # noqa: F401
    except ImportError:
        return None, "quflow needs numba (pip install -e '.[bench]')"
    saved = {name: module for name, module in sys.modules.items() if name == "quflow" or name.startswith("quflow.")}
    package = types.ModuleType("quflow")
    package.__path__ = [str(root / "quflow")]
    io = types.ModuleType("quflow.io")
    io.load_basis = lambda N: None  # nothing cached on disk: computed
    io.save_basis = lambda basis: None
    transforms = types.ModuleType("quflow.transforms")

    def _absent(*args, **kwargs):
        raise NotImplementedError("quflow's spherical transforms are not loaded by benchmarks.zeitlin")

    transforms.as_shr = transforms.mat2shr = _absent
    sys.modules.update({"quflow": package, "quflow.io": io, "quflow.transforms": transforms})
    try:
        with warnings.catch_warnings():  # its source's own (invalid escapes in docstrings): not ours to fix
            warnings.simplefilter("ignore")
            quantization = importlib.import_module("quflow.quantization")
            analysis = importlib.import_module("quflow.analysis")
            geometry = importlib.import_module("quflow.geometry")
            isospectral = importlib.import_module("quflow.integrators.isospectral")
    except Exception as error:  # noqa: BLE001  (any failure: the benchmark goes on without it)
        for name in [name for name in sys.modules if name == "quflow" or name.startswith("quflow.")]:
            del sys.modules[name]
        sys.modules.update(saved)
        return None, f"quflow at {root} did not import: {type(error).__name__}: {error}"
    return types.SimpleNamespace(isomp=isospectral.isomp, shr2mat=quantization.shr2mat, random_shr=analysis.random_shr,
                                 hbar=geometry.hbar, path=root), ""


def initial_state(z: lp.systems.Zeitlin, seed: int = 42, lmax: int = 10) -> np.ndarray:
    r"""The state of quflow's `shr2mat(random_shr(lmax, seed=seed), N)` without quflow: its
    Gaussian coefficients (NumPy's legacy generator seeded `seed`) up to degree `lmax`,
    damped by $(l(l+1))^{-1/2}$, no degree 0 or 1, unit norm."""
    rng = np.random.RandomState(seed)
    omega = rng.standard_normal((lmax + 1) ** 2)
    els = np.floor(np.sqrt(np.arange(omega.size))).astype(int)
    omega[0] = 0.0
    omega[1:] /= np.sqrt(els[1:] * (els[1:] + 1.0))
    omega[1:4] = 0.0
    omega /= np.linalg.norm(omega)
    full = np.zeros(z.N * z.N)
    full[: min(omega.size, full.size)] = omega[: full.size]
    return z.state_from_harmonics(full)


# -- one thread ------------------------------------------------------------------------------------
def thread_seconds() -> dict[str, float]:
    """CPU seconds of each thread of this process (Linux's /proc; empty elsewhere)."""
    out = {}
    tick = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
    for tid in os.listdir("/proc/self/task") if os.path.isdir("/proc/self/task") else []:
        try:
            fields = Path(f"/proc/self/task/{tid}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        out[tid] = (int(fields[11]) + int(fields[12])) / tick
    return out


def busy_threads(fn, share: float = 0.1) -> tuple[int, float, float]:
    """`(threads, wall, cpu)` of a call of `fn`: how many threads did at least `share` of its
    CPU time, its wall time and the process's CPU time."""
    before = thread_seconds()
    wall, cpu = time.perf_counter(), time.process_time()
    fn()
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    after = thread_seconds()
    used = [after[t] - before.get(t, 0.0) for t in after]
    return sum(u >= share * max(sum(used), 1e-9) for u in used), wall, cpu


# -- the codes -------------------------------------------------------------------------------------
@eqx.filter_jit
def advance(method: it.AbstractStepMap, c, n_steps: jax.Array):
    """`n_steps` (traced: one program for every count) steps of `method` on its carried state."""
    return jax.lax.fori_loop(0, n_steps, lambda _, c: method.step_carry(c), c)


class Library:
    """`integrators.IsospectralMidpoint`, or `integrators.Compensated` of it, run on its carried
    state (the matrix itself first)."""

    def __init__(self, z: lp.systems.Zeitlin, y0: np.ndarray, h: float, compensated: bool, tol: float | None = None):
        kwargs = {} if tol is None else {"tol": tol}
        self.plain = it.IsospectralMidpoint(z, h, **kwargs)
        self.method = it.Compensated(self.plain) if compensated else self.plain
        self.c0 = self.method.carry(jnp.asarray(y0))
        self.warm = jax.block_until_ready(advance(self.method, self.c0, jnp.asarray(10)))  # compiles

    def run(self, n: int, c=None):
        return jax.block_until_ready(advance(self.method, self.warm if c is None else c, jnp.asarray(n)))

    def iterations(self, n: int) -> float:
        # the plain map's count (the compensated one's differs only by its products' round-off)
        return self.plain.iterations_needed(np.asarray(self.method.uncarry(self.warm)), n_steps=n)[0]

    def matrices(self, n_steps: int, every: int) -> np.ndarray:
        """`W` at steps 0, every, 2 every, ... n_steps (the carried matrix, not rounded through
        coordinates)."""
        c, out = self.c0, [np.asarray(self.c0[0])]
        for _ in range(n_steps // every):
            c = self.run(every, c)
            out.append(np.asarray(c[0]))
        return np.stack(out)


class Quflow:
    """quflow's `isomp` (its default, or `compsum=True`)."""

    def __init__(self, quflow, W0: np.ndarray, h: float, compsum: bool):
        self.quflow, self.h, self.compsum = quflow, h, compsum
        self.W0 = np.array(W0)
        self.warm = self._isomp(self.W0.copy(), 10)[0]  # compiles numba's kernels
        self.stats: dict = {}

    def _isomp(self, W, n):
        stats = {"iterations": 0.0}  # quflow fills a non-empty dict only
        return self.quflow.isomp(W, self.h, steps=n, stats=stats, compsum=self.compsum), stats

    def run(self, n: int):
        W, self.stats = self._isomp(self.warm.copy(), n)
        return W

    def iterations(self, n: int) -> float:
        return self._isomp(self.warm.copy(), n)[1]["iterations"]

    def matrices(self, n_steps: int, every: int) -> np.ndarray:
        # one call: quflow keeps its compensation and its iteration's start only within a call;
        # the saved states by its callback (called before each step's update)
        W, out, step = self.W0.copy(), [], [0]

        def callback(W, dW):
            if step[0] % every == 0:
                out.append(np.array(W))
            step[0] += 1

        self.quflow.isomp(W, self.h, steps=n_steps, compsum=self.compsum, callback=callback)
        out.append(np.array(W))
        return np.stack(out)


def zgemm_seconds(N: int, repeats: int = 3) -> float:
    """The fastest time of one OpenBLAS ZGEMM (SciPy's) of two N x N complex matrices."""
    from scipy.linalg.blas import zgemm

    rng = np.random.default_rng(0)
    A = np.asfortranarray(rng.normal(size=(N, N)) + 1j * rng.normal(size=(N, N)))
    B = np.asfortranarray(rng.normal(size=(N, N)) + 1j * rng.normal(size=(N, N)))
    k = max(3, int(2e8 / (8 * N**3)))
    zgemm(1.0, A, B)
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(k):
            zgemm(1.0, A, B)
        best = min(best, (time.perf_counter() - start) / k)
    return best


# -- Casimirs --------------------------------------------------------------------------------------
def casimirs(Ws: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    r"""`(C, scale)`: $C_k = \mathrm{tr}(iW)^k$, $k = 2, 3, 4$, of each matrix of `Ws`
    `(n, N, N)` in extended precision (`np.longdouble`: the drift measured, not the round-off
    of measuring it), and $\sum_i|\lambda_i|^k$ of the first (the size a drift is relative to)."""
    iW = 1j * np.asarray(Ws, dtype=np.clongdouble)
    square = np.matmul(iW, iW)
    t = np.swapaxes(iW, -1, -2)
    C = np.stack([np.sum(iW * t, axis=(-2, -1)), np.sum(square * t, axis=(-2, -1)),
                  np.sum(square * np.swapaxes(square, -1, -2), axis=(-2, -1))], axis=-1).real
    spectrum = np.linalg.eigvalsh(1j * np.asarray(Ws[0], dtype=np.complex128))
    scale = np.array([np.sum(np.abs(spectrum) ** k) for k in (2, 3, 4)])
    return np.asarray(C, dtype=np.float64), scale


def casimir_drift(Ws: np.ndarray) -> float:
    r"""$\max_{t,k}|C_k(t) - C_k(0)|/\sum_i|\lambda_i|^k$ ($k = 2, 3, 4$: `casimirs`)."""
    C, scale = casimirs(Ws)
    return float((np.abs(C - C[0]) / scale).max())


# -- the measurements ------------------------------------------------------------------------------
def codes(N: int, quflow, h_over_hbar: float = 0.25) -> tuple[dict, np.ndarray, float]:
    """`({name: code}, W0, h)` for the size `N` (the quflow ones only with quflow)."""
    z = lp.systems.Zeitlin(N)
    y0 = initial_state(z)
    W0 = np.asarray(z.algebra.matrix(y0))
    h = h_over_hbar * z.hbar
    out = {}
    if quflow is not None:
        Wq = quflow.shr2mat(quflow.random_shr(lmax=10, seed=42), N=N)
        gap = np.abs(Wq - W0).max() / np.abs(Wq).max()
        # each code builds the quantized harmonics by its own eigen-solver: 5e-15 at N = 16,
        # 5e-13 at N = 512 (round-off growing with N); a wrong seed, damping or index is O(1)
        if not gap < 1e-10:
            raise RuntimeError(f"the initial matrix differs from quflow's by {gap:.1e} (relative) at N = {N}")
        out["quflow"] = Quflow(quflow, Wq, h, compsum=False)
        out["quflow compsum"] = Quflow(quflow, Wq, h, compsum=True)
    out["library"] = Library(z, y0, h, compensated=False)
    out["library compensated"] = Library(z, y0, h, compensated=True)
    return out, W0, h


def measure_size(N: int, quflow, repeats: int, min_seconds: float = 0.5) -> dict:
    """ms a step of each code and of one ZGEMM, timed in turns (`repeats` rounds)."""
    runners, _, h = codes(N, quflow)
    # steps a block: about min_seconds for the slowest code
    probe = {name: _timed(lambda r=r: r.run(2)) / 2 for name, r in runners.items()}
    n = max(2, int(min_seconds / max(probe.values())))
    best = {name: np.inf for name in runners} | {"zgemm": np.inf}
    for _ in range(repeats):
        for name, runner in runners.items():
            best[name] = min(best[name], _timed(lambda r=runner: r.run(n)) / n)
        best["zgemm"] = min(best["zgemm"], zgemm_seconds(N))
    iterations = {name: runner.iterations(min(n, 50) if name.startswith("library") else n)
                  for name, runner in runners.items()}
    return {"N": N, "h": h, "steps_timed": n, "zgemm_ms": best["zgemm"] * 1e3,
            "ms": {name: best[name] * 1e3 for name in runners}, "iterations": iterations}


def measure_accuracy(N: int, quflow, steps: int, reference_steps: int, every: int = 100) -> dict:
    """The Casimirs' drift over `steps` steps and, after `reference_steps` steps, the state's
    relative difference (Frobenius) from the library's compensated run at h/4, tol 1e-14."""
    runners, _, h = codes(N, quflow)
    z = lp.systems.Zeitlin(N)
    reference = Library(z, initial_state(z), h / 4, compensated=True, tol=1e-14).matrices(4 * reference_steps,
                                                                                           4 * reference_steps)[-1]
    out = {"N": N, "h": h, "steps": steps, "reference_steps": reference_steps, "drift": {}, "state": {}, "seconds": {}}
    for name, runner in runners.items():
        start = time.perf_counter()
        out["drift"][name] = casimir_drift(runner.matrices(steps, every)) if steps else None
        out["seconds"][name] = time.perf_counter() - start
        W = runner.matrices(reference_steps, reference_steps)[-1]
        out["state"][name] = float(np.linalg.norm(W - reference) / np.linalg.norm(reference))
    return out


def measure_long_drift(N: int, steps: int, every: int = 1000) -> dict:
    """The library's Casimir drift (plain and compensated) over `steps` steps at N, with the
    time each run took."""
    z = lp.systems.Zeitlin(N)
    out = {"N": N, "steps": steps, "h": 0.25 * z.hbar}
    for compensated in (False, True):
        start = time.perf_counter()
        Ws = Library(z, initial_state(z), 0.25 * z.hbar, compensated=compensated).matrices(steps, every)
        C, scale = casimirs(Ws)
        key = "compensated" if compensated else "plain"
        out[key] = {"seconds": time.perf_counter() - start, "drift": float((np.abs(C - C[0]) / scale).max()),
                    "drift_last": float((np.abs(C[-1] - C[0]) / scale).max())}
        print(f"N = {N}, {steps} steps, {key}: Casimir drift {out[key]['drift']:.1e} "
              f"({out[key]['seconds']:.0f} s)", flush=True)
    return out


def _timed(fn) -> float:
    start = time.perf_counter()
    fn()
    return time.perf_counter() - start


# -- the report ------------------------------------------------------------------------------------
def report(results: dict) -> None:
    env = results.get("environment", {})
    if env:
        print(f"one CPU ({env.get('cpus')}); XLA threads busy in a 3M product: {env.get('xla_threads')}; "
              f"load average {env.get('load_before')} before, {env.get('load_after')} after; "
              f"quflow: {env.get('quflow') or 'absent'}")
    sizes = results.get("sizes", [])
    if sizes:
        names = [m for m in METHODS if m in sizes[0]["ms"]]
        print("N     ZGEMM ms  " + "  ".join(f"{m + ' ms (ZGEMMs)':>30}" for m in names) + "   library/quflow  "
              "library compensated/quflow compsum   iterations a step (" + ", ".join(names) + ")")
        for r in sizes:
            z = r["zgemm_ms"]
            cells = "  ".join(f"{r['ms'][m]:>17.3f} ({r['ms'][m] / z:6.1f})     " for m in names)
            ratio = (f"{r['ms']['library'] / r['ms']['quflow']:14.2f}  "
                     f"{r['ms']['library compensated'] / r['ms']['quflow compsum']:34.2f}"
                     if "quflow" in r["ms"] else " " * 52)
            its = ", ".join(f"{r['iterations'][m]:.2f}" for m in names)
            print(f"{r['N']:<5d} {z:8.3f}  {cells} {ratio}   {its}")
    a = results.get("accuracy")
    if a:
        print(f"N = {a['N']}, h = 0.25 hbar: Casimir drift over {a['steps']} steps (max over k = 2..4 of "
              f"|tr(iW)^k - tr(iW0)^k| / sum |lambda|^k); state after {a['reference_steps']} steps against h/4 "
              "(relative, Frobenius)")
        for m, drift in a["drift"].items():
            shown = "-" if drift is None else f"{drift:.1e}"
            print(f"  {m:<22} drift {shown:>8}   state {a['state'][m]:.2e}   ({a['seconds'][m]:.0f} s)")
    d = results.get("long_drift")
    if d:
        for key in ("plain", "compensated"):
            print(f"N = {d['N']}, {d['steps']} steps of 0.25 hbar, library {key}: Casimir drift {d[key]['drift']:.1e} "
                  f"(at the end {d[key]['drift_last']:.1e}; {d[key]['seconds']:.0f} s)")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="*", default=[64, 128, 256, 512])
    parser.add_argument("--repeats", type=int, default=3, help="rounds of timing in turns")
    parser.add_argument("--casimir-N", type=int, default=64)
    parser.add_argument("--casimir-steps", type=int, default=10000, help="0: no Casimir drift or state difference")
    parser.add_argument("--reference-steps", type=int, default=100)
    parser.add_argument("--drift-N", type=int, default=32)
    parser.add_argument("--drift-steps", type=int, default=0, help="the library's long drift run (e.g. 1000000)")
    add_output_arguments(parser, NAME)
    args = parser.parse_args(argv)
    if args.report:
        report(saved_results(args.out))
        return
    quflow, why = load_quflow()
    if quflow is None:
        print(f"quflow skipped: {why}")
    loop = _product_loop(512, k=10)
    threads = busy_threads(loop)[0]
    results: dict = {"environment": {"cpus": sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
                                     "xla_threads": threads, "load_before": os.getloadavg()[0],
                                     "quflow": str(quflow.path) if quflow else None}, "sizes": []}
    for N in args.sizes:
        results["sizes"].append(measure_size(N, quflow, args.repeats))
        report({"sizes": results["sizes"][-1:]})
    if args.casimir_steps:
        results["accuracy"] = measure_accuracy(args.casimir_N, quflow, args.casimir_steps, args.reference_steps)
    if args.drift_steps:
        results["long_drift"] = measure_long_drift(args.drift_N, args.drift_steps)
    results["environment"]["load_after"] = os.getloadavg()[0]
    write_json(args.out, args, results)
    report(results)


def _product_loop(N: int, k: int = 20):
    """A compiled call of `k` complex N x N products as the library forms them
    (`integrators._products.matmul`)."""
    from integrators._products import matmul

    A = jnp.asarray(np.random.default_rng(0).normal(size=(N, N)) * (1 + 1j) / N)
    loop = jax.jit(lambda A: jax.lax.fori_loop(0, k, lambda _, X: matmul(A, X), A))
    jax.block_until_ready(loop(A))
    return lambda: jax.block_until_ready(loop(A))


if __name__ == "__main__":
    main()
