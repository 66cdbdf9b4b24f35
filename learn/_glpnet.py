r"""G-LPNets (paper section "G-LPNets: Derivation and test cases"): compositions of modules
$\widetilde{\mathbb T}_s y = \exp\!\big(\tfrac hM\,q_s(y)\,\mathbb M(\alpha_s)\big)y$,
$q_s = a_s\,\sigma(\langle\alpha_s, y\rangle) + b_s$ (eq. G_LPNets_moduli).

Each module is the exact flow of $\varphi_s(\langle\alpha_s, y\rangle)$ with
$\varphi_s' = a_s\sigma + b_s$, because $\langle\alpha_s, y\rangle$ is conserved along the flow
of a linear test Hamiltonian $\langle\alpha_s, y\rangle$: every module, hence the network, is an
exact Poisson map.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from integrators._splitting._strang import strang_compose
from integrators._step_map import check_state
from integrators.splitting import AbstractCompositionMethod
from liepoisson import JAX
from liepoisson._validation import as_state, check_system, positive_float, positive_int
from liepoisson.systems import AbstractPoissonSystem

from ._base import AbstractLearnedMap
from ._mlp import ACTIVATIONS, activation_antiderivative, as_key, check_activation


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

    **Arguments:** `system`; `n_modules` $M$ (default $2n$ for a system of dimension $n$:
    each basis direction twice, the paper's 6 for so(3)); `order` of the basis vectors (default cycling);
    `key`; `full_vectors`; `activation` $\sigma$ (paper: sigmoid); `h` (`None`: set by
    `learn.fit`); `symmetric`: the data-driven Strang splitting below; `linear_term`: a fourth
    scalar per module, $q_s = a_s\sigma(x) + e_s x + b_s$ with $x = \langle\alpha_s, y\rangle$,
    so that a quadratic piece of $\widetilde H$ is exact and the sigmoid carries the rest. A
    sigmoid alone is linear only in the limit $c_s \to 0$, and its cubic term,
    $-a_sc_s^3x^3/48$, has the opposite sign to its linear term $a_sc_sx/4$: it cannot fit
    $\Phi_s' = x/I - 0.1\sin x$.

    **As a splitting method.** Module $s$ is the exact flow of the ridge Hamiltonian
    $\Phi_s(\langle\alpha_s, y\rangle)$, $\Phi_s' = a_s\sigma + b_s$, so the network is a
    splitting of the learned Hamiltonian $\widetilde H = w\sum_s\Phi_s(\langle\alpha_s, y\rangle)$
    (`hamiltonian`). The paper's network (default) applies each module over $h/M$: Lie-Trotter
    for $\widetilde H$ with $w = 1/M$, order 1. `symmetric=True` applies modules $1..M-1$ over
    $h/2$, module $M$ over $h$, then $M-1..1$ over $h/2$ ($2M - 1$ flows): Strang for
    $\widetilde H$ with $w = 1$, symmetric and of order 2 in $h$, so it can be run at other step
    sizes (`with_h`) and inside the compositions of `integrators.splitting` through
    `learned_system()` (e.g. `it.splitting.Yoshida6(gnet.learned_system(), h)`).
    """

    a: jax.Array
    c: jax.Array
    b: jax.Array
    e: jax.Array | None
    activation: str
    system: AbstractPoissonSystem = eqx.field(static=True)
    order: tuple[int, ...] = eqx.field(static=True)
    full_vectors: bool = eqx.field(static=True)
    symmetric: bool = eqx.field(static=True)
    linear_term: bool = eqx.field(static=True)
    h: float | None

    def __init__(
        self,
        system: AbstractPoissonSystem,
        n_modules: int | None = None,
        order: Sequence[int] | None = None,
        key: int | jax.Array = 0,
        *,
        full_vectors: bool = False,
        activation: str = "sigmoid",
        h: float | None = None,
        symmetric: bool = False,
        linear_term: bool = False,
    ):
        self.system = check_system(system)
        # Default: every basis direction twice (the paper's 6 modules for so(3)), so that any
        # algebra's G-LPNet can rotate about each axis on both sides of the others.
        n_modules = 2 * system.dim if n_modules is None else positive_int(n_modules, "n_modules")
        self.order = _check_order(order, n_modules, system.dim)
        self.full_vectors = bool(full_vectors)
        if not isinstance(symmetric, (bool, np.bool_)):
            raise TypeError(f"symmetric must be True or False; got {symmetric!r}")
        self.symmetric = bool(symmetric)
        if not isinstance(linear_term, (bool, np.bool_)):
            raise TypeError(f"linear_term must be True or False; got {linear_term!r}")
        self.linear_term = bool(linear_term)
        self.activation = check_activation(activation)
        self.h = None if h is None else positive_float(h, "h")
        ka, kc, kb = jax.random.split(as_key(key), 3)
        shape = (n_modules, system.dim) if self.full_vectors else (n_modules,)
        self.a = jax.random.normal(ka, (n_modules,), jnp.float64)
        self.c = jax.random.normal(kc, shape, jnp.float64)
        self.b = 0.1 * jax.random.normal(kb, (n_modules,), jnp.float64)
        self.e = jnp.zeros(n_modules, jnp.float64) if self.linear_term else None

    @property
    def n_modules(self) -> int:
        return len(self.order)

    def module_vectors(self) -> jax.Array:
        r"""The vectors $\alpha_s$, shape `(n_modules, dim)`."""
        if self.full_vectors:
            return self.c
        return self.c[:, None] * jnp.eye(self.system.dim)[jnp.asarray(self.order)]

    def module_flow(self, s: int, t: float, y: jax.Array) -> jax.Array:
        r"""The exact flow of $\Phi_s(\langle\alpha_s, y\rangle)$ for time `t`: the test flow
        with the rate $q_s = a_s\sigma(\langle\alpha_s, y\rangle) + b_s$ (+ $e_s\langle\alpha_s,
        y\rangle$ with `linear_term`) frozen (it is conserved)."""
        alpha = self.module_vectors()[s]
        x = jnp.dot(alpha, y)
        q = self.a[s] * ACTIVATIONS[self.activation](x) + self.b[s]
        if self.linear_term:
            q = q + self.e[s] * x
        return self.system.test_flow(q * alpha, t, y)

    def step(self, y: jax.Array) -> jax.Array:
        y = check_state(y, self.system.dim)
        if self.symmetric:
            flows = [functools.partial(self.module_flow, s) for s in range(self.n_modules)]
            return strang_compose(flows, y, self.h)
        dt = self.h / self.n_modules
        for s in range(self.n_modules):
            y = self.module_flow(s, dt, y)
        return y

    @property
    def exact_flows_per_step(self) -> int:
        return 2 * self.n_modules - 1 if self.symmetric else self.n_modules

    @property
    def hamiltonian_weight(self) -> float:
        r"""$w$ in $\widetilde H = w\sum_s\Phi_s$: 1 (symmetric, Strang) or $1/M$ (Lie-Trotter)."""
        return 1.0 if self.symmetric else 1.0 / self.n_modules

    def hamiltonian(self, y: ArrayLike) -> jax.Array:
        r"""The learned Hamiltonian $\widetilde H(y) = w\sum_s\Phi_s(\langle\alpha_s, y\rangle)$
        (up to a constant), shape `(...)` for `y` of shape `(..., dim)`. Needs an activation
        with a closed-form antiderivative (`sigmoid`, `tanh`, `identity`)."""
        y = as_state(y, "y", self.system.dim)
        antiderivative = activation_antiderivative(self.activation)
        s = jnp.einsum("md,...d->...m", self.module_vectors(), y)
        e = 0.0 if self.e is None else self.e
        return self.hamiltonian_weight * jnp.sum(self.a * antiderivative(s, JAX) + 0.5 * e * s**2 + self.b * s, axis=-1)

    def learned_system(self):
        r"""The Poisson system $\dot y = \mathbb B(y)\nabla\widetilde H$ with this network's
        learned Hamiltonian and the system's bracket, split into its ridge pieces (one
        `CollectiveTerm` per module): every method of `integrators.splitting` runs on it, and
        `Strang(gnet.learned_system(), h)` is the symmetric network at step `h`."""
        from ._learned_system import LearnedHamiltonian

        return LearnedHamiltonian(self)

    def composed(self, method: Any) -> GLPNet:
        r"""The symmetric network whose step is the composition `method` of this network's
        Strang step, $S_{\gamma_r h}\circ\cdots\circ S_{\gamma_1 h}$ with the palindromic
        table $\gamma$ of an `integrators.splitting` composition (`TripleJump`, `Suzuki`,
        `McLachlan4`, `Yoshida6`; class or instance): the same map, to round-off, as one
        symmetric `GLPNet`. Adjacent flows of one module merge, and module $s$ run over
        $\gamma h/2$ is module $s$ with $(a_s, b_s, e_s)$ scaled by $\gamma$, so $M$ modules become
        $r(M-1)+1$ (`TripleJump`: $3M-2$).

        The data-driven splitting of higher order: fit a symmetric network (a Strang step, order
        2), compose it, and fit again from there (`learn.fit(..., optimiser=QuasiNewton(...,
        warm_start=False))`), or both in one call with `learn.fit_splitting`; the refit moves
        the pieces from the modified Hamiltonian of the Strang fit to that of the composition. On the algebras of `benchmarks/any_algebra.py`
        this lowers the loss 13x (so(4)) to 4000x (diamond) below the Strang fit's, where a
        `TripleJump`-shaped network trained from the identity warm start stays near a
        Strang-like minimum."""
        gammas = composition_coefficients(method)
        if not self.symmetric:
            raise ValueError(
                "composed needs a symmetric G-LPNet (its step is a Strang step); got symmetric=False: "
                "train GLPNet(system, symmetric=True) and compose that"
            )
        modules, weights = _composed_palindrome(self.n_modules, gammas)
        src = jnp.asarray(modules)
        w = jnp.asarray(weights)
        net = GLPNet(self.system, len(modules), [self.order[m] for m in modules], full_vectors=self.full_vectors,
                     activation=self.activation, h=self.h, symmetric=True, linear_term=self.linear_term)
        net = eqx.tree_at(lambda n: (n.a, n.c, n.b), net, (self.a[src] * w, self.c[src], self.b[src] * w))
        return eqx.tree_at(lambda n: n.e, net, self.e[src] * w) if self.linear_term else net

    def hyperparameters(self) -> dict[str, Any]:
        return {
            "n_modules": self.n_modules,
            "order": list(self.order),
            "full_vectors": self.full_vectors,
            "activation": self.activation,
            "symmetric": self.symmetric,
            "linear_term": self.linear_term,
        }


