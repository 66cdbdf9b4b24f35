r"""Choosing a family of learned Hamiltonians by its prediction of held-out trajectories: whole
groups of trajectories (recording sessions, conditions; each trajectory its own group by
default) are held out in turn, as scikit-learn's `GroupKFold`, the family refitted on the rest
and scored by the held-out trajectories' residuals, each from its start fitted to its own
observations with the refitted map held (errors in variables, as in training: the noise of a
first observation does not enter the comparison)."""

from __future__ import annotations

import dataclasses
from collections.abc import Hashable, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from integrators import Observations

from .._solvers._levenberg_marquardt import LevenbergMarquardt
from .._solvers._stage import Context, KeepIfBetter
from ._problem import Fitted

#: Folds of held-out selection at most (fewer groups: one group per fold).
FOLDS = 5

#: Gauss-Newton steps at most for the held-out trajectories' starts (from the full fit's).
START_STEPS = 20


def trajectory_groups(groups: Sequence[Hashable] | None, n_trajectories: int) -> np.ndarray:
    """The group index `(n_trajectories,)` of each trajectory (groups numbered in order of first
    appearance): `groups` one label per trajectory, or `None` (each trajectory its own group).
    `ValueError` for the wrong length or fewer than two groups."""
    if groups is None:
        return np.arange(n_trajectories)
    if isinstance(groups, (str, bytes)) or not isinstance(groups, Sequence | np.ndarray):
        raise TypeError(f"groups must be a sequence of labels, one per trajectory; got {groups!r}")
    labels = list(groups)
    if len(labels) != n_trajectories:
        raise ValueError(f"groups must hold one label per trajectory ({n_trajectories}); got {len(labels)}")
    order: dict[Any, int] = {}
    index = np.array([order.setdefault(label, len(order)) for label in labels])
    if len(order) < 2:
        raise ValueError(f"groups must name at least two groups to hold one out; got one ({labels[0]!r})")
    return index


def group_folds(group_of: np.ndarray, seed: int, folds: int = FOLDS) -> tuple[np.ndarray, ...]:
    """The held-out trajectories of each fold: the groups (`group_of`, from `trajectory_groups`)
    shuffled by `seed` and dealt into `min(folds, groups)` folds of nearly equal numbers of
    groups; a group is held out whole, in one fold."""
    n_groups = int(group_of.max()) + 1
    if n_groups < 2:
        raise ValueError("held-out selection needs at least two groups of trajectories")
    shuffled = np.random.default_rng(seed).permutation(n_groups)
    return tuple(np.flatnonzero(np.isin(group_of, part)) for part in np.array_split(shuffled, min(folds, n_groups)))


def segment_trajectories(data: Observations, window: int | None) -> np.ndarray:
    """The trajectory of each segment `learn.TrajectoryLoss` cuts (`window` intervals each,
    whole trajectories for `None`), in its order."""
    out = []
    for j, t in enumerate(data.times):
        n = t.size - 1
        out.extend([j] * len(range(0, n, n if window is None else window)))
    return np.asarray(out)


def _masked(segments: Any, rows: np.ndarray) -> Any:
    """`segments` with only the rows `rows` present (the others masked out, shapes kept: the
    compiled residuals and Jacobian are reused)."""
    keep = np.zeros(segments.mask.shape[0], bool)
    keep[rows] = True
    return dataclasses.replace(segments, mask=segments.mask * jnp.asarray(keep, segments.mask.dtype)[:, None])


@eqx.filter_jit
def _start_step(objective, model, starts, segments, lam):
    """One damped Gauss-Newton step of every segment's start (each segment's residuals depend
    on its own start only: $d\\times d$ normal equations per segment), and each segment's sum
    of squares before and after."""

    def residuals(s):
        return objective.residuals(Fitted(model, s), segments)  # (S, L, d)

    r = residuals(starts)
    dim = starts.shape[-1]
    by_start = jax.vmap(lambda e: jax.jvp(residuals, (starts,), (jnp.broadcast_to(e, starts.shape),))[1],
                        out_axes=-1)(jnp.eye(dim, dtype=starts.dtype))  # (S, L, d, d)
    A = jnp.einsum("sldi,sldj->sij", by_start, by_start)
    g = jnp.einsum("sldi,sld->si", by_start, r)
    damped = A + lam * (jnp.diag(jnp.ones(dim)) * jnp.diagonal(A, axis1=1, axis2=2)[:, None, :]
                        + jnp.finfo(A.dtype).eps * jnp.eye(dim))
    step = jnp.linalg.solve(damped, -g[..., None])[..., 0]
    before = jnp.sum(r**2, axis=(1, 2))
    after = jnp.sum(residuals(starts + step) ** 2, axis=(1, 2))
    return starts + step, before, after


