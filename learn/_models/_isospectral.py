r"""A learned isospectral map for Lie-Poisson systems on compact matrix algebras (Zeitlin's
model, the generalized rigid body): the isospectral midpoint step of a learned Hamiltonian
built from the system's own linear velocity operator."""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from integrators import IsospectralMidpoint
from integrators.internals import (
    ISOSPECTRAL_MAX_ITER,
    ISOSPECTRAL_TOL,
    check_h,
    check_isospectral,
    check_stage_tolerance,
)
from liepoisson.internals import positive_float, positive_int
from liepoisson.systems import AbstractLiePoissonSystem

from .._solvers._levenberg_marquardt import LevenbergMarquardt
from .._solvers._stage import KeepIfBetter
from ._base import AbstractCasimirConservingMap


def check_linear_velocity(system: AbstractLiePoissonSystem, what: str = "system") -> None:
    r"""`ValueError` unless `system.velocity_matrix` is linear in $W$ (a quadratic Hamiltonian),
    checked on two random matrices of its algebra."""
    algebra = system.algebra
    rng = np.random.default_rng(0)
    a, b = (algebra.matrix(jnp.asarray(rng.normal(size=system.dim))) for _ in range(2))
    S = system.velocity_matrix
    Sa, Sb, lhs = S(a), S(b), S(0.3 * a - 1.7 * b)
    if not all(bool(jnp.all(jnp.isfinite(x))) for x in (Sa, Sb, lhs)):
        raise ValueError(f"{what}: velocity_matrix returned non-finite values on random states; got {system!r}")
    rhs = 0.3 * Sa - 1.7 * Sb
    scale = float(jnp.max(jnp.abs(rhs)) + jnp.max(jnp.abs(Sa)) + jnp.max(jnp.abs(Sb)))
    # A linear operator in floating point agrees to round-off, which grows with the size of
    # the solves inside (Zeitlin's tridiagonal Poisson solve; BENCHMARKS.md, "W5"): 64 sqrt(dim)
    # eps of the scale, still far below the O(1) defect of a non-quadratic Hamiltonian.
    tol = 64 * np.sqrt(system.dim) * np.finfo(np.float64).eps * max(scale, np.finfo(np.float64).tiny)
    if not float(jnp.max(jnp.abs(lhs - rhs))) <= tol:
        raise ValueError(
            f"{what} must have a quadratic Hamiltonian (a velocity_matrix linear in W), as Zeitlin's model and "
            f"the generalized rigid body have: IsospectralPolynomial learns a polynomial of that linear operator; "
            f"got {system!r}, whose velocity_matrix is not linear"
        )


#: The degree when neither `degree` nor `theta` is given.
DEFAULT_DEGREE = 3


