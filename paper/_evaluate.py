"""Roll a learned map out from test initial conditions and measure it against the ground truth."""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Callable
from typing import Any

import numpy as np

import integrators as it
import learn
from learn import AbstractLearnedMap, TrainingRecord

from ._cluster import on_cluster, submit


def measure_rollout(model: AbstractLearnedMap, record: TrainingRecord | None, system, reference: np.ndarray,
                    defect_points: int = 200, integrals: dict | None = None) -> dict[str, Any]:
    """Metrics of `model` (trained as `record` says; `None`: no losses reported) rolled out
    from `reference[:, 0]` for as many steps as `reference` has: `integrators.rollout_figures`
    of the rollout, under its names in metrics.json.

    `reference`: ground truth of shape `(n_traj, n_steps+1, dim)`; `system`: the model's (the
    figures take $H$ and the Casimirs from `model.system`).
    Energy and Casimir errors are relative to the time mean as in the paper (`(E(t) - E(0)) /
    <E>`); maxima are over all trajectories and times, means over both; `integrals` (name ->
    function of the state) are reported as `<name>_rel_err_max` the same way; the Poisson
    defect is the largest at `defect_points` states drawn at random (seed 0) from the finite
    steps of every trajectory. A rollout that stops being finite has every error figure
    infinite (the library's divergence policy), with `diverged_at_step` and
    `energy_rel_err_max_finite_steps` saying what happened before.
    Returns the metrics, the rollout and the report.
    """
    reference = np.asarray(reference)
    n_points = reference.shape[1]
    t0 = time.perf_counter()
    y = np.asarray(model.rollout(reference[:, 0], n_points - 1, nonfinite="return"))
    rollout_time = time.perf_counter() - t0
    figures = it.rollout_figures(model, y, reference, integrals=integrals, defect_points=defect_points, defect_seed=0)
    metrics = {
        "train_loss": None if record is None else record.train_loss,
        "val_loss": None if record is None else record.val_loss,
        "energy_rel_err_max": figures.energy_error_max,
        "energy_rel_err_mean": figures.energy_error_mean,
        "energy_rel_err_max_per_trajectory": figures.energy_error_max_per_trajectory,
        "casimir_rel_drift_max": figures.casimir_drift_max if system.n_casimirs else None,
        "traj_err_final": figures.error_final,
        "poisson_defect_max": figures.poisson_defect_max,
        "wall_time_s": None if record is None else record.wall_time_s,
        "rollout_time_s": rollout_time,
        **{f"{name}_rel_err_max": value for name, value in figures.integral_error_max.items()},
    }
    if figures.divergence is not None:
        metrics["diverged_at_step"] = figures.diverged_at_step
        metrics["energy_rel_err_max_finite_steps"] = figures.report.before_divergence().max_energy_error
    return {"metrics": metrics, "rollout": y, "report": figures.report}


Trained = tuple[AbstractLearnedMap, TrainingRecord]


def compare(system, ours: Trained, baseline: Trained | None, reference, out_dir, data_states=None, label="LPNet",
            show=0, integrals=None):
    """Metrics of `ours = (model, record)` with the baseline's beside them (none if `baseline`
    is `None`), and the paper's figures for trajectory `show` of `reference` (a `Trajectories`).

    Returns `(metrics, rollouts)`, `rollouts = {"ours": ..., "baseline": ...}` (without
    "baseline" if there is none) of shape `(n_traj, n_steps+1, dim)`, so that experiments
    measure more without rolling out again."""
    runs = {"ours": measure_rollout(*ours, system, reference.states, integrals=integrals)}
    if baseline is not None:
        runs["baseline"] = measure_rollout(*baseline, system, reference.states, integrals=integrals)
    metrics = dict(runs["ours"]["metrics"])
    if baseline is not None:
        metrics["baseline"] = runs["baseline"]["metrics"]
    truth = reference.states[show]
    curves = {"ground truth (heyoka)": (truth, it.diagnostics(truth, system))}
    for key, name in (("ours", label), ("baseline", "MLP baseline")):
        if key in runs:
            y = runs[key]["rollout"][show]
            curves[name] = (y, it.diagnostics(y, system, reference=truth))
    try:
        metrics["figures"] = it.plot_comparison(out_dir, system, reference.times, curves, data_states=data_states)
    except ImportError as err:  # figures are an extra: say how to get them, keep the numbers
        print(f"  ({err}; skipping figures)")
        metrics["figures"] = []
    # Ground truth's own conservation, for the paper's "more precise than the ground truth".
    gt = it.diagnostics(reference.states, system, integrals=integrals)
    for name in integrals or {}:
        metrics[f"ground_truth_{name}_rel_err_max"] = gt.max_integral_error(name)
    if system.n_casimirs:
        metrics["ground_truth_casimir_rel_drift_max"] = gt.max_casimir_drift_relative
    metrics["ground_truth_energy_rel_err_max"] = gt.max_energy_error
    return metrics, {key: run["rollout"] for key, run in runs.items()}


def glpnet_on_same_data(system, data, reference, out_dir, iterations, starts, progress, n_modules=6,
                        full_vectors=False, integrals=None, method=it.splitting.LieTrotter):
    """A G-LPNet (`n_modules` modules composed by the splitting `method`, exactly Poisson) trained on
    the same pairs (all of them, as the paper trains G-LPNets) and rolled out from the same
    initial conditions: what an exact Poisson map makes of the same data. Returns
    `(model, metrics)`."""
    gnet, record = learn.fit(
        learn.GLPNet(system, n_modules=n_modules, key=0, full_vectors=full_vectors, method=method), data,
        optimiser=learn.KeepIfBetter(learn.Restarts(learn.WarmStart(learn.ScipyBFGS(iterations)), starts)),
        validation_fraction=0.0, seed=0, progress=progress,
    )
    gnet.save(out_dir / "glpnet.h5")
    return gnet, measure_rollout(gnet, record, system, reference.states, integrals=integrals)["metrics"]


