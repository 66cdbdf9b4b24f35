r"""Compensated composition of exact flows: the state carried between flows as an unevaluated
sum $y = y_{hi} + y_{lo}$, each flow adding its increment $\delta = \varphi_t(y) - y$ by an
error-free sum (Knuth's TwoSum, *The Art of Computer Programming* vol. 2, Sec. 4.2.2; Kahan's
compensated summation, Comm. ACM 8 (1965) 40; Ogita, Rump & Oishi, SIAM J. Sci. Comput. 26
(2005) 1955).

Every exact flow conserves the Casimirs, so what moves them over a long run is round-off, and
most of it is the rounding of the sum $y + \delta$ ($\epsilon|y|$ a flow, a random walk over
the flows). Carried in two parts, the state loses only the rounding of the increment itself,
of order $\epsilon|\delta|$ where the flow gives $\delta$ in closed form
(`liepoisson.systems.AbstractPoissonSystem.test_flow_increment`), a factor of the rotation angle
of a flow smaller. `integrators.Compensated(step_map)` is the variant; the plain map is unchanged.
"""

from __future__ import annotations

import abc
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp

from .._compensated import AbstractCompensable, two_sum
from .._step_map import traced_h, xla_flops
from ._base import AbstractFlows, AbstractSplittingMethod

#: A state carried in two parts, $y = y_{hi} + y_{lo}$ ($|y_{lo}|$ of the order of an ulp of $y_{hi}$).
Pair = tuple[jax.Array, jax.Array]


def compensated_flow(increment: Callable[[jax.Array], jax.Array], pair: Pair) -> Pair:
    r"""One flow $y \mapsto y + \delta(y)$ on a state carried as $(y_{hi}, y_{lo})$.

    `increment(y)` is $\delta(y) = \varphi_t(y) - y$ with the flow's parameters frozen (for a
    test flow: `system.test_flow_increment(alpha, t, y)`, `alpha` fixed). The high part moves
    by $\delta(y_{hi})$ through TwoSum, the low part by the linear part of the flow,
    $y_{lo} + \delta'(y_{hi})\,y_{lo}$ (forward mode; exact for a coadjoint flow, which is
    linear), plus the rounding error of the high sum. The low part is not renormalised here:
    it grows by at most half an ulp of $y_{hi}$ a flow, its own rounding is of order
    $\epsilon^2|y|$, and `AbstractCompensableStepMap` renormalises it once a step.
    """
    # Renormalising every flow gives the same figures, but inside a G-LPNet's scan over its
    # modules the larger loop body left XLA's CPU path for small loops, at several times the
    # cost of the plain step (benchmarks/casimir_drift.py).
    hi, lo = pair
    delta, delta_lo = jax.jvp(increment, (hi,), (lo,))
    hi, e = two_sum(hi, delta)
    return hi, lo + delta_lo + e


def _renormalised(pair: Pair) -> Pair:
    r"""$(y_{hi}, y_{lo})$ with the same sum and $|y_{lo}| \le$ half an ulp of $y_{hi}$
    (`two_sum` of the two parts)."""
    return two_sum(*pair)


class AbstractCompensableStepMap(AbstractCompensable):
    r"""A step map composed by a splitting `method` of flows that can run on a state carried in
    two parts (`compensated_flows`), each by `compensated_flow`: `Compensated(step_map)`
    carries $(y_{hi}, y_{lo})$ between the flows and between steps, renormalised once a
    step. A `learn.GLPNet` is one."""

    method: eqx.AbstractVar[AbstractSplittingMethod]

    @abc.abstractmethod
    def compensated_flows(self) -> AbstractFlows:
        r"""The map's flows as `flow(t, (y_hi, y_lo))`, each by `compensated_flow`, in the
        order of its `flows()` (the method applies its `ordering`)."""

    def compensated_carry(self, y: jax.Array) -> Pair:
        """`(y, 0)`."""
        return y, jnp.zeros_like(y)

    def compensated_step_carry(self, c: Pair) -> Pair:
        return _renormalised(self.method.compose(self.compensated_flows(), c, self.h))

    def compensated_uncarry(self, c: Pair) -> jax.Array:
        """$\\mathrm{fl}(y_{hi} + y_{lo})$ ($y_{hi}$ itself after a step, which renormalises)."""
        return c[0] + c[1]

    def compensated_step_flops(self) -> float:
        # As `composition_flops`: XLA counts a loop body once, so the inner composition of the
        # method's stages is counted over a list of its flows and multiplied.
        inner, count = self.method.stages()
        return count * xla_flops(_inner_composition, traced_h(self), jnp.zeros(self.system.dim), inner)


def _inner_composition(step_map: AbstractCompensableStepMap, y: jax.Array, inner: AbstractSplittingMethod
                       ) -> jax.Array:
    flows = list(step_map.compensated_flows())
    return step_map.compensated_uncarry(_renormalised(inner.compose(flows, step_map.compensated_carry(y), step_map.h)))
