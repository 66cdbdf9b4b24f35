"""Quasi-Newton minimisation of a full-batch loss with JAX gradients.

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
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optax
import scipy.optimize
from tqdm.auto import tqdm

from liepoisson import common_path_first

METHODS = ("bfgs", "lbfgsb", "lbfgs")

_SCIPY = {"bfgs": "BFGS", "lbfgsb": "L-BFGS-B"}
_LBFGS_CHUNK = 100


def check_method(method: Any) -> str:
    if method not in METHODS:
        raise ValueError(f"method must be one of {list(METHODS)}; got {method!r}")
    return method


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
    """`minimise(x0, max_iter, progress, desc) -> (x, {"epoch", "train_loss"})` for
    `loss(x, X, Y)`; `x` is the best iterate seen."""
    check_method(method)
    if method in _SCIPY:
        value_and_grad = _value_and_grad(loss)

        def minimise(x0, max_iter, progress, desc):
            return _scipy(_SCIPY[method], value_and_grad, x0, X, Y, max_iter, progress, desc)

        return minimise
    return _optax_lbfgs(loss, X, Y)


def _scipy(method, value_and_grad, x0, X, Y, max_iter, progress, desc):
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

    if method == "BFGS":
        options: dict[str, Any] = {"maxiter": max_iter, "gtol": 0.0}
    else:  # the default maxfun (15000) would stop long runs early
        options = {"maxiter": max_iter, "maxfun": 20 * max_iter, "maxcor": 50, "ftol": 0.0, "gtol": 0.0}
    try:
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

    def minimise(x0, max_iter, progress, desc):
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
