r"""Lie-Trotter splitting (order 1)."""

from __future__ import annotations

import numpy as np

from ._base import AbstractSplittingMethod, IndexedFlows


class LieTrotter(AbstractSplittingMethod):
    r"""$\Phi_h = \varphi^{[N]}_h\circ\cdots\circ\varphi^{[1]}_h$: the flow of $H_1$ first, then
    $H_2$, ..., $H_N$. Order 1 (Trotter 1959)."""

    order = 1

    @classmethod
    def compose(cls, flows, y, h):
        if isinstance(flows, IndexedFlows):
            return flows.scan(np.arange(len(flows)), np.ones(len(flows)), h, y)
        for flow in flows:
            y = flow(h, y)
        return y

    @classmethod
    def flows_per_step(cls, n_terms: int) -> int:
        return n_terms
