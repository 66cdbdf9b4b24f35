r"""Training as a free function: `learn.fit(model, data, optimiser=...)` returns a new model and
its `TrainingRecord`. The loss builds the training problem from the map and the data; the
optimiser stages (`learn.Adam`, `learn.ScipyLBFGSB`, `learn.LevenbergMarquardt`, ..., or any
`learn.AbstractStage`) run one after the other, each from the weights the previous one
handed on."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence
from typing import Any, TypeVar

import numpy as np
from numpy.typing import ArrayLike

from integrators import BodyObservations, Observations, Trajectories
from liepoisson.internals import positive_int, show_progress

from .._models._base import AbstractLearnedMap, check_learned_map
from .._solvers._adam import Adam
from .._solvers._checkpoint import Checkpoint
from .._solvers._record import StageRecord, TrainingRecord
from .._solvers._stage import (
    AbstractStage,
    Callback,
    Context,
    Progress,
    Result,
)
from ._losses import AbstractLoss, AlphaLoss, StateLoss
from ._observed import TrajectoryLoss
from ._problem import MapProblem

_Map = TypeVar("_Map", bound=AbstractLearnedMap)


def default_optimiser(model: AbstractLearnedMap) -> tuple[AbstractStage, ...]:
    """What `learn.fit` runs when given no optimiser: `model.default_optimiser()` (BFGS with
    the identity warm start, 3500 iterations, 4 starts, for a G-LPNet, as the paper; 100,000
    epochs of Adam, learning rate 1e-3, for the MLP-based maps)."""
    return check_learned_map(model).default_optimiser()


def fit(
    model: _Map,
    data: Trajectories | Observations | tuple[ArrayLike, ArrayLike],
    *,
    optimiser: AbstractStage | Sequence[AbstractStage] | None = None,
    epochs: int | None = None,
    h: float | None = None,
    validation_fraction: float = 0.2,
    seed: int = 0,
    loss: str | AbstractLoss | None = None,
    normalise: bool = False,
    checkpoint: Checkpoint | None = None,
    progress: bool | None = None,
    callback: Callback | None = None,
) -> tuple[_Map, TrainingRecord]:
    r"""Train a learned map on data; returns `(fitted model, TrainingRecord)`.

    **Arguments:**

    - `model`: a learned map (`LPNet`, `Reversible`, `GLPNet`, `MLPBaseline`, ...; not modified).
    - `data`: an `integrators.Trajectories` (consecutive states are the pairs, `h` its step),
      or `(y0, y1)` arrays `(N, dim)` with `h=`; or `integrators.Observations` (noisy states at
      their own times), compared by a `learn.TrajectoryLoss` (default: whole trajectories from
      fitted initial states; conventions, [Observations][conventions-observations]), the
      held-out fraction taken by whole trajectories, the map's `h` set to `h=`, its own, or the
      median interval.
    - `optimiser`: a stage (`Adam`, `ScipyBFGS`, `ScipyLBFGSB`, `OptaxLBFGS`,
      `LevenbergMarquardt`, `Optimistix`, or any `learn.AbstractStage`), possibly wrapped
      (`learn.KeepIfBetter`, `learn.Restarts`, `learn.WarmStart`), or a sequence of them run one
      after the other (e.g. `(Adam(100_000), KeepIfBetter(ScipyLBFGSB(30_000)))`: Adam refined
      by L-BFGS-B where that lowers the validation loss); default `default_optimiser(model)`. `epochs=N` is short for
      `optimiser=Adam(N)`.
    - `validation_fraction` of the pairs held out (random, seeded by `seed`, which also seeds
      mini-batches and restarts).
    - `loss`: a `learn.AbstractLoss`: on pairs `learn.StateLoss()` (default, the paper's: MSE
      between the step of $y_0$ and $y_1$), an LPNet's `learn.AlphaLoss()` (MSE between
      $\alpha(y_0)$ and the pairs' parameters) or one of your own (`learn.AbstractPairsLoss`);
      on observations a `learn.TrajectoryLoss`. The strings `"state"` and `"alpha"` name the
      first two (`"state"` on observations: `TrajectoryLoss(window=1, latent=False)`).
    - `normalise` (MLP-based maps, pairs): set the fixed input/output scalings from the training
      data first (inputs: mean/std of $y_0$; outputs: of the loss's targets, or of the first
      estimate of the LPNet's parameters, or of $y_1 - y_0$ for the baseline). Default `False`:
      a plain MLP as in the paper (what normalising does on E1: benchmarks,
      [Figures moved out of docstrings][figures-moved-out-of-docstrings-issue-27]).
    - `checkpoint`: a `Checkpoint` for the one resumable stage (`Adam` or `LevenbergMarquardt`).
    - `progress`: tqdm bars with the losses (`None`: only when stderr is a terminal);
      `callback(learn.Progress)`: called as training goes (after every 1000 Adam epochs, every
      SciPy or Levenberg-Marquardt iteration, every optax chunk, the end of every start), e.g. to
      log.
    """
    model = check_learned_map(model)
    stages = _stages(model, optimiser, epochs, checkpoint)
    if not isinstance(normalise, (bool, np.bool_)):
        raise TypeError(f"normalise must be True or False; got {normalise!r}")
    if callback is not None and not callable(callback):
        raise TypeError(f"callback must be callable as callback(learn.Progress); got {callback!r}")
    problem = resolve_loss(loss, data).problem(model, data, h=h, validation_fraction=validation_fraction, seed=seed,
                                        normalise=bool(normalise))
    context = Context(seed=int(seed), progress=show_progress(progress), checkpoint=checkpoint)
    problem, results = solve(problem, stages, context, callback)
    return problem.map(problem.y0), training_record(problem, results)


def solve(problem: MapProblem, stages: Sequence[AbstractStage], context: Context,
          callback: Callback | None = None) -> tuple[MapProblem, list[Result]]:
    """Run `stages` one after the other on `problem`, each from the solution of the last;
    `(problem from the final solution, the stages' results)`."""
    context = dataclasses.replace(context, file_settings=_file_settings(problem))
    for stage in stages:  # before any stage runs, not after an hour of Adam
        stage.check(problem, context)
    results: list[Result] = []
    for index, stage in enumerate(stages):
        report = None if callback is None else _reporter(callback, index, stage.name)
        result = stage.run(problem, dataclasses.replace(context, report=report, total=stage.budget))
        problem = problem.with_start(result.y)
        results.append(result)
    return problem, results


def training_record(problem: MapProblem, results: Sequence[Result]) -> TrainingRecord:
    """The `TrainingRecord` of a fit from its problem and the results of its stages (their
    histories numbered on, stage after stage)."""
    history = {key: [] for key in ("epoch", "train_loss", "val_loss")}
    offset = 0
    for result in results:
        history["epoch"].append(np.asarray(result.history["epoch"]) + offset)
        history["train_loss"].append(np.asarray(result.history["train_loss"], dtype=np.float64))
        history["val_loss"].append(np.asarray(result.history["val_loss"], dtype=np.float64))
        offset += result.record.iterations
    records: list[StageRecord] = [result.record for result in results]
    d = problem.description
    return TrainingRecord(
        model=problem.name, h=float(problem.map(problem.y0).h), seed=d.seed,
        validation_fraction=d.validation_fraction, loss=d.loss, normalise=d.normalise, n_train=d.n_train,
        n_val=d.n_val, stages=tuple(records),
        history={key: np.concatenate([np.zeros(0, int if key == "epoch" else float), *parts])
                 for key, parts in history.items()},
        train_loss=records[-1].train_loss, val_loss=records[-1].val_loss,
        wall_time_s=float(sum(r.wall_time_s for r in records)),
        gyro_bias=None if getattr(problem.y0, "shared", None) is None else np.asarray(problem.y0.shared),
    )


def _stages(model: AbstractLearnedMap, optimiser: Any, epochs: int | None,
            checkpoint: Checkpoint | None) -> tuple[AbstractStage, ...]:
    """The stages the user asked for (checked), or the model's default."""
    if epochs is not None:
        if optimiser is not None:
            raise ValueError("give either epochs (short for optimiser=learn.Adam(epochs)) or optimiser, not both")
        optimiser = Adam(positive_int(epochs, "epochs"))
    stages = model.default_optimiser() if optimiser is None else optimiser
    stages = (stages,) if isinstance(stages, AbstractStage) else stages
    try:
        stages = tuple(stages)
    except TypeError:
        stages = ()
    if not stages or not all(isinstance(s, AbstractStage) for s in stages):
        raise TypeError("optimiser must be a learn.Adam, learn.ScipyLBFGSB, learn.LevenbergMarquardt, ... (a "
                        f"learn.AbstractStage), or a sequence of them; got {optimiser!r}")
    if checkpoint is not None and not isinstance(checkpoint, Checkpoint):
        raise TypeError(f"checkpoint must be a learn.Checkpoint; got {type(checkpoint).__name__}")
    if checkpoint is not None and sum(s.resumable for s in stages) != 1:
        raise ValueError("checkpoint needs exactly one Adam or LevenbergMarquardt stage in optimiser")
    return stages


def resolve_loss(loss: str | AbstractLoss | None, data: Any) -> AbstractLoss:
    """The loss object: the one given, or named, or the data's default (`named_losses`)."""
    if isinstance(loss, AbstractLoss):
        return loss
    named = named_losses(data)
    if loss is None or (isinstance(loss, str) and loss in named):
        return named[loss]
    error = ValueError if isinstance(loss, str) else TypeError
    raise error(f"loss must be a learn.AbstractLoss ({', '.join(type(v).__name__ for k, v in named.items() if k is None)}"
                    f" for this data, or learn.StateLoss(), learn.AlphaLoss(), learn.TrajectoryLoss(), ...) or one of "
                    f"{[k for k in named if k]}; got {loss!r}")


@functools.singledispatch
def named_losses(data: Any) -> dict[str | None, AbstractLoss]:
    """The losses a kind of data knows by name, `None` its default: on pairs the state loss
    (default) and an LPNet's alpha loss."""
    return {None: StateLoss(), "state": StateLoss(), "alpha": AlphaLoss()}


@named_losses.register
def _(data: BodyObservations) -> dict[str | None, AbstractLoss]:
    """On body observations: whole trajectories with latent momenta (`learn.BodyLoss`)."""
    from ._body import BodyLoss

    return {None: BodyLoss()}


@named_losses.register
def _(data: Observations) -> dict[str | None, AbstractLoss]:
    """On observations: whole trajectories with fitted starts (default), and `"state"` the
    one-step loss between consecutive observations."""
    return {None: TrajectoryLoss(), "state": TrajectoryLoss(window=1, latent=False)}


def _file_settings(problem: MapProblem) -> dict[str, Any]:
    """What a checkpoint must have been written with to be resumed: the fit's description
    (without what observations alone have, on pairs)."""
    return {k: v for k, v in dataclasses.asdict(problem.description).items() if v is not None}


def _reporter(callback: Callback, stage: int, name: str):
    def report(done: int, total: int, train: float, val: float) -> None:
        callback(Progress(stage, name, done, total, train, val))

    return report
