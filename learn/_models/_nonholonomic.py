r"""A learned step of a nonholonomic system that keeps the constraint and a learned energy
exactly, for any weights ([Nonholonomic constraints][conventions-nonholonomic]).

The state is the body velocity $\xi$ (what a gyroscope or an odometer reads), not the momentum:
the constraint $C\xi = 0$ is known physics (the Suslov body's vector $a$, the sleigh's knife
edge), while the momentum needs the inertia that is to be learned. With $N$ an orthonormal
basis of $\mathfrak d = \ker C$ ($k = $ `dim` $- m$ columns), $w = N^\top\xi$, a learned
lower-triangular $L$ ($\det L = 1$: the energy's scale is not identifiable), $u = L^\top w$:

$$u' = \exp\bigl(h\,\Omega(w)\bigr)\,u, \qquad \xi' = N L^{-\top}u',$$

$\Omega(w)$ a skew-symmetric $k\times k$ matrix from a network. So $C\xi' = 0$ to round-off and
$\tfrac12|u|^2 = \tfrac12 w^\top LL^\top w$, a kinetic energy on $\mathfrak d$, is conserved
exactly, for any weights: the map moves on the ellipsoid of the learned energy inside the
constraint subspace; the true energy is conserved when $LL^\top$ is proportional to the true
metric $N^\top\mathbb M N$ (for $\dot\xi$ of a quadratic $H = \tfrac12\mu^\top\mathbb M^{-1}\mu$,
$\mu = \mathbb M\xi$). What it does not have: the Casimirs (the motion changes them) or a
Poisson structure (there is none).
"""

from __future__ import annotations

import abc
from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from integrators import AbstractReconstructingStepMap
from integrators.internals import check_h, check_state
from liepoisson.internals import positive_float
from liepoisson.systems import LiePoissonDAlembert

from .._solvers._levenberg_marquardt import LevenbergMarquardt
from .._solvers._stage import KeepIfBetter
from ._base import AbstractLearnedMap
from ._mlp import AffineMLP
from ._network_spec import network_from_spec
from ._networks import AbstractNetwork, check_network


def _checked_system(system: Any) -> LiePoissonDAlembert:
    """`system` if it is a nonholonomic system with at least two admissible directions."""
    if not isinstance(system, LiePoissonDAlembert):
        raise TypeError(f"system must be a liepoisson.systems.LiePoissonDAlembert (a nonholonomic system: the "
                        f"map keeps its constraint); got {type(system).__name__}")
    k = system.dim - system.constraints.shape[0]
    if k < 2:
        raise ValueError(f"{system!r} admits a {k}-dimensional space of velocities: a step that keeps a "
                         "quadratic energy there moves nothing (k >= 2 needed)")
    return system


def _rotate(u: jax.Array, angle: jax.Array) -> jax.Array:
    """`u` `(2,)` turned by `angle`: orthogonal to round-off."""
    c, s = jnp.cos(angle), jnp.sin(angle)
    return jnp.stack([c * u[0] - s * u[1], s * u[0] + c * u[1]])


