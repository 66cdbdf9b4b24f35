r"""Observed trajectories: states measured at their own (uneven) times, with noise, of a system
known by its Poisson structure; and `observe`, which makes such data from heyoka ground truth
for studies (noise of a given size and law, uneven sampling, dropped samples, all seeded)."""

from __future__ import annotations

import io
import json
import numbers
import os
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

import liepoisson
from liepoisson.internals import fraction, jsonable, positive_float, positive_int
from liepoisson.systems import AbstractPoissonSystem, system_for_file

from ._files import atomic_path, open_hdf5
from ._ground_truth import taylor_integrator
from ._noise import AbstractNoiseLaw, noise_law, noise_level
from ._observed_trajectories import AbstractObservedTrajectories, check_groups

FORMAT = "liepoisson-observations"
FORMAT_VERSION = 1


def _ragged_where(value: Any, name: str) -> str:
    """Where the nested sequence `value` stops being rectangular: the first entry whose shape
    differs from that of the entry before it."""
    shapes = []
    for j, item in enumerate(value):
        try:
            shapes.append(np.shape(item))
        except ValueError:
            return _ragged_where(item, f"{name}[{j}]")
    for j in range(1, len(shapes)):
        if shapes[j] != shapes[j - 1]:
            return f"{name}[{j}] has shape {shapes[j]} and {name}[{j - 1}] shape {shapes[j - 1]}"
    return f"{name} is not rectangular"


def _real_array(value: Any, name: str) -> np.ndarray:
    """`value` as a float64 array, or a `TypeError`/`ValueError` naming `name`: nothing
    (`None`), text, booleans and complex numbers are refused (never converted, nor their
    imaginary part dropped), and so is a ragged nesting of lists."""
    if value is None:
        raise TypeError(f"{name} is required: a real array or a list of arrays; got None")
    if isinstance(value, (str, bytes)):
        raise TypeError(f"{name} must be a real array or a list of arrays; got {type(value).__name__} {value!r}")
    try:
        arr = np.asarray(value)
    except ValueError:
        raise ValueError(f"{name} is ragged: {_ragged_where(value, name)}") from None
    if arr.dtype == object:  # e.g. a list holding None or other objects: convert element by element
        try:
            arr = np.asarray(arr.tolist(), dtype=np.float64)
        except (TypeError, ValueError):
            bad = next((v for v in arr.flat if not isinstance(v, numbers.Real) or isinstance(v, bool)), arr.flat[0])
            raise TypeError(f"{name} must hold real numbers; got {type(bad).__name__} {bad!r} in it") from None
    if arr.dtype.kind == "c":
        nonreal = np.argwhere(np.imag(arr) != 0)
        k = tuple(int(i) for i in nonreal[0]) if nonreal.size else (0,) * arr.ndim
        where = f"{name}[{', '.join(map(str, k))}]" if k else name
        raise TypeError(f"{name} must be real; got complex values ({where} = {arr[k]}); the imaginary part is not "
                        "dropped silently: pass the real part if that is what you mean")
    if arr.dtype.kind not in "iuf":
        raise TypeError(f"{name} must hold real numbers; got {_values(arr)}")
    return arr.astype(np.float64)


def _values(arr: np.ndarray) -> str:
    """What `arr` holds instead of numbers, for error messages: `text values such as 'a'`."""
    kind = {"U": "text", "S": "text", "b": "boolean", "c": "complex", "O": "object"}.get(arr.dtype.kind, arr.dtype.name)
    if not arr.size:
        return f"{kind} values"
    sample = arr.flat[0]
    return f"{kind} values such as {(sample.item() if isinstance(sample, np.generic) else sample)!r}"


def _per_trajectory(value: Any, name: str) -> np.ndarray | list[np.ndarray]:
    """`value` as one float64 array, or, for nested lists of different lengths (trajectories
    of their own lengths), as a list of float64 arrays, one per entry."""
    if value is None or isinstance(value, np.ndarray) or not isinstance(value, Sequence) \
            or isinstance(value, (str, bytes)):
        return _real_array(value, name)
    try:
        np.asarray(value)
    except ValueError:
        return [_real_array(item, f"{name}[{j}]") for j, item in enumerate(value)]
    return _real_array(value, name)


