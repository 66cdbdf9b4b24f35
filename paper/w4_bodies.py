"""W4 (beyond the paper): from what instruments measure to where the body points and where it
goes. A tumbling satellite (the rigid body I = (2, 1, 2/3) with its principal axes turned by
the rotation vector (0.4, -0.7, 0.5), 0.95 rad, from the sensor axes) observed by a star
tracker (attitude quaternions) and a gyroscope (body angular velocities), and an underwater
vehicle (Kirchhoff's body with an added mass coupling rotation and translation, W2's
"coupled Kirchhoff") observed by its navigation (pose: attitude and position) and its body
velocities; noise 0, 1e-3 and 1e-2 (attitude in radians per axis, velocities and positions
relative to their RMS size; `integrators.observe_body`), at a regular h = 0.1 or at steps
drawn from [0.05, 0.3]. The momenta are never observed. Fitted to the same observations:

- **G-LPNet**: `learn.fit_splitting(system, observations)`: TripleJump, the momenta latent
  (`learn.BodyLoss`, each interval in steps of at most `MAX_STEP`), the family of H~ chosen by
  the Bayesian information criterion;
- **limit**: the true family (any symmetric quadratic form, `learn.ParametricHamiltonian` with
  RK4 in 10 sub-steps on momentum and configuration) fitted on the same loss, initial states
  included, from the truth 10% off: what the data allow at best;
- **SINDy** and **weak SINDy** (pysindy, extra `peers`): a polynomial field of degree 2 for the
  body velocities (the observed ones; from the configurations' differences without them),
  integrated by LSODA with the kinematics (dq/dt = q (Omega, 0)/2, dx/dt = R v); threshold,
  constant, derivative or support width chosen on the training trajectories' rollouts (every
  study's rule, `paper._sindy.choose_sparse_field`);
- **neural ODE**: `learn.NeuralODE`, an MLP field for the body velocities (tanh) fitted to
  their trajectories by L-BFGS-B, integrated as SINDy's: no structure; its hidden layers and
  budget chosen on held-out training trajectories (every study's rule,
  `paper._neural_ode.fit_neural_ode`).

Every model predicts from 12 held-out initial conditions (attitude, position at the origin,
body velocity; the learned maps start from `learn.latent_momenta`) to `t_end` (50 for the
satellite, 20 for the vehicle), against heyoka's (g, mu): mean attitude error (the angle of
R_pred^T R_true), velocity error (relative to the velocities' RMS), position error (relative to
the distance travelled, RMS), and for the G-LPNet and the limit the inertia (its principal
values over their trace, and its principal axes) and, on their rollouts, the drift of the
latent momentum's Casimirs and of the spatial momentum.

The full profile then runs the **LLPNN protocol** (`LLPNN`: 200 trajectories x 101
observations at h = 0.1, noise 0.005, 50 test trajectories to t = 200, regular sampling) with,
beside the models above, its other baselines:

- **DeepONet**: `learn.fit_deeponet`, the state at t from the first observation (branch) and
  the time (trunk); no dynamics, so nothing carries it past the training horizon t = 10;
- **LPNet on reconstructed momenta**: the momenta from the observed velocities through the
  weak-form inertia estimate, the paper's LPNet fitted to their pairs, its phase
  (`learn.fit_phase`) to the observed attitudes.

Rows are saved as they are measured (`<out>/W4/rows/`): an interrupted run resumes.
"""

from __future__ import annotations

import abc
import dataclasses
import itertools
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import numpy as np
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation

import integrators as it
import learn
import liepoisson as lp
from integrators.internals import figure, save_figure, series_styles

from ._experiment import Column, Profile, fmt, optional, profiles, table_lines
from ._neural_ode import fit_neural_ode
from ._runner import GRID_COLUMNS, AbstractStudy, peer
from ._sindy import fit_sindy, fit_weak_sindy, sindy_available
from ._study import AbstractStudyModel
from ._systems import (
    coupled_kirchhoff_matrix,
    quadratic_body,
    quadratic_form,
    rotated_inverse_inertia,
    sphere,
)