class AbstractDAlembertMap(AbstractLearnedMap, AbstractReconstructingStepMap):
    r"""A learned step of the body velocity $\xi$ of a `LiePoissonDAlembert` system that keeps
    its constraint and a learned quadratic energy exactly, for any weights (module docstring):
    $w = N^\top\xi$, $u = L^\top w$, $u' = $ `advance(u, w)` with $|u'| = |u|$,
    $\xi' = NL^{-\top}u'$. What varies is `advance`."""

    log_diagonal: eqx.AbstractVar[jax.Array]
    lower: eqx.AbstractVar[jax.Array]
    system: eqx.AbstractVar[LiePoissonDAlembert]
    h: eqx.AbstractVar[float | None]

    @abc.abstractmethod
    def advance(self, u: jax.Array, w: jax.Array) -> jax.Array:
        r"""$u'$ `(k,)` from $u = L^\top w$ and $w$ over one step $h$, with $|u'| = |u|$ to
        round-off."""

    #: Training states whose largest relative constraint defect $|C\xi| / (|c_i||\xi|)$
    #: exceeds this are refused: they are not velocities of the system (momenta, most likely),
    #: or noisier than a tenth of their size.
    DATA_DEFECT_MAX = 0.1

    def check_data(self, states: np.ndarray, what: str) -> None:
        """`ValueError` unless `states` are admissible body velocities (to `DATA_DEFECT_MAX`)."""
        C = self.system.constraints
        size = np.linalg.norm(states, axis=-1, keepdims=True)
        defect = np.abs(states @ C.T) / (np.linalg.norm(C, axis=1) * np.where(size > 0, size, 1.0))
        worst = float(np.max(defect, initial=0.0))
        if worst > self.DATA_DEFECT_MAX:
            raise ValueError(
                f"{what} are not admissible body velocities of {self.system!r}: a state's constraint defect "
                f"|C xi| / (|c| |xi|) is {worst:.3g} (at most {self.DATA_DEFECT_MAX} accepted). A DAlembertMap steps "
                "body velocities (system.body_velocity of the momenta, or a gyroscope's readings), not momenta")

    @property
    def basis(self) -> np.ndarray:
        r"""$N$ `(dim, k)`: the orthonormal basis of the admissible velocities $\ker C$ in which
        the map works, $w = N^\top\xi$ (the same on every machine: `LiePoissonDAlembert.admissible_basis`)."""
        return self.system.admissible_basis()

    @property
    def k(self) -> int:
        """The dimension of the admissible velocities, `dim` minus the constraints."""
        return self.system.dim - self.system.constraints.shape[0]

    def metric_factor(self) -> jax.Array:
        r"""$L$ `(k, k)`, lower triangular with $\det L = 1$: the learned energy is
        $\tfrac12|L^\top N^\top\xi|^2$."""
        k = self.k
        d = self.log_diagonal - jnp.mean(self.log_diagonal)
        rows, cols = np.tril_indices(k, -1)
        return jnp.diag(jnp.exp(d)).at[rows, cols].set(self.lower)

    def energy(self, xi: jax.Array) -> jax.Array:
        r"""The learned energy $\tfrac12|L^\top N^\top\xi|^2$ (its scale fixed by $\det L = 1$),
        shape `(...)`: what every step keeps."""
        u = jnp.einsum("...a,ak,kj->...j", jnp.asarray(xi), jnp.asarray(self.system.admissible_basis()),
                       self.metric_factor())
        return 0.5 * jnp.sum(u * u, axis=-1)

    def step(self, xi: jax.Array) -> jax.Array:
        xi = check_state(xi, self.system.dim)
        check_h(self)  # a map without a step refuses here
        N = jnp.asarray(self.system.admissible_basis())
        L = self.metric_factor()
        w = N.T @ xi
        u_next = self.advance(L.T @ w, w)
        w_next = jax.scipy.linalg.solve_triangular(L.T, u_next, lower=False)
        return N @ w_next

    def lifted_step(self, g: jax.Array, xi: jax.Array) -> tuple[jax.Array, jax.Array]:
        xi_next = self.step(xi)
        h = check_h(self)
        return self.system.require_group().right_exp(g, 0.5 * h * (xi + xi_next)), xi_next

    @property
    def exact_flows_per_step(self) -> int:
        return 0


class DAlembertMap(AbstractDAlembertMap):
    r"""A learned step $\xi \mapsto \xi'$ of the body velocity of a `LiePoissonDAlembert`
    system that keeps its constraint and a learned quadratic energy on the constraint subspace
    exactly (module docstring). Fitted by `learn.fit` to `integrators.Trajectories` or
    `integrators.Observations` whose states are **body velocities** (`system.body_velocity` of
    the momenta, or a gyroscope's readings).

    `lifted_step(g, xi)` carries the configuration with the mean velocity of the step,
    $g' = g\exp\bigl(\tfrac h2(\xi + \xi')\bigr)$ (order 2; admissible, so a knife edge does
    not slip sideways within the step): where the sleigh is and where it points.

    **Arguments:** `system`, a `liepoisson.systems.LiePoissonDAlembert`; `hidden`, `activation`,
    `key`: the network from $w$ ($k$) to the $k(k-1)/2$ entries of $\Omega$ (default two hidden
    layers of 16, tanh); `h`; or `network`, any `learn.AbstractNetwork` of those sizes.
    """

    network: AbstractNetwork
    log_diagonal: jax.Array
    lower: jax.Array
    system: LiePoissonDAlembert = eqx.field(static=True)
    h: float | None

    def __init__(self, system: LiePoissonDAlembert, hidden: Sequence[int] | None = None,
                 activation: str | None = None, key: int | jax.Array | None = None, h: float | None = None, *,
                 network: AbstractNetwork | None = None):
        self.system = _checked_system(system)
        k = self.k
        n_out = k * (k - 1) // 2
        if network is None:
            network = AffineMLP(k, n_out, hidden=tuple(hidden) if hidden is not None else (16, 16),
                                activation=activation or "tanh", key=0 if key is None else key)
        elif hidden is not None or activation is not None or key is not None:
            raise ValueError("give network= or hidden/activation/key, not both")
        self.network = check_network(network, k, n_out, "admissible velocities to the rotation's generator")
        self.log_diagonal = jnp.zeros(k)
        self.lower = jnp.zeros(n_out)
        self.h = None if h is None else positive_float(h, "h")

    def generator(self, w: jax.Array) -> jax.Array:
        r"""$\Omega(w)$, the skew-symmetric `(k, k)` generator per unit time at the admissible
        velocity $w = N^\top\xi$."""
        k = self.k
        rows, cols = np.tril_indices(k, -1)
        entries = self.network(w)
        G = jnp.zeros((k, k), dtype=entries.dtype).at[rows, cols].set(entries)
        return G - G.T

    def advance(self, u: jax.Array, w: jax.Array) -> jax.Array:
        r"""$u' = \exp(h\,\Omega(w))\,u$."""
        A = check_h(self) * self.generator(w)
        if self.k == 2:  # the rotation in closed form: orthogonal to round-off
            return _rotate(u, A[1, 0])
        return jax.scipy.linalg.expm(A) @ u

    def hyperparameters(self) -> dict[str, Any]:
        return {"network": self.network.spec()}

    def reinitialised(self, key):
        """Fresh network weights from `key` and the identity metric."""
        return eqx.tree_at(lambda m: (m.network, m.log_diagonal, m.lower), self,
                           (self.network.reinitialised(key), jnp.zeros_like(self.log_diagonal),
                            jnp.zeros_like(self.lower)))

    @classmethod
    def from_hyperparameters(cls, system, hyperparameters, *, key=0, h=None):
        return cls(system, h=h, network=network_from_spec(hyperparameters["network"], key))


