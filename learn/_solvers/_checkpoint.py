"""Training checkpoints: where a resumable stage writes its state (`Checkpoint`), and the check
that a file being resumed was written for the same problem and settings."""

from __future__ import annotations

import dataclasses
import os
from typing import TYPE_CHECKING, Any

import numpy as np

from liepoisson.internals import jsonable, positive_int

if TYPE_CHECKING:
    from ._problem import AbstractProblem


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

    def resumable(self) -> bool:
        """Whether a run should continue from the file (`resume` and the file exists)."""
        return self.resume and os.path.exists(self.path)


def read_resumable(path: str, owner: AbstractProblem, settings: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """`(attrs, groups)` of the checkpoint at `path` for resuming `owner` with `settings`:
    `ValueError` if it was written for another structure (the problem's check) or other
    settings (each differing key named)."""
    attrs, groups = owner.read_checkpoint(path)
    for key, value in jsonable(settings).items():
        if attrs["fit_settings"].get(key) != value:
            raise ValueError(
                f"checkpoint {path!r} was written with {key}={attrs['fit_settings'].get(key)!r}; "
                f"resume needs the same value, got {key}={value!r}"
            )
    return attrs, groups


def logged_entries(attrs: dict[str, Any], size: int) -> int:
    """How many of a checkpoint's `size` history entries its last run logged (`logged`; in
    files written before it, a Levenberg-Marquardt run's steps `epoch`, an Adam run's (no
    `phase`) the whole history)."""
    if "logged" in attrs:
        return int(attrs["logged"])
    return int(attrs["epoch"]) if "phase" in attrs else size


def resumable_phase(checkpoint: Checkpoint, owner: AbstractProblem) -> dict[str, np.ndarray] | None:
    """The loss history of a warm start that the checkpoint says is done (written in phase 1,
    after it), or `None` (no file to resume, or written during the warm start)."""
    if not checkpoint.resumable():
        return None
    attrs, groups = owner.read_checkpoint(os.fspath(checkpoint.path))
    if int(attrs.get("phase", 1)) != 1:
        return None
    losses = np.asarray(groups["history"]["train_loss"])
    warm = losses[: losses.size - logged_entries(attrs, losses.size)]
    return {"epoch": np.arange(1, warm.size + 1), "train_loss": warm, "val_loss": np.full(warm.size, np.nan)}
