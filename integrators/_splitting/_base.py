r"""The abstract splitting method: a step map $y_{n+1} = \Phi_h(y_n)$ composed of the exact
flows $\varphi^{[k]}_t$ of the pieces $H = \sum_k H_k$ given by `system.hamiltonian_splitting()`."""

from __future__ import annotations

from collections.abc import Sequence
from typing import ClassVar

import equinox as eqx
import jax
import numpy as np

from liepoisson._validation import check_system, positive_float
from liepoisson.systems import AbstractExactTerm, AbstractPoissonSystem

from .._step_map import AbstractStepMap


class AbstractSplittingMethod(AbstractStepMap):
    r"""A splitting method $\Phi_h$ for a system with an exactly solvable splitting, as a step
    map (method + system + $h$).

    Every sub-flow is exact, Poisson and Casimir-preserving (a frozen-parameter test flow),
    so $\Phi_h$ is a Poisson map that conserves every Casimir to round-off, whatever its order.

    Final subclasses give `order`, `step` (the composition of sub-flows on one state) and
    `exact_flows_per_step`; `rollout`, `poisson_defect` and `cost` are shared.

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
        if terms is None:
            terms = tuple(system.hamiltonian_splitting())
            where = f"{system!r}.hamiltonian_splitting()"
        else:
            try:
                terms = tuple(terms)
            except TypeError as err:
                raise TypeError(f"terms must be a sequence of exact pieces; got {terms!r}") from err
            where = "terms"
        if not terms or not all(isinstance(t, AbstractExactTerm) for t in terms):
            raise TypeError(
                f"{where} must be a non-empty sequence of exact pieces (CollectiveTerm, FreeRigidBodyTerm, "
                f"or your own AbstractExactTerm); got {terms!r}"
            )
        if where == "terms":
            check_pieces_sum_to_hamiltonian(system, terms)
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


def check_pieces_sum_to_hamiltonian(
    system: AbstractPoissonSystem, terms: Sequence[AbstractExactTerm]
) -> None:
    r"""Raise `ValueError` unless $\sum_k H_k = H$ up to a constant at random sample points (to
    $10^3\varepsilon$ relative to the sizes of the values: a few dozen roundings)."""
    y = np.random.default_rng(0).normal(size=(16, system.dim))
    H = np.asarray(system.hamiltonian(y))
    parts = np.stack([np.asarray(t.value(system, y)) for t in terms])
    diff = H - parts.sum(axis=0)
    diff = diff - diff[0]  # a constant offset does not change the flow
    scale = np.abs(H).max() + np.abs(parts).sum(axis=0).max()
    if not np.all(np.abs(diff) <= 1e3 * np.finfo(np.float64).eps * scale):
        k = int(np.argmax(np.abs(diff)))
        raise ValueError(
            f"terms must sum to the Hamiltonian of {system!r}; at y = {y[k].round(3).tolist()} "
            f"H - sum(terms) differs from its value at another point by {diff[k]:.3g} "
            f"(terms: {[t.name or repr(t) for t in terms]})"
        )


def symmetric_coefficients(half: tuple[float, ...]) -> np.ndarray:
    """The palindrome `half + reversed(half[:-1])` as float64 (symmetric composition tables)."""
    half_arr = np.asarray(half, dtype=np.float64)
    return np.concatenate([half_arr, half_arr[-2::-1]])
