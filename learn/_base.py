"""What every learned step map shares: batched steps, rollouts, the Poisson defect, training
records and HDF5 save/load."""

from __future__ import annotations

import abc
import dataclasses
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import liepoisson as lp
from liepoisson.systems import AbstractPoissonSystem

from . import _checkpoint
from ._rollout import batched_step, poisson_defect, rollout
from ._validation import check_system, positive_int, states


class TrainingRecord:
    """What a fit produced: the loss history and the losses of the kept weights.

    Held by a model as a static field: hashable by identity, never traced.
    """

    def __init__(self, history, train_loss, val_loss, wall_time_s, info=None):
        self.history = {k: np.asarray(v) for k, v in history.items()}
        self.train_loss = float(train_loss)
        self.val_loss = float(val_loss)
        self.wall_time_s = float(wall_time_s)
        self.info = dict(info or {})

    def __repr__(self) -> str:
        return (
            f"TrainingRecord(train_loss={self.train_loss:.3g}, val_loss={self.val_loss:.3g}, "
            f"wall_time_s={self.wall_time_s:.3g})"
        )


def replace(module: eqx.Module, **changes: Any) -> eqx.Module:
    """A copy of `module` with some fields (static or not) replaced."""
    new = object.__new__(type(module))
    for f in dataclasses.fields(module):
        object.__setattr__(new, f.name, changes.pop(f.name, getattr(module, f.name)))
    if changes:
        raise TypeError(f"{type(module).__name__} has no fields {sorted(changes)}")
    return new


