"""The systems the studies share (W2's bodies are W4's satellite and vehicle), each built as a
user would, and the draws of their initial conditions: no study imports another's private
names."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax.numpy as jnp
import numpy as np
from scipy.spatial.transform import Rotation

import liepoisson as lp


def diamond() -> lp.systems.LiePoissonSystem:
    """A body on the 4-dimensional solvable "diamond" algebra: [p, q] = z, [n, p] = p,
    [n, q] = -q, z central; Casimirs z and pq + zn; H = (p^2 + q^2 + n^2)/2 + 0.1 exp(-z^2),
    bounded motion on the orbits with z != 0. Built from structure constants, as a user would."""
    C = np.zeros((4, 4, 4))
    for a, b, d, v in ((0, 1, 2, 1.0), (3, 0, 0, 1.0), (3, 1, 1, -1.0)):
        C[a, b, d], C[b, a, d] = v, -v
    g = lp.LieAlgebra(C, "diamond", ("p", "q", "z", "n"))
    return lp.systems.LiePoissonSystem(
        g, lambda m, xp: 0.5 * (m[0] ** 2 + m[1] ** 2 + m[3] ** 2) + 0.1 * xp.exp(-(m[2] ** 2)), name="diamond"
    )


def sphere(n: int, rng: np.random.Generator) -> np.ndarray:
    y = rng.normal(size=(n, 3))
    return y / np.linalg.norm(y, axis=1, keepdims=True)


def cube(dim: int) -> Callable[[int, np.random.Generator], np.ndarray]:
    return lambda n, rng: rng.uniform(-1.0, 1.0, size=(n, dim))


def symmetric(theta, n: int):
    """The symmetric matrix whose upper triangle (row-major) is `theta`."""
    upper = jnp.zeros((n, n)).at[jnp.triu_indices(n)].set(theta)
    return upper + upper.T - jnp.diag(jnp.diag(upper))


def quadratic_form(n: int) -> Callable[[Any, Any], Any]:
    r"""$\tfrac12 y^TAy$ with the upper triangle of $A$ unknown: a quadratic in any axes."""
    return lambda y, theta: 0.5 * y @ symmetric(theta, n) @ y


#: The rotated rigid body: I = (2, 1, 2/3) with its principal axes turned by this rotation
#: vector (0.95 rad) from the sensor axes.
ROTATION = (0.4, -0.7, 0.5)


def quadratic_body(algebra: lp.LieAlgebra, A: np.ndarray, name: str) -> lp.systems.LiePoissonSystem:
    r"""The Lie-Poisson system of $H = \tfrac12 y^TAy$ on `algebra`, written as a user would."""
    A = np.asarray(A, dtype=np.float64)
    n = A.shape[0]
    return lp.systems.LiePoissonSystem(
        algebra, lambda m, xp: 0.5 * sum(float(A[i, j]) * m[i] * m[j] for i in range(n) for j in range(n)), name=name)


def rotated_inverse_inertia() -> np.ndarray:
    r"""$R\,\mathrm{diag}(1/I)\,R^T$: the rigid body's inverse inertia in sensor axes."""
    R = Rotation.from_rotvec(ROTATION).as_matrix()
    return R @ np.diag([0.5, 1.0, 1.5]) @ R.T


def coupled_kirchhoff_matrix() -> np.ndarray:
    r"""Kirchhoff's body with an added-mass matrix coupling rotation and translation: the
    generalised mass $\begin{pmatrix}\mathbb I & C\\ C^T & \mathbb M\end{pmatrix}$ with
    $\mathbb I = \mathbb M = \mathrm{diag}(1, 2, 1)$ and
    $C = \begin{pmatrix}0 & 0.3 & 0\\ 0.2 & 0 & 0\\ 0 & 0 & 0.25\end{pmatrix}$; $H$ is half the
    momenta against its inverse."""
    mass = np.zeros((6, 6))
    mass[:3, :3] = mass[3:, 3:] = np.diag([1.0, 2.0, 1.0])
    mass[:3, 3:] = [[0.0, 0.3, 0.0], [0.2, 0.0, 0.0], [0.0, 0.0, 0.25]]
    mass[3:, :3] = mass[:3, 3:].T
    return np.linalg.inv(mass)


#: The non-polynomial rigid body: H = sum Pi_i^2 / (2 I_i) + KAPPA log(1 + (V . Pi)^2).
KAPPA, V = 0.2, (0.6, 0.0, 0.8)


def logarithmic_body() -> lp.systems.LiePoissonSystem:
    """A rigid body I = (2, 1, 2/3) with the energy term `KAPPA log(1 + (V . Pi)^2)`, outside
    every polynomial library."""
    v = [float(c) for c in V]

    def hamiltonian(m, xp):
        along = v[0] * m[0] + v[1] * m[1] + v[2] * m[2]
        return 0.25 * m[0] ** 2 + 0.5 * m[1] ** 2 + 0.75 * m[2] ** 2 + KAPPA * xp.log(1.0 + along * along)

    return lp.systems.LiePoissonSystem(lp.so3(), hamiltonian, name="logarithmic rigid body")