def rms_size(states: Sequence[np.ndarray]) -> float:
    r"""$\sqrt{\operatorname{mean}_k |y_k|^2}$ over the rows of every array `(n_k, dim)` of
    `states`: the size noise is measured against."""
    return float(np.sqrt(np.mean(np.concatenate([np.sum(y**2, axis=1) for y in states]))))


def times_per_trajectory(times: Any, n: int) -> list[np.ndarray]:
    """One array of times per trajectory (`n` of them): a single 1-D array (even an empty
    one) is shared by all."""
    ts = _per_trajectory(times, "times")
    if isinstance(ts, list):
        return ts
    return [ts] * n if ts.ndim <= 1 else list(ts)


def check_times(t: np.ndarray, name: str) -> np.ndarray:
    """`t` 1-D, finite and strictly increasing, or a `ValueError` naming the first entry that
    is not."""
    if t.ndim != 1:
        raise ValueError(f"{name} must be 1-D (one time per observation); got shape {t.shape}")
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise ValueError(f"{name} must be finite; {name}[{bad[0]}] = {t[bad[0]]}")
    steps = np.diff(t)
    bad = np.flatnonzero(steps <= 0)
    if bad.size:
        k = int(bad[0]) + 1
        what = "repeated" if steps[k - 1] == 0 else "unsorted"
        raise ValueError(
            f"{name} must be strictly increasing; {name}[{k}] = {t[k]} {'=' if what == 'repeated' else '<'} "
            f"{name}[{k - 1}] = {t[k - 1]} ({what} time: sort the observations by time and merge repeated ones)"
        )
    return t


#: Two systems have the same Poisson structure when their Poisson tensors agree to this
#: fraction of the largest entry, and their Casimir gradients span the same space (singular
#: values below this fraction of the largest are zero), at the states compared.
STRUCTURE_RTOL = 1e-9


def poisson_structure_difference(a: AbstractPoissonSystem, b: AbstractPoissonSystem) -> str | None:
    r"""How the Poisson structures of `a` and `b` differ, or `None` if they are the same: the
    same bracket $\mathbb B(y)$ and Casimirs whose gradients span the same space (the same
    leaves, whatever their normalisation). Only the structure is compared, not the
    Hamiltonians: a rigid body of other inertia has the same structure.

    Equal systems (`==`) are the same. Otherwise $\mathbb B$ is compared at the basis vectors
    $e_d$ (for a Lie-Poisson system, linear in $y$, that is comparing the structure constants
    and sign: $\mathbb B(e_d)_{ab} = \mp C_{abd}$) and at four seeded random states, and the
    Casimir gradients at the random states, to `STRUCTURE_RTOL`."""
    if a is b or a == b:
        return None
    if a.dim != b.dim:
        return f"the dimensions differ ({a.dim} and {b.dim})"
    from liepoisson.systems import LiePoissonDAlembert

    for x, y in ((a, b), (b, a)):
        if isinstance(x, LiePoissonDAlembert) and not (
                isinstance(y, LiePoissonDAlembert) and np.array_equal(x.constraints, y.constraints)
                and poisson_structure_difference(x.system, y.system) is None):
            return (f"{x!r} is nonholonomic: its motion (the constraint's reaction force) is not that of "
                    f"{y!r}'s bracket")
    random = np.random.default_rng(0).standard_normal((4, a.dim))
    ys = np.concatenate([np.eye(a.dim), random])
    Ba, Bb = np.asarray(a.poisson_tensor(ys)), np.asarray(b.poisson_tensor(ys))
    scale = max(float(np.nanmax(np.abs(Ba), initial=0.0)), float(np.nanmax(np.abs(Bb), initial=0.0)), 1e-300)
    same = np.isclose(Ba, Bb, rtol=0.0, atol=STRUCTURE_RTOL * scale, equal_nan=True)
    if not np.all(same):
        k, i, j = (int(v) for v in np.argwhere(~same)[0])
        return (f"their Poisson tensors differ: at y = {np.round(ys[k], 4).tolist()}, B[{i}, {j}] is {Ba[k, i, j]:.6g} "
                f"for {a!r} and {Bb[k, i, j]:.6g} for {b!r}")
    if a.n_casimirs != b.n_casimirs:
        return f"their brackets agree but {a!r} declares {a.n_casimirs} Casimir(s) and {b!r} {b.n_casimirs}"
    if a.n_casimirs:
        Ga = np.asarray(a.casimir_gradients(random)).reshape(len(random), a.n_casimirs, a.dim)
        Gb = np.asarray(b.casimir_gradients(random)).reshape(len(random), b.n_casimirs, b.dim)
        for y, ga, gb in zip(random, Ga, Gb):
            both = np.concatenate([ga, gb])
            cut = STRUCTURE_RTOL * max(float(np.linalg.norm(both, 2)), 1e-300)
            if not _rank(ga, cut) == _rank(gb, cut) == _rank(both, cut):
                return (f"their Casimirs differ: at y = {np.round(y, 4).tolist()} the gradients of one are not "
                        "combinations of the other's (other symplectic leaves)")
    return None


