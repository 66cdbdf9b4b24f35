"""Roll a learned map out from test initial conditions and measure it against the ground truth."""

from __future__ import annotations

import time
from typing import Any

import numpy as np

import integrators as it


def rollout_metrics(model, system, reference: np.ndarray, defect_points: int = 200) -> dict[str, Any]:
    """Metrics of `model` rolled out from `reference[:, 0]` for as many steps as `reference` has.

    `reference`: ground truth of shape `(n_traj, n_steps+1, dim)`. Energy and Casimir errors are
    relative to the time mean as in the paper (`(E(t) - E(0)) / <E>`); maxima are over all
    trajectories and times, means over both. Returns the metrics, the rollout and the reports.
    """
    reference = np.asarray(reference)
    n_traj, n_points, _ = reference.shape
    t0 = time.perf_counter()
    y = np.asarray(model.rollout(reference[:, 0], n_points - 1))
    rollout_time = time.perf_counter() - t0
    reports = [it.diagnostics(y[i], system, reference=reference[i]) for i in range(n_traj)]
    energy = np.stack([np.abs(np.asarray(r.energy_rel_err)) for r in reports])
    if system.n_casimirs:
        casimir = np.stack([np.abs(np.asarray(r.casimir_rel_drift)) for r in reports])
        casimir_max = float(np.max(casimir))
    else:
        casimir_max = None
    traj = np.stack([np.asarray(r.trajectory_error) for r in reports])
    finite = bool(np.all(np.isfinite(y)))
    rng = np.random.default_rng(0)
    flat = y.reshape(-1, y.shape[-1])
    flat = flat[np.all(np.isfinite(flat), axis=-1)]
    pick = flat[rng.choice(len(flat), size=min(defect_points, len(flat)), replace=False)]
    defect = float(np.max(np.asarray(model.poisson_defect(pick)))) if len(pick) else float("nan")
    metrics = {
        "train_loss": float(model.train_loss),
        "val_loss": float(model.val_loss) if model.val_loss is not None else None,
        "energy_rel_err_max": float(np.nanmax(energy)) if finite else float("inf"),
        "energy_rel_err_mean": float(np.nanmean(energy)) if finite else float("inf"),
        "casimir_rel_drift_max": casimir_max,
        "traj_err_final": float(np.max(traj[:, -1])) if finite else float("inf"),
        "poisson_defect_max": defect,
        "wall_time_s": float(model.wall_time_s),
        "rollout_time_s": rollout_time,
        "finite": finite,
    }
    return {"metrics": metrics, "rollout": y, "reports": reports}


def compare(system, ours, baseline, reference, out_dir, data_states=None, label="LPNet", show=0):
    """Metrics of `ours` with the baseline's beside them, and the paper's figures for
    trajectory `show` of `reference` (a `Trajectories`)."""
    from ._figures import plot_experiment

    res = rollout_metrics(ours, system, reference.states)
    bres = rollout_metrics(baseline, system, reference.states)
    metrics = dict(res["metrics"])
    metrics["baseline"] = bres["metrics"]
    metrics["figures"] = plot_experiment(
        out_dir,
        system,
        reference.times,
        reference.states[show],
        res["rollout"][show],
        bres["rollout"][show],
        res["reports"][show],
        it.diagnostics(reference.states[show], system),
        bres["reports"][show],
        data_states=data_states,
        label=label,
    )
    # Ground truth's own conservation, for the paper's "more precise than the ground truth".
    gt = [it.diagnostics(reference.states[i], system) for i in range(reference.states.shape[0])]
    if system.n_casimirs:
        metrics["ground_truth_casimir_rel_drift_max"] = float(
            max(np.max(np.abs(np.asarray(r.casimir_rel_drift))) for r in gt)
        )
    metrics["ground_truth_energy_rel_err_max"] = float(
        max(np.max(np.abs(np.asarray(r.energy_rel_err))) for r in gt)
    )
    return metrics
