r"""A solver stage of `learn.fit`: one abstract class with one `run(problem, context)` (a
solver's is the shared loop, `learn.AbstractSolver`), and the behaviours added to any stage
by wrapping it (as optimistix's `BestSoFarMinimiser`), never by its options: fresh restarts
(`Restarts`), the warm start a problem offers (`WarmStart`) and keeping the result only if it
beats the start (`KeepIfBetter`)."""

from __future__ import annotations

import abc
import dataclasses
import time
from collections.abc import Callable
from typing import Any, ClassVar

import jax
import numpy as np

from liepoisson.internals import positive_int

from ._checkpoint import Checkpoint, resumable_phase
from ._problem import AbstractProblem
from ._record import StageRecord


@dataclasses.dataclass(frozen=True)
class Progress:
    """What a `learn.fit` callback receives: the stage (index and optimiser name), how far it
    is (`iteration` of `total` epochs or iterations: `Adam` reports every compiled chunk of
    epochs, `ScipyBFGS` and `ScipyLBFGSB` every iteration, `OptaxLBFGS` every chunk,
    `LevenbergMarquardt` every step, `Restarts` the end of each start, `KeepIfBetter` the end) and the latest losses (`val_loss` NaN
    where not measured: inside a quasi-Newton or Levenberg-Marquardt run)."""

    stage: int
    optimiser: str
    iteration: int
    total: int
    train_loss: float
    val_loss: float


Callback = Callable[[Progress], None]


@dataclasses.dataclass(frozen=True)
class Context:
    """What a stage is run with besides its problem: the fit's `seed` (restarts, mini-batches),
    whether to show `progress` bars, `report(done, total, train, val)` for the callback (or
    `None`), `offset` (iterations run before this part of the stage), the `checkpoint` and, with
    a warm start, its `phase` (0 while solving the simpler problem, 1 after)."""

    seed: int = 0
    progress: bool = False
    report: Callable[[int, int, float, float], None] | None = None
    offset: int = 0
    total: int = 0
    checkpoint: Checkpoint | None = None
    phase: int = 1
    #: The problem a checkpoint file identifies (the outermost: a warm start's simpler problem
    #: is written under the full problem's name).
    owner: AbstractProblem | None = None
    #: A name for the progress bars.
    desc: str = ""
    #: What a checkpoint file must have been written with to be resumed (the fit's data
    #: split and the stage's settings, as JSON values).
    file_settings: dict[str, Any] = dataclasses.field(default_factory=dict)
    #: The losses of earlier parts of the stage (a warm start's), written before this part's
    #: in a checkpoint's history.
    earlier: tuple[float, ...] = ()

    def shifted(self, offset: int, **changes: Any) -> Context:
        return dataclasses.replace(self, offset=self.offset + offset, **changes)


@dataclasses.dataclass(frozen=True)
class Linearisation:
    r"""The residuals $r$ `(n,)` and Jacobian $J$ `(n, p)` of a least-squares objective at the
    flat trainable leaves `x` of a `y`, on the data `args`: what `learn.LevenbergMarquardt`
    computed at its last step, handed on in its `Result` so that what is measured on the fit
    afterwards (its information criterion, its residuals) reads them instead of evaluating
    them again."""

    x: jax.Array
    args: Any
    residuals: jax.Array
    jacobian: jax.Array

    def at(self, x: Any, args: Any) -> bool:
        """Whether these are the residuals and Jacobian at `x` (equal to the bit) on `args` (the
        same object, of JAX arrays only: immutable, where a NumPy array changed in place would
        be other data in the same object)."""
        if args is not self.args or not all(isinstance(a, jax.Array) for a in jax.tree_util.tree_leaves(args)):
            return False
        x, mine = np.asarray(x), np.asarray(self.x)
        return x.shape == mine.shape and x.dtype == mine.dtype and x.tobytes() == mine.tobytes()


@dataclasses.dataclass(frozen=True)
class Result:
    """What a stage returns: the new `y`, its record and its loss history (`epoch`,
    `train_loss`, `val_loss` arrays, `val_loss` NaN where not measured); `linearisation` the
    residuals and Jacobian where the stage computed them last (`learn.LevenbergMarquardt`;
    `None` otherwise)."""

    y: Any
    record: StageRecord
    history: dict[str, np.ndarray]
    linearisation: Linearisation | None = None


