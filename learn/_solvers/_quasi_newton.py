"""Quasi-Newton minimisation of a full-batch loss with JAX gradients, and the `QuasiNewton`
stage of `learn.fit` (every start minimised, the best kept; the warm start a map offers).

`minimiser(method, loss, X, Y)` compiles the value and gradient of `loss(x, X, Y)` (a flat
parameter vector `x`) once and returns `minimise(x0, max_iter, progress, desc) -> (x, history)`,
so that every start or stage of a fit reuses the compiled pieces.

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
that JAX's gradient needs next (BENCHMARKS.md, "BLAS threads in the SciPy loop").
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from typing import Any

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

from ._optimisers import QuasiNewton, check_method
from ._record import StageRecord

_SCIPY = {"bfgs": "BFGS", "lbfgsb": "L-BFGS-B"}
_LBFGS_CHUNK = 100


_VALUE_AND_GRAD: dict[Any, Any] = {}


def _value_and_grad(loss):
    """`jax.jit(jax.value_and_grad(loss))` (by `liepoisson.common_path_first`: a non-finite
    value is computed again with every path of `expm_action`), one per `loss` (by equality: a
    loss object equal to an earlier one reuses its compiled code)."""

    def build():
        return common_path_first(jax.value_and_grad(loss), lambda out: bool(np.isfinite(out[0])))

    try:
        if loss not in _VALUE_AND_GRAD:
            if len(_VALUE_AND_GRAD) >= 64:
                _VALUE_AND_GRAD.clear()
            _VALUE_AND_GRAD[loss] = build()
        return _VALUE_AND_GRAD[loss]
    except TypeError:  # unhashable
        return build()


def minimiser(method: str, loss: Callable[[jax.Array, Any, Any], jax.Array], X: Any, Y: Any):
    """`minimise(x0, max_iter, progress, desc, rtol=0, on_step=None) -> (x, {"epoch", "train_loss"})`
    for `loss(x, X, Y)`; `x` is the best iterate seen; `on_step(iterations done, loss)` after
    every iteration (SciPy) or chunk of iterations (optax)."""
    check_method(method)
    if method in _SCIPY:
        value_and_grad = _value_and_grad(loss)

        def minimise(x0, max_iter, progress, desc, rtol=0.0, on_step=None):
            return _scipy(_SCIPY[method], value_and_grad, x0, X, Y, max_iter, progress, desc, rtol, on_step)

        return minimise
    return _optax_lbfgs(loss, X, Y)


#: `QuasiNewton(rtol=...)` compares the loss with its value this many iterations earlier.
RTOL_WINDOW = 20


def _scipy(method, value_and_grad, x0, X, Y, max_iter, progress, desc, rtol=0.0, on_step=None):
    def fun(x):
        v, g = value_and_grad(jnp.asarray(x), X, Y)
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


def _optax_lbfgs(loss, X, Y):
    """optax L-BFGS (zoom line search) compiled in chunks of iterations; returns a minimiser."""
    opt = optax.lbfgs()

    def value_fn(x):
        return loss(x, X, Y)

    vg = optax.value_and_grad_from_state(value_fn)
    evaluate = jax.jit(value_fn)  # once per chunk; eagerly it would dispatch op by op

    @jax.jit
    def run(x, state):
        def body(carry, _):
            x, state = carry
            value, grad = vg(x, state=state)
            updates, state = opt.update(grad, state, x, value=value, grad=grad, value_fn=value_fn)
            return (optax.apply_updates(x, updates), state), value

        return jax.lax.scan(body, (x, state), None, length=_LBFGS_CHUNK)

    def minimise(x0, max_iter, progress, desc, rtol=0.0, on_step=None):  # rtol: SciPy methods only
        x, state = x0, opt.init(x0)
        losses: list[np.ndarray] = []
        bar = tqdm(total=max_iter, disable=not progress, desc=desc, unit="it", leave=False)
        done = 0
        best_x, best = x0, np.inf
        try:
            while done < max_iter:
                (x_new, state), values = run(x, state)
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
                current = float(evaluate(x))
                if current < best:
                    best_x, best = x, current
        finally:
            bar.close()
        train = np.concatenate(losses) if losses else np.zeros(0)
        hist = {"epoch": np.arange(1, len(train) + 1), "train_loss": train}
        return best_x, hist

    return minimise


_CACHE: dict[Any, Any] = {}


def _compiled(key: Any, build: Callable[[], Any]) -> Any:
    """`build()` once per `key` (a compiled function kept for later fits of the same model
    structure); unhashable keys build anew."""
    try:
        if key not in _CACHE:
            if len(_CACHE) >= 64:  # a long sweep over many structures: start afresh
                _CACHE.clear()
            _CACHE[key] = build()
        return _CACHE[key]
    except TypeError:
        return build()


class _FlatLoss:
    r"""`loss(x, (X, h), T)`: the training loss of the model with flat parameters `x` and step
    size `h` (traced). Equal (same hash) for the same loss, model structure and parameter
    layout, whatever the step size, so that `jax.jit` caches and the quasi-Newton minimisers
    compile once per structure, not once per fit."""

    def __init__(self, loss_fn, static, params):
        self.loss_fn = loss_fn
        self.has_h = hasattr(static, "h")  # every learned map has one; a bare module may not
        self.static = eqx.tree_at(lambda m: m.h, static, 0.0, is_leaf=lambda v: v is None) if self.has_h else static
        self.layout = (jax.tree_util.tree_structure(params),
                       tuple((a.shape, str(a.dtype)) for a in jax.tree_util.tree_leaves(params)))
        self.unravel = ravel_pytree(params)[1]

    def _key(self):
        return (self.loss_fn, self.static, self.layout)

    def __hash__(self):
        return hash(self._key())

    def __eq__(self, other):
        return isinstance(other, _FlatLoss) and self._key() == other._key()

    def __call__(self, x, Xh, T):
        X, h = Xh
        model = eqx.combine(self.unravel(x), self.static)
        if self.has_h:
            model = eqx.tree_at(lambda m: m.h, model, h)
        return self.loss_fn(model, X, T)


def _flat_loss(loss_fn, static, params) -> _FlatLoss:
    return _compiled(("loss", _FlatLoss(loss_fn, static, params)), lambda: _FlatLoss(loss_fn, static, params))


def run_quasi_newton(stage: QuasiNewton, model, train, val, loss_fn, seed: int, progress: bool, report):
    """Every start minimised, the best kept if it beats `model` (see `QuasiNewton`)."""
    (X, T), (Xv, Tv) = train, val
    has_val = Xv.shape[0] > 0
    params, static = eqx.partition(model, eqx.is_inexact_array)
    flat0, unravel = ravel_pytree(params)
    # The step size travels with the data, (X, h): one compiled loss serves a sweep over h.
    h = jnp.asarray(0.0 if getattr(model, "h", None) is None else model.h, dtype=jnp.float64)
    Xh, Xvh = (X, h), (Xv, h)
    loss = _flat_loss(loss_fn, static, params)
    evaluate = _compiled(("evaluate", loss), lambda: jax.jit(loss))
    minimise = minimiser(stage.method, loss, Xh, T)  # compiled once, reused by every start
    warm = model.warm_start() if stage.warm_start else None
    if warm is not None:
        linear = warm[0]
        lin_params, lin_static = eqx.partition(linear, eqx.is_inexact_array)
        lin_unravel = ravel_pytree(lin_params)[1]  # same flat layout, other static activation
        minimise_linear = minimiser(stage.method, _flat_loss(loss_fn, lin_static, lin_params), Xh, T)

    def losses(x):
        train_loss = float(evaluate(x, Xh, T))
        val_loss = float(evaluate(x, Xvh, Tv)) if has_val else float("nan")
        crit = val_loss if has_val else train_loss
        return (crit if np.isfinite(crit) else np.inf), train_loss, val_loss

    name = f"{type(model).__name__} {stage.method}"
    total = stage.restarts * stage.iterations
    start = time.perf_counter()
    results = []
    base = jax.random.PRNGKey(seed)
    for r in range(stage.restarts):
        if r == 0:
            x0 = flat0
        else:
            x0 = ravel_pytree(eqx.filter(model.reinitialised(jax.random.fold_in(base, r)), eqx.is_inexact_array))[0]
        desc = f"{name} start {r + 1}/{stage.restarts}" if stage.restarts > 1 else name
        before = r * stage.iterations
        on_step = None if report is None else (
            lambda done, value, before=before: report(before + done, total, value, float("nan")))
        if warm is not None:
            first = max(1, stage.iterations // 2)
            x_lin, h1 = minimise_linear(x0, first, progress, f"{desc} (warm start)", 0.0, on_step)
            # mapped onto this start's own weights (a restart's random vectors and activation)
            to_model = eqx.combine(unravel(x0), static).warm_start()[1]
            mapped = to_model(eqx.combine(lin_unravel(x_lin), lin_static), X)
            x_init = ravel_pytree(eqx.filter(mapped, eqx.is_inexact_array))[0]
            x, h2 = minimise(x_init, max(1, stage.iterations - first), progress, f"{desc} (from the warm start)",
                             stage.rtol, None if on_step is None else
                             (lambda done, value, f=first, g=on_step: g(f + done, value)))
            shift = h1["epoch"][-1] if len(h1["epoch"]) else 0
            hist = {"epoch": np.concatenate([h1["epoch"], h2["epoch"] + shift]),
                    "train_loss": np.concatenate([h1["train_loss"], h2["train_loss"]])}
        else:
            x, hist = minimise(x0, stage.iterations, progress, desc, stage.rtol, on_step)
        results.append((*losses(x), r, x, hist))
        if report is not None:
            report((r + 1) * stage.iterations, total, results[-1][1], results[-1][2])
    wall = time.perf_counter() - start
    crit, train_loss, val_loss, best_r, x, hist = min(results, key=lambda t: (t[0], t[3]))
    crit0, train0, val0 = losses(flat0)
    kept = bool(np.isfinite(crit) and crit < crit0)
    if not kept and not np.isfinite(crit0):
        raise FloatingPointError(f"{name}: every start diverged (non-finite loss) and the initial weights are not finite")
    history = {"epoch": np.asarray(hist["epoch"]), "train_loss": np.asarray(hist["train_loss"]),
               "val_loss": np.full(len(hist["train_loss"]), np.nan)}
    rec = StageRecord(
        optimiser="QuasiNewton", settings=dataclasses.asdict(stage), iterations=len(hist["train_loss"]),
        train_loss=train_loss if kept else train0, val_loss=val_loss if kept else val0, kept=kept,
        wall_time_s=wall,
        details={"best_start": best_r, "start_train_losses": [t[1] for t in sorted(results, key=lambda t: t[3])],
                 "train_loss_before": train0, "val_loss_before": val0},
    )
    fitted = eqx.combine(unravel(jnp.asarray(x)), static) if kept else model
    return fitted, rec, history
