r"""`Trajectories`: sampled solutions $y(t_n)$, $t_n = n h$, with their provenance, and the
HDF5 format of the conventions ([Numbers and files][numbers-and-files])."""

from __future__ import annotations

import datetime
import json
import numbers
import os
from collections.abc import Sequence
from typing import Any

import numpy as np

import liepoisson
from liepoisson.internals import positive_float
from liepoisson.systems import AbstractPoissonSystem, system_for_file

from ._files import atomic_path, open_hdf5
from ._validation_split import validation_split

#: Version of the on-disk layout; `Trajectories.load` refuses any other.
FORMAT_VERSION = 1

# HDF5 attributes cannot hold None: these sentinels stand for "not recorded".
_NO_TOLERANCE = float("nan")
_NO_SEED = -1

_REQUIRED_ATTRS = (
    "system",
    "system_params",
    "h",
    "integrator",
    "tolerance",
    "seed",
    "created",
    "liepoisson_version",
    "format_version",
)


def _now() -> str:
    return datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")


def _check_seed(seed: Any) -> int | None:
    if seed is None:
        return None
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or int(seed) < 0:
        raise TypeError(f"seed must be a non-negative integer or None; got {seed!r}")
    return int(seed)


def write_attributes(f: Any, metadata: dict[str, Any]) -> None:
    """Write `Trajectories.metadata` as the file's attributes (conventions, [Numbers and
    files][numbers-and-files])."""
    f.attrs["system"] = metadata["system"]
    f.attrs["system_params"] = json.dumps(metadata["system_params"], sort_keys=True)
    f.attrs["h"] = metadata["h"]
    f.attrs["integrator"] = metadata["integrator"]
    f.attrs["tolerance"] = _NO_TOLERANCE if metadata["tolerance"] is None else metadata["tolerance"]
    f.attrs["seed"] = np.int64(_NO_SEED if metadata["seed"] is None else metadata["seed"])
    f.attrs["created"] = metadata["created"]
    f.attrs["liepoisson_version"] = metadata["liepoisson_version"]
    f.attrs["format_version"] = np.int64(FORMAT_VERSION)


