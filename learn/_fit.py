r"""Training as a free function: `learn.fit(model, data, optimiser=...)` returns a new model and
its `TrainingRecord`. The optimisers are plain settings (`Adam`, `QuasiNewton`); a sequence of
them runs as stages, each starting from the weights the previous one kept."""

from __future__ import annotations

import dataclasses
import functools
import os
import time
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree
from numpy.typing import ArrayLike

from integrators import Trajectories
from liepoisson import vmap_samples
from liepoisson._progress import show_progress
from liepoisson._validation import positive_float, positive_int

from ._base import AbstractLearnedMap, check_learned_map
from ._data import PairData, prepare
from ._quasi_newton import check_method, minimiser
from ._record import StageRecord, TrainingRecord
from ._training import train_adam

_Map = TypeVar("_Map", bound=AbstractLearnedMap)


@dataclasses.dataclass(frozen=True)
class Adam:
    r"""Adam (optax) on the training loss, compiled in chunks of epochs; keeps the weights of
    the lowest validation loss (training loss without a validation set).

    `epochs`; `learning_rate`, and `final_learning_rate` for an exponential decay from one to
    the other over all steps (constant if `None`); `batch_size` `None` for full batch, else
    seeded shuffled mini-batches (remainder dropped per epoch); `log_every`: history resolution
    in epochs (default `epochs // 1000`).
    """

    epochs: int = 100_000
    learning_rate: float = 1e-3
    final_learning_rate: float | None = None
    batch_size: int | None = None
    log_every: int | None = None

    def __post_init__(self):
        positive_int(self.epochs, "Adam.epochs")
        positive_float(self.learning_rate, "Adam.learning_rate")
        if self.final_learning_rate is not None:
            positive_float(self.final_learning_rate, "Adam.final_learning_rate")
        if self.batch_size is not None:
            positive_int(self.batch_size, "Adam.batch_size")
        if self.log_every is not None:
            positive_int(self.log_every, "Adam.log_every")


@dataclasses.dataclass(frozen=True)
class QuasiNewton:
    r"""Full-batch quasi-Newton minimisation with JAX gradients, for every learned map.

    `iterations` per start; `method`: `"lbfgsb"` (SciPy L-BFGS-B, 50 correction pairs: thousands
    of parameters, an MLP), `"bfgs"` (SciPy BFGS, dense: a few dozen parameters, the paper's
    choice for G-LPNets) or `"lbfgs"` (optax, compiled in chunks); `restarts` starts in total,
    the first from the current weights, the others from fresh random weights
    (`model.reinitialised`, keys from the fit's `seed`); `warm_start` (G-LPNet only): each
    start first fits the network with the identity activation (flows of quadratics, a smooth
    problem) for half the iterations, maps it onto the linear regime of $\sigma$
    (`linear_to_activation`) and finishes with $\sigma$ (on E6 from random sigmoid starts
    BFGS stalls at MSE ~1e-6; the warm start reaches the paper's < 5e-10).

    The best start by validation loss (training loss without a validation set) is kept, and
    only if it beats the weights the stage started from.
    """

    iterations: int = 3500
    method: str = "lbfgsb"
    restarts: int = 1
    warm_start: bool = False

    def __post_init__(self):
        positive_int(self.iterations, "QuasiNewton.iterations")
        check_method(self.method)
        positive_int(self.restarts, "QuasiNewton.restarts")


Optimiser = Adam | QuasiNewton


@dataclasses.dataclass(frozen=True)
class Checkpoint:
    """Write Adam's state to `path` (HDF5) every `every` epochs and at the end; with `resume`,
    continue from the file if it exists (epoch, optimiser state, best weights: bit-identical to
    an uninterrupted run). Checks that the file was written by the same model, data split and
    Adam settings."""

    path: str | os.PathLike
    every: int = 10_000
    resume: bool = False

    def __post_init__(self):
        if not isinstance(self.path, (str, os.PathLike)):
            raise TypeError(f"Checkpoint.path must be a file path; got {type(self.path).__name__}")
        positive_int(self.every, "Checkpoint.every")


