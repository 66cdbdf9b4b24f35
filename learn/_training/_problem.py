"""The training problem of a learned map: what a loss builds from a map and data, and what the
solvers need of the map (fresh weights, its warm start, how its checkpoint is identified)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import numpy as np

from liepoisson.internals import jsonable
from liepoisson.systems import check_system_matches

from .. import _files
from .._models._base import AbstractLearnedMap, AbstractWarmStartableMap
from .._models._legacy import upgrade_attributes
from .._solvers._problem import AbstractObjective, AbstractProblem


@dataclasses.dataclass(frozen=True)
class Description:
    """What a fit's record and checkpoints say about its objective and data: the loss's name,
    the step `h`, the training and held-out sample counts (pairs, or observations), the split
    (`seed`, `validation_fraction`), `normalise`, and for observations `max_step` and the
    `substeps` per interval (the most of any interval: body observations take each
    interval's own count)."""

    loss: str
    h: float
    n_train: int
    n_val: int
    seed: int
    validation_fraction: float
    normalise: bool = False
    max_step: float | None = None
    substeps: int | None = None


@dataclasses.dataclass(frozen=True)
class MapProblem(AbstractProblem):
    """Train a learned map `y0` on `train` (pairs: `learn.Pairs`)."""

    objective: AbstractObjective
    y0: Any
    train: Any
    validation: Any | None
    description: Description

    @property
    def name(self) -> str:
        return type(self.map(self.y0)).__name__

    def map(self, y: Any) -> AbstractLearnedMap:
        """The learned map of a solution `y`."""
        return y

    def with_start(self, y0: Any) -> MapProblem:
        return dataclasses.replace(self, y0=y0)

    def step_size(self, y: Any) -> Any:
        return y.h

    def reinitialised(self, key: jax.Array) -> Any:
        return self.y0.reinitialised(key)

    def warm_start(self) -> tuple[MapProblem, Callable[[Any], Any]] | None:
        warm = _warm_start(self.y0)
        if warm is None:
            return None
        simpler, mapped = warm
        return self.with_start(simpler), lambda y: mapped(y, self.train.inputs)

    def file_attributes(self) -> dict[str, Any]:
        return self.map(self.y0).file_attributes()

    def read_checkpoint(self, path: str) -> tuple[dict[str, Any], dict[str, Any]]:
        model = self.map(self.y0)
        attrs, groups = _files.read_checkpoint(path, type(model).__name__, upgrade_attributes)
        try:
            check_system_matches(model.system, attrs.get("system"), attrs.get("system_params"), f"checkpoint {path!r}")
        except ValueError as err:
            raise ValueError(f"cannot resume: {err}") from None
        if attrs["hyperparameters"] != jsonable(model.hyperparameters()):
            raise ValueError(
                f"checkpoint {path!r} was written for a model with hyperparameters "
                f"{attrs['hyperparameters']}; this model has {model.hyperparameters()}"
            )
        return attrs, groups


def _warm_start(model: AbstractLearnedMap):
    """`model.warm_start()`; `ValueError` for a map that offers none."""
    if not isinstance(model, AbstractWarmStartableMap):
        raise ValueError(f"learn.WarmStart: a {type(model).__name__} has no warm start (a G-LPNet's identity warm "  # noqa: TRY004
                         "start); fit it without learn.WarmStart")
    return model.warm_start()


class Fitted(eqx.Module):
    """What is trained on observations: the map and, with errors in variables, the fitted
    start of every training segment `(S, dim)` (`None`: starts as observed); `shared`: unknowns
    of the observations that several segments share, e.g. a gyroscope bias per group of
    trajectories `(G, dim)` (`None`: none)."""

    model: Any
    starts: jax.Array | None
    shared: jax.Array | None = None


@dataclasses.dataclass(frozen=True)
class FittedProblem(MapProblem):
    """Train a map and the fitted starts (`Fitted`) on segments of observations
    (`learn.Segments`); the step size varies per interval, so none is traced."""

    def map(self, y: Fitted) -> AbstractLearnedMap:
        """The fitted map, at the step `h` of the description (none while fitting: every
        interval runs at its own)."""
        return eqx.tree_at(lambda m: m.h, y.model, self.description.h, is_leaf=lambda v: v is None)

    def step_size(self, y: Any) -> Any:
        return None

    def file_attributes(self) -> dict[str, Any]:
        raise ValueError("checkpoint= is not supported for observations yet (a checkpoint holds a map's weights, "
                         "not its fitted starts); fit without it")

    def reinitialised(self, key: jax.Array) -> Fitted:
        return Fitted(self.y0.model.reinitialised(key), self.y0.starts, self.y0.shared)

    def warm_start(self) -> tuple[FittedProblem, Callable[[Fitted], Fitted]] | None:
        warm = _warm_start(self.y0.model)
        if warm is None:
            return None
        simpler, mapped = warm
        # the map's warm start is scaled by the observed states
        present = np.asarray(self.train.mask).reshape(-1) > 0
        states = self.train.states.reshape(-1, self.train.states.shape[-1])[present]
        return (self.with_start(Fitted(simpler, self.y0.starts, self.y0.shared)),
                lambda y: Fitted(mapped(y.model, states), y.starts, y.shared))
