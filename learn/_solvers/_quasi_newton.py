"""Quasi-Newton minimisation of a full-batch loss with JAX gradients: the stages
`learn.ScipyBFGS`, `learn.ScipyLBFGSB` and `learn.OptaxLBFGS` of `learn.fit` (restarts, a warm
start and keep-if-better are the wrappers `learn.Restarts`, `learn.WarmStart` and
`learn.KeepIfBetter`).

Each is a solver of the shared loop (`learn.AbstractSolver`): SciPy's BFGS and L-BFGS-B one
iteration a step (SciPy's own loop in a thread of its own, handing each iteration over), optax's
L-BFGS one compiled chunk of iterations a step. The value and gradient of the flat objective
are compiled once per objective and structure, so that every start or stage of a fit reuses
them. Stopping tolerances are zero: a run stops after its iterations, when the line search can
make no more progress at float64 resolution, or by `rtol` (SciPy's).
"""

from __future__ import annotations

import contextvars
import dataclasses
import queue
import threading
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

from liepoisson import common_path_first
from liepoisson.internals import positive_int

from ._compiled import compiled
from ._loop import AbstractSolver, Step, losses_step
from ._problem import AbstractProblem
from ._stage import Context, Result

#: `ScipyBFGS(rtol=...)` and `ScipyLBFGSB(rtol=...)` compare the loss with its value this many
#: iterations earlier.
RTOL_WINDOW = 20

_LBFGS_CHUNK = 100


def _value_and_grad(loss: Callable[[jax.Array, Any], jax.Array]):
    """`loss`'s value and gradient, compiled once per loss (a non-finite value is computed
    again with every path of `expm_action`)."""
    return compiled(("value_and_grad", loss), lambda: common_path_first(
        jax.value_and_grad(loss), lambda out: bool(np.isfinite(out[0]))))


class _ScipyRun:
    """`scipy.optimize.minimize` turned inside out: it runs in a thread of its own (its loop is
    SciPy's) and hands each iteration's loss to the shared loop through its callback, waiting
    there for the next step or for the end (its callback then raises `StopIteration`, and SciPy
    returns that iterate). The arithmetic is SciPy's, unchanged; the caller's context variables
    are copied into the thread."""

    def __init__(self, method: str, value_and_grad: Any, x0: jax.Array, data: Any, max_iter: int):
        self._out: queue.Queue = queue.Queue()
        self._go: queue.Queue = queue.Queue()
        self._waiting = False
        self.x: np.ndarray = np.asarray(x0, dtype=np.float64)

        def evaluate(x):
            v, g = value_and_grad(jnp.asarray(x), data)
            return float(v), np.asarray(g, dtype=np.float64)

        # SciPy's first evaluation (at x0) is made here, so that the value and gradient compile
        # in the caller's thread, not in SciPy's (a segfault was seen in the persistent cache's
        # write of an executable compiled in SciPy's thread; not the only crash of that kind:
        # issue 63); the same compiled function gives the same numbers.
        start = np.array(x0, dtype=np.float64)
        first = [evaluate(start)]

        def fun(x):
            if first and np.array_equal(x, start):
                return first.pop()
            return evaluate(x)

        def callback(intermediate_result):
            self._out.put(("iteration", float(intermediate_result.fun), np.array(intermediate_result.x)))
            if self._go.get() == "stop":
                raise StopIteration  # SciPy >= 1.11 ends the run and returns this iterate

        if method == "BFGS":
            options: dict[str, Any] = {"maxiter": max_iter, "gtol": 0.0}
        else:  # the default maxfun (15000) would stop long runs early
            options = {"maxiter": max_iter, "maxfun": 20 * max_iter, "maxcor": 50, "ftol": 0.0, "gtol": 0.0}

        def minimise():
            try:
                res = scipy.optimize.minimize(fun, np.asarray(x0, dtype=np.float64), jac=True, method=method,
                                              callback=callback, options=options)
                self._out.put(("done", res.message, np.asarray(res.x)))
            except BaseException as err:  # noqa: BLE001 (handed to the loop's thread, raised there)
                self._out.put(("error", err, None))

        context = contextvars.copy_context()
        self._thread = threading.Thread(target=context.run, args=(minimise,), daemon=True)
        self._thread.start()

    def next(self) -> tuple[str, Any]:
        """`("iteration", loss)` after SciPy's next iteration, or `("done", message)`."""
        if self._waiting:
            self._go.put("go")
        kind, value, x = self._out.get()
        if kind == "error":
            self._waiting = False
            raise value
        self._waiting = kind == "iteration"
        self.x = x
        return kind, value

    def close(self) -> None:
        """End the run at the current iterate (its callback raises `StopIteration`)."""
        if self._waiting:
            self._go.put("stop")
            self._waiting = False
            kind, value, x = self._out.get()
            if kind == "error":
                raise value
            self.x = x
        self._thread.join()