def _rank(m: np.ndarray, cut: float) -> int:
    """The number of singular values of `m` above `cut`."""
    return int(np.sum(np.linalg.svd(m, compute_uv=False) > cut))


def _trajectories_of(ys: np.ndarray | list[np.ndarray], dim: int) -> list[np.ndarray]:
    """The trajectories of `states`: an `(n, dim)` array is one, an `(n_traj, n, dim)` array
    or a list of `(n_j, dim)` arrays several; a list of rows of different lengths is refused."""
    if isinstance(ys, np.ndarray):
        if ys.ndim == 2:
            return [ys]  # one trajectory (n, dim)
        if ys.ndim == 3 or (ys.ndim == 1 and ys.size == 0):
            if not len(ys):
                raise ValueError("states must hold at least one trajectory; got none")
            return list(ys)
        raise ValueError(f"states must be one trajectory (n_observations, {dim}), an array (n_trajectories, "
                         f"n_observations, {dim}) or a list of (n_j, {dim}) arrays; got shape {ys.shape}")
    if ys and all(y.ndim == 1 for y in ys):  # rows of one trajectory, of different lengths
        j = next((j for j, y in enumerate(ys) if y.shape != ys[0].shape), 0)
        raise ValueError(f"states is ragged: its rows are observations of one trajectory (n_observations, {dim}) "
                         f"but states[{j}] has {ys[j].size} component(s) and states[0] {ys[0].size}; every state has "
                         f"{dim} components (missing values are not masked: drop that observation and its time)")
    return ys


