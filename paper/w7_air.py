"""W7 (beyond the paper): bodies in air. A tossed body loses angular momentum to the air: on
real flights of a racquet (about 1 s, spins of 5-30 rad/s about the intermediate axis, with
the tennis-racket flips of Dzhanibekov's effect) drag took ~15% of |L| and 28% of the energy
per flight. Here a simulated stand-in: an elongated flat body with its two larger moments
close, `INERTIA` = (1, 6, 7) (the intermediate axis unstable: a spin about it flips), under
quadratic drag $\\dot\\Pi = \\Pi\\times\\Omega - |\\Omega|\\,D\\,\\Omega$ (`liepoisson.systems.Forced(
RigidBody(I), QuadraticDrag(D))`, `DRAG` symmetric positive definite with an off-diagonal
term; heyoka's ground truth), which takes 8-20% of |L| over a 1-s flight at 5-15 rad/s. It is
observed by a 100-Hz gyroscope only (`H`: body rates, never the momenta), with absolute noise
`noise` rad/s per axis and a constant bias per session (each axis drawn with standard
deviation `BIAS` rad/s; no model fits it).

Protocol: fitted on one session of slower flights (`TRAIN_SPINS`: 5-15 rad/s about the
intermediate axis, the other two rates 5-15% of the spin so that it flips, `FLIGHT` s each),
tested on another session (its own bias) of flights twice as fast (`TEST_SPINS`, 10-30
rad/s). Every model predicts each test flight from its first gyro sample (noise and bias
included) and is measured against the true rates: the relative RMS rate error over the
flight (mean over the test flights), and the flip period (the mean interval between the sign
changes of the intermediate-axis rate) against the truth's, on the flights that flip at
least twice. Models:

- **dissipative G-LPNet**: `learn.fit_dissipative(RigidBody(), records, any_axes=True)`: a
  quadratic H~ along learned axes composed by TripleJump with the flow of a learned drag whose
  matrix is positive semidefinite for every weight (linear, quadratic or ridge drag, the
  lowest BIC), started at the weak-form quadratic of the rates, momenta latent
  (`learn.BodyLoss`, sub-steps of 0.1 rad refined until their error is below the noise), by
  Levenberg-Marquardt;
- **conservative G-LPNet**: `learn.fit_splitting(RigidBody(), records, families=...)` with the
  conservative families of `learn.FAMILIES` given explicitly: exactly Poisson, no drag (one step per sampling interval); what the structure without dissipation does with
  data that lose energy;
- **LPNet**: `learn.BodyLPNet` (an LPNet's Lie-Euler step on latent momenta with a learned
  linear gyroscope readout), started at the step of the weak-form quadratic, fitted on
  `learn.BodyLoss` in sub-steps: it keeps the latent Casimir |mu|, so it cannot lose |L|;
- **SINDy** and **weak SINDy** (pysindy): a polynomial field of degree 2 for the rates (with
  or without a constant), STLSQ with the threshold, the constant and the derivative (SINDy) or
  the support width (weak SINDy) chosen on the rollout errors of the TRAINING flights from
  starts fitted to each flight, never the test (every study's rule, `paper._sindy.choose_sparse_field`);
- **limit**: the true family (the principal moments' ratios I1/I2, I3/I2, the symmetric drag
  matrix D at the scale I2 = 6, and each flight's initial rates) fitted by
  `scipy.optimize.least_squares` (Levenberg-Marquardt, Jacobian by `jax.jacfwd`) on whole
  training flights, integrated by RK4 in `LIMIT_SUBSTEPS` sub-steps per sampling interval,
  from the truth 10% off and the first gyro samples: what these data allow at best;
- **Euler, no drag**: Euler's equations with the true inertia and no drag (nothing fitted):
  where a physicist would start.

What is identified: the principal moments over the intermediate one, and the drag as a rate,
$\\mathbb I^{-1}D(\\Omega)$ at $\\Omega$ = 10 rad/s about the intermediate axis (1/s; gauge-free:
the scale of the latent momenta cancels), against the truth's.

Rows are saved as they are measured (`<out>/W7/rows/`): an interrupted run resumes.
"""

from __future__ import annotations

import abc
import dataclasses
import functools
import math
import time
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from scipy.optimize import least_squares

import integrators as it
import learn
import liepoisson as lp
from integrators.internals import figure, save_figure, series_styles