@dataclasses.dataclass
class _ScipyState:
    run: _ScipyRun
    unravel: Any
    done: int = 0


class _AbstractScipy(AbstractSolver):
    """One SciPy quasi-Newton run from the problem's start (no selection: `learn.KeepIfBetter`,
    `learn.Restarts` do that), its method `_method`; every iteration one step of the shared
    loop. BLAS on one thread (`threadpoolctl`, for the whole run): SciPy's host updates are small
    vector operations, and a multi-threaded BLAS pool spins after each of them on the cores that JAX's
    gradient needs next (benchmarks, [BLAS threads in the SciPy
    loop][blas-threads-in-the-scipy-loop-issue-29-benchmarksblas_threadspy])."""

    iterations: int
    rtol: float
    _method: ClassVar[str]

    def __post_init__(self):
        positive_int(self.iterations, f"{type(self).__name__}.iterations")
        if isinstance(self.rtol, bool) or not isinstance(self.rtol, (int, float)) or not 0 <= self.rtol < 1:
            raise ValueError(f"{type(self).__name__}.rtol must be a number in [0, 1); got {self.rtol!r}")

    def run(self, problem: AbstractProblem, context: Context) -> Result:
        # set from this thread: OpenBLAS takes a thread count set from another thread as that
        # thread's alone
        with threadpool_limits(limits=1, user_api="blas"):
            return super().run(problem, context)

    def init(self, problem: AbstractProblem, context: Context) -> Any:
        flat = problem.flat()
        x0, h = flat.ravel(problem.y0)
        run = _ScipyRun(self._method, _value_and_grad(flat), x0, (problem.train, h), self.iterations)
        return _ScipyState(run, _unflatten(problem))

    def step(self, problem: AbstractProblem, state: Any) -> tuple[Any, Step]:
        kind, value = state.run.next()
        if kind == "done":
            return state, losses_step(state.done, [], stop=str(value))
        state.done += 1
        return state, losses_step(state.done - 1, [value])

    def terminate(self, problem: AbstractProblem, state: Any, losses: list[float]) -> bool:
        if self.rtol <= 0 or len(losses) <= RTOL_WINDOW:
            return False
        before = losses[-1 - RTOL_WINDOW]
        return before - losses[-1] <= self.rtol * abs(before)

    def current(self, state: Any) -> Any:
        return state.unravel(state.run.x)

    def close(self, state: Any) -> None:
        state.run.close()


@dataclasses.dataclass(frozen=True)
class ScipyBFGS(_AbstractScipy):
    r"""SciPy's BFGS (dense inverse Hessian) on the full-batch loss with JAX gradients: for a
    few dozen weights (the paper's choice for G-LPNets). Not for thousands: SciPy updates the
    inverse Hessian by two dense $n \times n$ products a step, $O(n^3)$: use `learn.ScipyLBFGSB`
    (BENCHMARKS.md, "W6: learned maps that keep the constraint", a 64 x 64 neural ODE).

    `iterations` at most; `rtol`: stop once the loss has fallen by less than `rtol` of its value
    over the last 20 iterations (0, the default: run every iteration, or until the line search
    makes no progress at float64 resolution; a fit to noisy data reaches its noise floor long
    before, e.g. `rtol=1e-9`). The result is the last iterate: wrap it in `learn.KeepIfBetter`
    to keep it only if it lowers the selection loss, in `learn.Restarts` for fresh starts and
    in `learn.WarmStart` for a simpler problem first (the paper's G-LPNet training:
    `learn.KeepIfBetter(learn.Restarts(learn.WarmStart(learn.ScipyBFGS(3500)), 4))`). SciPy's
    loop runs in a thread of its own, handing each iteration to the shared loop."""

    iterations: int = 3500
    rtol: float = 0.0
    _method: ClassVar[str] = "BFGS"


