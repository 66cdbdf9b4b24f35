r"""Side-by-side comparison of step maps, learned or classical, against the heyoka ground truth:
the same initial conditions, the same output times, the same figures, timed in one run."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from liepoisson.internals import check_system, positive_float, states
from liepoisson.systems import AbstractPoissonSystem

from ._diagnostics import DiagnosticsReport
from ._ground_truth import ground_truth
from ._rollout_figures import RolloutFigures, rollout_figures
from ._step_map import AbstractStepMap, check_h
from ._timing import step_timing
from ._trajectories import Trajectories


def _from_figures(name: str) -> property:
    """A row's read-only view of its figures' field `name` (documented on `RolloutFigures`)."""
    return property(lambda row: getattr(row.figures, name), doc=f"`RolloutFigures.{name}` of the row's map.")


@dataclasses.dataclass(frozen=True)
class ComparisonRow:
    """One map's row of a `Comparison`: its `label`, step `h` and `n_steps`, its `figures` (the
    `RolloutFigures` of its rollout against the reference: the error figures of a map that
    diverged are infinite), `seconds_per_step` (wall time of one step of one trajectory,
    `step_timing` in this run) and `flops_per_step` (XLA's count).

    The figures read as the row's own: `error_final`, `error_max`, `energy_error_max`,
    `casimir_drift_max`, `poisson_defect_max`, `divergence` (a `Divergence` in steps of the map,
    or `None`), `diverged_at_step`, `report`."""

    label: str
    h: float
    n_steps: int
    figures: RolloutFigures
    seconds_per_step: float
    flops_per_step: float

    error_final = _from_figures("error_final")
    error_max = _from_figures("error_max")
    energy_error_max = _from_figures("energy_error_max")
    casimir_drift_max = _from_figures("casimir_drift_max")
    poisson_defect_max = _from_figures("poisson_defect_max")
    divergence = _from_figures("divergence")
    report = _from_figures("report")
    diverged_at_step = _from_figures("diverged_at_step")


@dataclasses.dataclass(frozen=True)
class Comparison:
    """What `compare` measured: `rows` (one per map, in the order given), the output `times`
    and the `reference` (heyoka); `reports` (label -> `DiagnosticsReport` against the
    reference) are the rows' own. Figures of it: `plot_work_precision`, `plot_energy`."""

    rows: tuple[ComparisonRow, ...]
    times: np.ndarray
    reference: np.ndarray

    @property
    def reports(self) -> dict[str, DiagnosticsReport]:
        """label -> the map's `DiagnosticsReport` against the reference."""
        return {r.label: r.figures.report for r in self.rows}

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


def _labelled(maps: list[AbstractStepMap]) -> dict[str, AbstractStepMap]:
    """Label a sequence of maps by their `label` and step size (numbered where that repeats)."""
    out: dict[str, AbstractStepMap] = {}
    for i, m in enumerate(maps):
        if not isinstance(m, AbstractStepMap):
            raise TypeError(f"maps[{i}] must be an integrators.AbstractStepMap; got {type(m).__name__}")
        label = m.label if m.h is None else f"{m.label} h={m.h:g}"
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

    **Returns:** a `Comparison` (`.rows`, `.table()`; figures: `plot_work_precision(comparison,
    path)`, `plot_energy(comparison, path)`).
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
        if m.system != system:
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
    rows = []
    for label, m in maps.items():
        per_output = plans[label]
        n_steps = per_output * n_outputs
        y = np.asarray(m.rollout(y0s, n_steps, save_every=per_output, nonfinite="return"))
        figures = rollout_figures(m, y, ref, times, save_every=per_output, defect_points=defect_points)
        timing = step_timing(m, y0s, min_seconds=timing_seconds, repeats=timing_repeats, outputs=n_outputs)
        rows.append(ComparisonRow(label=label, h=float(m.h), n_steps=n_steps, figures=figures,
                                  seconds_per_step=timing.seconds_per_step, flops_per_step=m.cost().flops))
    return Comparison(tuple(rows), times, ref)
