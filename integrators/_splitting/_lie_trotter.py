r"""Lie-Trotter splitting (order 1)."""

from __future__ import annotations

import numpy as np

from ._base import AbstractSplittingMethod


class LieTrotter(AbstractSplittingMethod):
    r"""$\Phi_h = \varphi^{[N]}_h\circ\cdots\circ\varphi^{[1]}_h$: the flow of $H_1$ first, then
    $H_2$, ..., $H_N$. Order 1 (Trotter 1959)."""

    order = 1

    def compose_in_order(self, flows, y, h):
        return flows.chain(np.arange(len(flows)), np.ones(len(flows)), h, y)

    def flows_per_step(self, n_terms: int) -> int:
        return n_terms