def composition_coefficients(method: Any) -> np.ndarray:
    r"""The table $\gamma$ of a composition of Strang steps (`integrators.splitting`
    `TripleJump`, `Suzuki`, `McLachlan4`, `Yoshida6`; class or instance)."""
    cls = method if isinstance(method, type) else type(method)
    if not issubclass(cls, AbstractCompositionMethod):
        raise TypeError(
            "method must be a composition of Strang steps from integrators.splitting (TripleJump, "
            f"Suzuki, McLachlan4, Yoshida6), class or instance; got {method!r}"
        )
    return np.asarray(cls.coefficients, dtype=np.float64)


def _composed_palindrome(n_modules: int, gammas: np.ndarray) -> tuple[list[int], list[float]]:
    r"""Modules and weights of the symmetric network equal to $S_{\gamma_r h}\circ\cdots\circ
    S_{\gamma_1 h}$ for a Strang step $S$ of `n_modules` modules: the flows $(s, \tau)$ (module,
    time in units of $h$) of the composition, adjacent flows of one module merged, give a
    palindrome whose first half (run over $h/2$: weight $2\tau$) and centre (run over $h$:
    weight $\tau$) are the new modules."""
    half = list(range(n_modules - 1))
    flows: list[list] = []
    for g in gammas:
        for s, tau in [(s, 0.5 * g) for s in half] + [(n_modules - 1, g)] + [(s, 0.5 * g) for s in reversed(half)]:
            if flows and flows[-1][0] == s:
                flows[-1][1] += tau
            else:
                flows.append([s, tau])
    centre = len(flows) // 2  # the merged list is an odd palindrome since gammas is
    modules = [s for s, _ in flows[: centre + 1]]
    weights = [2.0 * tau for _, tau in flows[:centre]] + [flows[centre][1]]
    return modules, weights


