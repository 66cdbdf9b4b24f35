r"""The data-driven splitting recipe: a G-LPNet is a splitting of a learned Hamiltonian
$\widetilde H = \sum_s\Phi_s(\langle\alpha_s, y\rangle)$; fitted as a Strang splitting,
then composed by a higher-order method and fitted again."""

from __future__ import annotations

import dataclasses
import functools
import math
import warnings
from collections.abc import Hashable, Sequence
from typing import Any

import equinox as eqx
import jax
import numpy as np
from numpy.typing import ArrayLike

from integrators import AbstractObservedTrajectories, BodyObservations, Observations, Trajectories
from integrators.splitting import LieTrotter, Strang, TripleJump
from liepoisson.internals import refuse_nonholonomic, show_progress
from liepoisson.systems import AbstractDissipativeSystem, AbstractPoissonSystem

from .._models._drag import DRAG_KINDS, Dissipative
from .._models._glpnet import GLPNet, check_method
from .._solvers._levenberg_marquardt import LevenbergMarquardt
from .._solvers._quasi_newton import ScipyBFGS
from .._solvers._record import TrainingRecord
from .._solvers._stage import AbstractStage, Context, KeepIfBetter, WarmStart
from ._body import weak_form_drag, weak_form_quadratic
from ._criterion import (
    BIC_RESOLUTION,
    FamilyChoice,
    SkippedFamily,
    family_score,
    lowest,
    lowest_held_out,
)
from ._dissipative import body_drag_start, body_loss_from_data, drag_fit, observed_drag_start
from ._families import FAMILIES, Family
from ._fit import fit, resolve_loss, solve, training_record
from ._held_out import (
    group_folds,
    group_scores,
    held_out_errors,
    segment_trajectories,
    trajectory_groups,
)
from ._observed import TrajectoryLoss, discretisation_ssr, information_criterion
from ._problem import Fitted
from ._steps import solve_within_noise
from ._units import state_size