def fit_held_out_starts(objective: Any, model: Any, starts: jax.Array, segments: Any) -> jax.Array:
    """Each present segment's sum of squared residuals `(S,)` (0 for absent ones) with its start
    fitted, `model` held: damped Gauss-Newton per segment from `starts`, a step kept where it
    lowers that segment's sum."""
    lam = 1e-3
    best = None
    for _ in range(START_STEPS):
        proposed, before, after = _start_step(objective, model, starts, segments, lam)
        better = after < before
        starts = jnp.where(better[:, None], proposed, starts)
        best = jnp.where(better, after, before)
        if not bool(jnp.any(better & (before - after > 1e-12 * before))):
            break
    return np.asarray(best)


def held_out_errors(problem: Any, segment_trajectory: np.ndarray, folds: Sequence[np.ndarray], iterations: int,
                    rtol: float, context: Context) -> tuple[np.ndarray, np.ndarray]:
    """`(squared residuals (n_trajectories,), components (n_trajectories,))` of each trajectory
    held out once: for each fold, the fitted `problem` (a `learn.FittedProblem` of whole
    observations, its `y0` the fit on every trajectory) refitted without the fold's trajectories
    (Levenberg-Marquardt from that fit, `iterations` steps at most, `rtol`), then the fold's
    trajectories' starts fitted with the refitted map held (`fit_held_out_starts`)."""
    train, objective = problem.train, problem.objective
    if problem.y0.shared is not None:
        raise ValueError("held-out selection cannot score a fit with unknowns shared by trajectories (a gyroscope "
                         "bias per group, learn.BodyLoss(bias=True)): a held-out group's bias is unknown. Choose the "
                         "family by selection='bic', or fit without bias")
    n_trajectories = int(segment_trajectory.max()) + 1
    ssr, count = np.zeros(n_trajectories), np.zeros(n_trajectories)
    width = jax.eval_shape(lambda: objective.residuals(problem.y0, train)).shape[-1]  # compared per observation
    components = np.asarray(jnp.sum(train.mask, axis=1)) * width
    for held in folds:
        out = np.isin(segment_trajectory, held)
        fold = dataclasses.replace(problem, train=_masked(train, np.flatnonzero(~out)))
        result = KeepIfBetter(LevenbergMarquardt(iterations, rtol)).run(fold, context)
        model = result.y.model
        per_segment = fit_held_out_starts(objective, model, problem.y0.starts, _masked(train, np.flatnonzero(out)))
        np.add.at(ssr, segment_trajectory[out], per_segment[out])
        np.add.at(count, segment_trajectory[out], components[out])
    return ssr, count


def group_scores(errors: dict[str, tuple[np.ndarray, np.ndarray]], group_of: np.ndarray
                 ) -> dict[str, tuple[float, float]]:
    """`{family: (held-out error, standard error of its difference from the lowest)}` from each
    family's per-trajectory `(squared residuals, components)`: the error is the total over the
    total components; the standard error that of the count-weighted mean of the per-group
    differences from the lowest family's errors (paired: the groups share their noise)."""
    n_groups = int(group_of.max()) + 1
    per_group = {}
    for name, (ssr, count) in errors.items():
        s, c = np.zeros(n_groups), np.zeros(n_groups)
        np.add.at(s, group_of, ssr)
        np.add.at(c, group_of, count)
        per_group[name] = (s, c)
    total = {name: float(s.sum() / c.sum()) for name, (s, c) in per_group.items()}
    best = min(total, key=total.get)
    s_best, c_best = per_group[best]
    weights = c_best / c_best.sum()
    out = {}
    for name, (s, c) in per_group.items():
        d = s / c - s_best / c_best
        mean = float(weights @ d)
        se = float(np.sqrt(np.sum(weights**2 * (d - mean) ** 2) * n_groups / max(n_groups - 1, 1)))
        out[name] = (total[name], se)
    return out
