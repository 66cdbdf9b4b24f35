r"""Strang splitting (order 2, symmetric): the basic step of every composition method."""

from __future__ import annotations

import numpy as np

from ._base import AbstractSplittingMethod, IndexedFlows


class Strang(AbstractSplittingMethod):
    r"""Strang (1968) splitting
    $\Phi_h = \varphi^{[1]}_{h/2}\cdots\varphi^{[N-1]}_{h/2}\,\varphi^{[N]}_h\,
    \varphi^{[N-1]}_{h/2}\cdots\varphi^{[1]}_{h/2}$ (applied right to left): symmetric,
    $\Phi_{-h} = \Phi_h^{-1}$, order 2.
    """

    order = 2

    @classmethod
    def compose(cls, flows, y, h):
        n = len(flows)
        if isinstance(flows, IndexedFlows):
            order = np.r_[np.arange(n - 1), n - 1, np.arange(n - 2, -1, -1)]
            return flows.scan(order, np.where(order == n - 1, 1.0, 0.5), h, y)
        for k in range(n - 1):
            y = flows[k](0.5 * h, y)
        y = flows[n - 1](h, y)
        for k in reversed(range(n - 1)):
            y = flows[k](0.5 * h, y)
        return y

    @classmethod
    def flows_per_step(cls, n_terms: int) -> int:
        return 2 * n_terms - 1
