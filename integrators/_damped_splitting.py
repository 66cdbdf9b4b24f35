r"""Splitting for double-bracket dissipation: the exact flows of the Hamiltonian's pieces and a
Lie-group step of the dissipation, composed by a splitting method's rule."""

from __future__ import annotations

import functools
import inspect

import equinox as eqx
import jax

from liepoisson.internals import positive_float
from liepoisson.systems import AbstractDissipativeSystem, AbstractExactTerm

from ._lie_group import AbstractLieGroupMethod, CommutatorFree2
from ._splitting._base import (
    AbstractSplittingMethod,
    Flow,
    composition_flops,
    default_terms,
    splitting_method,
)
from ._splitting._strang import Strang
from ._step_map import AbstractStepMap, check_state


def _final(cls: type) -> bool:
    """A method class that can step: not abstract, with its order (an abstract base has neither)."""
    return not inspect.isabstract(cls) and isinstance(getattr(cls, "order", None), int)


class DampedSplitting(AbstractStepMap):
    r"""$\dot\mu = \mathbb B\nabla H + \gamma\,\mathbb B K\mathbb B\nabla H$ (a
    `liepoisson.systems.DoubleBracket`, or any `AbstractDissipativeSystem`) split into the pieces
    $H_1, \dots, H_N$ of its conservative part's `hamiltonian_splitting()`, each moved by its exact flow, and the dissipation
    $\dot\mu = \mathbb B(\mu)\,\gamma K\mathbb B(\mu)\nabla H(\mu)$, a coadjoint motion with a
    state-dependent generator, moved by a Lie-group method (`dissipation.advance` on
    `system.dissipative_generator`). `method.compose` composes the $N + 1$ pieces, the
    dissipation last (for Strang: the middle, full step).

    Every sub-step is a coadjoint flow, so every Casimir is conserved to round-off. The order
    is the smaller of the composition's and the Lie-group method's (a composition of order
    $p$ of the exact sub-flows stays of order $p$ when a sub-flow is replaced by a method of
    order $\ge p$): `Strang` with `CommutatorFree2` is of order 2, `TripleJump` with
    `CommutatorFree4` of order 4. The compositions' negative sub-steps run the dissipation
    backward, which is harmless for $|\gamma h| \ll 1$.

    **Arguments:** `system`, a dissipative system (`DoubleBracket`); `h` > 0; `method`, an
    `integrators.splitting` method (default `Strang()`; a class stands for its instance; an
    `ordering` orders the $N + 1$ pieces); `dissipation`, a Lie-group method class (default
    `CommutatorFree2`).
    """

    system: AbstractDissipativeSystem = eqx.field(static=True)
    h: float
    method: AbstractSplittingMethod = eqx.field(static=True)
    dissipation: type[AbstractLieGroupMethod] = eqx.field(static=True)
    pieces: tuple[AbstractExactTerm, ...] = eqx.field(static=True)

    def __init__(
        self,
        system: AbstractDissipativeSystem,
        h: float,
        method: AbstractSplittingMethod | type[AbstractSplittingMethod] = Strang,
        dissipation: type[AbstractLieGroupMethod] = CommutatorFree2,
    ):
        if not isinstance(system, AbstractDissipativeSystem):
            raise TypeError(
                "system must be a dissipative system (a liepoisson.systems.AbstractDissipativeSystem, e.g. a "
                "DoubleBracket: a damped Lie-Poisson system); got "
                f"{type(system).__name__}. An undamped system is split by integrators.splitting's methods"
            )
        method = splitting_method(method)
        if not (isinstance(dissipation, type) and issubclass(dissipation, AbstractLieGroupMethod)) or not _final(
            dissipation
        ):
            raise TypeError(
                "dissipation must be a Lie-group method class (integrators.LieEuler, CommutatorFree2, "
                f"CommutatorFree4); got {dissipation!r}"
            )
        self.system = system
        self.h = positive_float(h, "h")
        self.method = method
        self.dissipation = dissipation
        self.pieces = default_terms(system.conservative)  # the same objects each time: compiled code is reused
        method.check_terms(len(self.pieces) + 1, f"the splitting of {system.conservative!r} and the dissipation")

    @property
    def order(self) -> int:
        return min(self.method.order, self.dissipation.order)

    def _dissipate(self, t: float | jax.Array, y: jax.Array) -> jax.Array:
        return self.dissipation.advance(self.system.dissipative_generator, self.system.test_flow, y, t)

    def flows(self) -> list[Flow]:
        r"""The exact flows of $H_1, \dots, H_N$, then the Lie-group step of the dissipation."""
        undamped = self.system.conservative
        return [functools.partial(term.flow, undamped) for term in self.pieces] + [self._dissipate]

    def step(self, y: jax.Array) -> jax.Array:
        return self.method.compose(self.flows(), check_state(y, self.system.dim), self.h)

    def step_flops(self) -> float:
        return composition_flops(self, self.method)

    @property
    def exact_flows_per_step(self) -> int:
        inner, count = self.method.stages()
        calls = [0] * (len(self.pieces) + 1)

        def counting(k):
            def flow(t, y):
                calls[k] += 1
                return y
            return flow

        inner.compose([counting(k) for k in range(len(calls))], 0.0, 1.0)
        return count * (sum(calls[:-1]) + calls[-1] * self.dissipation.exponentials)
