r"""Fitting G-LPNets with learned dissipation (`learn.Dissipative`) to observations: a quadratic
learned Hamiltonian and a drag family, chosen by the information criterion."""

from __future__ import annotations

import dataclasses
import functools
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
from .._solvers._stage import Context, KeepIfBetter
from ._body import BodyLoss, weak_form_drag
from ._criterion import FamilyChoice, family_score, lowest
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
    or, with `any_axes`, in any axes), started on body observations at the weak form's estimate
    with a diagonal drag (`learn.weak_form_drag`), on observed states at a small drag, each
    coefficient at least a rate `START_RATE` per unit of the data's span; fitted with
    $\widetilde H$ and the starts by Levenberg-Marquardt (`iterations`, default `ITERATIONS`) on
    `loss` (default for body observations `learn.BodyLoss` with sub-steps of at most
    `STEP_ANGLE` rad of the fastest observed rotation; for observations `learn.TrajectoryLoss`),
    composed by `method` (default `TripleJump`, order 4). The sub-steps are doubled while the
    fitted map's own discretisation error is above a tenth of its misfit (at most 3 times; a
    `UserWarning` if that was not enough), so that the map's step does not bias the inertia.
    The family with the lowest Bayesian information criterion is returned; every record's
    `choice` is the `learn.FamilyChoice` (each family's `learn.FamilyScore`, its sub-steps
    included).
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
        loss = body_loss_from_data(data, loss)
        start_of = functools.partial(body_drag_start, system, data, family, method, any_axes)
    elif isinstance(data, Observations):
        loss = TrajectoryLoss() if loss is None else loss
        if not isinstance(loss, TrajectoryLoss):
            raise TypeError(f"loss must be a learn.TrajectoryLoss for observations; got {type(loss).__name__}")
        start_of = functools.partial(observed_drag_start, system, data, family, method, any_axes)
    else:
        raise TypeError(f"data must be integrators.BodyObservations or Observations; got {type(data).__name__}")
    context = Context(seed=int(seed), progress=show_progress(progress))
    split = {"h": None, "validation_fraction": 0.0, "seed": int(seed), "normalise": False}
    fits = []
    for kind in kinds:
        problem, results, steps, criterion = drag_fit(loss.problem(start_of(kind), data, **split), iterations, 1e-10,
                                                      context)
        if not steps.within_noise:
            warnings.warn(f"the {kind} drag's fit errs by its own step more than the data's misfit (discretisation "
                          f"sum of squares {steps.discretisation_ssr:.3g} against {steps.ssr:.3g} after "
                          f"{steps.substeps} sub-steps): give a smaller max_step (loss=learn.BodyLoss(max_step=...))",
                          UserWarning, stacklevel=2)
        fits.append((f"{family.name}, {kind} drag", problem, results, criterion))
    scores = tuple(family_score(name, criterion) for name, _, _, criterion in fits)
    best = lowest([(s.bic, s.effective_parameters) for s in scores])
    choice = FamilyChoice(scores[best].family, "bic", scores)
    records = []
    for name, problem, results, criterion in fits:
        last = results[-1]
        results[-1] = dataclasses.replace(last, record=dataclasses.replace(
            last.record, details={**last.record.details, **criterion, "family": name}))
        records.append(dataclasses.replace(training_record(problem, results), choice=choice))
    problem = fits[best][1]
    return problem.map(problem.y0), tuple(r for k, r in enumerate(records) if k != best) + (records[best],)


def drag_fit(start: Any, iterations: int, rtol: float, context: Context) -> tuple[Any, list, Any, dict[str, Any]]:
    """`(problem, results, steps, criterion)`: a drag family's problem `start` solved by
    Levenberg-Marquardt (kept only if it lowers the loss) with its sub-steps refined until its
    step errs below the data (`solve_within_noise`); its `information_criterion` with the
    sub-steps and the discretisation error."""
    problem, results, steps = solve_within_noise(start, (KeepIfBetter(LevenbergMarquardt(iterations, rtol)),),
                                                 context)
    criterion = information_criterion(problem, problem.y0, results[-1].linearisation)
    criterion.update({"substeps": steps.substeps, "discretisation_ssr": steps.discretisation_ssr})
    return problem, results, steps, criterion


