r"""The discrete Lagrange-d'Alembert method on Lie groups (Fedorov & Zenkov, *Nonlinearity*
18, 2005; the discrete Euler-Poincaré equations of Bou-Rabee & Marsden, *Found. Comput. Math.*
9, 2009, with the reaction): a variational integrator of a nonholonomic system
([Nonholonomic constraints][conventions-nonholonomic]) whose discrete velocities keep the
constraint exactly.

For a kinetic energy $\ell(\xi) = \tfrac12\xi^\top\mathbb M\xi$ (a quadratic $H$), steps
$g_{k+1} = g_k\exp(h\xi_k)$ with the discrete velocities $\xi_k \in \mathfrak d = \ker C$, and
the discrete principle of Lagrange-d'Alembert (variations in $\mathfrak d$):

$$g\bigl(hK(\xi_k)\bigr)\,\mathbb M\xi_k = p_k + C^\top\lambda_k, \qquad
p_{k+1} = g\bigl(-hK(\xi_k)\bigr)\,\mathbb M\xi_k, \qquad g(z) = \frac{z}{e^z - 1},$$

$K(\xi)$ the matrix of $\mu \mapsto \mathbb B(\mu)\xi$ (so $\dot\mu = K(\xi)\mu$ is the
unconstrained equation; $g(\pm hK)$ is the dual of $\mathrm{dexp}^{-1}_{\pm h\xi}$), $p_k$ the
discrete momentum arriving at node $k$. The state of the step map is $p_k$; the momentum at
the node to order 2 is `node_momentum(p)`, the mean of $p_k$ and the departing $p_k +
C^\top\lambda_k$ (they differ by the reaction's impulse, $O(h)$). What it keeps: the
constraint holds for the discrete velocities $\xi_k$ (`velocity`) to round-off, not for the
node momenta; the energy is not conserved exactly (a variational integrator's is bounded for a
Hamiltonian system; Fedorov & Zenkov study what the discrete Suslov problem keeps).
"""

from __future__ import annotations

import abc

import equinox as eqx
import jax
import jax.numpy as jnp

from liepoisson.internals import positive_float, positive_int
from liepoisson.systems import LiePoissonDAlembert

from ._implicit import AbstractImplicitStepMap
from ._splitting._composition import AbstractCompositionMethod
from ._splitting._composition import TripleJump as _TripleJump
from ._step_map import AbstractStepMap, check_state


def _phi1(A: jax.Array) -> jax.Array:
    r"""$\varphi_1(A) = \sum_n A^n/(n+1)! = \int_0^1 e^{sA}\,ds$: the upper right block of
    $\exp\begin{pmatrix}A & I\\ 0 & 0\end{pmatrix}$ (exact at $A = 0$, no division)."""
    n = A.shape[0]
    block = jnp.zeros((2 * n, 2 * n), dtype=A.dtype).at[:n, :n].set(A).at[:n, n:].set(jnp.eye(n))
    return jax.scipy.linalg.expm(block)[:n, n:]


def _g(A: jax.Array, v: jax.Array) -> jax.Array:
    r"""$g(A)\,v$, $g(z) = z/(e^z - 1) = 1/\varphi_1(z)$."""
    return jnp.linalg.solve(_phi1(A), v)


class AbstractStaggeredStepMap(AbstractStepMap):
    r"""A step map whose state is not the momentum at the node: a variational integrator's
    momentum arriving at node $k$, with the velocity of the step after it in between.
    `node_momentum(states)` is the momentum at the nodes (what compares with $\mu(t_k)$) and
    `velocity(states)` the velocities the method keeps admissible."""

    @abc.abstractmethod
    def node_momentum(self, p: jax.Array) -> jax.Array:
        """The momentum at the nodes of states `(..., dim)`."""

    @abc.abstractmethod
    def velocity(self, p: jax.Array) -> jax.Array:
        """The velocities of the steps from states `(..., dim)`."""


