r"""What every kind of observed trajectories shares (`Observations` of states,
`BodyObservations` of configurations and velocities): trajectories $j = 0, \dots, S-1$, each
observed at its own strictly increasing times $t_{j,0} < \dots < t_{j,n_j-1}$, of a system,
with metadata and optionally a group label each (a recording session, a day, an instrument);
their intervals, and the selection and seeded split by whole trajectories."""

from __future__ import annotations

import abc
from collections.abc import Sequence
from typing import Any

import numpy as np

from liepoisson.internals import positive_int

from ._validation_split import validation_split


class AbstractObservedTrajectories(abc.ABC):
    r"""Trajectories observed at their own times: `system`, `times` (one strictly increasing
    1-D array per trajectory), `metadata` (JSON values) and `groups` (one label per trajectory,
    `None` when not given: what a fit holds out whole and shares a gyroscope bias over). A
    subclass says what is measured at those times and how to keep a subset of its trajectories
    (`_pick`)."""

    system: Any
    times: tuple[np.ndarray, ...]
    metadata: dict[str, Any]
    groups: tuple[str | int, ...] | None

    def group_index(self) -> np.ndarray:
        """The group of each trajectory `(n_trajectories,)`, numbered 0, 1, ... in order of first
        appearance of its label; without `groups`, each trajectory its own group."""
        if self.groups is None:
            return np.arange(len(self))
        order: dict[str | int, int] = {}
        return np.array([order.setdefault(label, len(order)) for label in self.groups])

    @property
    def n_groups(self) -> int:
        """How many groups (`n_trajectories` without `groups`)."""
        return int(self.group_index().max()) + 1

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
    def select(self, indices: int | Sequence[int] | np.ndarray) -> AbstractObservedTrajectories:
        """The trajectories `indices` (an int or a non-empty sequence of ints), in that order."""
        idx = np.atleast_1d(np.asarray(indices))
        if idx.size == 0 or not np.issubdtype(idx.dtype, np.integer):
            raise TypeError(f"indices must be an int or a non-empty sequence of ints; got {indices!r}")
        if np.any((idx < -len(self)) | (idx >= len(self))):
            raise IndexError(f"indices {idx.tolist()} out of range for {len(self)} trajectories")
        return self._pick([int(i) for i in idx])

    def split(self, validation_fraction: float, seed: int = 0) -> tuple[AbstractObservedTrajectories, AbstractObservedTrajectories | None]:
        """`(training, validation)` by whole trajectories (random, seeded,
        `integrators.internals.validation_split`): a held-out trajectory shares no observation
        with the training ones. `None` for no validation."""
        seed = positive_int(seed, "seed", minimum=0)
        train, val = validation_split(len(self), validation_fraction, seed, "trajectory")
        if len(val) == 0:
            return self, None
        return self.select(train), self.select(val)

    @classmethod
    def concatenate(cls, datasets: Sequence[AbstractObservedTrajectories], groups: Sequence[str | int] | None = None
                    ) -> AbstractObservedTrajectories:
        """The trajectories of `datasets` (observations of one kind, of one system, measuring
        the same things), one after the other, e.g. recording sessions read one file each.
        `groups`: one label per data set, given to each of its trajectories (e.g. the session);
        `None` keeps each data set's own groups (all have them, or none). The metadata are the
        data sets' in a list, `{"concatenated": [...]}`."""
        datasets = list(datasets) if isinstance(datasets, (Sequence, np.ndarray)) else None
        if not datasets or not all(type(d) is cls for d in datasets):
            raise TypeError(f"datasets must be a non-empty sequence of {cls.__name__}; got "
                            f"{[type(d).__name__ for d in datasets] if datasets else datasets!r}")
        first = datasets[0]
        for k, d in enumerate(datasets[1:], 1):
            if d.system != first.system:
                raise ValueError(f"datasets[{k}] is of {d.system!r}, datasets[0] of {first.system!r}")
        if groups is not None:
            labels = check_groups(groups, len(datasets))
            per = [label for d, label in zip(datasets, labels) for _ in range(len(d))]
        elif all(d.groups is not None for d in datasets):
            per = [label for d in datasets for label in d.groups]
        elif any(d.groups is not None for d in datasets):
            raise ValueError("some datasets have groups and some do not: give groups= (one label per data set) or "
                             "label them all")
        else:
            per = None
        return cls._joined(datasets, per, {"concatenated": [d.metadata for d in datasets]})

    @classmethod
    @abc.abstractmethod
    def _joined(cls, datasets: list[AbstractObservedTrajectories], groups: list[str | int] | None,
                metadata: dict[str, Any]) -> AbstractObservedTrajectories:
        """The trajectories of `datasets` (checked: one kind and one system) in one data set."""

    def _picked_groups(self, indices: list[int]) -> list[str | int] | None:
        """The group labels of the trajectories `indices` (`None` without groups)."""
        return None if self.groups is None else [self.groups[i] for i in indices]

    @abc.abstractmethod
    def _pick(self, indices: list[int]) -> AbstractObservedTrajectories:
        """The same kind of observations holding only the trajectories `indices` (checked),
        their groups kept."""


def check_groups(groups: Any, n_trajectories: int) -> tuple[str | int, ...] | None:
    """`groups` as a tuple of labels, one per trajectory (`None` stays `None`): each label a
    string or an integer (JSON values, kept in files); `TypeError`/`ValueError` naming
    `groups` otherwise."""
    if groups is None:
        return None
    if isinstance(groups, (str, bytes)) or not isinstance(groups, (Sequence, np.ndarray)):
        raise TypeError(f"groups must be a sequence of labels (strings or integers), one per trajectory; got "
                        f"{groups!r}")
    labels = []
    for j, label in enumerate(groups):
        if isinstance(label, np.generic):
            label = label.item()
        if isinstance(label, bool) or not isinstance(label, (str, int)):
            raise TypeError(f"groups[{j}] must be a string or an integer (a session's name or number); got "
                            f"{label!r} of type {type(label).__name__}")
        labels.append(label)
    if len(labels) != n_trajectories:
        raise ValueError(f"groups must hold one label per trajectory ({n_trajectories}); got {len(labels)}")
    return tuple(labels)
