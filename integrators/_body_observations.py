r"""What instruments measure of a body: its configuration (a star tracker's attitude, a
navigation system's pose) and its body velocity (a gyroscope's rates, a log's speeds), at
uneven times, with noise; never its momentum, which needs the inertia that is to be learned.
And `observe_body`, which makes such data from heyoka's ground truth of $(\mu, g)$.

Noise ([Observations of bodies][conventions-body-observations]): an attitude is rotated by a
random rotation vector of standard deviation `noise` radians per axis (in the body frame); a
position gets Gaussian noise of `noise` times the RMS size of the positions' displacements from each
trajectory's first; a velocity gets
Gaussian noise of `noise` times the RMS size of the velocities.
"""

from __future__ import annotations

import json
import os
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

import liepoisson
from liepoisson import Poses, Rotations
from liepoisson.internals import fraction, jsonable, positive_int
from liepoisson.systems import AbstractLiePoissonSystem, system_for_file

from ._files import atomic_path, open_hdf5
from ._ground_truth import initial_configurations, taylor_integrator
from ._noise import noise_level
from ._observations import (
    _per_trajectory,
    check_file_format,
    check_times,
    file_groups,
    long_columns,
    observation_plan,
    propagate_grids,
    read_csv,
    read_npz,
    rms_size,
    rows_by_trajectory,
    times_per_trajectory,
)
from ._observed_trajectories import AbstractObservedTrajectories, check_groups

FORMAT = "liepoisson-body-observations"
FORMAT_VERSION = 1
#: What can be measured: `"configurations"`, `"velocities"` or both.
MEASURED = ("configurations", "velocities")


#: Quaternions that look scalar first are refused when, read scalar last, the rotations between
#: successive attitudes miss the rotations the rates give by more than `SCALAR_FIRST_MISFIT` of
#: their size, and read scalar first they miss by `SCALAR_FIRST_GAIN` times less (medians over
#: the intervals: noise that swamps the motion spoils both readings alike and trips nothing).
SCALAR_FIRST_MISFIT = 0.5
SCALAR_FIRST_GAIN = 4.0


