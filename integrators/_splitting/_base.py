r"""The abstract splitting method: a rule composing flows $\varphi^{[k]}_t$ of the pieces of a
Hamiltonian $H = \sum_k H_k$ into one step $\Phi_h$, and the flows it composes.

A method is a stateless solver object (`Strang()`, `Strang(ordering=(2, 0, 1))`,
`TripleJump()`): its composition rule `compose(flows, y, h)` takes any flows, the exact flows of
a known Hamiltonian's pieces (bound to a system and $h$ by `integrators.splitting.Splitting`)
or the learned pieces of a `learn.GLPNet`. One engine for both: the flows carry their own way
of being chained (`AbstractFlows.chain`), a Python loop over separate functions (`FlowList`) or
one `jax.lax.scan` over stacked parameters (`IndexedFlows`). `Splitting` binds a method to a
system's pieces and a step size (here beside the methods: `Strang(system, h)` builds it)."""

from __future__ import annotations

import abc
import dataclasses
import functools
import weakref
from collections.abc import Callable, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from liepoisson.internals import check_system, positive_float, refuse_nonholonomic
from liepoisson.systems import (
    AbstractDissipativeSystem,
    AbstractExactTerm,
    AbstractPoissonSystem,
    check_splitting,
)

from .._step_map import (
    AbstractReconstructingStepMap,
    AbstractStepMap,
    check_state,
    traced_h,
    xla_flops,
)

#: A flow $\varphi_t(y)$ as `flow(t, y)` on one state.
Flow = Callable[[float, jax.Array], jax.Array]


class AbstractFlows(Sequence):
    r"""The flows $\varphi^{[1]}_t, \dots, \varphi^{[N]}_t$ a splitting method composes: a
    sequence of `flow(t, y)` that also knows how to apply a chain of them (`chain`) and how to
    be taken in another order (`permuted`). A method's rule is written once against this
    interface; how the chain is traced (unrolled, or one scanned flow) belongs to the flows."""

    @abc.abstractmethod
    def chain(self, indices: np.ndarray, weights: np.ndarray, h: float | jax.Array, y: jax.Array) -> jax.Array:
        r"""$\varphi^{[k_m]}_{w_m h}\circ\cdots\circ\varphi^{[k_1]}_{w_1 h}(y)$ for `indices`
        $k_i$ (0-based) and `weights` $w_i$, applied first to last."""

    @abc.abstractmethod
    def permuted(self, ordering: tuple[int, ...]) -> AbstractFlows:
        """The same flows with `self[ordering[k]]` in position `k`."""


class FlowList(AbstractFlows):
    """Flows given as separate functions `flow(t, y)`; a chain is a Python loop (every flow
    traced where it is applied)."""

    def __init__(self, flows: Sequence[Flow]):
        self.flows = tuple(flows)

    def __len__(self) -> int:
        return len(self.flows)

    def __getitem__(self, k):
        return self.flows[k]

    def chain(self, indices, weights, h, y):
        for k, w in zip(indices, weights):
            w = float(w)
            y = self.flows[int(k)](h if w == 1.0 else w * h, y)
        return y

    def permuted(self, ordering):
        return FlowList([self.flows[k] for k in ordering])


class IndexedFlows(AbstractFlows):
    r"""`n` flows of pieces of one kind, given by one function `flow(k, t, y)` that takes a
    traced index `k` (their parameters stacked, as a `learn.GLPNet`'s modules). A sequence of
    `flow(t, y)` like any other; a chain of them is one `jax.lax.scan` over `k`, so a step
    traces one flow, not every one (its compilation time: benchmarks, [Levenberg-Marquardt on
    the trajectory loss][levenberg-marquardt-on-the-trajectory-loss-learnlevenbergmarquardt]).
    `order` (default `range(n)`): which stacked flow is in each position."""

    def __init__(self, flow: Callable[[int | jax.Array, float, jax.Array], jax.Array], n: int,
                 order: Sequence[int] | None = None):
        self.flow = flow
        self.n = n
        self.order = None if order is None else np.asarray(order, dtype=np.int64)

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self[i] for i in range(self.n)[k]]
        if not -self.n <= k < self.n:
            raise IndexError(f"flow index {k} out of range for {self.n} flows")
        k = k % self.n
        return functools.partial(self.flow, k if self.order is None else int(self.order[k]))

    def chain(self, indices, weights, h, y):
        indices = np.asarray(indices) if self.order is None else self.order[np.asarray(indices)]

        def body(y, kw):
            k, w = kw
            return self.flow(k, w * h, y), None

        y, _ = jax.lax.scan(body, y, (jnp.asarray(indices), jnp.asarray(weights, dtype=jnp.result_type(float))))
        return y

    def permuted(self, ordering):
        order = np.arange(self.n) if self.order is None else self.order
        return IndexedFlows(self.flow, self.n, order[list(ordering)])


