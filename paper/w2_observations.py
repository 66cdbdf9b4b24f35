"""W2 (beyond the paper): learning from observations, noisy and unevenly sampled, of a system
whose Hamiltonian the learner is not given.

For the rigid body I = (2, 1, 2/3) on so(3)*, Kirchhoff's body (the paper's E5) on se(3)* and
a body on the 4-dimensional "diamond" algebra outside the catalogue (given by its structure
constants), and the Hamiltonians real bodies have: the rigid body with its principal axes
turned by the rotation vector (0.4, -0.7, 0.5) from the sensor axes, Kirchhoff's body with an
added mass coupling rotation and translation, Lagrange's heavy top (a linear term), and a rigid body
with the energy term 0.2 log(1 + (V . Pi)^2) outside every polynomial library: trajectories
observed with Gaussian noise of standard deviation 0, 1e-3 and 1e-2 times the states' RMS
size, at a regular h = 0.1 or at steps drawn from [0.05, 0.3] (`integrators.observe`). Fitted
to the same observations:

- **G-LPNet**: `learn.fit_splitting(system, observations)`: a TripleJump G-LPNet (one module
  per basis direction or learned direction) fitted by trajectory least squares with the initial
  states (errors in variables), the family of its learned Hamiltonian chosen by the Bayesian
  information criterion (`learn.FAMILIES`);
- **limit**: the true model family (`learn.ParametricHamiltonian`: the Hamiltonian's form
  with its coefficients unknown, RK4 with 10 sub-steps) fitted the same way: what the data
  allow at best;
- **SINDy** (pysindy, extra `peers`; skipped without it): polynomial library of degree 2,
  STLSQ, derivatives by finite differences or (regular sampling only: the smoother assumes
  even spacing) smoothed ones, integrated by LSODA; **weak SINDy**: the same library and
  STLSQ in weak form (pysindy's `WeakPDELibrary` on each trajectory's own times: no
  derivatives of the noisy data); for both, the threshold, the constant and the derivative or
  support width chosen on the training trajectories' rollouts (every study's rule,
  `paper._sindy.choose_sparse_field`);
- **MLP**: the unstructured residual MLP (3x16) on consecutive pairs, Adam then L-BFGS-B
  (regular sampling only: its step has no step-size input).

Every model is rolled out 1000 steps of 0.1 (t = 100) from 12 held-out initial conditions and
compared with heyoka: mean state error at t = 100, max relative energy error, Casimir drift
(max |C(t) - C(0)| over |grad C| |y|), fit time; for the rigid body, the identified
1/I_i - 1/I_j (`learn.quadratic_part`); for the G-LPNet, its learned Hamiltonian against the
true one modulo functions of the Casimirs (W1's `hamiltonian_mismatch`: max |H~ - H - f(C)| /
max |H| on the observed states, f the least-squares quadratic in the Casimirs).

Each row is saved (`<out>/W2/rows/`) as soon as it is measured; a rerun into the same folder
reads the saved rows and fits only the missing ones, so an interrupted `--full` run resumes.
"""

from __future__ import annotations

import dataclasses
import itertools
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax.numpy as jnp
import numpy as np

import integrators as it
import learn
import liepoisson as lp
from integrators.internals import figure, save_figure, series_styles, span_decades
from liepoisson.internals import casimir_scale

from ._experiment import Column, Profile, fmt, optional, profiles
from ._runner import GRID_COLUMNS, AbstractStudy, peer
from ._sindy import SINDyModel, WeakSINDyModel, sindy_available
from ._study import (
    AbstractHamiltonianModel,
    AbstractStudyModel,
    Fitted,
    Identified,
    MLPModel,
    ParametricModel,
    SplittingModel,
    Training,
)
from ._study import (
    differences as differences,
)
from ._systems import (
    KAPPA,
    V,
    coupled_kirchhoff_matrix,
    cube,
    diamond,
    logarithmic_body,
    quadratic_body,
    quadratic_form,
    rotated_inverse_inertia,
    sphere,
)

H_TEST, STEPS_TEST, N_TEST = 0.1, 1000, 12
DATA_SEED, TEST_SEED, TRAIN_SEED = 1, 100, 0
UNEVEN = (0.05, 0.3)


def _diagonal(y, theta):
    return 0.5 * jnp.sum(theta * y**2)


def _heavy_top_family(y, theta):
    return 0.5 * jnp.sum(theta[:3] * y[:3] ** 2) + jnp.dot(theta[3:], y[3:])