H_REGULAR, UNEVEN = 0.1, (0.05, 0.3)
#: The learned maps' training intervals run in steps of at most this; their predictions at
#: `H_EVAL` (splitting errors below the noise-free target of 1e-4 rad at t = 50).
MAX_STEP, H_EVAL, H_SAVE = 0.05, 0.05, 1.0
N_TEST = 12
#: L-BFGS-B iterations of the neural ODE's fit at most, per Levenberg-Marquardt step of the
#: others' (5000 at the full profile's 200: at 1000 the cap bound its fit, BENCHMARKS.md, "W4's
#: peers by the rule"); the profile's `neural_ode_iterations_per_step`.
NEURAL_ODE_ITERATIONS = 25
#: The same in the LLPNN part (1000 at 200 steps, the budget of its earlier reference): its 200
#: x 101 observations cost many times W4's own per iteration, and 5000 would take hours a body
#: (BENCHMARKS.md, "The LLPNN protocol as W4's second part, with its baselines").
LLPNN_NEURAL_ODE_ITERATIONS = 5
#: The neural ODE's hidden layers tried (`paper._neural_ode.fit_neural_ode`).
NEURAL_ODE_HIDDEN = ((32, 32), (64, 64))
#: Adam epochs of the DeepONet (LLPNN protocol only), from 3e-3 to 1e-5 (BENCHMARKS.md, "The
#: LLPNN protocol as W4's second part").
DEEPONET_EPOCHS = 60_000
#: L-BFGS-B iterations of the LPNet on reconstructed momenta (E5's quick profile).
LPNET_ITERATIONS = 2000
DATA_SEED, TEST_SEED, TRAIN_SEED = 1, 100, 0


def _vehicle(n: int, rng: np.random.Generator) -> np.ndarray:
    return rng.uniform(-1.0, 1.0, size=(n, 6))


