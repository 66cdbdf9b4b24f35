r"""Learned dissipation for G-LPNets: a drag $F(\xi) = -D(\xi)\,\xi$ with $D(\xi)$ symmetric
positive semidefinite for every weight (`LearnedDrag`), and a G-LPNet composed with its flow
(`Dissipative`), whose dissipative sub-step never increases the learned energy."""

from __future__ import annotations

import functools
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from integrators.internals import check_state, composition_flops
from integrators.splitting import FlowList
from liepoisson.systems import forces_flow

from ._base import AbstractBodyMap
from ._glpnet import GLPNet

#: The families of `LearnedDrag` (`kind`).
DRAG_KINDS = ("linear", "quadratic", "ridge")


def _safe_norm(x: jax.Array) -> jax.Array:
    """$|x|$ over the last axis, with derivative 0 (not NaN) at 0."""
    s = jnp.sum(x * x, axis=-1)
    positive = s > 0.0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, s, 1.0)), 0.0)


class LearnedDrag(eqx.Module):
    r"""A learned drag in the body frame, $F(\xi) = -D(\xi)\,\xi$, with a Rayleigh dissipation
    function $R(\xi) \ge 0$ where one exists; $D(\xi)$ is positive semidefinite for every weight,
    so $\xi\cdot F \le 0$ always:

    - `"linear"`: $D = LL^\top$ ($R = \tfrac12\xi^\top D\xi$, viscous);
    - `"quadratic"`: $D(\xi) = |\xi|\,LL^\top$ (aerodynamic drag, $F = -|\xi|D\xi$);
    - `"ridge"`: $D(\xi) = \sum_k (p_k^2 + q_k^2|\langle w_k, \xi\rangle|)\,w_kw_k^\top$, a learned
      $R = \sum_k p_k^2 s_k^2/2 + q_k^2|s_k|^3/3$ of $s_k = \langle w_k, \xi\rangle$: linear and
      quadratic drag along each learned direction (a flat body's plates).

    With `any_axes` the factor $L$ (or the directions $w_k$) is a full matrix; without, it is
    diagonal (the basis axes). `scale` sets the start, $D \approx$ `scale` times the identity
    (a nonzero start: $LL^\top$ has no gradient at $L = 0$).
    """

    kind: str = eqx.field(static=True)
    any_axes: bool = eqx.field(static=True)
    factor: jax.Array  # L (dim, dim) or its diagonal (dim,); for "ridge", p (dim,)
    quadratic_factor: jax.Array | None  # "ridge": q (dim,)
    directions: jax.Array | None  # "ridge" with any_axes: w_k as rows (dim, dim)

    def __init__(self, dim: int, kind: str = "quadratic", *, any_axes: bool = False, scale: float = 1e-2):
        if kind not in DRAG_KINDS:
            raise ValueError(f"kind must be one of {DRAG_KINDS}; got {kind!r}")
        if not isinstance(dim, (int, np.integer)) or isinstance(dim, bool) or dim < 1:
            raise TypeError(f"dim must be a positive int; got {dim!r}")
        scale = float(scale)
        if not np.isfinite(scale) or scale <= 0.0:
            raise ValueError(f"scale must be finite and > 0 (the start's drag size); got {scale!r}")
        self.kind = kind
        self.any_axes = bool(any_axes)
        root = np.sqrt(scale)
        if kind == "ridge":
            self.factor = jnp.full(dim, root)
            self.quadratic_factor = jnp.full(dim, root)
            self.directions = jnp.eye(dim) if any_axes else None
        else:
            self.factor = jnp.eye(dim) * root if any_axes else jnp.full(dim, root)
            self.quadratic_factor = None
            self.directions = None

    @property
    def dim(self) -> int:
        return self.factor.shape[0]

    @property
    def constant(self) -> bool:
        """Whether $D$ does not depend on $\\xi$ (linear drag: the exact flow)."""
        return self.kind == "linear"

    def matrix(self, xi: jax.Array) -> jax.Array:
        r"""$D(\xi)$ `(dim, dim)` for one body velocity `(dim,)`."""
        if self.kind == "ridge":
            W = jnp.eye(self.dim) if self.directions is None else self.directions
            s = W @ xi
            weights = self.factor**2 + self.quadratic_factor**2 * jnp.abs(s)
            return (W.T * weights) @ W
        L = self.factor if self.any_axes else jnp.diag(self.factor)
        D = L @ L.T
        return D if self.kind == "linear" else _safe_norm(xi) * D

    def force(self, xi: jax.Array) -> jax.Array:
        r"""$F(\xi) = -D(\xi)\xi$ for one body velocity."""
        return -self.matrix(xi) @ xi

    def spec(self) -> dict[str, Any]:
        return {"kind": self.kind, "any_axes": self.any_axes}