def fit_splitting(
    system: AbstractPoissonSystem,
    data: Trajectories | Observations | tuple[ArrayLike, ArrayLike],
    method: Any = TripleJump,
    *,
    iterations: int | None = None,
    loss: TrajectoryLoss | None = None,
    activation: str | None = None,
    key: int | jax.Array = 0,
    h: float | None = None,
    validation_fraction: float | None = None,
    seed: int = 0,
    progress: bool | None = None,
    families: Sequence[Family] | None = None,
    selection: str | None = None,
    groups: Sequence[Hashable] | None = None,
    dissipation: str | Sequence[str] | None = "auto",
) -> tuple[GLPNet | Dissipative, Sequence[TrainingRecord]]:
    r"""A G-LPNet for any Poisson system with test flows, as a data-driven splitting method;
    returns `(network, records)`, one `TrainingRecord` per fit.

    1. **Strang.** `GLPNet(system, n, method=Strang(), linear_term=True)`: one module per basis
       direction $e_k$ ($n$ = `system.dim`), $\Phi_k' = a_k\sigma(x) + e_kx + b_k$, whose step
       is the Strang splitting of $\widetilde H = \sum_k\Phi_k(c_ky_k)$, order 2. Fitted by
       BFGS (`iterations`, default 1000) from the identity warm start
       (`learn.WarmStart(learn.ScipyBFGS(...))`).
    2. **Refit by `method`** (default `integrators.splitting.TripleJump()`; `None` stops at
       step 1): the same learned pieces composed by `method`, fitted again by BFGS from there:
       the pieces move from the modified Hamiltonian of the Strang fit to that of the method.
       Both stages are exact Poisson maps for any weights; `method`'s `ordering`, if it has
       one, orders the modules of both.

    With `integrators.Observations` (noisy states at uneven times) the G-LPNet is composed by
    `method` from the start and fitted by Levenberg-Marquardt (`learn.LevenbergMarquardt`,
    `iterations` steps at most, default 200) with `loss` (default `learn.TrajectoryLoss()`:
    whole trajectories rolled out at their own intervals, initial states fitted with the map).
    Without `activation`, the nested families `learn.FAMILIES` of $\widetilde H$ are fitted,
    on the basis axes and along learned directions (any symmetric quadratic form, linear terms,
    sigmoid pieces), each from its least-squares quadratic of the observations' finite
    differences (`learn.Family.start`; the terms selected by the criterion for "quadratic,
    selected", `learn.select_quadratic`), a sigmoid family from the fit of the quadratic family
    it extends (`learn.Family.from_nested`; skipped when that family's residuals are `PRUNE_RATIO`
    (100) times the best's so far); a family containing one whose residuals are within that
    family's own discretisation error (exact data it explains as far as its step allows:
    `Family.contains`, `discretisation_ssr`) is skipped too, since it could only fit the
    step's error; a skipped family is announced by a `UserWarning` naming it, why, and how to
    fit it anyway. Every family is fitted to every trajectory (`validation_fraction` must be 0
    or `None` on observations: a validation split's noisy loss would veto converged fits), then
    chosen by `selection`:

    - `"held-out"` (the default on observations): whole groups of trajectories (`groups`, one
      label per trajectory, e.g. recording sessions; by default the data's own `groups`, else
      each trajectory its own group)
      are dealt by `seed` into 5 folds (as scikit-learn's `GroupKFold`; fewer groups, one per
      fold); each family is refitted without each fold (Levenberg-Marquardt from its fit on
      every trajectory) and scored by the mean squared residual of the fold's trajectories, each
      rolled out from its start fitted to its own observations with the refitted map held (so
      the noise of a first observation does not enter). Of the families within one standard
      error of the lowest held-out error (the per-group paired difference), the one with the
      fewest effective parameters, then the first fitted (`learn.FamilyChoice`);
    - `"bic"`: the lowest Bayesian information criterion (`information_criterion`; of criteria
      within 0.1 of the lowest, which the criterion cannot tell apart, the one with the fewest
      effective parameters, then the first fitted).

    With noisy data, parameters the data do not need cost accuracy; which criterion suits which
    data: conventions, [Observations][conventions-observations]. The records are those of every
    family fitted, the chosen one last; each last stage's `details` hold its criterion and
    held-out error, and every record's `choice` the typed `learn.FamilyChoice` (every family's
    `learn.FamilyScore`, the `learn.SkippedFamily` with their reasons, the chosen family).

    With `integrators.BodyObservations` (configurations and/or body velocities, what a star
    tracker and a gyroscope record) the momenta are latent: each family is fitted by
    Levenberg-Marquardt on `learn.BodyLoss` (the lifted step rolled out from a fitted momentum
    and configuration per trajectory; without `loss`, in sub-steps of 0.1 rad of the fastest
    observed rotation, doubled while the fitted map's own discretisation error exceeds a tenth
    of its misfit: conventions, "The step of a fit"), started from the inertia of `learn.body_quadratic_estimate`;
    the information criterion chooses as above ("quadratic, selected" is not offered: its selection reads
    momenta); a family whose start misfits the weak-form equations `SCREEN_RATIO` (10) times
    more than the best start, that extends one whose residuals are 100 times the best's, or
    that contains one fitted within its discretisation error is skipped (named in each
    record's `details["skipped"]` and `choice.skipped`); `selection` is `"bic"` by default,
    `"held-out"` on request (whole trajectories, or `groups`, held out as above: the choice
    that must transfer to a new recording session). With
    `dissipation` the families also hold a G-LPNet of a quadratic $\widetilde H$ composed with a
    learned drag (`learn.Dissipative`, fitted as `learn.fit_dissipative` does: sub-steps until
    the map's own error is below a tenth of its misfit), one family per drag kind
    (`learn.DRAG_KINDS`; `dissipation` a sequence of them), on the axes of the best conservative
    family so far; `"auto"` (the default) offers the linear and quadratic drags when the weak form
    with a drag (`learn.weak_form_drag`) fits the rates `DRAG_SCREEN_RATIO` (3) times better than
    without (a body that loses energy to the air), and names the
    ratio in `choice.skipped` otherwise; `None` offers none. The criterion chooses among all.
    On observed states (`integrators.Observations`) the same drag families are offered when the
    observed Casimirs follow a trend in time `DRAG_SCREEN_RATIO` times better than a constant
    (`casimir_trend_ratio`: states leaving their orbit), started at a small drag.

    `activation` fixes the pieces' $\sigma$ (`"sigmoid"`, the default for pairs and
    trajectories; `"identity"`: a quadratic $\widetilde H$ on the axes); `families`, the
    families to choose from on observations (default `learn.FAMILIES`; e.g.
    `(learn.FAMILIES[3],)` for any quadratic form alone), fitted in the order given (the
    skipping rules look back only). The other arguments are `learn.fit`'s (`validation_fraction`
    `None`: 0.2 on pairs and trajectories).
    """
    check_conservative(system)
    if method is not None:  # a wrong method fails before the first fit
        method = check_method(method)
        if isinstance(method, LieTrotter):
            raise ValueError("method=LieTrotter would not continue from the Strang fit: the paper's Lie-Trotter "
                             "G-LPNet weighs its Hamiltonian by 1/n_modules; use learn.GLPNet(system) and learn.fit")
        method.check_terms(system.dim, f"a G-LPNet of {system.dim} modules (one per basis direction)")
    observed = isinstance(data, AbstractObservedTrajectories)
    if validation_fraction is None:  # on observations every trajectory is fitted; folds hold some out
        validation_fraction = 0.0 if observed else 0.2
    elif observed and validation_fraction != 0:
        raise ValueError(
            f"validation_fraction={validation_fraction!r}: on observations every family is fitted to every "
            "trajectory and held-out trajectories choose the family (selection='held-out', whole groups with "
            "groups=); a validation split would veto converged fits on the noise of its trajectories. Pass 0 or None")
    selection = check_selection(selection, data, groups)
    if groups is None and selection == "held-out":  # the sessions the data were labelled with
        groups = data.groups
    common = {"h": h, "validation_fraction": validation_fraction, "seed": seed, "progress": progress,
              "selection": selection, "groups": groups}
    if families is not None:
        if activation is not None:
            raise ValueError("give activation= or families=, not both (a family has its activation)")
        families = tuple(families)
        if not families or not all(isinstance(f, Family) for f in families):
            raise TypeError(f"families must be a non-empty sequence of learn.Family (e.g. learn.FAMILIES[:2]); "
                            f"got {families!r}")
        if not isinstance(data, AbstractObservedTrajectories):
            raise ValueError("families= chooses between families on observations (integrators.Observations or "
                             "BodyObservations); pairs and trajectories fit one family (activation=)")
    common["dissipation"] = check_dissipation(dissipation, data, activation, families)
    return _recipe(data, system, method, loss, activation, iterations, key, common, families)


