r"""W6 (beyond the paper): nonholonomic systems, the Suslov problem and the Chaplygin sleigh:
energy and constraint against time, the approach to the asymptotic motion and the cost of a
step, for heyoka, the classical integrators, a learned map that keeps the constraint and a
neural ODE ([Nonholonomic constraints][conventions-nonholonomic]).

Protocol (the issue's): the Suslov problem with I = (1, 2, 3), a = (1, 1, 1) (not an eigenvector
of the inertia) and the Chaplygin sleigh with m = 1, I = 1, a = 0.5. Training data: heyoka
(tolerance eps) from `n_train` random unit momenta projected onto the constraint, sampled every
h = 0.1 for `train_steps` steps, as **body velocities** (what a gyroscope or an odometer reads),
with Gaussian noise of a fraction `noise` of their RMS size. Test: `n_test` further starts to
t = `t_end` against heyoka, every model stepping h = 0.1: the classical integrators on the
momenta (RK4, the implicit midpoint rule, `integrators.GaussLegendre4`; the discrete
Lagrange-d'Alembert method, measured on its discrete velocities, which it keeps admissible, its
heading $\theta_{k+1} = \theta_k + h\omega_k$ its own reconstruction; its symmetric composition
by TripleJump in the velocities, `integrators.ComposedLagrangeDAlembert`, order 4, without a
heading), `learn.DAlembertMap`
(its constraint and learned energy kept for any weights; `lm_steps` Levenberg-Marquardt steps on
the trajectory loss), `learn.QuadraticDAlembertMap` (the family of every quadratic energy,
four parameters, stepped by its exact flow; fitted the same way; for the sleigh also with its
mirror symmetry, `reflection=0`) and `learn.NeuralODE` on the velocities (tanh; its hidden
layers and budget, at most `neural_ode_iterations` L-BFGS-B iterations, chosen on held-out training
trajectories: every study's rule, `paper._neural_ode.fit_neural_ode`). Beside the classical
integrators, the exact flow in closed form (`QuadraticDAlembertMap.from_system`).

Figures, each the largest over the test starts: the relative error of the true energy
$\tfrac12\xi^\top\mathbb M\xi$ against its value at the start (it is constant: the reaction
does no work), the relative constraint $|C\xi|/(|c_i||\xi|)$, the relative state error at $t_\text{end}$
(the asymptotic motion: the Suslov body's steady rotation, the sleigh's straight line), the
settling time (after which the state stays within 1% of its value at $t_\text{end}$) against
heyoka's, and the microseconds a step (a compiled rollout of the test starts, the faster of two,
divided by steps and starts; for heyoka its whole integration, the faster of two, divided by
the output steps). For
the sleigh also the speed at $t_\text{end}$ and the heading, unwrapped along the run and
reconstructed from the velocities by the trapezoid rule, $\theta_{n+1} = \theta_n +
\tfrac h2(\omega_n + \omega_{n+1})$ (the heading of `DAlembertMap.lifted_step`; heyoka's from
its configurations). The figure `nonholonomic.png` draws the energy error, the constraint and
the distance to the asymptotic state against time.
"""

from __future__ import annotations

import abc
import dataclasses
import functools
import time
from pathlib import Path
from typing import Any

import numpy as np

import integrators as it
import learn
import liepoisson as lp
from integrators.internals import figure, save_figure, series_styles

from ._experiment import Column, Profile, fmt, profiles, table_lines
from ._neural_ode import HIDDEN, fit_neural_ode
from ._runner import AbstractStudy
from ._study import AbstractStudyModel

H = 0.1
SETTLED = 0.01  # the settling time: the state stays within this relative distance of its final value
EVERY = 10  # the series of the figure: every EVERY-th step
DATA_SEED, NOISE_SEED, TEST_SEED = 0, 1, 2
#: The neural ODE's hidden layers tried (`paper._neural_ode.fit_neural_ode`).
NEURAL_ODE_HIDDEN = HIDDEN
#: The basis direction of the admissible velocities a mirror symmetry flips, per system that has
#: one (`learn.QuadraticDAlembertMap(reflection=...)`): the sleigh's omega -> -omega.
MIRRORS = {"Chaplygin sleigh": 0}
CLASSICAL = {"RK4": it.RK4, "implicit midpoint": it.ImplicitMidpoint, "GaussLegendre4": it.GaussLegendre4}