class Dissipative(AbstractBodyMap):
    r"""A G-LPNet composed with the flow of a learned drag: the splitting `net.method` of the
    pieces of $\widetilde H$ (exact Poisson flows) and of $\dot\mu = F(\nabla\widetilde H(\mu))$,
    the drag last (Strang: the middle, full step), as `integrators.ForcedSplitting` composes a
    known Hamiltonian with known forces.

    The drag's flow is `liepoisson.systems.forces_flow` at the learned $\widetilde H$, which
    must be quadratic (a G-LPNet with the identity activation): exact for a linear drag, else
    the midpoint discrete gradient, so that **the drag's sub-step never increases
    $\widetilde H$, for any weights of the net and of the drag and any step $t > 0$**
    ($\widetilde H(\mu_1) - \widetilde H(\mu_0) = -t\,\bar\xi^\top D\bar\xi$). The pieces'
    flows are Poisson maps, the drag's is not: the map is not Poisson and does not keep the
    Casimirs (air drag takes angular momentum away); the configuration is carried exactly on
    the pieces and held on the drag's sub-step.

    **Arguments:** `net`, a `learn.GLPNet` with the identity activation; `drag`, a
    `learn.LearnedDrag` of the same dimension.
    """

    net: GLPNet
    drag: LearnedDrag

    def __init__(self, net: GLPNet, drag: LearnedDrag):
        if not isinstance(net, GLPNet):
            raise TypeError(f"net must be a learn.GLPNet; got {type(net).__name__}")
        if not isinstance(drag, LearnedDrag):
            raise TypeError(f"drag must be a learn.LearnedDrag; got {type(drag).__name__}")
        if net.activation != "identity":
            raise ValueError(
                f"net must have the identity activation (a quadratic learned Hamiltonian): the drag's "
                f"energy-decreasing step needs grad H affine; got activation {net.activation!r}")
        if drag.dim != net.system.dim:
            raise ValueError(f"drag is of dimension {drag.dim}; the net's system {net.system!r} has {net.system.dim}")
        self.net = net
        self.drag = drag

    @property
    def system(self):
        return self.net.system

    @property
    def h(self) -> float | None:
        return self.net.h

    @property
    def method(self):
        return self.net.method

    def quadratic_part(self) -> tuple[jax.Array, jax.Array]:
        r"""`(A, b)` with $\nabla\widetilde H(\mu) = A\mu + b$."""
        zero = jnp.zeros(self.system.dim)
        return jax.jacfwd(self.net.body_velocity)(zero), self.net.body_velocity(zero)

    def drag_flow(self, t: Any, y: jax.Array) -> jax.Array:
        r"""The learned drag's flow over `t` from one state (`liepoisson.systems.forces_flow`)."""
        A, b = self.quadratic_part()
        return forces_flow(A, b, self.drag.matrix, None, jnp.asarray(t, dtype=y.dtype), y,
                           constant=self.drag.constant)

    def flows(self) -> FlowList:
        n = self.net.n_modules
        return FlowList([functools.partial(self.net.module_flow, s) for s in range(n)] + [self.drag_flow])

    def step(self, y: jax.Array) -> jax.Array:
        return self.method.compose(self.flows(), check_state(y, self.system.dim), self.h)

    def _lifted_drag(self, t, gy):
        g, y = gy
        return g, self.drag_flow(t, y)

    def lifted_step(self, g: jax.Array, y: jax.Array) -> tuple[jax.Array, jax.Array]:
        group = self.system.require_group()
        net = self.net
        lifted = [functools.partial(lambda s, t, gy: net.terms.lifted_flow(net.system, s, t / net._time_divisor, gy), s)
                  for s in range(net.n_modules)]
        return self.method.compose(FlowList([*lifted, self._lifted_drag]),
                                   (group.check(g, "g"), check_state(y, self.system.dim)), self.h)

    def body_velocity(self, y: jax.Array) -> jax.Array:
        return self.net.body_velocity(y)

    def hamiltonian(self, y: Any) -> jax.Array:
        return self.net.hamiltonian(y)

    @property
    def exact_flows_per_step(self) -> int:
        return self.method.flows_per_step(self.net.n_modules + 1)

    def step_flops(self) -> float:
        return composition_flops(self, self.method)

    def hyperparameters(self) -> dict[str, Any]:
        return {"net": self.net.hyperparameters(), "drag": self.drag.spec()}

    def reinitialised(self, key):
        return eqx.tree_at(lambda m: m.net, self, self.net.reinitialised(key))

    @classmethod
    def from_hyperparameters(cls, system, hyperparameters, *, key=0, h=None):
        net = GLPNet.from_hyperparameters(system, hyperparameters["net"], key=key, h=h)
        return cls(net, LearnedDrag(system.dim, **hyperparameters["drag"]))

    def default_optimiser(self):
        return self.net.default_optimiser()
