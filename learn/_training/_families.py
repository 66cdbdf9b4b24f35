r"""The families of learned Hamiltonians `learn.fit_splitting` chooses from on observations, and
where each starts.

A family is a set of `RidgeTerms`, one module per basis direction: $\widetilde H =
\sum_s\Phi_s(\langle\alpha_s, y\rangle)$ with $\Phi_s' = a_s x$ (quadratic, even), $+ b_s$
(quadratic: linear terms of $\widetilde H$ too) or $a_s\sigma(x) + e_s x + b_s$ (general),
and $\alpha_s = c_se_s$ on the basis axes or $\alpha_s\in\mathbb R^n$ learned ("any axes").
A quadratic form in any axes is $\tfrac12 y^TAy = \sum_k\lambda_k\langle v_k, y\rangle^2/2$
over its eigenvectors, so $n$ modules along learned directions hold every symmetric $A$ (and,
with $b_s$, every linear term $\sum_s b_s\alpha_s$); each module is still solved exactly.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from integrators import Observations
from liepoisson.systems import AbstractPoissonSystem

from .._models._learned_terms import RidgeTerms


@dataclasses.dataclass(frozen=True)
class Family:
    r"""A family of learned Hamiltonians: `RidgeTerms` settings (`activation`, `linear_term`,
    `bias`) on the basis axes or, with `any_axes`, along learned directions."""

    name: str
    activation: str
    linear_term: bool
    bias: bool
    any_axes: bool = False

    @property
    def warm_start(self) -> bool:
        """Whether the fit starts from the same pieces with the identity activation."""
        return self.activation != "identity"

    def start(self, system: AbstractPoissonSystem, data: Observations, size: float) -> RidgeTerms:
        r"""The starting pieces: the family's quadratic $\tfrac12y^TAy + b^Ty$ fitted to the
        observations' finite differences (`quadratic_estimate`; $A$ diagonal on the axes, $b = 0$
        without `bias`), split along the eigenvectors $v_k$ of $A$ (the axes $e_k$ on the axes):
        $\alpha_k = v_k/s$, $a_k = \lambda_ks^2$, $b_k = s\,v_k^Tb$ with $s$ = `size`, the
        states' scale, so that the pieces' inputs $\langle\alpha_k, y\rangle$ are of order one.
        The general family starts from this quadratic with its sigmoids at zero (its warm start).
        The estimate is covariant: the same start in any units of time and state."""
        A, b = quadratic_estimate(system, data, linear=self.bias, diagonal=not self.any_axes)
        if self.any_axes:
            values, vectors = np.linalg.eigh(A)
        else:
            values, vectors = np.diag(A).copy(), np.eye(system.dim)
        terms = RidgeTerms(system.dim, system.dim, activation=self.activation, full_vectors=self.any_axes,
                           linear_term=self.linear_term, bias=self.bias)
        c = vectors.T / size if self.any_axes else np.full(system.dim, 1.0 / size)
        terms = eqx.tree_at(lambda t: (t.a, t.c), terms, (jnp.asarray(values * size**2), jnp.asarray(c)))
        if self.bias:
            terms = eqx.tree_at(lambda t: t.b, terms, jnp.asarray(size * (vectors.T @ b)))
        return terms


def quadratic_estimate(system: AbstractPoissonSystem, data: Observations, linear: bool = True,
                       diagonal: bool = False) -> tuple[np.ndarray, np.ndarray]:
    r"""`(A, b)`: the least-squares $\nabla H = Ay + b$ ($A$ symmetric, or diagonal with
    `diagonal`; $b = 0$ unless `linear`) of the observations' finite differences,
    $(y_1 - y_0)/\Delta t \approx \mathbb B(\bar y)(A\bar y + b)$ at the midpoints $\bar y$ of
    consecutive observations: linear in $(A, b)$. The motion does not see $\nabla H$ along the
    Casimirs' gradients; the minimum-norm solution leaves them out."""
    y0, y1, dt = data.intervals()
    mid = 0.5 * (y0 + y1)
    velocity = ((y1 - y0) / dt[:, None]).reshape(-1)
    B = np.asarray(system.poisson_tensor(mid))  # (N, n, n)
    n = system.dim
    i, j = np.diag_indices(n) if diagonal else np.triu_indices(n)
    # d/dA_ij of B(y) A y: B(y) (E_ij + E_ji) y (E_ii once)
    columns = []
    for a, c in zip(i, j, strict=True):
        e = np.zeros((n, n))
        e[a, c] = e[c, a] = 1.0
        columns.append(np.einsum("kpq,qr,kr->kp", B, e, mid).reshape(-1))
    if linear:
        columns.extend(B[:, :, q].reshape(-1) for q in range(n))
    design = np.stack(columns, axis=1)
    coefficients, *_ = np.linalg.lstsq(design, velocity, rcond=None)
    A = np.zeros((n, n))
    A[i, j] = A[j, i] = coefficients[: i.size]
    b = coefficients[i.size :] if linear else np.zeros(n)
    return A, b


#: The nested families `fit_splitting` fits on observations, simplest first (the BIC breaks a
#: tie in favour of the earlier).
FAMILIES = (
    Family("quadratic, even", "identity", linear_term=False, bias=False),
    Family("quadratic", "identity", linear_term=False, bias=True),
    Family("quadratic, any axes, even", "identity", linear_term=False, bias=False, any_axes=True),
    Family("quadratic, any axes", "identity", linear_term=False, bias=True, any_axes=True),
    Family("general", "sigmoid", linear_term=True, bias=True),
    Family("general, any axes", "sigmoid", linear_term=True, bias=True, any_axes=True),
)
