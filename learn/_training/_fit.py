r"""Training as a free function: `learn.fit(model, data, optimiser=...)` returns a new model and
its `TrainingRecord`. The optimisers (`learn.Adam`, `learn.QuasiNewton`) run as stages, each
starting from the weights the previous one kept; what differs between kinds of map, `fit` asks
the map."""

from __future__ import annotations

import dataclasses
import functools
import os
from collections.abc import Sequence
from typing import TypeVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from integrators import Observations, Trajectories
from liepoisson.internals import positive_int, show_progress

from .._models._base import AbstractLearnedMap, check_learned_map
from ._data import PairData, prepare
from .._solvers._levenberg_marquardt import check_size, run_levenberg_marquardt
from ._observed import TrajectoryLoss, observed_objective
from .._solvers._optimisers import (
    OPTIMISERS,
    Adam,
    Callback,
    Checkpoint,
    LevenbergMarquardt,
    Optimiser,
    Progress,
)
from .._solvers._quasi_newton import run_quasi_newton
from .._solvers._record import StageRecord, TrainingRecord
from .._solvers._adam import train_adam

_Map = TypeVar("_Map", bound=AbstractLearnedMap)


def default_optimiser(model: AbstractLearnedMap) -> tuple[Optimiser, ...]:
    """What `learn.fit` runs when given no optimiser: `model.default_optimiser()` (BFGS with
    the identity warm start, 3500 iterations, 4 starts, for a G-LPNet, as the paper; 100,000
    epochs of Adam, learning rate 1e-3, for the MLP-based maps)."""
    return check_learned_map(model).default_optimiser()