PROFILES = profiles(
    # "smoke" exercises the whole pipeline in seconds (tests); numbers are meaningless.
    smoke=Profile(n_train=6, train_steps=5, n_test=2, t_end=2.0, noises=(0.0, 1e-3), lm_steps=2, neural_ode_iterations=2),
    quick=Profile(n_train=100, train_steps=20, n_test=12, t_end=200.0, noises=(0.0, 1e-3), lm_steps=50,
                  neural_ode_iterations=500),
    full=Profile(n_train=100, train_steps=20, n_test=12, t_end=200.0, noises=(0.0, 1e-3), lm_steps=200,
                 neural_ode_iterations=2000),
)


def systems() -> dict[str, lp.systems.LiePoissonDAlembert]:
    """The study's systems, by name."""
    return {"Suslov": lp.systems.suslov((1.0, 2.0, 3.0), (1.0, 1.0, 1.0)),
            "Chaplygin sleigh": lp.systems.chaplygin_sleigh(1.0, 1.0, 0.5)}


def is_sleigh(system: lp.systems.LiePoissonDAlembert) -> bool:
    """Whether `system` moves on SE(2) (its heading and speed are reported)."""
    return system.group is not None and system.group.size == 9


def starts(system: lp.systems.LiePoissonDAlembert, n: int, seed: int) -> np.ndarray:
    """`n` random unit momenta projected onto the constraint, `(n, dim)`."""
    y = np.random.default_rng(seed).normal(size=(n, system.dim))
    return np.asarray(system.project(y / np.linalg.norm(y, axis=1, keepdims=True)))


def metric(system: lp.systems.LiePoissonDAlembert) -> np.ndarray:
    r"""$\mathbb M$ of $H = \tfrac12\mu^\top\mathbb M^{-1}\mu$: the true energy of a body
    velocity is $\tfrac12\xi^\top\mathbb M\xi$."""
    return system.kinetic_metric()


def observations(system, P: Profile, noise: float) -> it.Observations:
    """The training data: heyoka's body velocities every `H`, with Gaussian noise of a fraction
    `noise` of their RMS size."""
    xi = np.asarray(system.body_velocity(it.ground_truth(system, starts(system, P.n_train, DATA_SEED), H,
                                                          P.train_steps).states))
    rms = float(np.sqrt(np.mean(np.sum(xi**2, axis=-1))))
    noisy = xi + noise * rms * np.random.default_rng(NOISE_SEED).normal(size=xi.shape)
    return it.Observations(system, H * np.arange(P.train_steps + 1), list(noisy))


@dataclasses.dataclass(frozen=True)
class W6Row:
    system: str
    model: str
    kind: str  # "heyoka", "classical", "learned" or "baseline"
    noise: float | None
    energy_error_max: float
    constraint_max: float
    final_state_max: float
    final_state_mean: float
    settling_time_max: float  # the latest over the starts; inf if one never settles
    us_per_step: float | None
    fit_seconds: float | None
    diverged_at: float | None  # the first time a start left the finite range, or None
    speed_error_max: float | None  # the sleigh's, at t_end, relative
    heading_error_max_rad: float | None
    heading_error_max_rel: float | None  # relative to heyoka's angle turned
    # the figure's series (max over the starts, every EVERY-th step)
    energy_series: list[float]
    constraint_series: list[float]
    distance_series: list[float]


@dataclasses.dataclass(frozen=True)
class Truth:
    """heyoka's test trajectories of one system: velocities `(n, steps + 1, dim)`, headings
    unwrapped (the sleigh's; else None) and the seconds it took."""

    velocities: np.ndarray
    headings: np.ndarray | None
    seconds: float


def headings(omega: np.ndarray, h: float) -> np.ndarray:
    r"""The heading $\theta_n - \theta_0$ from angular velocities `(n, steps + 1)` by the
    trapezoid rule."""
    increments = 0.5 * h * (omega[:, 1:] + omega[:, :-1])
    return np.concatenate([np.zeros_like(omega[:, :1]), np.cumsum(increments, axis=1)], axis=1)