class Observations(AbstractObservedTrajectories):
    r"""Trajectories observed at their own times: trajectory $j$ is the states
    $y_j(t_{j,0}), \dots, y_j(t_{j,n_j-1})$ at strictly increasing times, uneven and different
    per trajectory, as measured (with noise: observations need not lie on one Casimir leaf).

    Only the Poisson structure of `system` is used by learning (its bracket and Casimirs); its
    Hamiltonian may be unknown (a `liepoisson.LiePoissonSystem` of an algebra with any
    Hamiltonian, or a catalogue system whose Hamiltonian is not used).

    **Arguments:**

    - `system`: an `AbstractPoissonSystem`.
    - `times`: one array of times per trajectory (a list of 1-D arrays, or an `(n_traj, n)`
      array); a single 1-D array is shared by every trajectory.
    - `states`: one `(n_j, dim)` array per trajectory (a list, or an `(n_traj, n, dim)` array).
    - `metadata`: JSON values kept with the data and in its file (how it was made).
    - `groups`: one label (a string or an integer) per trajectory, e.g. its recording session,
      kept in its file; `None` (default): none.

    Missing values are refused, not masked: drop the observation (its time with it).
    """

    def __init__(self, system: AbstractPoissonSystem, times: Any, states: Any, *,
                 metadata: dict[str, Any] | None = None, groups: Any = None):
        if not isinstance(system, AbstractPoissonSystem):
            raise TypeError(f"system must be an AbstractPoissonSystem; got {type(system).__name__}")
        dim = system.dim
        ys = _trajectories_of(_per_trajectory(states, "states"), dim)
        ts = times_per_trajectory(times, len(ys))
        if len(ts) != len(ys):
            raise ValueError(f"times has {len(ts)} trajectories and states {len(ys)}; give one time array per "
                             "trajectory (or one 1-D array shared by all)")
        for j, (t, y) in enumerate(zip(ts, ys)):
            if y.ndim != 2 or y.shape[1] != dim:
                raise ValueError(f"states[{j}] must have shape (n_observations, {dim}) for {system!r}; "
                                 f"got shape {y.shape}")
            if y.shape[0] < 2:
                raise ValueError(f"trajectory {j} has {y.shape[0]} observation(s); a trajectory needs at least two "
                                 "(a motion between two times): drop it or add observations")
            bad = np.argwhere(~np.isfinite(y))
            if bad.size:
                k, i = (int(v) for v in bad[0])
                raise ValueError(
                    f"states[{j}] must be finite; observation {k} (t = {t[k] if t.ndim == 1 and k < t.size else '?'}), "
                    f"component {i} is {y[k, i]}. Missing values are not masked: drop that observation and its time"
                )
            check_times(t, f"times[{j}]")
            if t.shape[0] < 2:
                raise ValueError(f"times[{j}] has {t.shape[0]} time(s); a trajectory needs at least 2 observation "
                                 f"times (a motion between two times), got {t.shape[0]}")
            if t.shape[0] != y.shape[0]:
                raise ValueError(f"times[{j}] has {t.shape[0]} entries and states[{j}] {y.shape[0]} observations; "
                                 "give one time per observation")
        self.system = system
        self.times: tuple[np.ndarray, ...] = tuple(t.copy() for t in ts)
        self.states: tuple[np.ndarray, ...] = tuple(y.copy() for y in ys)
        self.groups = check_groups(groups, len(ys))
        try:
            self.metadata: dict[str, Any] = jsonable(dict(metadata or {}))
        except (TypeError, ValueError) as err:
            raise TypeError(f"metadata must be a dict of JSON values; got {metadata!r}") from err

    def __repr__(self) -> str:
        steps = self.intervals()
        return (f"Observations({self.system!r}, {self.n_trajectories} trajectories, {self.n_observations} "
                f"observations, steps {steps.min():.3g}..{steps.max():.3g})")

    def pairs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        r"""Every pair of consecutive observations: `(y0, y1, dt)`, arrays `(N, dim)`, `(N, dim)`,
        `(N,)` with $y_1$ observed $dt$ after $y_0$ on the same trajectory (`dt` is
        `intervals()`)."""
        y0 = np.concatenate([y[:-1] for y in self.states])
        y1 = np.concatenate([y[1:] for y in self.states])
        return y0, y1, self.intervals()

    def rms_size(self) -> float:
        r"""$\sqrt{\operatorname{mean}_k |y_k|^2}$ over every observation: the size noise is
        measured against."""
        return rms_size(self.states)

    def _pick(self, indices: list[int]) -> Observations:
        return Observations(self.system, [self.times[i] for i in indices], [self.states[i] for i in indices],
                            metadata=self.metadata, groups=self._picked_groups(indices))

    @classmethod
    def _joined(cls, datasets, groups, metadata) -> Observations:
        return cls(datasets[0].system, [t for d in datasets for t in d.times], [y for d in datasets for y in d.states],
                   metadata=metadata, groups=groups)

    def check_system(self, system: AbstractPoissonSystem, what: str = "system") -> AbstractPoissonSystem:
        """`system` if it has the Poisson structure of the observations' system (equal, or the
        same bracket and Casimirs: `poisson_structure_difference`; its Hamiltonian may differ,
        it is what is learned), else a `ValueError` naming both (`what` names `system`)."""
        if not isinstance(system, AbstractPoissonSystem):
            raise TypeError(f"{what} must be an AbstractPoissonSystem; got {type(system).__name__}")
        reason = poisson_structure_difference(self.system, system)
        if reason is not None:
            raise ValueError(
                f"{what} {system!r} has another Poisson structure than the observations, which are of "
                f"{self.system!r}: {reason}. A map for one bracket cannot follow motions of the other; use a system "
                "with the observations' bracket and Casimirs (its Hamiltonian may differ: it is what is learned)"
            )
        return system

    # -- files -----------------------------------------------------------------------------
    def _long(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        index = np.concatenate([np.full(y.shape[0], j) for j, y in enumerate(self.states)])
        return index, np.concatenate(self.times), np.concatenate(self.states)

    def save(self, path: str | os.PathLike) -> None:
        """Write to HDF5, atomically (a temporary file renamed into place): datasets
        `trajectory` (index of each observation's trajectory), `t`, `states` `(N, dim)`; the
        system, metadata and groups (if any) as attributes."""
        import h5py

        index, t, y = self._long()
        with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
            f.create_dataset("trajectory", data=index)
            f.create_dataset("t", data=t)
            f.create_dataset("states", data=y)
            f.attrs["format"] = FORMAT
            f.attrs["format_version"] = FORMAT_VERSION
            f.attrs["system"] = self.system.name
            f.attrs["system_params"] = json.dumps(self.system.params)
            f.attrs["metadata"] = json.dumps(self.metadata)
            if self.groups is not None:
                f.attrs["groups"] = json.dumps(list(self.groups))
            f.attrs["liepoisson_version"] = liepoisson.__version__

    @classmethod
    def from_columns(cls, system: AbstractPoissonSystem, trajectory: ArrayLike, t: ArrayLike, states: ArrayLike,
                     *, metadata: dict[str, Any] | None = None, groups: Any = None,
                     source: str = "the data") -> Observations:
        """From the long format (one row per observation): the trajectory label of each row
        (any integers), its time and its state `(N, dim)`; rows in any order (sorted by time
        within each trajectory; repeated times are refused); `groups` one label per trajectory,
        in the order of their sorted labels."""
        label, t, (y,) = long_columns(trajectory, t, {"states": states}, source)
        times, (states,) = rows_by_trajectory(label, t, (y,))
        try:
            return cls(system, times, states, metadata=metadata, groups=groups)
        except ValueError as err:
            raise ValueError(f"{source}: {err}") from None

    @classmethod
    def load(cls, path: str | os.PathLike, system: AbstractPoissonSystem | None = None) -> Observations:
        """Read observations from a file:

        - HDF5 (`.h5`, `.hdf5`) written by `save`: the system is rebuilt from the file, or given
          `system`, checked against it;
        - NumPy `.npz` with arrays `trajectory`, `t`, `states` `(N, dim)`, or CSV with the header
          `trajectory,t,y0,...,y{dim-1}` (one row per observation, rows in any order): the
          file holds no system, so `system` (its Poisson structure) is required.

        A file of another kind, damaged or missing a field raises `ValueError` naming it."""
        path = os.fspath(path)
        suffix = os.path.splitext(path)[1].lower()
        if suffix in (".npz", ".csv"):
            if system is None:
                raise ValueError(f"{path!r} holds no system: pass system= (the Poisson structure the states live in)")
            if not isinstance(system, AbstractPoissonSystem):
                raise TypeError(f"system must be an AbstractPoissonSystem; got {type(system).__name__}")
            if suffix == ".npz":
                columns = read_npz(path, ("trajectory", "t", "states"), "an observations .npz holds trajectory, t "
                                   "and states (N, dim)")
                return cls.from_columns(system, columns["trajectory"], columns["t"], columns["states"],
                                        source=repr(path))
            label, t, _, (y,) = read_csv(path, (("y", system.dim),))
            return cls.from_columns(system, label, t, y, source=repr(path))
        f = open_hdf5(path, "liepoisson observations (written by Observations.save), or a .npz/.csv file")
        try:
            with f:
                check_file_format(f, path, FORMAT, FORMAT_VERSION, "observations")
                columns = tuple(_column(f[key][...], key, path) for key in ("trajectory", "t", "states"))
                name = _text(f.attrs["system"])
                params = _json_attribute(f.attrs["system_params"], "system_params", path)
                metadata = _json_attribute(f.attrs.get("metadata", "{}"), "metadata", path)
                groups = file_groups(f, path)
        except ValueError:
            raise
        except (OSError, KeyError, TypeError) as err:
            raise ValueError(f"{path!r} is damaged or lacks a field of an observations file: {err}") from err
        system = system_for_file(name, params, system, f"the file {path!r}")
        return cls.from_columns(system, *columns, metadata=metadata, groups=groups, source=repr(path))


def file_groups(f: Any, path: str) -> list[str | int] | None:
    """The `groups` attribute of an observations file (`None` if absent), or a `ValueError`
    naming the file when it is not a JSON list of labels."""
    groups = _json_attribute(f.attrs.get("groups", "null"), "groups", path)
    if groups is not None and not (isinstance(groups, list) and all(
            isinstance(g, (str, int)) and not isinstance(g, bool) for g in groups)):
        raise ValueError(f"{path!r}: its attribute groups must be a JSON list of labels (strings or integers), one "
                         f"per trajectory; got {groups!r}")
    return groups


def _text(value: Any) -> str:
    """An HDF5 string attribute as `str` (h5py gives `bytes` for fixed-length strings)."""
    return value.decode("utf-8", "replace") if isinstance(value, bytes) else str(value)


def _shown(value: Any) -> Any:
    """An attribute's value as Python shows it (text decoded, NumPy scalars as Python's)."""
    if isinstance(value, bytes):
        return _text(value)
    return value.item() if isinstance(value, np.generic) else value


def check_file_format(f: Any, path: str, expected_format: str, expected_version: int, what: str) -> None:
    """A `ValueError` naming the file `path` (open as `f`) unless its attributes `format` and
    `format_version` are `expected_format` and `expected_version`; `what` names the kind of
    file in the message (`"observations"`, `"body-observations"`)."""
    if f.attrs.get("format") != expected_format:
        raise ValueError(f"{path!r} is not a liepoisson {what} file (attribute format is "
                         f"{f.attrs.get('format')!r}, expected {expected_format!r})")
    version = format_version(f.attrs["format_version"], path)
    if version != expected_version:
        raise ValueError(f"{path!r} has format_version {version}; this liepoisson reads {expected_version}")


def format_version(value: Any, path: str) -> int:
    """The `format_version` attribute of the file `path` as an int, or a `ValueError` naming
    the file and what it holds instead."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Integral, np.integer)):
        raise ValueError(  # noqa: TRY004 (a damaged file, not a wrong argument type)
            f"{path!r}: the attribute format_version is {_shown(value)!r}; expected an integer "
            f"({FORMAT_VERSION} for this liepoisson): the file is damaged or was not written by liepoisson")
    return int(value)


def _json_attribute(value: Any, key: str, path: str) -> Any:
    """The JSON text of attribute `key` of the file `path`, parsed; a `ValueError` naming the
    file and the attribute if it is not JSON."""
    text = _text(value)
    try:
        return json.loads(text)
    except ValueError as err:
        shown = text if len(text) <= 80 else text[:77] + "..."
        raise ValueError(f"{path!r}: the attribute {key} is not JSON ({err}); got {shown!r}") from None


def _column(value: Any, key: str, path: str) -> np.ndarray:
    """The array `key` of an observations file as read, or a `ValueError` naming the file and
    the array if it does not hold real numbers (text labels, complex states)."""
    arr = np.asarray(value)
    if arr.dtype.kind not in "iuf":
        what = "trajectory labels (integers)" if key == "trajectory" else "real numbers"
        raise ValueError(f"{path!r}: the array {key!r} must hold {what}; got {_values(arr)}")
    return arr


def long_columns(trajectory: ArrayLike, t: ArrayLike, measured: dict[str, Any],
                 source: str) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """The long format's columns checked: `trajectory` labels (integers) and `t` of `N` rows,
    each array of `measured` `(N, width)`; errors name `source` and the column."""
    columns = []
    for name, value in (("trajectory", trajectory), ("t", t), *measured.items()):
        try:
            columns.append(_real_array(value, name))
        except (TypeError, ValueError) as err:
            raise type(err)(f"{source}: {err}") from None
    label, t, *rest = columns
    n = label.shape[0] if label.ndim == 1 else -1
    if n < 0 or t.shape != (n,) or any(v.ndim != 2 or v.shape[0] != n for v in rest):
        shapes = ", ".join(str(v.shape) for v in columns)
        raise ValueError(f"{source}: {', '.join(['trajectory', 't', *measured])} must have N, N and (N, width) "
                         f"entries; got shapes {shapes}")
    if label.size and not np.all(label == np.round(label)):
        raise ValueError(f"{source}: trajectory labels must be integers; got {label[:5].tolist()}...")
    return label, t, rest


def rows_by_trajectory(label: np.ndarray, t: np.ndarray,
                       columns: Sequence[np.ndarray]) -> tuple[list[np.ndarray], list[list[np.ndarray]]]:
    """`(times, per_column)`: the rows of each trajectory label (in label order), sorted by time
    (stably: repeated times stay for the constructor to refuse)."""
    times, out = [], [[] for _ in columns]
    for value in np.unique(label):
        rows = np.flatnonzero(label == value)
        rows = rows[np.argsort(t[rows], kind="stable")]
        times.append(t[rows])
        for k, column in enumerate(columns):
            out[k].append(column[rows])
    return times, out


def read_npz(path: str, required: Sequence[str], what: str, optional: Sequence[str] = ()) -> dict[str, np.ndarray]:
    """The arrays `required` (and those of `optional` present) of a `.npz` file, by name;
    `ValueError` naming the file if it is not one, or lacks a required array (`what` says
    what the file should hold)."""
    import zipfile

    try:
        with open(path, "rb") as f, np.load(f, allow_pickle=False) as z:
            missing = [k for k in required if k not in z]
            if missing:
                raise ValueError(f"{path!r} lacks the array(s) {missing}; {what}")
            return {key: _column(z[key], key, path) for key in (*required, *optional) if key in z}
    except ValueError as err:
        if str(err).startswith(repr(path)):
            raise
        raise ValueError(f"{path!r} is not a readable .npz file: {err}") from err
    except (OSError, EOFError, zipfile.BadZipFile) as err:
        raise ValueError(f"{path!r} is not a readable .npz file: {err}") from err


def read_csv(path: str, *layouts: Sequence[tuple[str, int]]) -> tuple[np.ndarray, np.ndarray, Any, list[np.ndarray]]:
    """`(trajectory, t, layout, blocks)` of a CSV file whose header is `trajectory,t` and then,
    for the one of the `layouts` (each a sequence of `(prefix, width)`) it matches, the columns
    `prefix0, ..., prefix{width-1}` of each block: e.g. `(("y", 3),)` reads
    `trajectory,t,y0,y1,y2`."""
    headers = [["trajectory", "t", *(f"{prefix}{i}" for prefix, width in layout for i in range(width))]
               for layout in layouts]
    try:
        with open(path, encoding="utf-8-sig") as f:  # a byte-order mark (spreadsheets write one) is skipped
            header = [h.strip() for h in f.readline().split(",")]
            if header not in headers:
                expected = " or ".join(repr(",".join(h)) for h in headers)
                raise ValueError(f"{path!r} has the header {','.join(header)!r}; expected {expected}")
            layout = layouts[headers.index(header)]
            width = len(header)
            body = f.read()
            rows = np.loadtxt(io.StringIO(body), delimiter=",", ndmin=2) if body.strip() else np.zeros((0, width))
    except (OSError, UnicodeDecodeError) as err:
        raise ValueError(f"{path!r} is not a readable CSV file: {err}") from err
    except ValueError as err:
        if "header" in str(err):
            raise
        raise ValueError(f"{path!r}: a row is not {width} numbers: {err}") from err
    if rows.size == 0:
        raise ValueError(f"{path!r} has a header and no observation")
    if rows.shape[1] != width:
        raise ValueError(f"{path!r}: rows have {rows.shape[1]} columns; expected {width}")
    blocks, start = [], 2
    for _, w in layout:
        blocks.append(rows[:, start:start + w])
        start += w
    return rows[:, 0], rows[:, 1], layout, blocks


def uneven_times(n_trajectories: int, n_observations: int, steps: tuple[float, float] = (0.05, 0.3), *,
                 seed: int = 0) -> np.ndarray:
    """Observation times `(n_trajectories, n_observations)` from 0, each step drawn uniformly
    from `steps = (low, high)` (0 < low <= high), seeded."""
    n_trajectories = positive_int(n_trajectories, "n_trajectories")
    n_observations = positive_int(n_observations, "n_observations", minimum=2)
    if not (isinstance(steps, (Sequence, np.ndarray)) and len(steps) == 2):
        raise TypeError(f"steps must be (low, high); got {steps!r}")
    low, high = positive_float(steps[0], "steps[0]"), positive_float(steps[1], "steps[1]")
    if high < low:
        raise ValueError(f"steps must be (low, high) with low <= high; got {steps}")
    dt = np.random.default_rng(positive_int(seed, "seed", minimum=0)).uniform(low, high,
                                                                             (n_trajectories, n_observations - 1))
    return np.concatenate([np.zeros((n_trajectories, 1)), np.cumsum(dt, axis=1)], axis=1)


def observation_plan(times: Any, n_trajectories: int, drop: float, seed: int
                     ) -> tuple[list[np.ndarray], list[np.ndarray], np.random.Generator]:
    """`(times, keep, noise stream)` of an `observe`-like call: the checked times of each of
    `n_trajectories` (at least two each), which observations survive `drop` (the first and
    last always), and the generator of the noise; drops and noise come from two independent
    streams of `seed`, so noise 0 gives the clean values at the same times."""
    ts = times_per_trajectory(times, n_trajectories)
    if len(ts) != n_trajectories:
        raise ValueError(f"times has {len(ts)} trajectories and y0 {n_trajectories} initial states")
    for j, t in enumerate(ts):
        check_times(t, f"times[{j}]")
        if t.size < 2:
            raise ValueError(f"times[{j}] has {t.size} time(s); a trajectory needs at least two observations")
    drops, noises = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(2))
    keep = []
    for t in ts:
        k = drops.random(t.size) >= drop
        k[0] = k[-1] = True
        keep.append(k)
    return ts, keep, noises


def propagate_grids(ta: Any, starts: np.ndarray, ts: list[np.ndarray]) -> list[np.ndarray]:
    """heyoka's states `(len(t), size)` at the times `t` of each trajectory from its start
    (one integrator `ta` reused); a trajectory heyoka cannot finish is a `RuntimeError`."""
    import heyoka as hy

    out = []
    for j, (y, t) in enumerate(zip(starts, ts, strict=True)):
        ta.time, ta.state[:] = float(t[0]), y
        outcome, *_, states = ta.propagate_grid(t)
        if outcome != hy.taylor_outcome.time_limit:
            raise RuntimeError(f"heyoka stopped trajectory {j} (start {np.asarray(y).tolist()}) at t={ta.time}: "
                               f"{outcome}")
        out.append(np.array(states))
    return out


def observe(system: AbstractPoissonSystem, y0: ArrayLike, times: Any, *, noise: float = 0.0,
            law: str | AbstractNoiseLaw = "gaussian", drop: float = 0.0, seed: int = 0,
            tol: float | None = None) -> Observations:
    r"""Observations of heyoka ground truth, for studies: trajectory $j$ starts from `y0[j]` at
    its first time and is observed at `times[j]`, with noise and dropped samples.

    **Arguments:**

    - `y0`: `(n_traj, dim)` (or `(dim,)`); `times`: as `Observations` (shared 1-D, per
      trajectory, or `uneven_times(...)`).
    - `noise`: standard deviation of the noise on each component, relative to the RMS size
      $\sqrt{\operatorname{mean}|y|^2}$ of the clean observations (>= 0).
    - `law`: an `AbstractNoiseLaw` (`GaussianNoise()`, `UniformNoise()`, `LaplaceNoise()` or
      your own), or its name `"gaussian"`, `"uniform"` or `"laplace"`; scaled to that
      standard deviation.
    - `drop`: the probability that an observation is dropped (the first and last of each
      trajectory are kept).
    - `seed`: the drops and the noise are drawn from two independent streams of this seed, so
      the same call with `noise=0` gives the clean states at the same times.
    - `tol`: heyoka's tolerance (default machine epsilon).

    The metadata records these settings and the absolute noise level `noise_std`.
    """
    if not isinstance(system, AbstractPoissonSystem):
        raise TypeError(f"system must be an AbstractPoissonSystem; got {type(system).__name__}")
    y0 = np.array(system.check_regular(y0, "y0"), dtype=np.float64).reshape(-1, system.dim)
    noise = noise_level(noise)
    law = noise_law(law)
    drop = fraction(drop, "drop")
    seed = positive_int(seed, "seed", minimum=0)
    ts, keep, noises = observation_plan(times, y0.shape[0], drop, seed)
    ta = taylor_integrator(system, tol)
    clean = [states[k] for states, k in zip(propagate_grids(ta, y0, ts), keep, strict=True)]
    std = noise * rms_size(clean)
    observed = []
    for y in clean:
        observed.append(y + std * law.sample(noises, y.shape))
    metadata = {"source": "integrators.observe", "noise": noise, "noise_std": std, "law": law.name, "drop": drop,
                "seed": seed, "tolerance": tol}
    return Observations(system, [t[k] for t, k in zip(ts, keep)], observed, metadata=metadata)
