"""The models of the studies beyond the paper behind one interface, `AbstractStudyModel` (every
study's); those of W1-W3 `fit` to data, then `simulate` from held-out initial conditions. One
final class per kind of model; what differs per system is data on the study's own protocol
object, never a branch on its name."""

from __future__ import annotations

import abc
import dataclasses
from collections.abc import Callable, Sequence
from typing import Any

import jax
import numpy as np

import integrators as it
import learn
import liepoisson as lp


@dataclasses.dataclass(frozen=True)
class Fitted:
    """A model fitted by a study: its `step_map` (what `integrators.rollout_figures` measures)
    and the `records` of its trainings, in order (none for a classical map)."""

    step_map: it.AbstractStepMap
    records: tuple[learn.TrainingRecord, ...] = ()

    @property
    def train_loss(self) -> float | None:
        """The training loss of the last training, or `None` for a map that was not trained."""
        return self.records[-1].train_loss if self.records else None

    @property
    def wall_time_s(self) -> float | None:
        """The training time of the last training, or `None`."""
        return self.records[-1].wall_time_s if self.records else None


class AbstractStudyModel(abc.ABC):
    """A model of a study (W1-W7), learned or peer alike, as `paper._runner.AbstractStudy`
    runs it: `fit(problem, data)` returns what it fitted to `data` of `problem` (the study's
    system or protocol); the study measures it by the prediction its rows need, declared by the
    study's own subclass of this one (`AbstractStateModel.simulate`, W4's `predict` of attitudes,
    ...). `label` names its rows; a new row of a study is a new instance in its `models`."""

    label: str

    @abc.abstractmethod
    def fit(self, problem: Any, data: Any, *, progress: bool = False) -> Any:
        """What the model fitted to `data` of `problem`."""

    def accepts(self, data: Any) -> bool:
        """Whether the model can be fitted to `data` (all models but those whose step has no
        step-size input take any sampling)."""
        return True


class AbstractStateModel(AbstractStudyModel):
    """A model of the states of a Poisson system (W1-W3): `fit(system, data)` returns a
    `Fitted`, `simulate(fitted, y0, n_steps, h)` its states from `y0` `(n, dim)` every step $h$,
    `(n, n_steps + 1, dim)`, with their non-finite tail if it diverged."""

    @abc.abstractmethod
    def fit(self, system: lp.systems.AbstractPoissonSystem, data: Any, *, progress: bool = False) -> Fitted:
        """Fit to `data` (an `integrators.Trajectories` or `Observations`) of `system`."""

    @abc.abstractmethod
    def simulate(self, fitted: Fitted, y0: np.ndarray, n_steps: int, h: float) -> np.ndarray:
        """`n_steps` steps of `h` from `y0`."""


class AbstractStepMapModel(AbstractStateModel):
    """A model whose fitted form is a step map: it simulates by the map's rollout at `h`."""

    def simulate(self, fitted: Fitted, y0: np.ndarray, n_steps: int, h: float) -> np.ndarray:
        return np.asarray(fitted.step_map.with_h(h).rollout(y0, n_steps, nonfinite="return"))


@dataclasses.dataclass(frozen=True)
class ClassicalMap(AbstractStepMapModel):
    """A classical integrator: `make(system, h)` returns its step map at step `h`; nothing is fitted."""

    label: str
    make: Callable[[lp.systems.AbstractPoissonSystem, float], it.AbstractStepMap]
    h: float

    def fit(self, system, data=None, *, progress=False) -> Fitted:
        return Fitted(self.make(system, self.h))


@dataclasses.dataclass(frozen=True)
class Training:
    """One call of `learn.fit`: its optimiser (or stages) and the objective's settings, passed
    as they are (`learn.fit`'s defaults are the defaults here)."""

    optimiser: Any
    loss: Any = None
    validation_fraction: float = 0.2
    seed: int = 0
    normalise: bool = False


class AbstractTrainedModel(AbstractStepMapModel):
    """A learned map built by `network(system)` and fitted by `learn.fit` in one call per
    `Training` of `trainings`, each from the previous one's result."""

    trainings: tuple[Training, ...]

    @abc.abstractmethod
    def network(self, system: lp.systems.AbstractPoissonSystem) -> learn.AbstractLearnedMap:
        """The untrained map."""

    def fit(self, system, data, *, progress=False) -> Fitted:
        model, records = self.network(system), []
        for t in self.trainings:
            model, record = learn.fit(model, data, optimiser=t.optimiser, loss=t.loss,
                                      validation_fraction=t.validation_fraction, seed=t.seed,
                                      normalise=t.normalise, progress=progress)
            records.append(record)
        return Fitted(model, tuple(records))


