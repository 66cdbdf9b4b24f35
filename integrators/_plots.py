"""Figures of trajectories and their conservation: the one plotting path of the library
(matplotlib's object API, no pyplot: no GUI backend, no global state). matplotlib is an
extra (`pip install 'liepoisson[paper]'`)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from liepoisson.systems import AbstractPoissonSystem

from ._comparison import Comparison
from ._convergence import Convergence
from ._diagnostics import DiagnosticsReport
from ._files import atomic_path

# Line styles by position: the reference first, then the maps compared with it.
_STYLES = ("b-", "r--", "g:", "m-.", "c--", "y:")
# Exact zeros (t = 0, round-off hits) have no place on a log axis: floored there.
_LOG_FLOOR = 1e-17


def series_styles(n: int) -> list[dict[str, Any]]:
    """`n` distinguishable line styles (colour, marker, dash) for up to 20 colours x 4 markers:
    the default colour cycle repeats after 10 and a plot of many maps would share colours."""
    from matplotlib import colormaps

    markers, dashes = ("o", "s", "^", "D"), ("-", "--", "-.", ":")
    return [{"color": colormaps["tab20"](k % 20), "marker": markers[(k // 10) % 4], "ls": dashes[(k // 5) % 4]}
            for k in range(n)]


def span_decades(ax: Any, axis: str = "x", decades: float = 1.2) -> None:
    """Widen a log axis to at least `decades` (> 1) around its data and label only its powers
    of ten, at least one of which is then in view: matplotlib labels the minor ticks of a
    log axis spanning a decade or two, and those labels overlap."""
    from matplotlib.ticker import NullFormatter

    lo, hi = ax.get_xlim() if axis == "x" else ax.get_ylim()
    if lo > 0 and hi > 0 and np.log10(hi / lo) < decades:
        centre, half = np.sqrt(lo * hi), 10 ** (decades / 2)
        (ax.set_xlim if axis == "x" else ax.set_ylim)(centre / half, centre * half)
    (ax.xaxis if axis == "x" else ax.yaxis).set_minor_formatter(NullFormatter())


def figure(**kwargs: Any):
    """A matplotlib `Figure` (object API), or ImportError saying how to get matplotlib."""
    try:
        from matplotlib.figure import Figure
    except ImportError as err:
        raise ImportError("figures need matplotlib: pip install 'liepoisson[paper]'") from err
    return Figure(**kwargs)


def save_figure(fig: Any, path: str | os.PathLike, **kwargs: Any) -> Path:
    """`fig.savefig` to `path` atomically (`atomic_path`: a figure interrupted, or drawn by two
    processes at once, never leaves a half file; a symlink at `path` is replaced, not written
    through), in the format `format=` names, else its suffix's (matplotlib's default format,
    its suffix added, when it has none); other `kwargs` as `savefig`'s. The path written;
    `ValueError` naming the format if matplotlib cannot write it."""
    from matplotlib import rcParams

    path = Path(os.fspath(path))
    fmt = kwargs.pop("format", None) or path.suffix[1:] or rcParams["savefig.format"]
    fmt = str(fmt).lower()
    if not path.suffix:
        path = path.with_name(f"{path.name.rstrip('.')}.{fmt}")
    supported = fig.canvas.get_supported_filetypes()
    if fmt not in supported:
        raise ValueError(f"save_figure: cannot write {path}: format {fmt!r} is not one of matplotlib's "
                         f"({', '.join(sorted(supported))}); give the file one of these suffixes")
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format=fmt, **kwargs)
    return path


def plot_comparison(
    out_dir: str | os.PathLike,
    system: AbstractPoissonSystem,
    times: np.ndarray,
    curves: dict[str, tuple[np.ndarray, DiagnosticsReport]],
    *,
    data_states: np.ndarray | None = None,
    show_steps: int = 2000,
) -> list[str]:
    """Write the paper's four figures for one trajectory computed by several maps; returns
    the file names written into `out_dir`.

    `curves` maps a label to `(states (T, dim), report)` with `report` from
    `integrators.diagnostics` (against the reference, for the trajectory error); the first
    entry is the reference (e.g. heyoka). Figures: `components.png` (each component against
    time, the first `show_steps` steps), `phase_portrait.png` (first three components, with
    `data_states` (n_traj, T, dim) in grey), `conservation.png` (relative energy error and
    Casimir drifts, log axis) and `trajectory_error.png` (the maps after the reference).
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    names = system.state_names
    labels = list(curves)
    styles = dict(zip(labels, _STYLES))
    files = []
    k = min(show_steps + 1, len(times))

    fig = figure(figsize=(8, 1.8 * system.dim))
    axes = fig.subplots(system.dim, 1, sharex=True, squeeze=False)[:, 0]
    for i, ax in enumerate(axes):
        for label, (states, _) in curves.items():
            ax.plot(times[:k], states[:k, i], styles[label], lw=1.0, label=label)
        ax.set_ylabel(names[i])
    axes[0].legend(loc="upper right", fontsize=7)
    axes[-1].set_xlabel("t")
    fig.tight_layout()
    save_figure(fig, out_dir / "components.png", dpi=110)
    files.append("components.png")

    if system.dim >= 3:
        fig = figure(figsize=(6, 6))
        ax = fig.add_subplot(projection="3d")
        if data_states is not None:
            for traj in np.asarray(data_states).reshape(-1, *np.shape(data_states)[-2:]):
                ax.plot(*traj[:, :3].T, "k-", lw=0.4, alpha=0.5)
        for label in labels[:2]:  # the reference and the first map: more is unreadable in 3D
            ax.plot(*curves[label][0][:, :3].T, styles[label], lw=0.7, label=label)
        ax.set_xlabel(names[0])
        ax.set_ylabel(names[1])
        ax.set_zlabel(names[2])
        ax.legend(fontsize=7)
        fig.tight_layout()
        save_figure(fig, out_dir / "phase_portrait.png", dpi=110)
        files.append("phase_portrait.png")

    n_cas = system.n_casimirs
    fig = figure(figsize=(8, 2.4 * (1 + n_cas)))
    axes = fig.subplots(1 + n_cas, 1, sharex=True, squeeze=False)[:, 0]
    for label, (_, report) in curves.items():
        t = times[: len(report.energy)]  # a diverged rollout is reported up to its divergence
        # Absolute values on a log axis: the errors span from round-off (Casimirs of the
        # learned maps) to O(1) (an unstructured baseline).
        axes[0].semilogy(t, np.maximum(np.abs(report.energy_error_relative), _LOG_FLOOR),
                         styles[label][0] + "-", lw=0.8, label=label)
        for j in range(n_cas):
            drift = np.maximum(np.abs(np.asarray(report.casimir_drift_relative)[:, j]), _LOG_FLOOR)
            axes[1 + j].semilogy(t, drift, styles[label][0] + "-", lw=0.8, label=label)
    axes[0].set_ylabel("|E(t)-E(0)|/<E>")
    for j in range(n_cas):
        axes[1 + j].set_ylabel(f"|C{j + 1}(t)-C{j + 1}(0)|/<C{j + 1}>")
    axes[0].legend(fontsize=7)
    axes[-1].set_xlabel("t")
    fig.tight_layout()
    save_figure(fig, out_dir / "conservation.png", dpi=110)
    files.append("conservation.png")

    fig = figure(figsize=(8, 3))
    ax = fig.subplots()
    for label in labels[1:]:
        report = curves[label][1]
        if report.trajectory_error is None:
            raise ValueError(f"curves[{label!r}]: the report has no trajectory error (diagnostics without reference)")
        n = len(report.trajectory_error)
        ax.semilogy(times[1:n], np.maximum(np.asarray(report.trajectory_error)[1:], _LOG_FLOOR),
                    styles[label][0] + "-", lw=0.8, label=label)
    ax.set_xlabel("t")
    ax.set_ylabel("|y(t) - y_ref(t)|")
    ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, out_dir / "trajectory_error.png", dpi=110)
    files.append("trajectory_error.png")
    return files