@dataclasses.dataclass(frozen=True)
class BodyProtocol:
    """A study's body: its system, observations (trajectories x observations, what is
    measured), the true quadratic form `A` of H, and the horizon of the predictions."""

    system: lp.systems.LiePoissonSystem
    n_trajectories: int
    n_observations: int
    initial: Callable[[int, np.random.Generator], np.ndarray]
    A: np.ndarray
    t_end: float
    measure: tuple[str, ...] = ("configurations", "velocities")

    @property
    def poses(self) -> bool:
        return isinstance(self.system.group, lp.Poses)

    def configurations(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """Random attitudes (and positions at the origin for a pose)."""
        q = Rotation.random(n, random_state=rng).as_quat()
        return np.concatenate([q, np.zeros((n, 3))], axis=1) if self.poses else q


def protocols() -> dict[str, BodyProtocol]:
    return {
        "satellite": BodyProtocol(quadratic_body(lp.so3(), rotated_inverse_inertia(), "rotated rigid body"), 30, 41,
                                  sphere, rotated_inverse_inertia(), 50.0),
        "vehicle": BodyProtocol(quadratic_body(lp.se3(), coupled_kirchhoff_matrix(), "coupled Kirchhoff"), 40, 41,
                                _vehicle, coupled_kirchhoff_matrix(), 20.0),
    }


def observations(protocol: BodyProtocol, noise: float, sampling: str, seed: int = DATA_SEED,
                 n_trajectories: int | None = None, n_observations: int | None = None) -> it.BodyObservations:
    n = protocol.n_trajectories if n_trajectories is None else n_trajectories
    m = protocol.n_observations if n_observations is None else n_observations
    rng = np.random.default_rng(seed)
    y0, g0 = protocol.initial(n, rng), protocol.configurations(n, rng)
    times = H_REGULAR * np.arange(m) if sampling == "regular" else it.uneven_times(n, m, UNEVEN, seed=seed)
    return it.observe_body(protocol.system, y0, g0, times, noise=noise, seed=seed, measure=protocol.measure)


@dataclasses.dataclass(frozen=True)
class TestSet:
    """Held-out initial conditions and heyoka's `(configurations, states)` every `H_SAVE`."""

    g0: np.ndarray
    xi0: np.ndarray
    configurations: np.ndarray
    states: np.ndarray
    velocities: np.ndarray


def test_set(protocol: BodyProtocol, t_end: float | None = None, n: int = N_TEST) -> TestSet:
    rng = np.random.default_rng(TEST_SEED)
    y0, g0 = protocol.initial(n, rng), protocol.configurations(n, rng)
    t_end = protocol.t_end if t_end is None else t_end
    truth = it.ground_truth(protocol.system, y0, H_SAVE, round(t_end / H_SAVE), g0=g0)
    velocities = np.asarray(protocol.system.body_velocity(truth.states))
    return TestSet(g0, velocities[:, 0], truth.configurations, truth.states, velocities)


@dataclasses.dataclass(frozen=True)
class Prediction:
    """A model's configurations and velocities `(n, steps, ...)` every `H_SAVE` from the test
    set's initial conditions; for a map with a latent momentum, its rollout's momenta."""

    configurations: np.ndarray
    velocities: np.ndarray
    momenta: np.ndarray | None = None


class AbstractBodyModel(AbstractStudyModel):
    """A model of W4: fitted to body observations, then predicting the test set's attitudes
    (poses) and velocities from their first values."""

    @abc.abstractmethod
    def fit(self, protocol: BodyProtocol, data: it.BodyObservations, *, progress: bool = False) -> Any:
        """The fitted model."""

    @abc.abstractmethod
    def predict(self, fitted: Any, protocol: BodyProtocol, test: TestSet) -> Prediction:
        """Configurations and velocities every `H_SAVE` from the test set's first ones."""

    def identified(self, fitted: Any, protocol: BodyProtocol) -> dict[str, Any]:
        """What the fit identified, for the row (nothing by default)."""
        return {}


@dataclasses.dataclass(frozen=True)
class LearnedBodyModel(AbstractBodyModel):
    """A map with a learned Hamiltonian fitted with latent momenta (`learn.AbstractBodyMap`).
    `unit`: fitted to the observations in this unit of time (seconds;
    `BodyObservations.in_units`), its predictions converted back."""

    unit: float = 1.0
    #: Levenberg-Marquardt steps of the fit.
    steps: int = 200

    @abc.abstractmethod
    def fit_in_units(self, protocol: BodyProtocol, data: it.BodyObservations, loss: learn.BodyLoss
                     ) -> learn.AbstractBodyMap:
        """The map fitted to `data` (already in `unit`) on `loss`."""

    def fit(self, protocol, data, *, progress=False):
        data = data if self.unit == 1.0 else data.in_units(self.unit)
        return self.fit_in_units(protocol, data, learn.BodyLoss(max_step=MAX_STEP / self.unit))

    def predict(self, fitted, protocol, test):
        mu0 = np.asarray(learn.latent_momenta(fitted, test.xi0 * self.unit))
        every = round(H_SAVE / H_EVAL)
        steps = every * (test.states.shape[1] - 1)
        g, mu = fitted.with_h(H_EVAL / self.unit).lifted_rollout(test.g0, mu0, steps, save_every=every)
        xi = np.asarray(jax.vmap(jax.vmap(fitted.body_velocity))(mu)) / self.unit
        return Prediction(np.asarray(g), xi, np.asarray(mu))

    def identified(self, fitted, protocol):
        ratios = _ratios(np.linalg.inv(learned_inertia(fitted)))
        return {"inertia_ratios": ratios.tolist(),
                "inertia_ratio_error": float(np.max(np.abs(ratios / _ratios(protocol.A) - 1.0)))}


@dataclasses.dataclass(frozen=True)
class GLPNetBodyModel(LearnedBodyModel):
    """The G-LPNet of `learn.fit_splitting`: every family, the lowest BIC."""

    label: str = "G-LPNet"

    def fit_in_units(self, protocol, data, loss):
        net, _ = learn.fit_splitting(protocol.system, data, loss=loss, iterations=self.steps, seed=TRAIN_SEED,
                                     key=TRAIN_SEED, progress=False)
        return net

    def identified(self, fitted, protocol):
        return {**super().identified(fitted, protocol), "family": _family(fitted)}


@dataclasses.dataclass(frozen=True)
class LimitBodyModel(LearnedBodyModel):
    """The parametric limit: the true quadratic family (`learn.ParametricHamiltonian`, RK4),
    started 10% off the truth."""

    label: str = "limit"

    def fit_in_units(self, protocol, data, loss):
        n = protocol.A.shape[0]
        theta0 = 1.1 * protocol.A[np.triu_indices(n)]
        model = learn.ParametricHamiltonian(protocol.system, quadratic_form(n), theta0, substeps=10)
        fitted, _ = learn.fit(model, data, loss=loss, optimiser=learn.KeepIfBetter(learn.LevenbergMarquardt(self.steps, rtol=1e-12)),
                              validation_fraction=0.0, seed=TRAIN_SEED, progress=False)
        return fitted


@dataclasses.dataclass(frozen=True)
class ReconstructedLPNet:
    r"""An LPNet fitted to reconstructed momenta, and the inertia that reconstructed them:
    $\mu = \mathbb M(\xi - b)$, $\xi = A\mu + b$ with $A = \mathbb M^{-1}$."""

    net: learn.LPNet
    A: np.ndarray
    b: np.ndarray


@dataclasses.dataclass(frozen=True)
class LPNetBodyModel(AbstractBodyModel):
    r"""The paper's LPNet where the momenta are not observed: momenta reconstructed from the
    observed velocities, $\mu = \mathbb M(\xi - b)$, with the inertia of the weak-form estimate
    (`learn.body_quadratic_estimate`: from the velocities, no model fitted); an LPNet (three
    hidden layers of 16, sigmoid, the test-flow parametrisation, so that its step carries the
    configuration) fitted on the paper's state loss (one step from each reconstructed momentum
    to the next; L-BFGS-B, `LPNET_ITERATIONS`), its phase (`learn.fit_phase(noisy=True)`) to the observed
    configurations; velocities back through the same inertia. Regular sampling only (the
    phase is fitted to pairs at one step)."""

    label: str = "LPNet on reconstructed momenta"

    def fit(self, protocol, data, *, progress=False):
        if not data.is_regular() or len({tuple(t - t[0]) for t in data.times}) > 1:
            raise ValueError("the LPNet on reconstructed momenta is fitted to pairs at one step on one time grid: "
                             "regular sampling, every trajectory at the same times, only")
        A, b = learn.body_quadratic_estimate(data)
        M = np.linalg.inv(A)
        momenta = np.stack([(v - b) @ M.T for v in data.velocities])
        h = float(data.times[0][1] - data.times[0][0])
        # noisy momenta: no Poisson map joins a pair of them (their Casimirs differ), so the net is
        # fitted on the paper's state loss, one step from each observed momentum to the next
        observed = it.Observations(protocol.system, list(data.times), list(momenta))
        net = learn.LPNet(protocol.system, hidden=(16, 16, 16), activation="sigmoid", key=TRAIN_SEED, h=h,
                          parametrisation=learn.TestFlowParametrisation(protocol.system))
        net, _ = learn.fit(net, observed, loss="state", optimiser=learn.KeepIfBetter(learn.ScipyLBFGSB(LPNET_ITERATIONS)),
                           validation_fraction=0.0, seed=TRAIN_SEED, progress=False)
        pairs = it.Trajectories(momenta, h, protocol.system, times=data.times[0] - data.times[0][0],
                                configurations=np.stack(data.configurations))
        net, _ = learn.fit_phase(net, pairs, noisy=True, progress=False)
        return ReconstructedLPNet(net, A, b)

    def predict(self, fitted, protocol, test):
        mu0 = (test.xi0 - fitted.b) @ np.linalg.inv(fitted.A).T
        every = round(H_SAVE / fitted.net.h)
        g, mu = fitted.net.lifted_rollout(test.g0, mu0, every * (test.states.shape[1] - 1), save_every=every)
        mu = np.asarray(mu)
        return Prediction(np.asarray(g), mu @ fitted.A.T + fitted.b, mu)


@dataclasses.dataclass(frozen=True)
class DeepONetBodyModel(AbstractBodyModel):
    """A DeepONet (`learn.fit_deeponet`: branch on the first observation, trunk on the time,
    two hidden layers of 64, tanh, 32 basis functions; `DEEPONET_EPOCHS` of Adam): the state
    at t from the initial one, no dynamics, nothing to carry it past the training horizon."""

    label: str = "DeepONet"

    def fit(self, protocol, data, *, progress=False):
        net, _ = learn.fit_deeponet(data, epochs=DEEPONET_EPOCHS, key=TRAIN_SEED, progress=False)
        return net

    def predict(self, fitted, protocol, test):
        t = H_SAVE * np.arange(test.states.shape[1])
        gs, xis = zip(*(fitted.predict(g0, xi0, t) for g0, xi0 in zip(test.g0, test.xi0)))
        return Prediction(np.stack(gs), np.stack(xis))


@dataclasses.dataclass(frozen=True)
class AbstractVelocityFieldModel(AbstractBodyModel):
    r"""A field $\dot\xi = f(\xi)$ for the body velocities without structure, identified from
    their samples (observed, or from the configurations), integrated with the kinematics."""

    #: The fit's iterations, where it iterates (in units of the others' Levenberg-Marquardt steps).
    steps: int = 200

    @abc.abstractmethod
    def field(self, as_states: it.Observations) -> Any:
        """The identified field (`predict(xi)` `(k, dim)` -> `(k, dim)`) of velocity samples."""

    def fit(self, protocol, data, *, progress=False):
        velocities = data.velocities if data.velocities is not None else [
            data.group_velocities(j) for j in range(len(data))]
        times = data.times if data.velocities is not None else [0.5 * (t[1:] + t[:-1]) for t in data.times]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return self.field(it.Observations(protocol.system, list(times), list(velocities)))

    def predict(self, fitted, protocol, test):
        group = protocol.system.group
        t = H_SAVE * np.arange(test.states.shape[1])
        gs, xis = [], []
        for g0, xi0 in zip(test.g0, test.xi0):
            dim = xi0.size

            def rhs(_, z, dim=dim):
                xi, g = z[:dim], z[dim:]
                dg = np.asarray(group.velocity_components(list(g), list(xi)), dtype=np.float64)
                return np.concatenate([fitted.predict(xi[None])[0], dg])

            def escape(_, z, dim=dim, xi0=xi0):
                return 100.0 * (1.0 + np.linalg.norm(xi0)) - np.linalg.norm(z[:dim])

            escape.terminal = True
            sol = solve_ivp(rhs, (0.0, t[-1]), np.concatenate([xi0, g0]), method="LSODA", t_eval=t, rtol=1e-10,
                            atol=1e-10, events=escape)
            out = np.full((t.size, dim + group.size), np.nan)
            out[: sol.y.shape[1]] = sol.y.T
            xis.append(out[:, :dim])
            gs.append(out[:, dim:])
        gs = np.stack(gs)
        finite = np.all(np.isfinite(gs), axis=-1)
        gs[finite] = np.asarray(group.project(gs[finite]))
        return Prediction(gs, np.stack(xis))




@dataclasses.dataclass(frozen=True)
class SINDyBodyModel(AbstractVelocityFieldModel):
    """SINDy (pysindy, STLSQ) on the velocities, its threshold, library and derivative chosen on
    the training trajectories' rollouts (`paper._sindy.fit_sindy`: every study's rule)."""

    label: str = "SINDy"

    def field(self, as_states):
        return fit_sindy(list(as_states.times), list(as_states.states))


@dataclasses.dataclass(frozen=True)
class WeakSINDyBodyModel(AbstractVelocityFieldModel):
    """Weak SINDy (W2's, one weak library per trajectory) on the velocities, its support width,
    threshold and library chosen on the training trajectories' rollouts
    (`paper._sindy.fit_weak_sindy`: every study's rule)."""

    label: str = "weak SINDy"

    def field(self, as_states):
        return fit_weak_sindy(list(as_states.times), list(as_states.states))


@dataclasses.dataclass(frozen=True)
class NeuralODEBodyModel(AbstractVelocityFieldModel):
    """A neural ODE on the velocities (`learn.NeuralODE`, an MLP field, tanh, RK4 sub-steps)
    fitted by L-BFGS-B on their trajectories with fitted starts, its hidden layers (of
    `NEURAL_ODE_HIDDEN`) and budget (at most `iterations_per_step` L-BFGS-B iterations per
    Levenberg-Marquardt step of the other fits) chosen on held-out training trajectories
    (`paper._neural_ode.fit_neural_ode`: every study's rule); the kinematics integrated beside
    it. No structure: the peer that shows what the Lie-Poisson one buys."""

    label: str = "neural ODE"
    #: The L-BFGS-B iterations at most per unit of `steps`.
    iterations_per_step: int = NEURAL_ODE_ITERATIONS

    def field(self, as_states):
        return fit_neural_ode(as_states, self.iterations_per_step * self.steps, NEURAL_ODE_HIDDEN, key=TRAIN_SEED,
                              seed=TRAIN_SEED)


@dataclasses.dataclass(frozen=True)
class W4Row:
    """One model on one condition: errors at `t_end`, fit time, and what it identified."""

    system: str
    noise: float
    sampling: str
    model: str
    fit_seconds: float
    attitude_error: float
    velocity_error: float
    position_error: float | None = optional()
    attitude_error_curve: Any = optional()
    inertia_ratios: Any = optional()
    inertia_ratio_error: float | None = optional()
    casimir_drift: float | None = optional()
    spatial_momentum_drift: float | None = optional()
    family: str | None = optional()
    part: str | None = optional()

    @property
    def condition(self) -> tuple[str | None, str, str, float]:
        return self.part, self.system, self.sampling, self.noise


def _ratios(A: np.ndarray) -> np.ndarray:
    """The inertia's principal values over their mean (the gauge-free part of the fit)."""
    M = np.linalg.inv(A)
    values = np.linalg.eigvalsh(M)
    return values / values.mean()


def measure(protocol: BodyProtocol, test: TestSet, prediction: Prediction) -> dict[str, Any]:
    """Errors of `prediction` against the test set at the end, and the attitude error curve."""
    angles = np.asarray(lp.rotation_angle(prediction.configurations[..., :4], test.configurations[..., :4]))
    angles = np.where(np.isfinite(angles), angles, np.inf)
    scale = float(np.sqrt(np.mean(np.sum(test.velocities**2, axis=-1))))
    dv = np.linalg.norm(prediction.velocities[:, -1] - test.velocities[:, -1], axis=-1) / scale
    out = {"attitude_error": float(np.mean(angles[:, -1])), "velocity_error": float(np.mean(np.where(
        np.isfinite(dv), dv, np.inf))), "attitude_error_curve": np.mean(angles, axis=0).tolist()}
    if protocol.poses:
        travelled = float(np.sqrt(np.mean(np.sum(test.configurations[:, -1, 4:] ** 2, axis=-1))))
        dx = np.linalg.norm(prediction.configurations[:, -1, 4:] - test.configurations[:, -1, 4:], axis=-1)
        out["position_error"] = float(np.mean(np.where(np.isfinite(dx), dx, np.inf))) / travelled
    if prediction.momenta is not None:
        system = protocol.system
        C = np.asarray(system.casimirs(prediction.momenta))
        J = np.asarray(system.spatial_momentum(prediction.configurations, prediction.momenta))
        out["casimir_drift"] = float(np.max(np.abs(C - C[:, :1])) / max(np.max(np.abs(C)), 1e-300))
        out["spatial_momentum_drift"] = float(np.max(np.abs(J - J[:, :1])) / max(np.max(np.abs(J)), 1e-300))
    return out


def models(operator_baselines: bool = False, steps: int = 200,
           neural_ode_iterations_per_step: int = NEURAL_ODE_ITERATIONS) -> list[AbstractBodyModel]:
    """W4's models, fitted in `steps` Levenberg-Marquardt steps (or as many units of their own
    iterations: `neural_ode_iterations_per_step` L-BFGS-B iterations a unit for the neural ODE); with
    `operator_baselines`, the LLPNN protocol's others too (a DeepONet and an LPNet on
    reconstructed momenta)."""
    out: list[AbstractBodyModel] = [GLPNetBodyModel(steps=steps), LimitBodyModel(steps=steps),
                                    NeuralODEBodyModel(steps=steps, iterations_per_step=neural_ode_iterations_per_step)]
    if sindy_available():
        out += [SINDyBodyModel(steps=steps), WeakSINDyBodyModel(steps=steps)]
    if operator_baselines:
        out += [DeepONetBodyModel(), LPNetBodyModel()]
    return out


def evaluate(protocol: BodyProtocol, model: AbstractBodyModel, data: it.BodyObservations, test: TestSet, *,
             system: str, noise: float, sampling: str, part: str | None = None) -> W4Row:
    start = time.perf_counter()
    fitted = model.fit(protocol, data)
    fit_seconds = time.perf_counter() - start
    figures = measure(protocol, test, model.predict(fitted, protocol, test))
    return W4Row(system=system, noise=noise, sampling=sampling, model=model.label, fit_seconds=fit_seconds,
                 part=part, **figures, **model.identified(fitted, protocol))


def _family(net) -> str:
    terms = net.terms
    axes = "any axes" if terms.full_vectors else "axes"
    return f"{terms.activation}, {axes}{', linear terms' if terms.bias else ''}"


def learned_inertia(fitted) -> np.ndarray:
    r"""The inertia $\widetilde{\mathbb M} = (\nabla^2\widetilde H)^{-1}$ of a fitted map at
    $\mu = 0$, scaled to trace $n$ (the gauge-free part: its ratios and principal axes)."""
    hessian = np.asarray(jax.hessian(lambda y: jax.numpy.sum(fitted.hamiltonian(y)))(
        np.zeros(fitted.system.dim)))
    M = np.linalg.inv(hessian)
    return M * M.shape[0] / np.trace(M)


def bootstrap_inertia(protocol: BodyProtocol, data: it.BodyObservations, n: int, seed: int = 0,
                      steps: int = 200) -> np.ndarray:
    """The G-LPNet's inertia (`learned_inertia`) over `n` fits to the trajectories of `data`
    resampled with replacement (seeded), `(n, dim, dim)`; the family the full data chose is
    refitted (`families=`), not chosen again."""
    net = GLPNetBodyModel(steps=steps).fit(protocol, data)
    family = next(f for f in learn.FAMILIES if not f.select and f.any_axes == net.terms.full_vectors
                  and f.bias == net.terms.bias and f.activation == net.terms.activation)
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        sample = data.select(rng.integers(0, len(data), len(data)))
        fitted, _ = learn.fit_splitting(protocol.system, sample, loss=learn.BodyLoss(max_step=MAX_STEP),
                                        iterations=steps, families=[family], progress=False)
        out.append(learned_inertia(fitted))
    return np.stack(out)


#: W4's settings: `steps`, Levenberg-Marquardt steps per fit; `n_trajectories`,
#: `n_observations`, `t_end`: the protocol's when None; `part`: a part of the study with its own
#: protocol (rows marked with it), run after the profile `then` names it; `operator_baselines`:
#: the LLPNN protocol's baselines besides W4's models; `neural_ode_iterations_per_step`: the
#: neural ODE's L-BFGS-B iterations at most per step (`steps` times this in all).
DEFAULTS = Profile(systems=(), noises=(), samplings=(), steps=200, n_trajectories=None, n_observations=None,
                   t_end=None, n_test=N_TEST, part=None, then=None, operator_baselines=False,
                   neural_ode_iterations_per_step=NEURAL_ODE_ITERATIONS)


def slug(P: Profile) -> str:
    """A part's short name in file names ('' for the main part)."""
    return "" if P.part is None else P.part.split()[0].lower()


def part_title(P: Profile) -> str:
    """A part's heading: its protocol."""
    return (f"{P.part}: {P.n_trajectories} x {P.n_observations} observations at h = {H_REGULAR:g}, "
            f"{P.n_test} test trajectories to t = {P.t_end:g}")


#: The protocol of Latent Lie-Poisson Neural Networks (Putkaradze 2026, as described in issue
#: 42: 200 trajectories x 101 observations at h = 0.1, noise 0.005 on configurations and
#: velocities, 50 test trajectories to t = 200), with its baselines: a neural ODE, a DeepONet
#: and an LPNet on reconstructed momenta.
LLPNN = DEFAULTS.replace(systems=("satellite", "vehicle"), noises=(0.005,), samplings=("regular",), n_trajectories=200,
                         n_observations=101, t_end=200.0, n_test=50, part="LLPNN protocol", operator_baselines=True,
                         neural_ode_iterations_per_step=LLPNN_NEURAL_ODE_ITERATIONS)


def _parts() -> list[Profile]:
    """Every part any profile runs after its own."""
    out, todo = [], list(PROFILES.values())
    while todo:
        P = todo.pop()
        if P.then is not None and P.then not in out:
            out.append(P.then)
            todo.append(P.then)
    return out


PROFILES = profiles(
    DEFAULTS,
    smoke=Profile(systems=("satellite",), noises=(1e-3,), samplings=("uneven",), steps=10, n_trajectories=4,
                  n_observations=8, t_end=5.0),
    quick=Profile(systems=("satellite",), noises=(0.0, 1e-3, 1e-2), samplings=("uneven",)),
    full=Profile(systems=("satellite", "vehicle"), noises=(0.0, 1e-3, 1e-2), samplings=("regular", "uneven"),
                 then=LLPNN),
)


@dataclasses.dataclass(frozen=True)
class Condition:
    """A cell of W4's grid: a part of the study (its profile `P`), a protocol's observations at
    one sampling and noise, and its test set."""

    P: Profile
    system: str
    sampling: str
    noise: float
    protocol: BodyProtocol
    data: it.BodyObservations
    test: TestSet


COLUMNS = (
    *GRID_COLUMNS,
    Column("attitude error [rad]", lambda r: r.attitude_error),
    Column("velocity error", lambda r: r.velocity_error),
    Column("position error", lambda r: r.position_error),
    Column("inertia ratios, max rel. error", lambda r: r.inertia_ratio_error),
    Column("Casimir drift", lambda r: r.casimir_drift),
    Column("spatial momentum drift", lambda r: r.spatial_momentum_drift),
    Column("fit [s]", lambda r: f"{r.fit_seconds:.1f}"),
    Column("H~ family", lambda r: r.family or "—"),
)


def _where(row: W4Row) -> str:
    return f"{'' if row.part is None else row.part + ', '}{row.system}, {row.sampling}, noise {row.noise:g}"



class W4(AbstractStudy):
    id = "W4"
    title = "from attitude, pose and velocities to where the body points and goes, momenta latent"
    profiles = PROFILES
    row_type = W4Row
    columns = COLUMNS

    def conditions(self, P):
        all_protocols = protocols()
        part: Profile | None = P
        while part is not None:
            for system in part.systems:
                protocol = all_protocols[system]
                test = test_set(protocol, part.t_end, part.n_test)
                for sampling, noise in itertools.product(part.samplings, part.noises):
                    data = observations(protocol, noise, sampling, n_trajectories=part.n_trajectories,
                                        n_observations=part.n_observations)
                    yield Condition(part, system, sampling, noise, protocol, data, test)
            part = part.then

    def models(self, P, condition):
        P = condition.P
        return models(P.operator_baselines, P.steps, P.neural_ode_iterations_per_step)

    def admits(self, condition, model):
        return True  # a model that cannot take the data says so

    def evaluate(self, condition, model, progress):
        c = condition
        return evaluate(c.protocol, model, c.data, c.test, system=c.system, noise=c.noise, sampling=c.sampling,
                        part=c.P.part)

    def row_name(self, profile, condition, model):
        c = condition
        prefix = profile if c.P.part is None else f"{profile}-{slug(c.P)}"
        return f"{prefix}-{c.system}-{c.sampling}-{c.noise:g}-{model.label}.json".replace(" ", "_")

    @staticmethod
    def line(row: W4Row) -> str:
        position = "" if row.position_error is None else f", position {fmt(row.position_error)}"
        ratios = "" if row.inertia_ratio_error is None else f", inertia ratios within {fmt(row.inertia_ratio_error)}"
        return (f"{_where(row)}, {row.model}: attitude error {fmt(row.attitude_error)} "
                f"rad, velocity {fmt(row.velocity_error)}{position}{ratios}, fit {row.fit_seconds:.1f} s")

    def verdict(self, rows: list[W4Row], conditions: Any = ()) -> list[str]:
        out = []
        for r in rows:
            if r.model != "G-LPNet":
                continue
            key = "position_error" if r.position_error is not None else "attitude_error"
            what = "position" if key == "position_error" else "attitude"
            parts = [f"{_where(r)}: G-LPNet {what} error {fmt(getattr(r, key))}"]
            limit = peer(rows, r, "limit")
            if limit:
                parts.append(f"{getattr(r, key) / getattr(limit, key):.2f}x the limit's ({fmt(getattr(limit, key))})")
            peers = ("neural ODE", "SINDy", "weak SINDy", DeepONetBodyModel.label, LPNetBodyModel.label)
            for other in (peer(rows, r, m) for m in peers):
                if other:
                    below = getattr(r, key) < getattr(other, key)
                    parts.append(f"{'below' if below else 'ABOVE'} {other.model}'s {fmt(getattr(other, key))}")
            parts.append(f"inertia ratios within {fmt(r.inertia_ratio_error)}, Casimir drift {fmt(r.casimir_drift)}, "
                         f"spatial momentum drift {fmt(r.spatial_momentum_drift)}")
            out.append("; ".join(parts))
        return out

    def figures(self, rows: list[W4Row], conditions: Any, out_dir: Path) -> list[str]:
        """Per system, sampling and noise: the mean attitude error against time, one line per model."""
        names = []
        for part, system in dict.fromkeys((r.part, r.system) for r in rows):
            conditions = list(dict.fromkeys((r.sampling, r.noise) for r in rows if (r.part, r.system) == (part, system)))
            fig = figure(figsize=(4.5 * len(conditions), 4.0))
            for k, (sampling, noise) in enumerate(conditions):
                ax = fig.add_subplot(1, len(conditions), k + 1)
                chosen = [r for r in rows if r.condition == (part, system, sampling, noise)]
                for r, style in zip(chosen, series_styles(len(chosen))):
                    curve = np.asarray(r.attitude_error_curve, dtype=np.float64)
                    t = H_SAVE * np.arange(curve.size)
                    ax.semilogy(t[1:], np.maximum(curve[1:], 1e-16), label=r.model, **style)
                ax.set_title(f"{'' if part is None else part + ': '}{system}, {sampling}, noise {noise:g}")
                ax.set_xlabel("t")
                ax.set_ylabel("attitude error [rad]")
                ax.legend(fontsize=8)
            prefix = next((slug(P) + "_" for P in _parts() if P.part == part and part is not None), "")
            name = f"attitude_error_{prefix}{system}.png"
            fig.tight_layout()
            save_figure(fig, out_dir / name, dpi=110)
            names.append(name)
        return names

    def summary(self, P, rows, conditions):
        return {"seeds": {"data": DATA_SEED, "test": TEST_SEED, "training": TRAIN_SEED},
                "model": "G-LPNet (TripleJump, momenta latent, family by BIC)"}

    def summary_rows(self, rows):
        return [(f"{_where(r).replace(',', '')} G-LPNet attitude error", "—", fmt(r.attitude_error),
                 fmt(getattr(peer(rows, r, "limit"), "attitude_error", None))) for r in rows if r.model == "G-LPNet"]

    def description(self, metrics):
        return (
            f"Seeds: {metrics.get('seeds')}. Errors at the end of the predictions (t = 50 for the satellite, "
            f"20 for the vehicle), means over {N_TEST} held-out initial conditions against heyoka; velocity error "
            "relative to the velocities' RMS, position error to the distance travelled; drifts of the learned maps' "
            "rollouts relative to the largest value.")

    def sections(self, metrics, rows):
        sections = [("Every fit", table_lines(COLUMNS, [r for r in rows if r.part is None]))]
        for part in dict.fromkeys(r.part for r in rows if r.part is not None):
            title = next((part_title(P) for P in _parts() if P.part == part), part)
            sections.append((title, table_lines(COLUMNS, [r for r in rows if r.part == part])))
        return sections


EXPERIMENT = W4()
