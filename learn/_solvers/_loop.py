r"""The one loop every solver of `learn.fit` runs in, as optimistix poses a solver: `init`,
`step`, `terminate` on a problem $f(y, \text{args})$ (`AbstractSolver`). The loop (`iterate`)
owns what is the same for all of them: the progress bar, the loss history, the callback's
reports, the best iterate so far, the checkpoint file (when it is written, its format, resuming
from it) and the `StageRecord`. A solver says only how it steps, when it stops early and what
it hands on.
"""

from __future__ import annotations

import abc
import dataclasses
import os
import time
from typing import Any, ClassVar

import numpy as np
from tqdm.auto import tqdm

from .. import _files
from ._checkpoint import logged_entries, read_resumable
from ._problem import AbstractProblem
from ._stage import AbstractIterationsStage, Context, Linearisation, Result, finished_record


@dataclasses.dataclass(frozen=True)
class Step:
    """What one `step` of a solver did: `done` iterations (or epochs) run; the losses it logs
    (`epochs` their numbers, counted from 1 within the run unless the solver numbers them
    otherwise; `train_loss`, `val_loss` NaN where not measured); `candidate`, an iterate
    `(y, score, iteration)` for the best so far (lowest `score`, the earliest on a tie) or
    `None`; `stop`, why the run ends now (empty: it goes on); `latest`, the training and
    validation losses to report (by default the last logged)."""

    done: int
    epochs: np.ndarray
    train_loss: np.ndarray
    val_loss: np.ndarray
    candidate: tuple[Any, float, int] | None = None
    stop: str = ""
    latest: tuple[float, float] | None = None


def losses_step(done_before: int, train_loss: Any, **changes: Any) -> Step:
    """A `Step` of `len(train_loss)` iterations after `done_before`, each logged, no
    validation loss."""
    train = np.atleast_1d(np.asarray(train_loss, dtype=np.float64))
    return Step(train.size, np.arange(done_before + 1, done_before + train.size + 1), train,
                np.full(train.size, np.nan), **changes)


class AbstractSolver(AbstractIterationsStage):
    """A stage as optimistix poses a solver: `init(problem, context)` its state, `step(problem,
    state)` one step (or a compiled chunk of steps) returning the new state and a `Step`,
    `terminate(problem, state, losses)` whether to stop before the next step (besides its
    budget of `iterations`), `current(state)` the iterate, and `postprocess(problem, state,
    best)` the `y` it hands on (by default the best candidate, else the current iterate), the
    record's `details` and the `Linearisation` it computed last. `run` is the shared loop
    (`iterate`). A resumable solver (`resumable = True`) also gives `optimizer_leaves(state)`
    and `resume(problem, context, state, attrs, groups)`."""

    #: What the progress bar counts.
    unit: ClassVar[str] = "it"
    #: Whether its steps offer candidates for the best so far (a checkpoint then keeps it).
    keeps_best: ClassVar[bool] = False

    @abc.abstractmethod
    def init(self, problem: AbstractProblem, context: Context) -> Any:
        """The state before the first step."""

    @abc.abstractmethod
    def step(self, problem: AbstractProblem, state: Any) -> tuple[Any, Step]:
        """One step from `state`."""

    def terminate(self, problem: AbstractProblem, state: Any, losses: list[float]) -> bool:
        """Whether to stop before another step (`losses`: the training losses logged so far,
        resumed ones included); by default only the budget stops a run."""
        return False

    @abc.abstractmethod
    def current(self, state: Any) -> Any:
        """The current iterate `y`."""

    def initial_best(self, problem: AbstractProblem) -> tuple[Any, float, int] | None:
        """The best-so-far before any step (`None`: none)."""
        return None

    def final_candidate(self, problem: AbstractProblem, state: Any, done: int) -> tuple[Any, float, int] | None:
        """A last candidate once the loop has ended (e.g. an iterate the steps never scored)."""
        return None

    def postprocess(self, problem: AbstractProblem, state: Any, best: tuple[Any, float, int] | None,
                    stopped: str) -> tuple[Any, dict[str, Any], Linearisation | None]:
        """`(y handed on, the record's details, linearisation)`."""
        return (self.current(state) if best is None else best[0]), {}, None

    def close(self, state: Any) -> None:
        """Release what `init` took (a thread, a file); called however the loop ends."""

    def file_settings(self) -> dict[str, Any]:
        """What a checkpoint must have been written with to be resumed by this solver."""
        return dataclasses.asdict(self)

    def optimizer_leaves(self, state: Any) -> list[Any]:
        """The optimiser's state for a checkpoint file (resumable solvers)."""
        raise NotImplementedError

    def resume(self, problem: AbstractProblem, context: Context, state: Any, attrs: dict[str, Any],
               groups: dict[str, Any], weights: Any) -> Any:
        """The state written in a checkpoint (`weights`: its current iterate, as a `y`)."""
        raise NotImplementedError

    def check(self, problem: AbstractProblem, context: Context) -> None:
        if context.checkpoint is not None and self.resumable:
            problem.file_attributes()  # a problem that cannot be written says so now

    def run(self, problem: AbstractProblem, context: Context) -> Result:
        self.check(problem, context)
        return iterate(self, problem, context)