def as_flows(flows: Sequence[Flow]) -> AbstractFlows:
    """`flows` as an `AbstractFlows` (any sequence of `flow(t, y)` becomes a `FlowList`)."""
    return flows if isinstance(flows, AbstractFlows) else FlowList(flows)


def check_ordering(ordering: Any, n: int | None = None, what: str | None = None) -> tuple[int, ...]:
    """`ordering` as a tuple of ints, a permutation of `range(n)` (`n` = its length when not
    given; `what` names the pieces in the message)."""
    try:
        ordering = tuple(int(k) for k in ordering)
    except (TypeError, ValueError) as err:
        raise TypeError(
            f"ordering must be a permutation of range({'n' if n is None else n}); got {ordering!r}"
        ) from err
    n = len(ordering) if n is None else n
    if sorted(ordering) != list(range(n)):
        of = "" if what is None else f" (the {n} pieces of {what})"
        raise ValueError(f"ordering must be a permutation of range({n}){of}; got {ordering}")
    return ordering


@dataclasses.dataclass(frozen=True)
class AbstractSplittingMethod(abc.ABC):
    r"""A splitting method: the rule that composes the flows $\varphi^{[k]}_t$ of the pieces
    $H = \sum_k H_k$ into one step $\Phi_h$. A stateless, hashable solver object
    (`Strang()`, `TripleJump()`), usable as a static field; bound to a system's pieces and a step
    size $h$ by `integrators.splitting.Splitting`, or to a `learn.GLPNet`'s learned pieces.

    With exact sub-flows every sub-step is a Poisson map that conserves every Casimir to
    round-off, and so is $\Phi_h$, whatever its order.

    Final subclasses give `order` (a class attribute, an int), `compose_in_order` (the rule on flows in the order
    they are applied) and `flows_per_step`; `compose` applies `ordering` and the rule.

    **Arguments:** `ordering` (keyword), a permutation of the pieces' indices (default: their
    given order): the orderings of the same method can differ by orders of magnitude in energy
    error (for the rigid body: Fasso, *Comparison of splitting algorithms for the rigid body*,
    J. Comput. Phys. 189 (2003) 527-538), e.g. `[Strang(ordering=p) for p in
    itertools.permutations(range(3))]`.

    A method class called with a system is the bound step map, as in earlier versions:
    `Strang(system, h, ordering=p, terms=...)` is `Splitting(system, h, Strang(ordering=p),
    terms=...)`.
    """

    ordering: tuple[int, ...] | None = dataclasses.field(default=None, kw_only=True)

    def __new__(cls, *args: Any, **kwargs: Any):
        if args or set(kwargs) - {"ordering"}:
            return _bound(cls, *args, **kwargs)
        return super().__new__(cls)

    def __post_init__(self):
        if self.ordering is not None:
            object.__setattr__(self, "ordering", check_ordering(self.ordering))

    @property
    @abc.abstractmethod
    def order(self) -> int:
        r"""The order $p$: $\Phi_h - \varphi_h = O(h^{p+1})$ (a class attribute of final methods)."""

    def compose(self, flows: Sequence[Flow], y: jax.Array, h: float | jax.Array) -> jax.Array:
        r"""$\Phi_h(y)$ composed of `flows[k](t, y)` $= \varphi^{[k+1]}_t(y)$ taken in
        `ordering`, for one state: the method's rule on any flows, exact pieces of a known $H$
        or learned ones (an `AbstractFlows`, or any sequence of `flow(t, y)`)."""
        flows = as_flows(flows)
        if self.ordering is not None:
            flows = flows.permuted(check_ordering(self.ordering, len(flows), f"the {len(flows)} flows"))
        return self.compose_in_order(flows, y, h)

    @abc.abstractmethod
    def compose_in_order(self, flows: AbstractFlows, y: jax.Array, h: float | jax.Array) -> jax.Array:
        """The composition rule on `flows` in the order they are applied."""

    @abc.abstractmethod
    def flows_per_step(self, n_terms: int) -> int:
        """How many flows `compose` evaluates for `n_terms` pieces."""

    def stages(self) -> tuple[AbstractSplittingMethod, int]:
        """`(inner, count)`: `compose` is `count` compositions by `inner` (itself, once, unless
        it loops over an inner method, as a composition of Strang steps does). XLA counts a
        loop body once, so `step_flops` counts `inner`'s and multiplies."""
        return self, 1

    def check_terms(self, n_terms: int, what: str) -> None:
        """`ValueError` if the method cannot compose `n_terms` pieces (`what` names them),
        its `ordering` included."""
        if n_terms < 1:
            raise ValueError(f"{type(self).__name__} needs at least one piece; {what} has none")
        if self.ordering is not None:
            check_ordering(self.ordering, n_terms, what)


