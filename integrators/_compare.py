r"""Side-by-side comparison of step maps, learned or classical, against the heyoka ground truth:
the same initial conditions, the same output times, the same figures, timed in one run."""

from __future__ import annotations

import dataclasses
import math
import os
import time
from collections.abc import Callable, Sequence

import jax
import numpy as np
from numpy.typing import ArrayLike

from liepoisson._validation import check_system, positive_float, states
from liepoisson.systems import AbstractPoissonSystem

from ._diagnostics import DiagnosticsReport, diagnostics
from ._ground_truth import ground_truth
from ._plots import figure, series_styles, span_decades
from ._step_map import AbstractStepMap
from ._trajectories import Trajectories


@dataclasses.dataclass(frozen=True)
class ComparisonRow:
    """One map's figures: `error_final` (max over trajectories of $|y(T) - y_\\text{ref}(T)|$),
    `error_max` (over all output times), `energy_error_max` (relative, as `diagnostics`),
    `casimir_drift_max` (relative), `poisson_defect_max` (over the first trajectory's outputs),
    `seconds_per_step` (wall time of one step of one trajectory, measured on the compiled
    rollout in this run), `flops_per_step` (XLA) and `diverged_at_step` (output index, or
    None)."""

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
    diverged_at_step: int | None


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
        """The rows as a Markdown table."""
        head = ("map", "h", "error at T", "max error", "max rel. energy error", "max rel. Casimir drift",
                "max Poisson defect", "s / step", "flops / step")
        lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for r in self.rows:
            cells = (r.label, f"{r.h:g}", *(f"{v:.3g}" for v in (
                r.error_final, r.error_max, r.energy_error_max, r.casimir_drift_max, r.poisson_defect_max,
                r.seconds_per_step, r.flops_per_step)))
            lines.append("| " + " | ".join(cells) + " |")
        return "\n".join(lines) + "\n"

    def plot_work_precision(self, path: str | os.PathLike) -> None:
        """Error at the final time against wall time per step (log-log), one point per map."""
        fig = figure(figsize=(6, 4), layout="constrained")
        ax = fig.subplots()
        for r, style in zip(self.rows, series_styles(len(self.rows))):
            style.pop("ls")
            ax.loglog([r.seconds_per_step], [max(r.error_final, 1e-17)], ls="none", label=r.label, **style)
        span_decades(ax, "x")
        ax.set_xlabel("wall time per step and trajectory [s]")
        ax.set_ylabel("|y(T) - y_ref(T)|")
        ax.legend(fontsize=7)
        fig.savefig(os.fspath(path))

    def plot_energy(self, path: str | os.PathLike) -> None:
        """Relative energy error against time (log axis), the largest over trajectories."""
        fig = figure(figsize=(7, 3.5), layout="constrained")
        ax = fig.subplots()
        for (label, report), style in zip(self.reports.items(), series_styles(len(self.reports))):
            e = np.abs(report.energy_error_relative).reshape(-1, len(report.times)).max(axis=0)
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
) -> Comparison:
    r"""Roll every map out from the same initial conditions to `t_final` and measure it against
    the heyoka reference at `n_outputs` equally spaced times.

    **Arguments:** `maps`, a dict label -> step map (or a sequence, labelled by class and $h$),
    all of `system`, each with an $h$ that divides the output interval $t_\text{final} /
    n_\text{outputs}$; `y0s` `(n_traj, dim)` or `(dim,)`; `reference`: a `Trajectories` at the
    output times (default: `ground_truth` at tolerance eps); `defect_points`: how many output
    states of the first trajectory enter the Poisson defect.

    **Returns:** a `Comparison` (`.rows`, `.table()`, `.plot_work_precision(path)`,
    `.plot_energy(path)`). Wall times come from a second, compiled run of each rollout.
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
        h = m._check_h()
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
        jax.block_until_ready(m.rollout(y0s, n_steps, save_every=per_output, nonfinite="return"))  # compile
        start = time.perf_counter()
        y = np.asarray(jax.block_until_ready(m.rollout(y0s, n_steps, save_every=per_output, nonfinite="return")))
        seconds = (time.perf_counter() - start) / (n_steps * len(y0s))
        report = diagnostics(y, system, reference=ref, times=times)
        good = y[0, : len(report.times)]
        pick = good[np.linspace(0, len(good) - 1, min(defect_points, len(good))).astype(int)]
        rows.append(ComparisonRow(
            label=label, h=float(m.h), n_steps=n_steps,
            error_final=float(np.max(report.trajectory_error[..., -1])) if report.diverged_at_step is None
            else math.inf,
            error_max=float(np.max(report.trajectory_error)),
            energy_error_max=report.max_energy_error,
            casimir_drift_max=report.max_casimir_drift_relative,
            poisson_defect_max=float(np.max(np.asarray(m.poisson_defect(pick)))),
            seconds_per_step=seconds, flops_per_step=m.cost().flops,
            diverged_at_step=report.diverged_at_step,
        ))
        reports[label] = report
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