@dataclasses.dataclass(frozen=True)
class LPNetModel(AbstractTrainedModel):
    """An LPNet (`learn.LPNet(system, key=key, h=h)`, the paper's architecture)."""

    label: str
    trainings: tuple[Training, ...]
    key: int = 0
    h: float | None = None

    def network(self, system):
        return learn.LPNet(system, key=self.key, h=self.h)


@dataclasses.dataclass(frozen=True)
class GLPNetModel(AbstractTrainedModel):
    """A G-LPNet of `modules_per_dimension` times the dimension modules composed by `method`."""

    label: str
    trainings: tuple[Training, ...]
    method: Any
    modules_per_dimension: int = 2
    key: int = 0

    def network(self, system):
        return learn.GLPNet(system, n_modules=self.modules_per_dimension * system.dim, key=self.key,
                            method=self.method)


@dataclasses.dataclass(frozen=True)
class MLPModel(AbstractTrainedModel):
    """The unstructured residual MLP (`learn.MLPBaseline`). Its step has no step-size input:
    it is fitted to regularly sampled data only."""

    label: str
    trainings: tuple[Training, ...]
    hidden: tuple[int, ...] = (16, 16, 16)
    key: int = 0

    def network(self, system):
        return learn.MLPBaseline(system, hidden=self.hidden, key=self.key)

    def accepts(self, data) -> bool:
        return data.is_regular()


@dataclasses.dataclass(frozen=True)
class Identified:
    """What a model identified of the true Hamiltonian $H$: the family of its learned
    $\\widetilde H$ that `learn.fit_splitting` chose and each family's BIC, its
    fitted coefficients `theta` (a parametric model), `hamiltonian_mismatch` against $H$, and the
    differences of the diagonal of its quadratic part (for the rigid body the identified
    $1/I_i - 1/I_j$); for a quadratic $H$, the relative (Frobenius) error of the identifiable
    part of its matrix (`learn.QuadraticPart.identifiable`) and, in dimension 3, the largest
    angle between the learned and the true principal axes. `None`: not measured for this model."""

    family: str | None = None
    bic: dict[str, float] | None = None
    theta: np.ndarray | None = None
    mismatch: dict[str, float] | None = None
    differences: np.ndarray | None = None
    identifiable_error: float | None = None
    axes_error_degrees: float | None = None


class AbstractHamiltonianModel(AbstractStateModel):
    """A model that learns a Hamiltonian: `identify` says what of the true one it recovered."""

    @abc.abstractmethod
    def identify(self, fitted: Fitted, system, states: np.ndarray, diagonal: bool) -> Identified:
        """What `fitted` identified, measured on `states`; the diagonal differences if `diagonal`."""


@dataclasses.dataclass(frozen=True)
class SplittingModel(AbstractStepMapModel, AbstractHamiltonianModel):
    """A G-LPNet fitted by `learn.fit_splitting` (the family of its learned Hamiltonian chosen by
    its default: held-out prediction on observations), with that function's arguments."""

    label: str
    iterations: int | None = None
    key: int = 0
    seed: int = 0
    validation_fraction: float | None = None  # fit_splitting's: 0.2 on pairs, 0 on observations
    loss: learn.TrajectoryLoss | None = None
    activation: str | None = None

    def fit(self, system, data, *, progress=False) -> Fitted:
        model, records = learn.fit_splitting(system, data, key=self.key, seed=self.seed,
                                             validation_fraction=self.validation_fraction,
                                             iterations=self.iterations, loss=self.loss,
                                             activation=self.activation, progress=progress)
        return Fitted(model, tuple(records))

    def identify(self, fitted, system, states, diagonal) -> Identified:
        choice = fitted.records[-1].choice  # a learn.FamilyChoice on observations; None on pairs
        family = None if choice is None else choice.chosen
        bic = None if choice is None else {score.family: score.bic for score in choice.scores}
        hamiltonian = fitted.step_map.hamiltonian
        learned = learn.quadratic_part(hamiltonian, system, states)
        return Identified(family=family, bic=bic, mismatch=hamiltonian_mismatch(hamiltonian, system, states),
                          differences=learned.diagonal_differences() if diagonal else None,
                          **quadratic_errors(learned, learn.quadratic_part(system.hamiltonian, system, states)))