def _logarithmic_family(y, theta):
    return 0.5 * jnp.sum(theta[:3] * y[:3] ** 2) + theta[3] * jnp.log1p(jnp.dot(theta[4:], y) ** 2)


def _heavy_top_initial(n: int, rng: np.random.Generator) -> np.ndarray:
    """Angular momenta in the cube [-1, 1]^3, the vertical a unit vector."""
    return np.concatenate([rng.uniform(-1.0, 1.0, size=(n, 3)), sphere(n, rng)], axis=1)


def _diamond_family(y, theta):
    return 0.5 * (theta[0] * y[0] ** 2 + theta[1] * y[1] ** 2 + theta[2] * y[3] ** 2) + theta[3] * jnp.exp(-y[2] ** 2)


@dataclasses.dataclass(frozen=True)
class Protocol:
    r"""A study's system, its observations (trajectories x observations from `initial`), the
    true model family `family(y, theta)` with its true parameters, and whether the differences
    of the diagonal of $H$ are reported (`diagonal_differences`: the rigid body, whose
    Hamiltonian is identified only modulo $|\Pi|^2$, so by its $1/I_i - 1/I_j$)."""

    system: lp.systems.AbstractPoissonSystem
    n_trajectories: int
    n_observations: int
    initial: Callable[[int, np.random.Generator], np.ndarray]
    family: Callable[[Any, Any], Any]
    true_theta: tuple[float, ...]
    diagonal_differences: bool = False
    theta0: tuple[float, ...] | None = None  # the limit's start (default: ones)
    leaf_circle: tuple[tuple[float, ...], tuple[float, ...]] | None = None  # see `leaf_profile`


def protocols() -> dict[str, Protocol]:
    return {
        "rigid body": Protocol(lp.systems.RigidBody(inertia=(2.0, 1.0, 2.0 / 3.0)), 30, 21, sphere, _diagonal,
                               (0.5, 1.0, 1.5), diagonal_differences=True),
        "Kirchhoff": Protocol(lp.systems.Kirchhoff(inertia=(1.0, 2.0, 1.0), mass=(1.0, 2.0, 1.0)), 40, 21, cube(6),
                              _diagonal, (1.0, 0.5, 1.0, 1.0, 0.5, 1.0)),
        "diamond": Protocol(diamond(), 40, 21, cube(4), _diamond_family, (1.0, 1.0, 1.0, 0.1)),
        # Hamiltonians real bodies have: principal axes off the sensor axes, coupled added mass,
        # a linear term, a non-polynomial energy (the limits start from the identity or 10% off)
        "rotated rigid body": Protocol(
            quadratic_body(lp.so3(), rotated_inverse_inertia(), "rotated rigid body"), 30, 21, sphere,
            quadratic_form(3), tuple(rotated_inverse_inertia()[np.triu_indices(3)]),
            theta0=tuple(np.eye(3)[np.triu_indices(3)])),
        "coupled Kirchhoff": Protocol(
            quadratic_body(lp.se3(), coupled_kirchhoff_matrix(), "coupled Kirchhoff"), 40, 21, cube(6),
            quadratic_form(6), tuple(coupled_kirchhoff_matrix()[np.triu_indices(6)]),
            theta0=tuple(np.eye(6)[np.triu_indices(6)])),
        "heavy top": Protocol(
            lp.systems.HeavyTop(inertia=(2.0, 2.0, 1.0), mgl=0.5, center_of_mass=(0.0, 0.0, 1.0)), 30, 21,
            _heavy_top_initial, _heavy_top_family, HEAVY_TOP_THETA, theta0=tuple(1.1 * np.asarray(HEAVY_TOP_THETA))),
        "logarithmic rigid body": Protocol(
            logarithmic_body(), 30, 21, sphere, _logarithmic_family, (0.5, 1.0, 1.5, KAPPA, *V),
            theta0=tuple(1.1 * np.asarray((0.5, 1.0, 1.5, KAPPA, *V))), leaf_circle=(V, (0.8, 0.0, -0.6))),
    }


#: The heavy top's true family parameters, 1/I_i and mgl chi: Lagrange's top (symmetric, its
#: centre of mass on the axis of symmetry: integrable, so that errors at t = 100 measure the
#: model, not chaos; an asymmetric top's observed states decorrelate long before).
HEAVY_TOP_THETA = (0.5, 0.5, 1.0, 0.0, 0.0, 0.5)


