"""The free rigid body on so(3)*."""

from __future__ import annotations

import jax
import numpy as np
from numpy.typing import ArrayLike

from .._catalogue import so3
from .._validation import positive_vector
from ._base import AbstractDefinedByParams, AbstractExactlySolvableSystem, AbstractLiePoissonSystem
from ._free_rigid_body import free_rigid_body_flow
from ._terms import CollectiveTerm


def _axis_term(axis: int, weight: float, dim: int, name: str) -> CollectiveTerm:
    form = np.zeros(dim)
    form[axis] = 1.0
    return CollectiveTerm(form, lambda s, w=weight: 0.5 * w * s[0] ** 2, name=name)


class RigidBody(AbstractLiePoissonSystem, AbstractExactlySolvableSystem, AbstractDefinedByParams):
    r"""Free rigid body: $H(\Pi) = \tfrac12 \Pi\cdot\mathbb{I}^{-1}\Pi$ on so(3)*,
    $\dot\Pi = \Pi\times\Omega$ with $\Omega = \mathbb{I}^{-1}\Pi$ (Euler's equations).

    **Arguments:** `inertia`, the principal moments $(I_1, I_2, I_3)$ (paper: diag(1, 2, 3)).
    """

    name = "RigidBody"

    def __init__(self, inertia=(1.0, 2.0, 3.0)):
        self.inertia = positive_vector(inertia, "inertia", 3)
        self.algebra = so3()

    @property
    def params(self):
        return {"inertia": self.inertia.tolist()}

    def hamiltonian_components(self, y, xp):
        I1, I2, I3 = (float(v) for v in self.inertia)
        return 0.5 * (y[0] ** 2 / I1 + y[1] ** 2 / I2 + y[2] ** 2 / I3)

    def hamiltonian_splitting(self):
        r"""$H = \sum_i \Pi_i^2/(2I_i)$: each piece rotates $\Pi$ about the body axis $e_i$."""
        return tuple(_axis_term(i, 1.0 / self.inertia[i], 3, f"T{i + 1}") for i in range(3))

    def exact_flow(self, t: ArrayLike, y: ArrayLike) -> jax.Array:
        r"""The exact solution $\Pi(t)$ from $\Pi(0)$ = `y` by Jacobi elliptic functions
        (`liepoisson.systems.free_rigid_body_flow`), batched over `y`."""
        return free_rigid_body_flow(self.inertia, t, y)
