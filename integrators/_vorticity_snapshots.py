r"""Snapshot files of vorticity fields on the sphere (Zeitlin's model, u(N) with N up to a few
hundred: dimension $N^2$ up to $10^5$), read into `integrators.Observations`, and noise relative
to the field's size.

A snapshot file is HDF5 with a dataset `t` `(n,)` (strictly increasing times) and either
`vorticity` `(n, N, N)` (complex skew-Hermitian matrices $W$) or `harmonics` `(n, N^2)` (real
spherical-harmonic coefficients $\omega_{lm}$, index $l^2 + l + m$, quflow's convention:
`liepoisson.systems.Zeitlin.state_from_harmonics`); attribute `format` =
`"liepoisson-vorticity-snapshots"`. One file is one trajectory. Snapshots are read and
converted one at a time (u(N) coordinates by one gather, $O(N^2)$; harmonics by one product
per diagonal, $O(N^3)$): nothing of size $N^2\times N^2$ is formed.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from liepoisson.internals import check_fits_in_memory, positive_int
from liepoisson.systems import Zeitlin

from ._files import atomic_path, open_hdf5
from ._noise import AbstractNoiseLaw, noise_law, noise_level
from ._observations import Observations, check_times

FORMAT = "liepoisson-vorticity-snapshots"
FORMAT_VERSION = 1


def write_vorticity_snapshots(path: str | os.PathLike, times: ArrayLike, fields: ArrayLike) -> None:
    r"""Write one trajectory of vorticity snapshots to the HDF5 file `path`, atomically (a
    temporary file renamed into place): `times` `(n,)` strictly increasing, `fields` either
    `(n, N, N)` skew-Hermitian matrices (dataset `vorticity`) or `(n, N^2)` real harmonic
    coefficients (dataset `harmonics`)."""
    import h5py

    t = check_times(np.asarray(times, dtype=np.float64), "times")
    fields = np.asarray(fields)
    if fields.dtype.kind in "iufc" and not np.all(np.isfinite(fields)):
        raise ValueError("fields must be finite")
    if fields.ndim == 3 and fields.shape[1] == fields.shape[2]:
        key, data = "vorticity", fields.astype(np.complex128)
        N = fields.shape[1]
        skew = np.max(np.abs(data + np.conj(np.swapaxes(data, 1, 2)))) if data.size else 0.0
        if not skew <= 1e-12 * max(float(np.max(np.abs(data), initial=0.0)), 1e-300):
            raise ValueError(f"fields must be skew-Hermitian matrices W (W^dagger = -W); the largest |W + W^dagger| "
                             f"is {skew:.3g}")
    elif fields.ndim == 2 and fields.dtype.kind in "iuf" and round(np.sqrt(fields.shape[1])) ** 2 == fields.shape[1]:
        key, data = "harmonics", fields.astype(np.float64)
        N = round(np.sqrt(fields.shape[1]))
    else:
        raise ValueError(f"fields must be (n, N, N) skew-Hermitian matrices or (n, N^2) real harmonic coefficients; "
                         f"got shape {fields.shape} and dtype {fields.dtype}")
    if data.shape[0] != t.shape[0]:
        raise ValueError(f"times has {t.shape[0]} entries and fields {data.shape[0]} snapshots; give one time per "
                         "snapshot")
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        f.create_dataset("t", data=t)
        f.create_dataset(key, data=data)
        f.attrs["format"] = FORMAT
        f.attrs["format_version"] = FORMAT_VERSION
        f.attrs["N"] = N


def read_vorticity_snapshots(paths: str | os.PathLike | Sequence[str | os.PathLike],
                             system: Zeitlin | None = None) -> Observations:
    r"""`integrators.Observations` of `liepoisson.systems.Zeitlin(N)` from snapshot files
    (module docstring), one trajectory per file, its states the u(N) coordinates of each
    snapshot's $W$ (so that $|y| = \|W\|_F$), read and converted one snapshot at a time.

    **Arguments:** `paths`, one file or a sequence of them; `system` (default
    `Zeitlin(N)`, N from the files), checked against every file's N. Files of different N, a
    file that is not a snapshot file, or one with non-finite or unsorted data raise
    `ValueError` naming the file."""
    if isinstance(paths, (str, os.PathLike)):
        paths = [paths]
    if not isinstance(paths, Sequence) or not paths:
        raise TypeError(f"paths must be a path or a non-empty sequence of paths; got {paths!r}")
    if system is not None and not isinstance(system, Zeitlin):
        raise TypeError(f"system must be liepoisson.systems.Zeitlin(N); got {system!r}")
    times, states = [], []
    for path in paths:
        path = os.fspath(path)
        f = open_hdf5(path, "a vorticity snapshot file (integrators.write_vorticity_snapshots)")
        with f:
            if f.attrs.get("format") != FORMAT:
                raise ValueError(f"{path!r} is not a vorticity snapshot file (attribute format is "
                                 f"{f.attrs.get('format')!r}, expected {FORMAT!r})")
            key = "vorticity" if "vorticity" in f else "harmonics" if "harmonics" in f else None
            if key is None or "t" not in f:
                raise ValueError(f"{path!r} lacks the dataset t or a dataset vorticity/harmonics")
            dataset = f[key]
            N = dataset.shape[1] if key == "vorticity" else round(np.sqrt(dataset.shape[1]))
            if system is None:
                system = Zeitlin(N)
            if N != system.N:
                raise ValueError(f"{path!r} holds fields of N = {N}; the system is {system!r} (N = {system.N}): every "
                                 "file of one data set must have the same N")
            n = dataset.shape[0]
            check_fits_in_memory(8 * n * system.dim, f"paths: {path!r}, {n} snapshots of dimension {system.dim}",
                                 "read fewer snapshots per file")
            t = check_times(np.asarray(f["t"][...], dtype=np.float64), f"{path!r}: t")
            if t.shape[0] != n:
                raise ValueError(f"{path!r}: t has {t.shape[0]} times and {key} {n} snapshots")
            y = np.empty((n, system.dim))
            for k in range(n):  # one snapshot at a time
                snapshot = np.asarray(dataset[k])
                if not np.all(np.isfinite(snapshot)):
                    raise ValueError(f"{path!r}: snapshot {k} (t = {t[k]}) is not finite")
                y[k] = _state(system, snapshot, key)
        times.append(t)
        states.append(y)
    return Observations(system, times, states, metadata={"source": "integrators.read_vorticity_snapshots",
                                                         "files": [os.fspath(p) for p in paths]})


def _state(system: Zeitlin, snapshot: np.ndarray, key: str) -> np.ndarray:
    """The u(N) coordinates of one snapshot."""
    if key == "harmonics":
        return system.state_from_harmonics(snapshot)
    return np.asarray(system.algebra.coordinates(snapshot))


def add_field_noise(data: Observations, noise: Any, *, law: str | AbstractNoiseLaw = "gaussian",
                    seed: int = 0) -> Observations:
    r"""`data` with noise on every component of every state, of standard deviation `noise`
    times the field's root-mean-square component, $\sqrt{\operatorname{mean}_{k,i} y_{k,i}^2}$
    over every observation: relative to the field's size, whatever its dimension (noise 1e-3
    makes the noise's norm about 1e-3 of the field's). `integrators.observe` measures its
    noise against the state's RMS *norm* $\sqrt{\operatorname{mean}_k|y_k|^2}$ instead, per
    component: right for a rigid body's three components, but at a field's dimension $n$ a
    noise $\sqrt n$ times the field's size (128 times at $n = 16{,}384$).

    `law` as `integrators.observe` (scaled to that standard deviation); `seed` seeds it. The
    metadata records `noise`, `noise_std` (the absolute standard deviation), `law`, `seed`."""
    if not isinstance(data, Observations):
        raise TypeError(f"data must be integrators.Observations; got {type(data).__name__}")
    noise = noise_level(noise)
    law = noise_law(law)
    seed = positive_int(seed, "seed", minimum=0)
    rms = float(np.sqrt(np.mean(np.concatenate([np.mean(y * y, axis=1) for y in data.states]))))
    std = noise * rms
    rng = np.random.default_rng(seed)
    states = [y + std * law.sample(rng, y.shape) for y in data.states]
    metadata = {**data.metadata, "noise": noise, "noise_std": std, "noise_relative_to": "rms component",
                "law": law.name, "seed": seed}
    return Observations(data.system, data.times, states, metadata=metadata, groups=data.groups)
