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

from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from liepoisson import MatrixLieAlgebra
from liepoisson.internals import dagger, positive_float, positive_int
from liepoisson.systems import AbstractLiePoissonSystem

from ._lapack import serial_lapack
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
    """`system` if it lives on a compact matrix algebra (so, u, su) in the body convention
    (and JAX's LAPACK made serial: `serial_lapack`)."""
    serial_lapack()
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


class IsospectralMidpoint(AbstractStepMap):
    r"""The isospectral midpoint method (module docstring): order 2, symmetric, a Lie-Poisson
    integrator for $\dot W = [B(W), W]$ (Modin & Viviani 2020) that keeps the spectrum of $W$
    to round-off.

    **Arguments:**

    - `system`, a Lie-Poisson system on so(N), u(N) or su(N); `h` > 0.
    - `tol` (default `DEFAULT_TOL`): the fixed-point iteration stops when an iteration moves
      the stage by at most `tol` times max|W|.
    - `iterations` (default `None`): `None` iterates until `tol` is met (at most `max_iter`
      iterations), the robust choice; an integer $k$ makes every step of a rollout do exactly
      $k$ iterations from its extrapolated start (straight-line code, which reverse-mode
      differentiation needs), and a step whose last iteration still moved more than `tol` is
      NaN (a rollout then says so and suggests more); `iterations_needed(y0)` says what a run
      needs, but a later step may need more.
    - `max_iter` (default `DEFAULT_MAX_ITER`): the cap of the iterations to `tol`.

    A rollout carries $W$ and the last three stage increments of each substep; its first step
    starts from a history found by three steps backwards (the method is symmetric: a step back
    shares its stage with the step forward it undoes), so every step starts from the quadratic
    extrapolation of the last three. `step(y)` alone starts cold and iterates to `tol`.
    """

    system: AbstractLiePoissonSystem = eqx.field(static=True)
    h: float
    tol: float = eqx.field(static=True)
    iterations: int | None = eqx.field(static=True)
    max_iter: int = eqx.field(static=True)
    substeps: ClassVar[tuple[float, ...]] = (1.0,)

    def __init__(self, system: AbstractLiePoissonSystem, h: float, *, tol: float = DEFAULT_TOL,
                 iterations: int | None = None, max_iter: int = DEFAULT_MAX_ITER):
        self.system = check_isospectral(system)
        self.h = positive_float(h, "h")
        self.tol = positive_float(tol, "tol")
        self.iterations = None if iterations is None else positive_int(iterations, "iterations")
        self.max_iter = positive_int(max_iter, "max_iter")

    @property
    def exact_flows_per_step(self) -> int:
        return 0

    @property
    def divergence_hint(self) -> str:
        if self.iterations is None:
            return (f"The fixed-point iteration did not meet tol={self.tol:g} within max_iter={self.max_iter} "
                    "iterations (a step too large for it to contract), or the state left the finite range: "
                    "try a smaller h")
        return (f"A step's fixed-point iteration did not meet tol={self.tol:g} in iterations={self.iterations} "
                f"(a step that has not converged is NaN): use more, e.g. IsospectralMidpoint(..., "
                f"iterations={self.iterations + 1}), or iterations=None to iterate until tol is met")

    def velocity_matrix(self, W: jax.Array) -> jax.Array:
        r"""$B(W)$ of $\dot W = [B(W), W]$ for `W` `(m, m)`: the system's
        (`system.velocity_matrix`); a learned map on this step overrides it."""
        return self.system.velocity_matrix(W)

    def _iterate(self, W, h, Wt):
        r"""One fixed-point iteration of the stage equation: `(new stage, B at Wt, moved)`."""
        B = self.velocity_matrix(Wt)
        X = B @ Wt  # [B, Wt] = X - X^dagger, B Wt B = X B (skew-Hermitian factors)
        Wn = W + 0.5 * h * (X - dagger(X)) + 0.25 * h * h * (X @ B)
        return Wn, B, jnp.max(jnp.abs(Wn - Wt))

    def _midpoint(self, W: jax.Array, h: jax.Array | float, D: jax.Array, iterations: int | None
                  ) -> tuple[jax.Array, jax.Array, jax.Array]:
        r"""One isospectral midpoint step of size `h` from `W`, the stage $\tilde W$ sought
        from $W + D$ by `iterations` iterations (None: until `tol`): returns the new state (NaN
        if the stage has not converged), the stage's increment $\tilde W - W$ and the
        iteration count."""
        scale = self.tol * jnp.maximum(jnp.max(jnp.abs(W)), jnp.finfo(jnp.float64).tiny)
        if iterations is None:

            def body(state):
                Wt, _, _, k = state
                return (*self._iterate(W, h, Wt), k + 1)

            Wt, B, moved, k = jax.lax.while_loop(
                lambda state: (state[2] > scale) & (state[3] < self.max_iter), body,
                (W + D, jnp.zeros_like(W), jnp.asarray(jnp.inf), jnp.asarray(0)))
        else:  # straight-line code: no control flow in the step
            Wt = W + D
            for _ in range(iterations):
                Wt, B, moved = self._iterate(W, h, Wt)
            k = jnp.asarray(iterations)
        # B is from the last iteration, at the iterate before the last (as quflow does):
        # converged to the tolerance, and one evaluation of B a step cheaper.
        B = 0.5 * h * B
        eye = jnp.eye(W.shape[-1], dtype=W.dtype)
        Q = jnp.linalg.solve(eye - B, eye + B)  # the Cayley transform: unitary (orthogonal)
        W1 = Q @ W @ dagger(Q)
        W1 = 0.5 * (W1 - dagger(W1))  # back onto the algebra (exact halving): no drift off it
        return jnp.where(moved <= scale, W1, jnp.nan), Wt - W, k

    def step_matrix(self, W: jax.Array) -> jax.Array:
        """One step on the matrix $W$ `(m, m)` of the state, the stage started at $W$ and
        iterated until `tol` (or `iterations` times, when set)."""
        for c in self.substeps:
            W, _, _ = self._midpoint(W, c * self.h, jnp.zeros_like(W), self.iterations)
        return W

    def step(self, y: jax.Array) -> jax.Array:
        algebra = self.system.algebra
        return algebra.coordinates(self.step_matrix(algebra.matrix(check_state(y, self.system.dim))))

    # A rollout carries W itself, and each substep's last three stage increments: the next
    # step's iteration starts from their quadratic extrapolation, O(h^4) from the solution
    # (quflow starts from the last increment, O(h^2)), which saves iterations (BENCHMARKS.md,
    # "Zeitlin's model"). Converting W to coordinates and back every step
    # would cost a rounding per step (u(N)'s basis has entries 1/sqrt(2)) and bias the Casimirs.
    def carry(self, y: jax.Array) -> tuple[jax.Array, tuple[Any, ...]]:
        W = self.system.algebra.matrix(check_state(y, self.system.dim))
        # Three steps back, each substep undoing one forward substep (in reverse order): the
        # stage it finds is that forward substep's, whose increment starts from the state it
        # lands on. One traced substep, scanned over the 3 x len(substeps) of them.
        S = len(self.substeps)
        coefficients = jnp.asarray([-self.substeps[index] for _ in range(3) for index in reversed(range(S))])

        def back(Wb, coefficient):
            Wn, D, _ = self._midpoint(Wb, coefficient * self.h, jnp.zeros_like(Wb), None)
            return Wn, Wb + D - Wn

        # The history is only where the iteration starts: no derivative flows through it (so a
        # rollout with a fixed `iterations` is reverse-differentiable: no while loop carries one).
        _, increments = jax.lax.scan(back, jax.lax.stop_gradient(W), coefficients)
        found = [[increments[step * S + (S - 1 - index)] for step in range(3)] for index in range(S)]
        return W, tuple(tuple(history) for history in found)

    def step_carry(self, c: tuple[jax.Array, tuple[Any, ...]]) -> tuple[jax.Array, tuple[Any, ...]]:
        return self._step_warm(c, self.iterations)[0]

    def _step_warm(self, c, iterations):
        W, histories = c
        updated, total = [], jnp.asarray(0)
        for coefficient, (D1, D2, D3) in zip(self.substeps, histories):
            W, D, k = self._midpoint(W, coefficient * self.h, 3.0 * (D1 - D2) + D3, iterations)
            updated.append((D, D1, D2))
            total = total + k
        return (W, tuple(updated)), total

    def uncarry(self, c: tuple[jax.Array, tuple[Any, ...]]) -> jax.Array:
        return self.system.algebra.coordinates(c[0])

    def iterations_needed(self, y: ArrayLike, n_steps: int = 20) -> tuple[float, int]:
        """`(mean, max)` of the fixed-point iterations (summed over substeps) that the steps
        of a rollout from `y` need to meet `tol`, over `n_steps` steps: choose `iterations=`
        from the max (and more for a flow that stiffens)."""
        n_steps = positive_int(n_steps, "n_steps")
        counts = np.asarray(_count_iterations(self, self.carry(jnp.asarray(y, jnp.float64)), n_steps))
        return float(counts.mean()), int(counts.max())


@eqx.filter_jit
def _count_iterations(method: IsospectralMidpoint, c: Any, n_steps: int) -> jax.Array:
    def body(c, _):
        c, k = method._step_warm(c, None)
        return c, k

    _, counts = jax.lax.scan(body, c, None, length=n_steps)
    return counts


class IsospectralTripleJump(IsospectralMidpoint):
    r"""Yoshida's triple jump of the isospectral midpoint: substeps $\gamma_1 h, \gamma_0 h,
    \gamma_1 h$, $\gamma_1 = 1/(2 - 2^{1/3})$, $\gamma_0 = 1 - 2\gamma_1$: order 4, symmetric,
    isospectral (each substep is a unitary conjugation). The composition of Modin & Viviani's
    isospectral methods of higher order (FoCM 2020, Sec. 5)."""

    substeps: ClassVar[tuple[float, ...]] = (_G1, _G0, _G1)


ISOSPECTRAL_METHODS = {"IsospectralMidpoint": IsospectralMidpoint, "IsospectralTripleJump": IsospectralTripleJump}
