r"""The generalized (Manakov) rigid body on so(N)*."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .._matrix_algebra import so
from .._validation import positive_vector
from ._base import AbstractDefinedByParams, AbstractLiePoissonSystem
from ._rigid_body import _axis_term


class GeneralizedRigidBody(AbstractLiePoissonSystem, AbstractDefinedByParams):
    r"""The free rigid body in $N$ dimensions (Manakov 1976; Ratiu 1980): on so(N)* with the
    body angular velocity $\Omega \in$ so(N) and momentum $M = J\Omega + \Omega J$,
    $J = \mathrm{diag}(J_1, \dots, J_N)$ the mass matrix,

    $$\dot M = [M, \Omega], \qquad H = \tfrac12\langle M, \Omega\rangle
    = \sum_{i<j} \frac{M_{ij}^2}{2(J_i + J_j)}.$$

    The state is $\mu_a = M_{ij}$, $i < j$ (`liepoisson.so(N)`); the Casimirs are
    $\tfrac12(-1)^k\mathrm{tr}\,M^{2k}$, $k < N/2$, and for even $N$ the Pfaffian
    $\mathrm{Pf}(M)$ (`liepoisson.so`). For $N = 3$ it is Euler's rigid body with principal
    moments $I_1 = J_2 + J_3$, $I_2 = J_1 + J_3$, $I_3 = J_1 + J_2$ (`RigidBody`, whose
    coordinates are $(\Pi_1, \Pi_2, \Pi_3) = (-M_{23}, M_{13}, -M_{12})$).

    **Arguments:** `J`, the $N \ge 3$ positive diagonal entries of the mass matrix.
    """

    name = "GeneralizedRigidBody"

    def __init__(self, J=(1.0, 1.3, 1.9, 2.6)):
        if isinstance(J, (str, bytes)) or np.ndim(J) != 1 or np.size(J) < 3:
            raise ValueError(f"J must hold N >= 3 positive numbers (the diagonal mass matrix of so(N)); got {J!r}")
        N = int(np.size(J))
        self.J = positive_vector(J, "J", N)
        self.algebra = so(N)
        self._pairs = [(i, j) for i in range(N) for j in range(i + 1, N)]
        self.inertia = np.array([self.J[i] + self.J[j] for i, j in self._pairs])
        self._denominator = self.J[:, None] + self.J[None, :]

    @property
    def N(self) -> int:
        return self.algebra.N

    @property
    def params(self):
        return {"J": self.J.tolist()}

    def hamiltonian_components(self, y, xp):
        return sum(0.5 * y[a] * y[a] / float(I) for a, I in enumerate(self.inertia))

    def hamiltonian_splitting(self):
        r"""$H = \sum_{i<j} M_{ij}^2/(2(J_i + J_j))$: each piece turns $M$ in the plane
        $(i, j)$ (the conjugation by a rotation in that plane)."""
        return tuple(_axis_term(a, 1.0 / self.inertia[a], self.dim, f"T{i + 1}{j + 1}")
                     for a, (i, j) in enumerate(self._pairs))

    def angular_velocity(self, M: jax.Array) -> jax.Array:
        r"""$\Omega_{ij} = M_{ij}/(J_i + J_j)$, solving $J\Omega + \Omega J = M$ (matrices)."""
        return M / jnp.asarray(self._denominator)

    def velocity_matrix(self, M: jax.Array) -> jax.Array:
        r"""$B(M) = -\Omega$: $\dot M = [M, \Omega] = [B, M]$ (the isospectral integrators)."""
        return -self.angular_velocity(M)