def fit(
    model: _Map,
    data: Trajectories | tuple[ArrayLike, ArrayLike],
    *,
    optimiser: Optimiser | Sequence[Optimiser] | None = None,
    epochs: int | None = None,
    h: float | None = None,
    validation_fraction: float = 0.2,
    seed: int = 0,
    loss: str | TrajectoryLoss | None = None,
    normalise: bool = False,
    checkpoint: Checkpoint | None = None,
    progress: bool | None = None,
    callback: Callback | None = None,
) -> tuple[_Map, TrainingRecord]:
    r"""Train a learned map on data pairs; returns `(fitted model, TrainingRecord)`.

    **Arguments:**

    - `model`: a learned map (`LPNet`, `Reversible`, `GLPNet`, `MLPBaseline`; not modified).
    - `data`: an `integrators.Trajectories` (consecutive states are the pairs, `h` its step),
      or `(y0, y1)` arrays `(N, dim)` with `h=`; or `integrators.Observations` (noisy states at
      their own times), compared by `loss`, a `learn.TrajectoryLoss` (default: whole
      trajectories from fitted initial states; docs/conventions.md, "Observations"), the
      held-out fraction taken by whole trajectories, the map's `h` set to `h=`, its own, or the
      median interval.
    - `optimiser`: an `Adam`, `QuasiNewton` or `LevenbergMarquardt`, or a sequence of them run one after the other
      (e.g. `(Adam(100_000), QuasiNewton(30_000))`, the paper's Adam refined by L-BFGS-B);
      default `default_optimiser(model)`. `epochs=N` is short for `optimiser=Adam(N)`.
    - `validation_fraction` of the pairs held out (random, seeded by `seed`, which also seeds
      mini-batches and restarts).
    - `loss` (pairs and trajectories): `"state"` (default, the paper's: MSE between the step of $y_0$ and $y_1$, for an
      LPNet through the exact flow, for a `Reversible` through its explicit residual form
      `training_prediction`) or another of `model.losses`: an LPNet's `"alpha"` (MSE between
      $\alpha(y_0)$ and the pairs' parameters `parametrisation.params_from_pair(y0, y1, h)`).
    - `normalise` (MLP-based maps): set the fixed input/output scalings from the training data
      first (inputs: mean/std of $y_0$; outputs: of the pairs' parameters for an LPNet, of
      $y_1 - y_0$ for the baseline). Default `False`: a plain MLP as in the paper (what
      normalising does on E1 is in BENCHMARKS.md).
    - `checkpoint`: a `Checkpoint` for the Adam or Levenberg-Marquardt stage (pairs and
      trajectories; not yet for observations).
    - `progress`: tqdm bars with the losses (`None`: only when stderr is a terminal); `callback(learn.Progress)`: called as training
      goes (after every 1000 Adam epochs, after every quasi-Newton start), e.g. to log.
    """
    model = check_learned_map(model)
    if epochs is not None:
        if optimiser is not None:
            raise ValueError("give either epochs (short for optimiser=learn.Adam(epochs)) or optimiser, not both")
        optimiser = Adam(positive_int(epochs, "epochs"))
    stages = model.default_optimiser() if optimiser is None else optimiser
    if isinstance(stages, OPTIMISERS):
        stages = (stages,)
    stages = tuple(stages)
    if not stages or not all(isinstance(s, OPTIMISERS) for s in stages):
        raise TypeError("optimiser must be a learn.Adam, learn.QuasiNewton or learn.LevenbergMarquardt, or a sequence "
                        f"of them; got {optimiser!r}")
    if not isinstance(normalise, (bool, np.bool_)):
        raise TypeError(f"normalise must be True or False; got {normalise!r}")
    if callback is not None and not callable(callback):
        raise TypeError(f"callback must be callable as callback(learn.Progress); got {callback!r}")
    if checkpoint is not None and not isinstance(checkpoint, Checkpoint):
        raise TypeError(f"checkpoint must be a learn.Checkpoint; got {type(checkpoint).__name__}")
    if checkpoint is not None and sum(isinstance(s, (Adam, LevenbergMarquardt)) for s in stages) != 1:
        raise ValueError("checkpoint needs exactly one Adam or LevenbergMarquardt stage in optimiser")
    for s in stages:
        if getattr(s, "warm_start", False) and not model.has_warm_start:
            raise ValueError(f"{type(s).__name__}(warm_start=True): a {type(model).__name__} has no warm start (the "
                             "G-LPNet's identity warm start); use warm_start=False")
    progress = show_progress(progress)
    if isinstance(data, Observations):
        if checkpoint is not None:
            raise ValueError("checkpoint= is not supported for observations yet; fit without it")
        if normalise:
            raise ValueError("normalise=True sets an MLP's scalings from pairs at one step; with observations, "
                             "build the map with its scalings (input_scaling=, output_scaling=) instead")
        fitted, records, history, settings, _ = fit_observations(model, data, stages, loss, h, validation_fraction,
                                                                 seed, progress, callback)
        model = fitted.model
        loss_name = f"observations: {settings['loss']}"
    else:
        loss = "state" if loss is None else loss
        loss_fn = model.loss_function(loss)
        pairs = prepare(data, model.system, h, validation_fraction, seed, conserves_casimirs=model.conserves_casimirs)
        if model.h is not None and abs(model.h - pairs.h) > 1e-12 * pairs.h:
            raise ValueError(
                f"the model's step h={model.h} differs from the data's h={pairs.h}; fit a model built "
                "with h=None (or the data's h), or data sampled at the model's step"
            )
        model = eqx.tree_at(lambda m: m.h, model, pairs.h, is_leaf=lambda x: x is None)
        model, train, val = _objective(model, pairs, loss, normalise)
        settings = {
            "validation_fraction": float(validation_fraction), "seed": int(seed), "loss": loss,
            "normalise": bool(normalise), "h": pairs.h, "n_train": int(train[0].shape[0]),
            "n_val": int(val[0].shape[0]),
        }
        model, records, history = _run_stages(stages, model, train, val, loss_fn, settings, checkpoint, progress,
                                              callback, type(model).__name__)
        loss_name = loss
    return model, training_record(model, settings, records, history, loss_name)


