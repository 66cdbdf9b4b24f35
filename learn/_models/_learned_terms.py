r"""Learnable collective terms: the pieces $\Phi_s(\langle\alpha_s, y\rangle)$ of a G-LPNet's
learned Hamiltonian, with $\Phi_s' = a_s\sigma(x) + e_s x + b_s$ (the moduli of
[the paper](https://arxiv.org/abs/2308.15349), Sec. 6.1, eq. (73), with an optional linear
term $e_s$).

The flow of $\Phi_s(\langle\alpha_s, y\rangle)$ is the test flow with the frozen parameter
$\Phi_s'(\langle\alpha_s, y\rangle)\,\alpha_s$, because $\langle\alpha_s, y\rangle$ is conserved
along the flow of the linear Hamiltonian $\langle\alpha_s, y\rangle$: every piece is solved
exactly and its flow is a Poisson map."""

from __future__ import annotations

import copy
from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from integrators.splitting import compensated_flow
from liepoisson.internals import positive_float, positive_int
from liepoisson.systems import AbstractPoissonSystem

from ._mlp import ACTIVATIONS, as_key, check_activation, check_init


def ridge_potential(x: Any, a: Any, b: Any, e: Any, antiderivative: Any, xp: Any) -> Any:
    r"""$\Phi(x) = a\,A(x) + \tfrac12 e x^2 + b x$ with $A' = \sigma$ (`antiderivative(x, xp)`),
    on any math namespace `xp` (JAX arrays, or heyoka expressions with float coefficients; a
    float `e` of exactly 0 adds no term): the one formula of a module's Hamiltonian."""
    value = a * antiderivative(x, xp)
    if not (isinstance(e, float) and e == 0.0):
        value = value + 0.5 * e * x * x
    return value + b * x


def _kept(kept: Sequence[bool] | None, n_modules: int, name: str) -> tuple[bool, ...] | None:
    if kept is None:
        return None
    try:
        kept = tuple(kept)
    except TypeError as err:
        raise TypeError(f"{name} must be a sequence of True/False, one per module; got {kept!r}") from err
    if len(kept) != n_modules or not all(isinstance(k, (bool, np.bool_)) for k in kept):
        raise ValueError(f"{name} must be {n_modules} values True/False, one per module; got {kept!r}")
    return tuple(bool(k) for k in kept)


def check_order(order: Sequence[int] | None, n_modules: int, dim: int) -> tuple[int, ...]:
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


