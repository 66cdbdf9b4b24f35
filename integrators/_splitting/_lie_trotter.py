r"""Lie-Trotter splitting (order 1)."""

from __future__ import annotations

from ._base import AbstractSplittingMethod


class LieTrotter(AbstractSplittingMethod):
    r"""$\Phi_h = \varphi^{[N]}_h\circ\cdots\circ\varphi^{[1]}_h$: the flow of $H_1$ first, then
    $H_2$, ..., $H_N$. Order 1 (Trotter 1959)."""

    order = 1

    @classmethod
    def compose(cls, flows, y, h):
        for flow in flows:
            y = flow(h, y)
        return y

    @classmethod
    def flows_per_step(cls, n_terms: int) -> int:
        return n_terms