#: With `dissipation="auto"`, drag families are offered on body observations when the weak form
#: with a drag misfits the rates this many times less than the fullest quadratic without
#: (`learn.weak_form_drag`, any axes and linear terms; the ratios measured in air, in vacuum and on
#: W4's bodies: BENCHMARKS.md, "W7: bodies in air").
DRAG_SCREEN_RATIO = 3.0


def casimir_trend_ratio(system: AbstractPoissonSystem, data: Observations) -> float:
    r"""How much better the observed Casimirs follow a linear trend in time than a constant, per
    trajectory: $\sum$ SSR(constant) / $\sum$ SSR(line), the largest over the Casimirs (each
    scaled by its spread). Noise alone gives about 1 + 1/(n - 2); a force that moves the states
    off their orbit (air drag taking $|\Pi|$ away) gives its trend. 0 for a system without
    Casimirs (no orbit to leave: the screen cannot tell, and offers nothing)."""
    if not system.n_casimirs:
        return 0.0
    constant, line = np.zeros(system.n_casimirs), np.zeros(system.n_casimirs)
    for t, y in zip(data.times, data.states, strict=True):
        if t.size < 3:
            continue
        c = np.asarray(system.casimirs(y)).reshape(t.size, -1)
        c = c - c.mean(axis=0)
        constant += np.sum(c**2, axis=0)
        design = np.column_stack([np.ones_like(t), t - t.mean()])
        residual = c - design @ np.linalg.lstsq(design, c, rcond=None)[0]
        line += np.sum(residual**2, axis=0)
    return float(np.max(constant / np.maximum(line, 1e-300)))


def check_dissipation(dissipation: Any, data: Any, activation: str | None, families: Any) -> tuple[str, ...] | str:
    """`dissipation` as `"auto"` or a tuple of drag kinds (empty: none)."""
    if dissipation is None:
        return ()
    if isinstance(dissipation, str) and dissipation == "auto":
        # a fixed activation or family list is a conservative choice made by the caller
        observed = isinstance(data, AbstractObservedTrajectories)
        return "auto" if observed and activation is None and families is None else ()
    kinds = (dissipation,) if isinstance(dissipation, str) else tuple(dissipation)
    if not kinds or any(k not in DRAG_KINDS for k in kinds):
        raise ValueError(f"dissipation must be 'auto', None or a sequence of {DRAG_KINDS}; got {dissipation!r}")
    if not isinstance(data, AbstractObservedTrajectories):
        raise ValueError("dissipation= offers drag families on observations (integrators.Observations, "  # noqa: TRY004 - an unfit value (file, data), not an argument of the wrong type
                         "BodyObservations); pairs and trajectories fit one conservative family")
    return kinds


#: The family criteria of `fit_splitting` on observations (`FamilyChoice.selection`).
SELECTIONS = ("held-out", "bic")


def check_selection(selection: str | None, data: Any, groups: Sequence[Hashable] | None) -> str | None:
    """`selection` checked and resolved (`None`: "held-out" on `integrators.Observations`, "bic"
    on body observations, where held-out folds refit every family five times over sub-stepped
    rollouts: asked for, e.g. with `groups=` of recording sessions); `None` for pairs and
    trajectories, which refuse it and `groups`."""
    if not isinstance(data, AbstractObservedTrajectories):
        if selection is not None or groups is not None:
            raise ValueError("selection= and groups= choose between families on observations "
                             "(integrators.Observations); pairs and trajectories fit one family")
        return None
    if selection is None:
        selection = "held-out" if isinstance(data, Observations) else "bic"
    if selection not in SELECTIONS:
        raise ValueError(f"selection must be one of {SELECTIONS}; got {selection!r}")
    if groups is not None and selection != "held-out":
        raise ValueError(f"groups= are held out by selection='held-out'; got selection={selection!r}")
    return selection