def history(train_loss: Any, epoch: Any = None) -> dict[str, np.ndarray]:
    """A history of training losses (epochs numbered from 1 unless given; no validation loss)."""
    train_loss = np.asarray(train_loss, dtype=np.float64)
    epoch = np.arange(1, train_loss.size + 1) if epoch is None else np.asarray(epoch)
    return {"epoch": epoch, "train_loss": train_loss, "val_loss": np.full(train_loss.size, np.nan)}


class AbstractStage(abc.ABC):
    """A solver stage: `run(problem, context)` minimises from `problem.y0` and returns a
    `Result`. `budget` is its iterations (or epochs); `with_budget(n)` the same stage with
    another, which is how a wrapper splits a stage. Restarts, a warm start and keeping the
    result only if it is better are wrappers around a stage (`Restarts`, `WarmStart`,
    `KeepIfBetter`), never its options."""

    #: Whether the stage writes its state to the fit's `learn.Checkpoint` and resumes from it.
    resumable: ClassVar[bool] = False

    @property
    def name(self) -> str:
        """What records and progress reports call the stage: its solver's class name."""
        return type(self).__name__

    @abc.abstractmethod
    def run(self, problem: AbstractProblem, context: Context) -> Result:
        """Run the stage on `problem`."""

    @property
    @abc.abstractmethod
    def budget(self) -> int:
        """Iterations (or epochs) at most."""

    @abc.abstractmethod
    def with_budget(self, budget: int) -> AbstractStage:
        """The same stage with `budget` iterations."""

    def check(self, problem: AbstractProblem, context: Context) -> None:
        """`ValueError` (before any stage runs) if this stage cannot solve `problem`."""


class AbstractIterationsStage(AbstractStage):
    """A stage whose budget is its field `iterations`."""

    iterations: int

    @property
    def budget(self) -> int:
        return self.iterations

    def with_budget(self, budget: int) -> AbstractIterationsStage:
        return dataclasses.replace(self, iterations=budget)


def finished_record(problem: AbstractProblem, stage: AbstractStage, iterations: int, started: float, y: Any,
                    details: dict[str, Any] | None = None) -> StageRecord:
    """The record of a stage's run from `problem`'s start that handed on `y` (its losses;
    `kept` True: the selection is `KeepIfBetter`'s), `started` the `time.perf_counter()` at
    its start."""
    losses = problem.losses(y)
    settings = dataclasses.asdict(stage) if dataclasses.is_dataclass(stage) else {}
    return StageRecord(optimiser=stage.name, settings=settings, iterations=iterations, train_loss=losses.train,
                       val_loss=losses.validation, kept=True, wall_time_s=time.perf_counter() - started,
                       details=details or {})


class AbstractWrappedStage(AbstractStage):
    """A stage that adds a behaviour to `stage`, delegating the rest."""

    stage: AbstractStage

    @property
    def budget(self) -> int:
        return self.stage.budget

    @property
    def name(self) -> str:
        return self.stage.name

    @property
    def resumable(self) -> bool:  # type: ignore[override]
        return self.stage.resumable

    def check(self, problem: AbstractProblem, context: Context) -> None:
        self.stage.check(problem, context)


@dataclasses.dataclass(frozen=True)
class KeepIfBetter(AbstractWrappedStage):
    """`stage`'s result only if it lowers the selection loss (validation, else training) of the
    start; else the start, with `kept=False`. The record's losses are those of what is handed
    on; its `details` add the start's (`train_loss_before`, `val_loss_before`)."""

    stage: AbstractStage

    def with_budget(self, budget: int) -> KeepIfBetter:
        return KeepIfBetter(self.stage.with_budget(budget))

    def run(self, problem: AbstractProblem, context: Context) -> Result:
        result = self.stage.run(problem, context)
        after, before = problem.losses(result.y), problem.losses(problem.y0)
        kept = bool(np.isfinite(after.selection) and after.selection < before.selection)
        if not kept and not np.isfinite(before.selection):
            raise FloatingPointError(f"{context.desc or problem.name}: the loss is not finite at the start nor at the "
                                     "end; check the weights and the data")
        if context.report is not None and context.phase == 1:
            context.report(context.offset + result.record.iterations, context.total, after.train, after.validation)
        end = after if kept else before
        record = dataclasses.replace(
            result.record, train_loss=end.train, val_loss=end.validation, kept=kept,
            details={**result.record.details, "train_loss_before": before.train, "val_loss_before": before.validation})
        return Result(result.y if kept else problem.y0, record, result.history,
                      result.linearisation if kept else None)