def training_record(model, settings, records, history, loss_name: str) -> TrainingRecord:
    """The `TrainingRecord` of a fit from its settings and stage records."""
    return TrainingRecord(
        model=type(model).__name__, h=float(model.h), seed=int(settings["seed"]),
        validation_fraction=float(settings["validation_fraction"]), loss=loss_name,
        normalise=bool(settings.get("normalise", False)), n_train=settings["n_train"], n_val=settings["n_val"],
        stages=tuple(records), history=history, train_loss=records[-1].train_loss,
        val_loss=records[-1].val_loss, wall_time_s=float(sum(r.wall_time_s for r in records)),
    )


def fit_observations(model, data, stages, loss, h, validation_fraction, seed, progress, callback):
    """`learn.fit` on `integrators.Observations`: `(fitted, stage records, history, settings,
    (loss_fn, (inputs, targets)))`, `fitted` a `Fitted` (the map and its fitted starts)."""
    fitted, train, val, loss_fn, settings = observed_objective(model, data, loss, h, validation_fraction, seed)
    fitted, records, history = _run_stages(stages, fitted, train, val, loss_fn, settings, None, progress, callback,
                                           type(model).__name__)
    return fitted, records, history, settings, (loss_fn, train)


def _run_stages(stages, model, train, val, loss_fn, settings, checkpoint, progress, callback, desc):
    """Run the optimiser stages one after the other; `(model, stage records, history)`."""
    X, T = (jnp.asarray(a) for a in train)
    Xv, Tv = (jnp.asarray(a) for a in val)
    seed = settings["seed"]
    history = {"epoch": np.zeros(0, int), "train_loss": np.zeros(0), "val_loss": np.zeros(0)}
    records = []
    if any(isinstance(stage, LevenbergMarquardt) for stage in stages):
        check_size(model, loss_fn, X, T)  # before any stage runs, not after an hour of Adam
    for index, stage in enumerate(stages):
        offset = sum(r.iterations for r in records)  # epochs and iterations run so far
        report = None if callback is None else functools.partial(_report, callback, index, type(stage).__name__)
        if isinstance(stage, Adam):
            model, rec, hist = _run_adam(stage, model, (X, T), (Xv, Tv), loss_fn, settings, checkpoint, progress,
                                         report, desc)
        elif isinstance(stage, LevenbergMarquardt):
            model, rec, hist = run_levenberg_marquardt(stage, model, (X, T), (Xv, Tv), loss_fn, seed, progress, report,
                                                       checkpoint, settings)
        else:
            model, rec, hist = run_quasi_newton(stage, model, (X, T), (Xv, Tv), loss_fn, seed, progress, report)
        hist = dict(hist, epoch=hist["epoch"] + offset)
        history = {k: np.concatenate([history[k], hist[k]]) for k in history}
        records.append(rec)
    return model, records, history


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


def _run_adam(stage: Adam, model, train, val, loss_fn, settings, checkpoint, progress, report, desc):
    log_every = stage.log_every if stage.log_every is not None else max(1, stage.epochs // 1000)
    best, info = train_adam(
        model, train, val, loss_fn,
        epochs=stage.epochs, learning_rate=stage.learning_rate, final_learning_rate=stage.final_learning_rate,
        batch_size=stage.batch_size, seed=settings["seed"], progress=progress, log_every=log_every,
        checkpoint=None if checkpoint is None else os.fspath(checkpoint.path),
        checkpoint_every=10_000 if checkpoint is None else checkpoint.every,
        resume=checkpoint is not None and checkpoint.resume,
        settings={**settings, **dataclasses.asdict(stage), "log_every": log_every}, desc=desc,
        on_chunk=None if report is None else lambda done, lt, lv: report(done, stage.epochs, lt, lv),
    )
    rec = StageRecord(
        optimiser="Adam", settings=dataclasses.asdict(stage), iterations=info["epochs"],
        train_loss=info["train_loss"], val_loss=info["val_loss"], kept=True, wall_time_s=info["wall_time_s"],
        details={"best_epoch": info["best_epoch"], "stopped": info["stopped"]},
    )
    return best, rec, info["history"]
