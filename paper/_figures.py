"""Figures like the paper's: components against time, phase portrait, conservation, error."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _pyplot():
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:  # figures are an extra: say how to get them, keep the numbers
        print("  (matplotlib not installed: skipping figures; pip install -e '.[paper]')")
        return None
    return plt


def plot_experiment(
    out_dir: Path,
    system,
    times: np.ndarray,
    reference: np.ndarray,
    ours: np.ndarray,
    baseline: np.ndarray | None,
    report_ours,
    report_reference,
    report_baseline=None,
    data_states: np.ndarray | None = None,
    label: str = "LPNet",
    show_steps: int = 2000,
) -> list[str]:
    """Write the paper's four figures for one trajectory; returns the file names.

    `reference`, `ours`, `baseline` have shape `(n_steps+1, dim)`; reports come from
    `integrators.diagnostics`.
    """
    plt = _pyplot()
    if plt is None:
        return []
    names = system.state_names
    files = []
    k = min(show_steps + 1, len(times))

    fig, axes = plt.subplots(system.dim, 1, figsize=(8, 1.8 * system.dim), sharex=True)
    for i, ax in enumerate(np.atleast_1d(axes)):
        ax.plot(times[:k], reference[:k, i], "b-", lw=1.2, label="ground truth (heyoka)")
        ax.plot(times[:k], ours[:k, i], "r--", lw=1.0, label=label)
        if baseline is not None:
            ax.plot(times[:k], baseline[:k, i], "g:", lw=1.0, label="MLP baseline")
        ax.set_ylabel(names[i])
    np.atleast_1d(axes)[0].legend(loc="upper right", fontsize=7)
    np.atleast_1d(axes)[-1].set_xlabel("t")
    fig.tight_layout()
    fig.savefig(out_dir / "components.png", dpi=110)
    plt.close(fig)
    files.append("components.png")

    if system.dim >= 3:
        fig = plt.figure(figsize=(6, 6))
        ax = fig.add_subplot(projection="3d")
        if data_states is not None:
            for traj in np.atleast_3d(data_states).reshape(-1, *data_states.shape[-2:]):
                ax.plot(*traj[:, :3].T, "k-", lw=0.4, alpha=0.5)
        ax.plot(*reference[:, :3].T, "b-", lw=0.8, label="ground truth")
        ax.plot(*ours[:, :3].T, "r--", lw=0.6, label=label)
        ax.set_xlabel(names[0])
        ax.set_ylabel(names[1])
        ax.set_zlabel(names[2])
        ax.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(out_dir / "phase_portrait.png", dpi=110)
        plt.close(fig)
        files.append("phase_portrait.png")

    n_cas = np.asarray(report_ours.casimir_drift_relative).shape[-1] if system.n_casimirs else 0
    fig, axes = plt.subplots(1 + n_cas, 1, figsize=(8, 2.4 * (1 + n_cas)), sharex=True)
    axes = np.atleast_1d(axes)
    for rep, style, lab in (
        (report_reference, "b-", "ground truth"),
        (report_ours, "r-", label),
        (report_baseline, "g-", "MLP baseline"),
    ):
        if rep is None:
            continue
        # Absolute values on a log axis (floored at 1e-17 for exact zeros): the errors span
        # from round-off (Casimirs of the learned maps) to O(1) (the unstructured baseline).
        energy = np.maximum(np.abs(np.asarray(rep.energy_error_relative)), 1e-17)
        axes[0].semilogy(times, energy, style, lw=0.8, label=lab)
        for j in range(n_cas):
            cas = np.maximum(np.abs(np.asarray(rep.casimir_drift_relative)[:, j]), 1e-17)
            axes[1 + j].semilogy(times, cas, style, lw=0.8, label=lab)
    axes[0].set_ylabel("|E(t)-E(0)|/<E>")
    for j in range(n_cas):
        axes[1 + j].set_ylabel(f"|C{j + 1}(t)-C{j + 1}(0)|/<C{j + 1}>")
    axes[0].legend(fontsize=7)
    axes[-1].set_xlabel("t")
    fig.tight_layout()
    fig.savefig(out_dir / "conservation.png", dpi=110)
    plt.close(fig)
    files.append("conservation.png")

    fig, ax = plt.subplots(figsize=(8, 3))
    ax.semilogy(times[1:], np.asarray(report_ours.trajectory_error)[1:], "r-", lw=0.8, label=label)
    if report_baseline is not None:
        ax.semilogy(times[1:], np.asarray(report_baseline.trajectory_error)[1:], "g-", lw=0.8, label="MLP baseline")
    ax.set_xlabel("t")
    ax.set_ylabel("|y(t) - y_ref(t)|")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out_dir / "trajectory_error.png", dpi=110)
    plt.close(fig)
    files.append("trajectory_error.png")
    return files
