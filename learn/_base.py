"""What every learned step map shares: it is an `integrators.AbstractStepMap` (rollouts, the
Poisson defect and the cost come from there), rebuilt from its hyperparameters, saved to and
loaded from HDF5."""

from __future__ import annotations

import abc
import os
from typing import TYPE_CHECKING, Any

import equinox as eqx
import jax
import numpy as np

import liepoisson as lp
from integrators import AbstractStepMap
from liepoisson._validation import check_system
from liepoisson.systems import AbstractPoissonSystem

from . import _checkpoint

if TYPE_CHECKING:  # typing.Self needs Python 3.11
    from typing_extensions import Self


class AbstractLearnedMap(AbstractStepMap):
    r"""A learned one-step map $y_{n+1} = \mathbb T(y_n)$ of a Poisson system: a pure pytree
    (architecture + weights). Train it with `learn.fit`, which returns a new map and a
    `TrainingRecord`.

    Final subclasses take `(system, *, key, h, **hyperparameters)` in their constructor and
    return those keyword arguments (JSON-serialisable) from `hyperparameters()`, so that a map
    is rebuilt from a file or re-initialised with a new key.
    """

    @abc.abstractmethod
    def hyperparameters(self) -> dict[str, Any]:
        """The constructor's keyword arguments besides `system`, `key` and `h` (JSON values)."""

    @property
    def n_parameters(self) -> int:
        """Number of trainable parameters (the floating-point array leaves)."""
        leaves = jax.tree_util.tree_leaves(eqx.filter(self, eqx.is_inexact_array))
        return int(sum(leaf.size for leaf in leaves))

    def reinitialised(self, key: int | jax.Array) -> Self:
        """The same architecture, scalings and `h` with fresh random weights from `key`."""
        return type(self)(self.system, key=key, h=self.h, **self.hyperparameters())

    # -- files -------------------------------------------------------------------------------
    def file_attributes(self) -> dict[str, Any]:
        """What identifies this map in a file: class, system, hyperparameters, `h`."""
        return {
            "class": type(self).__name__,
            "system": self.system.name,
            "system_params": self.system.params,
            "hyperparameters": self.hyperparameters(),
            "h": float("nan") if self.h is None else float(self.h),
            "liepoisson_version": lp.__version__,
        }

    def save(self, path: str | os.PathLike) -> None:
        """Write the map to an HDF5 file (hyperparameters as attributes, weights as datasets),
        atomically."""
        _checkpoint.write(path, self.file_attributes(), {"weights": _checkpoint.array_leaves(self)})

    @classmethod
    def load(cls, path: str | os.PathLike, system: AbstractPoissonSystem) -> Self:
        """Read a map written by `save` (or the best weights of an Adam checkpoint) for
        `system`, which must match the file's system."""
        system = check_system(system)
        attrs, groups = _checkpoint.read(path)
        check_file_matches(path, attrs, cls.__name__, system)
        h = attrs["h"]
        model = cls(system, key=0, h=None if np.isnan(h) else float(h), **attrs["hyperparameters"])
        weights = groups["best"] if "best" in groups else groups["weights"]
        return _checkpoint.replace_array_leaves(model, weights, f"path {os.fspath(path)!r}")


def check_file_matches(path: str | os.PathLike, attrs: dict[str, Any], class_name: str, system: AbstractPoissonSystem) -> None:
    """ValueError unless the file at `path` holds a `class_name` for `system`."""
    if attrs.get("class") != class_name:
        raise ValueError(f"path {os.fspath(path)!r} holds a {attrs.get('class')}, not a {class_name}")
    if attrs.get("system") != system.name or attrs.get("system_params") != _checkpoint.jsonable(system.params):
        raise ValueError(
            f"system {system!r} does not match the file {os.fspath(path)!r}, written for "
            f"{attrs.get('system')}({attrs.get('system_params')})"
        )
