r"""The figures of one map's rollout against a reference (errors, energy, Casimirs, integrals,
Poisson defect, where it diverged): the one evaluation path of `compare` and of the paper's
experiments."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping

import numpy as np
from numpy.typing import ArrayLike

from liepoisson.internals import positive_int

from ._diagnostics import DiagnosticsReport, Divergence, diagnostics
from ._step_map import AbstractStepMap
from ._trajectories import Trajectories


@dataclasses.dataclass(frozen=True)
class RolloutFigures:
    r"""The figures of one map's rollout, under the divergence policy: a rollout that stopped
    being finite has every error figure infinite, never the figures of its finite steps alone
    (those are in `report.before_divergence()`), and `divergence` says where it stopped.

    - `error_final`: $\max_i \|y_i(T) - y_{\text{ref},i}(T)\|_2$ over the trajectories $i$ at the
      last saved time; `error_max`: the same maximum over every saved time (both `None` without
      a reference);
    - `energy_error_max`, `energy_error_mean`: the maximum and the mean over trajectories and
      saved times of $|E(t) - E(0)|/|\langle E\rangle|$ ($\langle\cdot\rangle$ the time mean of
      each trajectory, as `diagnostics`); `energy_error_max_per_trajectory` `(n_traj,)`: the
      maximum of each trajectory over all its saved times, infinite for those that diverged (a
      trajectory that stayed finite keeps its own figure when another one diverged);
    - `casimir_drift_max`: $\max |C(t) - C(0)|/|\langle C\rangle|$ over Casimirs, trajectories
      and saved times (0 for a system without Casimirs);
    - `integral_error_max`: name $\to$ the same maximum for each integral passed;
    - `poisson_defect_max`: the largest `poisson_defect` of the map over the states sampled (see
      `rollout_figures`; finite states only), or `None` if none were asked for;
    - `divergence`: a `Divergence` in steps of the map (the first step at which a trajectory,
      or its energy, a Casimir or an integral, is not finite; which one; its last finite
      state), or `None`;
    - `report`: the `DiagnosticsReport` of the saved states (time series, for plots).
    """

    error_final: float | None
    error_max: float | None
    energy_error_max: float
    energy_error_mean: float
    energy_error_max_per_trajectory: np.ndarray
    casimir_drift_max: float
    integral_error_max: dict[str, float]
    poisson_defect_max: float | None
    divergence: Divergence | None
    report: DiagnosticsReport

    @property
    def diverged_at_step(self) -> int | None:
        """The first step of the map at which some trajectory (or its energy, a Casimir or an
        integral) is not finite, or `None`."""
        return None if self.divergence is None else self.divergence.step


def rollout_figures(
    step_map: AbstractStepMap,
    trajectory: ArrayLike,
    reference: ArrayLike | Trajectories | None = None,
    times: ArrayLike | None = None,
    *,
    save_every: int = 1,
    integrals: Mapping[str, Callable[[np.ndarray], ArrayLike]] | None = None,
    defect_points: int = 50,
    defect_seed: int | None = None,
) -> RolloutFigures:
    r"""The figures of `trajectory`, a rollout of `step_map`, against `reference`: the one
    evaluation path of `compare` and of the paper's experiments (see `RolloutFigures` for the
    definitions and the divergence policy).

    **Arguments:**

    - `step_map`: the `AbstractStepMap` rolled out (its `system` gives $H$ and the Casimirs).
    - `trajectory`: `step_map.rollout(y0s, n_steps, save_every=save_every, nonfinite="return")`,
      `(n_traj, T, dim)` or `(T, dim)`, with its non-finite tail if it diverged.
    - `reference`, `times`, `integrals`: as `diagnostics`.
    - `save_every`: the spacing of the saved states in steps of the map. If the rollout diverged
      between two saved states, the states in between are rolled out again from `trajectory`'s
      initial states to find the first non-finite step and the last finite state.
    - `defect_points`: how many finite saved states enter the Poisson defect (0: none);
      `defect_seed`: `None` takes them equally spaced along the first trajectory; an integer
      draws them at random, without replacement, from every trajectory
      (`numpy.random.default_rng(defect_seed)`).

    **Returns:** a `RolloutFigures`.
    """
    if not isinstance(step_map, AbstractStepMap):
        raise TypeError(f"step_map must be an integrators.AbstractStepMap; got {type(step_map).__name__}")
    system = step_map.system
    save_every = positive_int(save_every, "save_every")
    defect_points = positive_int(defect_points, "defect_points", minimum=0)
    if defect_seed is not None and (isinstance(defect_seed, bool) or not isinstance(defect_seed, int)):
        raise TypeError(f"defect_seed must be None or an integer; got {defect_seed!r}")
    report = diagnostics(trajectory, system, reference, times, integrals=integrals)
    y = np.asarray(trajectory.states if isinstance(trajectory, Trajectories) else trajectory, dtype=np.float64)
    y = y.reshape(-1, *y.shape[-2:])
    n_ok = y.shape[1] if report.divergence is None else report.divergence.step

    energy = np.abs(report.energy_error_relative).reshape(len(y), -1)
    per_trajectory = np.full(len(y), math.inf)
    if report.divergence is None:
        per_trajectory = energy.max(axis=1)
    else:
        # Each trajectory on its own: infinite if it diverged (a non-finite state, or an energy,
        # Casimir or integral that overflows), else the maximum over all its saved times.
        for i in np.flatnonzero(np.isfinite(y).all(axis=(1, 2))):
            per_trajectory[i] = diagnostics(y[i], system, integrals=integrals).max_energy_error

    divergence = report.divergence
    if divergence is not None:
        divergence = dataclasses.replace(divergence, step=divergence.step * save_every)
        if save_every > 1:  # find the step between the two saved states
            rerun = np.asarray(step_map.rollout(y[:, 0], divergence.step, nonfinite="return"))
            exact = diagnostics(rerun, system, integrals=integrals).divergence
            divergence = exact or divergence  # (a rerun that stays finite keeps the saved states' figure)

    defect = None
    if defect_points:
        if defect_seed is None:
            good = y[0, :n_ok]
            pick = good[np.linspace(0, len(good) - 1, min(defect_points, len(good))).astype(int)]
        else:
            good = y[:, :n_ok].reshape(-1, y.shape[-1])
            rng = np.random.default_rng(defect_seed)
            pick = good[rng.choice(len(good), size=min(defect_points, len(good)), replace=False)]
        defect = float(np.max(np.asarray(step_map.poisson_defect(pick))))

    error = report.trajectory_error
    return RolloutFigures(
        error_final=None if error is None else (
            math.inf if divergence is not None else float(np.max(error[..., -1]))),
        error_max=report.max_trajectory_error,
        energy_error_max=report.max_energy_error,
        energy_error_mean=report.mean_energy_error,
        energy_error_max_per_trajectory=per_trajectory,
        casimir_drift_max=report.max_casimir_drift_relative,
        integral_error_max={name: report.max_integral_error(name) for name in report.integral_error_relative},
        poisson_defect_max=defect,
        divergence=divergence,
        report=report,
    )