class RidgeTerms(eqx.Module):
    r"""$M$ learnable pieces $\Phi_s(\langle\alpha_s, y\rangle)$, $\Phi_s' = a_s\sigma(x) + b_s$
    (+ $e_s x$ with `linear_term`; without `bias`, $b_s = 0$: no linear part of
    $\widetilde H$ from the constants, e.g. for a quadratic $\widetilde H$ without linear terms).

    By default $\alpha_s = c_s\,e_{k(s)}$ with $k$ cycling over the basis (as the sequence
    $\widetilde{\mathbb T}_1\to\widetilde{\mathbb T}_2\to\widetilde{\mathbb T}_3\to\dots$ of
    [the paper](https://arxiv.org/abs/2308.15349), Sec. 6.2, eq. (76)): three scalars
    $(a_s, c_s, b_s)$ per piece; `full_vectors=True` learns
    $\alpha_s\in\mathbb R^n$. A linear term makes a quadratic piece exact and leaves the rest to
    $\sigma$: a sigmoid alone is linear only as $c_s \to 0$, and its cubic term
    $-a_sc_s^3x^3/48$ has the opposite sign to its linear term $a_sc_sx/4$.

    **Arguments:** `dim` of the state; `n_modules` $M$; `order` of the basis vectors (default
    cycling); `key`; `activation` $\sigma$ (paper: sigmoid); `full_vectors`; `linear_term`;
    `bias` (default, and the paper: True); `a_kept`, `b_kept`: which $a_s$ and $b_s$ the
    pieces have (default all): the others are zero and not trained (a piece $b_sx$ alone, or
    $a_sx^2/2$ without a linear part, e.g. a family of quadratics whose terms were selected);
    `init`: `"random"` (default, the paper's: $a_s, c_s \sim N(0, 1)$, $b_s \sim N(0, 0.01)$)
    or `"zero"` ($a_s = b_s = 0$: $\widetilde H = 0$ and the step is the identity; full vectors
    $c_s \sim N(0, 1/n)$, of unit expected length): the start for large systems, where the
    paper's full vectors have length $\sqrt n$ and its first step moves every state far.
    """

    a: jax.Array
    c: jax.Array
    b: jax.Array | None
    e: jax.Array | None
    activation: str = eqx.field(static=True)
    dim: int = eqx.field(static=True)
    order: tuple[int, ...] = eqx.field(static=True)
    full_vectors: bool = eqx.field(static=True)
    a_kept: tuple[bool, ...] | None = eqx.field(static=True)
    b_kept: tuple[bool, ...] | None = eqx.field(static=True)
    init: str = eqx.field(static=True)

    def __init__(self, dim: int, n_modules: int, order: Sequence[int] | None = None, key: int | jax.Array = 0, *,
                 activation: str = "sigmoid", full_vectors: bool = False, linear_term: bool = False,
                 bias: bool = True, a_kept: Sequence[bool] | None = None, b_kept: Sequence[bool] | None = None,
                 init: str = "random"):
        self.dim = positive_int(dim, "dim")
        n_modules = positive_int(n_modules, "n_modules")
        self.order = check_order(order, n_modules, dim)
        for name, value in (("full_vectors", full_vectors), ("linear_term", linear_term), ("bias", bias)):
            if not isinstance(value, (bool, np.bool_)):
                raise TypeError(f"{name} must be True or False; got {value!r}")
        self.full_vectors = bool(full_vectors)
        self.activation = check_activation(activation)
        ka, kc, kb = jax.random.split(as_key(key), 3)
        shape = (n_modules, dim) if self.full_vectors else (n_modules,)
        self.a = jax.random.normal(ka, (n_modules,), jnp.float64)
        self.c = jax.random.normal(kc, shape, jnp.float64)
        self.b = 0.1 * jax.random.normal(kb, (n_modules,), jnp.float64) if bias else None
        self.e = jnp.zeros(n_modules, jnp.float64) if linear_term else None
        self.init = check_init(init)
        if self.init == "zero":
            self.a = jnp.zeros_like(self.a)
            self.b = None if self.b is None else jnp.zeros_like(self.b)
            if self.full_vectors:
                self.c = self.c / np.sqrt(self.dim)
        self.a_kept = _kept(a_kept, n_modules, "a_kept")
        self.b_kept = _kept(b_kept, n_modules, "b_kept")
        if self.b_kept is not None and not bias:
            raise ValueError("b_kept selects among the biases b_s: it needs bias=True")
        if self.a_kept is not None:
            self.a = jnp.where(jnp.asarray(self.a_kept), self.a, 0.0)
        if self.b_kept is not None:
            self.b = jnp.where(jnp.asarray(self.b_kept), self.b, 0.0)

    @property
    def n_modules(self) -> int:
        return len(self.order)

    @property
    def linear_term(self) -> bool:
        return self.e is not None

    @property
    def bias(self) -> bool:
        return self.b is not None

    def a_values(self) -> jax.Array:
        """$a_s$, zero where not kept (`a_kept`)."""
        return self.a if self.a_kept is None else self.a * jnp.asarray(self.a_kept, self.a.dtype)

    def bias_values(self) -> jax.Array:
        """$b_s$, zeros without a bias or where not kept (`b_kept`)."""
        if self.b is None:
            return jnp.zeros_like(self.a)
        return self.b if self.b_kept is None else self.b * jnp.asarray(self.b_kept, self.b.dtype)

    def vectors(self) -> jax.Array:
        r"""The vectors $\alpha_s$, shape `(n_modules, dim)`."""
        if self.full_vectors:
            return self.c
        return self.c[:, None] * jnp.eye(self.dim)[jnp.asarray(self.order)]

    def vector(self, s: int | jax.Array) -> jax.Array:
        r"""$\alpha_s$ alone (a module's flow needs only its own vector; `s` may be traced)."""
        if self.full_vectors:
            return self.c[s]
        return jnp.zeros(self.dim, self.c.dtype).at[jnp.asarray(self.order)[s]].set(self.c[s])

    def reinitialised(self, key: int | jax.Array) -> RidgeTerms:
        """The same family of pieces with fresh parameters from `key`."""
        return RidgeTerms(self.dim, self.n_modules, self.order, key, activation=self.activation,
                          full_vectors=self.full_vectors, linear_term=self.linear_term, bias=self.bias,
                          a_kept=self.a_kept, b_kept=self.b_kept, init=self.init)

    def in_units(self, time: float, size: float) -> RidgeTerms:
        r"""The pieces that move states of size `size` over times in units `time` as these
        move unit states over unit times: $(a_s, b_s, e_s) \cdot$ `size`/`time`,
        $\alpha_s/$`size`.

        On a Lie-Poisson system (a bracket linear in $y$) the G-LPNet of the result maps
        $\text{size}\cdot z$ over a step $\text{time}\cdot\tau$ to $\text{size}$ times what
        this one maps $z$ to over $\tau$: the inputs $\langle\alpha_s, y\rangle$ are
        unchanged and the rates $q_s\alpha_s$ scale by 1/`time`. On any Poisson system with
        `size` = 1 it is the change of the unit of time (conventions, [Units][units])."""
        time, size = positive_float(time, "time"), positive_float(size, "size")
        rate = size / time
        new = eqx.tree_at(lambda m: (m.a, m.c), self, (self.a * rate, self.c / size))
        if self.b is not None:
            new = eqx.tree_at(lambda m: m.b, new, self.b * rate)
        if self.e is not None:
            new = eqx.tree_at(lambda m: m.e, new, self.e * rate)
        return new

    def with_activation(self, activation: str) -> RidgeTerms:
        r"""The same pieces with another activation $\sigma$ (a static field: a copy)."""
        new = copy.copy(self)
        object.__setattr__(new, "activation", check_activation(activation))
        return new

    def flow(self, system: AbstractPoissonSystem, s: int | jax.Array, t: Any, y: jax.Array) -> jax.Array:
        r"""The exact flow of $\Phi_s(\langle\alpha_s, y\rangle)$ for time `t`: the test flow
        with the rate $\Phi_s'(\langle\alpha_s, y\rangle)$ frozen (it is conserved)."""
        return system.test_flow(self.velocity(s, y), t, y)

    def compensated_flow(self, system: AbstractPoissonSystem, s: int | jax.Array, t: Any,
                         pair: tuple[jax.Array, jax.Array]) -> tuple[jax.Array, jax.Array]:
        r"""`flow` on a state carried as $(y_{hi}, y_{lo})$
        (`integrators.splitting.compensated_flow`), the rate frozen at $y_{hi}$."""
        alpha = self.velocity(s, pair[0])
        return compensated_flow(lambda y: system.test_flow_increment(alpha, t, y), pair)

    def velocity(self, s: int | jax.Array, y: jax.Array) -> jax.Array:
        r"""$\nabla\Phi_s = \Phi_s'(\langle\alpha_s, y\rangle)\,\alpha_s$: the body velocity of
        piece `s`, constant along its flow (the rate is conserved)."""
        alpha = self.vector(s)
        x = jnp.dot(alpha, y)
        q = self.a_values()[s] * ACTIVATIONS[self.activation](x)
        if self.b is not None:
            q = q + self.bias_values()[s]
        if self.e is not None:
            q = q + self.e[s] * x
        return q * alpha

    def lifted_flow(self, system: AbstractPoissonSystem, s: int | jax.Array, t: Any,
                    gy: tuple[jax.Array, jax.Array]) -> tuple[jax.Array, jax.Array]:
        r"""`flow` on $(g, \mu)$: $(g\exp(t\nabla\Phi_s), \ldots)$, exact."""
        g, y = gy
        return system.lifted_test_flow(self.velocity(s, y), t, g, y)

    def spec(self) -> dict[str, Any]:
        return {"n_modules": self.n_modules, "order": list(self.order), "full_vectors": self.full_vectors,
                "activation": self.activation, "linear_term": self.linear_term,
                **({} if self.bias else {"bias": False}),  # files before `bias` have one
                **({} if self.a_kept is None else {"a_kept": list(self.a_kept)}),
                **({} if self.b_kept is None else {"b_kept": list(self.b_kept)}),
                **({} if self.init == "random" else {"init": self.init})}  # files before `init`: random
