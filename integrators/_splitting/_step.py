r"""A splitting method bound to a system's pieces and a step size: the step map
$y_{n+1} = \Phi_h(y_n)$ of `method.compose` on the exact flows of $H = \sum_k H_k$."""

from __future__ import annotations

import functools
from collections.abc import Sequence

import equinox as eqx
import jax

from liepoisson.internals import check_system, positive_float
from liepoisson.systems import (
    AbstractDissipativeSystem,
    AbstractExactTerm,
    AbstractPoissonSystem,
    check_splitting,
)

from .._step_map import AbstractStepMap, check_state
from ._base import (
    AbstractSplittingMethod,
    FlowList,
    composition_flops,
    default_terms,
    splitting_method,
)
from ._strang import Strang


class Splitting(AbstractStepMap):
    r"""The splitting method `method` on the exact flows $\varphi^{[k]}_t$ of the pieces of
    `system`'s Hamiltonian, at step size `h`: $y_{n+1} = \Phi_h(y_n)$.

    Every sub-flow is exact, Poisson and Casimir-preserving (a frozen-parameter test flow),
    so $\Phi_h$ is a Poisson map that conserves every Casimir to round-off, whatever its order.

    **Arguments:** `system`, an `AbstractPoissonSystem` whose `hamiltonian_splitting()` gives
    the pieces; `h` > 0, the step size; `method`, an `integrators.splitting` method
    (`Strang()`, the default; `TripleJump()`, `Strang(ordering=(2, 0, 1))`, ...; a class stands
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
        method: AbstractSplittingMethod | type[AbstractSplittingMethod] | None = None,
        *,
        terms: Sequence[AbstractExactTerm] | None = None,
    ):
        self.system = check_system(system)
        if isinstance(system, AbstractDissipativeSystem):
            raise ValueError(  # noqa: TRY004 (a system of the wrong kind, not of the wrong type)
                f"{system!r} is dissipative: a splitting of its Hamiltonian would integrate the undamped "
                "system. Use integrators.DampedSplitting or a Lie-group method (integrators.CommutatorFree4, ...)"
            )
        self.method = Strang() if method is None else splitting_method(method)
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

    @property
    def exact_flows_per_step(self) -> int:
        return self.method.flows_per_step(len(self.pieces))

    def step_flops(self) -> float:
        return composition_flops(self, self.method)
