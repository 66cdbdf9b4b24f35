"""What every learned step map shares: it is an `integrators.AbstractStepMap` (rollouts, the
Poisson defect and the cost come from there), rebuilt from its hyperparameters, saved to and
loaded from HDF5."""

from __future__ import annotations

import abc
import os
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import equinox as eqx
import jax
import numpy as np

import liepoisson as lp
from integrators import AbstractReconstructingStepMap, AbstractStepMap
from liepoisson.internals import check_system, jsonable
from liepoisson.systems import AbstractPoissonSystem, system_for_file

from .. import _files as _checkpoint
from .._solvers._adam import Adam
from .._solvers._stage import AbstractStage
from ._legacy import upgrade_attributes

if TYPE_CHECKING:  # typing.Self needs Python 3.11
    from typing_extensions import Self


class AbstractLearnedMap(AbstractStepMap):
    r"""A learned one-step map $y_{n+1} = \mathbb T(y_n)$ of a Poisson system: a pure pytree
    (architecture + weights). Train it with `learn.fit`, which returns a new map and a
    `TrainingRecord`; what differs between kinds of map is a method (`default_optimiser`,
    `normalised`: its fixed scalings) or a capability class (`AbstractCasimirConservingMap`,
    `AbstractWarmStartableMap`).

    Final subclasses return their architecture as JSON values from `hyperparameters()` and
    rebuild themselves from it in `from_hyperparameters`, so that a map is rebuilt from a file
    or re-initialised with a new key.
    """

    @abc.abstractmethod
    def hyperparameters(self) -> dict[str, Any]:
        """The architecture as JSON values (what `from_hyperparameters` takes)."""

    @classmethod
    def from_hyperparameters(cls, system: AbstractPoissonSystem, hyperparameters: dict[str, Any], *,
                             key: int | jax.Array = 0, h: float | None = None) -> Self:
        """The map of this architecture on `system` with fresh weights from `key` (default: the
        constructor's keyword arguments)."""
        return cls(system, key=key, h=h, **hyperparameters)

    def check_data(self, states: np.ndarray, what: str) -> None:
        """`ValueError` if the training `states` `(N, dim)` cannot be this map's states (every
        state can, unless a subclass says)."""

    def training_prediction(self, y0: jax.Array, y1: jax.Array) -> jax.Array:
        """What the state loss compares with $y_1$ for the pair $(y_0, y_1)$ (one sample each):
        `step(y0)`; a map with an implicit step returns an explicit residual form instead that
        equals $y_1$ exactly when the step carries $y_0$ to $y_1$ (`learn.Reversible`)."""
        return self.step(y0)

    def body_records_hint(self) -> str:
        """How to learn from `integrators.BodyObservations` with this map's kind when the map
        itself cannot (it is no `AbstractBodyMap`): a sentence `learn.BodyLoss` adds to its
        error; empty when there is no way."""
        return ""

    def default_optimiser(self) -> tuple[AbstractStage, ...]:
        """The optimiser stages `learn.fit` runs when given none: 100,000 epochs of Adam
        (learning rate 1e-3), the paper's for its MLPs."""
        return (Adam(),)

    def normalised(self, y0: np.ndarray, y1: np.ndarray, h: float, targets: np.ndarray | None = None) -> Self:
        """The map with its fixed input/output scalings set from training pairs (and the
        loss's `targets` where they are not states). Maps without scalings refuse."""
        raise ValueError(f"normalise=True sets the scalings of an MLP; a {type(self).__name__} has none")

    @property
    def n_parameters(self) -> int:
        """Number of trainable parameters (the floating-point array leaves)."""
        leaves = jax.tree_util.tree_leaves(eqx.filter(self, eqx.is_inexact_array))
        return int(sum(leaf.size for leaf in leaves))

    def reinitialised(self, key: int | jax.Array) -> Self:
        """The same architecture, scalings and `h` with fresh random weights from `key`."""
        return type(self).from_hyperparameters(self.system, self.hyperparameters(), key=key, h=self.h)

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
        atomically. A map whose parts the library cannot rebuild from a file (a network kind or
        splitting method of your own) is refused before anything is written."""
        attrs = self.file_attributes()
        try:
            type(self).from_hyperparameters(self.system, jsonable(attrs["hyperparameters"]), key=0,
                                            h=self.h)
        except (KeyError, TypeError, ValueError) as err:
            raise ValueError(
                f"this {type(self).__name__} cannot be saved: a file records the architecture by name, and "
                f"{type(err).__name__}: {err}. Save its weights yourself (eqx.tree_serialise_leaves) or build it "
                "from the library's networks and splitting methods"
            ) from err
        _checkpoint.write(path, attrs, {"weights": _checkpoint.array_leaves(self)})

    @classmethod
    def load(cls, path: str | os.PathLike, system: AbstractPoissonSystem | None = None) -> Self:
        """Read a map written by `save` (or the best weights of an Adam checkpoint). The
        system is rebuilt from the file (catalogue systems and user `LiePoissonSystem`s) or,
        given `system`, checked to match it (same algebra, Hamiltonian values at the saved
        probe points for a user system; same parameters otherwise). Files of format version 1
        (before learned maps were composed) are read into today's classes."""
        attrs, groups = _checkpoint.read(path)
        return cls.from_file(path, upgrade_attributes(attrs, f"path {os.fspath(path)!r}"), groups, system)

    @classmethod
    def from_file(cls, path: str | os.PathLike, attrs: dict[str, Any], groups: dict[str, Any],
                  system: AbstractPoissonSystem | None = None) -> Self:
        """The map of a file already read (`attrs` upgraded to today's format, `groups`): what
        `load` does after reading, for a caller that read the file to find its class."""
        if attrs.get("upgraded_from") is not None and attrs["upgraded_from"] != attrs.get("class") \
                and attrs["upgraded_from"] == cls.__name__:
            raise ValueError(
                f"path {os.fspath(path)!r} holds a version-1 {attrs['upgraded_from']} with flags that are now "
                f"the wrapper learn.{attrs['class']}: read it with learn.{attrs['class']}.load (or learn.load)"
            )
        system = check_file_matches(path, attrs, cls.__name__, system)
        try:
            h = float(attrs["h"])
            model = cls.from_hyperparameters(system, attrs["hyperparameters"], key=0, h=None if np.isnan(h) else h)
            weights = groups["best"] if "best" in groups else groups["weights"]
        except (KeyError, TypeError, ValueError) as err:
            raise ValueError(
                f"path {os.fspath(path)!r} is not a complete {cls.__name__} file ({type(err).__name__}: {err})"
            ) from err
        return _checkpoint.replace_array_leaves(model, weights, f"path {os.fspath(path)!r}")


