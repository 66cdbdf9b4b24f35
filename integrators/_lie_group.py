r"""Lie-group methods on the coadjoint action, for $\dot\mu = \mathbb B(\mu)\,\xi(\mu)$ with a
state-dependent generator $\xi$ (`system.generator`: $\nabla H$, plus the dissipation of a
`liepoisson.systems.DoubleBracket`).

Each stage freezes the generator and moves by its exact coadjoint flow, `system.test_flow(xi,
t, mu)`, so every step stays on the coadjoint orbit and conserves every Casimir to round-off,
damped or not. The step is not a Poisson map (the generator depends on the state), so for a
Hamiltonian system these methods conserve neither the energy nor the symplectic structure of
the orbit; for a damped one they keep exactly what the flow keeps. References: Iserles,
Munthe-Kaas, Norsett & Zanna, *Lie-group methods*, Acta Numerica 9 (2000); Celledoni,
Marthinsen & Owren, *Commutator-free Lie group methods*, Future Gener. Comput. Syst. 19 (2003)."""

from __future__ import annotations

import abc
from collections.abc import Callable
from typing import ClassVar

import equinox as eqx
import jax

from liepoisson.internals import check_system, positive_float, refuse_nonholonomic
from liepoisson.systems import AbstractForcedSystem, AbstractLiePoissonSystem

from ._step_map import AbstractStepMap, check_state

#: $\xi(\mu)$ for one state.
Generator = Callable[[jax.Array], jax.Array]
#: The exact flow $\exp(t\,\xi)\cdot\mu$ of a frozen generator, `flow(xi, t, mu)`.
CoadjointFlow = Callable[[jax.Array, float | jax.Array, jax.Array], jax.Array]


def check_lie_poisson(system, what: str = "system") -> AbstractLiePoissonSystem:
    """`system` if it is Lie-Poisson (a coadjoint action to move by); `TypeError` otherwise."""
    check_system(system)
    if not isinstance(system, AbstractLiePoissonSystem):
        raise TypeError(
            f"{what} must be a Lie-Poisson system (RigidBody, HeavyTop, Kirchhoff, a LiePoissonSystem or "
            f"a DoubleBracket of one): Lie-group methods move by its coadjoint action; got {type(system).__name__}"
        )
    refuse_nonholonomic(system, "a Lie-group method")
    if isinstance(system, AbstractForcedSystem):
        raise ValueError(  # noqa: TRY004 (a system of the right type, unsuitable)
            f"{what} is forced ({system!r}): its forces move the momenta off the coadjoint orbit, where a Lie-group "
            "method cannot follow. Use integrators.ForcedSplitting, integrators.RK4 or integrators.ground_truth")
    return system


class AbstractLieGroupMethod(AbstractStepMap):
    r"""A Lie-group method $\mu_{n+1} = \Phi_h(\mu_n)$ for $\dot\mu = \mathbb B(\mu)\,\xi(\mu)$:
    compositions of exact coadjoint flows with generators frozen per stage.

    A method is its rule, `advance(generator, flow, mu, h)`, a class method on any generator
    and coadjoint flow: the step maps apply it to `system.generator`, `DampedSplitting` to the
    dissipative part alone.

    **Arguments:** `system`, a Lie-Poisson system (`liepoisson.systems.AbstractLiePoissonSystem`,
    damped or not); `h` > 0.
    """

    system: AbstractLiePoissonSystem = eqx.field(static=True)
    h: float
    order: ClassVar[int]
    #: Coadjoint flows (exponentials) per step.
    exponentials: ClassVar[int]

    def __init__(self, system: AbstractLiePoissonSystem, h: float):
        self.system = check_lie_poisson(system)
        self.h = positive_float(h, "h")

    @classmethod
    @abc.abstractmethod
    def advance(cls, generator: Generator, flow: CoadjointFlow, y: jax.Array, h: float | jax.Array) -> jax.Array:
        r"""$\Phi_h(y)$ for one state, the generator frozen per stage."""

    def step(self, y: jax.Array) -> jax.Array:
        return type(self).advance(self.system.generator, self.system.test_flow, check_state(y, self.system.dim), self.h)

    @property
    def exact_flows_per_step(self) -> int:
        return type(self).exponentials


class LieEuler(AbstractLieGroupMethod):
    r"""The Lie-Euler method $\mu_{n+1} = \exp(h\,\xi(\mu_n))\cdot\mu_n$: order 1, one flow.
    An LPNet's step has this form, its generator learned."""

    order = 1
    exponentials = 1

    @classmethod
    def advance(cls, generator, flow, y, h):
        return flow(generator(y), h, y)


class CommutatorFree2(AbstractLieGroupMethod):
    r"""The commutator-free method of order 2 built on Heun's method (Celledoni, Marthinsen &
    Owren 2003): $F_1 = \xi(\mu)$, $F_2 = \xi(\exp(hF_1)\cdot\mu)$,
    $\mu_{n+1} = \exp(\tfrac h2 F_2)\cdot\exp(\tfrac h2 F_1)\cdot\mu$ (right to left); three flows."""

    order = 2
    exponentials = 3

    @classmethod
    def advance(cls, generator, flow, y, h):
        F1 = generator(y)
        F2 = generator(flow(F1, h, y))
        return flow(F2, 0.5 * h, flow(F1, 0.5 * h, y))


class CommutatorFree4(AbstractLieGroupMethod):
    r"""The commutator-free method of order 4 of Celledoni, Marthinsen & Owren (2003), on the
    classical Runge-Kutta tableau: $F_i = \xi(Y_i)$ with $Y_1 = \mu$,
    $Y_2 = \exp(\tfrac h2 F_1)\cdot\mu$, $Y_3 = \exp(\tfrac h2 F_2)\cdot\mu$,
    $Y_4 = \exp(h(F_3 - \tfrac12 F_1))\cdot Y_2$, and
    $\mu_{n+1} = \exp(h(-\tfrac1{12}F_1 + \tfrac16 F_2 + \tfrac16 F_3 + \tfrac14 F_4))\cdot
    \exp(h(\tfrac14 F_1 + \tfrac16 F_2 + \tfrac16 F_3 - \tfrac1{12}F_4))\cdot\mu$ (right to
    left); five flows."""

    order = 4
    exponentials = 5

    @classmethod
    def advance(cls, generator, flow, y, h):
        F1 = generator(y)
        Y2 = flow(F1, 0.5 * h, y)
        F2 = generator(Y2)
        F3 = generator(flow(F2, 0.5 * h, y))
        F4 = generator(flow(F3 - 0.5 * F1, h, Y2))
        first = (1 / 4) * F1 + (1 / 6) * (F2 + F3) - (1 / 12) * F4
        second = -(1 / 12) * F1 + (1 / 6) * (F2 + F3) + (1 / 4) * F4
        return flow(second, h, flow(first, h, y))


#: Every Lie-group method, for parametrised tests and studies.
LIE_GROUP_METHODS = (LieEuler, CommutatorFree2, CommutatorFree4)
