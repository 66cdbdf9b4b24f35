r"""Ground truth: Taylor's method (heyoka) on $\dot y = \mathbb{B}(y)\nabla H(y)$, the ODE built
symbolically from the system's own Hamiltonian and Poisson tensor (`system.heyoka_system()`)."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import os
import threading
import weakref
from collections.abc import Container, Iterator
from typing import Any

import h5py
import numpy as np
from numpy.typing import ArrayLike

from liepoisson.internals import positive_float, positive_int, progress_bar, show_progress
from liepoisson.systems import AbstractPoissonSystem, Forced

from ._distributed import check_client, map_unordered
from ._step_map import check_fits_in_memory
from ._trajectories import Trajectories, _check_seed, write_attributes

log = logging.getLogger("liepoisson")

#: Default tolerance of the Taylor integrator: double-precision machine epsilon.
EPS = float(np.finfo(np.float64).eps)

# Compiling a taylor_adaptive (LLVM JIT) costs ~0.1-1 s, far more than integrating one
# trajectory, so integrators are reused across calls: by value for systems that their params
# describe (`system.value_key()`), else on the object itself.
# An integrator is not thread-safe (it holds its state), so each thread has its own caches: the
# threads of a Dask worker (or of any thread pool) integrate chunks at the same time.
class _ThreadCaches(threading.local):
    def __init__(self):  # runs once in each thread that reads it
        self.by_params: dict[tuple[Any, ...], Any] = {}
        self.by_object: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


_CACHES = _ThreadCaches()


#: Above this many state variables of the system (its variational equations not counted) heyoka
#: compiles in compact mode.
COMPACT_MODE_STATES = 32
#: ... and above this many characters of the printed right-hand sides (variational equations
#: included): the default mode's compile time grows much faster than the expression (fresh
#: heyoka cache: Zeitlin N = 3 / 4 / 5, 8k / 16k / 25k characters, 5 / 40 / 160 s against
#: 0.2 / 0.8 / 0.9 s compact; Kirchhoff's variational equations, 18k, 38 s against 0.9 s),
#: while compact mode integrates these sizes about 2x slower (milliseconds to t = 1000).
COMPACT_MODE_CHARACTERS = 6000


def _caches() -> tuple[dict[tuple[Any, ...], Any], weakref.WeakKeyDictionary]:
    return _CACHES.by_params, _CACHES.by_object


def taylor_integrator(
    system: AbstractPoissonSystem, tol: float | None = None, *, variational: bool = False, configured: bool = False
):
    """The (cached) `heyoka.taylor_adaptive` of `system` at tolerance `tol` (default eps).

    With `variational=True` the state is augmented by the first-order variational equations
    (`heyoka.var_ode_sys`): `state[dim:].reshape(dim, dim)[i, j]` is $\\partial y_i/\\partial y_j(0)$.
    With `configured=True` the state is $(\\mu, g)$, `dim + group.size` components: the
    reconstruction $\\dot g = g\\,\\nabla H$ beside the motion (`system.heyoka_configured_system()`).
    Shared between calls of the same thread: set `ta.time` and `ta.state` before every use.
    """
    import heyoka as hy

    if not isinstance(system, AbstractPoissonSystem):
        raise TypeError(f"system must be an AbstractPoissonSystem; got {type(system).__name__}")
    tol = EPS if tol is None else positive_float(tol, "tol")
    by_params, by_object = _caches()
    group = system.require_group() if configured else None
    if system.value_key() is not None:
        key = (system.value_key(), tol, variational, group)
        cache = by_params
    else:
        key = (tol, variational, group)
        cache = by_object.setdefault(system, {})
    if key not in cache:
        ode = system.heyoka_configured_system() if configured else system.heyoka_system()
        n_state = len(ode)
        if variational:
            ode = hy.var_ode_sys(ode, hy.var_args.vars, order=1)
        # Large systems compile in compact mode (functions per Taylor-coefficient formula instead of
        # one unrolled program): the default mode's compile time explodes with the expression's
        # size (BENCHMARKS.md, "heyoka ground truth of Zeitlin's model").
        rhs = ode.sys if variational else ode
        compact = n_state > COMPACT_MODE_STATES or sum(len(str(f)) for _, f in rhs) > COMPACT_MODE_CHARACTERS
        cache[key] = hy.taylor_adaptive(ode, [0.0] * n_state, tol=tol, compact_mode=compact)
    return cache[key]


def _initial_conditions(system: AbstractPoissonSystem, y0: ArrayLike) -> np.ndarray:
    y0 = np.asarray(system.check_regular(y0, "y0"))
    if y0.ndim == 1:
        y0 = y0[None]
    if y0.ndim != 2:
        raise ValueError(
            f"y0 must have shape ({system.dim},) or (n_traj, {system.dim}); got shape {y0.shape}"
        )
    if isinstance(system, Forced):
        system.check_taylor_starts(y0, "y0")
    return y0


def _progress_bar(total: int, progress: bool | None):
    # Auto: on a terminal, and only for a run that is still going after a few seconds.
    return progress_bar(total, "ground truth", "traj", progress, delay=3.0 if progress is None else 0.0,
                        unit_scale=True)


@dataclasses.dataclass(frozen=True)
class _Job:
    """A validated ground-truth request."""

    system: AbstractPoissonSystem
    y0: np.ndarray
    h: float
    n_steps: int
    tol: float
    max_steps: int
    chunk_size: int
    seed: int | None
    g0: np.ndarray | None = None

    @property
    def grid(self) -> np.ndarray:
        return self.h * np.arange(self.n_steps + 1, dtype=np.float64)

    @property
    def shape(self) -> tuple[int, int, int]:
        """`(n_traj, n_steps + 1, width)`: the momenta, then the configurations if any."""
        return (self.y0.shape[0], self.n_steps + 1, self.system.dim + (0 if self.g0 is None else self.g0.shape[1]))

    def chunks(self, skip: Container[int] = ()) -> Iterator[tuple[int, tuple[Any, ...]]]:
        """`(k, (start, y0[start:stop], grid, tol, max_steps))` for every chunk k not in `skip`."""
        grid = self.grid
        for k, start in enumerate(range(0, self.y0.shape[0], self.chunk_size)):
            if k not in skip:
                g0 = None if self.g0 is None else self.g0[start : start + self.chunk_size]
                yield k, (start, self.y0[start : start + self.chunk_size], grid, self.tol, self.max_steps, g0)

    @property
    def n_chunks(self) -> int:
        return -(-self.y0.shape[0] // self.chunk_size)

    def fingerprint(self) -> str:
        """What makes two requests the same computation (for resuming a file)."""
        return json.dumps({
            "system": self.system.name, "system_params": self.system.params, "h": self.h,
            "n_steps": self.n_steps, "tol": self.tol, "max_steps": self.max_steps,
            "chunk_size": self.chunk_size, "seed": self.seed,
            "y0_sha256": hashlib.sha256(np.ascontiguousarray(self.y0).tobytes()).hexdigest(),
            "n_traj": self.y0.shape[0],
            **({} if self.g0 is None else
               {"g0_sha256": hashlib.sha256(np.ascontiguousarray(self.g0).tobytes()).hexdigest()}),
        }, sort_keys=True)

    def trajectories(self, states: np.ndarray) -> Trajectories:
        """`states` `(n, m, dim)` at the first `m` output times (`(n, m, dim + group.size)` with
        the configurations), with this job's provenance."""
        dim = self.system.dim
        return Trajectories(states[..., :dim], self.h, self.system, times=self.grid[: states.shape[1]],
                            integrator="heyoka-taylor", tolerance=self.tol, seed=self.seed,
                            configurations=None if self.g0 is None else states[..., dim:])