def _bound(cls: type[AbstractSplittingMethod], system: AbstractPoissonSystem, h: float,
           ordering: Sequence[int] | None = None, *, terms: Sequence[AbstractExactTerm] | None = None):
    return Splitting(system, h, cls(ordering=ordering), terms=terms)


def splitting_method(method: Any, name: str = "method") -> AbstractSplittingMethod:
    """`method` as a method instance: a final class of `integrators.splitting` is instantiated
    (`Strang` -> `Strang()`); an instance is itself. `TypeError` naming `name` otherwise."""
    if isinstance(method, type) and issubclass(method, AbstractSplittingMethod):
        try:
            return method()
        except TypeError as err:
            raise TypeError(f"{name} must be a splitting method (integrators.splitting.Strang, ...); got {method!r}: "
                            f"{err}") from None
    if isinstance(method, AbstractSplittingMethod):
        return method
    hint = ("; this is a step map bound to a system: pass its method (Strang(), Strang(ordering=...))"
            if isinstance(method, AbstractStepMap) else "")
    raise TypeError(
        f"{name} must be a splitting method of integrators.splitting (LieTrotter, Strang, TripleJump, "
        f"Yoshida6, ..., an instance such as Strang(ordering=(1, 0, 2)), or a class); got {method!r}{hint}"
    )


def composition_flops(step_map: AbstractStepMap, method: AbstractSplittingMethod) -> float:
    """XLA's flop count of one step of `step_map` = `method.compose(step_map.flows(), y, h)`:
    the inner composition of `method.stages()` counted once and multiplied (XLA counts a loop
    body once). `step_map` needs `flows()` and `h` (a classical method, or a `learn.GLPNet`)."""
    inner, count = method.stages()
    return count * xla_flops(_inner_composition, traced_h(step_map), jnp.zeros(step_map.system.dim), inner)


def _inner_composition(step_map: AbstractStepMap, y: jax.Array, inner: AbstractSplittingMethod) -> jax.Array:
    # a plain list: every flow traced, as XLA counts a scanned flow once
    return inner.compose(list(step_map.flows()), y, step_map.h)


_TERMS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def default_terms(system: AbstractPoissonSystem) -> tuple[AbstractExactTerm, ...]:
    """`system.hamiltonian_splitting()`, the same objects for every method built on `system`:
    the pieces are a static field, so equal pieces let `rollout` reuse its compiled code across
    methods' instances and step sizes instead of recompiling for each new instance."""
    try:
        return _TERMS[system]
    except (KeyError, TypeError):
        terms = tuple(system.hamiltonian_splitting())
    try:
        _TERMS[system] = terms
    except TypeError:  # a system that cannot be weakly referenced: no cache
        pass
    return terms


def symmetric_coefficients(half: tuple[float, ...]) -> np.ndarray:
    """The palindrome `half + reversed(half[:-1])` as float64 (symmetric composition tables)."""
    half_arr = np.asarray(half, dtype=np.float64)
    return np.concatenate([half_arr, half_arr[-2::-1]])