@dataclasses.dataclass(frozen=True)
class Restarts(AbstractWrappedStage):
    """`stage` run from `starts` starts, the first from the problem's start, the others from
    fresh random weights (`problem.reinitialised`, keys from the fit's seed); the best by
    selection loss (the earliest on a tie) is returned, its record's `details` naming it
    (`best_start`) and the training loss of every start (`start_train_losses`)."""

    stage: AbstractStage
    starts: int = 1

    def __post_init__(self):
        positive_int(self.starts, "Restarts.starts")

    @property
    def budget(self) -> int:
        return self.starts * self.stage.budget

    def with_budget(self, budget: int) -> Restarts:
        return Restarts(self.stage.with_budget(max(1, budget // self.starts)), self.starts)

    def run(self, problem: AbstractProblem, context: Context) -> Result:
        base = jax.random.PRNGKey(context.seed)
        name = context.desc or problem.name
        start = time.perf_counter()
        runs = []
        for r in range(self.starts):
            start_r = problem if r == 0 else problem.with_start(problem.reinitialised(jax.random.fold_in(base, r)))
            desc = f"{name} start {r + 1}/{self.starts}" if self.starts > 1 else name
            before = r * self.stage.budget
            result = self.stage.run(start_r, context.shifted(before, desc=desc))
            losses = problem.losses(result.y)
            runs.append((losses.selection, r, losses, result))
            if context.report is not None:
                context.report(context.offset + (r + 1) * self.stage.budget, context.total, losses.train,
                               losses.validation)
        _, best, losses, result = min(runs, key=lambda t: (t[0], t[1]))
        record = dataclasses.replace(
            result.record, train_loss=losses.train, val_loss=losses.validation, wall_time_s=time.perf_counter() - start,
            details={**result.record.details, "best_start": best,
                     "start_train_losses": [run[2].train for run in runs]})
        return Result(result.y, record, result.history, result.linearisation)


@dataclasses.dataclass(frozen=True)
class WarmStart(AbstractWrappedStage):
    """`stage` first on the simpler problem the problem offers (`problem.warm_start()`, e.g. a
    G-LPNet's identity activation: flows of quadratics, a smooth problem) for half its budget,
    then on the problem from the solution mapped onto it for the rest; `stage` alone where the
    problem offers none. Resumes from a checkpoint in either half."""

    stage: AbstractStage

    def with_budget(self, budget: int) -> WarmStart:
        return WarmStart(self.stage.with_budget(budget))

    def check(self, problem: AbstractProblem, context: Context) -> None:
        problem.warm_start()  # a problem that cannot offer one says so before anything runs
        self.stage.check(problem, context)

    def run(self, problem: AbstractProblem, context: Context) -> Result:
        warm = problem.warm_start()
        if warm is None:
            return self.stage.run(problem, context)
        simpler, to_this = warm
        first = max(1, self.budget // 2)
        rest = self.stage.with_budget(max(1, self.budget - first))
        name = context.desc or problem.name
        start = time.perf_counter()
        owner = context.owner or problem
        earlier = _resumed_warm_history(context, owner)
        if earlier is None:
            head = self.stage.with_budget(first).run(
                simpler, context.shifted(0, phase=0, owner=owner, desc=f"{name} (warm start)"))
            tail_problem = problem.with_start(to_this(head.y))
            earlier = head.history
        else:  # the checkpoint was written after the warm start: go on from its weights
            tail_problem = problem
        tail = rest.run(tail_problem, context.shifted(
            earlier["train_loss"].size, phase=1, owner=owner, desc=f"{name} (from the warm start)",
            earlier=tuple(float(v) for v in earlier["train_loss"])))
        shift = earlier["epoch"][-1] if earlier["epoch"].size else 0
        combined = {key: np.concatenate([earlier[key], tail.history[key] + (shift if key == "epoch" else 0)])
                    for key in ("epoch", "train_loss", "val_loss")}
        record = dataclasses.replace(tail.record, iterations=int(combined["train_loss"].size),
                                     wall_time_s=time.perf_counter() - start)
        return Result(tail.y, record, combined, tail.linearisation)


def _resumed_warm_history(context: Context, owner: AbstractProblem) -> dict[str, np.ndarray] | None:
    """The history of a warm start a checkpoint says is done (`phase` 1), else `None`."""
    if context.checkpoint is None:
        return None
    return resumable_phase(context.checkpoint, owner)
