r"""G-LPNets (paper section "G-LPNets: Derivation and test cases"): compositions of modules
$\widetilde{\mathbb T}_s y = \exp\!\big(\tfrac hM\,q_s(y)\,\mathbb M(\alpha_s)\big)y$,
$q_s = a_s\,\sigma(\langle\alpha_s, y\rangle) + b_s$ (eq. G_LPNets_moduli).

Each module is the exact flow of $\varphi_s(\langle\alpha_s, y\rangle)$ with
$\varphi_s' = a_s\sigma + b_s$, because $\langle\alpha_s, y\rangle$ is conserved along the flow
of a linear test Hamiltonian $\langle\alpha_s, y\rangle$: every module, hence the network, is an
exact Poisson map.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from integrators._step_map import check_state
from liepoisson._validation import check_system, positive_float, positive_int
from liepoisson.systems import AbstractPoissonSystem

from ._base import AbstractLearnedMap
from ._mlp import ACTIVATIONS, as_key, check_activation


def _check_order(order: Sequence[int] | None, n_modules: int, dim: int) -> tuple[int, ...]:
    if order is None:
        return tuple(s % dim for s in range(n_modules))
    try:
        order = tuple(order)
    except TypeError as err:
        raise TypeError(f"order must be a sequence of basis indices; got {order!r}") from err
    if len(order) != n_modules:
        raise ValueError(f"order must have n_modules = {n_modules} entries; got {len(order)}")
    for s, k in enumerate(order):
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 0 <= k < dim:
            raise ValueError(f"order[{s}] must be a basis index in [0, {dim}); got {k!r}")
    return tuple(int(k) for k in order)


class GLPNet(AbstractLearnedMap):
    r"""Global Lie-Poisson network: $M$ modules $\widetilde{\mathbb T}_s$, each a rescaled exact
    test flow over $h/M$ (paper eqs. G_LPNets_moduli, Loss_function_G_LPNets).

    By default $\alpha_s = c_s\,e_{k(s)}$ with $k$ cycling over the basis ($e_1, e_2, e_3, e_1,
    \ldots$, paper eq. Rot_sequence): three scalars $(a_s, c_s, b_s)$ per module, 18 parameters
    for 6 modules. `full_vectors=True` learns $\alpha_s\in\mathbb R^n$. Exactly Poisson and
    Casimir-conserving for any parameters. Trained by default with BFGS and the identity warm
    start (`learn.fit(gnet, data)`, see `learn.QuasiNewton`).

    **Arguments:** `system`; `n_modules` $M$; `order` of the basis vectors (default cycling);
    `key`; `full_vectors`; `activation` $\sigma$ (paper: sigmoid); `h` (`None`: set by
    `learn.fit`).
    """

    a: jax.Array
    c: jax.Array
    b: jax.Array
    activation: str
    system: AbstractPoissonSystem = eqx.field(static=True)
    order: tuple[int, ...] = eqx.field(static=True)
    full_vectors: bool = eqx.field(static=True)
    h: float | None

    def __init__(
        self,
        system: AbstractPoissonSystem,
        n_modules: int = 6,
        order: Sequence[int] | None = None,
        key: int | jax.Array = 0,
        *,
        full_vectors: bool = False,
        activation: str = "sigmoid",
        h: float | None = None,
    ):
        self.system = check_system(system)
        n_modules = positive_int(n_modules, "n_modules")
        self.order = _check_order(order, n_modules, system.dim)
        self.full_vectors = bool(full_vectors)
        self.activation = check_activation(activation)
        self.h = None if h is None else positive_float(h, "h")
        ka, kc, kb = jax.random.split(as_key(key), 3)
        shape = (n_modules, system.dim) if self.full_vectors else (n_modules,)
        self.a = jax.random.normal(ka, (n_modules,), jnp.float64)
        self.c = jax.random.normal(kc, shape, jnp.float64)
        self.b = 0.1 * jax.random.normal(kb, (n_modules,), jnp.float64)

    @property
    def n_modules(self) -> int:
        return len(self.order)

    def module_vectors(self) -> jax.Array:
        r"""The vectors $\alpha_s$, shape `(n_modules, dim)`."""
        if self.full_vectors:
            return self.c
        return self.c[:, None] * jnp.eye(self.system.dim)[jnp.asarray(self.order)]

    def step(self, y: jax.Array) -> jax.Array:
        y = check_state(y, self.system.dim)
        act = ACTIVATIONS[self.activation]
        vectors = self.module_vectors()
        dt = self.h / self.n_modules
        for s in range(self.n_modules):
            alpha = vectors[s]
            q = self.a[s] * act(jnp.dot(alpha, y)) + self.b[s]
            y = self.system.test_flow(q * alpha, dt, y)
        return y

    @property
    def exact_flows_per_step(self) -> int:
        return self.n_modules

    def hyperparameters(self) -> dict[str, Any]:
        return {
            "n_modules": self.n_modules,
            "order": list(self.order),
            "full_vectors": self.full_vectors,
            "activation": self.activation,
        }


def linear_to_activation(net: GLPNet, linear: GLPNet, X: jax.Array, width: float = 0.05) -> GLPNet:
    r"""The `net` (activation $\sigma$) that reproduces the identity-activation `linear` to
    first order in the linear regime of $\sigma$.

    With $\alpha'_s = \epsilon_s\alpha_s$ the rate $q'_s\alpha'_s$ must equal $q_s\alpha_s$, so
    $q'_s = (a_s\langle\alpha_s, y\rangle + b_s)/\epsilon_s$. With
    $\sigma(x) \approx \sigma_0 + \sigma_1 x$: $a'_s = a_s/(\sigma_1\epsilon_s^2)$,
    $b'_s = b_s/\epsilon_s - \sigma_0 a'_s$. $\epsilon_s$ keeps
    $|\epsilon_s\langle\alpha_s, y\rangle| \le$ `width` on the data, where the neglected
    curvature is a relative $O(\text{width}^2)$.
    """
    act = ACTIVATIONS[net.activation]
    s0, s1 = float(act(0.0)), float(jax.grad(act)(0.0))
    if s1 == 0.0:
        raise ValueError(f"warm start needs an activation with sigma'(0) != 0; {net.activation!r} has 0")
    vectors = linear.module_vectors()
    spread = jnp.max(jnp.abs(X @ vectors.T), axis=0)  # max |<alpha_s, y>| over the data
    eps = width / jnp.maximum(spread, 1e-300)
    a = linear.a / (s1 * eps**2)
    b = linear.b / eps - s0 * a
    c = linear.c * (eps[:, None] if net.full_vectors else eps)
    return eqx.tree_at(lambda n: (n.a, n.c, n.b), net, (a, c, b))