from ._experiment import Column, Profile, fmt, optional, profiles, table_lines
from ._runner import AbstractStudy
from ._sindy import (
    BLOW_UP,
    SparseField,
    _flow,
    fit_sindy,
    fit_weak_sindy,
    relative_rms,
    sindy_available,
)
from ._study import AbstractStudyModel

#: The body: principal moments (an elongated flat body: the two larger close) and the
#: quadratic drag matrix D in the body frame (symmetric, positive definite, coupling axes 1
#: and 3), in units where I2 = 6.
INERTIA = (1.0, 6.0, 7.0)
DRAG = 6.0 * np.array([[0.006, 0.0, 0.002], [0.0, 0.018, 0.0], [0.002, 0.0, 0.014]])
H = 0.01  # the gyroscope's sampling interval: 100 Hz
FLIGHT = 1.0  # seconds per flight
TRAIN_SPINS, TEST_SPINS = (5.0, 15.0), (10.0, 30.0)  # rad/s about the intermediate axis
PERTURBATION = (0.05, 0.15)  # the other two rates, as a fraction of the spin
BIAS = 0.01  # rad/s: the standard deviation of each axis's constant bias in a session
#: The rate at which the drag is reported: rad/s about the intermediate axis.
REFERENCE_SPIN = 10.0
#: RK4 sub-steps per sampling interval of the limit's and Euler's integrations (0.03 rad per
#: sub-step at 30 rad/s: their error is far below the gyroscope's noise).
LIMIT_SUBSTEPS = 10
#: The learned maps predict in sub-steps of at most this rotation (rad; 7 per sampling interval at
#: 33 rad/s): what they learned is a Hamiltonian and a drag, not a step at the training spins.
PREDICTION_ANGLE = 0.05
#: The LPNet's training sub-steps (s): 0.04 rad at 16 rad/s.
LPNET_MAX_STEP = 0.0025
FIT_LIMIT_S = 120.0  # every fit should take less
DATA_SEED, TEST_SEED, TRAIN_SEED = 1, 100, 0


def air_body() -> lp.systems.Forced:
    """The tossed body: `RigidBody(INERTIA)` under `QuadraticDrag(DRAG)`."""
    return lp.systems.Forced(lp.systems.RigidBody(INERTIA), lp.systems.QuadraticDrag(DRAG))


@dataclasses.dataclass(frozen=True)
class Session:
    """Flights of one session: the sampling `times` `(m,)`, the true body rates `(n, m, 3)`,
    the gyroscope `records` (rates plus noise and the session's `bias`)."""

    times: np.ndarray
    rates: np.ndarray
    records: it.BodyObservations
    bias: np.ndarray

    @property
    def measured(self) -> np.ndarray:
        return np.stack(self.records.velocities)


def initial_rates(n: int, spins: tuple[float, float], rng: np.random.Generator) -> np.ndarray:
    """`(n, 3)` rates: a spin about the intermediate axis (either sign) with the other two a
    fraction `PERTURBATION` of it in a random direction."""
    spin = rng.uniform(*spins, n) * rng.choice([-1.0, 1.0], n)
    size = rng.uniform(*PERTURBATION, n) * np.abs(spin)
    angle = rng.uniform(0.0, 2.0 * np.pi, n)
    return np.column_stack([size * np.cos(angle), spin, size * np.sin(angle)])


def session(n: int, spins: tuple[float, float], noise: float, seed: int, duration: float = FLIGHT) -> Session:
    """`n` flights of `duration` s from `initial_rates(spins)`, heyoka's truth sampled every
    `H`, the gyroscope's rates with absolute noise `noise` rad/s and the session's bias."""
    rng = np.random.default_rng(seed)
    omega0 = initial_rates(n, spins, rng)
    steps = round(duration / H)
    truth = it.ground_truth(air_body(), omega0 * np.asarray(INERTIA), H, steps)
    rates = np.asarray(truth.states) / np.asarray(INERTIA)
    bias = rng.normal(0.0, BIAS, 3)
    measured = rates + noise * rng.normal(size=rates.shape) + bias
    times = H * np.arange(steps + 1)
    records = it.BodyObservations(lp.systems.RigidBody(), [times] * n, velocities=list(measured),
                                  metadata={"noise_rad_s": noise, "bias_rad_s": bias.tolist()})
    return Session(times, rates, records, bias)


# -- the true family, integrated by RK4 in JAX (the limit and Euler's equations) --