def _job(system, y0, h, n_steps, tol, max_steps, seed, progress, chunk_size, g0=None) -> _Job:
    if not isinstance(system, AbstractPoissonSystem):
        raise TypeError(f"system must be an AbstractPoissonSystem; got {type(system).__name__}")
    h = positive_float(h, "h")
    n_steps = positive_int(n_steps, "n_steps")
    tol_used = EPS if tol is None else positive_float(tol, "tol")
    if not tol_used < 1.0:
        raise ValueError(f"tol must be a relative tolerance in (0, 1), e.g. 1e-12; got {tol!r}")
    max_steps = positive_int(max_steps, "max_steps", minimum=0)
    y0 = _initial_conditions(system, y0)
    if g0 is not None:
        g0 = initial_configurations(system, g0, y0.shape[0])
    show_progress(progress)  # validates it before any work
    width = system.dim + (0 if g0 is None else g0.shape[1])
    if chunk_size is None:  # about 16 MiB of output per chunk
        chunk_size = max(1, 2**24 // (8 * (n_steps + 1) * width))
    chunk_size = min(positive_int(chunk_size, "chunk_size"), y0.shape[0])
    return _Job(system, y0, h, n_steps, tol_used, max_steps, chunk_size, _check_seed(seed), g0)


def initial_configurations(system: AbstractPoissonSystem, g0: ArrayLike, n_traj: int) -> np.ndarray:
    """`g0` as `(n_traj, group.size)` on `system.group` (one configuration is used for every
    trajectory)."""
    require = getattr(system, "require_group", None)
    if require is None:
        raise ValueError(f"g0 needs a Lie-Poisson system with a configuration group; {system!r} is not one")
    group = require()
    g0 = np.asarray(group.check(g0, "g0"))
    if g0.ndim == 1:
        g0 = np.broadcast_to(g0, (n_traj, group.size))
    if g0.shape != (n_traj, group.size):
        raise ValueError(f"g0 must have shape ({group.size},) or ({n_traj}, {group.size}) (one configuration of "
                         f"{group.name} per initial state); got shape {g0.shape}")
    return np.ascontiguousarray(g0)


def integrate_chunk(
    system: AbstractPoissonSystem, start: int, y0: np.ndarray, grid: np.ndarray, tol: float, max_steps: int,
    g0: np.ndarray | None = None,
) -> np.ndarray:
    r"""The states `(len(y0), len(grid), dim)` of the trajectories from `y0` (numbered from
    `start` in errors), by one compiled integrator of this process (reused across calls);
    with configurations `g0`, `(len(y0), len(grid), dim + group.size)`, $(\mu, g)$."""
    import heyoka as hy

    ta = taylor_integrator(system, tol, configured=g0 is not None)
    start_states = y0 if g0 is None else np.concatenate([y0, g0], axis=1)
    out = np.empty((y0.shape[0], grid.shape[0], start_states.shape[1]))
    for i, y in enumerate(start_states):
        ta.time = 0.0
        ta.state[:] = y
        outcome, *_, states = ta.propagate_grid(grid, max_steps=max_steps)
        if outcome != hy.taylor_outcome.time_limit:
            raise RuntimeError(
                f"heyoka stopped trajectory {start + i} (y0={y.tolist()}) at t={ta.time} with outcome {outcome}"
            )
        out[i] = states
    return out


def ground_truth(
    system: AbstractPoissonSystem,
    y0: ArrayLike,
    h: float,
    n_steps: int,
    tol: float | None = None,
    *,
    progress: bool | None = None,
    max_steps: int = 0,
    seed: int | None = None,
    client: Any = None,
    chunk_size: int | None = None,
    g0: ArrayLike | None = None,
) -> Trajectories:
    r"""Integrate $\dot y = \mathbb{B}(y)\nabla H(y)$ (`system.heyoka_system()`; with the
    dissipation of a `DoubleBracket`) with heyoka's adaptive Taylor method and
    sample it at $t_n = n h$, $n = 0..n_\text{steps}$.

    The Taylor order and step follow from `tol` (default machine epsilon), so the local error
    is at round-off level: Casimirs and energy drift like a random walk of rounding errors.
    One compiled integrator serves every initial condition (re-set `time` and `state`, then
    `propagate_grid`): for these small systems a loop over one integrator beats heyoka's
    ensemble mode by a wide margin (benchmarks,
    [Ground truth][ground-truth-heyoka-taylor-vs-scipy-dop853-and-bdf-benchmarksground_truthpy]).

    **Arguments:**

    - `system`: an `AbstractPoissonSystem`.
    - `y0`: `(dim,)` or `(n_traj, dim)`, finite.
    - `h`: sampling step (> 0); `n_steps`: number of steps (integer >= 1).
    - `tol`: heyoka tolerance (> 0), default machine epsilon.
    - `progress`: `True`/`False` to force the tqdm bar; `None` shows it only on a terminal
      and for a run still going after 3 s.
    - `max_steps`: heyoka's cap on steps per trajectory (0: none).
    - `seed`: the seed that drew `y0`, if any; recorded in the data set's metadata.
    - `client`: a `dask.distributed.Client` (extra `dask`): the trajectories are integrated
      in chunks of `chunk_size` on its workers (each worker compiles the integrator once).
      The result is bitwise the same as without. For ensembles larger than memory, write
      them to a file chunk by chunk with `save_ground_truth`.
    - `chunk_size`: trajectories per task (default: about 16 MiB of output per chunk).
    - `g0`: initial configurations on `system.group`, `(group.size,)` (the same for every
      trajectory) or `(n_traj, group.size)`: then $\dot g = g\,\nabla H$ is integrated with
      the momenta (`system.heyoka_configured_system()`), and the result holds
      `configurations`.

    **Returns:** `Trajectories` with `states` of shape `(n_traj, n_steps + 1, dim)` (and
    `configurations` `(n_traj, n_steps + 1, group.size)` with `g0`).

    Raises `RuntimeError` naming the trajectory if heyoka stops early (non-finite state, step
    cap).
    """
    job = _job(system, y0, h, n_steps, tol, max_steps, seed, progress, chunk_size, g0)
    client = check_client(client)
    check_fits_in_memory(job.shape, "the requested trajectories (n_traj, n_steps + 1, dim)",
                         "ask for fewer trajectories or output times (a larger sampling step h and fewer n_steps for "
                         "the same final time: heyoka's own step is adaptive), or write them to a file chunk by "
                         "chunk with save_ground_truth")
    out = np.empty(job.shape)
    with _progress_bar(job.shape[0], progress) as bar:
        for k, states in map_unordered(integrate_chunk, job.chunks(), client=client, shared=(job.system,)):
            start = k * job.chunk_size
            out[start : start + states.shape[0]] = states
            bar.update(states.shape[0])
    return job.trajectories(out)


def save_ground_truth(
    path: str | os.PathLike,
    system: AbstractPoissonSystem,
    y0: ArrayLike,
    h: float,
    n_steps: int,
    tol: float | None = None,
    *,
    client: Any = None,
    chunk_size: int | None = None,
    progress: bool | None = None,
    max_steps: int = 0,
    seed: int | None = None,
    g0: ArrayLike | None = None,
) -> str:
    r"""`ground_truth(...)` written chunk by chunk to the HDF5 file `path` (the format of
    `Trajectories.save`), never holding more than a few chunks in memory: for ensembles
    larger than memory, and for large ones on a Dask cluster.

    The chunks go to `.<name>.partial.h5` beside `path` as they finish (on the workers of
    `client` if given, else here), which is renamed to `path` once complete. A rerun with the
    same arguments after a crash or Ctrl-C computes only the chunks missing from the partial
    file (a partial file of other arguments is started over). The data are bitwise those of
    `ground_truth(system, y0, h, n_steps, tol)`. Read them back with `Trajectories.load(path)`,
    or a part of them with `Trajectories.load(path, select=...)`.

    Arguments as in `ground_truth`; `chunk_size` trajectories per chunk (default about 16 MiB
    of output each); with `g0` the configurations are written beside the momenta (the
    `configurations` data set of `Trajectories.save`). **Returns** `path`.
    """
    job = _job(system, y0, h, n_steps, tol, max_steps, seed, progress, chunk_size, g0)
    client = check_client(client)
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"path must be a file name (str or os.PathLike); got {type(path).__name__}")
    path = os.fspath(path)
    if os.path.isdir(path):
        raise IsADirectoryError(f"cannot save to {path!r}: it is a folder; give a file name")
    partial = _partial_path(path)
    done = _open_partial(partial, job)
    log.info("ground truth %s: %d of %d chunks already in %s", path, len(done), job.n_chunks, partial)
    with _progress_bar(job.shape[0], progress) as bar:
        bar.update(sum(min(job.chunk_size, job.shape[0] - k * job.chunk_size) for k in done))
        for k, states in map_unordered(integrate_chunk, job.chunks(skip=done), client=client, shared=(job.system,)):
            start = k * job.chunk_size
            with h5py.File(partial, "r+") as f:  # closed after every chunk: a crash loses no chunk written
                f["trajectories"][start : start + states.shape[0]] = states[..., : system.dim]
                if job.g0 is not None:
                    f["configurations"][start : start + states.shape[0]] = states[..., system.dim :]
                f["chunk_done"][k] = True
            bar.update(states.shape[0])
    with h5py.File(partial, "r+") as f:
        del f["chunk_done"]
        del f.attrs["job"]
        first = job.y0[:1, None] if job.g0 is None else np.concatenate([job.y0[:1, None], job.g0[:1, None]], axis=-1)
        write_attributes(f, job.trajectories(first).metadata)
    with open(partial, "rb+") as fh:  # on disk before the rename makes it visible
        os.fsync(fh.fileno())
    os.replace(partial, path)  # the same folder: atomic
    return path