def observations(protocol: Protocol, noise: float, sampling: str, seed: int = DATA_SEED,
                 n_trajectories: int | None = None, n_observations: int | None = None) -> it.Observations:
    """The protocol's observations: initial states, times and noise all from `seed`."""
    n = protocol.n_trajectories if n_trajectories is None else n_trajectories
    m = protocol.n_observations if n_observations is None else n_observations
    y0 = protocol.initial(n, np.random.default_rng(seed))
    times = H_TEST * np.arange(m) if sampling == "regular" else it.uneven_times(n, m, UNEVEN, seed=seed)
    return it.observe(protocol.system, y0, times, noise=noise, seed=seed)


def test_set(protocol: Protocol, n: int = N_TEST, steps: int = STEPS_TEST) -> tuple[np.ndarray, np.ndarray]:
    """`n` held-out initial conditions and heyoka's states at t = 0.1 k, k = 0..steps."""
    y0 = protocol.initial(n, np.random.default_rng(TEST_SEED))
    return y0, it.ground_truth(protocol.system, y0, H_TEST, steps).states


@dataclasses.dataclass(frozen=True)
class RolloutFigures:
    r"""The study's figures of rollouts against heyoka: `state_error`, the mean over initial
    conditions of the error at the end; `energy_error`, the max relative error of the true $H$
    against its initial value; `casimir_drift`, max $|C(t) - C(0)|$ in units of
    $|\nabla C|\,|y|$ at the start (a Casimir may vanish on the data; `None` for a system without
    Casimirs). Infinite for a rollout that diverged."""

    state_error: float
    energy_error: float
    casimir_drift: float | None


def figures(fitted: Fitted, states: np.ndarray, reference: np.ndarray) -> RolloutFigures:
    """The figures of rollouts `(n, steps + 1, dim)` of `fitted`, from its
    `integrators.rollout_figures` against `reference`: the issue's protocol rather than that
    function's summaries (the mean over initial conditions, not the max; energy relative to
    E(0); Casimirs in units of |grad C| |y|)."""
    system = fitted.step_map.system
    result = it.rollout_figures(fitted.step_map, states, reference, defect_points=0)
    if result.divergence is not None:
        return RolloutFigures(np.inf, np.inf, np.inf if system.n_casimirs else None)
    report = result.report
    energy0 = np.asarray(system.hamiltonian(reference[:, :1]))
    drift = None
    if system.n_casimirs:
        gradients = np.asarray(system.casimir_gradients(states[:, :1])).reshape(len(states), 1, -1, states.shape[-1])
        scale = casimir_scale(gradients, states[:, :1])
        drift = float(np.max(np.abs(report.casimir_drift) / np.maximum(scale, np.finfo(float).tiny)))
    return RolloutFigures(
        state_error=float(np.mean(report.trajectory_error[:, -1])),
        energy_error=float(np.max(np.abs(report.energy - energy0) / np.abs(energy0))),
        casimir_drift=drift,
    )


#: Points of a `leaf_profile` around its circle.
PROFILE_POINTS = 73


def leaf_profile(hamiltonian: Callable[[np.ndarray], Any], circle: tuple[Any, Any]) -> list[float]:
    r"""`hamiltonian` around the great circle $\cos\theta\,u + \sin\theta\,w$ (`circle`
    $= (u, w)$ orthonormal, on the leaf $|y| = 1$), $\theta$ at `PROFILE_POINTS` points of
    $[0, 2\pi]$, less its mean: on one leaf a Hamiltonian is identified up to a constant, so
    this is the shape the motion sees."""
    theta = np.linspace(0.0, 2.0 * np.pi, PROFILE_POINTS)
    u, w = (np.asarray(v, dtype=np.float64) for v in circle)
    values = np.asarray(hamiltonian(np.cos(theta)[:, None] * u + np.sin(theta)[:, None] * w), dtype=np.float64)
    return (values - values.mean()).tolist()