def _rates_field(omega, ratios, drag):
    r"""$\dot\Omega = \mathbb I^{-1}(\mathbb I\Omega\times\Omega - |\Omega|D\Omega)$, `ratios`
    the principal moments over I2 (I2 = `INERTIA[1]`), `drag` the 6 entries of D's upper triangle."""
    inertia = jnp.stack([ratios[0], jnp.ones_like(ratios[0]), ratios[1]]) * INERTIA[1]
    D = _symmetric(drag)
    speed = jnp.linalg.norm(omega, axis=-1, keepdims=True)
    return (jnp.cross(omega * inertia, omega) - speed * omega @ D) / inertia


def _symmetric(upper):
    a, b, c, d, e, f = (upper[k] for k in range(6))
    return jnp.array([[a, b, c], [b, d, e], [c, e, f]])


def _upper(D: np.ndarray) -> np.ndarray:
    return np.asarray(D)[np.triu_indices(3)]


@functools.partial(jax.jit, static_argnums=(3,))
def true_family_rates(ratios, drag, omega0, n_intervals: int):
    """Rates `(n, n_intervals + 1, 3)` of the true family from `omega0` `(n, 3)` every `H`
    (RK4, `LIMIT_SUBSTEPS` sub-steps per interval)."""
    k = H / LIMIT_SUBSTEPS

    def rk4(w, _):
        a = _rates_field(w, ratios, drag)
        b = _rates_field(w + 0.5 * k * a, ratios, drag)
        c = _rates_field(w + 0.5 * k * b, ratios, drag)
        d = _rates_field(w + k * c, ratios, drag)
        return w + k / 6.0 * (a + 2.0 * b + 2.0 * c + d), None

    def interval(w, _):
        w, _ = jax.lax.scan(rk4, w, None, length=LIMIT_SUBSTEPS)
        return w, w

    _, out = jax.lax.scan(interval, omega0, None, length=n_intervals)
    return jnp.concatenate([omega0[None], out]).transpose(1, 0, 2)


@dataclasses.dataclass(frozen=True)
class TrueFamily:
    """A member of the true family: the principal moments over I2 and D (at I2 = 6)."""

    ratios: np.ndarray
    D: np.ndarray


# -- the models --

@dataclasses.dataclass(frozen=True)
class Identified:
    """What a model found: the principal moments over the intermediate one (sorted), and the
    drag rate $\\mathbb I^{-1}D(\\Omega)$ at `REFERENCE_SPIN` about the intermediate axis (1/s)."""

    inertia_ratios: np.ndarray | None = None
    drag_rate: np.ndarray | None = None
    detail: str | None = None


def _sorted_ratios(M: np.ndarray) -> np.ndarray:
    values = np.linalg.eigvalsh(0.5 * (M + M.T))
    return values / values[1]


def true_drag_rate() -> np.ndarray:
    return REFERENCE_SPIN * np.diag(1.0 / np.asarray(INERTIA)) @ DRAG


class AbstractFlightModel(AbstractStudyModel):
    """A model of W7: fitted to the training session's gyro records of a rigid body (`body`, its
    inertia unknown), then predicting each test flight's rates from its first gyro sample."""

    @abc.abstractmethod
    def fit(self, body: lp.systems.RigidBody, train: Session, *, progress: bool = False) -> Any:
        """The fitted model."""

    @abc.abstractmethod
    def predict(self, fitted: Any, omega0: np.ndarray, n_intervals: int) -> np.ndarray:
        """Rates `(n, n_intervals + 1, 3)` every `H` from `omega0` `(n, 3)`."""

    def identified(self, fitted: Any) -> Identified:
        return Identified()


class AbstractLearnedFlightModel(AbstractFlightModel):
    """A learned map with latent momenta: starts from `learn.latent_momenta` of the first
    sample, rolled out in the fewest equal sub-steps of `H` that turn the fastest test flight by
    at most `PREDICTION_ANGLE` rad; the rates are its body velocities."""

    def predict(self, fitted, omega0, n_intervals):
        mu0 = np.asarray(learn.latent_momenta(fitted, omega0))
        k = max(1, math.ceil(H * float(np.max(np.linalg.norm(omega0, axis=-1))) / PREDICTION_ANGLE))
        mu = fitted.with_h(H / k).rollout(mu0, k * n_intervals, save_every=k, nonfinite="return")
        return np.asarray(jax.vmap(jax.vmap(fitted.body_velocity))(mu))