def settling_times(xi: np.ndarray, h: float) -> np.ndarray:
    """Per trajectory `(n, steps + 1, dim)`: the time after which the state stays within
    `SETTLED` of its last value, relative to its size (inf if it is not finite)."""
    with np.errstate(invalid="ignore", over="ignore"):  # a diverged trajectory: inf, never settled
        distance = np.linalg.norm(xi - xi[:, -1:], axis=-1) / np.linalg.norm(xi[:, -1:], axis=-1)
    out = np.full(xi.shape[0], np.inf)
    for i, d in enumerate(distance):
        if np.all(np.isfinite(d)):
            far = np.nonzero(d > SETTLED)[0]
            out[i] = 0.0 if far.size == 0 else (far[-1] + 1) * h
    return out


def measure(system_label: str, system, name: str, kind: str, xi: np.ndarray, truth: Truth, *, noise: float | None = None,
            us_per_step: float | None = None, fit_seconds: float | None = None,
            heading: np.ndarray | None = None) -> W6Row:
    """The figures of velocities `xi` `(n, steps + 1, dim)` (non-finite after a divergence)
    against heyoka's; the sleigh's `heading` `(n, steps + 1)` reconstructed from `xi` unless
    given (heyoka's own, from its configurations)."""
    reference = truth.velocities
    M, C = metric(system), np.asarray(system.constraints)
    finite = np.all(np.isfinite(xi), axis=-1)
    bad = np.nonzero(~np.all(finite, axis=0))[0]
    diverged_at = float(bad[0] * H) if bad.size else None

    def energy(x):
        return 0.5 * np.einsum("...a,ab,...b->...", x, M, x)

    with np.errstate(invalid="ignore", over="ignore"):
        # the energy is constant: every model's (and heyoka's own) error against the start's
        energy_error = np.where(finite, np.abs(energy(xi) / energy(reference[:, :1]) - 1.0), np.inf)
        size = np.linalg.norm(xi, axis=-1)
        constraint = np.where(finite, np.max(np.abs(xi @ C.T) / np.linalg.norm(C, axis=1), axis=-1)
                              / np.where(size > 0, size, 1.0), np.inf)
        asymptote = reference[:, -1:]
        distance = np.where(finite, np.linalg.norm(xi - asymptote, axis=-1) / np.linalg.norm(asymptote, axis=-1),
                            np.inf)
    final = distance[:, -1]
    speed = heading_max = heading_rel = None
    if truth.headings is not None:
        with np.errstate(invalid="ignore", over="ignore"):
            speed = float(np.max(np.where(finite[:, -1], np.abs(xi[:, -1, 1] - reference[:, -1, 1])
                                          / np.abs(reference[:, -1, 1]), np.inf)))
            heading = headings(xi[..., 0], H) if heading is None else heading
            turn = np.abs(heading[:, -1] - truth.headings[:, -1])
        turn = np.where(finite[:, -1], turn, np.inf)
        heading_max = float(np.max(turn))
        turned = np.abs(truth.headings[:, -1])
        with np.errstate(divide="ignore", invalid="ignore"):  # a start that does not turn: 0 of 0, else inf
            heading_rel = float(np.max(np.where(turn == 0.0, 0.0, turn / turned)))

    def series(x):  # for the figure: four digits
        return [float(f"{v:.4g}") for v in np.max(x, axis=0)[::EVERY]]

    return W6Row(system=system_label, model=name, kind=kind, noise=noise,
                 energy_error_max=float(np.max(energy_error)), constraint_max=float(np.max(constraint)),
                 final_state_max=float(np.max(final)), final_state_mean=float(np.mean(final)),
                 settling_time_max=float(np.max(settling_times(xi, H))), us_per_step=us_per_step,
                 fit_seconds=fit_seconds, diverged_at=diverged_at, speed_error_max=speed,
                 heading_error_max_rad=heading_max, heading_error_max_rel=heading_rel,
                 energy_series=series(energy_error), constraint_series=series(constraint),
                 distance_series=series(distance))