def body_loss_from_data(data: BodyObservations, loss: BodyLoss | None) -> BodyLoss:
    """`loss`, or `learn.BodyLoss` in sub-steps of `STEP_ANGLE` of the fastest observed rotation."""
    if loss is None:
        fastest = max(float(np.max(np.linalg.norm(v, axis=1))) for v in _velocities(data))
        return BodyLoss(max_step=STEP_ANGLE / fastest if fastest > 0 else None)
    if not isinstance(loss, BodyLoss):
        raise TypeError(f"loss must be a learn.BodyLoss for body observations; got {type(loss).__name__}")
    return loss


def body_drag_start(system, data: BodyObservations, family: Family, method, any_axes: bool, kind: str) -> Dissipative:
    r"""The start of a drag family on body observations: $\widetilde H$ and a diagonal drag from
    the weak form with the drag (`weak_form_drag`: linear for "linear", quadratic for
    "quadratic", both for "ridge"), each drag coefficient at least its floor (`_floor`: a zero
    factor has no gradient)."""
    estimates = {k: weak_form_drag(data, k, linear=family.bias, diagonal=not family.any_axes)
                 for k in (("linear", "quadratic") if kind == "ridge" else (kind,))}
    A, b, _, _ = estimates["quadratic" if kind != "linear" else "linear"]
    xi = np.concatenate(_velocities(data))
    mu = np.linalg.solve(A, (xi - b).T).T
    size = float(np.sqrt(np.mean(np.sum(mu**2, axis=1)))) or 1.0
    net = GLPNet(system, terms=family.terms_of(system, A, b, size), method=method)
    rate = float(np.sqrt(np.mean(np.sum(xi**2, axis=1)))) or 1.0
    floor = _floor(net, data, rate)
    roots = {k: np.sqrt(np.maximum(np.diag(D), floor[k])) for k, (_, _, D, _) in estimates.items()}
    drag = LearnedDrag(system.dim, kind, any_axes=any_axes)
    if kind == "ridge":
        drag = eqx.tree_at(lambda d: (d.factor, d.quadratic_factor), drag,
                           (jnp.asarray(roots["linear"]), jnp.asarray(roots["quadratic"])))
    else:
        root = roots[kind]
        drag = eqx.tree_at(lambda d: d.factor, drag, jnp.asarray(np.diag(root) if any_axes else root))
    return Dissipative(net, drag)


def observed_drag_start(system, data: Observations, family: Family, method, any_axes: bool, kind: str) -> Dissipative:
    r"""The start of a drag family on observed states: $\widetilde H$ from the finite
    differences (`Family.start`), the drag at its floor (`_floor`)."""
    net = GLPNet(system, terms=family.start(system, data, state_size(system, data)), method=method)
    A, b = _affine(net)
    xi = np.concatenate(list(data.states)) @ A.T + b
    rate = float(np.sqrt(np.mean(np.sum(xi**2, axis=1)))) or 1.0
    floor = _floor(net, data, rate)
    drag = LearnedDrag(system.dim, kind, any_axes=any_axes, scale=floor["quadratic" if kind == "quadratic" else "linear"])
    if kind == "ridge":
        drag = eqx.tree_at(lambda d: d.quadratic_factor, drag, jnp.full(system.dim, math.sqrt(floor["quadratic"])))
    return Dissipative(net, drag)


def _floor(net: GLPNet, data, rate: float) -> dict[str, float]:
    """The smallest drag a fit starts from, by kind: a rate $|AD|$ of `START_RATE` per unit of
    the data's mean span (divided by the RMS rate for the quadratic drag)."""
    A, _ = _affine(net)
    curvature = float(np.mean(np.abs(np.linalg.eigvalsh(0.5 * (A + A.T))))) or 1.0
    linear = START_RATE / (_span(data) * curvature)
    return {"linear": linear, "quadratic": linear / rate}


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