#: Below this $x = hA$ the closed form's $\tanh x / x$, $\operatorname{sech} x$ and
#: $(1 - \operatorname{sech} x)/x^2$ are their Taylor series (truncation ~x^4 / 10 < 1e-17).
_SERIES_BELOW = 1e-4


class QuadraticDAlembertMap(AbstractDAlembertMap):
    r"""The family of every quadratic energy on a two-dimensional constraint subspace ($k = 2$:
    the Suslov problem, the Chaplygin sleigh), stepped by its **exact flow** in closed form.

    With $H$ quadratic, the motion on $\mathfrak d$ is a quadratic vector field that keeps
    $\tfrac12 w^\top LL^\top w$; in $u = L^\top w$ it is $\dot u = (c\cdot u)\,Ju$ for a
    vector $c$ ($J$ the quarter turn): every such field is of this form, and the family has
    four identifiable parameters ($c$; $L$ lower triangular with $\det L = 1$), those of the
    system. With $A = |c||u|$, $p = c\cdot u$, $q = c\times u$, the angle $\psi$ of $u$ from
    $c$ obeys $\dot\psi = A\cos\psi$, so $\sin\psi(t) = \tanh(At + \operatorname{artanh}
    \sin\psi_0)$ and

    $$u(h) \propto \frac{\operatorname{sech}(hA)\,u + |u|^2\bigl(q\,h^2\sigma(hA) +
    h\tanh(hA)/(hA)\bigr)Jc}{1 + q\,h\tanh(hA)/(hA)}, \qquad
    \sigma(x) = \frac{1 - \operatorname{sech}x}{x^2},$$

    smooth at $A = 0$; the step turns $u$ by the angle from $u$ to $u(h)$, so $|u|$ is kept to
    round-off. Fitted like `DAlembertMap` (body velocities); `from_system` gives the exact flow
    of a known system. `lifted_step` is `DAlembertMap`'s (order 2 in the configuration).

    **A mirror symmetry** (`reflection=i`): the motions of a body symmetric under the
    reflection $S$ that flips the $i$-th direction of the basis $N$ (`basis`) are mapped to
    motions by $S$. The family's members with that symmetry are those with a diagonal $L$ and
    $c$ along $e_i$ ($JS = -SJ$ in the plane, so $f(Sw) = Sf(w)$ needs $Sc = -c$); with
    `reflection` the others are left out, and the steady motions $c\cdot u = 0$ lie exactly on
    the mirror line $w_i = 0$ for any fitted weights. The Chaplygin sleigh ($N = (e_\omega,
    e_v)$) with `reflection=0`: $\omega \to -\omega$ (the reflection of the plane through the
    blade), so its straight line ($\omega = 0$) is exact, however noisy the data.

    **Arguments:** `system`, a `liepoisson.systems.LiePoissonDAlembert` with $k = 2$ and a
    quadratic Hamiltonian; `h`; `key` is accepted and unused (the fit starts at $c = 0$, the
    identity metric: restarts repeat the same fit); `reflection`: `None` (default) or the
    index 0 or 1 of the basis direction a mirror symmetry flips.
    """

    rate: jax.Array
    log_diagonal: jax.Array
    lower: jax.Array
    system: LiePoissonDAlembert = eqx.field(static=True)
    h: float | None
    reflection: int | None = eqx.field(static=True)

    def __init__(self, system: LiePoissonDAlembert, key: int | jax.Array | None = None, h: float | None = None,
                 reflection: int | None = None):
        del key  # the family's start is fixed
        self.system = _checked_system(system)
        if self.k != 2:
            raise ValueError(f"{system!r} admits a {self.k}-dimensional space of velocities: the quadratic family's "
                             "exact flow is in closed form for k = 2 (the Suslov problem, the Chaplygin sleigh); "
                             "use learn.DAlembertMap, whose network generator takes any k")
        if reflection is not None and (isinstance(reflection, (bool, np.bool_)) or not isinstance(
                reflection, (int, np.integer)) or reflection not in (0, 1)):
            raise ValueError(f"reflection must be None or the index 0 or 1 of the basis direction of the admissible "
                             f"velocities that a mirror symmetry flips (QuadraticDAlembertMap.basis); got {reflection!r}")
        self.reflection = None if reflection is None else int(reflection)
        self.rate = jnp.zeros(2)
        self.log_diagonal = jnp.zeros(2)
        self.lower = jnp.zeros(1)
        self.h = None if h is None else positive_float(h, "h")

    @classmethod
    def from_system(cls, system: LiePoissonDAlembert, h: float | None = None) -> QuadraticDAlembertMap:
        r"""The member of the family that is `system`'s exact flow: $LL^\top$ the metric
        $N^\top\mathbb M N$ scaled to $\det = 1$ (with $\mathbb M$ the inverse Hessian of the
        quadratic $H$), $c$ from the vector field at two velocities. `ValueError` if $H$ is
        not quadratic."""
        model = cls(system, h=h)
        M = system.kinetic_metric()
        N = system.admissible_basis()
        Mw = N.T @ M @ N
        L = np.linalg.cholesky(Mw / np.sqrt(np.linalg.det(Mw)))
        model = eqx.tree_at(lambda m: (m.log_diagonal, m.lower), model,
                            (jnp.asarray(np.log(np.diag(L))), jnp.asarray(L[1:, :1].ravel())))
        # omega(u) = c . u = (Ju) . du/dt / |u|^2 at u = e_1, e_2
        rate = []
        for u in np.eye(2):
            w = np.linalg.solve(L.T, u)
            xi_dot = np.linalg.solve(M, np.asarray(system.vector_field(jnp.asarray(M @ (N @ w)))))
            u_dot = L.T @ (N.T @ xi_dot)
            rate.append(np.array([-u[1], u[0]]) @ u_dot)
        return eqx.tree_at(lambda m: m.rate, model, jnp.asarray(rate))

    def metric_factor(self) -> jax.Array:
        L = super().metric_factor()
        return L if self.reflection is None else jnp.diag(jnp.diag(L))

    def rate_vector(self) -> jax.Array:
        r"""$c$ of $\dot u = (c\cdot u)\,Ju$: the fitted `rate`, along $e_i$ alone with `reflection=i`."""
        return self.rate if self.reflection is None else self.rate * jnp.eye(2)[self.reflection]

    def advance(self, u: jax.Array, w: jax.Array) -> jax.Array:
        h = check_h(self)
        c = self.rate_vector()
        p = c @ u
        q = c[0] * u[1] - c[1] * u[0]
        r2 = u @ u
        x2 = h * h * (p * p + q * q)  # (h A)^2, A = |c| |u|
        small = x2 < _SERIES_BELOW**2
        x2s = jnp.where(small, 1.0, x2)  # the other branch's argument, kept finite for gradients
        x = jnp.sqrt(x2s)
        sech = jnp.where(small, 1.0 - x2 / 2 + 5 * x2 * x2 / 24, 1.0 / jnp.cosh(x))
        tau = h * jnp.where(small, 1.0 - x2 / 3, jnp.tanh(x) / x)  # tanh(hA) / A
        sigma = jnp.where(small, 0.5 - 5 * x2 / 24, (1.0 - 1.0 / jnp.cosh(x)) / x2s)
        Jc = jnp.stack([-c[1], c[0]])
        target = (sech * u + r2 * (q * h * h * sigma + tau) * Jc) / (1.0 + q * tau)
        # the turn from u to u(h): atan2 of the cross and dot products (0 for u = 0)
        cross = u[0] * target[1] - u[1] * target[0]
        dot = u @ target
        moving = r2 > 0
        angle = jnp.where(moving, jnp.arctan2(cross, jnp.where(moving, dot, 1.0)), 0.0)
        return _rotate(u, angle)

    def hyperparameters(self) -> dict[str, Any]:
        return {"reflection": self.reflection}

    def reinitialised(self, key):
        """The map itself: the family starts at c = 0 whatever the key."""
        return self

    def default_optimiser(self):
        """Levenberg-Marquardt, 100 steps (four parameters)."""
        return (KeepIfBetter(LevenbergMarquardt(100)),)