@dataclasses.dataclass(frozen=True)
class DissipativeFlightModel(AbstractLearnedFlightModel):
    """The dissipative G-LPNet of `learn.fit_dissipative`: a quadratic H~ along learned axes
    composed by TripleJump with a learned drag along any axes (linear, quadratic or ridge, the
    lowest BIC), fitted with the momenta latent in sub-steps refined until their error is below
    the noise."""

    label: str = "dissipative G-LPNet"
    #: The drag families tried (`None`: `learn.fit_dissipative`'s, all of them).
    kinds: tuple[str, ...] | None = None
    #: Levenberg-Marquardt steps per drag family (and per refinement of the sub-steps): on
    #: W7's flights the loss is flat from the 5th (BENCHMARKS.md, "W7: bodies in air").
    iterations: int = 20
    #: The profile's Levenberg-Marquardt steps (the fit takes at most `iterations` of them).
    steps: int = 200

    def fit(self, body, train, *, progress=False):
        kinds = {} if self.kinds is None else {"kinds": self.kinds}
        model, records = learn.fit_dissipative(body, train.records, any_axes=True,
                                               iterations=min(self.steps, self.iterations), seed=TRAIN_SEED,
                                               progress=False, **kinds)
        choice = records[-1].choice
        return DissipativeFit(model, f"{choice.chosen}, sub-steps x{choice.score(choice.chosen).substeps}")

    def predict(self, fitted, omega0, n_intervals):
        return super().predict(fitted.model, omega0, n_intervals)

    def identified(self, fitted):
        A, _ = fitted.model.quadratic_part()
        A = np.asarray(A)
        reference = np.array([0.0, REFERENCE_SPIN, 0.0])
        drag = A @ np.asarray(fitted.model.drag.matrix(reference))
        return Identified(_sorted_ratios(np.linalg.inv(A)), drag, fitted.chosen)


@dataclasses.dataclass(frozen=True)
class DissipativeFit:
    """A fitted `learn.Dissipative` and the family `learn.fit_dissipative` chose."""

    model: learn.Dissipative
    chosen: str


@dataclasses.dataclass(frozen=True)
class ConservativeFlightModel(AbstractLearnedFlightModel):
    """The conservative G-LPNet of `learn.fit_splitting` (the families of `learn.FAMILIES` that
    body records allow, the choice `fit_splitting`'s): no drag."""

    label: str = "conservative G-LPNet"
    #: The names of the families of H~ tried (`None`: `learn.fit_splitting`'s, all of them).
    families: tuple[str, ...] | None = None
    #: Levenberg-Marquardt steps per family.
    steps: int = 200

    def fit(self, body, train, *, progress=False):
        # the families given explicitly (a conservative choice: without them fit_splitting may
        # offer drag families on body records), all but those that select terms on momenta
        families = [f for f in learn.FAMILIES if not f.select and (self.families is None or f.name in self.families)]
        net, _ = learn.fit_splitting(body, train.records, loss=learn.BodyLoss(),
                                     iterations=self.steps, seed=TRAIN_SEED, key=TRAIN_SEED, progress=False,
                                     families=families)
        return net

    def identified(self, fitted):
        hessian = np.asarray(jax.hessian(fitted.hamiltonian)(np.zeros(3)))
        terms = fitted.terms
        family = f"{terms.activation}, {'any axes' if terms.full_vectors else 'axes'}"
        return Identified(_sorted_ratios(np.linalg.inv(hessian)), np.zeros((3, 3)), f"H~ {family}")


@dataclasses.dataclass(frozen=True)
class LPNetFlightModel(AbstractLearnedFlightModel):
    """The LPNet on latent momenta (`learn.BodyLPNet`: a Lie-Euler step of a learned generator,
    one hidden layer of 16, tanh, and a learned linear gyroscope readout), started at the step
    of the weak-form quadratic and fitted on `learn.BodyLoss` in sub-steps of at most
    `LPNET_MAX_STEP` (the Lie-Euler step is of order 1): each step keeps the latent Casimir
    |mu|, so it cannot lose angular momentum to the air."""

    label: str = "LPNet"
    #: Levenberg-Marquardt steps.
    steps: int = 200

    def fit(self, body, train, *, progress=False):
        A, b, _ = learn.weak_form_quadratic(train.records, linear=True, diagonal=False)
        model = learn.BodyLPNet.at_quadratic(body, A, b, hidden=(16,), key=TRAIN_SEED)
        fitted, _ = learn.fit(model, train.records, loss=learn.BodyLoss(max_step=LPNET_MAX_STEP),
                              optimiser=learn.KeepIfBetter(learn.LevenbergMarquardt(self.steps)), progress=False)
        return fitted

    def identified(self, fitted):
        K = np.asarray(fitted.readout)
        return Identified(_sorted_ratios(np.linalg.inv(0.5 * (K + K.T))), np.zeros((3, 3)))