def check_conservative(system: AbstractPoissonSystem) -> None:
    """`ValueError` for a dissipative `system`: a G-LPNet is a Poisson map, built on a
    Hamiltonian system's bracket; and for a nonholonomic one (its Casimirs change)."""
    refuse_nonholonomic(system, "a G-LPNet")
    if isinstance(system, AbstractDissipativeSystem):  # a system of the right type, unsuitable
        raise ValueError(  # noqa: TRY004
            f"system is dissipative ({system!r}): a G-LPNet is a Poisson map and keeps the energy up to its error, "
            f"so it cannot follow energy decay on the orbit. Fit an LPNet (learn.fit(learn.LPNet(system), data)), "
            f"whose steps keep the Casimirs and can lose energy; to fit a G-LPNet to these data anyway (to see what "
            f"it misses), pass the conservative part, system.conservative. docs/conventions.md, 'Dissipation on the "
            f"orbit'")


def warn_dissipative_data(data: Observations) -> None:
    """A `UserWarning` when the observations come from a dissipative system: the G-LPNet fitted
    with a conservative bracket cannot follow their energy decay."""
    if isinstance(data.system, AbstractDissipativeSystem):
        warnings.warn(
            f"the observations are of a dissipative system ({data.system!r}): a G-LPNet is a Poisson map and cannot "
            f"follow their energy decay; an LPNet can (learn.fit(learn.LPNet(system), data); docs/conventions.md, "
            f"'Dissipation on the orbit')", UserWarning, stacklevel=4)


@functools.singledispatch
def _recipe(data, system, method, loss, activation, iterations, key, common, families=None):
    """Pairs and trajectories: Strang, then the same pieces composed by `method`, by BFGS."""
    iterations = BFGS_ITERATIONS if iterations is None else iterations
    if loss is not None:
        raise ValueError("loss= is for observations (integrators.Observations); pairs and Trajectories are fitted on "
                         "the one-step state loss")
    # the Strang stage applies the pieces in the order the refit will
    strang_method = Strang(ordering=None if method is None else method.ordering)
    net = GLPNet(system, system.dim, key=key, method=strang_method, linear_term=True,
                 activation="sigmoid" if activation is None else activation)
    common = {k: common[k] for k in ("h", "validation_fraction", "seed", "progress")}
    strang, first = fit(net, data, optimiser=KeepIfBetter(WarmStart(ScipyBFGS(iterations))), **common)
    if method is None:
        return strang, (first,)
    refit = GLPNet(system, terms=strang.terms, method=method, h=strang.h)
    fitted, second = fit(refit, data, optimiser=KeepIfBetter(ScipyBFGS(iterations)), **common)
    return fitted, (first, second)


#: BFGS iterations per stage on pairs, Levenberg-Marquardt steps per stage on observations.
BFGS_ITERATIONS, LM_ITERATIONS = 1000, 200

#: Each fit to observations stops once 3 Levenberg-Marquardt steps lower the loss by less
#: than this fraction: noisy data put a floor under the loss long before `iterations`, and
#: exact data keep lowering it by more (BENCHMARKS.md, "Learning from observations").
RTOL = 1e-10

# ... or by less than `BIC_RESOLUTION` of the information criterion over those steps: a
# decrease the criterion cannot tell from none, while the weights creep along directions the
# data barely fix (learned directions of equal eigenvalues rotating into each other).

@_recipe.register
def _(data: Observations, system, method, loss, activation, iterations, key, common, families=None):
    """Observations: each family (or the one of `activation`) fitted by Levenberg-Marquardt
    through `method` to every trajectory; chosen by held-out prediction or the lowest BIC."""
    warn_dissipative_data(data)
    families = families or FAMILIES if activation is None else (
        Family(activation, activation, linear_term=activation != "identity", bias=True),)
    return search_families(_ObservedStates(system, data, resolve_loss(loss, data)), families, method, iterations,
                           common)


@dataclasses.dataclass
class _Fit:
    """One family fitted by `search_families`: its `problem` solved, the stages' `results`, the
    `family` (a `Family`, or a `_DragFamily`) and its `criterion` (`information_criterion`,
    with the discretisation error and sub-steps where measured)."""

    problem: Any
    results: list
    family: Any
    criterion: dict[str, Any]

    @property
    def bic(self) -> float:
        return self.criterion["bic"]


