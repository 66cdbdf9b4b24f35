r"""Side-by-side comparison of step maps, learned or classical, against the heyoka ground truth:
the same initial conditions, the same output times, the same figures, timed in one run."""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Callable, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike

from liepoisson.internals import check_system, positive_float, positive_int, states
from liepoisson.systems import AbstractPoissonSystem

from ._diagnostics import DiagnosticsReport, Divergence, diagnostics
from ._ground_truth import ground_truth
from ._plots import figure, series_styles, span_decades
from ._step_map import AbstractStepMap, check_h
from ._timing import step_timing
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


@dataclasses.dataclass(frozen=True)
class ComparisonRow:
    """One map's figures: `error_final` (max over trajectories of $|y(T) - y_\\text{ref}(T)|$),
    `error_max` (over all output times), `energy_error_max` (relative, as `diagnostics`),
    `casimir_drift_max` (relative), `poisson_defect_max` (over the first trajectory's outputs),
    as `RolloutFigures` (the error figures of a map that diverged are infinite);
    `seconds_per_step` (wall time of one step of one trajectory, `step_timing` in this run),
    `flops_per_step` (XLA's count) and `divergence` (a `Divergence` in steps of the map: the
    first non-finite step, the trajectory, its last finite state; or `None`)."""

    label: str
    h: float
    n_steps: int
    error_final: float
    error_max: float
    energy_error_max: float
    casimir_drift_max: float
    poisson_defect_max: float
    seconds_per_step: float
    flops_per_step: float
    divergence: Divergence | None

    @property
    def diverged_at_step(self) -> int | None:
        """The first step of the map at which some trajectory (or its energy, a Casimir or an
        integral) is not finite, or `None`."""
        return None if self.divergence is None else self.divergence.step


@dataclasses.dataclass(frozen=True)
class Comparison:
    """What `compare` measured: `rows` (one per map, in the order given), the output `times`,
    the `reference` (heyoka) and each map's `reports` (label -> `DiagnosticsReport` against
    the reference)."""

    rows: tuple[ComparisonRow, ...]
    times: np.ndarray
    reference: np.ndarray
    reports: dict[str, DiagnosticsReport]

    def table(self) -> str:
        """The rows as a Markdown table; a map that diverged has infinite errors, the step at
        which it did in the last column and, below the table, its last finite state."""
        head = ("map", "h", "error at T", "max error", "max rel. energy error", "max rel. Casimir drift",
                "max Poisson defect", "s / step", "flops / step", "diverged at step")
        lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for r in self.rows:
            cells = (r.label, f"{r.h:g}", *(f"{v:.3g}" for v in (
                r.error_final, r.error_max, r.energy_error_max, r.casimir_drift_max, r.poisson_defect_max,
                r.seconds_per_step, r.flops_per_step)), "—" if r.divergence is None else str(r.divergence.step))
            lines.append("| " + " | ".join(cells) + " |")
        diverged = [r for r in self.rows if r.divergence is not None]
        if diverged:
            lines.append("")
            lines += [f"{r.label} stopped being finite at {r.divergence}." for r in diverged]
        return "\n".join(lines) + "\n"

    def plot_work_precision(self, path: str | os.PathLike) -> None:
        """Error at the final time against wall time per step (log-log), one point per map (a
        map that diverged has no point, only its legend entry saying where it diverged)."""
        fig = figure(figsize=(6, 4), layout="constrained")
        ax = fig.subplots()
        for r, style in zip(self.rows, series_styles(len(self.rows))):
            style.pop("ls")
            if r.divergence is not None:
                ax.loglog([], [], ls="none", label=f"{r.label} (diverged at step {r.divergence.step})", **style)
                continue
            ax.loglog([r.seconds_per_step], [max(r.error_final, 1e-17)], ls="none", label=r.label, **style)
        span_decades(ax, "x")
        ax.set_xlabel("wall time per step and trajectory [s]")
        ax.set_ylabel("|y(T) - y_ref(T)|")
        ax.legend(fontsize=7)
        fig.savefig(os.fspath(path))

    def plot_energy(self, path: str | os.PathLike) -> None:
        """Relative energy error against time (log axis), the largest over trajectories; a map
        that diverged up to the last output before it did."""
        fig = figure(figsize=(7, 3.5), layout="constrained")
        ax = fig.subplots()
        for (label, report), row, style in zip(self.reports.items(), self.rows, series_styles(len(self.reports))):
            e = np.abs(report.energy_error_relative).reshape(-1, len(report.times)).max(axis=0)
            if row.divergence is not None:
                label = f"{label} (diverged at step {row.divergence.step})"
            ax.semilogy(report.times, np.maximum(e, 1e-17), lw=0.8, label=label, markevery=0.1, ms=3, **style)
        ax.set_xlabel("t")
        ax.set_ylabel("|E(t) - E(0)| / <E>")
        ax.legend(fontsize=7)
        fig.savefig(os.fspath(path))