@dataclasses.dataclass(frozen=True)
class LimitFlightModel(AbstractFlightModel):
    """The true family fitted by `scipy.optimize.least_squares` on whole training flights from
    the truth 10% off (ratios and D) and the first gyro samples (initial rates)."""

    label: str = "limit"
    #: Levenberg-Marquardt steps (at least 10: `least_squares` counts evaluations, twice as many).
    steps: int = 200

    def fit(self, body, train, *, progress=False):
        measured = train.measured
        n, m = measured.shape[:2]
        truth = np.concatenate([[INERTIA[0] / INERTIA[1], INERTIA[2] / INERTIA[1]], _upper(DRAG)])
        x0 = np.concatenate([1.1 * truth, measured[:, 0].ravel()])

        def residuals(x):
            rates = true_family_rates(x[:2], x[2:8], x[8:].reshape(n, 3), m - 1)
            return (rates - measured).ravel()

        residuals = jax.jit(residuals)
        jacobian = jax.jit(jax.jacfwd(residuals))
        result = least_squares(lambda x: np.asarray(residuals(x)), x0, jac=lambda x: np.asarray(jacobian(x)),
                               method="lm", x_scale="jac", max_nfev=max(2 * self.steps, 20))
        return TrueFamily(result.x[:2], np.asarray(_symmetric(result.x[2:8])))

    def predict(self, fitted, omega0, n_intervals):
        return np.asarray(true_family_rates(fitted.ratios, _upper(fitted.D), omega0, n_intervals))

    def identified(self, fitted):
        inertia = np.array([fitted.ratios[0], 1.0, fitted.ratios[1]]) * INERTIA[1]
        drag = REFERENCE_SPIN * np.diag(1.0 / inertia) @ fitted.D
        return Identified(np.sort(inertia) / np.sort(inertia)[1], drag)


@dataclasses.dataclass(frozen=True)
class EulerFlightModel(LimitFlightModel):
    """Euler's equations with the true inertia and no drag: nothing fitted."""

    label: str = "Euler, no drag"

    def fit(self, body, train, *, progress=False):
        return TrueFamily(np.array([INERTIA[0] / INERTIA[1], INERTIA[2] / INERTIA[1]]), np.zeros((3, 3)))


class AbstractSparseFlightModel(AbstractFlightModel):
    """A sparse polynomial field of degree 2 for the rates (pysindy, STLSQ), its threshold,
    library and derivative or support width chosen on the rollouts of the TRAINING flights from
    starts fitted to each flight (`paper._sindy.choose_sparse_field`: every study's rule). Integrated by
    LSODA."""

    @abc.abstractmethod
    def fit_field(self, times: list[np.ndarray], rates: list[np.ndarray]) -> SparseField:
        """The field chosen by the rule for the measured `rates` at their `times`."""

    def fit(self, body, train, *, progress=False):
        return self.fit_field(list(train.records.times), list(train.records.velocities))

    def predict(self, fitted, omega0, n_intervals):
        times = H * np.arange(n_intervals + 1)
        return np.stack([_flow(fitted, w, times, BLOW_UP * max(float(np.linalg.norm(w)), 1e-3)) for w in omega0])

    def identified(self, fitted):
        return Identified(detail=f"{fitted.setting}, threshold {fitted.threshold:g}, "
                                 f"{'with' if fitted.constant else 'no'} constant, {fitted.field.terms} terms")


@dataclasses.dataclass(frozen=True)
class SINDyFlightModel(AbstractSparseFlightModel):
    """SINDy on differences of the rates (`paper._sindy.fit_sindy`)."""

    label: str = "SINDy"

    def fit_field(self, times, rates):
        return fit_sindy(times, rates)


