r"""The `LevenbergMarquardt` stage of `learn.fit`: Levenberg-Marquardt on the residuals $r(x)$
of a least-squares loss (`loss_fn.residuals(model, inputs, targets)`, whose mean square is the
loss), over the flat trainable leaves $x$.

Each step evaluates $r$ and its Jacobian $J$ once (one compiled call: `jax.jacfwd`, or the
loss's own `jacobian` where it knows a block structure, e.g. fitted starts), then solves the
damped normal equations $(J^TJ + \lambda D)\delta = -J^Tr$, $D = \mathrm{diag}(J^TJ)$ (the
largest seen: Marquardt's scaling, Moré 1978), by a lineax Cholesky, trying larger $\lambda$ until
the step lowers $\|r\|^2$; $\lambda$ is updated by Nielsen's rule. The loop runs on the host
between two small compiled functions, so a map is compiled twice (residuals, Jacobian), not
into one solver program: optimistix's `LevenbergMarquardt` on the same losses spends 29 s
compiling a G-LPNet fit that runs in 7 s (BENCHMARKS.md, "Second-order optimisers").
"""

from __future__ import annotations

import dataclasses
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
from jax.flatten_util import ravel_pytree
from tqdm.auto import tqdm

from ._observed import Fitted
from ._optimisers import LevenbergMarquardt
from ._quasi_newton import _compiled
from ._record import StageRecord

#: Trial steps per iteration at most (each multiplies the damping by a growing factor).
MAX_TRIALS = 30

#: `LevenbergMarquardt(rtol=...)` compares the loss with its value this many steps earlier.
WINDOW = 3


class _Residuals:
    r"""The residuals $r(x)$ `(n,)` and Jacobian $J(x)$ `(n, p)` of `loss_fn` for the model whose
    flat trainable leaves are $x$, compiled. Equal (same hash) for the same loss, structure and
    layout: compiled once per structure, not once per fit."""

    def __init__(self, loss_fn, static, params):
        self.loss_fn = loss_fn
        self.static = static
        self.layout = (jax.tree_util.tree_structure(params),
                       tuple((a.shape, str(a.dtype)) for a in jax.tree_util.tree_leaves(params)))
        self.unravel = ravel_pytree(params)[1]
        self.blocks = isinstance(params, Fitted) and params.starts is not None and hasattr(loss_fn, "jacobian")
        self.residuals = jax.jit(self._residuals)
        self.jacobian = jax.jit(self._jacobian)

    def _key(self):
        return (self.loss_fn, self.static, self.layout)

    def __hash__(self):
        return hash(self._key())

    def __eq__(self, other):
        return isinstance(other, _Residuals) and self._key() == other._key()

    def model(self, x):
        return eqx.combine(self.unravel(x), self.static)

    def _residuals(self, x, X, T):
        return self.loss_fn.residuals(self.model(x), X, T).reshape(-1)

    def _jacobian(self, x, X, T):
        if self.blocks:
            return self.loss_fn.jacobian(self.model(x), X, T)
        return self._residuals(x, X, T), jax.jacfwd(self._residuals)(x, X, T)


@jax.jit
def _normal_equations(r, J):
    return J.T @ J, J.T @ r


@jax.jit
def _damped_step(A, g, D, lam):
    r"""$\delta$ solving $(A + \lambda\,\mathrm{diag}(D))\delta = -g$ (lineax Cholesky; NaN where
    the damped matrix is not positive definite to round-off)."""
    operator = lx.MatrixLinearOperator(A + lam * jnp.diag(D), lx.positive_semidefinite_tag)
    return lx.linear_solve(operator, -g, lx.Cholesky(), throw=False).value