def plot_diagnostics(report: DiagnosticsReport, path: str | os.PathLike, *, title: str = "") -> None:
    """Plot $|E(t)-E(0)|/|\\langle E\\rangle|$, $|C(t)-C(0)|/|\\langle C\\rangle|$ and the
    trajectory error (log scale, one line per trajectory) to `path` (any matplotlib format)."""
    if not isinstance(report, DiagnosticsReport):
        raise TypeError(f"report must be a DiagnosticsReport; got {type(report).__name__}")

    def lines(a: np.ndarray) -> np.ndarray:  # (T, n_lines) for ax.semilogy
        a = np.abs(a)
        a = a.reshape(-1, a.shape[-1]) if a.ndim > 1 else a[None]
        return np.where(a.T > 0, a.T, np.nan)  # exact zeros (t = 0) have no place on a log axis

    panels = [("relative energy error", report.energy_error_relative)]
    if report.casimirs.shape[-1]:
        drift = np.moveaxis(report.casimir_drift_relative, -1, 0)  # one panel line per Casimir
        panels.append(("relative Casimir drift", drift.reshape(-1, drift.shape[-1])))
    for name, values in report.integral_error_relative.items():
        panels.append((f"relative error of {name}", values))
    if report.trajectory_error is not None:
        panels.append(("trajectory error", report.trajectory_error))
    fig = figure(figsize=(5.0, 2.2 * len(panels)), layout="constrained")
    axes = fig.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0]
    for ax, (label, data) in zip(axes, panels):
        ax.semilogy(report.times, lines(data), lw=0.8)
        ax.set_ylabel(label)
    axes[-1].set_xlabel("t")
    if title:
        axes[0].set_title(title)
    save_figure(fig, path)


def _comparison_axes(comparison: Comparison, figsize: tuple[float, float]) -> tuple[Any, Any]:
    if not isinstance(comparison, Comparison):
        raise TypeError(f"comparison must be an integrators.Comparison; got {type(comparison).__name__}")
    fig = figure(figsize=figsize, layout="constrained")
    return fig, fig.subplots()