class AbstractLearnedMap(eqx.Module):
    r"""A learned one-step map $y_{n+1} = \mathbb T(y_n)$ of a Poisson system.

    Subclasses define `_step` (one sample, traceable), their hyperparameters and how to build
    an untrained skeleton from them; rollouts, the Poisson defect and files are shared.
    """

    system: eqx.AbstractVar[AbstractPoissonSystem]
    h: eqx.AbstractVar[float | None]
    record: eqx.AbstractVar[TrainingRecord | None]

    # -- what a learned map defines ----------------------------------------------------------
    @abc.abstractmethod
    def _step(self, y: jax.Array) -> jax.Array:
        """One step for one sample `(dim,)`; `self.h` is set."""

    @abc.abstractmethod
    def hyperparameters(self) -> dict[str, Any]:
        """JSON-serialisable description from which `_skeleton` rebuilds the architecture."""

    @classmethod
    @abc.abstractmethod
    def _skeleton(cls, system: AbstractPoissonSystem, hyperparameters: dict[str, Any]):
        """A model with the given hyperparameters (weights to be replaced)."""

    # -- shared ----------------------------------------------------------------------------
    def _require_h(self) -> float:
        if self.h is None:
            raise ValueError(
                f"{type(self).__name__} has no time step yet: fit it to data or pass h= when "
                "constructing it"
            )
        return self.h

    def __call__(self, y: jax.Array) -> jax.Array:
        """One learned step of one sample `(dim,)`."""
        self._require_h()
        return self._step(y)

    def step(self, y: Any) -> jax.Array:
        """One learned step, batched over leading axes: `(..., dim)` -> `(..., dim)`."""
        self._require_h()
        y = states(y, "y", self.system.dim)
        flat = jnp.asarray(y.reshape(-1, self.system.dim))
        return batched_step(self, flat).reshape(y.shape)

    def rollout(self, y0: Any, n_steps: Any) -> jax.Array:
        """Iterate the learned step: `(n_steps+1, dim)` for `y0` `(dim,)`, or
        `(n_traj, n_steps+1, dim)` for `y0` `(n_traj, dim)`; row 0 is `y0`."""
        self._require_h()
        n_steps = positive_int(n_steps, "n_steps", minimum=0)
        y0 = states(y0, "y0", self.system.dim)
        if y0.ndim > 2:
            raise ValueError(f"y0 must have shape (dim,) or (n_traj, dim); got {y0.shape}")
        single = y0.ndim == 1
        out = rollout(self, jnp.asarray(y0.reshape(-1, self.system.dim)), n_steps)
        return out[0] if single else out

    def poisson_defect(self, y: Any) -> jax.Array:
        r"""$\max_{ab}|(J\,\mathbb B(y)\,J^\top - \mathbb B(\mathbb T y))_{ab}|$ per point,
        $J = \partial\mathbb T/\partial y$ (forward-mode autodiff): zero for a Poisson map.
        `y` `(..., dim)` -> `(...)`."""
        self._require_h()
        y = states(y, "y", self.system.dim)
        flat = jnp.asarray(y.reshape(-1, self.system.dim))
        return poisson_defect(self, flat).reshape(y.shape[:-1])

    @property
    def n_parameters(self) -> int:
        """Number of trainable parameters (the floating-point array leaves)."""
        leaves = jax.tree_util.tree_leaves(eqx.filter(self, eqx.is_inexact_array))
        return int(sum(leaf.size for leaf in leaves))

    @property
    def history(self) -> dict[str, np.ndarray]:
        """Loss history of the last fit (`epoch`/`iteration`, `train_loss`, `val_loss`)."""
        return {} if self.record is None else self.record.history

    @property
    def train_loss(self) -> float:
        """Training loss of the kept weights (NaN if never fitted)."""
        return float("nan") if self.record is None else self.record.train_loss

    @property
    def val_loss(self) -> float:
        """Validation loss of the kept weights (NaN if never fitted or no validation set)."""
        return float("nan") if self.record is None else self.record.val_loss

    @property
    def wall_time_s(self) -> float:
        """Wall-clock time of the last fit in seconds (NaN if never fitted)."""
        return float("nan") if self.record is None else self.record.wall_time_s

    # -- files -------------------------------------------------------------------------------
    def file_content(self) -> tuple[dict[str, Any], dict[str, Any]]:
        """Attributes and weight groups of this model's HDF5 file."""
        rec = self.record
        attrs = {
            "class": type(self).__name__,
            "system": self.system.name,
            "system_params": self.system.params,
            "hyperparameters": self.hyperparameters(),
            "h": float("nan") if self.h is None else float(self.h),
            "train_loss": self.train_loss,
            "val_loss": self.val_loss,
            "wall_time_s": self.wall_time_s,
            "info": {} if rec is None else rec.info,
            "liepoisson_version": lp.__version__,
        }
        groups: dict[str, Any] = {"weights": _checkpoint.array_leaves(self)}
        if rec is not None:
            groups["history"] = rec.history
        return attrs, groups

    def save(self, path: Any) -> None:
        """Write the model to an HDF5 file (hyperparameters as attributes, weights as
        datasets), atomically."""
        attrs, groups = self.file_content()
        _checkpoint.write(path, attrs, groups)

    @classmethod
    def load(cls, path: Any, system: Any):
        """Read a model (or the best weights of a training checkpoint) written by `save`/`fit`."""
        system = check_system(system)
        attrs, groups = _checkpoint.read(path)
        if attrs.get("class") != cls.__name__:
            raise ValueError(f"path {path!r} holds a {attrs.get('class')}, not a {cls.__name__}")
        if attrs["system"] != system.name or attrs["system_params"] != _checkpoint.jsonable(system.params):
            raise ValueError(
                f"system {system!r} does not match the file's {attrs['system']}"
                f"({attrs['system_params']})"
            )
        model = cls._skeleton(system, attrs["hyperparameters"])
        weights = groups["best"] if "best" in groups else groups["weights"]
        model = _checkpoint.replace_array_leaves(model, weights, f"path {path!r}")
        h = attrs["h"]
        record = None
        if "history" in groups:
            record = TrainingRecord(
                groups["history"], attrs["train_loss"], attrs["val_loss"], attrs["wall_time_s"],
                attrs.get("info", {}),
            )
        return replace(model, h=None if np.isnan(h) else float(h), record=record)