class Splitting(AbstractReconstructingStepMap):
    r"""The splitting method `method` on the exact flows $\varphi^{[k]}_t$ of the pieces of
    `system`'s Hamiltonian, at step size `h`: $y_{n+1} = \Phi_h(y_n)$.

    Every sub-flow is exact, Poisson and Casimir-preserving (a frozen-parameter test flow),
    so $\Phi_h$ is a Poisson map that conserves every Casimir to round-off, whatever its order.

    **Arguments:** `system`, an `AbstractPoissonSystem` whose `hamiltonian_splitting()` gives
    the pieces; `h` > 0, the step size; `method`, an `integrators.splitting` method
    (`Strang()`, `TripleJump()`, `Strang(ordering=(2, 0, 1))`, ...; a class stands
    for its instance without ordering); `terms`, your own exact pieces instead of
    `hamiltonian_splitting()` (e.g. `[FreeRigidBodyTerm(I), CollectiveTerm(...)]`), checked to
    sum to $H$ at sample points.

    `Strang(system, h, ordering=p)` builds the same map as `Splitting(system, h,
    Strang(ordering=p))`.
    """

    system: AbstractPoissonSystem = eqx.field(static=True)
    h: float
    method: AbstractSplittingMethod = eqx.field(static=True)
    pieces: tuple[AbstractExactTerm, ...] = eqx.field(static=True)

    def __init__(
        self,
        system: AbstractPoissonSystem,
        h: float,
        method: AbstractSplittingMethod | type[AbstractSplittingMethod],
        *,
        terms: Sequence[AbstractExactTerm] | None = None,
    ):
        self.system = check_system(system)
        if isinstance(system, AbstractDissipativeSystem):
            raise ValueError(  # noqa: TRY004 (a system of the wrong kind, not of the wrong type)
                f"{system!r} is dissipative: a splitting of its Hamiltonian would integrate the undamped "
                "system. Use integrators.DampedSplitting or a Lie-group method (integrators.CommutatorFree4, ...)"
            )
        refuse_nonholonomic(system, "a splitting method")
        self.method = splitting_method(method)
        self.pieces = default_terms(system) if terms is None else check_splitting(system, terms, "terms")
        self.h = positive_float(h, "h")

    def __check_init__(self):
        self.method.check_terms(len(self.pieces), f"the splitting of {self.system!r}")

    @property
    def order(self) -> int:
        return self.method.order

    @property
    def ordering(self) -> tuple[int, ...]:
        """The order in which the pieces are applied (the method's `ordering`, or their own)."""
        return tuple(range(len(self.pieces))) if self.method.ordering is None else self.method.ordering

    @property
    def terms(self) -> tuple[AbstractExactTerm, ...]:
        r"""The pieces $H_1, \dots, H_N$ in `ordering` (their flows are applied in this order)."""
        return tuple(self.pieces[k] for k in self.ordering)

    @property
    def label(self) -> str:
        return type(self.method).__name__

    def flows(self) -> FlowList:
        r"""The exact flows $\varphi^{[k]}_t$ of the pieces, as `flow(t, y)`, in the order of
        `pieces` (`method.compose` applies its `ordering`)."""
        return FlowList([functools.partial(term.flow, self.system) for term in self.pieces])

    def step(self, y: jax.Array) -> jax.Array:
        return self.method.compose(self.flows(), check_state(y, self.system.dim), self.h)

    def lifted_flows(self) -> FlowList:
        r"""The exact flows of the pieces on $(g, \mu)$ (`AbstractExactTerm.lifted_flow`)."""
        return FlowList([functools.partial(term.lifted_flow, self.system) for term in self.pieces])

    def lifted_step(self, g: jax.Array, y: jax.Array) -> tuple[jax.Array, jax.Array]:
        r"""The same composition of the pieces' flows, each lifted to the configuration: exact
        reconstruction (the method's order for $(g, \mu)$ together)."""
        group = self.system.require_group()
        return self.method.compose(self.lifted_flows(), (group.check(g, "g"), check_state(y, self.system.dim)),
                                   self.h)

    @property
    def exact_flows_per_step(self) -> int:
        return self.method.flows_per_step(len(self.pieces))

    def step_flops(self) -> float:
        return composition_flops(self, self.method)