@dataclasses.dataclass(frozen=True)
class W2Row:
    """One model fitted to one condition (system, sampling, noise): its `RolloutFigures`, fit
    time and training loss, and for a model that learns a Hamiltonian what it `Identified`
    (flattened: `family`, `bic`, `theta`, the `hamiltonian_mismatch` figures, the diagonal
    `differences` and their `difference_error` against the truth)."""

    system: str
    noise: float
    sampling: str
    model: str
    fit_seconds: float
    state_error: float
    energy_error: float
    casimir_drift: float | None = optional()
    train_loss: float | None = optional()
    family: str | None = optional()
    bic: dict[str, float] | None = optional()
    theta: Any = optional()
    learned_hamiltonian_vs_H: float | None = optional()
    learned_hamiltonian_vs_H_mod_casimirs: float | None = optional()
    learned_vector_field_vs_H: float | None = optional()
    differences: Any = optional()
    difference_error: Any = optional()
    identifiable_error: float | None = optional()
    axes_error_degrees: float | None = optional()
    leaf_profile: Any = optional()  # the learned H~ around the protocol's leaf circle

    @property
    def condition(self) -> tuple[str, str, float]:
        return self.system, self.sampling, self.noise


def models(protocol: Protocol, profile: Profile) -> list[AbstractStudyModel]:
    """The study's models for `protocol`: the G-LPNet (`learn.fit_splitting`), the parametric
    limit, SINDy and weak SINDy (if pysindy is installed) and the MLP, fitted with `TRAIN_SEED`."""
    out: list[AbstractStudyModel] = [
        SplittingModel("G-LPNet", iterations=profile.steps, key=TRAIN_SEED, seed=TRAIN_SEED, validation_fraction=0.0),
        ParametricModel("limit", (Training(learn.KeepIfBetter(learn.LevenbergMarquardt(profile.steps, rtol=1e-12)),
                                           loss=learn.TrajectoryLoss(), validation_fraction=0.0, seed=TRAIN_SEED),),
                        family=protocol.family,
                        theta0=protocol.theta0 or (1.0,) * len(protocol.true_theta)),
    ]
    if sindy_available():
        out += [SINDyModel("SINDy"), WeakSINDyModel("weak SINDy")]
    out.append(mlp(profile.iterations))
    return out


def mlp(iterations: int, seed: int = TRAIN_SEED) -> MLPModel:
    """The residual MLP (3x16) on consecutive pairs: Adam (10 epochs per iteration, learning rate
    1e-3 decaying to 1e-5, full batch), then L-BFGS-B (`iterations`)."""
    optimiser = (learn.Adam(10 * iterations, learning_rate=1e-3, final_learning_rate=1e-5),
                 learn.KeepIfBetter(learn.ScipyLBFGSB(iterations)))
    return MLPModel("MLP", (Training(optimiser, loss=learn.TrajectoryLoss(window=1, latent=False),
                                     validation_fraction=0.0, seed=seed),), key=seed)


def evaluate(protocol: Protocol, model: AbstractStudyModel, data: it.Observations, y0: np.ndarray,
             reference: np.ndarray, *, system: str, noise: float, sampling: str) -> W2Row:
    """Fit `model` to `data` and measure its rollouts against `reference`."""
    start = time.perf_counter()
    fitted = model.fit(protocol.system, data)
    identified, profile = Identified(), None
    if isinstance(model, AbstractHamiltonianModel):
        identified = model.identify(fitted, protocol.system, np.concatenate(data.states),
                                    protocol.diagonal_differences)
        if protocol.leaf_circle is not None:
            profile = leaf_profile(fitted.step_map.hamiltonian, protocol.leaf_circle)
    fit_seconds = time.perf_counter() - start
    measured = figures(fitted, model.simulate(fitted, y0, reference.shape[1] - 1, H_TEST), reference)
    error = None
    if identified.differences is not None:
        error = np.abs(np.asarray(identified.differences) - differences(protocol.true_theta))
    mismatch = identified.mismatch or {}
    return W2Row(
        system=system, noise=noise, sampling=sampling, model=model.label, fit_seconds=fit_seconds,
        state_error=measured.state_error, energy_error=measured.energy_error, casimir_drift=measured.casimir_drift,
        train_loss=fitted.train_loss, family=identified.family, bic=identified.bic, theta=identified.theta,
        learned_hamiltonian_vs_H=mismatch.get("learned_hamiltonian_vs_H"),
        learned_hamiltonian_vs_H_mod_casimirs=mismatch.get("learned_hamiltonian_vs_H_mod_casimirs"),
        learned_vector_field_vs_H=mismatch.get("learned_vector_field_vs_H"),
        differences=identified.differences, difference_error=error,
        identifiable_error=identified.identifiable_error, axes_error_degrees=identified.axes_error_degrees,
        leaf_profile=profile,
    )


