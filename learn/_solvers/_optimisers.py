"""The optimisers of `learn.fit` as plain settings (`Adam`, `QuasiNewton`), and what a fit
reports and resumes from (`Progress`, `Checkpoint`)."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable
from typing import Any

import numpy as np

from liepoisson.internals import positive_float, positive_int

#: Quasi-Newton methods: SciPy BFGS (dense), SciPy L-BFGS-B, optax L-BFGS.
QUASI_NEWTON_METHODS = ("bfgs", "lbfgsb", "lbfgs")


def check_method(method: Any) -> str:
    if method not in QUASI_NEWTON_METHODS:
        raise ValueError(f"method must be one of {list(QUASI_NEWTON_METHODS)}; got {method!r}")
    return method


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
    (`model.reinitialised`, keys from the fit's `seed`); `warm_start` (maps whose
    `warm_start()` offers one: a G-LPNet): each start first fits a simpler map for half the
    iterations (for a G-LPNet the identity activation: flows of quadratics, a smooth problem),
    maps it onto the model (`linear_to_activation`: the linear regime of $\sigma$) and finishes
    there (what it does on E6 is in BENCHMARKS.md).

    `rtol` (SciPy methods): stop a start once the loss has fallen by less than `rtol` of its
    value over the last 20 iterations (0, the default: run every iteration; a fit to noisy
    data reaches its noise floor long before, e.g. `rtol=1e-9`).

    The best start by validation loss (training loss without a validation set) is kept, and
    only if it beats the weights the stage started from.
    """

    iterations: int = 3500
    method: str = "lbfgsb"
    restarts: int = 1
    warm_start: bool = False
    rtol: float = 0.0

    def __post_init__(self):
        if isinstance(self.rtol, bool) or not isinstance(self.rtol, (int, float)) or not 0 <= self.rtol < 1:
            raise ValueError(f"QuasiNewton.rtol must be a number in [0, 1); got {self.rtol!r}")
        positive_int(self.iterations, "QuasiNewton.iterations")
        check_method(self.method)
        if not isinstance(self.warm_start, (bool, np.bool_)):
            raise TypeError(f"QuasiNewton.warm_start must be True or False; got {self.warm_start!r}")
        positive_int(self.restarts, "QuasiNewton.restarts")


@dataclasses.dataclass(frozen=True)
class LevenbergMarquardt:
    r"""Levenberg-Marquardt on the residuals $r$ of a least-squares loss: every loss of
    `learn.fit` (pairs: the state and alpha losses, `learn.MeanSquares`; observations:
    `learn.TrajectoryLoss`). Each step evaluates $r$ and its Jacobian $J$ once and solves
    $(J^TJ + \lambda D)\delta = -J^Tr$ by a lineax Cholesky, $D$ the largest
    $\mathrm{diag}(J^TJ)$ seen (Marquardt's scaling), $\lambda$ by Nielsen's rule; the loop
    runs on the host between two compiled functions (`learn/_solvers/_levenberg_marquardt.py` says why not
    optimistix).

    For a few dozen to a few hundred unknowns it reaches the minimum of a least-squares loss
    in tens of steps where BFGS takes hundreds (BENCHMARKS.md, "Learning from observations");
    each step costs $p$ forward passes for $p$ weights ($p + d$ with fitted starts:
    `ObservationLoss.jacobian`), so for the thousands of weights of an MLP use `QuasiNewton`
    (a step that would hold more than 2000 passes is refused).

    `iterations`: steps at most; `rtol`: stop once the loss has fallen by less than `rtol` of
    its value over the last 3 steps (0: only when no damping lowers it); `warm_start`: as
    `QuasiNewton`'s (half the steps on the simpler map a G-LPNet offers, then the rest from
    its fit). The result is kept only if it lowers the selection loss (validation, or training
    without a validation set). Deterministic; resumable with a `learn.Checkpoint`.
    """

    iterations: int = 200
    rtol: float = 1e-10
    warm_start: bool = False

    def __post_init__(self):
        positive_int(self.iterations, "LevenbergMarquardt.iterations")
        if isinstance(self.rtol, bool) or not isinstance(self.rtol, (int, float)) or not 0 <= self.rtol < 1:
            raise ValueError(f"LevenbergMarquardt.rtol must be a number in [0, 1); got {self.rtol!r}")
        if not isinstance(self.warm_start, (bool, np.bool_)):
            raise TypeError(f"LevenbergMarquardt.warm_start must be True or False; got {self.warm_start!r}")


Optimiser = Adam | QuasiNewton | LevenbergMarquardt
OPTIMISERS = (Adam, QuasiNewton, LevenbergMarquardt)


@dataclasses.dataclass(frozen=True)
class Checkpoint:
    """Write the state of the fit's Adam or Levenberg-Marquardt stage to `path` (HDF5) every
    `every` epochs or steps and at the end; with `resume`, continue from the file if it exists
    (epoch, optimiser state, best weights: bit-identical to an uninterrupted run). Checks that
    the file was written by the same model, data split and optimiser settings."""

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
    is (`iteration` of `total` epochs or iterations: `Adam` reports every compiled chunk of
    epochs, `QuasiNewton` every iteration (SciPy) or chunk (optax) and at the end of each start,
    `LevenbergMarquardt` every step and at the end) and the latest losses (`val_loss` NaN
    where not measured: inside a quasi-Newton or Levenberg-Marquardt run)."""

    stage: int
    optimiser: str
    iteration: int
    total: int
    train_loss: float
    val_loss: float


Callback = Callable[[Progress], None]
