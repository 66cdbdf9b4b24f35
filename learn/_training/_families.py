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
from ._criterion import bic, effective_parameters


@dataclasses.dataclass(frozen=True)
class Family:
    r"""A family of learned Hamiltonians: `RidgeTerms` settings (`activation`, `linear_term`,
    `bias`) on the basis axes or, with `any_axes`, along learned directions."""

    name: str
    activation: str
    linear_term: bool
    bias: bool
    any_axes: bool = False
    #: Keep only the terms $a_k$, $b_k$ that the criterion selects on the finite differences
    #: (`select_quadratic`); on the basis axes, identity activation.
    select: bool = False
    #: The quadratic family this one extends (its pieces plus sigmoids): when it was fitted
    #: first, this family starts from its fit (`from_nested`), not from a warm start of its own.
    nested: str | None = None

    def from_nested(self, terms: RidgeTerms, fitted: RidgeTerms) -> RidgeTerms:
        r"""`terms` (this family's pieces) at the fitted quadratic pieces of the family it
        extends: $e_s = a_s$ (the quadratic as the linear term of $\Phi_s'$), $c_s$, $b_s$ as
        fitted, $a_s = 0$ (the sigmoids start from zero): the same $\widetilde H$, so the fit
        starts where the nested family's ended."""
        terms = eqx.tree_at(lambda t: (t.a, t.c, t.e), terms,
                            (jnp.zeros_like(fitted.a), fitted.c, fitted.a_values()))
        return terms if fitted.b is None else eqx.tree_at(lambda t: t.b, terms, fitted.bias_values())

    def contains(self, other: Family) -> bool:
        r"""Whether every member of `other` (another family) is one of this family's: this
        family's pieces are along learned directions if `other`'s are, it has linear terms
        $b_s$ if `other` has, and its $\Phi_s'$ holds `other`'s (the same activation with a
        linear term $e_sx$ if `other` has one, or a quadratic $\Phi_s$ inside a general one with
        $a_s = 0$). A family of selected terms is contained in those holding all of its terms,
        and contains none."""
        if other == self or self.select:
            return False
        if self.activation == other.activation:
            holds = self.activation == "identity" or self.linear_term or not other.linear_term
        else:
            holds = other.activation == "identity" and self.linear_term
        return holds and (self.any_axes or not other.any_axes) and (self.bias or not other.bias)

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
        kept: dict = {}
        if self.select:
            A, b, a_kept, b_kept = select_quadratic(system, data)
            kept = {"a_kept": a_kept, "b_kept": b_kept}
        else:
            A, b = quadratic_estimate(system, data, linear=self.bias, diagonal=not self.any_axes)
        return self.terms_of(system, A, b, size, **kept)

    def terms_of(self, system: AbstractPoissonSystem, A: np.ndarray, b: np.ndarray, size: float,
                 **kept: tuple[bool, ...]) -> RidgeTerms:
        r"""This family's pieces holding $\tfrac12y^\top Ay + b^\top y$ (`start`'s split along
        the eigenvectors of $A$, or the axes), inputs scaled by `size`."""
        if self.any_axes:
            values, vectors = np.linalg.eigh(A)
        else:
            values, vectors = np.diag(A).copy(), np.eye(system.dim)
        terms = RidgeTerms(system.dim, system.dim, activation=self.activation, full_vectors=self.any_axes,
                           linear_term=self.linear_term, bias=self.bias, **kept)
        c = vectors.T / size if self.any_axes else np.full(system.dim, 1.0 / size)
        terms = eqx.tree_at(lambda t: (t.a, t.c), terms, (jnp.asarray(values * size**2), jnp.asarray(c)))
        if self.bias:
            terms = eqx.tree_at(lambda t: t.b, terms, jnp.asarray(size * (vectors.T @ b)))
        return terms


def _design(system: AbstractPoissonSystem, data: Observations, linear: bool, diagonal: bool):
    """`(design, velocity, (i, j))` of the least-squares problem of `quadratic_estimate`."""
    y0, y1, dt = data.pairs()
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
    return np.stack(columns, axis=1), velocity, (i, j)