def timed_rollout(step_map: it.AbstractStepMap, y0: np.ndarray, n_steps: int) -> tuple[np.ndarray, float]:
    """Every step of `step_map` from `y0` `(n, dim)` (non-finite after a divergence) and the
    microseconds a step and start (compiled; the faster of two runs)."""
    best, ys = np.inf, None
    for _ in range(2):
        begin = time.perf_counter()
        ys = np.asarray(step_map.rollout(y0, n_steps, nonfinite="return"))
        best = min(best, time.perf_counter() - begin)
    return ys, 1e6 * best / (n_steps * y0.shape[0])


def ground_truth(system, P: Profile) -> Truth:
    """heyoka from the test starts to `t_end`, every step (the sleigh with its configurations)."""
    n_steps = round(P.t_end / H)
    y0 = starts(system, P.n_test, TEST_SEED)
    g0 = np.tile(np.eye(3).reshape(1, 9), (P.n_test, 1)) if is_sleigh(system) else None
    seconds = np.inf
    for _ in range(2):  # the faster of two: the first compiles heyoka's integrator
        begin = time.perf_counter()
        truth = it.ground_truth(system, y0, H, n_steps, **({"g0": g0} if g0 is not None else {}))
        seconds = min(seconds, time.perf_counter() - begin)
    velocities = np.asarray(system.body_velocity(truth.states))
    heading = None
    if g0 is not None:
        heading = np.unwrap(lp.systems.sleigh_pose(np.asarray(truth.configurations))[..., 0], axis=1)
        heading = heading - heading[:, :1]
    return Truth(velocities, heading, seconds)


class Condition:
    """A system of W6 at a profile: heyoka's test trajectories (`truth`, computed when a row
    first needs them: a rerun that reads every row integrates nothing) and the test starts."""

    def __init__(self, name: str, system: lp.systems.LiePoissonDAlembert, P: Profile):
        self.name, self.system, self.P = name, system, P
        self.n_steps = round(P.t_end / H)

    @functools.cached_property
    def truth(self) -> Truth:
        return ground_truth(self.system, self.P)

    @functools.cached_property
    def momenta0(self) -> np.ndarray:
        return starts(self.system, self.P.n_test, TEST_SEED)


@dataclasses.dataclass(frozen=True)
class Run:
    """A model's velocities on a condition's test starts: `(n, steps + 1, dim)`, the
    microseconds a step, and the sleigh's heading if the model has its own (else `None`)."""

    velocities: np.ndarray
    us_per_step: float
    heading: np.ndarray | None = None


class AbstractNonholonomicModel(AbstractStudyModel):
    """A model of W6: `fit(system, data)` (the training velocities, for the models that learn),
    then `run` from the condition's test starts. `kind` is the rows' ("heyoka", "classical",
    "learned" or "baseline"); `noise` the training data's (`None`: nothing learned)."""

    kind: str = "classical"
    noise: float | None = None

    def fit(self, system, data, *, progress=False):
        return None

    @abc.abstractmethod
    def run(self, fitted: Any, condition: Condition) -> Run:
        """The velocities of `fitted` from the test starts, timed."""

    @property
    def key(self) -> str:
        """The row's file name (without system and suffix)."""
        return self.label.lower().replace(" ", "_")


@dataclasses.dataclass(frozen=True)
class Heyoka(AbstractNonholonomicModel):
    """heyoka itself (tolerance eps): the truth's row, its integration timed."""

    label: str = "heyoka"
    kind: str = "heyoka"

    def run(self, fitted, condition):
        truth = condition.truth
        return Run(truth.velocities, 1e6 * truth.seconds / (condition.n_steps * condition.P.n_test), truth.headings)


@dataclasses.dataclass(frozen=True)
class ClassicalModel(AbstractNonholonomicModel):
    """A classical integrator `make(system, H)` on the momenta; its velocities from them."""

    label: str
    make: Any = None

    def fit(self, system, data, *, progress=False):
        return self.make(system, H)

    def run(self, fitted, condition):
        mu, us = timed_rollout(fitted, condition.momenta0, condition.n_steps)
        return Run(np.asarray(condition.system.body_velocity(mu)), us)


