r"""The abstract splitting method: a step map $y_{n+1} = \Phi_h(y_n)$ composed of the exact
flows $\varphi^{[k]}_t$ of the pieces $H = \sum_k H_k$ given by `system.hamiltonian_splitting()`.

A method is its composition rule, `compose(flows, y, h)`, a class method on any sequence of
flows: the classical methods apply it to the exact flows of a known Hamiltonian's pieces, a
`learn.GLPNet` to the flows of its learned pieces. One engine for both."""

from __future__ import annotations

import abc
import functools
import weakref
from collections.abc import Callable, Sequence
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from liepoisson.internals import check_system, positive_float
from liepoisson.systems import AbstractDissipativeSystem, AbstractExactTerm, AbstractPoissonSystem, check_splitting

from .._step_map import AbstractStepMap, check_state, traced_h, xla_flops

#: A flow $\varphi_t(y)$ as `flow(t, y)` on one state.
Flow = Callable[[float, jax.Array], jax.Array]


class IndexedFlows(Sequence):
    r"""`n` flows of pieces of one kind, given by one function `flow(k, t, y)` that takes a
    traced index `k` (their parameters stacked, as a `learn.GLPNet`'s modules). A sequence of
    `flow(t, y)` like any other; `Strang` and `LieTrotter` compose it in a `jax.lax.scan` over
    `k`, so a step traces one flow, not every one (its compilation time: BENCHMARKS.md,
    "Learning from observations")."""

    def __init__(self, flow: Callable[[int | jax.Array, float, jax.Array], jax.Array], n: int):
        self.flow = flow
        self.n = n

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self[i] for i in range(self.n)[k]]
        if not -self.n <= k < self.n:
            raise IndexError(f"flow index {k} out of range for {self.n} flows")
        return functools.partial(self.flow, k % self.n)

    def scan(self, order: np.ndarray, weights: np.ndarray, h: float | jax.Array, y: jax.Array) -> jax.Array:
        r"""$\varphi^{[k_m]}_{w_m h}\circ\cdots\circ\varphi^{[k_1]}_{w_1 h}(y)$ for `order`
        $k_i$ and `weights` $w_i$, in one `jax.lax.scan`."""

        def body(y, kw):
            k, w = kw
            return self.flow(k, w * h, y), None

        y, _ = jax.lax.scan(body, y, (jnp.asarray(order), jnp.asarray(weights, dtype=jnp.result_type(float))))
        return y


