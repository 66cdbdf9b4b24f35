r"""The `LevenbergMarquardt` stage of `learn.fit`: Levenberg-Marquardt on the residuals $r(x)$
of a least-squares loss (`loss_fn.residuals(model, inputs, targets)`, whose mean square is the
loss), over the flat trainable leaves $x$.

Each step evaluates $r$ and its Jacobian $J$ once (one compiled call: `jax.jacfwd`, or the
loss's own `jacobian` where it knows a block structure, e.g. fitted starts), then solves the
damped normal equations $(J^TJ + \lambda D)\delta = -J^Tr$, $D = \mathrm{diag}(J^TJ)$ (the
largest seen: Marquardt's scaling, Moré 1978), by a lineax Cholesky, trying larger $\lambda$ until
the step lowers $\|r\|^2$; $\lambda$ is updated by Nielsen's rule. The loop runs on the host
between two small compiled functions, so a map is compiled twice (residuals, Jacobian), not
into one solver program: optimistix's `LevenbergMarquardt` on the same losses spends longer
compiling a G-LPNet fit than running it (BENCHMARKS.md, "Learning from observations").
"""

from __future__ import annotations

import dataclasses
import os
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
from jax.flatten_util import ravel_pytree
from tqdm.auto import tqdm

from .. import _files as _checkpoint
from .._training._observed import Fitted
from ._optimisers import LevenbergMarquardt
from ._quasi_newton import _compiled
from ._record import StageRecord
from ._adam import read_resumable

#: Trial steps per iteration at most (each multiplies the damping by a growing factor).
MAX_TRIALS = 30

#: The largest Jacobian (residuals x unknowns) a step may hold: 1.6 GB of float64.
MAX_JACOBIAN = 200_000_000

#: The most forward passes (Jacobian columns computed at once) a step may take: `jax.jacfwd`
#: holds every pass's intermediates together.
MAX_PASSES = 2000