def _row_label(row: Any) -> str:
    """A row's label, saying where its map diverged if it did."""
    return row.label if row.divergence is None else f"{row.label} (diverged at step {row.divergence.step})"


def plot_work_precision(comparison: Comparison, path: str | os.PathLike) -> None:
    """Error at the final time against wall time per step (log-log) of a `compare` result, one
    point per map (a map that diverged has no point, only its legend entry saying where it
    diverged), written to `path` (any matplotlib format)."""
    fig, ax = _comparison_axes(comparison, (6, 4))
    for r, style in zip(comparison.rows, series_styles(len(comparison.rows))):
        style.pop("ls")
        if r.divergence is not None:
            ax.loglog([], [], ls="none", label=_row_label(r), **style)
            continue
        ax.loglog([r.seconds_per_step], [max(r.error_final, _LOG_FLOOR)], ls="none", label=r.label, **style)
    span_decades(ax, "x")
    ax.set_xlabel("wall time per step and trajectory [s]")
    ax.set_ylabel("|y(T) - y_ref(T)|")
    ax.legend(fontsize=7)
    save_figure(fig, path)


def plot_energy(comparison: Comparison, path: str | os.PathLike) -> None:
    """Relative energy error against time (log axis) of each map of a `compare` result, the
    largest over trajectories; a map that diverged up to the last output before it did."""
    fig, ax = _comparison_axes(comparison, (7, 3.5))
    for row, style in zip(comparison.rows, series_styles(len(comparison.rows))):
        report = row.report
        e = np.abs(report.energy_error_relative).reshape(-1, len(report.times)).max(axis=0)
        ax.semilogy(report.times, np.maximum(e, _LOG_FLOOR), lw=0.8, label=_row_label(row), markevery=0.1, ms=3,
                    **style)
    ax.set_xlabel("t")
    ax.set_ylabel("|E(t) - E(0)| / <E>")
    ax.legend(fontsize=7)
    save_figure(fig, path)


def plot_convergence(convergence: Convergence, path: str | os.PathLike, *, label: str = "") -> None:
    """Error against step size (log-log) of a `convergence` result, with the observed order in
    the legend."""
    if not isinstance(convergence, Convergence):
        raise TypeError(f"convergence must be an integrators.Convergence; got {type(convergence).__name__}")
    fig = figure(figsize=(5, 4), layout="constrained")
    ax = fig.subplots()
    ax.loglog(convergence.hs, convergence.errors, "o-",
              label=f"{label} (observed order {convergence.order:.2f})".strip())
    ax.set_xticks(convergence.hs, [f"{h:g}" for h in convergence.hs])  # the step sizes, not minor labels
    ax.minorticks_off()
    ax.set_xlabel("h")
    ax.set_ylabel("|y(T) - y_ref(T)|")
    ax.legend(fontsize=7)
    save_figure(fig, path)


def plot_vorticity(system: Any, states: Any, path: str | os.PathLike, *, titles: Any = None,
                   n_theta: int | None = None, n_phi: int | None = None) -> None:
    r"""The vorticity of one or more states of a `liepoisson.systems.Zeitlin` on the sphere, in
    Mollweide's equal-area projection, side by side on one colour scale (red positive, blue
    negative), saved to `path`.

    **Arguments:** `system`, a `Zeitlin`; `states` `(dim,)` or `(k, dim)`; `titles`, one per
    state (e.g. the times); `n_theta`, `n_phi`, the grid (default $2N \times 4N$).
    """
    from liepoisson.systems import Zeitlin

    if not isinstance(system, Zeitlin):
        raise TypeError(f"system must be a liepoisson.systems.Zeitlin; got {type(system).__name__}")
    states = np.atleast_2d(np.asarray(states, dtype=np.float64))
    if states.ndim != 2 or states.shape[-1] != system.dim:
        raise ValueError(f"states must have shape ({system.dim},) or (k, {system.dim}); got {np.shape(states)}")
    titles = [None] * len(states) if titles is None else list(titles)
    if len(titles) != len(states):
        raise ValueError(f"titles must hold one title per state ({len(states)}); got {len(titles)}")
    fields = [system.vorticity(y, n_theta, n_phi) for y in states]
    top = max(float(np.abs(f).max()) for _, _, f in fields) or 1.0
    fig = figure(figsize=(4.2 * len(states), 2.6), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, len(states), subplot_kw={"projection": "mollweide"}))
    for ax, (theta, phi, f), title in zip(axes, fields, titles):
        lon = np.where(phi > np.pi, phi - 2 * np.pi, phi)  # [-pi, pi) for the projection
        order = np.argsort(lon)
        image = ax.pcolormesh(lon[order], np.pi / 2 - theta, f[:, order], cmap="RdBu_r", vmin=-top, vmax=top,
                              shading="nearest")
        ax.set_xticklabels([])
        ax.set_yticklabels([])
        ax.grid(True, lw=0.3)
        if title is not None:
            ax.set_title(str(title), fontsize=9)
    fig.colorbar(image, ax=axes.tolist(), shrink=0.7, label="vorticity")
    save_figure(fig, path)