class AbstractSplittingMethod(AbstractStepMap):
    r"""A splitting method $\Phi_h$ for a system with an exactly solvable splitting, as a step
    map (method + system + $h$).

    Every sub-flow is exact, Poisson and Casimir-preserving (a frozen-parameter test flow),
    so $\Phi_h$ is a Poisson map that conserves every Casimir to round-off, whatever its order.

    Final subclasses give `order`, the composition rule `compose` and `flows_per_step`; `step`,
    `rollout`, `poisson_defect` and `cost` are shared.

    **Arguments:** `system`, an `AbstractPoissonSystem` whose `hamiltonian_splitting()` gives
    the pieces; `h` > 0, the step size; `ordering`, a permutation of the pieces' indices (default
    their order in `hamiltonian_splitting()`): the orderings of the same method can differ by
    orders of magnitude in energy error (for the rigid body: Fasso, *Comparison of splitting
    algorithms for the rigid body*, J. Comput. Phys. 189 (2003) 527-538), e.g.
    `[Strang(body, h, ordering=p) for p in itertools.permutations(range(3))]`; `terms`, your
    own exact pieces instead of `hamiltonian_splitting()` (e.g. `[FreeRigidBodyTerm(I),
    CollectiveTerm(...)]`), checked to sum to $H$ at sample points.
    """

    system: AbstractPoissonSystem = eqx.field(static=True)
    h: float
    ordering: tuple[int, ...] = eqx.field(static=True)
    pieces: tuple[AbstractExactTerm, ...] = eqx.field(static=True)
    order: ClassVar[int]

    def __init__(
        self,
        system: AbstractPoissonSystem,
        h: float,
        ordering: Sequence[int] | None = None,
        *,
        terms: Sequence[AbstractExactTerm] | None = None,
    ):
        self.system = check_system(system)
        if isinstance(system, AbstractDissipativeSystem):
            raise ValueError(
                f"{system!r} is dissipative: a splitting of its Hamiltonian would integrate the undamped "
                "system. Use integrators.DampedSplitting or a Lie-group method (integrators.CommutatorFree4, ...)"
            )
        if terms is None:
            terms = default_terms(system)
        else:
            terms = check_splitting(system, terms, "terms")
        self.pieces = terms
        self.h = positive_float(h, "h")
        n = len(terms)
        try:
            ordering = tuple(range(n)) if ordering is None else tuple(int(k) for k in ordering)
        except (TypeError, ValueError) as err:
            raise TypeError(
                f"ordering must be a permutation of range({n}); got {ordering!r}"
            ) from err
        if sorted(ordering) != list(range(n)):
            raise ValueError(
                f"ordering must be a permutation of range({n}) (the {n} pieces of {system!r}); got {ordering}"
            )
        self.ordering = ordering

    @property
    def terms(self) -> tuple[AbstractExactTerm, ...]:
        r"""The pieces $H_1, \dots, H_N$ in `ordering` (their flows are applied in this order)."""
        return tuple(self.pieces[k] for k in self.ordering)

    def flow(self, k: int, t: float, y: jax.Array) -> jax.Array:
        r"""Exact flow $\varphi^{[k]}_t(y)$ of the $k$-th piece."""
        return self.terms[k].flow(self.system, t, y)

    @classmethod
    @abc.abstractmethod
    def compose(cls, flows: Sequence[Flow], y: jax.Array, h: float | jax.Array) -> jax.Array:
        r"""$\Phi_h(y)$ composed of `flows[k](t, y)` $= \varphi^{[k+1]}_t(y)$, for one state:
        the method's rule on any flows, exact pieces of a known $H$ or learned ones."""

    @classmethod
    @abc.abstractmethod
    def flows_per_step(cls, n_terms: int) -> int:
        """How many flows `compose` evaluates for `n_terms` pieces."""

    @classmethod
    def stages(cls) -> tuple[type[AbstractSplittingMethod], int]:
        """`(inner, count)`: `compose` is `count` compositions by `inner` (itself, once, unless
        it loops over an inner method, as a composition of Strang steps does). XLA counts a
        loop body once, so `step_flops` counts `inner`'s and multiplies."""
        return cls, 1

    @classmethod
    def check_terms(cls, n_terms: int, what: str) -> None:
        """`ValueError` if the method cannot compose `n_terms` pieces (`what` names them)."""
        if n_terms < 1:
            raise ValueError(f"{cls.__name__} needs at least one piece; {what} has none")

    def __check_init__(self):
        type(self).check_terms(len(self.pieces), f"the splitting of {self.system!r}")

    def step(self, y: jax.Array) -> jax.Array:
        return type(self).compose(self.flows(), check_state(y, self.system.dim), self.h)

    @property
    def exact_flows_per_step(self) -> int:
        return type(self).flows_per_step(len(self.terms))

    def flows(self) -> list[Flow]:
        r"""The exact flows $\varphi^{[k]}_t$ of the pieces in `ordering`, as `flow(t, y)`."""
        return [functools.partial(self.flow, k) for k in range(len(self.terms))]

    def step_flops(self) -> float:
        return composition_flops(self, type(self))


def composition_flops(step_map: AbstractStepMap, method: type[AbstractSplittingMethod]) -> float:
    """XLA's flop count of one step of `step_map` = `method.compose(step_map.flows(), y, h)`:
    the inner composition of `method.stages()` counted once and multiplied (XLA counts a loop
    body once). `step_map` needs `flows()` and `h` (a classical method, or a `learn.GLPNet`)."""
    inner, count = method.stages()
    return count * xla_flops(_inner_composition, traced_h(step_map), jnp.zeros(step_map.system.dim), inner)


def _inner_composition(step_map: AbstractStepMap, y: jax.Array, inner: type[AbstractSplittingMethod]) -> jax.Array:
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