def refine_after_adam(adam: Trained, data, iterations, system, reference, progress):
    """The Adam-fitted (the paper's optimiser) `adam = (net, record)` refined by `iterations`
    of L-BFGS-B on the same training pairs (same split), and the Adam-only network's metrics.

    Returns `((refined, record), adam_only)`; `adam_only["wall_time_s"]` is Adam's, the
    refinement's is in the refined record."""
    net, rec = adam
    refined = learn.fit(
        net, data, optimiser=learn.KeepIfBetter(learn.ScipyLBFGSB(iterations)),
        validation_fraction=rec.validation_fraction, seed=rec.seed, loss=rec.loss, progress=progress,
    )
    metrics = measure_rollout(net, rec, system, reference.states)["metrics"]
    keys = ("train_loss", "val_loss", "energy_rel_err_max", "energy_rel_err_mean",
            "energy_rel_err_max_per_trajectory", "traj_err_final", "poisson_defect_max", "wall_time_s")
    return refined, {k: metrics[k] for k in keys}


def _one_seed(make, fit, data, refine_iterations, system, reference, seed, progress):
    """One seed of `start_lpnet_seeds` (a task where trainings run)."""
    first = learn.fit(make(seed), data, **fit(seed), progress=progress)
    (net, rec), adam_only = refine_after_adam(first, data, refine_iterations, system, reference, progress)
    per_trajectory = measure_rollout(net, rec, system, reference.states)["metrics"]["energy_rel_err_max_per_trajectory"]
    return first, (net, rec), adam_only, per_trajectory


def start_training(fn: Callable[..., Any], /, *args: Any, **kwargs: Any):
    """Start `fn(*args, **kwargs)` where trainings run (`paper._cluster.submit`; its
    `.result()` waits), its progress bars off when that is elsewhere."""
    if "progress" in kwargs:
        kwargs["progress"] = kwargs["progress"] and not on_cluster()
    return submit(functools.partial(fn, *args, **kwargs))


@dataclasses.dataclass(frozen=True)
class StartedSeeds:
    """The trainings `start_lpnet_seeds` started: a future per seed."""

    futures: list
    seeds: list
    refine_iterations: int


def start_lpnet_seeds(make, fit, data, refine_iterations, system, reference, seeds, progress) -> StartedSeeds:
    """Start the seeds' trainings (`start_training`); `collect_lpnet_seeds` waits for them and
    says what they are. Between the two, an experiment starts its other trainings (a baseline,
    a G-LPNet), so that they run beside the seeds."""
    futures = [start_training(_one_seed, make, fit, data, refine_iterations, system, reference, seed,
                              progress=progress) for seed in seeds]
    return StartedSeeds(futures, list(seeds), refine_iterations)


def collect_lpnet_seeds(started: StartedSeeds, label: str):
    """Wait for the trainings `start_lpnet_seeds` started: `make(seed)` for each seed, fitted
    by `learn.fit` with the keyword arguments `fit(seed)` (an Adam stage), then
    `refine_after_adam`, and rolled out against `reference`.

    Returns `(trained, metrics)`: the refined `(network, record)` pairs (seed order) and the
    per-seed lists `energy_rel_err_max_seeds`, `train_loss_seeds` and their `*_adam_only` twins,
    the medians `energy_rel_err_max_median` and `adam_only_energy_median`,
    `energy_rel_err_max_per_trajectory_median` (each trajectory's median over seeds), and
    `adam_only`, `wall_time_s` of the first seed (Adam plus refinement)."""
    trained, energies, per_trajectory, adam_runs = [], [], [], []
    runs = [f.result() for f in started.futures]
    for seed, (first, (net, rec), adam_only, each) in zip(started.seeds, runs):
        energy = float(np.max(each))
        trained.append((net, rec))
        energies.append(energy)
        per_trajectory.append(each)
        adam_runs.append(adam_only)
        print(
            f"  {label} seed {seed}: train {rec.train_loss:.2e} val {rec.val_loss:.2e} energy max {energy:.2e} "
            f"(Adam only: train {adam_only['train_loss']:.2e}, energy max {adam_only['energy_rel_err_max']:.2e}; "
            f"{first[1].wall_time_s + rec.wall_time_s:.1f} s)"
        )
    adam_energies = [a["energy_rel_err_max"] for a in adam_runs]
    metrics = {
        "energy_rel_err_max_seeds": energies,
        "energy_rel_err_max_median": float(np.median(energies)),
        "energy_rel_err_max_per_trajectory_median": np.median(np.asarray(per_trajectory, dtype=float), axis=0).tolist(),
        "train_loss_seeds": [r.train_loss for _, r in trained],
        "energy_rel_err_max_seeds_adam_only": adam_energies,
        "adam_only_energy_median": float(np.median(adam_energies)),
        "train_loss_seeds_adam_only": [a["train_loss"] for a in adam_runs],
        "adam_only": adam_runs[0],
        "wall_time_s": adam_runs[0]["wall_time_s"] + trained[0][1].wall_time_s,
        "refine_iterations": started.refine_iterations,
    }
    return trained, metrics