def _rotation_misfit(q: np.ndarray, rates: np.ndarray, dt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    r"""`|log(q_k^{-1} q_{k+1}) - (w_k + w_{k+1}) dt_k / 2|` per interval (the body rotation
    between successive attitudes against the mean rate's), and the size of the latter."""
    from scipy.spatial.transform import Rotation

    moved = (Rotation.from_quat(q[:-1]).inv() * Rotation.from_quat(q[1:])).as_rotvec()
    expected = 0.5 * (rates[:-1] + rates[1:]) * dt[:, None]
    return np.linalg.norm(moved - expected, axis=1), np.linalg.norm(expected, axis=1)


def check_scalar_last(group: Any, times: tuple[np.ndarray, ...], configurations: tuple[np.ndarray, ...],
                      velocities: tuple[np.ndarray, ...]) -> None:
    r"""`ValueError` if attitudes (`Rotations`, `Poses`: the first four components) fit the
    measured rates (the first three components of the body velocity) much better read scalar
    first, $(w, x, y, z)$, than scalar last, $(x, y, z, w)$, as they are taken."""
    if not isinstance(group, (Rotations, Poses)):
        return
    last, first, size = [], [], []
    for t, g, v in zip(times, configurations, velocities, strict=True):
        dt, q, rates = np.diff(t), g[:, :4], v[:, :3]
        e_last, s = _rotation_misfit(q, rates, dt)
        e_first, _ = _rotation_misfit(np.roll(q, -1, axis=1), rates, dt)
        last.append(e_last), first.append(e_first), size.append(s)
    last, first, size = (float(np.median(np.concatenate(x))) for x in (last, first, size))
    if size > 0.0 and last > SCALAR_FIRST_MISFIT * size and SCALAR_FIRST_GAIN * first < last:
        convert = ("g[:, [1, 2, 3, 0, 4, 5, 6]] (the quaternion's scalar moved last, the position kept)"
                   if isinstance(group, Poses) else "np.roll(q, -1, axis=-1)")
        raise ValueError(
            f"configurations look like quaternions given scalar first, (w, x, y, z): read scalar last, (x, y, z, w), "
            f"as they are taken (scipy's Rotation.as_quat()), the rotations between successive attitudes miss the "
            f"rotations the velocities' rates give by {last / size:.0%} of their size (median over the intervals), "
            f"read scalar first by {first / size:.0%}. Convert them with {convert}, or "
            "Rotation.from_quat(q, scalar_first=True).as_quat()"
        )


def _check_system(system: Any) -> AbstractLiePoissonSystem:
    if not isinstance(system, AbstractLiePoissonSystem):
        raise TypeError(f"system must be a Lie-Poisson system (liepoisson.systems.AbstractLiePoissonSystem) with a "
                        f"configuration group; got {type(system).__name__}")
    system.require_group()
    return system


def _rows(value: Any, name: str, n: int, width: int, times: list[np.ndarray]) -> list[np.ndarray]:
    arrays = _per_trajectory(value, name)
    arrays = list(arrays) if isinstance(arrays, list) or arrays.ndim == 3 else [arrays]
    if len(arrays) != n:
        raise ValueError(f"{name} has {len(arrays)} trajectories and times {n}; give one array per trajectory")
    out = []
    for j, (a, t) in enumerate(zip(arrays, times)):
        a = np.asarray(a, dtype=np.float64)
        if a.ndim != 2 or a.shape[1] != width:
            raise ValueError(f"{name}[{j}] must have shape (n_observations, {width}); got shape {a.shape}")
        if a.shape[0] != t.shape[0]:
            raise ValueError(f"{name}[{j}] has {a.shape[0]} observations and times[{j}] {t.shape[0]}; give one "
                             "time per observation")
        bad = np.argwhere(~np.isfinite(a))
        if bad.size:
            k, i = (int(v) for v in bad[0])
            raise ValueError(f"{name}[{j}] must be finite; observation {k} (t = {t[k]}), component {i} is {a[k, i]}. "
                             "Missing values are not masked: drop that observation and its time")
        out.append(a.copy())
    return out


class BodyObservations(AbstractObservedTrajectories):
    r"""Trajectories of a body observed at their own times: configurations $g_j(t_{j,k})$ on
    `system.group` (unit quaternions $(x, y, z, w)$, scalar last, for `liepoisson.Rotations`;
    quaternion and position for `liepoisson.Poses`), body velocities $\xi_j(t_{j,k})$
    ($\Omega$ for a rigid body; $(\Omega, v)$ for a vehicle), or both. The momenta are not
    observed: a fit treats them as unknowns ([Observations of bodies][conventions-body-observations]).

    **Arguments:**

    - `system`: a Lie-Poisson system with a configuration group (its Hamiltonian is what is
      learned; only its algebra and group are used).
    - `times`: one array of times per trajectory (or one 1-D array shared by all), strictly
      increasing.
    - `configurations`: one `(n_j, group.size)` array per trajectory, or `None`; quaternions
      within `liepoisson._groups.QUATERNION_TOLERANCE` (1e-6) of unit norm are normalised,
      others refused. With velocities too, attitudes whose successive rotations fit the rates
      much better read scalar first are refused as such (`check_scalar_last`).
    - `velocities`: one `(n_j, dim)` array per trajectory, or `None`. At least one of the two.
    - `metadata`: JSON values kept with the data and in its file.
    - `groups`: one label (a string or an integer) per trajectory, e.g. its recording session
      (a fit holds whole groups out and shares a gyroscope bias within one); `None`: none.
    """

    def __init__(self, system: AbstractLiePoissonSystem, times: Any, configurations: Any = None,
                 velocities: Any = None, *, metadata: dict[str, Any] | None = None, groups: Any = None):
        system = _check_system(system)
        group = system.group
        if configurations is None and velocities is None:
            raise ValueError("give configurations, velocities or both: observations need something measured")
        first = configurations if configurations is not None else velocities
        arr = _per_trajectory(first, "configurations" if configurations is not None else "velocities")
        n = len(arr) if isinstance(arr, list) or arr.ndim == 3 else 1
        ts = times_per_trajectory(times, n)
        if len(ts) != n:
            raise ValueError(f"times has {len(ts)} trajectories and the measurements {n}; give one time array per "
                             "trajectory (or one 1-D array shared by all)")
        for j, t in enumerate(ts):
            check_times(t, f"times[{j}]")
            if t.shape[0] < 2:
                raise ValueError(f"times[{j}] has {t.shape[0]} time(s); a trajectory needs at least two observations")
        self.system = system
        self.times: tuple[np.ndarray, ...] = tuple(np.array(t, dtype=np.float64) for t in ts)
        self.configurations: tuple[np.ndarray, ...] | None = None
        self.velocities: tuple[np.ndarray, ...] | None = None
        if configurations is not None:
            gs = _rows(configurations, "configurations", n, group.size, list(self.times))
            self.configurations = tuple(np.asarray(group.check(g, f"configurations[{j}]")) for j, g in enumerate(gs))
        if velocities is not None:
            self.velocities = tuple(_rows(velocities, "velocities", n, system.dim, list(self.times)))
        if self.configurations is not None and self.velocities is not None:
            check_scalar_last(group, self.times, self.configurations, self.velocities)
        self.groups = check_groups(groups, n)
        try:
            self.metadata: dict[str, Any] = jsonable(dict(metadata or {}))
        except (TypeError, ValueError) as err:
            raise TypeError(f"metadata must be a dict of JSON values; got {metadata!r}") from err

    # -- shape -----------------------------------------------------------------------------
    @property
    def group(self):
        return self.system.group

    @property
    def measured(self) -> tuple[str, ...]:
        """What these observations hold: `("configurations", "velocities")` or one of them."""
        return tuple(k for k in MEASURED if getattr(self, k) is not None)

    def __repr__(self) -> str:
        steps = np.concatenate([np.diff(t) for t in self.times])
        return (f"BodyObservations({self.system!r}, {' and '.join(self.measured)}, {self.n_trajectories} "
                f"trajectories, {self.n_observations} observations, steps {steps.min():.3g}..{steps.max():.3g})")

    def velocity_scale(self) -> float:
        r"""$\sqrt{\operatorname{mean}|\xi|^2}$ of the observed velocities (of the finite
        differences of the configurations when no velocity is observed): what velocity noise
        and velocity residuals are measured against."""
        if self.velocities is not None:
            return rms_size(self.velocities)
        return rms_size([self.group_velocities(j) for j in range(len(self))])

    def position_scale(self) -> float | None:
        r"""The RMS size of the observed positions' displacements from each trajectory's first
        (poses; the same wherever the origin is), 1 if nothing moves; `None` without poses."""
        if self.configurations is None or not isinstance(self.group, Poses):
            return None
        return displacement_scale(self.configurations)

    def group_velocities(self, j: int) -> np.ndarray:
        r"""The body velocities `(n_j - 1, dim)` over the intervals of trajectory `j` from its
        configurations, $\log(g_k^{-1}g_{k+1})/\Delta t$ (at the intervals' midpoints)."""
        if self.configurations is None:
            raise ValueError("these observations hold no configurations")
        g = self.configurations[j]
        return np.asarray(self.group.log_between(g[:-1], g[1:])) / np.diff(self.times[j])[:, None]

    def _pick(self, indices: list[int]) -> BodyObservations:
        pick = (lambda xs: None if xs is None else [xs[i] for i in indices])
        return BodyObservations(self.system, pick(self.times), pick(self.configurations), pick(self.velocities),
                                metadata=self.metadata, groups=self._picked_groups(indices))

    @classmethod
    def _joined(cls, datasets, groups, metadata) -> BodyObservations:
        measured = datasets[0].measured
        for k, d in enumerate(datasets[1:], 1):
            if d.measured != measured:
                raise ValueError(f"datasets[{k}] holds {' and '.join(d.measured)}, datasets[0] {' and '.join(measured)}: "
                                 "concatenate observations of the same measurements")
        join = (lambda key: None if key not in measured else [x for d in datasets for x in getattr(d, key)])
        return cls(datasets[0].system, [t for d in datasets for t in d.times], join("configurations"),
                   join("velocities"), metadata=metadata, groups=groups)

    def in_units(self, time: float) -> BodyObservations:
        """The same observations with times divided by `time` (e.g. 1e-3 for milliseconds to
        seconds) and velocities multiplied by it: configurations do not change."""
        from liepoisson.internals import positive_float

        time = positive_float(time, "time")
        return BodyObservations(self.system, [t / time for t in self.times], self.configurations,
                                None if self.velocities is None else [v * time for v in self.velocities],
                                metadata={**self.metadata, "time_unit": time}, groups=self.groups)

    # -- files -----------------------------------------------------------------------------
    def save(self, path: str | os.PathLike) -> None:
        """Write to HDF5, atomically: datasets `trajectory` (each observation's trajectory),
        `t`, and `configurations` `(N, group.size)` and/or `velocities` `(N, dim)`; the system,
        the group, the metadata and the trajectories' groups (if any) as attributes."""
        import h5py

        index = np.concatenate([np.full(t.size, j) for j, t in enumerate(self.times)])
        with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
            f.create_dataset("trajectory", data=index)
            f.create_dataset("t", data=np.concatenate(self.times))
            for key in self.measured:
                f.create_dataset(key, data=np.concatenate(getattr(self, key)))
            f.attrs["format"] = FORMAT
            f.attrs["format_version"] = FORMAT_VERSION
            f.attrs["system"] = self.system.name
            f.attrs["system_params"] = json.dumps(self.system.params)
            f.attrs["group"] = self.group.name
            f.attrs["metadata"] = json.dumps(self.metadata)
            if self.groups is not None:
                f.attrs["groups"] = json.dumps(list(self.groups))
            f.attrs["liepoisson_version"] = liepoisson.__version__

    @classmethod
    def from_columns(cls, system: AbstractLiePoissonSystem, trajectory: ArrayLike, t: ArrayLike, *,
                     configurations: ArrayLike | None = None, velocities: ArrayLike | None = None,
                     metadata: dict[str, Any] | None = None, groups: Any = None,
                     source: str = "the data") -> BodyObservations:
        """From the long format (one row per observation, as a logger writes them): the
        trajectory label of each row (any integers), its time, and its configuration
        `(N, group.size)` and/or body velocity `(N, dim)`; rows in any order (sorted by time
        within each trajectory; repeated times are refused); `groups` one label per
        trajectory, in the order of their sorted labels."""
        measured = {k: v for k, v in (("configurations", configurations), ("velocities", velocities))
                    if v is not None}
        if not measured:
            raise ValueError(f"{source}: give configurations, velocities or both: observations need something "
                             "measured")
        label, t, columns = long_columns(trajectory, t, measured, source)
        times, per_trajectory = rows_by_trajectory(label, t, columns)
        try:
            return cls(system, times, **dict(zip(measured, per_trajectory)), metadata=metadata, groups=groups)
        except ValueError as err:
            raise ValueError(f"{source}: {err}") from None

    @classmethod
    def load(cls, path: str | os.PathLike, system: AbstractLiePoissonSystem | None = None) -> BodyObservations:
        """Read body observations from a file:

        - HDF5 (`.h5`, `.hdf5`) written by `save`: the system rebuilt from the file, or `system`
          checked against it;
        - NumPy `.npz` with arrays `trajectory`, `t` and `configurations` `(N, group.size)`
          and/or `velocities` `(N, dim)`, or CSV with the header `trajectory,t,g0,...,xi0,...`
          (configurations `g0..g{group.size-1}` then velocities `xi0..xi{dim-1}`, either
          block alone too; one row per observation, rows in any order): the file holds no
          system, so `system` is required. Configurations are as `BodyObservations` takes
          them: unit quaternions $(x, y, z, w)$, scalar last, then the position for a pose.

        A file of another kind, damaged or missing a field raises `ValueError` naming it."""
        path = os.fspath(path)
        suffix = os.path.splitext(path)[1].lower()
        if suffix in (".npz", ".csv"):
            if system is None:
                raise ValueError(f"{path!r} holds no system: pass system= (the body whose configurations and "
                                 "velocities these are)")
            system = _check_system(system)
            if suffix == ".npz":
                columns = read_npz(path, ("trajectory", "t"), "a body-observations .npz holds trajectory, t and "
                                   "configurations (N, group.size) and/or velocities (N, dim)", optional=MEASURED)
                if not any(k in columns for k in MEASURED):
                    raise ValueError(f"{path!r} holds neither configurations nor velocities; a body-observations "
                                     ".npz holds trajectory, t and one or both of them")
                return cls.from_columns(system, columns["trajectory"], columns["t"],
                                        **{k: columns[k] for k in MEASURED if k in columns}, source=repr(path))
            g, xi = ("g", system.group.size), ("xi", system.dim)
            layouts = ((g, xi), (g,), (xi,))
            label, t, layout, blocks = read_csv(path, *layouts)
            names = [{"g": "configurations", "xi": "velocities"}[prefix] for prefix, _ in layout]
            return cls.from_columns(system, label, t, **dict(zip(names, blocks)), source=repr(path))
        f = open_hdf5(path, "liepoisson body observations (written by BodyObservations.save)")
        try:
            with f:
                check_file_format(f, path, FORMAT, FORMAT_VERSION, "body-observations")
                index, t = f["trajectory"][...], f["t"][...]
                data = {k: f[k][...] for k in MEASURED if k in f}
                name = f.attrs["system"]
                params = json.loads(f.attrs["system_params"])
                metadata = json.loads(f.attrs.get("metadata", "{}"))
                groups = file_groups(f, path)
        except ValueError:
            raise
        except (OSError, KeyError, TypeError) as err:
            raise ValueError(f"{path!r} is damaged or lacks a field of a body-observations file: {err}") from err
        name = name.decode() if isinstance(name, bytes) else str(name)
        system = system_for_file(name, params, system, f"the file {path!r}")
        if index.shape != t.shape or any(v.shape[0] != t.shape[0] for v in data.values()):
            raise ValueError(f"{path!r} holds columns of different lengths")
        labels = np.unique(index)
        rows = [np.flatnonzero(index == v) for v in labels]
        return cls(system, [t[r] for r in rows],
                   *[[data[k][r] for r in rows] if k in data else None for k in MEASURED], metadata=metadata,
                   groups=groups)


def displacement_scale(poses: list[np.ndarray]) -> float:
    """The RMS size of the positions' displacements from each trajectory's first, 1 if 0."""
    size = rms_size([g[:, 4:] - g[:1, 4:] for g in poses])
    return size if size > 0.0 else 1.0


def observe_body(system: AbstractLiePoissonSystem, y0: ArrayLike, g0: ArrayLike, times: Any, *,
                 noise: float = 0.0, measure: str | tuple[str, ...] = MEASURED, drop: float = 0.0, seed: int = 0,
                 tol: float | None = None) -> BodyObservations:
    r"""What instruments would record of heyoka's ground truth of $(\mu, g)$, for studies:
    trajectory $j$ from momentum `y0[j]` and configuration `g0[j]` at `times[j][0]`, observed at
    `times[j]`.

    **Arguments:** `y0` `(n, dim)`; `g0` `(n, group.size)` or `(group.size,)`; `times` as
    `BodyObservations` (or `integrators.uneven_times(...)`); `noise` >= 0: attitude noise in
    radians (a random rotation vector with that standard deviation per axis, in the body
    frame), velocities' noise relative to their RMS size, positions' to that of their
    displacements from each trajectory's first; `measure`:
    `"configurations"`, `"velocities"` or both (default); `drop`: the probability that an
    observation is dropped (the first and last of each trajectory are kept); `seed`: drops and
    noise from independent streams of it (noise 0 gives the clean values at the same times).
    """
    system = _check_system(system)
    group = system.group
    measure = (measure,) if isinstance(measure, str) else tuple(measure)
    if not measure or any(m not in MEASURED for m in measure):
        raise ValueError(f"measure must be 'configurations', 'velocities' or both; got {measure!r}")
    y0 = np.array(system.check_regular(y0, "y0"), dtype=np.float64).reshape(-1, system.dim)
    g0 = initial_configurations(system, g0, y0.shape[0])
    noise = noise_level(noise)
    drop = fraction(drop, "drop")
    seed = positive_int(seed, "seed", minimum=0)
    ts, keep, noises = observation_plan(times, y0.shape[0], drop, seed)
    ta = taylor_integrator(system, tol, configured=True)
    mus, gs = [], []
    for states, k in zip(propagate_grids(ta, np.concatenate([y0, g0], axis=1), ts), keep, strict=True):
        states = states[k]
        mus.append(states[:, : system.dim])
        gs.append(np.asarray(group.project(states[:, system.dim :])))
    velocities = [np.asarray(system.body_velocity(m)) for m in mus]
    v_std = noise * rms_size(velocities)
    out_v = [v + v_std * noises.standard_normal(v.shape) for v in velocities] if "velocities" in measure else None
    out_g = None
    if "configurations" in measure:
        out_g = []
        p_std = noise * displacement_scale(gs) if isinstance(group, Poses) else 0.0
        for g in gs:
            rotation = noise * noises.standard_normal((g.shape[0], 3))
            q = np.asarray(Rotations().right_exp(g[:, :4], rotation))
            if isinstance(group, Poses):
                out_g.append(np.concatenate([q, g[:, 4:] + p_std * noises.standard_normal((g.shape[0], 3))], axis=1))
            elif isinstance(group, Rotations):
                out_g.append(q)
            else:
                out_g.append(np.asarray(group.right_exp(g, noise * noises.standard_normal((g.shape[0], group.dim)))))
    metadata = {"source": "integrators.observe_body", "noise": noise, "measure": list(measure), "drop": drop,
                "seed": seed, "tolerance": tol, "velocity_noise_std": v_std}
    return BodyObservations(system, [t[k] for t, k in zip(ts, keep)], out_g, out_v, metadata=metadata)