class _DataKind:
    """What `search_families` needs of one kind of observations: the loss, the starting terms of
    a family (and a reason to skip it before fitting), how a family's fit is solved, and the
    trajectory of each segment of the loss (which held-out folds remove)."""

    def __init__(self, system: AbstractPoissonSystem, data: Any, loss: Any):
        self.system, self.data, self.loss = system, data, loss

    def components(self) -> int:
        """The observed numbers (what the criterion's resolution is divided over)."""
        return self.data.n_observations * self.system.dim

    def screen(self, family: Family) -> str | None:
        """A reason to skip `family` before fitting it, or `None`."""
        return None

    def terms(self, family: Family) -> Any:
        """The learned pieces `family` starts from (`learn.RidgeTerms`)."""
        raise NotImplementedError

    def warm_start(self, family: Family) -> bool:
        """Whether a family's fit starts with the identity warm start (not from a nested fit)."""
        return False

    def solve(self, start: Any, stages: tuple, context: Context) -> tuple[Any, list, dict[str, Any]]:
        """`(problem solved, results, what to add to its criterion)`."""
        problem, results = solve(start, stages, context)
        return problem, results, {}

    def segment_trajectories(self) -> np.ndarray:
        """The trajectory of each segment of the loss's problems."""
        raise NotImplementedError


class _ObservedStates(_DataKind):
    """`integrators.Observations`: each family from the least-squares quadratic of the finite
    differences, in the data's units; the family's own warm start."""

    def __init__(self, system, data, loss):
        super().__init__(system, data, loss)
        self.size = state_size(system, data)

    def terms(self, family):
        return family.start(self.system, self.data, self.size)

    def warm_start(self, family):
        return family.warm_start

    def segment_trajectories(self):
        return segment_trajectories(self.data, self.loss.window)


class _ObservedBodies(_DataKind):
    """`integrators.BodyObservations`: each family from the quadratic of `weak_form_quadratic`
    (skipped when it misfits the weak form `SCREEN_RATIO` times the best start), solved with
    sub-steps from the data when no loss was given (`solve_within_noise`)."""

    def __init__(self, system, data, loss, families):
        super().__init__(system, data, body_loss_from_data(data, loss))
        self.steps_from_data = loss is None  # sub-steps of STEP_ANGLE, refined until below the noise
        self.velocities = data.velocities if data.velocities is not None else [
            data.group_velocities(j) for j in range(len(data))]
        self.starts = {(f.bias, f.any_axes): weak_form_quadratic(data, linear=f.bias, diagonal=not f.any_axes)
                       for f in families}
        self.least = min(misfit for _, _, misfit in self.starts.values())

    def components(self):
        return super().components() * len(self.data.measured)

    def screen(self, family):
        misfit = self.starts[family.bias, family.any_axes][2]
        if misfit > SCREEN_RATIO * self.least:
            return (f"its quadratic start misfits the weak-form equations {misfit / self.least:.3g} times more than "
                    f"the best start (more than SCREEN_RATIO = {SCREEN_RATIO:g})")
        return None

    def terms(self, family):
        A, b, _ = self.starts[family.bias, family.any_axes]
        return family.terms_of(self.system, A, b, _momentum_size(A, b, self.velocities))

    def solve(self, start, stages, context):
        if not self.steps_from_data:
            return super().solve(start, stages, context)
        problem, results, steps = solve_within_noise(start, stages, context)
        return problem, results, {"substeps": steps.substeps}

    def segment_trajectories(self):
        return np.arange(len(self.data))  # whole trajectories, one segment each


