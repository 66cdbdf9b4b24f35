r"""An operator network without dynamics: the state at time $t$ straight from the initial one
(DeepONet; Lu, Jin, Pang, Zhang & Karniadakis, Nat. Mach. Intell. 3, 2021). A baseline of
the Latent Lie-Poisson Neural Networks protocol: it takes no step, so nothing carries it past
the times it was trained on."""

from __future__ import annotations

from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from liepoisson.internals import positive_int

from ._mlp import AffineMLP, affine, as_key


class DeepONet(eqx.Module):
    r"""$u(t) = m + s\odot\big(\sum_{k=1}^{p} b_{\cdot k}(u_0)\,\tau_k(t) + c\big)$: a branch
    MLP $b$ of the initial state $u_0$ (`in_size`) to `out_size` x `width` coefficients, a trunk
    MLP $\tau$ of the time to `width` basis functions, a bias $c$, and fixed output scalings
    $(m, s)$ (`rescaled`). One evaluation per time, no step: it interpolates in $(u_0, t)$ and
    has no reason to hold past the training horizon (the point of comparing it).

    **Arguments:** `in_size`, `out_size`; `width` ($p$); `hidden` layer widths and
    `activation` of both MLPs; `key` (int seed or PRNG key).
    """

    branch: AffineMLP
    trunk: AffineMLP
    bias: jax.Array
    in_size: int = eqx.field(static=True)
    out_size: int = eqx.field(static=True)
    width: int = eqx.field(static=True)
    output_shift: tuple[float, ...]
    output_scale: tuple[float, ...]

    def __init__(self, in_size: int, out_size: int, *, width: int = 32, hidden: Sequence[int] = (64, 64),
                 activation: str = "tanh", key: int | jax.Array = 0):
        self.in_size = positive_int(in_size, "in_size")
        self.out_size = positive_int(out_size, "out_size")
        self.width = positive_int(width, "width")
        k1, k2 = jax.random.split(as_key(key))
        self.branch = AffineMLP(self.in_size, self.out_size * self.width, hidden, activation, k1)
        self.trunk = AffineMLP(1, self.width, hidden, activation, k2)
        self.bias = jnp.zeros(self.out_size)
        self.output_shift, self.output_scale = (0.0,) * self.out_size, (1.0,) * self.out_size

    def coefficients(self, u0: jax.Array) -> jax.Array:
        """The branch's coefficients `(out_size, width)` of one initial state."""
        return self.branch(u0).reshape(self.out_size, self.width)

    def basis(self, t: jax.Array) -> jax.Array:
        """The trunk's basis functions `(width,)` at one time."""
        return self.trunk(jnp.reshape(t, (1,)))

    def combine(self, coefficients: jax.Array, basis: jax.Array) -> jax.Array:
        r"""The state `(..., out_size)` of branch coefficients `(..., out_size, width)` and trunk
        basis values `(..., width)`: $m + s\odot(b\,\tau + c)$."""
        u = jnp.einsum("...op,...p->...o", coefficients, basis) + self.bias
        return jnp.asarray(self.output_shift) + jnp.asarray(self.output_scale) * u

    def __call__(self, u0: jax.Array, t: jax.Array) -> jax.Array:
        """The state `(..., out_size)` at the times `t` `(...)` from one initial state `u0`."""
        t = jnp.asarray(t, dtype=jnp.float64)
        tau = jax.vmap(self.basis)(t.reshape(-1))  # (T, width)
        u = self.combine(self.coefficients(jnp.asarray(u0, dtype=jnp.float64))[None], tau)
        return u.reshape(t.shape + (self.out_size,))

    def rescaled(self, u0: ArrayLike, t: ArrayLike, u: ArrayLike) -> DeepONet:
        r"""Scalings from samples: the branch's inputs those of `u0` `(S, in_size)`, the trunk's
        of the times `t` `(N,)`, the output's mean and spread those of the states `u`
        `(N, out_size)` (both MLPs' outputs left at unit scale)."""
        u0, t, u = (np.asarray(a, dtype=np.float64) for a in (u0, t, u))
        if u0.ndim != 2 or u0.shape[1] != self.in_size or u.ndim != 2 or u.shape[1] != self.out_size:
            raise ValueError(f"u0 must have shape (S, {self.in_size}) and u (N, {self.out_size}); got shapes "
                             f"{u0.shape} and {u.shape}")
        in_shift, in_scale = affine(u0, self.in_size)
        t_shift, t_scale = affine(t.reshape(-1, 1), 1)
        out_shift, out_scale = affine(u, self.out_size)
        net = eqx.tree_at(lambda n: (n.branch.input_shift, n.branch.input_scale), self, (in_shift, in_scale))
        net = eqx.tree_at(lambda n: (n.trunk.input_shift, n.trunk.input_scale), net, (t_shift, t_scale))
        return eqx.tree_at(lambda n: (n.output_shift, n.output_scale), net, (out_shift, out_scale))