def iterate(solver: AbstractSolver, problem: AbstractProblem, context: Context) -> Result:
    """Run `solver` on `problem`: its steps until its budget, its `terminate` or a step's
    `stop`; the progress bar, the history, the reports, the best so far and the checkpoint
    (every `checkpoint.every` iterations and at the end; resumed from when asked and written
    in the same phase of a warm start) are this loop's."""
    started = time.perf_counter()
    state = solver.init(problem, context)
    history: dict[str, list] = {"epoch": [], "train_loss": [], "val_loss": []}
    best = solver.initial_best(problem)
    done, elapsed0 = 0, 0.0
    saved = None
    if context.checkpoint is not None and solver.resumable:
        saved = _CheckpointFile(context, problem, solver)
        resumed = saved.read(problem)
        if resumed is not None:
            attrs, groups, part, weights = resumed
            state = solver.resume(problem, context, state, attrs, groups, weights)
            done, elapsed0 = int(attrs["epoch"]), float(attrs["elapsed_s"])
            history = {key: list(value) for key, value in part.items()}
            if solver.keeps_best and int(attrs["best_epoch"]) >= 0:
                best = (_files.replace_array_leaves(problem.y0, groups["best"], "best"), float(attrs["best_loss"]),
                        int(attrs["best_epoch"]))
    last_saved = done
    stopped = ""
    desc = context.desc or f"{problem.name} {solver.name}"
    bar = tqdm(total=solver.budget, initial=done, disable=not context.progress, desc=desc, unit=solver.unit,
               leave=False)
    try:
        while done < solver.budget and not solver.terminate(problem, state, history["train_loss"]):
            state, step = solver.step(problem, state)
            done += step.done
            history["epoch"].extend(np.asarray(step.epochs).tolist())
            history["train_loss"].extend(np.asarray(step.train_loss).tolist())
            history["val_loss"].extend(np.asarray(step.val_loss).tolist())
            if step.candidate is not None and (best is None or step.candidate[1] < best[1]):
                best = step.candidate
            if step.done:
                train, val = step.latest or (float(step.train_loss[-1]), float(step.val_loss[-1]))
                bar.update(step.done)
                bar.set_postfix(loss=f"{train:.3g}", **({"best": f"{best[1]:.3g}"} if solver.keeps_best else {}))
                if context.report is not None:
                    context.report(context.offset + done, context.total, train, val)
            if step.stop:
                stopped = step.stop
                break
            if saved is not None and done - last_saved >= saved.every and done < solver.budget:
                saved.write(solver, state, best, history, done, elapsed0 + time.perf_counter() - started)
                last_saved = done
    finally:
        bar.close()
        solver.close(state)
    final = solver.final_candidate(problem, state, done)
    if final is not None and (best is None or final[1] < best[1]):
        best = final
    if saved is not None and done > 0:
        saved.write(solver, state, best, history, done, elapsed0 + time.perf_counter() - started)
    y, details, linearisation = solver.postprocess(problem, state, best, stopped)
    record = finished_record(problem, solver, done, started, y, details)
    record = dataclasses.replace(record, wall_time_s=elapsed0 + record.wall_time_s)
    out = {key: np.asarray(value, dtype=int if key == "epoch" else np.float64) for key, value in history.items()}
    return Result(y, record, out, linearisation)