class IsospectralPolynomial(IsospectralMidpoint, AbstractCasimirConservingMap):
    r"""The isospectral midpoint step (`integrators.IsospectralMidpoint`) of a learned
    quadratic Hamiltonian: with $S$ the system's linear velocity operator ($\dot W = [S(W), W]$,
    $S = \Delta_N^{-1}/\hbar$ for Zeitlin's model), the step solves $\dot W = [B_\theta(W), W]$,

    $$B_\theta(W) = \sum_{k=1}^{K}\theta_k\,S^k(W),$$

    a polynomial of $S$ with learned coefficients $\theta$ (`degree` $K$). $S$ is self-adjoint
    for the pairing, so $B_\theta$ is the gradient of $H_\theta(W) = \tfrac12\sum_k\theta_k
    \langle W, S^k W\rangle$ (up to the pairing's sign and normalisation): every step is the isospectral midpoint
    of that Hamiltonian, a conjugation by the unitary Cayley transform of
    $\tfrac h2 B_\theta(\widetilde W)$. Casimirs ($\mathrm{tr}\,W^k$, the spectrum) are kept to
    round-off whatever $\theta$: like an LPNet's, each step moves on the coadjoint orbit, but
    by the implicit midpoint of a learned Hamiltonian, not by composed exact flows. Degree 1 is
    a rescaling of time: $\theta = (c)$ at step $h$ is the classical method at step $ch$. For
    Zeitlin's model $B_\theta$ is diagonal in
    the quantized spherical harmonics, the function $\sum_k\theta_k(-1/(\hbar\,l(l+1)))^k$ of
    the degree $l$: the data can correct the midpoint's phase error degree by degree. $\theta =
    (1, 0, \dots)$ is the classical method.

    **Arguments:** `system` (so(N), u(N), su(N), body convention, quadratic Hamiltonian);
    `theta` (default $(1, 0, \dots, 0)$ of length `degree`, default `DEFAULT_DEGREE`; given,
    its length is the degree); `h`; `tol`, `iterations`,
    `max_iter` as `IsospectralMidpoint` (default: iterate until `tol`). Fit by
    `learn.fit(model, (y0, y1), h=...)` on pairs with its default optimiser,
    Levenberg-Marquardt, whose forward-mode Jacobian passes through the iteration's while loop;
    a reverse-mode optimiser (Adam, ScipyBFGS) needs `iterations=k` (straight-line steps).
    """

    theta: jax.Array
    degree: int = eqx.field(static=True)

    def __init__(self, system: AbstractLiePoissonSystem, *, degree: int | None = None, theta: ArrayLike | None = None,
                 h: float | None = None, tol: float = ISOSPECTRAL_TOL, iterations: int | None = None,
                 max_iter: int = ISOSPECTRAL_MAX_ITER, key: Any = None):
        self.system = check_isospectral(system)
        check_linear_velocity(system)
        if theta is None:
            degree = DEFAULT_DEGREE if degree is None else positive_int(degree, "degree")
            theta = np.zeros(degree)
            theta[0] = 1.0
        theta = np.asarray(theta, dtype=np.float64)
        if theta.ndim != 1 or theta.size == 0 or not np.all(np.isfinite(theta)):
            raise ValueError(f"theta must be a non-empty finite 1-D array (theta_1..theta_K); got {theta!r}")
        if degree is not None and positive_int(degree, "degree") != theta.size:
            raise ValueError(f"theta has {theta.size} coefficients but degree={degree}; give one of them, or both "
                             "consistent")
        self.degree = int(theta.size)
        self.theta = jnp.asarray(theta)
        self.h = None if h is None else positive_float(h, "h")
        self.tol = check_stage_tolerance(tol)
        self.iterations = None if iterations is None else positive_int(iterations, "iterations")
        self.max_iter = positive_int(max_iter, "max_iter")

    def velocity_matrix(self, W: jax.Array) -> jax.Array:
        r"""$B_\theta(W) = \sum_k\theta_k S^k(W)$ ($K$ applications of $S$)."""
        S = self.system.velocity_matrix
        # the degree from theta itself (static under jit): a theta of another length swapped in
        # by eqx.tree_at is evaluated as what it is
        inner = self.theta[-1] * W  # Horner: S(theta_1 W + S(theta_2 W + ... S(theta_K W)))
        for k in range(self.theta.shape[0] - 2, -1, -1):
            inner = self.theta[k] * W + S(inner)
        return S(inner)

    def step(self, y: jax.Array) -> jax.Array:
        check_h(self)
        return super().step(y)

    def carry(self, y: jax.Array):
        check_h(self)
        return super().carry(y)

    def hyperparameters(self) -> dict[str, Any]:
        return {"degree": self.degree, "tol": self.tol, "iterations": self.iterations, "max_iter": self.max_iter}

    def reinitialised(self, key: int | jax.Array) -> IsospectralPolynomial:
        """The map itself: theta has no random start (restarts of a fit repeat the same fit)."""
        return self

    def default_optimiser(self):
        """Levenberg-Marquardt, 50 steps (a few coefficients; forward-mode Jacobian)."""
        return (KeepIfBetter(LevenbergMarquardt(50)),)