class DiscreteLagrangeDAlembert(AbstractStaggeredStepMap, AbstractImplicitStepMap):
    r"""The discrete Lagrange-d'Alembert method (module docstring): order 2, symmetric and
    reversible (below), variational; the discrete velocities $\xi_k$ keep the constraint to
    round-off.

    The state is the discrete momentum $p_k$ at node $k$ (an approximation of $\mu(t_k)$;
    start from the system's momentum). Each step solves the $k = \dim\ker C$ equations
    $N^\top\bigl(g(hK(Nw))\,\mathbb MNw - p_k\bigr) = 0$ for $\xi_k = Nw$ ($N$ the
    system's `admissible_basis`: the multipliers drop out) by `iterations` Newton steps from
    $w = N^\top\mathbb M^{-1}p_k$; `velocity(p)` returns that $\xi_k$.

    The step depends on $p_k$ only through $N^\top p_k$ (a reaction impulse $C^\top\lambda$
    added to $p_k$ changes $\lambda_k$ only), and as a map of $N^\top p$ it is
    **symmetric**, $\Phi_{-h} = \Phi_h^{-1}$ (the step at $-h$ from $p_{k+1}$ solves its
    equation with $\xi_k$ and no impulse, and arrives at $p_k + C^\top\lambda_k$), and
    **reversible** under $\mu\mapsto-\mu$ ($K$ is linear in $\xi$): the property that
    McLachlan & Perlmutter (*J. Nonlinear Sci.* 16, 2006) found behind nonholonomic
    integrators' good energy behaviour, and Modin & Verdier (*Numer. Math.* 144, 2020) showed
    to be what makes them work on reversible systems such as these. Its map of discrete
    velocities is symmetric too, and composes to higher orders: `ComposedLagrangeDAlembert`.

    **Arguments:** `system`, a `liepoisson.systems.LiePoissonDAlembert` with a quadratic
    Hamiltonian (a kinetic energy); `h` > 0; `iterations` >= 1 (default 8).
    """

    system: LiePoissonDAlembert = eqx.field(static=True)
    h: float
    iterations: int = eqx.field(static=True)
    metric: jax.Array  # M, from the system
    basis: jax.Array  # N, from the system

    def __init__(self, system: LiePoissonDAlembert, h: float, iterations: int = 8):
        if not isinstance(system, LiePoissonDAlembert):
            raise TypeError(f"system must be a liepoisson.systems.LiePoissonDAlembert (a nonholonomic system); got "
                            f"{type(system).__name__}")
        self.metric = jnp.asarray(system.kinetic_metric())  # a quadratic H, or a ValueError saying why not
        self.basis = jnp.asarray(system.admissible_basis())
        self.system = system
        self.h = positive_float(h, "h")
        self.iterations = positive_int(iterations, "iterations")

    def _generator(self, xi: jax.Array) -> jax.Array:
        r"""$K(\xi)$: $K(\xi)\mu = \mathbb B(\mu)\xi$ of the unconstrained system (linear in $\mu$)."""
        unconstrained = self.system.system
        return jax.jacfwd(lambda mu: unconstrained.poisson_tensor(mu) @ xi)(jnp.zeros_like(xi))

    def _residual(self, p: jax.Array, w: jax.Array) -> jax.Array:
        N, M = self.basis, self.metric
        xi = N @ w
        return N.T @ (_g(self.h * self._generator(xi), M @ xi) - p)

    def start(self, y: jax.Array) -> tuple[jax.Array, jax.Array]:
        N, M = self.basis, self.metric
        return y, N.T @ jnp.linalg.solve(M, y)

    def iterate(self, p: jax.Array, w: jax.Array) -> jax.Array:
        """One Newton step on $N^\\top(g(hK(Nw))\\,\\mathbb MNw - p) = 0$."""
        return w - jnp.linalg.solve(jax.jacfwd(lambda v: self._residual(p, v))(w), self._residual(p, w))

    def finish(self, p: jax.Array, w: jax.Array) -> jax.Array:
        r"""$p_{k+1} = g(-hK(\xi_k))\,\mathbb M\xi_k$."""
        return self.arriving(w)

    def arriving(self, w: jax.Array) -> jax.Array:
        r"""$g(-hK(\xi))\,\mathbb M\xi$, $\xi = Nw$: the momentum a step of velocity $\xi$
        arrives with."""
        xi = self.basis @ w
        return _g(-self.h * self._generator(xi), self.metric @ xi)

    def node_momentum(self, p: jax.Array) -> jax.Array:
        r"""$\tfrac12(p_k + p_k^+)$ `(..., dim)`, $p_k^+ = p_k + C^\top\lambda_k =
        g(hK(\xi_k))\,\mathbb M\xi_k$: the momentum at node $k$ to order 2 (the arriving
        momentum $p_k$ and the departing one differ by the reaction's impulse, $O(h)$)."""
        p = jnp.asarray(p, dtype=jnp.float64)
        return _node_momenta(self, p.reshape((-1, self.system.dim))).reshape(p.shape)

    def velocity(self, p: jax.Array) -> jax.Array:
        r"""$\xi_k$ `(..., dim)`: the discrete velocity of the step from the node momentum $p_k$
        (admissible to round-off)."""
        p = jnp.asarray(p, dtype=jnp.float64)
        return _velocities(self, p.reshape((-1, self.system.dim))).reshape(p.shape)

    def _velocity(self, p: jax.Array) -> jax.Array:
        context, w = self.start(p)
        w = jax.lax.fori_loop(0, self.iterations, lambda _, v: self.iterate(context, v), w)
        return self.basis @ w

    @property
    def exact_flows_per_step(self) -> int:
        return 0


# One state after the other (`lax.map`, not `vmap`): batched over ~1000 states the solves
# and matrix exponentials of the Newton steps stalled XLA's CPU runtime (BENCHMARKS.md,
# "Nonholonomic systems").
@eqx.filter_jit
def _velocities(method: DiscreteLagrangeDAlembert, p: jax.Array) -> jax.Array:
    return jax.lax.map(method._velocity, p)


