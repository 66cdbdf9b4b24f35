r"""The exact solution as a step map, for systems that have one in closed form (the free rigid
body by Jacobi elliptic functions): the baseline with no truncation error at all."""

from __future__ import annotations

import equinox as eqx
import jax

from liepoisson.internals import check_system, positive_float
from liepoisson.systems import AbstractExactlySolvableSystem, AbstractPoissonSystem

from ._step_map import AbstractStepMap, check_state


class ExactFlow(AbstractStepMap):
    r"""$y_{n+1} = \varphi_h(y_n)$ with the system's closed-form solution `system.exact_flow(t, y)`
    (e.g. `RigidBody`: Jacobi elliptic functions). Exact to round-off for every `h`, Poisson
    and Casimir-preserving; one exact flow per step.

    **Arguments:** `system`, a `liepoisson.systems.AbstractExactlySolvableSystem`; `h` > 0.
    """

    system: AbstractExactlySolvableSystem = eqx.field(static=True)
    h: float

    def __init__(self, system: AbstractPoissonSystem, h: float):
        self.system = check_system(system)
        if not isinstance(system, AbstractExactlySolvableSystem):
            raise TypeError(
                f"ExactFlow needs a system with a closed-form solution exact_flow(t, y), a "
                f"liepoisson.systems.AbstractExactlySolvableSystem (e.g. RigidBody); {system!r} is not one"
            )
        self.h = positive_float(h, "h")

    def step(self, y: jax.Array) -> jax.Array:
        return self.system.exact_flow(self.h, check_state(y, self.system.dim))

    @property
    def exact_flows_per_step(self) -> int:
        return 1