@dataclasses.dataclass(frozen=True)
class DiscreteLagrangeDAlembertModel(ClassicalModel):
    """`integrators.DiscreteLagrangeDAlembert`, measured on its discrete velocities (the ones it
    keeps admissible); its heading its own reconstruction, $\theta_{k+1} = \theta_k + h\\omega_k$."""

    label: str = "discrete Lagrange-d'Alembert"
    make: Any = it.DiscreteLagrangeDAlembert

    @property
    def key(self):
        return "discrete_lagrange_dalembert"

    def run(self, fitted, condition):
        p, us = timed_rollout(fitted, condition.momenta0, condition.n_steps)
        xi = np.asarray(fitted.velocity(p))
        heading = None
        if condition.truth.headings is not None:  # g_{k+1} = g_k exp(h xi_k): theta_{k+1} = theta_k + h omega_k
            heading = np.concatenate([np.zeros_like(xi[:, :1, 0]), np.cumsum(H * xi[:, :-1, 0], axis=1)], axis=1)
        return Run(xi, us, heading)


@dataclasses.dataclass(frozen=True)
class ComposedLagrangeDAlembertModel(ClassicalModel):
    """`integrators.ComposedLagrangeDAlembert` (TripleJump in the velocities); no heading: its
    sub-steps' poses are not kept."""

    label: str = "DLA, TripleJump"
    make: Any = it.ComposedLagrangeDAlembert

    @property
    def key(self):
        return "dla_triplejump"


@dataclasses.dataclass(frozen=True)
class ExactFlowModel(AbstractNonholonomicModel):
    """The exact flow in closed form (`learn.QuadraticDAlembertMap.from_system`), on the velocities."""

    label: str = "exact flow"

    def fit(self, system, data, *, progress=False):
        return learn.QuadraticDAlembertMap.from_system(system, H)

    def run(self, fitted, condition):
        return Run(*timed_rollout(fitted, condition.truth.velocities[:, 0], condition.n_steps))


class AbstractLearnedVelocityModel(AbstractNonholonomicModel):
    """A map fitted to the training velocities at `noise`, stepping the velocities."""

    kind = "learned"

    def run(self, fitted, condition):
        return Run(*timed_rollout(fitted, condition.truth.velocities[:, 0], condition.n_steps))

    @property
    def key(self):
        return f"{self.label.lower().replace(',', '').replace(' ', '_')}_noise{self.noise:g}"


@dataclasses.dataclass(frozen=True)
class DAlembertMapModel(AbstractLearnedVelocityModel):
    """`learn.DAlembertMap` (its constraint and learned energy kept for any weights), `lm_steps`
    Levenberg-Marquardt steps on the trajectory loss."""

    noise: float = 0.0
    lm_steps: int = 200
    label: str = "DAlembertMap"

    def fit(self, system, data, *, progress=False):
        fitted, _ = learn.fit(learn.DAlembertMap(system, key=DATA_SEED, h=H), data,
                              optimiser=learn.KeepIfBetter(learn.LevenbergMarquardt(self.lm_steps)),
                              validation_fraction=0.0, progress=progress)
        return fitted


@dataclasses.dataclass(frozen=True)
class QuadraticDAlembertMapModel(AbstractLearnedVelocityModel):
    """`learn.QuadraticDAlembertMap` (every quadratic energy, stepped by its exact flow), with the
    mirror symmetry `reflection` if given, fitted as `DAlembertMapModel`."""

    noise: float = 0.0
    lm_steps: int = 200
    reflection: int | None = None
    label: str = "QuadraticDAlembertMap"

    def fit(self, system, data, *, progress=False):
        mirror = {} if self.reflection is None else {"reflection": self.reflection}
        fitted, _ = learn.fit(learn.QuadraticDAlembertMap(system, h=H, **mirror), data,
                              optimiser=learn.KeepIfBetter(learn.LevenbergMarquardt(self.lm_steps)),
                              validation_fraction=0.0, progress=progress)
        return fitted


