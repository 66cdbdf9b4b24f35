r"""Classical Runge-Kutta step maps without splitting, the baselines of a comparison:
RK4 (no geometric structure at all) and the Gauss-Legendre methods, the implicit midpoint rule
and its two-stage order-4 sibling (symplectic for canonical systems; for a Lie-Poisson system
they conserve every quadratic Casimir, e.g. $|\Pi|^2$, but are not Poisson maps; for a
nonholonomic system with a quadratic $H$ they keep the constraint, linear in $\mu$, and the
energy to round-off)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from liepoisson.internals import check_system, positive_float, positive_int
from liepoisson.systems import AbstractPoissonSystem

from ._implicit import AbstractImplicitStepMap
from ._step_map import AbstractStepMap, check_state


def rk4_steps(field: Callable[[Any], Any], y: Any, h: float | jax.Array, substeps: int = 1) -> Any:
    r"""`substeps` classical Runge-Kutta steps (RK4, as `RK4`) of $\dot y = f(y)$ over $h$,
    for `y` any pytree of arrays (a state; a configuration and a state); one step is traced,
    and looped over when there are several."""
    dt = h / substeps

    def shifted(z, k, c):
        return jax.tree_util.tree_map(lambda zi, ki: zi + c * ki, z, k)

    def one(_, z):
        k1 = field(z)
        k2 = field(shifted(z, k1, 0.5 * dt))
        k3 = field(shifted(z, k2, 0.5 * dt))
        k4 = field(shifted(z, k3, dt))
        return jax.tree_util.tree_map(lambda zi, a, b, c, d: zi + (dt / 6.0) * (a + 2.0 * b + 2.0 * c + d),
                                      z, k1, k2, k3, k4)

    return one(0, y) if substeps == 1 else jax.lax.fori_loop(0, substeps, one, y)


class RK4(AbstractStepMap):
    r"""The classical Runge-Kutta method of order 4 on $\dot y = \mathbb B(y)\nabla H(y)$:
    $k_1 = f(y)$, $k_2 = f(y + \tfrac h2 k_1)$, $k_3 = f(y + \tfrac h2 k_2)$,
    $k_4 = f(y + h k_3)$, $y_{n+1} = y + \tfrac h6(k_1 + 2k_2 + 2k_3 + k_4)$
    (Hairer, Norsett, Wanner, *Solving ODEs I*, Sec. II.1). Conserves nothing exactly.

    **Arguments:** `system`; `h` > 0.
    """

    system: AbstractPoissonSystem = eqx.field(static=True)
    h: float

    def __init__(self, system: AbstractPoissonSystem, h: float):
        self.system = check_system(system)
        self.h = positive_float(h, "h")

    def step(self, y: jax.Array) -> jax.Array:
        return rk4_steps(self.system.vector_field, check_state(y, self.system.dim), self.h)

    @property
    def exact_flows_per_step(self) -> int:
        return 0


class ImplicitMidpoint(AbstractImplicitStepMap):
    r"""The implicit midpoint rule $y_{n+1} = y_n + h f\big(\tfrac12(y_n + y_{n+1})\big)$,
    order 2, symmetric. It conserves every quadratic first integral exactly (Cooper 1987;
    Hairer, Lubich, Wanner, *Geometric Numerical Integration*, Thm. IV.2.2), so the quadratic
    Casimirs of so(3)* and se(3)* to round-off and, for a quadratic Hamiltonian, the energy;
    it is not a Poisson map of a Lie-Poisson bracket (its Poisson defect is $O(h^3)$).

    The stage equation is solved by `iterations` Newton steps from the explicit Euler guess (a
    fixed count, so the step is differentiable and compiles to a loop; Newton converges
    quadratically, and the default reaches round-off for $h\|f'\| \lesssim 1$). A step whose
    last Newton step still moves the solution is NaN (`integrators.AbstractImplicitStepMap`).

    **Arguments:** `system`; `h` > 0; `iterations` >= 1 (default 8).
    """

    system: AbstractPoissonSystem = eqx.field(static=True)
    h: float
    iterations: int = eqx.field(static=True)

    def __init__(self, system: AbstractPoissonSystem, h: float, iterations: int = 8):
        self.system = check_system(system)
        self.h = positive_float(h, "h")
        self.iterations = positive_int(iterations, "iterations")

    def start(self, y: jax.Array) -> tuple[jax.Array, jax.Array]:
        return y, y + self.h * self.system.vector_field(y)  # explicit Euler

    def iterate(self, y: jax.Array, z: jax.Array) -> jax.Array:
        """One Newton step on the stage equation $z - y - h f((y + z)/2) = 0$."""
        h, f = self.h, self.system.vector_field
        jac = jax.jacfwd(f)(0.5 * (y + z))
        return z - jnp.linalg.solve(jnp.eye(self.system.dim) - 0.5 * h * jac, z - y - h * f(0.5 * (y + z)))

    @property
    def exact_flows_per_step(self) -> int:
        return 0


#: The two-stage Gauss-Legendre tableau: $c = \tfrac12 \mp \tfrac{\sqrt3}{6}$, $b = (\tfrac12, \tfrac12)$.
_SQRT3_6 = np.sqrt(3.0) / 6.0
GAUSS4_A = np.array([[0.25, 0.25 - _SQRT3_6], [0.25 + _SQRT3_6, 0.25]])
GAUSS4_B = np.array([0.5, 0.5])


class GaussLegendre4(AbstractImplicitStepMap):
    r"""The two-stage Gauss-Legendre method (Hairer, Lubich, Wanner, *Geometric Numerical
    Integration*, Sec. II.1.3): $Z_i = h\sum_j a_{ij} f(y + Z_j)$, $y_{n+1} = y + h\sum_i b_i
    f(y + Z_i)$, $a = \begin{pmatrix}\tfrac14 & \tfrac14 - \tfrac{\sqrt3}6\\ \tfrac14 +
    \tfrac{\sqrt3}6 & \tfrac14\end{pmatrix}$, $b = (\tfrac12, \tfrac12)$: order 4, symmetric,
    and, like the implicit midpoint rule (the one-stage Gauss method), it conserves every
    linear and quadratic first integral exactly (Thm. IV.2.2): the quadratic Casimirs of a
    Lie-Poisson system. On a nonholonomic system with a quadratic Hamiltonian
    (`liepoisson.systems.suslov`, `chaplygin_sleigh`) the constraint $g = C\mathbb M^{-1}\mu$
    obeys the linear $\dot g = -\kappa g$ (Baumgarte's term), so every stage of a state on it
    stays on it, and there the energy $\tfrac12\mu^\top\mathbb M^{-1}\mu$ is a quadratic
    invariant: both kept to the round-off of the stage solve.

    The stages are solved by `iterations` Newton steps on the $2\,$`dim` equations from
    $Z = 0$; a step whose last Newton step still moves them is NaN.

    **Arguments:** `system`; `h` > 0; `iterations` >= 1 (default 8).
    """

    system: AbstractPoissonSystem = eqx.field(static=True)
    h: float
    iterations: int = eqx.field(static=True)

    def __init__(self, system: AbstractPoissonSystem, h: float, iterations: int = 8):
        self.system = check_system(system)
        self.h = positive_float(h, "h")
        self.iterations = positive_int(iterations, "iterations")

    def _residual(self, y: jax.Array, Z: jax.Array) -> jax.Array:
        F = jax.vmap(self.system.vector_field)(y + Z)  # (2, dim)
        return Z - self.h * jnp.asarray(GAUSS4_A) @ F

    def start(self, y: jax.Array) -> tuple[jax.Array, jax.Array]:
        return y, jnp.zeros((2, y.shape[-1]), dtype=y.dtype)

    def iterate(self, y: jax.Array, Z: jax.Array) -> jax.Array:
        r"""One Newton step on the stage equations $Z - h\,(a\otimes I)\,F(y + Z) = 0$."""
        n = 2 * y.shape[-1]
        flat = Z.reshape(n)
        jac = jax.jacfwd(lambda z: self._residual(y, z.reshape(Z.shape)).reshape(n))(flat)
        return (flat - jnp.linalg.solve(jac, self._residual(y, Z).reshape(n))).reshape(Z.shape)

    def finish(self, y: jax.Array, Z: jax.Array) -> jax.Array:
        F = jax.vmap(self.system.vector_field)(y + Z)
        return y + self.h * jnp.asarray(GAUSS4_B) @ F

    @property
    def exact_flows_per_step(self) -> int:
        return 0