class AbstractCasimirConservingMap(AbstractLearnedMap):
    """A learned map whose every step moves on the Casimir leaf of its start (a coadjoint
    orbit for a Lie-Poisson system): `learn.fit` refuses data pairs whose Casimirs differ,
    which no such map can connect."""


class AbstractWarmStartableMap(AbstractLearnedMap):
    """A learned map that offers a simpler map to fit first (`learn.WarmStart`)."""

    @abc.abstractmethod
    def warm_start(self) -> tuple[AbstractLearnedMap, Callable[[AbstractLearnedMap, np.ndarray], Self]] | None:
        """`(simpler, mapped)`: a simpler map to fit first and `mapped(fitted_simpler, states)`,
        this map started from it (`states` `(N, dim)`: the training states, e.g. to scale the
        mapping); `None` if this map is already the simpler one."""


class AbstractBodyMap(AbstractLearnedMap, AbstractReconstructingStepMap):
    r"""A learned map of a Hamiltonian $\widetilde H$ that carries the configuration: its
    body velocity $\xi = \nabla\widetilde H(\mu)$ is what a gyroscope reads, so it can be fitted
    on configurations and velocities with the momenta latent (`learn.BodyLoss`)."""

    @abc.abstractmethod
    def body_velocity(self, y: jax.Array) -> jax.Array:
        r"""$\xi = \nabla\widetilde H(y)$ for one state `(dim,)`."""


class AbstractOneFlowMap(AbstractLearnedMap):
    r"""A learned map whose step is one exact step $\mathbb T(h, \alpha(y))\,y$ of a
    parametrisation, at the parameters $\alpha(y)$ of a network (an LPNet): each data pair
    determines the parameters of its step, so the map can be fitted on them
    (`learn.AlphaLoss`)."""

    @abc.abstractmethod
    def alpha(self, y: jax.Array) -> jax.Array:
        r"""$\alpha(y)$ `(n_params,)` for one state."""

    @property
    @abc.abstractmethod
    def output_scales(self) -> jax.Array:
        """The scale of each parameter the network outputs (1 without scalings)."""

    @abc.abstractmethod
    def params_from_pair(self, y0: np.ndarray, y1: np.ndarray, h: float) -> np.ndarray:
        """The parameters `(N, n_params)` of the exact step that carries each `y0` to `y1`."""


def check_learned_map(value: Any, name: str = "model must be") -> AbstractLearnedMap:
    """`value` if it is a learned map, else `TypeError` saying what `name` (e.g. "model must
    be") should have been."""
    if not isinstance(value, AbstractLearnedMap):
        raise TypeError(f"{name} a learned map (learn.LPNet, Reversible, GLPNet, MLPBaseline); "
                        f"got {type(value).__name__}")
    return value


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