@dataclasses.dataclass(frozen=True)
class Progress:
    """What a `learn.fit` callback receives: the stage (index and optimiser name), how far it
    is (`iteration` of `total` epochs or iterations; for `QuasiNewton` reported once per
    start) and the latest losses (`val_loss` NaN where not measured)."""

    stage: int
    optimiser: str
    iteration: int
    total: int
    train_loss: float
    val_loss: float


Callback = Callable[[Progress], None]


def default_optimiser(model: AbstractLearnedMap) -> tuple[Optimiser, ...]:
    """What `learn.fit` runs when given no optimiser: `model.default_optimiser()` (BFGS with
    the identity warm start, 3500 iterations, 4 starts, for a G-LPNet, as the paper; 100,000
    epochs of Adam, learning rate 1e-3, for the MLP-based maps)."""
    return check_learned_map(model).default_optimiser()




def state_mse(model: AbstractLearnedMap, y0: jax.Array, y1: jax.Array) -> jax.Array:
    """Mean squared error of one learned step over pairs `(N, dim)`: the state loss of every
    learned map (paper eqs. Loss_function, Loss_function_G_LPNets), through
    `training_prediction` (the explicit residual form of an implicit step)."""
    return jnp.mean((vmap_samples(model.training_prediction)(y0, y1) - y1) ** 2)