def run_levenberg_marquardt(stage: LevenbergMarquardt, model, train, val, loss_fn, seed: int, progress: bool,
                            report):
    """Minimise the loss's residuals from `model` (after the warm start it offers, if asked);
    the result is kept if it lowers the selection loss (validation, or training without a
    validation set)."""
    del seed  # one deterministic start
    if not hasattr(loss_fn, "residuals"):
        raise ValueError(f"learn.LevenbergMarquardt needs a least-squares loss (one with residuals); {loss_fn!r} has "
                         "none: use learn.QuasiNewton")
    (X, T), (Xv, Tv) = train, val
    has_val = Xv.shape[0] > 0
    name = f"{type(getattr(model, 'model', model)).__name__} Levenberg-Marquardt"
    start = time.perf_counter()
    evaluate = _compiled(("loss", loss_fn), lambda: eqx.filter_jit(loss_fn))

    def losses(m):
        train_loss = float(evaluate(m, X, T))
        val_loss = float(evaluate(m, Xv, Tv)) if has_val else float("nan")
        crit = val_loss if has_val else train_loss
        return (crit if np.isfinite(crit) else np.inf), train_loss, val_loss

    iterations = stage.iterations
    history: list[float] = []
    current = model
    warm = model.warm_start() if stage.warm_start else None
    if warm is not None:
        simpler, to_model = warm
        first = max(1, iterations // 2)
        simpler, values = _minimise(stage.rtol, simpler, X, T, loss_fn, first, progress, f"{name} (warm start)")
        history += values
        current = to_model(simpler, X)
        iterations = max(1, iterations - first)
    fitted, values = _minimise(stage.rtol, current, X, T, loss_fn, iterations, progress, name)
    history += values
    crit, train_loss, val_loss = losses(fitted)
    crit0, train0, val0 = losses(model)
    kept = bool(np.isfinite(crit) and crit < crit0)
    if not kept and not np.isfinite(crit0):
        raise FloatingPointError(f"{name}: the fit diverged (non-finite loss) and the initial weights are not finite")
    if report is not None:
        report(len(history), stage.iterations, train_loss, val_loss)
    hist = {"epoch": np.arange(1, len(history) + 1), "train_loss": np.asarray(history),
            "val_loss": np.full(len(history), np.nan)}
    rec = StageRecord(
        optimiser="LevenbergMarquardt", settings=dataclasses.asdict(stage), iterations=len(history),
        train_loss=train_loss if kept else train0, val_loss=val_loss if kept else val0, kept=kept,
        wall_time_s=time.perf_counter() - start, details={"train_loss_before": train0, "val_loss_before": val0},
    )
    return (fitted if kept else model), rec, hist


def _minimise(rtol, model, X, T, loss_fn, iterations, progress, desc):
    """`(model, losses)`: up to `iterations` Levenberg-Marquardt steps from `model`, stopping
    once the loss has fallen by less than `rtol` of its value over the last `WINDOW`
    steps, or no damping finds a lower loss; the loss after each step."""
    params, static = eqx.partition(model, eqx.is_inexact_array)
    fn = _compiled(("residuals", _Residuals(loss_fn, static, params)), lambda: _Residuals(loss_fn, static, params))
    x = ravel_pytree(params)[0]
    r, J = fn.jacobian(x, X, T)
    cost = float(r @ r)
    scale = cost / float(evaluate_loss(fn, loss_fn, x, X, T)) if cost > 0 else 1.0  # sum r^2 -> the loss
    D = None
    lam, nu = None, 2.0
    values: list[float] = []
    bar = tqdm(total=iterations, disable=not progress, desc=desc, unit="it", leave=False)
    try:
        for _ in range(iterations):
            if not np.isfinite(cost):
                break
            A, g = _normal_equations(r, J)
            diag = jnp.maximum(jnp.diag(A), jnp.finfo(A.dtype).tiny)
            D = diag if D is None else jnp.maximum(D, diag)
            if lam is None:
                lam = 1e-3
            accepted = False
            for _ in range(MAX_TRIALS):
                delta = _damped_step(A, g, D, lam)
                if bool(jnp.all(jnp.isfinite(delta))):
                    x_new = x + delta
                    r_new = fn.residuals(x_new, X, T)
                    cost_new = float(r_new @ r_new)
                    predicted = -float(2 * g @ delta + delta @ (A @ delta))  # model decrease of sum r^2
                    if np.isfinite(cost_new) and cost_new < cost and predicted > 0:
                        rho = (cost - cost_new) / predicted
                        lam *= max(1 / 3, 1 - (2 * rho - 1) ** 3)
                        nu = 2.0
                        accepted = True
                        break
                lam *= nu
                nu *= 2
            if not accepted:  # no damping lowers the loss: a minimum to round-off
                break
            x, cost = x_new, cost_new
            r, J = fn.jacobian(x, X, T)
            values.append(cost / scale)
            bar.update(1)
            bar.set_postfix(loss=f"{values[-1]:.3g}")
            if rtol > 0 and len(values) > WINDOW:
                before = values[-1 - WINDOW]
                if before - values[-1] <= rtol * abs(before):
                    break
    finally:
        bar.close()
    return fn.model(x), values


def evaluate_loss(fn, loss_fn, x, X, T) -> float:
    return float(_compiled(("loss", loss_fn), lambda: eqx.filter_jit(loss_fn))(fn.model(x), X, T))