@dataclasses.dataclass(frozen=True)
class WeakSINDyFlightModel(AbstractSparseFlightModel):
    """Weak SINDy as W2's (`paper._sindy.fit_weak_sindy`: one weak library per flight, the
    rows stacked)."""

    label: str = "weak SINDy"

    def fit_field(self, times, rates):
        return fit_weak_sindy(times, rates, seed=TRAIN_SEED)


def models(profile: Profile) -> list[AbstractFlightModel]:
    """W7's models, the G-LPNets' families as `profile` restricts them."""
    steps = profile.steps
    out: list[AbstractFlightModel] = [DissipativeFlightModel(kinds=profile.drag_kinds, steps=steps),
                                      ConservativeFlightModel(families=profile.families, steps=steps),
                                      LPNetFlightModel(steps=steps), LimitFlightModel(steps=steps), EulerFlightModel()]
    if sindy_available():
        out += [SINDyFlightModel(), WeakSINDyFlightModel()]
    return out


# -- what is measured --

def flip_times(times: np.ndarray, rate: np.ndarray) -> np.ndarray:
    """The times where the intermediate-axis rate `rate` `(m,)` changes sign (linear
    interpolation between samples)."""
    s = np.flatnonzero(np.sign(rate[1:]) * np.sign(rate[:-1]) < 0)
    return times[s] + (times[s + 1] - times[s]) * rate[s] / (rate[s] - rate[s + 1])


def flip_period(times: np.ndarray, rate: np.ndarray) -> float:
    """The mean interval between successive flips (NaN with fewer than two)."""
    flips = flip_times(times, rate)
    return float((flips[-1] - flips[0]) / (flips.size - 1)) if flips.size >= 2 else np.nan


def measure(test: Session, rates: np.ndarray) -> dict[str, Any]:
    """Rate error (mean over flights of the relative RMS error against the true rates) and flip
    period error (median over the flights that flip at least twice; a prediction that does not
    is missed)."""
    errors = [relative_rms(p, r) for p, r in zip(rates, test.rates)]
    flip_errors, missed = [], 0
    for p, r in zip(rates, test.rates):
        true = flip_period(test.times, r[:, 1])
        if np.isnan(true):
            continue
        found = flip_period(test.times, p[:, 1]) if np.all(np.isfinite(p)) else np.nan
        missed += int(np.isnan(found))
        flip_errors.append(np.inf if np.isnan(found) else abs(found / true - 1.0))
    return {"rate_error": float(np.mean(errors)), "rate_errors": [float(e) for e in errors],
            "flip_period_error": float(np.median(flip_errors)) if flip_errors else None,
            "flights_flipping": len(flip_errors), "flips_missed": missed, "example_rates": rates[0].tolist()}


@dataclasses.dataclass(frozen=True)
class W7Row:
    """One model at one noise level, on the test session."""

    noise: float
    model: str
    fit_seconds: float
    rate_error: float
    rate_errors: Any
    flip_period_error: float | None
    flights_flipping: int
    flips_missed: int
    example_rates: Any = optional()
    inertia_ratios: Any = optional()
    drag_rate: Any = optional()
    drag_error: float | None = optional()
    detail: str | None = optional()


def evaluate(model: AbstractFlightModel, train: Session, test: Session, *, noise: float) -> W7Row:
    start = time.perf_counter()
    fitted = model.fit(lp.systems.RigidBody(), train)
    fit_seconds = time.perf_counter() - start
    rates = model.predict(fitted, test.measured[:, 0], test.times.size - 1)
    found = model.identified(fitted)
    drag = {}
    if found.drag_rate is not None:
        true = true_drag_rate()
        drag = {"drag_rate": np.asarray(found.drag_rate).tolist(),
                "drag_error": float(np.linalg.norm(found.drag_rate - true) / np.linalg.norm(true))}
    return W7Row(noise=noise, model=model.label, fit_seconds=fit_seconds, **measure(test, rates), **drag,
                 inertia_ratios=None if found.inertia_ratios is None else np.asarray(found.inertia_ratios).tolist(),
                 detail=found.detail)


PROFILES = profiles(
    # steps: Levenberg-Marquardt steps; drag_kinds, families: the dissipative G-LPNet's drag
    # families and the conservative one's families of H~ (None: all; the smoke profile tries one
    # each, to compile fewer maps)
    Profile(n_train=12, n_test=12, duration=FLIGHT, steps=200, drag_kinds=None, families=None),
    smoke=Profile(noises=(0.02,), n_train=3, n_test=2, duration=0.3, steps=10, drag_kinds=("quadratic",),
                  families=("quadratic, any axes, even",)),
    quick=Profile(noises=(0.02,)),
    full=Profile(noises=(0.01, 0.02, 0.05)),
)