COLUMNS = (
    *GRID_COLUMNS,
    Column("state error t=100", lambda r: r.state_error),
    Column("max energy error", lambda r: r.energy_error),
    Column("Casimir drift", lambda r: r.casimir_drift),
    Column("fit [s]", lambda r: f"{r.fit_seconds:.1f}"),
    Column("H~ family", lambda r: r.family or "—"),
    Column("H~ - H mod Casimirs", lambda r: r.learned_hamiltonian_vs_H_mod_casimirs),
    Column("max error of 1/I_i - 1/I_j", lambda r: None if r.difference_error is None else max(r.difference_error)),
    Column("identifiable A, rel. error", lambda r: r.identifiable_error),
    Column("principal axes, max error [deg]", lambda r: r.axes_error_degrees),
)


PROFILES = profiles(
    # steps: Levenberg-Marquardt steps per stage (the G-LPNet and the limit); iterations: the
    # MLP's L-BFGS-B iterations (after 10x as many Adam epochs); n_trajectories and
    # n_observations: the protocol's when None
    Profile(steps=200, n_trajectories=None, n_observations=None, test_steps=STEPS_TEST),
    # "smoke" exercises the pipeline in seconds (tests): one system, small data, few iterations.
    smoke=Profile(systems=("rigid body",), noises=(1e-3,), samplings=("regular",), iterations=30, steps=20,
                  n_trajectories=6, n_observations=6, test_steps=50),
    quick=Profile(systems=("rigid body",), noises=(0.0, 1e-3, 1e-2), samplings=("regular", "uneven"),
                  iterations=1000),
    full=Profile(systems=("rigid body", "Kirchhoff", "diamond", "rotated rigid body", "coupled Kirchhoff",
                          "heavy top", "logarithmic rigid body"), noises=(0.0, 1e-3, 1e-2),
                 samplings=("regular", "uneven"), iterations=1000),
)


@dataclasses.dataclass(frozen=True)
class Condition:
    """A cell of W2's grid: a protocol's observations at one sampling and noise, and its
    held-out initial conditions `y0` with heyoka's `reference` from them."""

    system: str
    sampling: str
    noise: float
    protocol: Protocol
    data: it.Observations
    y0: np.ndarray
    reference: np.ndarray