def search_families(kind: _DataKind, families: Sequence[Family], method: Any, iterations: int | None,
                    common: dict[str, Any]) -> tuple[Any, tuple[TrainingRecord, ...]]:
    """Each family fitted by Levenberg-Marquardt through `method` (Strang by default) to every
    trajectory of `kind`'s data, in order: skipped when `kind` screens it out or `skip_reason`
    says its fit could not help; an extension from its nested family's fit, stopped once it
    cannot catch up with the best criterion (`catch_up_target`); then the drag families
    (`drag_fits`); chosen by held-out prediction (whole groups) or the lowest BIC
    (`chosen_by`)."""
    system, data, loss = kind.system, kind.data, kind.loss
    method = Strang() if method is None else method
    iterations = LM_ITERATIONS if iterations is None else iterations
    context = Context(seed=int(common["seed"]), progress=show_progress(common["progress"]))
    split = {"h": common["h"], "validation_fraction": common["validation_fraction"], "seed": common["seed"],
             "normalise": False}
    group_of = trajectory_groups(common["groups"], len(data)) if common["selection"] == "held-out" else None
    rtol = max(RTOL, BIC_RESOLUTION / kind.components())
    fits: list[_Fit] = []
    fitted, ssr, skipped, explained = {}, {}, [], []
    for k, family in enumerate(families):
        reason = kind.screen(family) or skip_reason(family, ssr, explained)
        if reason is not None:
            skipped.append(skip(family, reason))
            continue
        net = GLPNet(system, terms=kind.terms(family), method=method)
        start = loss.problem(net, data, **split)
        warm_start, target = kind.warm_start(family), None
        if family.nested in fitted:  # from the nested family's fit, map and initial states
            nested = fitted[family.nested]
            net = eqx.tree_at(lambda n: n.terms, net, family.from_nested(net.terms, nested.model.terms))
            start = start.with_start(Fitted(net, nested.starts, nested.shared))
            warm_start = False
            target = catch_up_target(start, [f.bic for f in fits])
        problem, results, measured = kind.solve(
            start, (_lm(LevenbergMarquardt(iterations, rtol, target=target), warm_start),), context)
        fitted[family.name] = problem.y0
        criterion = information_criterion(problem, problem.y0, results[-1].linearisation)
        criterion.update(step_accuracy(problem, family, families[k + 1 :], results[-1].linearisation))
        criterion.update(measured)
        if explained_within_its_step(criterion):
            explained.append(family)
        ssr[family.name] = criterion["ssr"]
        fits.append(_Fit(problem, results, family, {**criterion, "target_loss": target}))
    fits += drag_fits(system, data, method, iterations, rtol, context, common["dissipation"], fits, skipped, loss)
    scores = tuple(family_score(f.family.name, f.criterion) for f in fits)
    choice = FamilyChoice(scores[0].family, common["selection"], scores, tuple(skipped))
    if group_of is not None and len(fits) > 1:  # one family fitted: nothing to hold out for
        choice = held_out_choice(fits, kind.segment_trajectories(), group_of, iterations, rtol, context, choice)
    return chosen_last(fits, *chosen_by(choice))


def _lm(stage: LevenbergMarquardt, warm_start: bool) -> AbstractStage:
    """`stage` kept only if it lowers the loss, after the warm start if `warm_start`."""
    return KeepIfBetter(WarmStart(stage) if warm_start else stage)


def chosen_by(choice: FamilyChoice) -> tuple[int, FamilyChoice]:
    """The index of the family `choice`'s criterion chooses (held-out errors where measured,
    else the BIC), and `choice` naming it."""
    index = lowest_held_out(choice.scores) if choice.by_held_out is not None else lowest(
        [(s.bic, s.effective_parameters) for s in choice.scores])
    return index, dataclasses.replace(choice, chosen=choice.scores[index].family)


def held_out_choice(fits: Sequence[Any], rows: np.ndarray, group_of: Any, iterations: int,
                    rtol: float, context: Context, choice: FamilyChoice) -> FamilyChoice:
    """`choice` with each fitted family's held-out error (`learn._training._held_out`): folds
    of whole groups, each family refitted per fold from its fit on every trajectory; `rows`:
    the trajectory of each segment of the fits' problems."""
    folds = group_folds(group_of, context.seed)
    errors = {}
    for f in fits:
        fold_context = dataclasses.replace(context, desc=f"{f.family.name}: held-out folds")
        errors[f.family.name] = held_out_errors(f.problem, rows, folds, iterations, rtol, fold_context)
    by_family = group_scores(errors, group_of)
    scores = tuple(dataclasses.replace(s, held_out_error=by_family[s.family][0],
                                       held_out_standard_error=by_family[s.family][1]) for s in choice.scores)
    return dataclasses.replace(choice, selection="held-out", scores=scores, folds=len(folds),
                               groups=int(group_of.max()) + 1)


def chosen_last(fits: Sequence[Any], index: int, choice: FamilyChoice) -> tuple[Any, tuple[TrainingRecord, ...]]:
    """`(the chosen map, records)`: every fitted family's record (`details` with its criterion,
    the family's name, the skipped families' names, its held-out error), the chosen one last,
    `choice` on each."""
    records = []
    for f, score in zip(fits, choice.scores, strict=True):
        problem, results, criterion = f.problem, list(f.results), f.criterion
        last = results[-1]
        results[-1] = dataclasses.replace(last, record=dataclasses.replace(
            last.record, details={**last.record.details, **criterion, "family": f.family.name,
                                  "skipped": [s.family for s in choice.skipped],
                                  "held_out_error": score.held_out_error}))
        records.append(dataclasses.replace(training_record(problem, results), choice=choice))
    best = fits[index].problem
    return best.map(best.y0), tuple(r for k, r in enumerate(records) if k != index) + (records[index],)


def skip_reason(family: Family, ssr: dict[str, float], explained: Sequence[Family]) -> str | None:
    """Why `family` is not fitted (`extends_a_misfit`, `contains_an_explanation`), `None` if it is."""
    if extends_a_misfit(family, ssr):
        return (f"it extends {family.nested!r}, whose residuals are {ssr[family.nested] / min(ssr.values()):.3g} "
                f"times the best family's so far (more than PRUNE_RATIO = {PRUNE_RATIO:g}): its extra pieces lie "
                "along the same directions, which missed structure they cannot supply")
    within = [f.name for f in explained if extends_along_its_directions(family, f)]
    if within:
        return (f"it extends {within[0]!r} along the same directions, which fitted the observations within its own "
                "discretisation error: its extra terms could only fit the step's error")
    return None