def fit(
    model: _Map,
    data: Trajectories | tuple[ArrayLike, ArrayLike],
    *,
    optimiser: Optimiser | Sequence[Optimiser] | None = None,
    epochs: int | None = None,
    h: float | None = None,
    validation_fraction: float = 0.2,
    seed: int = 0,
    loss: str = "state",
    normalise: bool = False,
    checkpoint: Checkpoint | None = None,
    progress: bool | None = None,
    callback: Callback | None = None,
) -> tuple[_Map, TrainingRecord]:
    r"""Train a learned map on data pairs; returns `(fitted model, TrainingRecord)`.

    **Arguments:**

    - `model`: a learned map (`LPNet`, `Reversible`, `GLPNet`, `MLPBaseline`; not modified).
    - `data`: an `integrators.Trajectories` (consecutive states are the pairs, `h` its step),
      or `(y0, y1)` arrays `(N, dim)` with `h=`.
    - `optimiser`: an `Adam` or `QuasiNewton`, or a sequence of them run one after the other
      (e.g. `(Adam(100_000), QuasiNewton(30_000))`, the paper's Adam refined by L-BFGS-B);
      default `default_optimiser(model)`. `epochs=N` is short for `optimiser=Adam(N)`.
    - `validation_fraction` of the pairs held out (random, seeded by `seed`, which also seeds
      mini-batches and restarts).
    - `loss`: `"state"` (default, the paper's: MSE between the step of $y_0$ and $y_1$, for an
      LPNet through the exact flow, for a `Reversible` through its explicit residual form
      `training_prediction`) or another of `model.losses`: an LPNet's `"alpha"` (MSE between
      $\alpha(y_0)$ and the pairs' parameters `parametrisation.params_from_pair(y0, y1, h)`).
    - `normalise` (MLP-based maps): set the fixed input/output scalings from the training data
      first (inputs: mean/std of $y_0$; outputs: of the pairs' parameters for an LPNet, of
      $y_1 - y_0$ for the baseline). Default `False`: a plain MLP as in the paper. On E1
      normalising reaches a lower loss (1.6e-11 vs 3-4e-11 after 1e5 epochs) but the
      10,000-step rollout drifts more in energy (2e-3..0.6 vs 4e-4..7e-4).
    - `checkpoint`: a `Checkpoint` for the Adam stage.
    - `progress`: tqdm bars with the losses (`None`: only when stderr is a terminal); `callback(learn.Progress)`: called as training
      goes (after every 1000 Adam epochs, after every quasi-Newton start), e.g. to log.
    """
    model = check_learned_map(model)
    if epochs is not None:
        if optimiser is not None:
            raise ValueError("give either epochs (short for optimiser=learn.Adam(epochs)) or optimiser, not both")
        optimiser = Adam(positive_int(epochs, "epochs"))
    stages = model.default_optimiser() if optimiser is None else optimiser
    if isinstance(stages, (Adam, QuasiNewton)):
        stages = (stages,)
    stages = tuple(stages)
    if not stages or not all(isinstance(s, (Adam, QuasiNewton)) for s in stages):
        raise TypeError(f"optimiser must be a learn.Adam or learn.QuasiNewton, or a sequence of them; got {optimiser!r}")
    loss_fn = model.loss_function(loss)  # ValueError for a loss this map cannot train on
    if callback is not None and not callable(callback):
        raise TypeError(f"callback must be callable as callback(learn.Progress); got {callback!r}")
    if checkpoint is not None and not isinstance(checkpoint, Checkpoint):
        raise TypeError(f"checkpoint must be a learn.Checkpoint; got {type(checkpoint).__name__}")
    if checkpoint is not None and sum(isinstance(s, Adam) for s in stages) != 1:
        raise ValueError("checkpoint needs exactly one Adam stage in optimiser")
    if any(isinstance(s, QuasiNewton) and s.warm_start for s in stages) and not model.has_warm_start:
        raise ValueError(f"QuasiNewton(warm_start=True): a {type(model).__name__} has no warm start (the G-LPNet's "
                         "identity warm start); use warm_start=False")
    pairs = prepare(data, model.system, h, validation_fraction, seed, conserves_casimirs=model.conserves_casimirs)
    if model.h is not None and abs(model.h - pairs.h) > 1e-12 * pairs.h:
        raise ValueError(
            f"the model's step h={model.h} differs from the data's h={pairs.h}; fit a model built "
            "with h=None (or the data's h), or data sampled at the model's step"
        )
    model = eqx.tree_at(lambda m: m.h, model, pairs.h, is_leaf=lambda x: x is None)
    progress = show_progress(progress)
    model, train, val = _objective(model, pairs, loss, normalise)
    X, T = (jnp.asarray(a) for a in train)
    Xv, Tv = (jnp.asarray(a) for a in val)
    settings = {
        "validation_fraction": float(validation_fraction), "seed": int(seed), "loss": loss,
        "normalise": bool(normalise), "h": pairs.h, "n_train": int(X.shape[0]), "n_val": int(Xv.shape[0]),
    }
    history = {"epoch": np.zeros(0, int), "train_loss": np.zeros(0), "val_loss": np.zeros(0)}
    records = []
    for index, stage in enumerate(stages):
        offset = sum(r.iterations for r in records)  # epochs and iterations run so far
        report = None if callback is None else functools.partial(_report, callback, index, type(stage).__name__)
        if isinstance(stage, Adam):
            model, rec, hist = _run_adam(stage, model, (X, T), (Xv, Tv), loss_fn, settings, checkpoint, progress,
                                         report)
        else:
            model, rec, hist = _run_quasi_newton(stage, model, (X, T), (Xv, Tv), loss_fn, seed, progress, report)
        hist = dict(hist, epoch=hist["epoch"] + offset)
        history = {k: np.concatenate([history[k], hist[k]]) for k in history}
        records.append(rec)
    record = TrainingRecord(
        model=type(model).__name__, h=pairs.h, seed=int(seed), validation_fraction=float(validation_fraction),
        loss=loss, normalise=bool(normalise), n_train=settings["n_train"], n_val=settings["n_val"],
        stages=tuple(records), history=history, train_loss=records[-1].train_loss,
        val_loss=records[-1].val_loss, wall_time_s=float(sum(r.wall_time_s for r in records)),
    )
    return model, record