class W2(AbstractStudy):
    id = "W2"
    title = "learning from observations: noisy, unevenly sampled trajectories, against SINDy and the parametric limit"
    profiles = PROFILES
    row_type = W2Row
    columns = COLUMNS

    def conditions(self, P):
        all_protocols = protocols()
        for system in P.systems:
            protocol = all_protocols[system]
            y0, reference = test_set(protocol, steps=P.test_steps)
            for sampling, noise in itertools.product(P.samplings, P.noises):
                data = observations(protocol, noise, sampling, n_trajectories=P.n_trajectories,
                                    n_observations=P.n_observations)
                yield Condition(system, sampling, noise, protocol, data, y0, reference)

    def models(self, P, condition):
        return models(condition.protocol, P)

    def evaluate(self, condition, model, progress):
        c = condition
        return evaluate(c.protocol, model, c.data, c.y0, c.reference, system=c.system, noise=c.noise,
                        sampling=c.sampling)

    def row_name(self, profile, condition, model):
        c = condition
        return f"{profile}-{c.system}-{c.sampling}-{c.noise:g}-{model.label}.json".replace(" ", "_")

    @staticmethod
    def line(row: W2Row) -> str:
        extra = ""
        if row.difference_error is not None:
            extra = f", max |error of 1/I_i - 1/I_j| {np.max(row.difference_error):.1e}"
        if row.identifiable_error is not None:
            extra += f", identifiable A within {fmt(row.identifiable_error)}"
        if row.axes_error_degrees is not None:
            extra += f", principal axes within {row.axes_error_degrees:.2g} deg"
        if row.family:
            extra += f", H~ {row.family}"
        if row.learned_hamiltonian_vs_H_mod_casimirs is not None:
            extra += f", H~ - H mod Casimirs {fmt(row.learned_hamiltonian_vs_H_mod_casimirs)}"
        return (f"{row.system}, {row.sampling}, noise {row.noise:g}, {row.model}: state error (t=100) "
                f"{fmt(row.state_error)}, energy {fmt(row.energy_error)}, Casimir {fmt(row.casimir_drift)}, "
                f"fit {row.fit_seconds:.1f} s{extra}")

    def verdict(self, rows: list[W2Row], conditions: Any = ()) -> list[str]:
        """Per system, sampling and noise: the G-LPNet against SINDy and the parametric limit."""
        out = []
        for r in rows:
            if r.model != "G-LPNet":
                continue
            limit, sindy = peer(rows, r, "limit"), peer(rows, r, "SINDy")
            parts = [f"{r.system}, {r.sampling}, noise {r.noise:g}: G-LPNet state error {fmt(r.state_error)}"]
            if limit and r.noise == 0:
                parts.append(f"the limit {fmt(limit.state_error)} (exact data: the true family is exact up to its "
                             "RK4; the G-LPNet's error is that of its splitting)")
            elif limit:
                parts.append(f"{r.state_error / limit.state_error:.2f}x the limit's ({fmt(limit.state_error)}), "
                             f"energy error {r.energy_error / limit.energy_error:.2f}x")
            for other in (sindy, peer(rows, r, "weak SINDy")):
                if other:
                    below = r.state_error < other.state_error
                    parts.append(f"{'below' if below else 'ABOVE'} {other.model}'s {fmt(other.state_error)}")
            parts.append(f"Casimir drift {fmt(r.casimir_drift)}")
            out.append("; ".join(parts))
        return out

    def figures(self, rows: list[W2Row], conditions: Any, out_dir: Path) -> list[str]:
        """Per system and sampling: state error at t = 100 against the noise, one line per model."""
        names = []
        for system in dict.fromkeys(r.system for r in rows):
            samplings = list(dict.fromkeys(r.sampling for r in rows if r.system == system))
            fig = figure(figsize=(5.5 * len(samplings), 4.5))
            axes = np.atleast_1d(fig.subplots(1, len(samplings)))
            for ax, sampling in zip(axes, samplings):
                sub = [r for r in rows if r.system == system and r.sampling == sampling]
                labels = list(dict.fromkeys(r.model for r in sub))
                for label, style in zip(labels, series_styles(len(labels))):
                    pts = sorted((r for r in sub if r.model == label), key=lambda r: r.noise)
                    noise = np.array([max(r.noise, 1e-4) for r in pts])  # noise 0 drawn at 1e-4
                    ax.loglog(noise, [r.state_error for r in pts], label=label, **style)
                ax.set_xlabel("noise (relative; 0 drawn at 1e-4)")
                ax.set_ylabel("mean state error at t = 100")
                ax.set_title(f"{system}, {sampling} sampling")
                span_decades(ax, "y")
                ax.legend()
            name = f"state_error_{system.replace(' ', '_')}.png"
            save_figure(fig, out_dir / name, dpi=120)
            names.append(name)
        names.extend(_profile_plots(rows, out_dir))
        return names

    def summary(self, P, rows, conditions):
        return {
            "seeds": {"data": DATA_SEED, "test": TEST_SEED, "training": TRAIN_SEED},
            "sindy": "pysindy " + _version("pysindy") if sindy_available() else "not installed (extra peers)",
            "model": "G-LPNet (TripleJump, family by held-out prediction)",
            "test_steps": P.test_steps,
        }

    def summary_rows(self, rows):
        return [(f"{r.system} {r.sampling} noise {r.noise:g} G-LPNet state error(t=100)", "—",
                 fmt(r.state_error), fmt(getattr(peer(rows, r, "limit"), "state_error", None)))
                for r in rows if r.model == "G-LPNet"]

    def description(self, metrics):
        return (
            f"Seeds: {metrics.get('seeds')}. SINDy: {metrics.get('sindy')}. Figures: means over "
            f"{N_TEST} held-out initial conditions, rolled out {metrics.get('test_steps')} steps of 0.1 against heyoka; "
            "energy: max relative error of the true H; Casimir drift: max |C(t) - C(0)| / (|grad C| |y|).")




def _version(name: str) -> str:
    from importlib.metadata import version

    return version(name)



def non_quadratic_part(profile: Any) -> np.ndarray:
    r"""A `leaf_profile` less its least-squares $c_0 + c_1\cos2\theta + c_2\sin2\theta$: on a
    great circle of the leaf every quadratic form is of that shape, so what is left is the part
    of the Hamiltonian no quadratic one has."""
    theta = np.linspace(0.0, 2.0 * np.pi, PROFILE_POINTS)
    basis = np.stack([np.ones_like(theta), np.cos(2 * theta), np.sin(2 * theta)], axis=1)
    values = np.asarray(profile, dtype=np.float64)
    return values - basis @ np.linalg.lstsq(basis, values, rcond=None)[0]


