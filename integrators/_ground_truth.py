r"""Ground truth: Taylor's method (heyoka) on $\dot y = \mathbb{B}(y)\nabla H(y)$, the ODE built
symbolically from the system's own Hamiltonian and Poisson tensor (`system.heyoka_system()`)."""

from __future__ import annotations

import json
import os
import weakref
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from liepoisson._progress import progress_bar, show_progress
from liepoisson._validation import as_state, positive_float, positive_int
from liepoisson.systems import SYSTEMS, AbstractPoissonSystem

from ._trajectories import Trajectories

#: Default tolerance of the Taylor integrator: double-precision machine epsilon.
EPS = float(np.finfo(np.float64).eps)

# Compiling a taylor_adaptive (LLVM JIT) costs ~0.1-1 s, far more than integrating one
# trajectory, so integrators are reused across calls. Catalogue systems are fully described by
# (class, params); any other system (a user Hamiltonian) is cached on the object itself.
_CACHE_BY_PARAMS: dict[tuple[Any, ...], Any] = {}
_CACHE_BY_OBJECT: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def taylor_integrator(
    system: AbstractPoissonSystem, tol: float | None = None, *, variational: bool = False
):
    """The (cached) `heyoka.taylor_adaptive` of `system` at tolerance `tol` (default eps).

    With `variational=True` the state is augmented by the first-order variational equations
    (`heyoka.var_ode_sys`): `state[dim:].reshape(dim, dim)[i, j]` is $\\partial y_i/\\partial y_j(0)$.
    Shared between calls: set `ta.time` and `ta.state` before every use.
    """
    import heyoka as hy

    if not isinstance(system, AbstractPoissonSystem):
        raise TypeError(f"system must be an AbstractPoissonSystem; got {type(system).__name__}")
    tol = EPS if tol is None else positive_float(tol, "tol")
    if SYSTEMS.get(system.name) is type(system):
        key = (type(system), json.dumps(system.params, sort_keys=True), tol, variational)
        cache = _CACHE_BY_PARAMS
    else:
        key = (tol, variational)
        cache = _CACHE_BY_OBJECT.setdefault(system, {})
    if key not in cache:
        ode = system.heyoka_system()
        if variational:
            ode = hy.var_ode_sys(ode, hy.var_args.vars, order=1)
        cache[key] = hy.taylor_adaptive(ode, [0.0] * system.dim, tol=tol)
    return cache[key]


def _initial_conditions(system: AbstractPoissonSystem, y0: ArrayLike) -> np.ndarray:
    y0 = np.asarray(as_state(y0, "y0", system.dim))
    if y0.ndim == 1:
        y0 = y0[None]
    if y0.ndim != 2:
        raise ValueError(
            f"y0 must have shape ({system.dim},) or (n_traj, {system.dim}); got shape {y0.shape}"
        )
    return y0


def _progress_bar(total: int, progress: bool | None):
    # Auto: on a terminal, and only for a run that is still going after a few seconds.
    return progress_bar(total, "ground truth", "traj", progress, delay=3.0 if progress is None else 0.0)


def check_fits_in_memory(shape: tuple[int, ...], what: str) -> None:
    """`ValueError` (before allocating) if a float64 array of `shape` is larger than the
    machine's available physical memory."""
    need = 8 * int(np.prod(shape, dtype=np.float64))
    try:
        free = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):  # not available on this platform
        return
    if need > free:
        raise ValueError(
            f"{what} of shape {shape} need {need / 2**30:.3g} GiB, more than the {free / 2**30:.3g} GiB "
            "of memory available; ask for fewer trajectories or steps, or save in chunks"
        )


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
) -> Trajectories:
    r"""Integrate $\dot y = \mathbb{B}(y)\nabla H(y)$ with heyoka's adaptive Taylor method and
    sample it at $t_n = n h$, $n = 0..n_\text{steps}$.

    The Taylor order and step follow from `tol` (default machine epsilon), so the local error
    is at round-off level: Casimirs and energy drift like a random walk of rounding errors.
    One compiled integrator serves every initial condition (re-set `time` and `state`, then
    `propagate_grid`): for these small systems a loop over one integrator beats heyoka's
    ensemble mode by a wide margin (see BENCHMARKS.md).

    **Arguments:**

    - `system`: an `AbstractPoissonSystem`.
    - `y0`: `(dim,)` or `(n_traj, dim)`, finite.
    - `h`: sampling step (> 0); `n_steps`: number of steps (integer >= 1).
    - `tol`: heyoka tolerance (> 0), default machine epsilon.
    - `progress`: `True`/`False` to force the tqdm bar; `None` shows it only on a terminal
      and for a run still going after 3 s.
    - `max_steps`: heyoka's cap on steps per trajectory (0: none).
    - `seed`: the seed that drew `y0`, if any; recorded in the data set's metadata.

    **Returns:** `Trajectories` with `states` of shape `(n_traj, n_steps + 1, dim)`.

    Raises `RuntimeError` naming the trajectory if heyoka stops early (non-finite state, step
    cap).
    """
    import heyoka as hy

    if not isinstance(system, AbstractPoissonSystem):
        raise TypeError(f"system must be an AbstractPoissonSystem; got {type(system).__name__}")
    h = positive_float(h, "h")
    n_steps = positive_int(n_steps, "n_steps")
    tol_used = EPS if tol is None else positive_float(tol, "tol")
    if not tol_used < 1.0:
        raise ValueError(f"tol must be a relative tolerance in (0, 1), e.g. 1e-12; got {tol!r}")
    max_steps = positive_int(max_steps, "max_steps", minimum=0)
    y0 = _initial_conditions(system, y0)
    show_progress(progress)  # validates it before any work
    check_fits_in_memory((y0.shape[0], n_steps + 1, system.dim), "the requested trajectories (n_traj, n_steps + 1, dim)")

    ta = taylor_integrator(system, tol_used)
    grid = h * np.arange(n_steps + 1, dtype=np.float64)
    out = np.empty((y0.shape[0], n_steps + 1, system.dim))
    with _progress_bar(y0.shape[0], progress) as bar:
        for i, y in enumerate(y0):
            ta.time = 0.0
            ta.state[:] = y
            outcome, *_, states = ta.propagate_grid(grid, max_steps=max_steps)
            if outcome != hy.taylor_outcome.time_limit:
                raise RuntimeError(
                    f"heyoka stopped trajectory {i} (y0={y.tolist()}) at t={ta.time} with "
                    f"outcome {outcome}"
                )
            out[i] = states
            bar.update(1)
    return Trajectories(
        out, h, system, times=grid, integrator="heyoka-taylor", tolerance=tol_used, seed=seed
    )
