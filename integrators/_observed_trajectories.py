r"""What every kind of observed trajectories shares (`Observations` of states,
`BodyObservations` of configurations and velocities): trajectories $j = 0, \dots, S-1$, each
observed at its own strictly increasing times $t_{j,0} < \dots < t_{j,n_j-1}$, of a system,
with metadata; their intervals, and the selection and seeded split by whole trajectories."""

from __future__ import annotations

import abc
from collections.abc import Sequence
from typing import Any, TypeVar

import numpy as np

from liepoisson.internals import positive_int

from ._validation_split import validation_split

_Self = TypeVar("_Self", bound="AbstractObservedTrajectories")


class AbstractObservedTrajectories(abc.ABC):
    r"""Trajectories observed at their own times: `system`, `times` (one strictly increasing
    1-D array per trajectory) and `metadata` (JSON values). A subclass says what is measured at
    those times and how to keep a subset of its trajectories (`_pick`)."""

    system: Any
    times: tuple[np.ndarray, ...]
    metadata: dict[str, Any]

    # -- shape -----------------------------------------------------------------------------
    @property
    def n_trajectories(self) -> int:
        return len(self.times)

    def __len__(self) -> int:
        return len(self.times)

    @property
    def dim(self) -> int:
        return self.system.dim

    @property
    def n_observations(self) -> int:
        """All observation times of all trajectories."""
        return int(sum(t.size for t in self.times))

    def intervals(self) -> np.ndarray:
        r"""Every interval $t_{j,k+1} - t_{j,k}$ between consecutive observations of a
        trajectory, `(N,)`, trajectory after trajectory."""
        return np.concatenate([np.diff(t) for t in self.times])

    def is_regular(self, rtol: float = 1e-9) -> bool:
        """Whether every interval between observations is the same (to `rtol`)."""
        dt = self.intervals()
        return bool(np.all(np.abs(dt - dt[0]) <= rtol * dt[0]))

    # -- subsets ---------------------------------------------------------------------------
    def select(self: _Self, indices: int | Sequence[int] | np.ndarray) -> _Self:
        """The trajectories `indices` (an int or a non-empty sequence of ints), in that order."""
        idx = np.atleast_1d(np.asarray(indices))
        if idx.size == 0 or not np.issubdtype(idx.dtype, np.integer):
            raise TypeError(f"indices must be an int or a non-empty sequence of ints; got {indices!r}")
        if np.any((idx < -len(self)) | (idx >= len(self))):
            raise IndexError(f"indices {idx.tolist()} out of range for {len(self)} trajectories")
        return self._pick([int(i) for i in idx])

    def split(self: _Self, validation_fraction: float, seed: int = 0) -> tuple[_Self, _Self | None]:
        """`(training, validation)` by whole trajectories (random, seeded,
        `integrators.internals.validation_split`): a held-out trajectory shares no observation
        with the training ones. `None` for no validation."""
        seed = positive_int(seed, "seed", minimum=0)
        train, val = validation_split(len(self), validation_fraction, seed, "trajectory")
        if len(val) == 0:
            return self, None
        return self.select(train), self.select(val)

    @abc.abstractmethod
    def _pick(self: _Self, indices: list[int]) -> _Self:
        """The same kind of observations holding only the trajectories `indices` (checked)."""