@dataclasses.dataclass(frozen=True)
class Condition:
    """A noise level of W7: the training session and the test session at that noise."""

    noise: float
    train: Session
    test: Session


def _ratios_cell(r: W7Row) -> str:
    if r.inertia_ratios is None:
        return "—"
    a, _, c = r.inertia_ratios
    return f"{a:.4f}, {c:.4f}"


def _drag_cell(r: W7Row) -> str:
    if r.drag_rate is None:
        return "—"
    diagonal = np.diag(np.asarray(r.drag_rate))
    if not np.any(diagonal):
        return "none"
    return f"({', '.join(f'{d:.3f}' for d in diagonal)}), error {fmt(r.drag_error)}"


def _fit_cell(r: W7Row) -> str:
    return "—" if r.model == EulerFlightModel.label else f"{r.fit_seconds:.1f}"


COLUMNS = (
    Column("noise [rad/s]", lambda r: f"{r.noise:g}"),
    Column("model", lambda r: r.model),
    Column("rate error", lambda r: r.rate_error),
    Column("flip period error", lambda r: r.flip_period_error),
    Column("flips missed", lambda r: f"{r.flips_missed}/{r.flights_flipping}"),
    Column("I1/I2, I3/I2", _ratios_cell),
    Column(f"drag rate diag. at {REFERENCE_SPIN:g} rad/s [1/s]", _drag_cell),
    Column("fit [s]", _fit_cell),
    Column("chosen", lambda r: r.detail or "—"),
)


def _peer(rows: list[W7Row], row: W7Row, model: str) -> W7Row | None:
    return next((r for r in rows if r.noise == row.noise and r.model == model), None)


def line(row: W7Row) -> str:
    return (f"noise {row.noise:g}, {row.model}: rate error {fmt(row.rate_error)}, flip period error "
            f"{fmt(row.flip_period_error)}, fit {row.fit_seconds:.1f} s")


def verdict(rows: list[W7Row]) -> list[str]:
    out = []
    for r in rows:
        if r.model != DissipativeFlightModel.label:
            continue
        parts = [f"noise {r.noise:g}: dissipative G-LPNet rate error {fmt(r.rate_error)} on the faster session"]
        limit = _peer(rows, r, LimitFlightModel.label)
        if limit:
            ratio = r.rate_error / limit.rate_error
            parts.append(f"{ratio:.2f}x the limit's {fmt(limit.rate_error)} "
                         f"({'within' if ratio <= 1.5 else 'NOT within'} 1.5x)")
        for peer in (_peer(rows, r, m) for m in (SINDyFlightModel.label, WeakSINDyFlightModel.label)):
            if peer:
                below = r.rate_error < peer.rate_error
                parts.append(f"{'below' if below else 'ABOVE'} {peer.model}'s {fmt(peer.rate_error)}")
        conservative = _peer(rows, r, ConservativeFlightModel.label)
        if conservative:
            parts.append(f"the conservative G-LPNet's {fmt(conservative.rate_error)} is "
                         f"{conservative.rate_error / r.rate_error:.1f}x it (flip period error "
                         f"{fmt(conservative.flip_period_error)} against {fmt(r.flip_period_error)})")
        lpnet = _peer(rows, r, LPNetFlightModel.label)
        if lpnet:
            parts.append(f"the LPNet's (it keeps |mu|) {fmt(lpnet.rate_error)}")
        euler = _peer(rows, r, EulerFlightModel.label)
        if euler:
            parts.append(f"Euler's equations without drag {fmt(euler.rate_error)}")
        out.append("; ".join(parts))
    fits = [r for r in rows if r.model != EulerFlightModel.label]
    if fits:
        slowest = max(fits, key=lambda r: r.fit_seconds)
        out.append(f"every fit {'under' if slowest.fit_seconds < FIT_LIMIT_S else 'NOT under'} "
                   f"{FIT_LIMIT_S:g} s: the slowest, {slowest.model} at noise {slowest.noise:g}, "
                   f"{slowest.fit_seconds:.1f} s")
    return out