def _report(callback: Callback, stage: int, name: str, done: int, total: int, train: float, val: float) -> None:
    callback(Progress(stage, name, done, total, train, val))


def _objective(model: AbstractLearnedMap, pairs: PairData, loss: str, normalise: bool):
    """`(model, (inputs, targets), (inputs_val, targets_val))` for the loss named `loss`; the
    model's scalings set from the training pairs when `normalise`."""
    targets = model.loss_targets(loss, pairs.y0, pairs.y1, pairs.h)
    targets_val = (model.loss_targets(loss, pairs.y0_val, pairs.y1_val, pairs.h) if pairs.has_validation
                   else np.zeros((0, targets.shape[-1])))
    if normalise:
        model = model.normalised(pairs.y0, pairs.y1, pairs.h, None if loss == "state" else targets)
    return model, (pairs.y0, targets), (pairs.y0_val, targets_val)


def _run_adam(stage: Adam, model, train, val, loss_fn, settings, checkpoint, progress, report):
    log_every = stage.log_every if stage.log_every is not None else max(1, stage.epochs // 1000)
    best, info = train_adam(
        model, train, val, loss_fn,
        epochs=stage.epochs, learning_rate=stage.learning_rate, final_learning_rate=stage.final_learning_rate,
        batch_size=stage.batch_size, seed=settings["seed"], progress=progress, log_every=log_every,
        checkpoint=None if checkpoint is None else os.fspath(checkpoint.path),
        checkpoint_every=10_000 if checkpoint is None else checkpoint.every,
        resume=checkpoint is not None and checkpoint.resume,
        settings={**settings, **dataclasses.asdict(stage), "log_every": log_every}, desc=type(model).__name__,
        on_chunk=None if report is None else lambda done, lt, lv: report(done, stage.epochs, lt, lv),
    )
    rec = StageRecord(
        optimiser="Adam", settings=dataclasses.asdict(stage), iterations=info["epochs"],
        train_loss=info["train_loss"], val_loss=info["val_loss"], kept=True, wall_time_s=info["wall_time_s"],
        details={"best_epoch": info["best_epoch"], "stopped": info["stopped"]},
    )
    return best, rec, info["history"]


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


def _run_quasi_newton(stage: QuasiNewton, model, train, val, loss_fn, seed: int, progress: bool, report):
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
    start = time.perf_counter()
    results = []
    base = jax.random.PRNGKey(seed)
    for r in range(stage.restarts):
        if r == 0:
            x0 = flat0
        else:
            x0 = ravel_pytree(eqx.filter(model.reinitialised(jax.random.fold_in(base, r)), eqx.is_inexact_array))[0]
        desc = f"{name} start {r + 1}/{stage.restarts}" if stage.restarts > 1 else name
        if warm is not None:
            first = max(1, stage.iterations // 2)
            x_lin, h1 = minimise_linear(x0, first, progress, f"{desc} (identity)")
            # mapped onto this start's own weights (a restart's random vectors and activation)
            to_model = eqx.combine(unravel(x0), static).warm_start()[1]
            mapped = to_model(eqx.combine(lin_unravel(x_lin), lin_static), X)
            x_init = ravel_pytree(eqx.filter(mapped, eqx.is_inexact_array))[0]
            x, h2 = minimise(x_init, max(1, stage.iterations - first), progress, f"{desc} ({model.activation})")
            shift = h1["epoch"][-1] if len(h1["epoch"]) else 0
            hist = {"epoch": np.concatenate([h1["epoch"], h2["epoch"] + shift]),
                    "train_loss": np.concatenate([h1["train_loss"], h2["train_loss"]])}
        else:
            x, hist = minimise(x0, stage.iterations, progress, desc)
        results.append((*losses(x), r, x, hist))
        if report is not None:
            report((r + 1) * stage.iterations, stage.restarts * stage.iterations, results[-1][1], results[-1][2])
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