#: The damping lambda is kept in this range (relative to the Marquardt scaling D).
LAMBDA_RANGE = (1e-16, 1e16)

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
                            report, checkpoint=None, settings=None):
    """Minimise the loss's residuals from `model` (after the warm start it offers, if asked);
    the result is kept if it lowers the selection loss (validation, or training without a
    validation set). With a `learn.Checkpoint`, the state (weights, damping, Marquardt
    scaling, history, phase) is written every `checkpoint.every` steps and at the end, and a
    run with `resume` continues from the file, bit-identical to an uninterrupted one."""
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

    settings = {**(settings or {}), **dataclasses.asdict(stage)}
    saved = _Saved(checkpoint, model, settings) if checkpoint is not None else None
    resumed = saved.read() if saved is not None and checkpoint.resume and os.path.exists(checkpoint.path) else None
    iterations = stage.iterations
    history: list[float] = []
    current = model

    def on_step(offset):
        if report is None:
            return None
        return lambda done, value: report(offset + done, stage.iterations, value, float("nan"))

    warm = model.warm_start() if stage.warm_start else None
    if warm is not None:
        simpler, to_model = warm
        first = max(1, iterations // 2)
        if resumed is None or resumed["phase"] == 0:
            simpler, values = _minimise(stage.rtol, simpler, X, T, loss_fn, first, progress, f"{name} (warm start)",
                                        saved, 0, resumed, on_step=on_step(0))
            resumed = None
            history += values
            current = to_model(simpler, X)
        else:
            history += resumed["warm_history"]
        iterations = max(1, iterations - first)
    fitted, values = _minimise(stage.rtol, current, X, T, loss_fn, iterations, progress, name, saved, 1, resumed,
                               history, on_step(len(history)))
    history += values
    crit, train_loss, val_loss = losses(fitted)
    crit0, train0, val0 = losses(model)
    kept = bool(np.isfinite(crit) and crit < crit0)
    if not kept and not np.isfinite(crit0):
        raise FloatingPointError(f"{name}: the loss is not finite at the start nor at the end; check the weights and "
                                 "the data")
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


class _Saved:
    r"""A Levenberg-Marquardt checkpoint in `learn.fit`'s checkpoint format: `weights` the
    current weights, `best` the same after the warm start (every accepted step lowers the
    training loss) and the model's starting weights during it, `optimizer` the damping
    $\lambda$, its growth factor $\nu$ and the Marquardt scaling $D$, `history` the losses;
    `phase` 0 while fitting the warm start's simpler map, 1 after."""

    def __init__(self, checkpoint, model, settings):
        self.path = os.fspath(checkpoint.path)
        self.every = checkpoint.every
        self.model = model
        self.settings = settings
        self.attrs = model.file_attributes()

    def read(self) -> dict:
        attrs, groups = read_resumable(self.path, self.model, self.settings)
        lam, nu, D = groups["optimizer"]
        losses = list(np.asarray(groups["history"]["train_loss"]))
        phase = int(attrs.get("phase", 1))
        done = int(attrs["epoch"])
        return {"phase": phase, "weights": groups["weights"], "lam": float(lam), "nu": float(nu), "D": np.asarray(D),
                "values": losses[len(losses) - done:] if phase == 1 else losses,
                "warm_history": losses[: len(losses) - done] if phase == 1 else [],
                "elapsed": float(attrs["elapsed_s"])}

    def write(self, phase, model, lam, nu, D, values, earlier, elapsed):
        leaves = _checkpoint.array_leaves(model)
        # `best` is what loading the file as a model gives: during the warm start (the simpler
        # map's weights in `weights`) the model's own starting weights
        best = leaves if phase == 1 else _checkpoint.array_leaves(self.model)
        losses = np.asarray([*earlier, *values])
        _checkpoint.write(self.path, {**self.attrs, "epoch": len(values), "best_epoch": len(losses),
                                      "best_loss": float(losses[-1]) if losses.size else float("nan"),
                                      "elapsed_s": float(elapsed), "fit_settings": self.settings, "phase": phase},
                          {"weights": leaves, "best": best,
                           "optimizer": [np.asarray(lam), np.asarray(nu), np.asarray(D)],
                           "history": {"epoch": np.arange(1, losses.size + 1), "train_loss": losses,
                                       "val_loss": np.full(losses.size, np.nan)}})


def _minimise(rtol, model, X, T, loss_fn, iterations, progress, desc, saved=None, phase=1, resumed=None,
              earlier=(), on_step=None):
    """`(model, losses)`: up to `iterations` Levenberg-Marquardt steps from `model`, stopping
    once the loss has fallen by less than `rtol` of its value over the last `WINDOW` steps,
    or no damping finds a lower loss; the loss after each step. With `saved`, the state is
    written every `saved.every` steps and at the end; `resumed` continues from a read state;
    `on_step(steps done, loss)` after every step."""
    start = time.perf_counter()
    if resumed is not None:
        model = _checkpoint.replace_array_leaves(model, resumed["weights"], "weights")
    params, static = eqx.partition(model, eqx.is_inexact_array)
    fn = _compiled(("residuals", _Residuals(loss_fn, static, params)), lambda: _Residuals(loss_fn, static, params))
    x = ravel_pytree(params)[0]
    check_size(model, loss_fn, X, T)
    r, J = fn.jacobian(x, X, T)
    cost = float(r @ r)  # always from the Jacobian's call: a resumed run starts from the same number
    if not np.isfinite(cost):
        raise FloatingPointError(f"{desc}: the loss at the start is not finite; check the weights and the data")
    scale = float(loss_fn.count(model, X, T)) if hasattr(loss_fn, "count") else float(r.size)  # sum r^2 -> loss
    D, lam, nu = None, 1e-3, 2.0
    values: list[float] = []
    elapsed0 = 0.0
    if resumed is not None:
        D, lam, nu = jnp.asarray(resumed["D"]), resumed["lam"], resumed["nu"]
        values, elapsed0 = list(resumed["values"]), resumed["elapsed"]
    last_saved = len(values)

    def save():
        if saved is not None:
            saved.write(phase, fn.model(x), lam, nu, D, values, earlier, elapsed0 + time.perf_counter() - start)

    bar = tqdm(total=iterations, initial=len(values), disable=not progress, desc=desc, unit="it", leave=False)
    try:
        while len(values) < iterations:
            if not np.isfinite(cost) or _converged(values, rtol):
                break
            A, g = _normal_equations(r, J)
            if not bool(jnp.all(jnp.isfinite(A)) and jnp.all(jnp.isfinite(g))):
                raise FloatingPointError(f"{desc}: the Jacobian after step {len(values)} is not finite (the map's "
                                         "derivatives overflow at these weights); try fewer iterations or another start")
            diag = jnp.diag(A)
            # a weight the residuals do not see gets a scale from the others (MINPACK's rule)
            diag = jnp.maximum(diag, jnp.finfo(A.dtype).eps * jnp.maximum(jnp.max(diag), jnp.finfo(A.dtype).tiny))
            D = diag if D is None else jnp.maximum(D, diag)
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
                        lam = max(lam * max(1 / 3, 1 - (2 * rho - 1) ** 3), LAMBDA_RANGE[0])
                        nu = 2.0
                        accepted = True
                        break
                lam = min(lam * nu, LAMBDA_RANGE[1])
                nu *= 2
            if not accepted:  # no damping lowers the loss: a minimum to round-off
                break
            x = x_new
            r, J = fn.jacobian(x, X, T)
            cost = float(r @ r)
            values.append(cost / scale)
            bar.update(1)
            bar.set_postfix(loss=f"{values[-1]:.3g}")
            if on_step is not None:
                on_step(len(values), values[-1])
            if saved is not None and len(values) - last_saved >= saved.every:
                save()
                last_saved = len(values)
    finally:
        bar.close()
    if saved is not None and D is not None and len(values) != last_saved:
        save()
    return fn.model(x), values


def check_size(model, loss_fn, X, T) -> None:
    """`ValueError` if a Levenberg-Marquardt step on `model` would hold a Jacobian too large
    for memory (`MAX_JACOBIAN` entries or `MAX_PASSES` forward passes)."""
    params, static = eqx.partition(model, eqx.is_inexact_array)
    fn = _Residuals(loss_fn, static, params)
    n_unknowns = ravel_pytree(params)[0].size
    n_residuals = jax.eval_shape(fn.residuals, ravel_pytree(params)[0], X, T).shape[0]
    passes = n_unknowns - (params.starts.size - params.starts.shape[-1] if fn.blocks else 0)
    if n_residuals * n_unknowns > MAX_JACOBIAN or passes > MAX_PASSES:
        raise ValueError(
            f"learn.LevenbergMarquardt: the Jacobian would be {n_residuals} residuals x {n_unknowns} unknowns, "
            f"{passes} forward passes (at most {MAX_PASSES}, and {8 * MAX_JACOBIAN / 1e9:.1f} GB); it suits maps "
            "of a few hundred weights (a G-LPNet); for an MLP use learn.QuasiNewton or learn.Adam"
        )


def _converged(values, rtol) -> bool:
    """Whether the loss fell by less than `rtol` of its value over the last `WINDOW` steps."""
    if rtol <= 0 or len(values) <= WINDOW:
        return False
    before = values[-1 - WINDOW]
    return before - values[-1] <= rtol * abs(before)


