r"""Isospectral integrators for Lie-Poisson systems on compact matrix algebras (so(N), u(N),
su(N)): every step is a conjugation $W_{n+1} = Q\,W_n\,Q^\dagger$ by a unitary (orthogonal)
$Q$, so the whole spectrum of $W$, hence every Casimir $\mathrm{tr}\,W^k$, is kept to round-off
whatever the accuracy of the stage equation.

The isospectral midpoint method (Viviani & Modin, *A Casimir preserving scheme for long-time
simulation of spherical ideal hydrodynamics*, JFM 2020; Modin & Viviani, *Lie-Poisson methods
for isospectral flows*, FoCM 2020) for $\dot W = [B(W), W]$, $B(W)^\dagger = -B(W)$:

$$W_n = (1 - \tfrac h2\tilde B)\,\tilde W\,(1 + \tfrac h2\tilde B), \qquad
W_{n+1} = (1 + \tfrac h2\tilde B)\,\tilde W\,(1 - \tfrac h2\tilde B), \qquad \tilde B = B(\tilde W).$$

Eliminating $\tilde W$: $W_{n+1} = Q W_n Q^\dagger$ with the Cayley transform
$Q = (1 - \tfrac h2\tilde B)^{-1}(1 + \tfrac h2\tilde B)$, unitary for any skew-Hermitian
$\tilde B$. The stage equation $\tilde W = W_n + \tfrac h2[\tilde B, \tilde W] +
\tfrac{h^2}4\tilde B\tilde W\tilde B$ is solved by fixed-point iteration; with
$X = \tilde B\tilde W$ (skew-Hermitian factors: $\tilde W\tilde B = X^\dagger$) an iteration
costs two matrix products and one evaluation of $B$. The new state is formed as the
conjugation, not from the stage equation, so the Casimirs do not depend on the iteration's
tolerance (quflow forms it from the stage equation; its Casimirs drift at its tolerance).

For a body system $\dot M = [M, \Xi]$ with $\Xi = \partial H/\partial\mu$ as a matrix
(conventions, matrix algebras), $B = -\Xi$.
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp

from liepoisson import MatrixLieAlgebra
from liepoisson.internals import positive_float, positive_int
from liepoisson.systems import AbstractLiePoissonSystem

from ._lie_group import check_lie_poisson
from ._step_map import AbstractStepMap, check_state

#: The fixed-point iteration stops when an iteration moves the stage by at most `tol` times
#: max|W| (entrywise). 1e-10: the stage's error enters the step's accuracy (energy, state), not
#: its Casimirs; at the step sizes of a Zeitlin run it is below the method's local error.
DEFAULT_TOL = 1e-10
#: Iterations after which a step that has not met the tolerance is NaN (a step too large for
#: the iteration to contract).
DEFAULT_MAX_ITER = 100

# Yoshida's triple jump: a symmetric method of order 2 composed with steps g1 h, g0 h, g1 h
# is of order 4 (Yoshida, Phys. Lett. A 150, 1990).
_G1 = 1.0 / (2.0 - 2.0 ** (1.0 / 3.0))
_G0 = 1.0 - 2.0 * _G1


def check_isospectral(system: AbstractLiePoissonSystem, what: str = "system") -> AbstractLiePoissonSystem:
    """`system` if it lives on a compact matrix algebra (so, u, su) in the body convention."""
    check_lie_poisson(system, what)
    algebra = system.algebra
    if not isinstance(algebra, MatrixLieAlgebra) or algebra.family not in ("so", "u", "su"):
        raise TypeError(
            f"{what} must be a Lie-Poisson system on a compact matrix algebra (liepoisson.so(N), u(N), su(N)): "
            f"the isospectral methods conjugate by unitary matrices; got one on {algebra!r}"
        )
    if algebra.sign != -1:
        raise ValueError(f"{what} must be a body system (sign=-1); got sign={algebra.sign}")
    return system


def velocity_matrix(system: AbstractLiePoissonSystem, W: jax.Array) -> jax.Array:
    r"""$B(W)$ with $\dot W = [B(W), W]$: the system's own `velocity_matrix` when it has one
    (Zeitlin's model: the stream matrix), else $-\Xi$, $\Xi$ the matrix of `generator`."""
    own = getattr(system, "velocity_matrix", None)
    if own is not None:
        return own(W)
    algebra = system.algebra
    return -algebra.matrix(system.generator(algebra.coordinates(W)))


class IsospectralMidpoint(AbstractStepMap):
    r"""The isospectral midpoint method (module docstring): order 2, symmetric, a Lie-Poisson
    integrator for $\dot W = [B(W), W]$ (Modin & Viviani 2020) that keeps the spectrum of $W$
    to round-off.

    **Arguments:** `system`, a Lie-Poisson system on so(N), u(N) or su(N); `h` > 0; `tol`
    (default `DEFAULT_TOL`), the fixed-point iteration's stopping tolerance relative to
    max|W|; `max_iter` (default `DEFAULT_MAX_ITER`): a step still moving after that many
    iterations is NaN.

    `step_matrix(W)` steps a matrix, `iterations(W)` says how many iterations a step took.
    """

    system: AbstractLiePoissonSystem = eqx.field(static=True)
    h: float
    tol: float = eqx.field(static=True)
    max_iter: int = eqx.field(static=True)
    substeps: ClassVar[tuple[float, ...]] = (1.0,)

    def __init__(self, system: AbstractLiePoissonSystem, h: float, *, tol: float = DEFAULT_TOL,
                 max_iter: int = DEFAULT_MAX_ITER):
        self.system = check_isospectral(system)
        self.h = positive_float(h, "h")
        self.tol = positive_float(tol, "tol")
        self.max_iter = positive_int(max_iter, "max_iter")

    @property
    def exact_flows_per_step(self) -> int:
        return 0

    def _midpoint(self, W: jax.Array, h: jax.Array | float) -> tuple[jax.Array, jax.Array]:
        """One isospectral midpoint step of size `h` from `W`, and its iteration count."""
        dagger = (lambda X: jnp.conj(X.T)) if jnp.iscomplexobj(W) else (lambda X: X.T)
        scale = self.tol * jnp.maximum(jnp.max(jnp.abs(W)), jnp.finfo(jnp.float64).tiny)

        def stage(Wt):
            B = velocity_matrix(self.system, Wt)
            X = B @ Wt
            return W + 0.5 * h * (X - dagger(X)) + 0.25 * h * h * (X @ B)

        def cond(state):
            _, moved, k = state
            return (moved > scale) & (k < self.max_iter)

        def body(state):
            Wt, _, k = state
            Wn = stage(Wt)
            return Wn, jnp.max(jnp.abs(Wn - Wt)), k + 1

        Wt, moved, k = jax.lax.while_loop(cond, body, (W, jnp.asarray(jnp.inf), jnp.asarray(0)))
        B = 0.5 * h * velocity_matrix(self.system, Wt)
        eye = jnp.eye(W.shape[-1], dtype=W.dtype)
        Q = jnp.linalg.solve(eye - B, eye + B)  # the Cayley transform: unitary (orthogonal)
        W1 = Q @ W @ dagger(Q)
        W1 = 0.5 * (W1 - dagger(W1))  # back onto the algebra (exact halving): no drift off it
        return jnp.where(moved <= scale, W1, jnp.nan), k

    def step_matrix(self, W: jax.Array) -> jax.Array:
        """One step on the matrix $W$ `(m, m)` of the state."""
        for c in self.substeps:
            W, _ = self._midpoint(W, c * self.h)
        return W

    def step(self, y: jax.Array) -> jax.Array:
        algebra = self.system.algebra
        return algebra.coordinates(self.step_matrix(algebra.matrix(check_state(y, self.system.dim))))

    # A rollout carries W itself: converting to coordinates and back every step would cost
    # a rounding per step (the basis of u(N) has entries 1/sqrt(2)) and bias the Casimirs.
    def carry(self, y: jax.Array) -> jax.Array:
        return self.system.algebra.matrix(check_state(y, self.system.dim))

    def step_carry(self, c: jax.Array) -> jax.Array:
        return self.step_matrix(c)

    def uncarry(self, c: jax.Array) -> jax.Array:
        return self.system.algebra.coordinates(c)

    def iterations(self, y: jax.Array) -> jax.Array:
        """The fixed-point iterations of one step from `y` (summed over substeps)."""
        algebra = self.system.algebra
        W = algebra.matrix(check_state(jnp.asarray(y, jnp.float64), self.system.dim))
        total = jnp.asarray(0)
        for c in self.substeps:
            W, k = self._midpoint(W, c * self.h)
            total = total + k
        return total


class IsospectralTripleJump(IsospectralMidpoint):
    r"""Yoshida's triple jump of the isospectral midpoint: substeps $\gamma_1 h, \gamma_0 h,
    \gamma_1 h$, $\gamma_1 = 1/(2 - 2^{1/3})$, $\gamma_0 = 1 - 2\gamma_1$: order 4, symmetric,
    isospectral (each substep is a unitary conjugation). The composition of Modin & Viviani's
    isospectral methods of higher order (FoCM 2020, Sec. 5)."""

    substeps: ClassVar[tuple[float, ...]] = (_G1, _G0, _G1)


ISOSPECTRAL_METHODS = {"IsospectralMidpoint": IsospectralMidpoint, "IsospectralTripleJump": IsospectralTripleJump}