def linear_to_activation(net: GLPNet, linear: GLPNet, X: jax.Array, width: float = 0.05) -> GLPNet:
    r"""The `net` (activation $\sigma$) that reproduces the identity-activation `linear` to
    first order in the linear regime of $\sigma$.

    With $\alpha'_s = \epsilon_s\alpha_s$ the rate $q'_s\alpha'_s$ must equal $q_s\alpha_s$, so
    $q'_s = (a_s\langle\alpha_s, y\rangle + b_s)/\epsilon_s$. With
    $\sigma(x) \approx \sigma_0 + \sigma_1 x$: $a'_s = a_s/(\sigma_1\epsilon_s^2)$,
    $b'_s = b_s/\epsilon_s - \sigma_0 a'_s$. $\epsilon_s$ keeps
    $|\epsilon_s\langle\alpha_s, y\rangle| \le$ `width` on the data, where the neglected
    curvature is a relative $O(\text{width}^2)$.

    With a linear term (`linear_term=True`) the map is exact: $e'_s = a_s + e_s$, $a'_s = 0$,
    $b'_s = b_s$, $\alpha'_s = \alpha_s$, and the sigmoid starts from zero.
    """
    if net.linear_term:
        zero = jnp.zeros_like(linear.a)
        return eqx.tree_at(lambda n: (n.a, n.c, n.b, n.e), net, (zero, linear.c, linear.b, linear.a + linear.e))
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


