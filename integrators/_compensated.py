r"""Compensated accumulation: a step map whose state is carried between its updates (flows,
steps) as an unevaluated sum $y = y_{hi} + y_{lo}$, each update adding its increment
$\delta$ by an error-free sum (Knuth's TwoSum, *The Art of Computer Programming* vol. 2,
Sec. 4.2.2; Kahan's compensated summation, Comm. ACM 8 (1965) 40; Ogita, Rump & Oishi, SIAM
J. Sci. Comput. 26 (2005) 1955).

A map that keeps the Casimirs exactly in exact arithmetic (a composition of exact flows, an
isospectral conjugation) loses them over a long run to round-off, and most of it is the
rounding of the sum $y + \delta$ ($\epsilon|y|$ an update, a random walk over the updates).
Carried in two parts, the state loses only the rounding of the increment itself, of order
$\epsilon|\delta|$ where the increment is formed without the cancellation of a difference.
`Compensated(step_map)` is the variant, for any `AbstractCompensable` map (`learn.GLPNet`,
`integrators.IsospectralMidpoint`); the plain map is unchanged.
"""

from __future__ import annotations

import abc
from typing import Any

import jax
import jax.numpy as jnp

from liepoisson.systems import AbstractPoissonSystem

from ._step_map import AbstractStepMap, check_h, check_state, traced_h, xla_flops


def two_sum(a: jax.Array, b: jax.Array) -> tuple[jax.Array, jax.Array]:
    r"""$(s, e)$ with $s = \mathrm{fl}(a + b)$ and $s + e = a + b$ exactly, elementwise, for
    any finite $a, b$ (Knuth's TwoSum: six operations, no branch, no ordering of $|a|, |b|$;
    complex entries part by part, their sums being exact part by part)."""
    s = a + b
    b_virtual = s - a
    return s, (a - (s - b_virtual)) + (b - b_virtual)


class AbstractCompensable(AbstractStepMap):
    r"""A step map that can run with compensated accumulation: what `Compensated` wraps.

    Its compensated form is a carried state holding the low part $y_{lo}$ beside the map's
    own (`compensated_carry`), one step on it (`compensated_step_carry`) and the state back
    (`compensated_uncarry`); `Compensated` runs these in `rollout`. A composition of exact
    flows (`integrators.splitting.AbstractCompensableStepMap`, a `learn.GLPNet`) and the
    isospectral methods (`IsospectralMidpoint`, `IsospectralTripleJump`) are ones.
    """

    @abc.abstractmethod
    def compensated_carry(self, y: jax.Array) -> Any:
        """The state `y` `(dim,)` carried with a zero low part."""

    @abc.abstractmethod
    def compensated_step_carry(self, c: Any) -> Any:
        """One step on a state carried by `compensated_carry`, its increments added by
        `two_sum`."""

    @abc.abstractmethod
    def compensated_uncarry(self, c: Any) -> jax.Array:
        """The state `(dim,)` of a compensated carried one."""

    def compensated_step(self, y: jax.Array) -> jax.Array:
        """One compensated step from `y` alone (default: carry, one step, uncarry)."""
        return self.compensated_uncarry(self.compensated_step_carry(self.compensated_carry(y)))

    def compensated_step_flops(self) -> float:
        """XLA's flop count of `compensated_step` (as `step_flops` for `step`)."""
        return xla_flops(lambda m, y: m.compensated_step(y), traced_h(self), jnp.zeros(self.system.dim))


class Compensated(AbstractStepMap):
    r"""`step_map` with compensated accumulation: its state carried between its updates, and
    between steps of a `rollout`, as $y_{hi} + y_{lo}$, each increment added by `two_sum`.

    The same map in exact arithmetic; in floating point each update loses the rounding of its
    increment, $\epsilon|\delta|$, instead of that of the sum $y + \delta$, $\epsilon|y|$: the
    Casimirs random-walk a factor of about $|\delta|/|y|$ slower. For a composition of exact
    flows (`learn.GLPNet`) every flow is compensated (`integrators.splitting.compensated_flow`);
    for the isospectral methods every step's increment $W_{n+1} - W_n$ (quflow's `compsum`),
    its products formed more accurately (`IsospectralMidpoint`). The costs beside the plain
    maps': `benchmarks/casimir_drift.py`, `benchmarks/zeitlin.py`.

    **Arguments:** `step_map`, an `AbstractCompensable` map (a `learn.GLPNet`, an
    `integrators.IsospectralMidpoint`). Its `system`, `h`, `exact_flows_per_step` and
    `divergence_hint` are this map's; `with_h` changes the wrapped map's step.
    """

    step_map: AbstractCompensable

    def __init__(self, step_map: AbstractCompensable):
        if not isinstance(step_map, AbstractCompensable):
            expected = ("step_map must be a step map that can run compensated (an integrators.AbstractCompensable: "
                        "a learn.GLPNet, an integrators.IsospectralMidpoint or IsospectralTripleJump)")
            raise TypeError(f"{expected}; got {step_map!r}" if isinstance(step_map, AbstractStepMap)
                            else f"{expected}; got a {type(step_map).__name__}")
        self.step_map = step_map

    @property
    def system(self) -> AbstractPoissonSystem:  # type: ignore[override]
        return self.step_map.system

    @property
    def h(self) -> float | None:  # type: ignore[override]
        return self.step_map.h

    @property
    def label(self) -> str:
        return f"Compensated({self.step_map.label})"

    @property
    def exact_flows_per_step(self) -> int:
        return self.step_map.exact_flows_per_step

    @property
    def divergence_hint(self) -> str:
        return self.step_map.divergence_hint

    def with_h(self, h: float) -> Compensated:
        return Compensated(self.step_map.with_h(h))

    def carry(self, y: jax.Array) -> Any:
        return self.step_map.compensated_carry(y)

    def step_carry(self, c: Any) -> Any:
        return self.step_map.compensated_step_carry(c)

    def uncarry(self, c: Any) -> jax.Array:
        return self.step_map.compensated_uncarry(c)

    def step(self, y: jax.Array) -> jax.Array:
        check_h(self)
        return self.step_map.compensated_step(check_state(y, self.system.dim))

    def step_flops(self) -> float:
        return self.step_map.compensated_step_flops()
