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
$\tilde B$. The stage equation, $\tilde W = X W_n X^\dagger$ with
$X = (1 - \tfrac h2\tilde B)^{-1}$, is solved by a quasi-Newton iteration (quflow's
`isomp_quasinewton`): $\tilde B$ from the iterate, then the next iterate $X W_n X^\dagger$ with
$\tilde B$ frozen. Each iteration forms the Cayley conjugation $Q W_n Q^\dagger$ of its
iterate as an increment $Q W_n Q^\dagger - W_n$ (the Cayley transform's increment $Q - 1$ by
block elimination, about one matrix product; two matrix products, in real arithmetic; one
evaluation of $B$) and the next iterate from the same products ($X = (Q + 1)/2$); the step is the conjugation of the iterate the last
iteration started from, accepted when that iteration moved it by at most `tol` in quflow's
norm (the largest row sum, relative to $W_n$'s). The new state is the conjugation, not the
stage equation, so the Casimirs do not depend on the iteration's tolerance (quflow forms it
from the stage equation; its Casimirs drift at its tolerance). A rollout starts each step's
iteration from a polynomial extrapolation of the past stages, close enough that one iteration
is the rule (BENCHMARKS.md, "Zeitlin's model"). `integrators.Compensated(method)` adds the
increments by compensated summation (quflow's `compsum`): the Casimirs then keep to the
round-off of the increments, not of $W$.

For a body system $\dot M = [M, \Xi]$ with $\Xi = \partial H/\partial\mu$ as a matrix
(conventions, matrix algebras), $B = -\Xi$.
"""

from __future__ import annotations

import functools
from fractions import Fraction
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from liepoisson import MatrixLieAlgebra
from liepoisson.internals import dagger, positive_float, positive_int
from liepoisson.systems import AbstractLiePoissonSystem

from ._compensated import AbstractCompensable, two_sum
from ._lapack import serial_lapack
from ._lie_group import check_lie_poisson
from ._products import cayley_increment, matmul
from ._splitting._composition import TripleJump
from ._step_map import check_state

#: The stage iteration stops when an iteration moves the stage by at most `tol` times
#: ||W||_inf (the largest row sum of |W_ij|, quflow's norm). 1e-10: the stage's error enters the step's accuracy (energy, state), not
#: its Casimirs; at the step sizes of a Zeitlin run it is below the method's local error.
DEFAULT_TOL = 1e-10
#: Iterations after which a step that has not met the tolerance is NaN (a step too large for
#: the iteration to contract).
DEFAULT_MAX_ITER = 100



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


def check_stage_tolerance(tol: Any, name: str = "tol") -> float:
    r"""`tol` as a float in (0, 1): relative to $\|W\|_\infty$, the largest move of the stage
    iteration that is accepted; at 1 or more the first iterate is accepted, converged or not."""
    tol = positive_float(tol, name)
    if tol >= 1.0:
        raise ValueError(f"{name} must be in (0, 1): the stage iteration stops when an iteration moves the stage by "
                         f"at most {name} times ||W||_inf, so at {name} >= 1 it accepts its first iterate unchecked "
                         f"(the default is {DEFAULT_TOL:g}); got {tol!r}")
    return tol


class IsospectralMidpoint(AbstractCompensable):
    r"""The isospectral midpoint method (module docstring): order 2, symmetric, a Lie-Poisson
    integrator for $\dot W = [B(W), W]$ (Modin & Viviani 2020) that keeps the spectrum of $W$
    to round-off.

    **Arguments:**

    - `system`, a Lie-Poisson system on so(N), u(N) or su(N); `h` > 0.
    - `tol` in (0, 1) (default `DEFAULT_TOL`): the stage iteration stops when an iteration
      moves the stage by at most `tol` times $\|W\|_\infty$ (largest row sum; both in that norm).
    - `iterations` (default `None`): `None` iterates until `tol` is met (at most `max_iter`
      iterations), the robust choice; an integer $k$ makes every step of a rollout do exactly
      $k$ iterations from its extrapolated start (straight-line code, which reverse-mode
      differentiation needs), and a step whose last iteration still moved more than `tol` is
      NaN (a rollout then says so and suggests more); `iterations_needed(y0)` says what a run
      needs, but a later step may need more.
    - `max_iter` (default `DEFAULT_MAX_ITER`): the cap of the iterations to `tol`.

    `integrators.Compensated(IsospectralMidpoint(...))` sums the steps' increments
    $W_{n+1} = W_n + \Delta W_n$ with compensated summation (TwoSum, the rounding error of
    each sum carried to the next), as quflow's `compsum`: the Casimirs then drift only by the
    round-off of the increments, not of $W$ (the figures: BENCHMARKS.md, "Zeitlin's model").
    It costs a few additions a step and, for complex $W$, the increment's two products by four
    real products instead of three.

    A rollout carries $W$ and the last `PREDICTOR_POINTS` stage increments of each substep; its
    first step starts from a history found by as many steps backwards (the method is
    symmetric: a step back shares its stage with the step forward it undoes), so every step
    starts from the least-squares extrapolation of degree `PREDICTOR_DEGREE` through them.
    `step(y)` alone starts cold and iterates to `tol`.
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
        self.tol = check_stage_tolerance(tol)
        self.iterations = None if iterations is None else positive_int(iterations, "iterations")
        self.max_iter = positive_int(max_iter, "max_iter")

    @property
    def exact_flows_per_step(self) -> int:
        return 0

    @property
    def divergence_hint(self) -> str:
        if self.iterations is None:
            return (f"The stage iteration did not meet tol={self.tol:g} within max_iter={self.max_iter} "
                    "iterations (a step too large for it to contract), or the state left the finite range: "
                    "try a smaller h")
        return (f"A step's stage iteration did not meet tol={self.tol:g} in iterations={self.iterations} "
                f"(a step that has not converged is NaN): use more, e.g. IsospectralMidpoint(..., "
                f"iterations={self.iterations + 1}), or iterations=None to iterate until tol is met")

    def velocity_matrix(self, W: jax.Array) -> jax.Array:
        r"""$B(W)$ of $\dot W = [B(W), W]$ for `W` `(m, m)`: the system's
        (`system.velocity_matrix`); a learned map on this step overrides it."""
        return self.system.velocity_matrix(W)

    def _iterate(self, W: jax.Array, h: jax.Array | float, Wt: jax.Array, real_products: int = 3
                 ) -> tuple[jax.Array, jax.Array, jax.Array]:
        r"""One quasi-Newton iteration of the stage equation from the iterate `Wt`: with
        $B = \tfrac h2 B(\widetilde W)$ the step's candidate is the conjugation
        $Q W Q^\dagger$ by the Cayley transform $Q = (1 - B)^{-1}(1 + B)$, formed as an
        increment: with $E = Q - 1 = 2(1 - B)^{-1}B$ (`_products.cayley_increment`: block
        elimination, about one product),

        $$Q W Q^\dagger - W = EW - (EW)^\dagger + EWE^\dagger$$

        ($W^\dagger = -W$), two products whose round-off is that of the increment, not of $W$
        (what compensated summation needs: `integrators.Compensated`). The stage the iteration
        moves to is the stage equation solved with $B$ frozen, $X W X^\dagger$ with
        $X = (1 - B)^{-1} = 1 + E/2$, from the same products: $W + (EW - (EW)^\dagger)/2 +
        EWE^\dagger/4$.
        Returns `(increment, next iterate, moved)`, `moved` the largest row sum of the
        iterate's change. The products in real arithmetic (`_products.matmul`: XLA's complex
        product is several times slower on CPU, and LAPACK's LU and triangular solves several
        products), by `real_products` real products a complex one (3, or 4 when compensated)."""
        B = 0.5 * h * self.velocity_matrix(Wt)
        E = 2.0 * cayley_increment(B)  # Q - 1, Q the Cayley transform: unitary (orthogonal)
        # compensated: the increment's round-off is all that is left; four real products a
        # complex one keep it at eps |E||W| (3M's is up to twice that; measured in
        # BENCHMARKS.md, "Zeitlin's model")
        EW = matmul(E, W, real_products=real_products)
        EWE = matmul(EW, dagger(E), real_products=real_products)
        S = EW - dagger(EW)
        dW = S + EWE
        dW = 0.5 * (dW - dagger(dW))  # on the algebra (exact halving): W + dW stays on it, to the last bit
        # X W X^dagger from the same products; its round-off is far below tol (it is only where
        # the next iteration starts)
        G = W + 0.5 * S + 0.25 * EWE
        return dW, G, _norm(G - Wt)

    def _midpoint(self, W: jax.Array, h: jax.Array | float, D: jax.Array, iterations: int | None,
                  real_products: int = 3) -> tuple[jax.Array, jax.Array, jax.Array]:
        r"""One isospectral midpoint step of size `h` from `W`, the stage $\tilde W$ sought
        from $W + D$ by `iterations` quasi-Newton iterations (None: until `tol`): returns the
        step's increment $W_{n+1} - W$ (NaN if the stage has not converged), the stage's
        increment $\tilde W - W$ (the last iteration's, one iteration past the stage whose $B$
        made the step) and the iteration count. `real_products` as `_iterate`.

        The step is the Cayley conjugation of the iterate that the last iteration started
        from, accepted when that iteration moved it by at most `tol` times max|W| (quflow's
        rule, one evaluation of $B$ a step fewer than iterating once more)."""
        scale = self.tol * jnp.maximum(_norm(W), jnp.finfo(jnp.float64).tiny)
        if iterations is None:

            def body(state):
                Wt, _, _, k = state
                dW, G, moved = self._iterate(W, h, Wt, real_products)
                return G, dW, moved, k + 1

            Wt, dW, moved, k = jax.lax.while_loop(
                lambda state: (state[2] > scale) & (state[3] < self.max_iter), body,
                (W + D, jnp.zeros_like(W), jnp.asarray(jnp.inf), jnp.asarray(0)))
        else:  # straight-line code: no control flow in the step
            Wt = W + D
            for _ in range(iterations):
                dW, Wt, moved = self._iterate(W, h, Wt, real_products)
            k = jnp.asarray(iterations)
        return jnp.where(moved <= scale, dW, jnp.nan), Wt - W, k

    def step_matrix(self, W: jax.Array) -> jax.Array:
        """One step on the matrix $W$ `(m, m)` of the state, the stage started at $W$ and
        iterated until `tol` (or `iterations` times, when set)."""
        return self._step_cold(W, None)[0]

    def _step_cold(self, W: jax.Array, low: jax.Array | None) -> tuple[jax.Array, jax.Array | None]:
        # `low` None: the plain sum; an array: the compensated one (`_accumulate`)
        real_products = 3 if low is None else 4
        for c in self.substeps:
            dW, _, _ = self._midpoint(W, c * self.h, jnp.zeros_like(W), self.iterations, real_products)
            W, low = _accumulate(W, low, dW)
        return W, low

    def step(self, y: jax.Array) -> jax.Array:
        algebra = self.system.algebra
        return algebra.coordinates(self.step_matrix(algebra.matrix(check_state(y, self.system.dim))))

    def compensated_step(self, y: jax.Array) -> jax.Array:
        """`step` with the substeps' increments added by `two_sum` (the stage started at $W$,
        as `step`)."""
        algebra = self.system.algebra
        W = algebra.matrix(check_state(y, self.system.dim))
        return algebra.coordinates(self._step_cold(W, jnp.zeros_like(W))[0])

    # A rollout carries W itself, each substep's last `PREDICTOR_POINTS` stage increments (a
    # ring buffer) and how many of them are filled: the next step's iteration starts from
    # their least-squares polynomial extrapolation (`predictor_weights`), which saves
    # iterations (BENCHMARKS.md, "Zeitlin's model"). Converting W to coordinates and back every
    # step would cost a rounding per step (u(N)'s basis has entries 1/sqrt(2)) and bias the
    # Casimirs.
    def carry(self, y: jax.Array) -> tuple[jax.Array, tuple[jax.Array, ...], jax.Array]:
        W = self.system.algebra.matrix(check_state(y, self.system.dim))
        return W, self._histories(W, 3), jnp.asarray(PREDICTOR_POINTS)

    def _histories(self, W: jax.Array, real_products: int) -> tuple[jax.Array, ...]:
        M, S = PREDICTOR_POINTS, len(self.substeps)
        # The history is found by M steps backwards, each substep undoing one forward substep
        # (in reverse order; the method is symmetric: a step back shares its stage with the step
        # forward it undoes), warm-started by the same extrapolation of the increments found so
        # far. No derivative flows through it: it is only where the iteration starts (so a
        # rollout with a fixed `iterations` is reverse-differentiable: no while loop carries one).
        backwards = tuple(-c for c in reversed(self.substeps))
        empty = jnp.zeros((M, *W.shape), W.dtype)

        def back(state, _):
            Wb, histories, count = state
            found, updated = [], []
            for coefficient, history in zip(backwards, histories):
                dW, D, _ = self._midpoint(Wb, coefficient * self.h, _predict(history, count), None,
                                          real_products)
                Wn = Wb + dW
                updated.append(_push(history, D, count))
                found.append(Wb + D - Wn)  # the forward substep's increment, from where it starts
                Wb = Wn
            return (Wb, tuple(updated), _counted(count)), jnp.stack(found)

        _, found = jax.lax.scan(back, (jax.lax.stop_gradient(W), (empty,) * S, jnp.asarray(0)), None, length=M)
        # found[j, s]: backward step j (the forward step j + 1 before W), backward substep s
        # (forward substep S - 1 - s); the forward ring full, the oldest in slot 0 (count M)
        return tuple(found[::-1, S - 1 - index] for index in range(S))

    def step_carry(self, c: tuple[jax.Array, tuple[jax.Array, ...], jax.Array]
                   ) -> tuple[jax.Array, tuple[jax.Array, ...], jax.Array]:
        return self._step_warm(c, self.iterations)[0]

    def _step_warm(self, c, iterations, low=None):
        W, histories, count = c
        real_products = 3 if low is None else 4
        updated, total = [], jnp.asarray(0)
        for coefficient, history in zip(self.substeps, histories):
            dW, D, k = self._midpoint(W, coefficient * self.h, _predict(history, count), iterations, real_products)
            W, low = _accumulate(W, low, dW)
            updated.append(_push(history, D, count))
            total = total + k
        return (W, tuple(updated), _counted(count)), low, total

    def uncarry(self, c: tuple[jax.Array, tuple[jax.Array, ...], jax.Array]) -> jax.Array:
        return self.system.algebra.coordinates(c[0])

    # Compensated (integrators.Compensated): the carried state and the low part of W beside it;
    # the history is found, and every step's increment formed, by four real products a complex
    # one (`_iterate`).
    def compensated_carry(self, y: jax.Array) -> tuple[jax.Array, tuple[jax.Array, ...], jax.Array, jax.Array]:
        W = self.system.algebra.matrix(check_state(y, self.system.dim))
        return W, self._histories(W, 4), jnp.asarray(PREDICTOR_POINTS), jnp.zeros_like(W)

    def compensated_step_carry(self, c: tuple[jax.Array, tuple[jax.Array, ...], jax.Array, jax.Array]
                               ) -> tuple[jax.Array, tuple[jax.Array, ...], jax.Array, jax.Array]:
        c, low, _ = self._step_warm(c[:3], self.iterations, c[3])
        return (*c, low)

    def compensated_uncarry(self, c: tuple[jax.Array, tuple[jax.Array, ...], jax.Array, jax.Array]) -> jax.Array:
        """The coordinates of $W_{hi}$ (the low part, at most half an ulp of each entry,
        dropped)."""
        return self.uncarry(c[:3])

    def iterations_needed(self, y: ArrayLike, n_steps: int = 20) -> tuple[float, int]:
        """`(mean, max)` of the quasi-Newton iterations (summed over substeps) that the steps
        of a rollout from `y` need to meet `tol`, over `n_steps` steps: choose `iterations=`
        from the max (and more for a flow that stiffens)."""
        n_steps = positive_int(n_steps, "n_steps")
        counts = np.asarray(_count_iterations(self, self.carry(jnp.asarray(y, jnp.float64)), n_steps))
        return float(counts.mean()), int(counts.max())


#: How many past stage increments a rollout keeps, and the degree of the least-squares
#: polynomial through them whose value one step ahead starts the next stage iteration.
PREDICTOR_POINTS = 8
PREDICTOR_DEGREE = 5


def _accumulate(W: jax.Array, low: jax.Array | None, dW: jax.Array) -> tuple[jax.Array, jax.Array | None]:
    """`W + dW`, or with `low` the sum so far to twice the working precision: `two_sum` of
    `W` and `dW + low` (quflow's `compsum`)."""
    if low is None:
        return W + dW, None
    return two_sum(W, dW + low)


def _norm(A: jax.Array) -> jax.Array:
    r"""$\|A\|_\infty$, the largest row sum of $|A_{ij}|$ (quflow's norm of the iteration's
    residual)."""
    return jnp.max(jnp.sum(jnp.abs(A), axis=-1), axis=-1)


@functools.cache
def predictor_weights(points: int = PREDICTOR_POINTS, degree: int = PREDICTOR_DEGREE) -> np.ndarray:
    r"""`(points + 1, points)`: row $k$ the weights $w_j$ of the $j$-th latest of $k$ known
    increments ($j = 1..k$, zero beyond) in the prediction $\sum_j w_j D_{n-j}$ of $D_n$: the
    least-squares polynomial of degree $\min(k - 1, \text{degree})$ through them, at the next
    step (row 0: no history, a cold start). Exact rationals, rounded once: the weights sum to
    1 to the last bit (a constant history is predicted exactly)."""
    table = np.zeros((points + 1, points))
    for k in range(1, points + 1):
        # w = V (V^T V)^{-1} e_0, V_jp = t_j^p at t_j = -j: the normal equations in fractions
        d = min(k - 1, degree) + 1
        V = [[Fraction(-j) ** p for p in range(d)] for j in range(1, k + 1)]
        A = [[sum(V[j][p] * V[j][q] for j in range(k)) for q in range(d)] + [Fraction(int(p == 0))]
             for p in range(d)]
        for p in range(d):  # Gauss-Jordan: A is symmetric positive definite (no pivoting)
            A[p] = [a / A[p][p] for a in A[p]]
            for r in range(d):
                if r != p:
                    A[r] = [a - A[r][p] * b for a, b in zip(A[r], A[p])]
        c = [A[p][d] for p in range(d)]  # (V^T V)^{-1} e_0
        table[k, :k] = [float(sum(V[j][p] * c[p] for p in range(d))) for j in range(k)]
    return table


def _predict(history: jax.Array, count: jax.Array) -> jax.Array:
    r"""The next increment extrapolated from the ring `history` `(M, m, m)` after `count`
    pushes (`_push`: the $j$-th latest in slot $(\text{count} - j) \bmod M$; fewer than $M$
    pushes, the extrapolation of those there are)."""
    M = history.shape[0]
    row = jnp.asarray(predictor_weights(M))[jnp.minimum(count, M)]  # j-th latest at index j - 1
    return jnp.tensordot(row[(count - 1 - jnp.arange(M)) % M], history, axes=1)


def _push(history: jax.Array, D: jax.Array, count: jax.Array) -> jax.Array:
    """`history` with `D` written over the oldest, slot `count mod M` (in place in a compiled
    loop)."""
    return history.at[count % history.shape[0]].set(D)


def _counted(count: jax.Array) -> jax.Array:
    """The count after one more push, kept below 2M (its residue mod M and min(count, M) kept)."""
    count = count + 1
    return jnp.where(count >= 2 * PREDICTOR_POINTS, count - PREDICTOR_POINTS, count)


@eqx.filter_jit
def _count_iterations(method: IsospectralMidpoint, c: Any, n_steps: int) -> jax.Array:
    def body(c, _):
        c, _, k = method._step_warm(c, None)
        return c, k

    _, counts = jax.lax.scan(body, c, None, length=n_steps)
    return counts


class IsospectralTripleJump(IsospectralMidpoint):
    r"""Yoshida's triple jump of the isospectral midpoint: substeps $\gamma_1 h, \gamma_0 h,
    \gamma_1 h$, $\gamma_1 = 1/(2 - 2^{1/3})$, $\gamma_0 = 1 - 2\gamma_1$: order 4, symmetric,
    isospectral (each substep is a unitary conjugation). The composition of Modin & Viviani's
    isospectral methods of higher order (FoCM 2020, Sec. 5)."""

    # the coefficients of integrators.splitting.TripleJump (one table for both)
    substeps: ClassVar[tuple[float, ...]] = tuple(float(c) for c in TripleJump.coefficients)


ISOSPECTRAL_METHODS = {"IsospectralMidpoint": IsospectralMidpoint, "IsospectralTripleJump": IsospectralTripleJump}
