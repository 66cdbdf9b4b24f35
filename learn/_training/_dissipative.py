r"""Fitting G-LPNets with learned dissipation (`learn.Dissipative`) to observations: a quadratic
learned Hamiltonian and a drag family, chosen by the information criterion."""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from integrators import BodyObservations, Observations
from integrators.splitting import TripleJump
from liepoisson.internals import positive_float, show_progress
from liepoisson.systems import AbstractLiePoissonSystem

from .._models._drag import DRAG_KINDS, Dissipative, LearnedDrag
from .._models._glpnet import GLPNet, check_method
from .._solvers._levenberg_marquardt import LevenbergMarquardt
from .._solvers._record import TrainingRecord
from .._solvers._stage import Context
from ._body import BodyLoss, weak_form_quadratic
from ._criterion import lowest
from ._families import FAMILIES, Family
from ._fit import training_record
from ._observed import TrajectoryLoss, information_criterion
from ._steps import solve_within_noise
from ._units import state_size

#: Levenberg-Marquardt steps per drag family.
ITERATIONS = 200

#: The first sub-step the fits take, as a rotation angle: each interval is cut into steps of
#: $h|\xi|_{\max} \le$ this (`learn.BodyLoss(max_step=...)`); the sub-steps are then doubled
#: while the fitted map's own discretisation error exceeds a tenth of its misfit
#: (`solve_within_noise`).
STEP_ANGLE = 0.1

#: The drag a fit starts from: its rate $|AD|$ is this fraction per unit of the data's span
#: (a nonzero start: $LL^\top$ has no gradient at $L = 0$).
START_RATE = 0.01


def fit_dissipative(
    system: AbstractLiePoissonSystem,
    data: BodyObservations | Observations,
    *,
    kinds: Sequence[str] = DRAG_KINDS,
    any_axes: bool = False,
    method: Any = TripleJump,
    loss: BodyLoss | TrajectoryLoss | None = None,
    iterations: int | None = None,
    seed: int = 0,
    progress: bool | None = None,
) -> tuple[Dissipative, tuple[TrainingRecord, ...]]:
    r"""A `learn.Dissipative` (a G-LPNet of a quadratic $\widetilde H$ composed with a learned
    drag's flow) fitted to `data`; returns `(model, records)`, one record per drag family, the
    chosen one last.

    $\widetilde H$ is a quadratic on the basis axes (`any_axes`: any symmetric form; from
    the least-squares quadratic of the observations, as `learn.fit_splitting` starts), the
    drag each of `kinds` (`learn.LearnedDrag`: `"linear"`, `"quadratic"`, `"ridge"`, on the axes
    or, with `any_axes`, in any axes), started at a small drag (`START_RATE`) and fitted with
    $\widetilde H$ and the starts by Levenberg-Marquardt (`iterations`, default `ITERATIONS`) on
    `loss` (default for body observations `learn.BodyLoss` with sub-steps of at most
    `STEP_ANGLE` rad of the fastest observed rotation; for observations `learn.TrajectoryLoss`),
    composed by `method` (default `TripleJump`, order 4). The sub-steps are doubled while the
    fitted map's own discretisation error is above a tenth of its misfit (at most 3 times; a
    `UserWarning` if that was not enough), so that the map's step does not bias the inertia.
    The family with the lowest Bayesian information criterion is returned; each record's last
    stage's `details` hold its `family`, `bic`, `ssr`, `effective_parameters`, `substeps` and
    `discretisation_ssr`.
    """
    if not isinstance(system, AbstractLiePoissonSystem):
        raise TypeError(f"system must be a Lie-Poisson system (e.g. liepoisson.systems.RigidBody); got "
                        f"{type(system).__name__}")
    kinds = tuple(kinds)
    if not kinds or any(k not in DRAG_KINDS for k in kinds):
        raise ValueError(f"kinds must be a non-empty sequence of {DRAG_KINDS}; got {kinds!r}")
    method = check_method(method)
    iterations = ITERATIONS if iterations is None else int(iterations)
    family = next(f for f in FAMILIES if f.name == ("quadratic, any axes, even" if any_axes else "quadratic, even"))
    if isinstance(data, BodyObservations):
        net, loss, span, rate = _body_start(system, data, family, method, loss)
    elif isinstance(data, Observations):
        net, loss, span, rate = _observed_start(system, data, family, method, loss)
    else:
        raise TypeError(f"data must be integrators.BodyObservations or Observations; got {type(data).__name__}")
    context = Context(seed=int(seed), progress=show_progress(progress))
    split = {"h": None, "validation_fraction": 0.0, "seed": int(seed), "normalise": False}
    A, _ = _affine(net)  # grad H~ = A mu + b: the drag's rate is A D
    curvature = float(np.mean(np.abs(np.linalg.eigvalsh(0.5 * (A + A.T))))) or 1.0
    fits = []
    for kind in kinds:
        linear_scale = START_RATE / (span * curvature)
        scale = linear_scale / rate if kind == "quadratic" else linear_scale
        drag = LearnedDrag(system.dim, kind, any_axes=any_axes, scale=scale)
        if kind == "ridge":
            drag = eqx.tree_at(lambda d: d.quadratic_factor, drag, drag.quadratic_factor / math.sqrt(rate))
        start = loss.problem(Dissipative(net, drag), data, **split)
        problem, results, steps = solve_within_noise(
            start, (LevenbergMarquardt(iterations, 1e-10, warm_start=False),), context)
        if not steps.within_noise:
            warnings.warn(f"the {kind} drag's fit errs by its own step more than the data's misfit (discretisation "
                          f"sum of squares {steps.discretisation_ssr:.3g} against {steps.ssr:.3g} after "
                          f"{steps.substeps} sub-steps): give a smaller max_step (loss=learn.BodyLoss(max_step=...))",
                          UserWarning, stacklevel=2)
        criterion = information_criterion(problem, problem.y0)
        criterion.update({"substeps": steps.substeps, "discretisation_ssr": steps.discretisation_ssr})
        last = results[-1]
        results[-1] = dataclasses.replace(last, record=dataclasses.replace(
            last.record, details={**last.record.details, **criterion, "family": f"{family.name}, {kind} drag"}))
        fits.append((criterion, problem.map(problem.y0), training_record(problem, results)))
    best = lowest([(c["bic"], c["effective_parameters"]) for c, _, _ in fits])
    records = tuple(r for k, (_, _, r) in enumerate(fits) if k != best) + (fits[best][2],)
    return fits[best][1], records


