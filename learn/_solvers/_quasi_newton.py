"""Quasi-Newton minimisation of a full-batch loss with JAX gradients: the stages
`learn.ScipyBFGS`, `learn.ScipyLBFGSB` and `learn.OptaxLBFGS` of `learn.fit` (restarts, a warm
start and keep-if-better are the wrappers `learn.Restarts`, `learn.WarmStart` and
`learn.KeepIfBetter`).

`minimiser(method, loss)` compiles the value and gradient of `loss(x, data)` (a flat parameter
vector `x`) once per loss and returns `minimise(x0, data, max_iter, progress, desc) -> (x,
history)`, so that every start or stage of a fit reuses the compiled pieces.

Methods:

- `"bfgs"`: SciPy BFGS (dense inverse Hessian; the paper's choice for G-LPNets, a few dozen
  parameters).
- `"lbfgsb"`: SciPy L-BFGS-B with 50 correction pairs (thousands of parameters: the MLP of an
  LPNet).
- `"lbfgs"`: optax L-BFGS with zoom line search, compiled in chunks of iterations.

Stopping tolerances are zero: a run stops after `max_iter` iterations or when the line search
can make no more progress at float64 resolution.

The SciPy methods run with NumPy's BLAS on one thread (`threadpoolctl`): their host updates are
small vector operations, and a multi-threaded BLAS pool spins after each of them on the cores
that JAX's gradient needs next (benchmarks, [BLAS threads in the SciPy
loop][blas-threads-in-the-scipy-loop-issue-29-benchmarksblas_threadspy]).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
import scipy.optimize
from jax.flatten_util import ravel_pytree
from threadpoolctl import threadpool_limits
from tqdm.auto import tqdm

from liepoisson import common_path_first
from liepoisson.internals import positive_int

from ._compiled import compiled
from ._problem import AbstractProblem
from ._stage import AbstractIterationsStage, Context, Result, finished_record, history

_SCIPY = {"bfgs": "BFGS", "lbfgsb": "L-BFGS-B"}
_LBFGS_CHUNK = 100

#: Quasi-Newton methods: SciPy BFGS (dense), SciPy L-BFGS-B, optax L-BFGS.
QUASI_NEWTON_METHODS = ("bfgs", "lbfgsb", "lbfgs")


def check_method(method: Any) -> str:
    if method not in QUASI_NEWTON_METHODS:
        raise ValueError(f"method must be one of {list(QUASI_NEWTON_METHODS)}; got {method!r}")
    return method


def minimiser(method: str, loss: Callable[[jax.Array, Any], jax.Array]):
    """`minimise(x0, data, max_iter, progress, desc, rtol=0, on_step=None) -> (x, {"epoch",
    "train_loss"})` for `loss(x, data)`, compiled once per `(method, loss)`; `x` is the best
    iterate seen; `on_step(iterations done, loss)` after every iteration (SciPy) or chunk of
    iterations (optax)."""
    check_method(method)
    if method in _SCIPY:
        # a non-finite value is computed again with every path of `expm_action`
        value_and_grad = compiled(("value_and_grad", loss), lambda: common_path_first(
            jax.value_and_grad(loss), lambda out: bool(np.isfinite(out[0]))))

        def minimise(x0, data, max_iter, progress, desc, rtol=0.0, on_step=None):
            return _scipy(_SCIPY[method], value_and_grad, x0, data, max_iter, progress, desc, rtol, on_step)

        return minimise
    return compiled(("lbfgs", loss), lambda: _optax_lbfgs(loss))


#: `ScipyBFGS(rtol=...)` and `ScipyLBFGSB(rtol=...)` compare the loss with its value this many iterations earlier.
RTOL_WINDOW = 20


def _scipy(method, value_and_grad, x0, data, max_iter, progress, desc, rtol=0.0, on_step=None):
    def fun(x):
        v, g = value_and_grad(jnp.asarray(x), data)
        return float(v), np.asarray(g, dtype=np.float64)

    losses: list[float] = []
    bar = tqdm(total=max_iter, disable=not progress, desc=desc, unit="it", leave=False)

    def callback(intermediate_result):
        losses.append(float(intermediate_result.fun))
        bar.update(1)
        if len(losses) % 50 == 0:
            bar.set_postfix(loss=f"{losses[-1]:.3g}")
        if on_step is not None:
            on_step(len(losses), losses[-1])
        if rtol > 0 and len(losses) > RTOL_WINDOW:
            before = losses[-1 - RTOL_WINDOW]
            if before - losses[-1] <= rtol * abs(before):
                raise StopIteration  # SciPy >= 1.11 ends the run and returns this iterate

    if method == "BFGS":
        options: dict[str, Any] = {"maxiter": max_iter, "gtol": 0.0}
    else:  # the default maxfun (15000) would stop long runs early
        options = {"maxiter": max_iter, "maxfun": 20 * max_iter, "maxcor": 50, "ftol": 0.0, "gtol": 0.0}
    try:
        with threadpool_limits(limits=1, user_api="blas"):
            res = scipy.optimize.minimize(
                fun, np.asarray(x0, dtype=np.float64), jac=True, method=method, callback=callback, options=options
            )
    finally:
        bar.close()
    hist = {"epoch": np.arange(1, len(losses) + 1), "train_loss": np.asarray(losses)}
    return jnp.asarray(res.x), hist


def _optax_lbfgs(loss):
    """optax L-BFGS (zoom line search) compiled in chunks of iterations; returns a minimiser."""
    opt = optax.lbfgs()
    evaluate = jax.jit(loss)  # once per chunk; eagerly it would dispatch op by op

    @jax.jit
    def run(x, state, data):
        def value_fn(x):
            return loss(x, data)

        vg = optax.value_and_grad_from_state(value_fn)

        def body(carry, _):
            x, state = carry
            value, grad = vg(x, state=state)
            updates, state = opt.update(grad, state, x, value=value, grad=grad, value_fn=value_fn)
            return (optax.apply_updates(x, updates), state), value

        return jax.lax.scan(body, (x, state), None, length=_LBFGS_CHUNK)

    def minimise(x0, data, max_iter, progress, desc, rtol=0.0, on_step=None):  # rtol: SciPy methods only
        x, state = x0, opt.init(x0)
        losses: list[np.ndarray] = []
        bar = tqdm(total=max_iter, disable=not progress, desc=desc, unit="it", leave=False)
        done = 0
        best_x, best = x0, np.inf
        try:
            while done < max_iter:
                (x_new, state), values = run(x, state, data)
                values = np.asarray(values)[: max_iter - done]
                losses.append(values)
                done += len(values)
                bar.update(len(values))
                bar.set_postfix(loss=f"{values[-1]:.3g}")
                if on_step is not None:
                    on_step(done, float(values[-1]))
                if not np.all(np.isfinite(values)):
                    break
                x = x_new
                current = float(evaluate(x, data))
                if current < best:
                    best_x, best = x, current
        finally:
            bar.close()
        train = np.concatenate(losses) if losses else np.zeros(0)
        hist = {"epoch": np.arange(1, len(train) + 1), "train_loss": train}
        return best_x, hist

    return minimise


class _AbstractQuasiNewton(AbstractIterationsStage):
    """One quasi-Newton run from the problem's start, its method `_method` (no selection:
    `learn.KeepIfBetter`, `learn.Restarts` do that)."""

    iterations: int
    _method: ClassVar[str]

    def __post_init__(self):
        positive_int(self.iterations, f"{type(self).__name__}.iterations")
        rtol = getattr(self, "rtol", 0.0)
        if isinstance(rtol, bool) or not isinstance(rtol, (int, float)) or not 0 <= rtol < 1:
            raise ValueError(f"{type(self).__name__}.rtol must be a number in [0, 1); got {rtol!r}")

    def run(self, problem: AbstractProblem, context: Context) -> Result:
        flat = problem.flat()
        x0, h = flat.ravel(problem.y0)
        minimise = minimiser(self._method, flat)
        start = time.perf_counter()
        x, hist = minimise(x0, (problem.train, h), self.iterations, context.progress,
                           context.desc or f"{problem.name} {self.name}", getattr(self, "rtol", 0.0),
                           context.on_step())
        params, static = eqx.partition(problem.y0, eqx.is_inexact_array)
        y = eqx.combine(ravel_pytree(params)[1](jnp.asarray(x)), static)
        record = finished_record(problem, self, len(hist["train_loss"]), start, y)
        return Result(y, record, history(hist["train_loss"], hist["epoch"]))


@dataclasses.dataclass(frozen=True)
class ScipyBFGS(_AbstractQuasiNewton):
    r"""SciPy's BFGS (dense inverse Hessian) on the full-batch loss with JAX gradients: for a
    few dozen weights (the paper's choice for G-LPNets).

    `iterations` at most; `rtol`: stop once the loss has fallen by less than `rtol` of its value
    over the last 20 iterations (0, the default: run every iteration, or until the line search
    makes no progress at float64 resolution; a fit to noisy data reaches its noise floor long
    before, e.g. `rtol=1e-9`). The result is the last iterate: wrap it in `learn.KeepIfBetter`
    to keep it only if it lowers the selection loss, in `learn.Restarts` for fresh starts and
    in `learn.WarmStart` for a simpler problem first (the paper's G-LPNet training:
    `learn.KeepIfBetter(learn.Restarts(learn.WarmStart(learn.ScipyBFGS(3500)), 4))`)."""

    iterations: int = 3500
    rtol: float = 0.0
    _method: ClassVar[str] = "bfgs"


@dataclasses.dataclass(frozen=True)
class ScipyLBFGSB(_AbstractQuasiNewton):
    r"""SciPy's L-BFGS-B with 50 correction pairs on the full-batch loss with JAX gradients: for
    thousands of weights (the MLP of an LPNet; Adam refined by it,
    `(learn.Adam(30_000), learn.KeepIfBetter(learn.ScipyLBFGSB(5000)))`).

    `iterations` and `rtol` as `learn.ScipyBFGS`'s; the result is the last iterate (wrappers:
    `learn.KeepIfBetter`, `learn.Restarts`, `learn.WarmStart`)."""

    iterations: int = 3500
    rtol: float = 0.0
    _method: ClassVar[str] = "lbfgsb"


@dataclasses.dataclass(frozen=True)
class OptaxLBFGS(_AbstractQuasiNewton):
    r"""optax's L-BFGS with its zoom line search, compiled in chunks of 100 iterations (the loop
    on the device): `iterations` at most; the result is the iterate of lowest training loss at
    the end of a chunk (wrappers: `learn.KeepIfBetter`, `learn.Restarts`, `learn.WarmStart`)."""

    iterations: int = 3500
    _method: ClassVar[str] = "lbfgs"