@eqx.filter_jit
def _node_momenta(method: DiscreteLagrangeDAlembert, p: jax.Array) -> jax.Array:
    def one(q):
        xi = method._velocity(q)
        return 0.5 * (q + _g(method.h * method._generator(xi), method.metric @ xi))

    return jax.lax.map(one, p)


class ComposedLagrangeDAlembert(AbstractStepMap):
    r"""Symmetric compositions of the discrete Lagrange-d'Alembert method, in its velocities:
    $\Phi_h = F_{\gamma_sh}\circ\cdots\circ F_{\gamma_1h}$ with the palindromic table
    $\gamma$ of a composition method (`integrators.splitting.TripleJump`, the default,
    `Suzuki`, `McLachlan4`: order 4; `Yoshida6`: order 6; Hairer, Lubich & Wanner, Sec. II.4)
    and $F_h$ the method's map of discrete velocities, $\xi_k\mapsto\xi_{k+1}$:

    $$N^\top g\bigl(hK(\xi_{k+1})\bigr)\,\mathbb M\xi_{k+1} = N^\top g\bigl(-hK(\xi_k)\bigr)\,\mathbb M\xi_k,$$

    the equation of two consecutive steps of `DiscreteLagrangeDAlembert` with the multiplier
    eliminated. $F_h$ is symmetric ($F_{-h} = F_h^{-1}$: the equation is the same read
    backwards) and of order 2, so the composition has the table's order; and every steady
    motion ($K(\xi)\mathbb M\xi \in \operatorname{im}C^\top$) is a fixed point of $F_h$ for
    every $h$ ($g(z) - g(-z) = -z$), so of the composition too. (Composed in the arriving
    momenta instead, each sub-step would read the momentum arriving from a sub-step of
    another length: the steady motions drift, the energy by $O(h^p)$ per unit time;
    BENCHMARKS.md, "Nonholonomic systems".)

    The state is the momentum $\mathbb M\xi$ of the velocity $\xi = Nw \in \ker C$ (a
    rollout carries $w$); a state off the constraint is read by its class $N^\top y$ (as
    `system.project`). Every sub-step's velocity is in $\ker C$ to round-off.

    **Arguments:** `system` and `iterations` as `DiscreteLagrangeDAlembert`'s (each sub-step's
    Newton steps, from the velocity before it); `h` > 0; `method`, an `integrators.splitting`
    composition method.
    """

    base: DiscreteLagrangeDAlembert
    h: float
    method: AbstractCompositionMethod = eqx.field(static=True)

    def __init__(self, system: LiePoissonDAlembert, h: float, method: AbstractCompositionMethod | None = None,
                 iterations: int = 8):
        method = _TripleJump() if method is None else method
        if not isinstance(method, AbstractCompositionMethod):
            raise TypeError(f"method must be a composition method of integrators.splitting (TripleJump, Suzuki, "
                            f"McLachlan4, Yoshida6): a table of sub-steps; got {method!r}")
        self.base = DiscreteLagrangeDAlembert(system, h, iterations)
        self.h = self.base.h
        self.method = method

    @property
    def system(self) -> LiePoissonDAlembert:
        return self.base.system

    @property
    def order(self) -> int:
        """The composition method's order."""
        return self.method.order

    def carry(self, y: jax.Array) -> jax.Array:
        r"""$w$ with $N^\top\mathbb MNw = N^\top y$: the velocity $Nw$ of the admissible
        momentum with the class of `y`."""
        N, M = self.base.basis, self.base.metric
        return jnp.linalg.solve(N.T @ M @ N, N.T @ y)

    def uncarry(self, w: jax.Array) -> jax.Array:
        return self.base.metric @ (self.base.basis @ w)

    def step_carry(self, w: jax.Array) -> jax.Array:
        def substep(w, gamma):  # F at gamma h: from the momentum arriving from a step of gamma h
            m = eqx.tree_at(lambda m: m.h, self.base, gamma * self.h)
            w, converged = m.solve(m.arriving(w), w)
            return jnp.where(converged, w, jnp.nan), None

        return jax.lax.scan(substep, w, jnp.asarray(self.method.coefficients))[0]

    def step(self, y: jax.Array) -> jax.Array:
        return self.uncarry(self.step_carry(self.carry(check_state(y, self.system.dim))))

    @property
    def label(self) -> str:
        return f"ComposedLagrangeDAlembert({type(self.method).__name__})"

    @property
    def divergence_hint(self) -> str:
        return (f"The map left the finite range, or a sub-step's Newton iteration did not converge in "
                f"iterations={self.base.iterations} (such a sub-step is NaN, never its last iterate): build it with "
                f"more iterations= or a smaller h (the table's sub-steps reach {max(abs(self.method.coefficients)):.2f} h)")

    @property
    def exact_flows_per_step(self) -> int:
        return 0

    def step_flops(self) -> float:
        """One sub-step's count times the sub-steps (XLA counts a scan's body once)."""
        return len(self.method.coefficients) * self.base.step_flops()