def _plot(rows: list[W7Row], test: Session, noise: float, out_dir: Path) -> str:
    """The first test flight's rates: truth, gyroscope and each model's prediction."""
    chosen = [r for r in rows if r.noise == noise and r.example_rates is not None]
    fig = figure(figsize=(12.0, 3.6))
    for axis in range(3):
        ax = fig.add_subplot(1, 3, axis + 1)
        ax.plot(test.times, test.rates[0, :, axis], color="k", linewidth=4.0, alpha=0.3, label="truth")
        ax.plot(test.times, test.measured[0, :, axis], ".", color="0.4", markersize=2, label="gyroscope")
        for r, style in zip(chosen, series_styles(len(chosen))):
            ax.plot(test.times, np.asarray(r.example_rates)[:, axis], label=r.model, linewidth=1.2,
                    **{**style, "marker": None})
        ax.set_xlabel("t [s]")
        ax.set_ylabel(f"Omega_{axis + 1} [rad/s]")
    fig.axes[0].legend(fontsize=7, loc="lower left")
    fig.suptitle(f"a test flight (twice the training spins), gyro noise {noise:g} rad/s")
    fig.tight_layout()
    name = f"test_flight_noise_{noise:g}.png"
    save_figure(fig, out_dir / name, dpi=110)
    return name


class W7(AbstractStudy):
    id = "W7"
    title = "bodies in air: a tossed body under quadratic drag seen by a gyroscope, flips predicted"
    profiles = PROFILES
    row_type = W7Row
    columns = COLUMNS

    def conditions(self, P):
        for noise in P.noises:
            yield Condition(noise, session(P.n_train, TRAIN_SPINS, noise, DATA_SEED, P.duration),
                            session(P.n_test, TEST_SPINS, noise, TEST_SEED, P.duration))

    def models(self, P, condition):
        return models(P)

    def evaluate(self, condition, model, progress):
        return evaluate(model, condition.train, condition.test, noise=condition.noise)

    def row_name(self, profile, condition, model):
        return f"{profile}-{condition.noise:g}-{model.label}.json".replace(" ", "_").replace(",", "")

    def line(self, row):
        return line(row)

    def verdict(self, rows, conditions):
        return verdict(rows)

    def figures(self, rows, conditions, out_dir):
        return [_plot(rows, c.test, c.noise, out_dir) for c in conditions]

    def summary(self, P, rows, conditions):
        return {"seeds": {"data": DATA_SEED, "test": TEST_SEED, "training": TRAIN_SEED},
                "protocol": {"train_flights": P.n_train, "test_flights": P.n_test, "duration_s": P.duration,
                             "levenberg_marquardt_steps": P.steps},
                "body": {"inertia": list(INERTIA), "drag": DRAG.tolist(), "true_drag_rate": true_drag_rate().tolist()},
                "model": "dissipative G-LPNet (quadratic H~, learned quadratic drag, momenta latent)"}

    def summary_rows(self, rows):
        return [(f"noise {r.noise:g} dissipative G-LPNet rate error", "—", fmt(r.rate_error),
                 fmt(getattr(_peer(rows, r, LimitFlightModel.label), "rate_error", None)))
                for r in rows if r.model == DissipativeFlightModel.label]

    def description(self, metrics):
        true = np.diag(np.asarray(metrics.get("body", {}).get("true_drag_rate", true_drag_rate())))
        protocol = metrics.get("protocol", {})
        return (
            f"Seeds: {metrics.get('seeds')}. The body I = {INERTIA} under quadratic drag; fitted on a session of "
            f"{protocol.get('train_flights')} flights of {protocol.get('duration_s')} s at {TRAIN_SPINS[0]:g}-{TRAIN_SPINS[1]:g} rad/s, tested on another of {protocol.get('test_flights')} at "
            f"{TEST_SPINS[0]:g}-{TEST_SPINS[1]:g} rad/s, each flight predicted from its first gyro sample. Rate "
            "error: relative RMS against the true rates, mean over the test flights; flip period error: median "
            "relative error of the mean interval between sign changes of Omega_2 over the test flights that flip "
            f"at least twice. Truth: I1/I2, I3/I2 = {INERTIA[0] / INERTIA[1]:.4f}, {INERTIA[2] / INERTIA[1]:.4f}; "
            f"drag rate diagonal ({', '.join(f'{d:.3f}' for d in true)}) 1/s; drag error: relative (Frobenius) "
            "error of the whole matrix.")

    def sections(self, metrics, rows):
        return [("Every model", table_lines(COLUMNS, rows))]


EXPERIMENT = W7()
