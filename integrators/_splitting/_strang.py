r"""Strang splitting (order 2, symmetric): the basic step of every composition method."""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence

import jax

from .._step_map import check_state
from ._base import AbstractSplittingMethod


def strang_compose(flows: Sequence[Callable[[float, jax.Array], jax.Array]], y: jax.Array, h: float) -> jax.Array:
    r"""$\varphi^{[1]}_{h/2}\circ\cdots\circ\varphi^{[N-1]}_{h/2}\circ\varphi^{[N]}_h\circ
    \varphi^{[N-1]}_{h/2}\circ\cdots\circ\varphi^{[1]}_{h/2}$ (applied right to left) for
    `flows[k](t, y)` $= \varphi^{[k+1]}_t(y)$: the one Strang composition, shared by the
    classical methods and the symmetric G-LPNet."""
    n = len(flows)
    for k in range(n - 1):
        y = flows[k](0.5 * h, y)
    y = flows[n - 1](h, y)
    for k in reversed(range(n - 1)):
        y = flows[k](0.5 * h, y)
    return y


def strang_step(method: AbstractSplittingMethod, y: jax.Array, h: float) -> jax.Array:
    """The Strang step of `method`'s pieces in its `ordering`."""
    return strang_compose([functools.partial(method.flow, k) for k in range(len(method.terms))], y, h)


def strang_flows(method: AbstractSplittingMethod) -> int:
    """Exact sub-flows of one Strang step: $2N - 1$."""
    return 2 * len(method.terms) - 1


class Strang(AbstractSplittingMethod):
    r"""Strang (1968) splitting
    $\Phi_h = \varphi^{[1]}_{h/2}\cdots\varphi^{[N-1]}_{h/2}\,\varphi^{[N]}_h\,
    \varphi^{[N-1]}_{h/2}\cdots\varphi^{[1]}_{h/2}$: symmetric, $\Phi_{-h} = \Phi_h^{-1}$, order 2.
    """

    order = 2

    def step(self, y):
        return strang_step(self, check_state(y, self.system.dim), self.h)

    @property
    def exact_flows_per_step(self) -> int:
        return strang_flows(self)