def _integer_attribute(value: Any, key: str, path: str) -> int:
    """The integer attribute `key` of the file `path`, or a `ValueError` naming the file, the
    attribute and what it holds instead (a damaged file, or not one of liepoisson's)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Integral, np.integer)):
        shown = value.decode("utf-8", "replace") if isinstance(value, bytes) else value
        raise ValueError(  # noqa: TRY004 (a damaged file, not a wrong argument type)
            f"{path!r}: the attribute {key} is {shown!r}; expected an integer (the file is damaged or was not "
            "written by liepoisson)"
        )
    return int(value)


def _selection(select: Any, n_traj: int) -> Any:
    """`select` of `Trajectories.load` as an h5py index that keeps the array 3-D."""
    if select is None:
        return slice(None)
    if isinstance(select, numbers.Integral) and not isinstance(select, bool):
        i = int(select)
        if not -n_traj <= i < n_traj:
            raise IndexError(f"select={i} is out of range for a file of {n_traj} trajectories")
        return slice(i % n_traj, i % n_traj + 1)
    if isinstance(select, slice):
        if select.step is not None and select.step <= 0:
            raise ValueError(f"select must be a slice with a positive step; got {select!r}")
        if len(range(*select.indices(n_traj))) == 0:
            raise IndexError(f"select={select!r} selects none of the file's {n_traj} trajectories")
        return select
    idx = np.asarray(select) if isinstance(select, (Sequence, np.ndarray)) else None
    if idx is None or idx.ndim != 1 or idx.size == 0 or idx.dtype.kind not in "iu":
        raise TypeError(f"select must be an int, a slice or a non-empty sequence of ints; got {select!r}")
    if np.any(np.diff(idx) <= 0) or idx[0] < 0 or idx[-1] >= n_traj:
        raise IndexError(
            f"select must be increasing indices in [0, {n_traj}) for a file of {n_traj} trajectories; got {select!r}"
        )
    return idx


class Trajectories:
    r"""A data set of `n_traj` trajectories sampled at `n_steps + 1` equally spaced times.

    `states[i, n]` is $y_i(t_n)$ with $t_n = n h$ (`times[n]`). The learning code uses exactly
    `h`, `system`, `states`, `times`, `pairs()` and `split(...)`.

    **Arguments:**

    - `states`: `(n_traj, n_steps + 1, dim)` (a single `(n_steps + 1, dim)` trajectory is
      promoted to `n_traj = 1`), finite, stored as float64.
    - `h`: the sampling step, > 0.
    - `system`: the `AbstractPoissonSystem` that generated them (`dim` must match).
    - `times`: `(n_steps + 1,)`; default `h * arange(n_steps + 1)`.
    - `integrator`, `tolerance`, `seed`: provenance, written to the file.
    - `configurations` (keyword): the configurations $g_i(t_n)$ beside the momenta,
      `(n_traj, n_steps + 1, group.size)` in the representation of `system.group` (unit
      quaternions, scalar last, for `Rotations`; checked to lie on the group), or `None`.
    """

    def __init__(
        self,
        states: Any,
        h: float,
        system: AbstractPoissonSystem,
        *,
        times: Any = None,
        integrator: str = "heyoka-taylor",
        tolerance: float | None = None,
        seed: int | None = None,
        created: str | None = None,
        liepoisson_version: str | None = None,
        configurations: Any = None,
    ):
        if not isinstance(system, AbstractPoissonSystem):
            raise TypeError(f"system must be an AbstractPoissonSystem; got {type(system).__name__}")
        self.h = positive_float(h, "h")
        try:
            arr = np.array(states, dtype=np.float64)  # a copy: the data set owns its arrays
        except (TypeError, ValueError) as err:
            raise TypeError(f"states must be a real array (n_traj, n_steps+1, dim); got {type(states).__name__}") from err
        if arr.ndim == 2:
            arr = arr[None]
        if arr.ndim != 3 or arr.shape[-1] != system.dim or arr.shape[1] < 1:
            raise ValueError(
                f"states must have shape (n_traj, n_steps+1, {system.dim}) for {system!r}; "
                f"got shape {np.shape(states)}"
            )
        if not np.all(np.isfinite(arr)):
            bad = tuple(int(i) for i in np.argwhere(~np.isfinite(arr))[0])
            raise ValueError(f"states must be finite; found {arr[bad]} at index {bad}")
        if times is None:
            t = self.h * np.arange(arr.shape[1], dtype=np.float64)
        else:
            t = np.array(times, dtype=np.float64)
            if t.shape != (arr.shape[1],):
                raise ValueError(f"times must have shape ({arr.shape[1]},); got shape {t.shape}")
            if not np.all(np.isfinite(t)):
                raise ValueError("times must be finite")
        if not isinstance(integrator, str):
            raise TypeError(f"integrator must be a string; got {integrator!r}")
        if tolerance is not None:
            tolerance = float(tolerance)
            if not np.isfinite(tolerance):  # NaN is how a file says "none"
                tolerance = None
        self.states = arr
        self.times = t
        self.configurations = _configurations(configurations, system, arr.shape)
        self.system = system
        self.integrator = integrator
        self.tolerance = tolerance
        self.seed = _check_seed(seed)
        self.created = created or _now()
        self.liepoisson_version = liepoisson_version or liepoisson.__version__

    # -- shape ----------------------------------------------------------------------------
    @property
    def n_traj(self) -> int:
        return self.states.shape[0]

    @property
    def n_steps(self) -> int:
        return self.states.shape[1] - 1

    @property
    def dim(self) -> int:
        return self.states.shape[2]

    def __len__(self) -> int:
        return self.n_traj

    @property
    def metadata(self) -> dict[str, Any]:
        """Everything but the arrays (as written to the file)."""
        return {
            "system": self.system.name,
            "system_params": dict(self.system.params),
            "h": self.h,
            "integrator": self.integrator,
            "tolerance": self.tolerance,
            "seed": self.seed,
            "created": self.created,
            "liepoisson_version": self.liepoisson_version,
            "format_version": FORMAT_VERSION,
        }

    def __repr__(self) -> str:
        return (
            f"Trajectories({self.system!r}, n_traj={self.n_traj}, n_steps={self.n_steps}, "
            f"h={self.h}, integrator={self.integrator!r})"
        )

    def _like(self, states: np.ndarray, times: np.ndarray | None = None,
              configurations: np.ndarray | None = None) -> Trajectories:
        return Trajectories(
            states,
            self.h,
            self.system,
            times=self.times if times is None else times,
            integrator=self.integrator,
            tolerance=self.tolerance,
            seed=self.seed,
            created=self.created,
            liepoisson_version=self.liepoisson_version,
            configurations=configurations,
        )

    # -- learning views -------------------------------------------------------------------
    def pairs(self) -> tuple[np.ndarray, np.ndarray]:
        r"""All one-step pairs $(y_n, y_{n+1})$, each `(n_traj * n_steps, dim)`, trajectory-major."""
        return (
            self.states[:, :-1].reshape(-1, self.dim).copy(),
            self.states[:, 1:].reshape(-1, self.dim).copy(),
        )

    def split(
        self, validation_fraction: float = 0.2, seed: int = 0
    ) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
        """Seeded random split of `pairs()`: `((y0_train, y1_train), (y0_val, y1_val))`.

        `round(validation_fraction * n_pairs)` pairs, drawn without replacement by
        `numpy.random.default_rng(seed)`, go to validation; both parts keep their time order.
        """
        seed = _check_seed(seed)
        y0, y1 = self.pairs()
        train, val = validation_split(y0.shape[0], validation_fraction, seed, "pair")
        return (y0[train], y1[train]), (y0[val], y1[val])

    # -- subsets ----------------------------------------------------------------------------
    def select(self, indices: int | slice | Sequence[int] | np.ndarray) -> Trajectories:
        """The trajectories `indices` (int, slice, sequence or boolean mask); always 3-D."""
        if isinstance(indices, numbers.Integral) and not isinstance(indices, bool):
            i = int(indices)
            if not -self.n_traj <= i < self.n_traj:
                raise IndexError(f"trajectory index {i} out of range for n_traj={self.n_traj}")
            indices = [i]
        states = self.states[indices]
        if states.ndim != 3 or states.shape[0] == 0:
            raise IndexError(f"indices must select at least one trajectory; got {indices!r}")
        return self._like(states, configurations=None if self.configurations is None else self.configurations[indices])

    __getitem__ = select

    @staticmethod
    def concatenate(datasets: Sequence[Trajectories]) -> Trajectories:
        """Stack data sets of the same system, `h`, times and provenance along `n_traj`."""
        datasets = list(datasets)
        if not datasets or not all(isinstance(d, Trajectories) for d in datasets):
            raise TypeError("datasets must be a non-empty sequence of Trajectories")
        first = datasets[0]
        for k, d in enumerate(datasets[1:], 1):
            if (d.system.name, d.system.params) != (first.system.name, first.system.params):
                raise ValueError(f"datasets[{k}] is of {d.system!r}, datasets[0] of {first.system!r}")
            if d.h != first.h or not np.array_equal(d.times, first.times):
                raise ValueError(f"datasets[{k}] has other times (h={d.h}) than datasets[0] (h={first.h})")
            if (d.integrator, d.tolerance) != (first.integrator, first.tolerance):
                raise ValueError(
                    f"datasets[{k}] comes from {d.integrator} (tol {d.tolerance}), datasets[0] "
                    f"from {first.integrator} (tol {first.tolerance})"
                )
        with_g = [d.configurations is not None for d in datasets]
        if any(with_g) and not all(with_g):
            k = with_g.index(not with_g[0])
            raise ValueError(f"datasets[{k}] {'has' if with_g[k] else 'has no'} configurations, datasets[0] "
                             f"{'has' if with_g[0] else 'has none'}: concatenate data sets of the same kind")
        configurations = np.concatenate([d.configurations for d in datasets], axis=0) if with_g[0] else None
        return first._like(np.concatenate([d.states for d in datasets], axis=0), configurations=configurations)

    # -- HDF5 -------------------------------------------------------------------------------
    def save(self, path: str | os.PathLike) -> None:
        """Write to HDF5 (conventions, [Numbers and files][numbers-and-files]), atomically: a
        temporary file in the same directory is renamed over `path` only once complete, so a
        failure never leaves a half file nor clobbers an existing one."""
        import h5py

        with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
            f.create_dataset("trajectories", data=self.states)
            f.create_dataset("times", data=self.times)
            if self.configurations is not None:
                f.create_dataset("configurations", data=self.configurations)
            write_attributes(f, self.metadata)

    @classmethod
    def load(
        cls, path: str | os.PathLike, system: AbstractPoissonSystem | None = None, *, select: Any = None
    ) -> Trajectories:
        """Read a file written by `save`. The system is rebuilt from the file
        (`liepoisson.systems.from_name(name, params)`: catalogue systems and user
        `LiePoissonSystem`s, whose definition is saved) or, given `system`, checked to match the
        file (for a system class of your own, or a splitting that could not be saved). Raises
        `ValueError` naming the file for a file that is not HDF5, is truncated, lacks the
        datasets or attributes, has another `format_version`, or holds another system.

        `select` reads only some trajectories of a file too large for memory: an int, a
        `slice` or increasing indices (default: all)."""
        path = os.fspath(path)
        if select is not None and (
            isinstance(select, (str, bytes)) or not isinstance(select, (numbers.Integral, slice, Sequence, np.ndarray))
        ):
            raise TypeError(f"select must be an int, a slice or a non-empty sequence of ints; got {select!r}")
        f = open_hdf5(path, "a liepoisson trajectory data set (written by Trajectories.save)")
        try:
            with f:
                missing = [k for k in ("trajectories", "times") if k not in f]
                missing += [f"attribute {a!r}" for a in _REQUIRED_ATTRS if a not in f.attrs]
                if missing:
                    raise ValueError(
                        f"{path!r} is not a liepoisson trajectory file: missing {', '.join(missing)}"
                    )
                version = _integer_attribute(f.attrs["format_version"], "format_version", path)
                if version != FORMAT_VERSION:
                    raise ValueError(
                        f"{path!r} has format_version {version}; this liepoisson reads "
                        f"format_version {FORMAT_VERSION}"
                    )
                attrs = {a: f.attrs[a] for a in _REQUIRED_ATTRS}
                n_traj = f["trajectories"].shape[0] if f["trajectories"].ndim == 3 else 0
                states = f["trajectories"][_selection(select, n_traj)]
                times = f["times"][...]
                configurations = (f["configurations"][_selection(select, n_traj)] if "configurations" in f
                                  else None)
        except (ValueError, IndexError):
            raise
        except (OSError, KeyError, TypeError) as err:
            raise ValueError(f"{path!r} is damaged (truncated or corrupt HDF5 data): {err}") from err

        def text(v: Any) -> str:
            return v.decode() if isinstance(v, bytes) else str(v)

        try:
            params = json.loads(text(attrs["system_params"]))
        except ValueError as err:
            raise ValueError(f"{path!r}: the system parameters are not JSON: {err}") from err
        system = system_for_file(text(attrs["system"]), params, system, f"the file {path!r}")
        seed = _integer_attribute(attrs["seed"], "seed", path)
        try:
            return cls(
                states,
                float(attrs["h"]),
                system,
                times=times,
                integrator=text(attrs["integrator"]),
                tolerance=float(attrs["tolerance"]),
                seed=None if seed == _NO_SEED else seed,
                created=text(attrs["created"]),
                liepoisson_version=text(attrs["liepoisson_version"]),
                configurations=configurations,
            )
        except (ValueError, TypeError) as err:
            raise ValueError(f"{path!r} holds inconsistent data: {err}") from err


def _configurations(configurations: Any, system: AbstractPoissonSystem, shape: tuple[int, ...]) -> np.ndarray | None:
    """`configurations` checked against `system.group` and the states' `shape`, or None."""
    if configurations is None:
        return None
    group = getattr(system, "require_group", None)
    if group is None:
        raise ValueError(f"configurations need a Lie-Poisson system with a configuration group; {system!r} is not one")
    group = group()
    try:
        arr = np.array(configurations, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise TypeError(f"configurations must be a real array (n_traj, n_steps+1, {group.size}); "
                        f"got {type(configurations).__name__}") from err
    if arr.ndim == 2:
        arr = arr[None]
    if arr.shape != (*shape[:2], group.size):
        raise ValueError(f"configurations must have shape {(*shape[:2], group.size)} (the states' trajectories and "
                         f"times, then the {group.size} components of {group.name}); got shape {np.shape(configurations)}")
    return np.array(group.check(arr, "configurations"))