def _profile_plots(rows: list[W2Row], out_dir: Path) -> list[str]:
    """Per system with a leaf circle: the true and the learned Hamiltonians around it (top) and
    their parts no quadratic has (bottom), one column per condition: a non-polynomial term's
    shape against the truth."""
    all_protocols = protocols()
    names = []
    for system in dict.fromkeys(r.system for r in rows if r.leaf_profile is not None):
        circle = all_protocols[system].leaf_circle
        truth = leaf_profile(all_protocols[system].system.hamiltonian, circle)
        conditions = list(dict.fromkeys(r.condition for r in rows if r.system == system and r.leaf_profile))
        fig = figure(figsize=(6.0 * len(conditions), 7.5), layout="constrained")
        axes = np.asarray(fig.subplots(2, len(conditions), squeeze=False))
        theta = np.linspace(0.0, 2.0 * np.pi, PROFILE_POINTS)
        for column, condition in enumerate(conditions):
            sub = [r for r in rows if r.condition == condition and r.leaf_profile]
            for ax, part in zip(axes[:, column], (np.asarray, non_quadratic_part)):
                ax.plot(theta, part(truth), color="k", lw=3, alpha=0.35, label="true H")
                for r, style in zip(sub, series_styles(len(sub))):
                    ax.plot(theta, part(r.leaf_profile), label=f"{r.model} H~", **style)
                ax.legend(fontsize="small")
            axes[0, column].set_title(f"{system}, {condition[1]}, noise {condition[2]:g}")
            axes[0, column].set_ylabel("H less its mean on the circle")
            axes[1, column].set_ylabel("its part no quadratic H has")
            axes[1, column].set_xlabel("angle around the great circle through V on |Pi| = 1 [rad]")
        name = f"leaf_profile_{system.replace(' ', '_')}.png"
        save_figure(fig, out_dir / name, dpi=120)
        names.append(name)
    return names


EXPERIMENT = W2()


def bootstrap_quadratic(protocol: Protocol, data: it.Observations, n: int, seed: int = 0,
                        iterations: int | None = None) -> list[learn.QuadraticPart]:
    """The quadratic parts (`learn.quadratic_part` over the resample's states) of `n` G-LPNets,
    each fitted to the trajectories of `data` resampled with replacement (seeded): their spread
    is the uncertainty of what the G-LPNet identifies."""
    model = SplittingModel("G-LPNet", iterations=iterations, key=TRAIN_SEED, seed=TRAIN_SEED, validation_fraction=0.0)
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        sample = data.select(rng.integers(0, len(data), len(data)))
        fitted = model.fit(protocol.system, sample)
        out.append(learn.quadratic_part(fitted.step_map.hamiltonian, protocol.system, np.concatenate(sample.states)))
    return out


def bootstrap_differences(protocol: Protocol, data: it.Observations, n: int, seed: int = 0,
                          iterations: int | None = None) -> np.ndarray:
    """The rigid body's identified 1/I_i - 1/I_j from `bootstrap_quadratic`: `(n, 3)`."""
    return np.asarray([q.diagonal_differences() for q in bootstrap_quadratic(protocol, data, n, seed, iterations)])


def bootstrap_axes(protocol: Protocol, data: it.Observations, n: int, seed: int = 0,
                   iterations: int | None = None) -> dict[str, np.ndarray]:
    """A body in dimension 3 with a quadratic Hamiltonian: the principal axes from
    `bootstrap_quadratic` against the true ones: `values` `(n, 3)` (the $1/I_k$ less their
    mean), `angles` `(n, 3)` (radians, each learned axis to the true one), and the true
    `true_values`, `true_rotation_vector`."""
    true = learn.quadratic_part(protocol.system.hamiltonian, protocol.system, np.concatenate(data.states))
    axes = true.principal_axes()
    parts = [q.principal_axes() for q in bootstrap_quadratic(protocol, data, n, seed, iterations)]
    return {"values": np.asarray([p.values for p in parts]), "angles": np.asarray([p.angles_to(axes.axes) for p in parts]),
            "rotation_vectors": np.asarray([p.rotation_vector() for p in parts]),
            "true_values": axes.values, "true_rotation_vector": axes.rotation_vector()}