def _partial_path(path: str) -> str:
    directory, name = os.path.split(os.path.abspath(path))
    return os.path.join(directory, f".{name}.partial.h5")


def _partial_shapes(job: _Job) -> dict[str, tuple[int, ...]]:
    """The data sets of a job's partial file and their shapes: the momenta and, with
    configurations, the configurations."""
    n, m, width = job.shape
    dim = job.system.dim
    return {"trajectories": (n, m, dim), **({} if width == dim else {"configurations": (n, m, width - dim)})}


def _open_partial(partial: str, job: _Job) -> set[int]:
    """The chunks already in the partial file of this job; creates it (over a partial file of
    another job, or a damaged one) if needed."""
    fingerprint = job.fingerprint()
    if os.path.exists(partial):
        try:
            with h5py.File(partial, "r") as f:
                shapes = {name: f[name].shape for name in ("trajectories", "configurations") if name in f}
                if f.attrs.get("job") == fingerprint and shapes == _partial_shapes(job):
                    return {int(k) for k in np.flatnonzero(f["chunk_done"][...])}
        except (OSError, KeyError, ValueError):  # damaged by a crash mid-write: start over
            pass
        log.info("ground truth: starting %s over (it was of another request or damaged)", partial)
    os.makedirs(os.path.dirname(partial), exist_ok=True)
    with h5py.File(partial, "w") as f:
        for name, shape in _partial_shapes(job).items():
            per_traj = shape[1] * shape[2]
            f.create_dataset(name, shape=shape, dtype=np.float64,
                             chunks=(max(1, min(shape[0], 2**17 // per_traj)), *shape[1:]))
        f.create_dataset("times", data=job.grid)
        f.create_dataset("chunk_done", data=np.zeros(job.n_chunks, dtype=bool))
        f.attrs["job"] = fingerprint
    return set()
