"""What a rollout does when a trajectory leaves the finite range: raise `RolloutDivergedError`
naming where (`RaiseIfNonfinite`) or return the states with their non-finite tail
(`ReturnNonfinite`)."""

from __future__ import annotations

import abc
from typing import Any

import jax
import numpy as np

from ._choices import AbstractChoice, by_name


class RolloutDivergedError(FloatingPointError):
    """A rollout left the finite range. Attributes: `trajectory` (index into `y0`), `step`
    (the first saved step that is not finite), `last_finite_step`, `state` (the state there)
    and `states` (the whole output, with its non-finite tail)."""

    def __init__(self, message: str, *, trajectory: int, step: int, last_finite_step: int, state: np.ndarray,
                 states: np.ndarray):
        super().__init__(message)
        self.trajectory, self.step, self.last_finite_step = trajectory, step, last_finite_step
        self.state, self.states = state, states


class AbstractNonfinitePolicy(AbstractChoice):
    """What `AbstractStepMap.rollout` does with a trajectory that left the finite range; `name`
    is the string `rollout(nonfinite=...)` also accepts."""

    @abc.abstractmethod
    def check(self, step_map: Any, out: jax.Array, save_every: int) -> None:
        """Act on the rollout `out` `(N, T, dim)` of `step_map`, saved every `save_every` steps."""


class ReturnNonfinite(AbstractNonfinitePolicy):
    """Return the states with their non-finite tail (`integrators.diagnostics` and
    `rollout_figures` report where they stop being finite)."""

    name = "return"

    def check(self, step_map: Any, out: jax.Array, save_every: int) -> None:
        pass


class RaiseIfNonfinite(AbstractNonfinitePolicy):
    """Raise `RolloutDivergedError` for the earliest non-finite saved state (ties: the lowest
    trajectory index), naming the trajectory, the steps between which it diverged, its last
    finite state and the map's `divergence_hint`."""

    name = "raise"

    def check(self, step_map: Any, out: jax.Array, save_every: int) -> None:
        _raise_if_nonfinite(step_map, out, save_every)


#: The policies by the names `rollout(nonfinite=...)` accepts.
NONFINITE_POLICIES: dict[str, AbstractNonfinitePolicy] = {p.name: p for p in (RaiseIfNonfinite(), ReturnNonfinite())}


def nonfinite_policy(nonfinite: str | AbstractNonfinitePolicy) -> AbstractNonfinitePolicy:
    """`nonfinite` as an `AbstractNonfinitePolicy`: an instance, or `"raise"` or `"return"`."""
    return by_name(nonfinite, NONFINITE_POLICIES, AbstractNonfinitePolicy, "nonfinite")


def _raise_if_nonfinite(step_map: Any, out: jax.Array, save_every: int) -> None:
    y = np.asarray(out)
    finite = np.isfinite(y).all(axis=-1)
    if finite.all():
        return
    first = np.where(finite.all(axis=1), y.shape[1], np.argmin(finite, axis=1))
    i = int(np.argmin(first))
    k = int(first[i])
    last = y[i, k - 1]
    when = f"at step {k}" if save_every == 1 else f"between steps {(k - 1) * save_every} and {k * save_every}"
    raise RolloutDivergedError(
        f"{step_map.label} (h={step_map.h:g}) diverged: trajectory {i} became non-finite "
        f"{when}; its last finite state (step {(k - 1) * save_every}) is {_short(last)}. "
        f"{step_map.divergence_hint}; pass nonfinite='return' to get the states with their non-finite tail",
        trajectory=i, step=k * save_every, last_finite_step=(k - 1) * save_every, state=last, states=y,
    )


def _short(state: np.ndarray, shown: int = 12) -> str:
    """A state for a message: all of a small one, the first `shown` components of a large one
    (the `RolloutDivergedError` carries the whole state)."""
    if state.size <= shown:
        return str(np.round(state, 6).tolist())
    return f"{str(np.round(state[:shown], 6).tolist())[:-1]}, ... ({state.size} components; the error's .state has all)]"