@dataclasses.dataclass(frozen=True)
class NeuralODEModel(AbstractLearnedVelocityModel):
    """`learn.NeuralODE` on the velocities, its size and budget (at most `iterations` L-BFGS-B
    iterations) chosen among `NEURAL_ODE_HIDDEN` by `paper._neural_ode.fit_neural_ode`."""

    noise: float = 0.0
    iterations: int = 2000
    label: str = "neural ODE"
    kind: str = "baseline"

    def fit(self, system, data, *, progress=False):
        return fit_neural_ode(data, self.iterations, NEURAL_ODE_HIDDEN, key=DATA_SEED, seed=DATA_SEED).net


def models(name: str, P: Profile) -> list[AbstractNonholonomicModel]:
    """W6's models of the system `name`, in the order of its rows: heyoka, the classical
    integrators, the exact flow, then per noise the learned maps and the neural ODE."""
    out: list[AbstractNonholonomicModel] = [Heyoka()]
    out += [ClassicalModel(label, make) for label, make in CLASSICAL.items()]
    out += [DiscreteLagrangeDAlembertModel(), ComposedLagrangeDAlembertModel(), ExactFlowModel()]
    for noise in P.noises:
        out += [DAlembertMapModel(noise, P.lm_steps), QuadraticDAlembertMapModel(noise, P.lm_steps)]
        if name in MIRRORS:  # the family with the body's mirror symmetry
            out.append(QuadraticDAlembertMapModel(noise, P.lm_steps, reflection=MIRRORS[name],
                                                  label="QuadraticDAlembertMap, mirror"))
        out.append(NeuralODEModel(noise, P.neural_ode_iterations))
    return out


def line(r: W6Row) -> str:
    """One row in words (progress and verdict)."""
    text = (f"{r.system}, {r.model}" + (f" (noise {r.noise:g})" if r.noise is not None else "")
            + f": energy {fmt(r.energy_error_max)}, constraint {fmt(r.constraint_max)}, state at the end "
            f"{fmt(r.final_state_max)}, settled by t = {_time(r.settling_time_max)}")
    if r.heading_error_max_rad is not None:
        text += (f", speed {fmt(r.speed_error_max)}, heading {fmt(r.heading_error_max_rad)} rad "
                 f"({fmt(r.heading_error_max_rel)} of the turn)")
    if r.diverged_at is not None:
        text += f", diverged at t = {r.diverged_at:g}"
    return text


def verdict(rows: list[W6Row]) -> list[str]:
    out = []
    for name in dict.fromkeys(r.system for r in rows):
        mine = [r for r in rows if r.system == name]
        heyoka = next(r for r in mine if r.kind == "heyoka")
        out.append(f"{name}: heyoka keeps the constraint to {fmt(heyoka.constraint_max)} and settles (within "
                   f"{SETTLED:g}) by t = {_time(heyoka.settling_time_max)}")
        for r in mine:
            if r.kind == "heyoka":
                continue
            text = line(r) + f" (heyoka settles by {_time(heyoka.settling_time_max)})"
            if r.kind == "learned":
                checks = [f"constraint {'<=' if r.constraint_max <= 1e-13 else 'NOT <='} 1e-13",
                          f"energy {'within' if r.energy_error_max <= 0.01 else 'NOT within'} 1%",
                          f"asymptotic state {'within' if r.final_state_max <= 0.01 else 'NOT within'} 1%"]
                if r.heading_error_max_rel is not None:
                    checks += [f"speed {'within' if r.speed_error_max <= 0.01 else 'NOT within'} 1%",
                               f"heading {'within' if r.heading_error_max_rel <= 0.01 else 'NOT within'} 1%"]
                text += " [" + "; ".join(checks) + "]"
            out.append(text)
    return out


