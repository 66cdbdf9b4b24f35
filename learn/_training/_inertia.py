r"""The inertia a learned map of a body holds: principal moments at the scale the data identify,
principal axes, and their spread over fits to resampled trajectories (the bootstrap).

From body velocities alone ($\xi$, what a gyroscope reads) the momenta are latent and the
inertia is identified only up to a factor: $\mathbb I\dot\xi = (\mathbb I\xi)\times\xi + F$ is
unchanged by $\mathbb I \to c\,\mathbb I$, $F \to cF$. The moments are therefore reported over
their sum (`Inertia.moments`, summing to 1), the drag relative to the inertia."""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from integrators import BodyObservations, Observations
from liepoisson.internals import positive_int, progress_bar

from .._models._base import AbstractBodyMap
from .._solvers._levenberg_marquardt import LevenbergMarquardt
from .._solvers._stage import KeepIfBetter
from ._body import BodyLoss, latent_momenta
from ._identify import PrincipalAxes, quadratic_part

#: Levenberg-Marquardt steps of each bootstrap refit (from the fitted map: a short walk).
BOOTSTRAP_ITERATIONS = 30


@dataclasses.dataclass(frozen=True)
class Inertia:
    r"""Principal moments of inertia over their sum (`moments`, ascending, summing to 1), the
    principal axes (`axes`, columns, a rotation from the data's axes), and, from `n_bootstrap`
    refits to resampled trajectories, the standard deviation of each moment
    (`moments_spread`) and the RMS angle (radians) of each axis from the fit's
    (`axes_spread`); `None` without a bootstrap."""

    moments: np.ndarray
    axes: np.ndarray
    moments_spread: np.ndarray | None = None
    axes_spread: np.ndarray | None = None
    n_bootstrap: int = 0

    def ratios(self) -> np.ndarray:
        """The moments over the middle one ($I_1/I_2$, 1, $I_3/I_2$ for a body)."""
        return self.moments / self.moments[len(self.moments) // 2]


def inertia_matrix(model: AbstractBodyMap, data: BodyObservations | Observations | None = None) -> np.ndarray:
    r"""$\mathbb I = A^{-1}$ for the quadratic part $\tfrac12\mu^\top A\mu + b^\top\mu$ of the
    map's $\widetilde H$: its Hessian when $\widetilde H$ is quadratic; else the least-squares
    quadratic over the data's momenta (latent ones from the observed velocities), where the
    fit holds, not the Hessian at one point."""
    if not isinstance(model, AbstractBodyMap):
        raise TypeError(f"model must be a learned map of a body with a learned Hamiltonian (learn.GLPNet, "
                        f"learn.Dissipative); got {type(model).__name__}")
    dim = model.system.dim
    zero = jnp.zeros(dim)
    A = np.asarray(jax.jacfwd(model.body_velocity)(zero))
    probes = np.random.default_rng(0).normal(size=(4, dim))
    affine = probes @ A.T + np.asarray(model.body_velocity(zero))
    exact = np.asarray(jax.vmap(model.body_velocity)(jnp.asarray(probes)))
    if not np.allclose(affine, exact, rtol=1e-10, atol=1e-10 * float(np.max(np.abs(exact)))):  # not quadratic
        if data is None:
            raise ValueError(f"the map's learned Hamiltonian is not quadratic (activation {getattr(model, 'activation', '?')!r}): "
                             "its inertia depends on the state; give data= (the observations it was fitted to) to "
                             "take the least-squares quadratic over their momenta")
        samples = _momenta(model, data)
        A = quadratic_part(model.hamiltonian, model.system, samples).matrix
    return np.linalg.inv(0.5 * (A + A.T))


def inertia(model: AbstractBodyMap, data: BodyObservations | Observations | None = None, *, n_bootstrap: int = 0,
            loss: BodyLoss | None = None, seed: int = 0, progress: bool | None = None) -> Inertia:
    r"""The principal moments (over their sum) and axes of the map's inertia
    (`inertia_matrix`), with their bootstrap spread when `n_bootstrap` > 0: the map refitted
    (`BOOTSTRAP_ITERATIONS` Levenberg-Marquardt steps from the fit, `loss`, default
    `learn.BodyLoss()`) to `n_bootstrap` resamples of `data`'s trajectories drawn with
    replacement (seeded by `seed`)."""
    I = inertia_matrix(model, data)
    moments, axes = _principal(I)
    if n_bootstrap == 0:
        return Inertia(moments, axes)
    n_bootstrap = positive_int(n_bootstrap, "n_bootstrap")
    if not isinstance(data, BodyObservations):
        raise ValueError("n_bootstrap > 0 refits the map to resampled trajectories: give data= (the "  # noqa: TRY004 - an unfit value (file, data), not an argument of the wrong type
                         f"integrators.BodyObservations it was fitted to); got {type(data).__name__}")
    from ._fit import fit

    rng = np.random.default_rng(seed)
    loss = BodyLoss() if loss is None else loss
    samples_m, angles = [], []
    with progress_bar(n_bootstrap, "bootstrap", "fit", progress) as bar:
        for _ in range(n_bootstrap):
            resample = data.select(rng.integers(0, len(data), size=len(data)))
            refit, _ = fit(model, resample, loss=loss, optimiser=(KeepIfBetter(LevenbergMarquardt(BOOTSTRAP_ITERATIONS)),),
                           progress=False)
            m, ax = _principal(inertia_matrix(refit, resample))
            samples_m.append(m)
            angles.append(PrincipalAxes(m, ax).angles_to(axes))
            bar.update(1)
    return Inertia(moments, axes, np.std(samples_m, axis=0, ddof=1) if n_bootstrap > 1 else np.zeros_like(moments),
                   np.sqrt(np.mean(np.square(angles), axis=0)), n_bootstrap)


def _principal(I: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    values, vectors = np.linalg.eigh(I)
    if np.linalg.det(vectors) < 0:
        vectors[:, -1] = -vectors[:, -1]
    return values / np.sum(values), vectors


def _momenta(model: Any, data: BodyObservations | Observations) -> np.ndarray:
    if isinstance(data, Observations):
        return np.concatenate(list(data.states))
    if not isinstance(data, BodyObservations):
        raise TypeError(f"data must be integrators.BodyObservations or Observations; got {type(data).__name__}")
    velocities = data.velocities if data.velocities is not None else [
        data.group_velocities(j) for j in range(len(data))]
    return np.asarray(latent_momenta(model, np.concatenate(list(velocities))))