def skip(family: Family, reason: str) -> SkippedFamily:
    """A `SkippedFamily`, announced by a `UserWarning` that says how to fit it anyway."""
    warnings.warn(f"fit_splitting: family {family.name!r} not fitted: {reason}. To fit it anyway, pass it alone: "
                  f"families=[f for f in learn.FAMILIES if f.name == {family.name!r}]", UserWarning, stacklevel=5)
    return SkippedFamily(family.name, reason)


def catch_up_target(start: Any, bics: Sequence[float]) -> float | None:
    r"""The loss an extension family started at `start` (its nested family's fit) must reach
    to beat the best information criterion of the families fitted so far (`bics`; `None` if
    none):
    $\exp((\mathrm{BIC}^* - k\log n)/n)$, the loss $\mathrm{SSR}/n$ at which
    $n\log(\mathrm{SSR}/n) + k\log n = \mathrm{BIC}^*$, with $k$ its effective parameters at
    the start (its extra pieces, started flat, have not yet all come into play, so $k$ is at
    most the fitted family's and the target at least its own). Levenberg-Marquardt stops a fit
    whose loss, at its recent rate, would not reach it (`LevenbergMarquardt(target=...)`): its
    extra parameters cost more than its loss repays. Only extensions: they start at a
    converged fit, so their rate from the start is their pace; a family from a least-squares
    start may fall slowly for its first steps, then fast (measured: the diamond's "quadratic,
    any axes" at noise 0, whose stop at step 6 changed the family chosen)."""
    if not bics:
        return None
    criterion = information_criterion(start, start.y0)
    n, k = criterion["n"], criterion["effective_parameters"]
    return math.exp((min(bics) - k * math.log(n)) / n)


def extends_a_misfit(family: Family, ssr: dict[str, float]) -> bool:
    """Whether `family` extends a nested family whose fit's sum of squared residuals (`ssr`, by
    family name, of the families fitted so far) is more than `PRUNE_RATIO` times the least:
    its extra pieces lie along the same directions as the nested family's, which missed
    structure they cannot supply (e.g. sigmoids on the basis axes for principal axes off them)."""
    return family.nested in ssr and ssr[family.nested] > PRUNE_RATIO * min(ssr.values())



def step_accuracy(problem: Any, family: Family, later: Sequence[Family], linearisation: Any = None) -> dict[str, Any]:
    """`{"discretisation_ssr": ...}` of a fitted family that a `later` family extends along its
    directions (`discretisation_ssr`, reading the fit's `linearisation`; none otherwise: nothing
    would be skipped on it)."""
    if not any(extends_along_its_directions(f, family) for f in later):
        return {}
    return {"discretisation_ssr": discretisation_ssr(problem, problem.y0, linearisation)}


def explained_within_its_step(criterion: dict[str, Any]) -> bool:
    """Whether a family's sum of squared residuals is within its discretisation error (both
    in `criterion`, from `information_criterion` and `step_accuracy`)."""
    return "discretisation_ssr" in criterion and criterion["ssr"] <= criterion["discretisation_ssr"]


def contains_an_explanation(family: Family, explained: Sequence[Family]) -> bool:
    """Whether `family` extends, along the same directions, one that fitted the observations
    to within its own discretisation error (`explained`): data that family explains as far as
    its step allows, exact data of a Hamiltonian it holds. More terms along the same pieces'
    directions (linear terms, sigmoids) could only fit the step's error (terms of the method's
    modified Hamiltonian), not more of the body, and the criterion, whose likelihood takes the
    residuals for noise, would choose them for that. Learned directions are still fitted
    after a family on the axes: they split the same Hamiltonian into other pieces, whose
    composition may err less at the data's steps (BENCHMARKS.md, "Exact data: families
    explained within the step's error")."""
    return any(extends_along_its_directions(family, f) for f in explained)


def extends_along_its_directions(family: Family, other: Family) -> bool:
    """Whether `family` contains `other` (`Family.contains`) with its pieces along the same
    kind of directions (both on the axes, or both learned)."""
    return family.contains(other) and family.any_axes == other.any_axes


#: On observations and body observations, a family that extends a nested one is skipped when
#: the nested family's sum of squared residuals is more than this many times the best family's
#: so far (`extends_a_misfit`). A residual 10x larger in RMS is structure (e.g. principal axes
#: off the basis axes) that the extension's sigmoid pieces along the same directions would
#: have to remove.
PRUNE_RATIO = 100.0

