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
from liepoisson.systems import AbstractPoissonSystem, system_for_file

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

    def training_prediction(self, y0: jax.Array, y1: jax.Array) -> jax.Array:
        """What the state loss compares with $y_1$ for the pair $(y_0, y_1)$ (one sample each):
        `step(y0)`; a map with an implicit step returns an explicit residual form instead that
        equals $y_1$ exactly when the step carries $y_0$ to $y_1$ (a reversible `LPNet`)."""
        return self.step(y0)

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
    def load(cls, path: str | os.PathLike, system: AbstractPoissonSystem | None = None) -> Self:
        """Read a map written by `save` (or the best weights of an Adam checkpoint). The
        system is rebuilt from the file (catalogue systems and user `LiePoissonSystem`s) or,
        given `system`, checked to match it (same algebra, Hamiltonian values at the saved
        probe points for a user system; same parameters otherwise)."""
        attrs, groups = _checkpoint.read(path)
        system = check_file_matches(path, attrs, cls.__name__, system)
        try:
            h = float(attrs["h"])
            model = cls(system, key=0, h=None if np.isnan(h) else h, **attrs["hyperparameters"])
            weights = groups["best"] if "best" in groups else groups["weights"]
        except (KeyError, TypeError, ValueError) as err:
            raise ValueError(
                f"path {os.fspath(path)!r} is not a complete {cls.__name__} file ({type(err).__name__}: {err})"
            ) from err
        return _checkpoint.replace_array_leaves(model, weights, f"path {os.fspath(path)!r}")


def check_file_matches(
    path: str | os.PathLike, attrs: dict[str, Any], class_name: str, system: AbstractPoissonSystem | None
) -> AbstractPoissonSystem:
    """The system of the file at `path`, which must hold a `class_name`: rebuilt from the file
    when `system` is None, else `system` checked to match it. `ValueError` otherwise."""
    if attrs.get("class") != class_name:
        raise ValueError(f"path {os.fspath(path)!r} holds a {attrs.get('class')}, not a {class_name}")
    if system is not None:
        system = check_system(system)
    name, params = attrs.get("system"), attrs.get("system_params")
    if not isinstance(name, str) or not isinstance(params, dict):
        raise ValueError(f"path {os.fspath(path)!r} does not record its system (attributes 'system', 'system_params')")  # noqa: TRY004 (a damaged file)
    return system_for_file(name, params, system, f"the file {os.fspath(path)!r}")