@dataclasses.dataclass(frozen=True)
class ScipyLBFGSB(_AbstractScipy):
    r"""SciPy's L-BFGS-B with 50 correction pairs on the full-batch loss with JAX gradients: for
    thousands of weights (the MLP of an LPNet; Adam refined by it,
    `(learn.Adam(30_000), learn.KeepIfBetter(learn.ScipyLBFGSB(5000)))`).

    `iterations` and `rtol` as `learn.ScipyBFGS`'s; the result is the last iterate (wrappers:
    `learn.KeepIfBetter`, `learn.Restarts`, `learn.WarmStart`)."""

    iterations: int = 3500
    rtol: float = 0.0
    _method: ClassVar[str] = "L-BFGS-B"


def _optax_lbfgs(loss: Callable[[jax.Array, Any], jax.Array]):
    """`(init, run, evaluate)` of optax's L-BFGS (zoom line search) on `loss(x, data)`: `run` one
    compiled chunk of `_LBFGS_CHUNK` iterations, compiled once per loss."""
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

    return opt.init, run, evaluate


@dataclasses.dataclass
class _OptaxState:
    x: jax.Array
    opt_state: Any
    data: Any
    #: The `y` of a flat `x` (the problem's fixed part, its step size included).
    y: Callable[[jax.Array], Any]
    done: int = 0


def _unflatten(problem: AbstractProblem) -> Callable[[Any], Any]:
    """The `y` whose flat trainable leaves are `x`, the rest the start's."""
    params, static = eqx.partition(problem.y0, eqx.is_inexact_array)
    unravel = ravel_pytree(params)[1]
    return lambda x: eqx.combine(unravel(jnp.asarray(x)), static)


@dataclasses.dataclass(frozen=True)
class OptaxLBFGS(AbstractSolver):
    r"""optax's L-BFGS with its zoom line search, compiled in chunks of 100 iterations (the loop
    on the device; one chunk a step of the shared loop): `iterations` at most; the result is
    the iterate of lowest training loss at the end of a chunk (wrappers: `learn.KeepIfBetter`,
    `learn.Restarts`, `learn.WarmStart`)."""

    iterations: int = 3500
    keeps_best: ClassVar[bool] = True

    def __post_init__(self):
        positive_int(self.iterations, "OptaxLBFGS.iterations")

    def _compiled(self, problem: AbstractProblem):
        flat = problem.flat()
        return flat, compiled(("lbfgs", flat), lambda: _optax_lbfgs(flat))

    def init(self, problem: AbstractProblem, context: Context) -> Any:
        flat, (opt_init, _, _) = self._compiled(problem)
        x0, h = flat.ravel(problem.y0)
        return _OptaxState(x0, opt_init(x0), (problem.train, h), _unflatten(problem))

    def initial_best(self, problem: AbstractProblem) -> tuple[Any, float, int]:
        return problem.y0, np.inf, 0

    def step(self, problem: AbstractProblem, state: Any) -> tuple[Any, Step]:
        _, (_, run, evaluate) = self._compiled(problem)
        (x_new, opt_state), values = run(state.x, state.opt_state, state.data)
        values = np.asarray(values)[: self.iterations - state.done]
        before, state.done = state.done, state.done + len(values)
        if not np.all(np.isfinite(values)):
            return state, losses_step(before, values, stop="a non-finite loss; kept the best iterate before it")
        state.x, state.opt_state = x_new, opt_state
        current = float(evaluate(state.x, state.data))
        return state, losses_step(before, values, candidate=(state.y(state.x), current, state.done))

    def current(self, state: Any) -> Any:
        return state.y(state.x)
