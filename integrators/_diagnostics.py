r"""Diagnostics of a computed trajectory: Casimir drift, relative energy error, error against a
reference, and a plot of them."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from liepoisson.systems import AbstractPoissonSystem

from ._trajectories import Trajectories

# |<C>| below this is "zero" (e.g. Pi.p = 0 for Kirchhoff): the relative drift then divides by 1,
# i.e. falls back to the absolute drift, rather than blowing up.
_TINY = 1e-12


def _safe_denominator(mean: np.ndarray) -> np.ndarray:
    return np.where(np.abs(mean) > _TINY, mean, 1.0)


@dataclasses.dataclass(frozen=True)
class Divergence:
    r"""Where a trajectory stopped being finite.

    - `step`: the first step at which some trajectory is not finite (an index into the states
      given to `diagnostics`; a step of the map in `rollout_figures` and `compare`), or, in
      `diagnostics`, at which its energy, a Casimir or an integral is not (a state on its way
      out overflows those first);
    - `trajectory`: which one (the lowest index among those not finite at `step`; 0 for a
      single trajectory);
    - `state`: its last finite state (with finite energy, Casimirs and integrals), the one at
      `step - 1`.
    """

    step: int
    trajectory: int
    state: np.ndarray

    def __str__(self) -> str:
        return (f"step {self.step} (trajectory {self.trajectory}; last finite state, at step {self.step - 1}: "
                f"{np.round(self.state, 6).tolist()})")


def first_divergence(y: np.ndarray) -> Divergence | None:
    """The `Divergence` of states `y` `(n_traj, T, dim)`, or `None` if they are all finite."""
    finite = np.isfinite(y).all(axis=-1)  # (n_traj, T)
    if finite.all():
        return None
    first = np.where(finite.all(axis=1), y.shape[1], np.argmin(finite, axis=1))
    i = int(np.argmin(first))  # ties: the lowest trajectory index
    k = int(first[i])
    return Divergence(step=k, trajectory=i, state=y[i, k - 1] if k else y[i, 0])


@dataclasses.dataclass(frozen=True)
class DiagnosticsReport:
    r"""Time series and summaries of a trajectory's conservation and accuracy.

    Arrays have the trajectory's leading shape: `(T,)` for one trajectory, `(n_traj, T)` for
    many (a trailing `k` axis for Casimirs).

    - `casimirs`: $C(t)$; `casimir_drift`: $C(t) - C(0)$;
      `casimir_drift_relative`: $(C(t) - C(0))/\langle C\rangle$, $\langle\cdot\rangle$ the time
      mean (paper's figure captions), divided by 1 where $|\langle C\rangle| < 10^{-12}$.
    - `energy`: $E(t) = H(y(t))$; `energy_error_relative`: $(E(t) - E(0))/\langle E\rangle$
      (the paper's relative energy error), with the same safe denominator.
    - `trajectory_error`: $\|y(t) - y_\text{ref}(t)\|_2$ per time, or `None` without reference.
    - `integrals`, `integral_error_relative`: name $\to I(t)$ and $(I(t) - I(0))/\langle I\rangle$
      for the extra conserved quantities passed to `diagnostics` (e.g. the charged particle's
      $I = x_1p_2 - x_2p_1 + r^3/3$).
    - `divergence`: where the trajectory stopped being finite (a `Divergence`: the first step at
      which some trajectory, or its energy, a Casimir or an integral, is not finite; which one;
      its last finite state), or `None`. The time series above then cover the steps before it.

    The divergence policy: the scalar figures of a trajectory that stopped being finite
    (`max_energy_error`, `max_casimir_drift_relative`, `max_trajectory_error`, the means,
    `max_integral_error`, `summary()`) are infinite, never those of its finite steps alone, which
    would pass a diverged map for a good one; `before_divergence()` gives those on request.
    """

    times: np.ndarray
    casimirs: np.ndarray
    casimir_drift: np.ndarray
    casimir_drift_relative: np.ndarray
    energy: np.ndarray
    energy_error_relative: np.ndarray
    trajectory_error: np.ndarray | None
    integrals: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)
    integral_error_relative: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)
    divergence: Divergence | None = None

    @property
    def diverged_at_step(self) -> int | None:
        """The first step at which some trajectory, or its energy, a Casimir or an integral, is not
        finite (`divergence.step`), or `None`."""
        return None if self.divergence is None else self.divergence.step

    def before_divergence(self) -> DiagnosticsReport:
        """The report of the steps before the divergence, as if they were the whole trajectory:
        its figures are those of the finite steps alone (what happened before; never the
        figures of the map). The report itself if the trajectory stayed finite."""
        return dataclasses.replace(self, divergence=None)

    def _figure(self, values: np.ndarray) -> float:
        """`values` (finite) as a figure of the trajectory: infinite if it diverged."""
        return math.inf if self.divergence is not None else float(values)

    @property
    def max_casimir_drift(self) -> float:
        """$\\max_t |C(t) - C(0)|$ over all Casimirs and trajectories (0 if there are none)."""
        return self._figure(np.max(np.abs(self.casimir_drift), initial=0.0))

    @property
    def mean_casimir_drift(self) -> float:
        return self._figure(np.mean(np.abs(self.casimir_drift)) if self.casimir_drift.size else 0.0)

    @property
    def max_casimir_drift_relative(self) -> float:
        """$\\max_t |C(t) - C(0)|/|\\langle C\\rangle|$ over all Casimirs and trajectories."""
        return self._figure(np.max(np.abs(self.casimir_drift_relative), initial=0.0))

    @property
    def mean_casimir_drift_relative(self) -> float:
        a = self.casimir_drift_relative
        return self._figure(np.mean(np.abs(a)) if a.size else 0.0)

    @property
    def max_energy_error(self) -> float:
        """$\\max_t |E(t) - E(0)|/|\\langle E\\rangle|$ over all trajectories."""
        return self._figure(np.max(np.abs(self.energy_error_relative)))

    @property
    def mean_energy_error(self) -> float:
        return self._figure(np.mean(np.abs(self.energy_error_relative)))

    @property
    def max_trajectory_error(self) -> float | None:
        return None if self.trajectory_error is None else self._figure(np.max(self.trajectory_error))

    @property
    def mean_trajectory_error(self) -> float | None:
        return None if self.trajectory_error is None else self._figure(np.mean(self.trajectory_error))

    def max_integral_error(self, name: str) -> float:
        r"""$\max_t |I(t) - I(0)|/|\langle I\rangle|$ of the integral `name`."""
        if name not in self.integral_error_relative:
            raise KeyError(f"no integral {name!r}; this report has {sorted(self.integral_error_relative)}")
        return self._figure(np.max(np.abs(self.integral_error_relative[name])))

    def error_growth_rate(self, window: tuple[float, float]) -> float:
        """`error_growth_rate` of the largest trajectory error at each time over `window`."""
        if self.trajectory_error is None:
            raise ValueError("error_growth_rate needs a report made with a reference")
        error = self.trajectory_error.reshape(-1, self.trajectory_error.shape[-1]).max(axis=0)
        return error_growth_rate(self.times[: len(error)], error, window)

    def summary(self) -> dict[str, float | None]:
        """The scalar figures, for tables and logs."""
        return {
            "diverged_at_step": self.diverged_at_step,
            **{f"max_integral_error[{k}]": self.max_integral_error(k) for k in self.integral_error_relative},
            "max_casimir_drift": self.max_casimir_drift,
            "mean_casimir_drift": self.mean_casimir_drift,
            "max_casimir_drift_relative": self.max_casimir_drift_relative,
            "mean_casimir_drift_relative": self.mean_casimir_drift_relative,
            "max_energy_error": self.max_energy_error,
            "mean_energy_error": self.mean_energy_error,
            "max_trajectory_error": self.max_trajectory_error,
            "mean_trajectory_error": self.mean_trajectory_error,
        }

    def __getitem__(self, key: str) -> Any:  # dict-like access to fields and summaries
        if key in self.summary():
            return self.summary()[key]
        if key in {f.name for f in dataclasses.fields(self)}:
            return getattr(self, key)
        raise KeyError(key)


def _as_path(trajectory: Any, name: str, dim: int) -> tuple[np.ndarray, np.ndarray | None]:
    if isinstance(trajectory, Trajectories):
        return trajectory.states, trajectory.times
    try:
        arr = np.asarray(trajectory, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise TypeError(f"{name} must be an array (T, {dim}) or (n_traj, T, {dim}); got {type(trajectory).__name__}") from err
    if arr.ndim not in (2, 3) or arr.shape[-1] != dim:
        raise ValueError(f"{name} must have shape (T, {dim}) or (n_traj, T, {dim}); got shape {arr.shape}")
    return arr, None


#: `per_state` evaluates on at least this many states, padded to a power of two.
MIN_BUCKET = 256


def per_state(fn: Callable[[Any], ArrayLike], y: np.ndarray) -> np.ndarray:
    """`fn(y)` for a function of states `(..., dim)` with one value (or vector) per state,
    evaluated on the states flattened and padded (with the first state) to a power of two of
    at least `MIN_BUCKET`: JAX compiles its operations once per padded length, not once per
    trajectory length (scoring flights of 50 lengths compiled 50 times). Each state's value is
    the unpadded one to the bit (the operations act state by state)."""
    dim = y.shape[-1]
    flat = y.reshape(-1, dim)
    n = flat.shape[0]
    padded = max(MIN_BUCKET, 1 << max(n - 1, 0).bit_length())
    if padded > n:
        flat = np.concatenate([flat, np.repeat(flat[:1], padded - n, axis=0)])
    out = np.asarray(fn(flat))[:n]
    return out.reshape(y.shape[:-1] + out.shape[1:])


def diagnostics(
    trajectory: ArrayLike | Trajectories,
    system: AbstractPoissonSystem,
    reference: ArrayLike | Trajectories | None = None,
    times: ArrayLike | None = None,
    *,
    integrals: Mapping[str, Callable[[np.ndarray], ArrayLike]] | None = None,
) -> DiagnosticsReport:
    r"""Casimir drift, relative energy error and (with `reference`) the error over time.

    **Arguments:**

    - `trajectory`: `(T, dim)`, `(n_traj, T, dim)` or a `Trajectories`.
    - `system`: the `AbstractPoissonSystem` (its `hamiltonian` and `casimirs`).
    - `reference`: same shape (or a `Trajectories`), e.g. the ground truth, or `None`.
    - `times`: `(T,)`; default the times of `trajectory` or `reference` if either is a
      `Trajectories`, else the step index `0..T-1`.
    - `integrals`: name $\to$ `f(y)`, further conserved quantities evaluated on states
      `(..., dim)` and reported like the energy.

    A trajectory that stops being finite (a diverged rollout) has its time series up to the
    step before the first non-finite state of any trajectory, or the first state whose energy,
    Casimirs or integrals are not finite (an integral that is NaN for another reason, such as
    `arccos` of $1 + \epsilon$, counts too: make it finite on the states it is given), and
    infinite figures (see `DiagnosticsReport`: `divergence` says where); a non-finite initial
    state or reference is a `ValueError`.

    For a dissipative system (`liepoisson.systems.DoubleBracket`) the "energy error" is the
    change of $H$ from its initial value, which the physics makes: compare with the energy of
    `reference` instead, as study W3 does.

    **Returns:** a `DiagnosticsReport` (see there for the definitions).
    """
    if not isinstance(system, AbstractPoissonSystem):
        raise TypeError(f"system must be an AbstractPoissonSystem; got {type(system).__name__}")
    y, t_data = _as_path(trajectory, "trajectory", system.dim)
    ref, t_ref = (None, None) if reference is None else _as_path(reference, "reference", system.dim)
    T = y.shape[-2]
    if times is None:
        t_known = t_data if t_data is not None else t_ref
        times = t_known if t_known is not None else np.arange(T, dtype=np.float64)
    times = np.asarray(times, dtype=np.float64)
    if times.shape != (T,):
        raise ValueError(f"times must have shape ({T},) to match trajectory; got {times.shape}")

    if ref is not None and ref.shape != y.shape:
        raise ValueError(f"reference must have the trajectory's shape {y.shape}; got {ref.shape}")
    divergence = first_divergence(y.reshape(-1, T, system.dim))
    diverged = None if divergence is None else divergence.step
    if diverged == 0:
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(y[..., 0, :]))[0])
        where = f"trajectory {bad[0]}, component {bad[1]}" if y.ndim == 3 else f"component {bad[0]}"
        raise ValueError(f"trajectory must start finite; the initial state has {where} = {y[..., 0, :][bad]}")
    if ref is not None and not np.all(np.isfinite(ref)):
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(ref))[0])
        raise ValueError(f"reference must be finite; found {ref[bad]} at index {bad}")
    if diverged is not None:
        y, times = y[..., :diverged, :], times[:diverged]
        ref = None if ref is None else ref[..., :diverged, :]

    for name, f in (integrals or {}).items():
        if not callable(f):
            raise TypeError(f"integrals[{name!r}] must be callable f(y) -> values; got {f!r}")
    # A finite state far out can overflow its energy, a Casimir or an integral (a rollout on its
    # way out): the series then end before the first step where one of those is not finite.
    with np.errstate(over="ignore", invalid="ignore"):
        C = per_state(system.casimirs, y)  # (..., T, k)
        E = per_state(system.hamiltonian, y)  # (..., T)
        values = {name: np.asarray(f(y), dtype=np.float64) for name, f in (integrals or {}).items()}
    for name, I in values.items():
        if I.shape != E.shape:
            raise ValueError(f"integrals[{name!r}] must return one value per state, shape {E.shape}; got {I.shape}")
    finite = np.isfinite(E) & np.isfinite(C).all(axis=-1)
    for I in values.values():
        finite &= np.isfinite(I)
    if not finite.all():
        overflow = first_divergence(np.where(finite[..., None], y, np.nan).reshape(-1, finite.shape[-1], system.dim))
        i, k = overflow.trajectory, overflow.step
        paths = y.reshape(-1, finite.shape[-1], system.dim)
        if k == 0:
            first = {"energy": E, **{f"integral {name!r}": I for name, I in values.items()}}
            bad = [f"{name} {v.reshape(len(paths), -1)[i, 0]}" for name, v in first.items()
                   if not np.isfinite(v.reshape(len(paths), -1)[i, 0])]
            bad += ["a non-finite Casimir"] if not np.isfinite(C.reshape(len(paths), -1, C.shape[-1])[i, 0]).all() else []
            raise ValueError(f"trajectory must start with a finite energy, Casimirs and integrals; the initial "
                             f"state {paths[i, 0].tolist()} of trajectory {i} has {', '.join(bad)}")
        divergence = Divergence(step=k, trajectory=i, state=paths[i, k - 1])
        y, times, C, E = y[..., :k, :], times[:k], C[..., :k, :], E[..., :k]
        ref = None if ref is None else ref[..., :k, :]
        values = {name: I[..., :k] for name, I in values.items()}
    dC = C - C[..., :1, :]
    dC_rel = dC / _safe_denominator(np.mean(C, axis=-2, keepdims=True))
    dE_rel = (E - E[..., :1]) / _safe_denominator(np.mean(E, axis=-1, keepdims=True))
    errors = {name: (I - I[..., :1]) / _safe_denominator(np.mean(I, axis=-1, keepdims=True))
              for name, I in values.items()}
    error = None
    if ref is not None:
        error = np.linalg.norm(y - ref, axis=-1)
    return DiagnosticsReport(times, C, dC, dC_rel, E, dE_rel, error, values, errors, divergence)


def error_growth_rate(times: ArrayLike, error: ArrayLike, window: tuple[float, float]) -> float:
    r"""The rate $\lambda$ of $e(t) \approx c\,e^{\lambda t}$: least-squares slope of $\log e$
    against $t$ over the points with $t$ in `window` $= (t_0, t_1)$ and finite $e > 0$.

    **Arguments:** `times` and `error`, both `(T,)`; `window`, a pair $t_0 < t_1$.

    **Returns:** $\lambda$ (the paper's "error ~ exp(0.25 t)" for Kirchhoff, E5).

    Raises `ValueError` for mismatched shapes, a window with $t_0 \ge t_1$, or fewer than two
    usable points in it."""
    times = np.asarray(times, dtype=np.float64)
    error = np.asarray(error, dtype=np.float64)
    if times.ndim != 1 or times.shape != error.shape:
        raise ValueError(f"times and error must be 1-D of the same shape; got {times.shape} and {error.shape}")
    try:
        bounds = np.asarray(window, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise TypeError(f"window must be a pair of numbers (t_min, t_max); got {window!r}") from err
    if bounds.shape != (2,):
        raise ValueError(f"window must be a pair (t_min, t_max); got {window!r}")
    t0, t1 = float(bounds[0]), float(bounds[1])
    if not t0 < t1:
        raise ValueError(f"window must have t_min < t_max; got {window!r}")
    inside = (times >= t0) & (times <= t1)
    mask = inside & (error > 0) & np.isfinite(error)
    if mask.sum() < 2:
        raise ValueError(
            f"error_growth_rate needs at least 2 points with t in window {window!r} and finite error > 0; "
            f"{int(inside.sum())} times lie in the window, {int(mask.sum())} of them with such an error"
        )
    return float(np.polyfit(times[mask], np.log(error[mask]), 1)[0])