def _labelled(maps: list[AbstractStepMap]) -> dict[str, AbstractStepMap]:
    """Label a sequence of maps by class and step size (numbered where that repeats)."""
    out: dict[str, AbstractStepMap] = {}
    for i, m in enumerate(maps):
        if not isinstance(m, AbstractStepMap):
            raise TypeError(f"maps[{i}] must be an integrators.AbstractStepMap; got {type(m).__name__}")
        label = type(m).__name__ if m.h is None else f"{type(m).__name__} h={m.h:g}"
        out[label if label not in out else f"{label} ({i})"] = m
    return out


def compare(
    maps: dict[str, AbstractStepMap] | Sequence[AbstractStepMap],
    system: AbstractPoissonSystem,
    y0s: ArrayLike,
    *,
    t_final: float,
    n_outputs: int = 100,
    reference: Trajectories | None = None,
    defect_points: int = 50,
    timing_seconds: float = 0.05,
    timing_repeats: int = 5,
) -> Comparison:
    r"""Roll every map out from the same initial conditions to `t_final` and measure it against
    the heyoka reference at `n_outputs` equally spaced times.

    **Arguments:** `maps`, a dict label -> step map (or a sequence, labelled by class and $h$),
    all of `system`, each with an $h$ that divides the output interval $t_\text{final} /
    n_\text{outputs}$; `y0s` `(n_traj, dim)` or `(dim,)`; `reference`: a `Trajectories` at the
    output times (default: `ground_truth` at tolerance eps); `defect_points`: how many output
    states of the first trajectory enter the Poisson defect; `timing_seconds`,
    `timing_repeats`: `step_timing`'s `min_seconds` and `repeats`.

    Every figure is `rollout_figures` of the map's rollout: a map that stops being finite has
    infinite error figures, and its row names the first non-finite step and the last finite
    state. The wall time per step is `step_timing` on the same initial conditions (the fastest
    of several compiled rollouts, each long enough that dispatch is a small part of it), beside
    XLA's flop count of a step.

    **Returns:** a `Comparison` (`.rows`, `.table()`, `.plot_work_precision(path)`,
    `.plot_energy(path)`).
    """
    system = check_system(system)
    t_final = positive_float(t_final, "t_final")
    if isinstance(n_outputs, bool) or not isinstance(n_outputs, int) or n_outputs < 1:
        raise ValueError(f"n_outputs must be an integer >= 1; got {n_outputs!r}")
    y0s = states(y0s, "y0s", system.dim).reshape(-1, system.dim)
    if not isinstance(maps, dict):
        maps = _labelled(list(maps))
    if not maps:
        raise ValueError("maps must hold at least one step map")
    interval = t_final / n_outputs
    plans = {}
    for label, m in maps.items():
        if not isinstance(m, AbstractStepMap):
            raise TypeError(f"maps[{label!r}] must be an integrators.AbstractStepMap; got {type(m).__name__}")
        if m.system is not system:
            raise ValueError(f"maps[{label!r}] is a map of {m.system!r}, not of the system compared, {system!r}")
        h = check_h(m)
        per_output = round(interval / h)
        if per_output < 1 or not math.isclose(per_output * h, interval, rel_tol=1e-9):
            raise ValueError(
                f"maps[{label!r}]: h = {h:g} must divide the output interval t_final / n_outputs = {interval:g}"
            )
        plans[label] = per_output
    if reference is None:
        reference = ground_truth(system, y0s, h=interval, n_steps=n_outputs)
    elif not isinstance(reference, Trajectories) or reference.states.shape != (len(y0s), n_outputs + 1, system.dim):
        raise ValueError(
            f"reference must be a Trajectories of shape ({len(y0s)}, {n_outputs + 1}, {system.dim}) at the output times"
        )
    ref = reference.states
    times = interval * np.arange(n_outputs + 1)
    rows, reports = [], {}
    for label, m in maps.items():
        per_output = plans[label]
        n_steps = per_output * n_outputs
        y = np.asarray(m.rollout(y0s, n_steps, save_every=per_output, nonfinite="return"))
        figures = rollout_figures(m, y, ref, times, save_every=per_output, defect_points=defect_points)
        timing = step_timing(m, y0s, min_seconds=timing_seconds, repeats=timing_repeats, outputs=n_outputs)
        rows.append(ComparisonRow(
            label=label, h=float(m.h), n_steps=n_steps,
            error_final=figures.error_final, error_max=figures.error_max,
            energy_error_max=figures.energy_error_max, casimir_drift_max=figures.casimir_drift_max,
            poisson_defect_max=figures.poisson_defect_max,
            seconds_per_step=timing.seconds_per_step, flops_per_step=m.cost().flops,
            divergence=figures.divergence,
        ))
        reports[label] = figures.report
    return Comparison(tuple(rows), times, ref, reports)