#: On body observations, a family whose quadratic start misfits the weak-form equations
#: (`weak_form_quadratic`) more than this many times the least of any family's is skipped.
#: The misfit is the least squared singular value of the same equations with fewer columns:
#: where the family holds the body, noise alone, within 2x of the fuller family's (tested);
#: the ratios on W4's rotated bodies: BENCHMARKS.md, "Every W4 fit under 2 minutes on 2 quiet cores".
SCREEN_RATIO = 10.0


@_recipe.register
def _(data: BodyObservations, system, method, loss, activation, iterations, key, common, families=None):
    """Body observations (configurations, velocities; momenta latent): each family from the
    quadratic of `weak_form_quadratic`, fitted by Levenberg-Marquardt on `learn.BodyLoss`
    through `method`; the lowest BIC wins (held-out sessions on request)."""
    if system.group != data.group:
        raise ValueError(f"system {system!r} moves configurations on {system.group!r}; the observations are on "
                         f"{data.group!r}")
    if families is not None and any(f.select for f in families):
        raise ValueError("families with select=True ('quadratic, selected') choose their terms on the momenta's "
                         "finite differences, which body observations do not have; leave them out")
    families = (families or tuple(f for f in FAMILIES if not f.select)) if activation is None else (
        Family(activation, activation, linear_term=activation != "identity", bias=True),)
    common = {**common, "validation_fraction": 0.0}
    return search_families(_ObservedBodies(system, data, loss, families), families, method, iterations, common)


@dataclasses.dataclass(frozen=True)
class _DragFamily:
    """A drag family's name, where a `Family` stands in the fits."""

    name: str


def _drag_screened(measured: str, meaning: str) -> SkippedFamily:
    """The drag families skipped by the screen of `dissipation="auto"`: what was `measured`
    (a ratio below `DRAG_SCREEN_RATIO`), what that means, and how to fit them anyway."""
    return SkippedFamily("drag families", (
        f"{measured} (less than DRAG_SCREEN_RATIO = {DRAG_SCREEN_RATIO:g}): {meaning}; "
        "pass dissipation=('linear', 'quadratic') to fit them anyway"))


def drag_fits(system, data: BodyObservations | Observations, method, iterations: int, rtol: float,
              context: Context, dissipation: tuple[str, ...] | str, fits: list, skipped: list,
              loss: TrajectoryLoss | None = None) -> list:
    """The fits (`_Fit`) of the drag families `dissipation` asks (`"auto"`: the linear and
    quadratic drag when the data show a loss a drag explains: `drag_screen`)."""
    if not dissipation:
        return []
    if dissipation == "auto" and isinstance(data, Observations):
        ratio = casimir_trend_ratio(system, data)
        if ratio < DRAG_SCREEN_RATIO:
            skipped.append(_drag_screened(
                f"the observed Casimirs follow a trend in time only {ratio:.3g} times better than a constant",
                "nothing the data show leaves the orbit"))
            return []
        dissipation = ("linear", "quadratic")
    if dissipation == "auto":
        # the fullest quadratic against it with a drag: the drag must explain what no quadratic does
        _, _, conservative = weak_form_quadratic(data, linear=True, diagonal=False)
        ratios = {k: conservative / max(weak_form_drag(data, k, linear=True, diagonal=False)[3], 1e-300)
                  for k in ("linear", "quadratic")}
        if max(ratios.values()) < DRAG_SCREEN_RATIO:
            skipped.append(_drag_screened(
                f"the weak form with a drag fits the rates only {max(ratios.values()):.3g} times better than without",
                "nothing the data show is lost to a drag"))
            return []
        dissipation = ("linear", "quadratic")
    best = min(fits, key=lambda f: f.bic) if fits else None
    any_axes = bool(best is not None and best.family.any_axes)
    family = next(f for f in FAMILIES if f.name == ("quadratic, any axes, even" if any_axes else "quadratic, even"))
    if isinstance(data, BodyObservations):
        loss, make = body_loss_from_data(data, None), body_drag_start
    else:
        loss, make = TrajectoryLoss() if loss is None else loss, observed_drag_start
    split = {"h": None, "validation_fraction": 0.0, "seed": context.seed, "normalise": False}
    out = []
    for kind in dissipation:
        problem, results, _, criterion = drag_fit(
            loss.problem(make(system, data, family, method, any_axes, kind), data, **split), iterations, rtol, context)
        out.append(_Fit(problem, results, _DragFamily(f"{family.name}, {kind} drag"), criterion))
    return out


def _momentum_size(A, b, velocities) -> float:
    r"""The RMS size of the momenta $\mu = A^{-1}(\xi - b)$ of the velocities (the latent
    states' scale), 1 if 0."""

    xi = np.concatenate(velocities)
    mu = np.linalg.solve(A, (xi - b).T).T
    size = float(np.sqrt(np.mean(np.sum(mu**2, axis=1))))
    return size if size > 0.0 else 1.0
