r"""Splitting for forced Lie-Poisson systems: the exact flows of the Hamiltonian's pieces and the
flow of the forces (exact for linear drag, else an energy-decreasing discrete gradient),
composed by a splitting method's rule."""

from __future__ import annotations

import functools
from collections.abc import Sequence

import equinox as eqx
import jax

from liepoisson.internals import positive_float
from liepoisson.systems import AbstractExactTerm, Forced, check_splitting

from ._splitting._base import (
    AbstractSplittingMethod,
    Flow,
    FlowList,
    composition_flops,
    default_terms,
    splitting_method,
)
from ._splitting._strang import Strang
from ._step_map import AbstractReconstructingStepMap, check_state


class ForcedSplitting(AbstractReconstructingStepMap):
    r"""$\dot\mu = \mathbb B\nabla H + F(\nabla H)$ (a `liepoisson.systems.Forced`) split into
    the pieces $H_1, \dots, H_N$ of the unforced system's `hamiltonian_splitting()` (or
    `terms`), each moved by its exact flow, and the forces' flow $\dot\mu = F(\nabla H)$
    (`Forced.force_flow`), composed by `method` with the forces last (for Strang: the middle,
    full step).

    The forces' flow is exact for linear drag and constant torques (an affine flow), and the
    midpoint discrete gradient with quadratic drag: symmetric and of order 2, so `Strang` is of
    order 2 and `TripleJump` of order 4 (tested against heyoka). Under dissipative forces the
    forces' flow never increases the energy for any step $t > 0$; with pieces that keep $H$
    (`terms=[FreeRigidBodyTerm(inertia)]`, the rigid body's exact flow) every Strang step
    therefore keeps $H$ from increasing. An order-4 composition has a negative sub-step
    (Sheng-Suzuki: every real splitting beyond order 2 has one), on which the forces run
    backward: its energy decreases only up to the method's error.

    The configuration is reconstructed exactly on the conservative pieces ($\dot g = g\,\xi$)
    and held on the forces' flow (`lifted_step`, `lifted_rollout`).

    **Arguments:** `system`, a `Forced` system whose Hamiltonian is quadratic in $\mu$ (rigid
    body, Kirchhoff, heavy top); `h` > 0; `method`, an `integrators.splitting` method
    (default `Strang()`); `terms`, your own exact pieces of the unforced Hamiltonian.
    """

    system: Forced = eqx.field(static=True)
    h: float
    method: AbstractSplittingMethod = eqx.field(static=True)
    pieces: tuple[AbstractExactTerm, ...] = eqx.field(static=True)

    def __init__(self, system: Forced, h: float,
                 method: AbstractSplittingMethod | type[AbstractSplittingMethod] = Strang, *,
                 terms: Sequence[AbstractExactTerm] | None = None):
        if not isinstance(system, Forced):
            raise TypeError(f"system must be a liepoisson.systems.Forced (a Lie-Poisson system with forces); got "
                            f"{type(system).__name__}. An unforced system is split by integrators.splitting's methods")
        method = splitting_method(method)
        system.quadratic_hamiltonian()  # a ValueError now, not at the first step
        self.system = system
        self.h = positive_float(h, "h")
        self.method = method
        self.pieces = (default_terms(system.conservative) if terms is None
                       else check_splitting(system.conservative, terms, "terms"))
        method.check_terms(len(self.pieces) + 1, f"the splitting of {system.conservative!r} and the forces")

    @property
    def order(self) -> int:
        return self.method.order

    def _forces(self, t, y):
        return self.system.force_flow(t, y)

    def flows(self) -> list[Flow]:
        r"""The exact flows of $H_1, \dots, H_N$, then the forces' flow."""
        undamped = self.system.conservative
        return [functools.partial(term.flow, undamped) for term in self.pieces] + [self._forces]

    def step(self, y: jax.Array) -> jax.Array:
        return self.method.compose(self.flows(), check_state(y, self.system.dim), self.h)

    def _lifted_forces(self, t, gy):
        g, y = gy
        return g, self.system.force_flow(t, y)

    def lifted_step(self, g: jax.Array, y: jax.Array) -> tuple[jax.Array, jax.Array]:
        r"""The same composition on $(g, \mu)$: the pieces' flows lifted exactly, $g$ held on
        the forces' flow."""
        group = self.system.require_group()
        undamped = self.system.conservative
        flows = FlowList([functools.partial(term.lifted_flow, undamped) for term in self.pieces]
                         + [self._lifted_forces])
        return self.method.compose(flows, (group.check(g, "g"), check_state(y, self.system.dim)), self.h)

    @property
    def exact_flows_per_step(self) -> int:
        return self.method.flows_per_step(len(self.pieces) + 1)

    def step_flops(self) -> float:
        return composition_flops(self, self.method)
