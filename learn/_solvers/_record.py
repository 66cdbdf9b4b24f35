"""What a training run produced: a typed record, saved to and loaded from HDF5."""

from __future__ import annotations

import dataclasses
import os
from typing import Any

import numpy as np

from .. import _files as _checkpoint

_KIND = "TrainingRecord"


@dataclasses.dataclass(frozen=True)
class StageRecord:
    """One stage of a fit (an `Adam`, `ScipyLBFGSB`, `LevenbergMarquardt`, ... run).

    `optimiser` is the stage's class name and `settings` its fields; `iterations` the epochs or
    iterations run; `train_loss`/`val_loss` are those of the weights the stage hands on (its
    start's when `kept` is False: a quasi-Newton result that did not lower the selection loss
    is dropped); `details` holds what only some stages have (best epoch, why a run stopped,
    the losses of every start).
    """

    optimiser: str
    settings: dict[str, Any]
    iterations: int
    train_loss: float
    val_loss: float
    kept: bool
    wall_time_s: float
    details: dict[str, Any] = dataclasses.field(default_factory=dict)


@dataclasses.dataclass(frozen=True)
class TrainingRecord:
    """What `learn.fit` produced besides the model.

    `history` has `epoch` (Adam epochs, then quasi-Newton iterations numbered on from there),
    `train_loss` and `val_loss` (NaN where not measured); `train_loss`/`val_loss` are the
    losses of the returned weights (`val_loss` NaN without a validation set); `wall_time_s`
    the training time of all stages. `h`, `seed`, `validation_fraction`, `loss`, `normalise`,
    `n_train` and `n_val` describe the data and the objective; `stages` the optimisers.
    `choice`: on the records of `learn.fit_splitting` on observations, its `learn.FamilyChoice`
    (the families' criteria, the skipped families, the one chosen); `None` otherwise. It is not
    saved (the last stage's `details` keep each family's criterion). `gyro_bias`: with
    `learn.BodyLoss(bias=True)`, the gyroscope bias fitted for each group of trajectories
    `(G, dim)` (groups in order of first appearance, `BodyObservations.group_index`); `None`
    otherwise.
    """

    model: str
    h: float
    seed: int
    validation_fraction: float
    loss: str
    normalise: bool
    n_train: int
    n_val: int
    stages: tuple[StageRecord, ...]
    history: dict[str, np.ndarray]
    train_loss: float
    val_loss: float
    wall_time_s: float
    choice: Any = None
    gyro_bias: np.ndarray | None = None

    def __repr__(self) -> str:
        stages = " + ".join(s.optimiser for s in self.stages)
        return (
            f"TrainingRecord({self.model}, {stages}: train_loss={self.train_loss:.3g}, "
            f"val_loss={self.val_loss:.3g}, wall_time_s={self.wall_time_s:.3g})"
        )

    def save(self, path: str | os.PathLike) -> None:
        """Write to an HDF5 file (scalars and stages as attributes, history and the gyroscope
        bias as datasets), atomically."""
        attrs = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                 if f.name not in ("history", "choice", "gyro_bias")}
        attrs["class"] = _KIND
        attrs["stages"] = [dataclasses.asdict(s) for s in self.stages]
        arrays = {"history": self.history}
        if self.gyro_bias is not None:
            arrays["fitted"] = {"gyro_bias": np.asarray(self.gyro_bias)}
        _checkpoint.write(path, attrs, arrays)

    @classmethod
    def load(cls, path: str | os.PathLike) -> TrainingRecord:
        """Read a record written by `save`."""
        attrs, groups = _checkpoint.read(path)
        if attrs.get("class") != _KIND:
            raise ValueError(f"path {os.fspath(path)!r} holds a {attrs.get('class')}, not a {_KIND}")
        names = {f.name for f in dataclasses.fields(cls)} - {"history", "stages", "choice", "gyro_bias"}
        try:
            values = {k: attrs[k] for k in names}
            stages = tuple(StageRecord(**s) for s in attrs["stages"])
            history = groups["history"]
        except (KeyError, TypeError) as err:
            raise ValueError(f"path {os.fspath(path)!r} is not a complete TrainingRecord file ({err})") from err
        bias = groups.get("fitted", {}).get("gyro_bias")
        return cls(stages=stages, history=history, gyro_bias=None if bias is None else np.asarray(bias), **values)