def quadratic_errors(learned: learn.QuadraticPart, true: learn.QuadraticPart) -> dict[str, float]:
    """`identifiable_error` and (dimension 3) `axes_error_degrees` of `learned` against the
    quadratic part of a true Hamiltonian that is quadratic (nothing otherwise)."""
    if true.residual > 1e-9:  # the true H is not quadratic: no matrix to compare
        return {}
    reference = true.identifiable()
    out = {"identifiable_error": float(np.linalg.norm(learned.identifiable() - reference) / np.linalg.norm(reference))}
    if reference.shape == (3, 3):
        angles = learned.principal_axes().angles_to(true.principal_axes().axes)
        out["axes_error_degrees"] = float(np.degrees(np.max(angles)))
    return out


@dataclasses.dataclass(frozen=True)
class ConservativePartModel(SplittingModel):
    """A G-LPNet fitted by `learn.fit_splitting` with the conservative part of a dissipative
    system (its bracket; `fit_splitting` refuses the dissipative system itself): an exactly
    Poisson map fitted to data it cannot follow, to show what the structure cannot do."""

    def fit(self, system, data, *, progress=False) -> Fitted:
        return super().fit(system.conservative, data, progress=progress)


@dataclasses.dataclass(frozen=True)
class ParametricModel(AbstractTrainedModel, AbstractHamiltonianModel):
    """The true model family `family(y, theta)` with unknown coefficients
    (`learn.ParametricHamiltonian`, RK4 with `substeps` sub-steps), from `theta0`."""

    label: str
    trainings: tuple[Training, ...]
    family: Callable[[Any, Any], Any]
    theta0: tuple[float, ...]
    substeps: int = 10

    def network(self, system):
        return learn.ParametricHamiltonian(system, self.family, np.asarray(self.theta0, dtype=np.float64),
                                           substeps=self.substeps)

    def identify(self, fitted, system, states, diagonal) -> Identified:
        theta = np.asarray(fitted.step_map.theta)
        return Identified(theta=theta, differences=differences(theta) if diagonal else None)


def differences(theta) -> np.ndarray:
    """theta_i - theta_j for i < j (for the rigid body, the identified 1/I_i - 1/I_j)."""
    theta = np.asarray(theta)
    i, j = np.triu_indices(theta.size, 1)
    return theta[i] - theta[j]


def hamiltonian_mismatch(learned_hamiltonian, system, y) -> dict[str, float]:
    r"""How far a learned Hamiltonian $\widetilde H$ is from the system's $H$ on the states `y`:

    - `learned_hamiltonian_vs_H`: $\max|d - \bar d| / \max|H|$ with $d = \widetilde H - H$. A
      function of the Casimirs in $d$ shows here although it moves no trajectory;
    - `learned_hamiltonian_vs_H_mod_casimirs`: the same after subtracting from $d$ its
      least-squares fit by the polynomials of degree $\le 2$ in the Casimirs;
    - `learned_vector_field_vs_H`: $\max|X_{\widetilde H} - X_H| / \max|X_H|$ with
      $X_F = \mathbb B(y)\nabla F$: blind to Casimir terms by construction.
    """
    y = np.asarray(y, dtype=np.float64)
    H = np.asarray(system.hamiltonian(y))
    d = np.asarray(learned_hamiltonian(y)) - H
    C = np.asarray(system.casimirs(y))
    k = C.shape[-1]
    basis = np.stack([np.ones_like(d), *C.T, *(C[:, i] * C[:, j] for i in range(k) for j in range(i, k))], axis=-1)
    fit, *_ = np.linalg.lstsq(basis, d, rcond=None)
    grad = jax.vmap(jax.grad(lambda z: learned_hamiltonian(z[None])[0]))(y)
    X_learned = np.einsum("...ab,...b->...a", np.asarray(system.poisson_tensor(y)), np.asarray(grad))
    X = np.asarray(system.vector_field(y))
    return {
        "learned_hamiltonian_vs_H": float(np.max(np.abs(d - d.mean())) / np.max(np.abs(H))),
        "learned_hamiltonian_vs_H_mod_casimirs": float(np.max(np.abs(d - basis @ fit)) / np.max(np.abs(H))),
        "learned_vector_field_vs_H": float(
            np.max(np.linalg.norm(X_learned - X, axis=-1)) / np.max(np.linalg.norm(X, axis=-1))
        ),
    }


def fit_all(models: Sequence[AbstractStateModel], system, data, progress: bool = False) -> list[Fitted]:
    """`model.fit(system, data)` for each model (one task of `paper._cluster.map_trainings`)."""
    return [model.fit(system, data, progress=progress) for model in models]