class W6(AbstractStudy):
    id = "W6"
    title = "Nonholonomic systems: the Suslov problem and the Chaplygin sleigh"
    profiles = PROFILES
    row_type = W6Row

    def conditions(self, P):
        for name, system in systems().items():
            print(f"W6: {name}", flush=True)
            yield Condition(name, system, P)

    def models(self, P, condition):
        return models(condition.name, P)

    def evaluate(self, condition, model, progress):
        system = condition.system
        data = None if model.noise is None else observations(system, condition.P, model.noise)
        begin = time.perf_counter()
        fitted = model.fit(system, data, progress=progress)
        seconds = time.perf_counter() - begin
        run = model.run(fitted, condition)
        return measure(condition.name, system, model.label, model.kind, run.velocities, condition.truth,
                       noise=model.noise, us_per_step=run.us_per_step, heading=run.heading,
                       fit_seconds=None if model.noise is None else seconds)

    def row_name(self, profile, condition, model):
        return f"{condition.name.lower().replace(' ', '_')}_{model.key}.json"

    def line(self, row):
        return line(row)

    def verdict(self, rows, conditions):
        return verdict(rows)

    def figures(self, rows, conditions, out_dir):
        return [plot(rows, out_dir)]

    def summary(self, P, rows, conditions):
        return {"profile_settings": P.as_dict(), "h": H, "settled": SETTLED}

    def summary_rows(self, rows):
        return [(f"{r.system} {r.model}" + (f" (noise {r.noise:g})" if r.noise is not None else "")
                 + ": state error at the end", "—", fmt(r.final_state_max), "—") for r in rows]

    def description(self, metrics):
        P = metrics.get("profile_settings", {})
        return (f"Every model steps h = {metrics.get('h')} to t = {P.get('t_end')} from {P.get('n_test')} "
                f"starts against heyoka (tol = eps); learned maps from {P.get('n_train')} trajectories x "
                f"{P.get('train_steps')} steps of body velocities. Figures: the largest over the starts. "
                f"Figure: `nonholonomic.png`.")

    def sections(self, metrics, rows):
        return [("Every model", table_lines(COLUMNS, rows))]


COLUMNS = (
    Column("system", lambda r: r.system),
    Column("model", lambda r: r.model),
    Column("noise", lambda r: "—" if r.noise is None else f"{r.noise:g}"),
    Column("energy error, max", lambda r: r.energy_error_max),
    Column("constraint, max", lambda r: r.constraint_max),
    Column("state error at the end, max (mean)", lambda r: f"{fmt(r.final_state_max)} ({fmt(r.final_state_mean)})"),
    Column("settled by t", lambda r: _time(r.settling_time_max)),
    Column("sleigh: speed, heading [rad] at the end", lambda r: "—" if r.heading_error_max_rad is None else
           f"{fmt(r.speed_error_max)}, {fmt(r.heading_error_max_rad)}"),
    Column("us a step", lambda r: r.us_per_step),
    Column("fit [s]", lambda r: r.fit_seconds),
)


def _time(x: float) -> str:
    return "never" if not np.isfinite(x) else f"{x:.1f}"


def plot(rows: list[W6Row], out_dir: Path) -> str:
    """Per system (columns): the energy error, the constraint and the distance to heyoka's
    asymptotic state against time (rows, log scale), the largest over the starts."""
    names = list(dict.fromkeys(r.system for r in rows))
    fig = figure(figsize=(6 * len(names), 11))
    axes = np.asarray(fig.subplots(3, len(names), sharex=True)).reshape(3, len(names))
    labels = ("relative energy error", "relative constraint", "distance to the asymptotic state")
    for column, name in zip(axes.T, names):
        mine = [r for r in rows if r.system == name]
        for r, style in zip(mine, series_styles(len(mine))):
            label = r.model + (f", noise {r.noise:g}" if r.noise else "")
            for ax, values in zip(column, (r.energy_series, r.constraint_series, r.distance_series)):
                v = np.asarray(values, dtype=float)
                t = np.arange(len(v)) * EVERY * H
                # zeros (exact starts) are drawn at round-off, not dropped
                ax.semilogy(t, np.maximum(v, 1e-17), label=label, color=style["color"], ls=style["ls"], lw=1.2)
        column[0].set_title(name)
        column[0].legend(fontsize=7)
        for ax, label in zip(column, labels):
            ax.set_ylabel(label)
        column[-1].set_xlabel("t")
    fig.tight_layout()
    name = "nonholonomic.png"
    save_figure(fig, out_dir / name, dpi=110)
    return name


EXPERIMENT = W6()