@dataclasses.dataclass(frozen=True)
class Convergence:
    """Global error at `t_final` (max over trajectories) for each step size `hs`, and the
    observed `order`: the slope of a least-squares line through $(\\log h, \\log e)$."""

    hs: np.ndarray
    errors: np.ndarray
    order: float

    def plot(self, path: str | os.PathLike, *, label: str = "") -> None:
        """Error against step size, log-log, with the observed order in the legend."""
        fig = figure(figsize=(5, 4), layout="constrained")
        ax = fig.subplots()
        ax.loglog(self.hs, self.errors, "o-", label=f"{label} (observed order {self.order:.2f})".strip())
        ax.set_xticks(self.hs, [f"{h:g}" for h in self.hs])  # the step sizes, not minor labels
        ax.minorticks_off()
        ax.set_xlabel("h")
        ax.set_ylabel("|y(T) - y_ref(T)|")
        ax.legend(fontsize=7)
        fig.savefig(os.fspath(path))


def convergence(
    make: Callable[[float], AbstractStepMap],
    system: AbstractPoissonSystem,
    y0s: ArrayLike,
    *,
    t_final: float,
    hs: Sequence[float],
) -> Convergence:
    r"""The error at `t_final` of `make(h)` for each `h` in `hs` against heyoka, and the
    observed order. `make(h)` returns a step map of `system` with step `h` (a splitting
    method, `lambda h: Strang(system, h)`, or a learned map run at another step than it was
    trained at, `lambda h: eqx.tree_at(lambda m: m.h, net, h)`); each `h` must divide
    `t_final`."""
    system = check_system(system)
    t_final = positive_float(t_final, "t_final")
    y0s = states(y0s, "y0s", system.dim).reshape(-1, system.dim)
    hs = np.asarray([positive_float(h, f"hs[{i}]") for i, h in enumerate(hs)])
    if len(hs) < 2:
        raise ValueError(f"hs must hold at least 2 step sizes to fit an order; got {len(hs)}")
    truth = ground_truth(system, y0s, h=t_final, n_steps=1).states[:, -1]
    errors = []
    for i, h in enumerate(hs):
        n = round(t_final / h)
        if n < 1 or not math.isclose(n * h, t_final, rel_tol=1e-9):
            raise ValueError(f"hs[{i}] = {h:g} must divide t_final = {t_final:g}")
        m = make(float(h))
        if not isinstance(m, AbstractStepMap) or m.system is not system:
            raise TypeError(f"make({h:g}) must return an integrators.AbstractStepMap of {system!r}; got {m!r}")
        y = np.asarray(m.rollout(y0s, n, save_every=n, nonfinite="return"))[:, -1]
        errors.append(float(np.max(np.linalg.norm(y - truth, axis=-1))))
    errors = np.asarray(errors)
    usable = errors > 0
    if usable.sum() < 2 or not np.all(np.isfinite(errors)):
        raise ValueError(f"cannot fit an order: errors {errors.tolist()} (need 2 finite, non-zero)")
    order = float(np.polyfit(np.log(hs[usable]), np.log(errors[usable]), 1)[0])
    return Convergence(hs, errors, order)