def _criterion(design: np.ndarray, velocity: np.ndarray) -> tuple[float, np.ndarray]:
    r"""`(bic, coefficients)` of the least squares `design @ x = velocity`: $n\log(\mathrm{SSR}/n)
    + k\log n$, $k$ the numerical rank of the design (unit-norm columns)."""
    tiny = np.finfo(float).tiny  # exact data (every velocity 0): no log of 0
    if design.shape[1] == 0:
        return bic(max(float(velocity @ velocity), tiny), velocity.size, 0), np.zeros(0)
    coefficients, *_ = np.linalg.lstsq(design, velocity, rcond=None)
    residual = velocity - design @ coefficients
    ssr = max(float(residual @ residual), tiny)
    return bic(ssr, velocity.size, effective_parameters(design)), coefficients


#: Backward elimination drops a term while the criterion rises by less than this (a term whose
#: column is a combination of the others, e.g. along a Casimir, changes nothing: dropped).
SELECT_RESOLUTION = 0.1


def select_quadratic(system: AbstractPoissonSystem, data: Observations
                     ) -> tuple[np.ndarray, np.ndarray, tuple[bool, ...], tuple[bool, ...]]:
    r"""`(A, b, a_kept, b_kept)`: the diagonal quadratic $\tfrac12\sum_k a_ky_k^2 + b_ky_k$ of
    `quadratic_estimate` with only the terms the data need, by backward elimination on its
    least squares: starting from all $2n$ terms, drop the term whose removal lowers the
    Bayesian information criterion of the finite differences most (or raises it by less than
    `SELECT_RESOLUTION`: a term the others make redundant, e.g. one of the $a_k$ of a Casimir
    $\sum_ky_k^2$), until every removal raises it. A term the data do not determine costs
    accuracy (conventions, [Observations][conventions-observations]): e.g. the heavy top's
    $\tfrac12\sum\Pi_k^2/I_k + mgl\,\Gamma_3$ keeps four of its twelve terms."""
    design, velocity, _ = _design(system, data, linear=True, diagonal=True)
    n = system.dim
    kept = list(range(2 * n))
    lowest, _ = _criterion(design, velocity)
    while kept:
        trials = [(_criterion(design[:, [c for c in kept if c != d]], velocity)[0], d) for d in kept]
        best, drop = min(trials)
        if best >= lowest + SELECT_RESOLUTION:
            break
        kept.remove(drop)
        lowest = min(lowest, best)
    _, coefficients = _criterion(design[:, kept], velocity)
    full = np.zeros(2 * n)
    full[kept] = coefficients
    mask = np.isin(np.arange(2 * n), kept)
    return np.diag(full[:n]), full[n:], tuple(bool(k) for k in mask[:n]), tuple(bool(k) for k in mask[n:])


def quadratic_estimate(system: AbstractPoissonSystem, data: Observations, linear: bool = True,
                       diagonal: bool = False) -> tuple[np.ndarray, np.ndarray]:
    r"""`(A, b)`: the least-squares $\nabla H = Ay + b$ ($A$ symmetric, or diagonal with
    `diagonal`; $b = 0$ unless `linear`) of the observations' finite differences,
    $(y_1 - y_0)/\Delta t \approx \mathbb B(\bar y)(A\bar y + b)$ at the midpoints $\bar y$ of
    consecutive observations: linear in $(A, b)$. The motion does not see $\nabla H$ along the
    Casimirs' gradients; the minimum-norm solution leaves them out."""
    n = system.dim
    design, velocity, (i, j) = _design(system, data, linear, diagonal)
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
    Family("quadratic, selected", "identity", linear_term=False, bias=True, select=True),
    Family("quadratic, any axes, even", "identity", linear_term=False, bias=False, any_axes=True),
    Family("quadratic, any axes", "identity", linear_term=False, bias=True, any_axes=True),
    Family("general", "sigmoid", linear_term=True, bias=True, nested="quadratic"),
    Family("general, any axes", "sigmoid", linear_term=True, bias=True, any_axes=True, nested="quadratic, any axes"),
)
