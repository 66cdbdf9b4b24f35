r"""A known family of Hamiltonians with unknown parameters, as a map to fit: the "true model"
of a study, which a learned map is measured against (fitted to the same data, it shows how
far the data allow a method to go)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from integrators.internals import check_h, check_state, rk4_steps
from liepoisson.internals import check_system, positive_float, positive_int, refuse_nonholonomic
from liepoisson.systems import AbstractPoissonSystem

from .._solvers._quasi_newton import ScipyBFGS
from .._solvers._stage import KeepIfBetter
from ._base import AbstractBodyMap


class ParametricHamiltonian(AbstractBodyMap):
    r"""The flow of $\dot y = \mathbb B(y)\nabla_y H(y; \theta)$ over one step, for a
    Hamiltonian family `hamiltonian(y, theta)` (JAX, scalar) with parameters $\theta$ fitted
    by `learn.fit`; the bracket is `system`'s.

    The step is `substeps` classical Runge-Kutta steps (RK4): accurate (local error
    $O((h/n)^5)$), not structure-preserving (Casimirs drift at that level), which is what a
    reference model needs. Fitted to observations by trajectory least squares (`learn.fit(...,
    loss=learn.TrajectoryLoss())`, initial states included), it is the parametric limit that a
    learned map can at best reach on the same data.

    Example, the rigid body with unknown inverse moments of inertia:
    `ParametricHamiltonian(system, lambda y, d: 0.5 * jnp.sum(d * y**2), theta=jnp.ones(3))`.
    """

    system: AbstractPoissonSystem
    theta: jax.Array
    hamiltonian_family: Callable[[jax.Array, jax.Array], jax.Array] = eqx.field(static=True)
    substeps: int = eqx.field(static=True)
    h: float | None


    def __init__(self, system: AbstractPoissonSystem, hamiltonian: Callable[[jax.Array, jax.Array], jax.Array],
                 theta: ArrayLike, *, substeps: int = 10, h: float | None = None, key: Any = None):
        self.system = check_system(system)
        refuse_nonholonomic(system, "a ParametricHamiltonian (B grad H, without the reaction force)")
        if not callable(hamiltonian):
            raise TypeError(f"hamiltonian must be a function (y, theta) -> scalar; got {hamiltonian!r}")
        theta = np.asarray(theta, dtype=np.float64)
        if theta.ndim != 1 or theta.size == 0 or not np.all(np.isfinite(theta)):
            raise ValueError(f"theta must be a non-empty finite 1-D array (the initial parameters); got {theta!r}")
        value = hamiltonian(jnp.zeros(system.dim) + 0.5, jnp.asarray(theta))
        if jnp.shape(value) != ():
            raise ValueError(f"hamiltonian(y, theta) must return a scalar; got shape {jnp.shape(value)}")
        self.theta = jnp.asarray(theta)
        self.hamiltonian_family = hamiltonian
        self.substeps = positive_int(substeps, "substeps")
        self.h = None if h is None else positive_float(h, "h")

    def hamiltonian(self, y: ArrayLike) -> jax.Array:
        r"""$H(y; \theta)$ at the fitted parameters, shape `(...)` for `y` `(..., dim)`."""
        y = jnp.asarray(y)
        flat = y.reshape(-1, self.system.dim)
        return jax.vmap(lambda x: self.hamiltonian_family(x, self.theta))(flat).reshape(y.shape[:-1])

    def vector_field(self, y: jax.Array) -> jax.Array:
        return self.system.poisson_tensor(y) @ jax.grad(self.hamiltonian_family)(y, self.theta)

    def step(self, y: jax.Array) -> jax.Array:
        return rk4_steps(self.vector_field, check_state(y, self.system.dim), check_h(self), self.substeps)

    def body_velocity(self, y: jax.Array) -> jax.Array:
        r"""$\xi = \nabla_y H(y; \theta)$ for one state: the body velocity ($\dot g = g\,\xi$)."""
        return jax.grad(self.hamiltonian_family)(y, self.theta)

    def lifted_step(self, g: jax.Array, y: jax.Array) -> tuple[jax.Array, jax.Array]:
        r"""RK4 (`substeps` steps) on $(g, y)$ with $\dot g = g\,\nabla H$ written in the group's
        coordinates (`group.velocity_components`), then $g$ projected on the group (a unit
        quaternion normalised): accurate, not structure-preserving, as `step`."""
        group = self.system.require_group()
        g, y = group.check(g, "g"), check_state(y, self.system.dim)

        def f(z):
            gz, yz = z
            xi = self.body_velocity(yz)
            dg = jnp.stack(group.velocity_components([gz[i] for i in range(group.size)], [xi[i] for i in range(xi.size)]))
            return dg, self.system.poisson_tensor(yz) @ xi

        g1, y1 = rk4_steps(f, (g, y), check_h(self), self.substeps)
        return group.project(g1), y1

    @property
    def exact_flows_per_step(self) -> int:
        return 0

    def hyperparameters(self) -> dict[str, Any]:
        # the family is a function: it is not saved (a file could not rebuild it)
        return {"hamiltonian": self.hamiltonian_family, "substeps": self.substeps}

    @classmethod
    def from_hyperparameters(cls, system, hyperparameters, *, key=0, h=None):
        hp = dict(hyperparameters)
        if not callable(hp.get("hamiltonian")):
            raise TypeError("a ParametricHamiltonian's family is a Python function, which a file cannot hold")
        return cls(system, hp["hamiltonian"], np.ones(1), substeps=hp["substeps"], h=h)

    def reinitialised(self, key):
        return self  # no random initialisation: the parameters start where they were given

    def default_optimiser(self):
        """BFGS, 1000 iterations (a few parameters and, with observations, the fitted starts)."""
        return (KeepIfBetter(ScipyBFGS(1000)),)
