r"""G-LPNets ([the paper](https://arxiv.org/abs/2308.15349), Sec. 6, "G-LPNets: Derivation and
test cases"): a classical splitting method applied to learnable collective terms, the
data-driven splitting of a learned Hamiltonian
$\widetilde H = w\sum_s\Phi_s(\langle\alpha_s, y\rangle)$ (Sec. 6.1, eqs. (73) and (74)).

Each piece is solved exactly (`learn.RidgeTerms`) and its flow is a Poisson map, so the network
is an exact Poisson map for any weights, whatever the method composing the pieces.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from numpy.typing import ArrayLike

from integrators.internals import check_state, composition_flops, splitting_method
from integrators.splitting import (
    AbstractCompensableStepMap,
    AbstractSplittingMethod,
    IndexedFlows,
    LieTrotter,
)
from liepoisson import JAX
from liepoisson.internals import as_state, check_system, positive_float, refuse_nonholonomic
from liepoisson.systems import AbstractPoissonSystem

from .._solvers._quasi_newton import ScipyBFGS
from .._solvers._stage import KeepIfBetter, Restarts, WarmStart
from ._base import AbstractBodyMap, AbstractCasimirConservingMap, AbstractWarmStartableMap
from ._learned_terms import RidgeTerms, ridge_potential
from ._mlp import ACTIVATIONS, activation_antiderivative
from ._networks import network_or_default


def check_method(method: Any) -> AbstractSplittingMethod:
    """A splitting method instance of `integrators.splitting` (`Strang()`,
    `Strang(ordering=...)`); a class stands for its instance without ordering."""
    return splitting_method(method)


class GLPNet(AbstractCasimirConservingMap, AbstractWarmStartableMap, AbstractBodyMap,
             AbstractCompensableStepMap):
    r"""Global Lie-Poisson network: the splitting `method` of the learned Hamiltonian
    $\widetilde H = w\sum_s\Phi_s(\langle\alpha_s, y\rangle)$ over its pieces, the
    `learn.RidgeTerms` $\Phi_s' = a_s\sigma(x) + b_s$
    ([the paper](https://arxiv.org/abs/2308.15349), Sec. 6.1, eqs. (73) and (74)).

    `method` is any `integrators.splitting` method, run by the same code that runs it on a
    known Hamiltonian's pieces: `LieTrotter` (default) is the paper's G-LPNet, each module over
    $h/M$, i.e. $w = 1/M$, order 1; `Strang` applies modules $1..M-1$ over $h/2$, module $M$ over
    $h$, then $M-1..1$ over $h/2$, symmetric and of order 2, with $w = 1$; `TripleJump`,
    `Yoshida6`, ... compose Strang steps to order 4 and 6 ($w = 1$). The network IS
    `integrators.splitting.Splitting(net.learned_system(), h, net.method)`, its `ordering`
    included: a symmetric one runs at other step sizes (`with_h`).
    Exactly Poisson and Casimir-conserving for any parameters; trained by default with BFGS
    and the identity warm start (`learn.fit(gnet, data)`, see `learn.ScipyBFGS`).

    **Arguments:** `system`; `n_modules` $M$ (default $2n$ for a system of dimension $n$: each
    basis direction twice, the paper's 6 for so(3)), `order`, `key`, `activation` (paper:
    sigmoid), `full_vectors`, `linear_term`, `init` (`"zero"`: start at $\widetilde H = 0$, the
    identity step; for large systems): the pieces, `learn.RidgeTerms`, or `terms`, such
    pieces given whole (then none of those); `method`, a method instance (`Strang()`,
    `Strang(ordering=...)`: the order in which the modules are applied) or class (its
    instance without ordering); `h` (`None`: set by `learn.fit`).
    """

    terms: RidgeTerms
    system: AbstractPoissonSystem = eqx.field(static=True)
    method: AbstractSplittingMethod = eqx.field(static=True)
    h: float | None

    def __init__(
        self,
        system: AbstractPoissonSystem,
        n_modules: int | None = None,
        order: Sequence[int] | None = None,
        key: int | jax.Array | None = None,
        *,
        method: Any = LieTrotter,
        h: float | None = None,
        activation: str | None = None,
        full_vectors: bool | None = None,
        linear_term: bool | None = None,
        terms: RidgeTerms | None = None,
        init: str | None = None,
    ):
        self.system = check_system(system)
        refuse_nonholonomic(system, "a G-LPNet")
        # Default: every basis direction twice (the paper's 6 modules for so(3)), so that any
        # algebra's G-LPNet can rotate about each axis on both sides of the others.
        terms = network_or_default(
            terms, functools.partial(default_terms, system.dim), "terms", n_modules=n_modules, order=order, key=key,
            activation=activation, full_vectors=full_vectors, linear_term=linear_term, init=init)
        if not isinstance(terms, RidgeTerms):
            raise TypeError(f"terms must be a learn.RidgeTerms; got {type(terms).__name__}")
        if terms.dim != system.dim:
            raise ValueError(f"terms are for states of dimension {terms.dim}; {system!r} has {system.dim}")
        self.terms = terms
        self.method = check_method(method)
        self.method.check_terms(terms.n_modules, f"a GLPNet of {terms.n_modules} modules")
        self.h = None if h is None else positive_float(h, "h")

    @property
    def n_modules(self) -> int:
        return self.terms.n_modules

    @property
    def activation(self) -> str:
        return self.terms.activation

    @property
    def _time_divisor(self) -> int:
        # the paper's Lie-Trotter network runs each module over h/M (w = 1/M), written as a
        # division of the time so that its arithmetic is the paper's
        return self.n_modules if isinstance(self.method, LieTrotter) else 1

    @property
    def hamiltonian_weight(self) -> float:
        r"""$w$ in $\widetilde H = w\sum_s\Phi_s$: $1/M$ (`LieTrotter`, the paper's) or 1."""
        return 1.0 / self._time_divisor

    def module_vectors(self) -> jax.Array:
        r"""The vectors $\alpha_s$, shape `(n_modules, dim)`."""
        return self.terms.vectors()

    def module_flow(self, s: int | jax.Array, t: Any, y: jax.Array) -> jax.Array:
        r"""The exact flow of $w\Phi_s(\langle\alpha_s, y\rangle)$ for time `t` (`s` may be traced)."""
        return self.terms.flow(self.system, s, t / self._time_divisor, y)

    def flows(self) -> IndexedFlows:
        r"""The flows of the pieces of $\widetilde H$, as `flow(t, y)`, in module order: one
        function of the module index (`integrators.splitting.IndexedFlows`), which the method
        scans (in its `ordering`)."""
        return IndexedFlows(self.module_flow, self.n_modules)

    def step(self, y: jax.Array) -> jax.Array:
        return self.method.compose(self.flows(), check_state(y, self.system.dim), self.h)

    def compensated_flows(self) -> IndexedFlows:
        r"""`flows()` on states carried as $(y_{hi}, y_{lo})$: what
        `integrators.Compensated(net)` composes (Casimirs kept over long runs)."""
        def flow(s, t, pair):
            return self.terms.compensated_flow(self.system, s, t / self._time_divisor, pair)

        return IndexedFlows(flow, self.n_modules)

    def lifted_step(self, g: jax.Array, y: jax.Array) -> tuple[jax.Array, jax.Array]:
        r"""The step on $(g, \mu)$: each module's flow lifted, $g \mapsto
        g\exp(t\,w\nabla\Phi_s)$ (its body velocity is constant along it), so the
        reconstruction is exact for the learned $\widetilde H$ and the spatial momentum is
        kept to round-off."""
        group = self.system.require_group()
        flows = IndexedFlows(lambda s, t, gy: self.terms.lifted_flow(self.system, s, t / self._time_divisor, gy),
                             self.n_modules)
        return self.method.compose(flows, (group.check(g, "g"), check_state(y, self.system.dim)), self.h)

    @property
    def exact_flows_per_step(self) -> int:
        return self.method.flows_per_step(self.n_modules)

    def step_flops(self) -> float:
        return composition_flops(self, self.method)

    def hamiltonian(self, y: ArrayLike) -> jax.Array:
        r"""The learned Hamiltonian $\widetilde H(y) = w\sum_s\Phi_s(\langle\alpha_s, y\rangle)$
        (up to a constant), shape `(...)` for `y` of shape `(..., dim)`. Needs an activation
        with a closed-form antiderivative (`sigmoid`, `tanh`, `identity`)."""
        y = as_state(y, "y", self.system.dim)
        t = self.terms
        s = jnp.einsum("md,...d->...m", t.vectors(), y)
        e = 0.0 if t.e is None else t.e
        potential = ridge_potential(s, t.a_values(), t.bias_values(), e, activation_antiderivative(t.activation), JAX)
        return self.hamiltonian_weight * jnp.sum(potential, axis=-1)

    def body_velocity(self, y: jax.Array) -> jax.Array:
        r"""$\xi = \nabla\widetilde H(y) = w\sum_s\Phi_s'(\langle\alpha_s, y\rangle)\,\alpha_s$ for
        one state `(dim,)`: the body velocity a configuration moves with ($\dot g = g\,\xi$),
        what a gyroscope measures."""
        velocities = jax.vmap(lambda s: self.terms.velocity(s, y))(jnp.arange(self.n_modules))
        return self.hamiltonian_weight * jnp.sum(velocities, axis=0)

    def learned_system(self):
        r"""The Poisson system $\dot y = \mathbb B(y)\nabla\widetilde H$ with this network's
        learned Hamiltonian and the system's bracket, split into its pieces (one
        `CollectiveTerm` per module): every method of `integrators.splitting` runs on it, and
        `integrators.splitting.Splitting(gnet.learned_system(), h, gnet.method)` is this network
        at step `h`."""
        from ._learned_system import LearnedHamiltonian

        return LearnedHamiltonian(self)

    def hyperparameters(self) -> dict[str, Any]:
        return {**self.terms.spec(), "method": method_record(self.method)}

    def reinitialised(self, key):
        return eqx.tree_at(lambda m: m.terms, self, self.terms.reinitialised(key))

    @classmethod
    def from_hyperparameters(cls, system, hyperparameters, *, key=0, h=None):
        hp = dict(hyperparameters)
        method = method_from_record(hp.pop("method"))
        return cls(system, h=h, method=method, terms=RidgeTerms(system.dim, key=key, **hp))

    # -- what learn.fit asks -------------------------------------------------------------------
    def default_optimiser(self):
        """BFGS with the identity warm start (3500 iterations, 4 starts), as the paper."""
        return (KeepIfBetter(Restarts(WarmStart(ScipyBFGS(3500)), 4)),)

    def warm_start(self):
        """The same network with the identity activation (flows of quadratics, a smooth
        problem), and `linear_to_activation` to map its fit onto this one; `None` if this one
        already has the identity."""
        if self.activation == "identity":
            return None
        linear = eqx.tree_at(lambda m: m.terms, self, self.terms.with_activation("identity"))
        return linear, functools.partial(linear_to_activation, self)


def default_terms(dim: int, n_modules: int | None = None, **kwargs: Any) -> RidgeTerms:
    return RidgeTerms(dim, 2 * dim if n_modules is None else n_modules, **kwargs)


def method_record(method: AbstractSplittingMethod) -> dict[str, Any]:
    """`method` as JSON values for a file: its class name and its ordering (`None`: the
    modules' own order)."""
    return {"name": type(method).__name__, "ordering": None if method.ordering is None else list(method.ordering)}


def method_from_record(record: Any) -> AbstractSplittingMethod:
    """The method of `method_record`, or of a bare class name (files written before the
    ordering was recorded)."""
    from integrators.splitting import splitting_method_by_name

    name, ordering = (record, None) if isinstance(record, str) else (record["name"], record["ordering"])
    return type(splitting_method_by_name(name))(ordering=ordering)


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
    if net.terms.linear_term:
        lin = linear.terms
        zero = jnp.zeros_like(lin.a)
        net = eqx.tree_at(lambda n: (n.terms.a, n.terms.c, n.terms.e), net, (zero, lin.c, lin.a + lin.e))
        return net if lin.b is None else eqx.tree_at(lambda n: n.terms.b, net, lin.b)
    act = ACTIVATIONS[net.activation]
    s0, s1 = float(act(0.0)), float(jax.grad(act)(0.0))
    if s1 == 0.0:
        raise ValueError(f"warm start needs an activation with sigma'(0) != 0; {net.activation!r} has 0")
    vectors = linear.module_vectors()
    spread = jnp.max(jnp.abs(X @ vectors.T), axis=0)  # max |<alpha_s, y>| over the data
    eps = width / jnp.maximum(spread, 1e-300)
    a = linear.terms.a / (s1 * eps**2)
    c = linear.terms.c * (eps[:, None] if net.terms.full_vectors else eps)
    if not net.terms.bias:
        raise ValueError("the warm start of a sigmoid piece without a linear term needs the bias b_s (it cancels "
                         "sigma(0)): build the terms with bias=True or linear_term=True")
    b = linear.terms.b / eps - s0 * a
    return eqx.tree_at(lambda n: (n.terms.a, n.terms.c, n.terms.b), net, (a, c, b))