def _body_start(system, data: BodyObservations, family: Family, method, loss):
    """The net from the weak-form quadratic of body observations, the loss, the span and the
    observed rotation rate (for the drag's start)."""
    if loss is None:
        fastest = max(float(np.max(np.linalg.norm(v, axis=1))) for v in _velocities(data))
        loss = BodyLoss(max_step=STEP_ANGLE / fastest if fastest > 0 else None)
    elif not isinstance(loss, BodyLoss):
        raise TypeError(f"loss must be a learn.BodyLoss for body observations; got {type(loss).__name__}")
    A, b, _ = weak_form_quadratic(data, linear=family.bias, diagonal=not family.any_axes)
    velocities = _velocities(data)
    xi = np.concatenate(velocities)
    mu = np.linalg.solve(A, (xi - b).T).T
    size = float(np.sqrt(np.mean(np.sum(mu**2, axis=1)))) or 1.0
    net = GLPNet(system, terms=family.terms_of(system, A, b, size), method=method)
    rate = float(np.sqrt(np.mean(np.sum(xi**2, axis=1)))) or 1.0
    return net, loss, _span(data), rate


def _observed_start(system, data: Observations, family: Family, method, loss):
    """As `_body_start`, for observed states."""
    loss = TrajectoryLoss() if loss is None else loss
    if not isinstance(loss, TrajectoryLoss):
        raise TypeError(f"loss must be a learn.TrajectoryLoss for observations; got {type(loss).__name__}")
    net = GLPNet(system, terms=family.start(system, data, state_size(system, data)), method=method)
    A, b = _affine(net)
    xi = np.concatenate(list(data.states)) @ A.T + b
    rate = float(np.sqrt(np.mean(np.sum(xi**2, axis=1)))) or 1.0
    return net, loss, _span(data), rate


def _affine(net: GLPNet) -> tuple[np.ndarray, np.ndarray]:
    r"""`(A, b)` with the net's body velocity $A\mu + b$ (a quadratic $\widetilde H$)."""
    zero = jnp.zeros(net.system.dim)
    return np.asarray(jax.jacfwd(net.body_velocity)(zero)), np.asarray(net.body_velocity(zero))


def _velocities(data: BodyObservations) -> list[np.ndarray]:
    return list(data.velocities) if data.velocities is not None else [
        data.group_velocities(j) for j in range(len(data))]


def _span(data) -> float:
    """The mean duration of a trajectory (the drag's start is set against it)."""
    return positive_float(float(np.mean([t[-1] - t[0] for t in data.times])), "the trajectories' duration")