class _CheckpointFile:
    r"""The loop's checkpoint file, one format for every resumable solver: attributes `epoch`
    (iterations of this run), `logged` (its entries in the history), `best_loss`,
    `best_epoch`, `elapsed_s`, `fit_settings` and `phase` (0 while a warm start's simpler
    problem is solved, 1 after) besides the problem's own (its structure); groups `weights`
    (the current iterate), `best` (the best so far, the current iterate for a solver that
    keeps none; during a warm start the owner's starting weights: what loading the file as a
    model gives), `optimizer` (the solver's state) and `history` (the warm start's losses, then
    this run's)."""

    def __init__(self, context: Context, problem: AbstractProblem, solver: AbstractSolver):
        self.path = os.fspath(context.checkpoint.path)
        self.every = context.checkpoint.every
        self.resumable = context.checkpoint.resumable()
        self.owner = context.owner or problem
        self.phase = context.phase
        self.earlier = np.asarray(context.earlier, dtype=np.float64)
        self.settings = {**context.file_settings, **solver.file_settings()}
        self.attrs = self.owner.file_attributes()

    def read(self, problem: AbstractProblem):
        """`(attrs, groups, this run's history, its current iterate)` of a file to resume in
        this phase, else `None`."""
        if not self.resumable:
            return None
        attrs, groups = read_resumable(self.path, self.owner, self.settings)
        if int(attrs.get("phase", 1)) != self.phase:
            return None
        size = len(groups["history"]["train_loss"])
        logged = logged_entries(attrs, size)
        part = {key: np.asarray(value)[size - logged:] for key, value in groups["history"].items()}
        part["epoch"] = part["epoch"] - (size - logged)
        return attrs, groups, part, _files.replace_array_leaves(problem.y0, groups["weights"], "weights")

    def write(self, solver, state, best, history, done, elapsed):
        current = solver.current(state)
        leaves = _files.array_leaves(current)
        train = np.concatenate([self.earlier, np.asarray(history["train_loss"], dtype=np.float64)])
        val = np.concatenate([np.full(self.earlier.size, np.nan), np.asarray(history["val_loss"], dtype=np.float64)])
        epoch = np.concatenate([np.arange(1, self.earlier.size + 1),
                                np.asarray(history["epoch"], dtype=int) + self.earlier.size])
        if best is None:  # a solver keeping no best: its current iterate, the last loss
            best_leaves, best_loss, best_epoch = leaves, float(train[-1]) if train.size else float("nan"), train.size
        else:
            best_leaves, best_loss, best_epoch = _files.array_leaves(best[0]), float(best[1]), int(best[2])
        if self.phase != 1:
            best_leaves = _files.array_leaves(self.owner.y0)
        _files.write(self.path, {**self.attrs, "epoch": int(done), "logged": len(history["train_loss"]),
                                 "best_loss": best_loss, "best_epoch": best_epoch, "elapsed_s": float(elapsed),
                                 "fit_settings": self.settings, "phase": self.phase},
                     {"weights": leaves, "best": best_leaves, "optimizer": solver.optimizer_leaves(state),
                      "history": {"epoch": epoch, "train_loss": train, "val_loss": val}})
