r"""Strang splitting (order 2, symmetric): the basic step of every composition method."""

from __future__ import annotations

import numpy as np

from ._base import AbstractSplittingMethod


class Strang(AbstractSplittingMethod):
    r"""Strang (1968) splitting
    $\Phi_h = \varphi^{[1]}_{h/2}\cdots\varphi^{[N-1]}_{h/2}\,\varphi^{[N]}_h\,
    \varphi^{[N-1]}_{h/2}\cdots\varphi^{[1]}_{h/2}$ (applied right to left): symmetric,
    $\Phi_{-h} = \Phi_h^{-1}$, order 2.
    """

    order = 2

    def compose_in_order(self, flows, y, h):
        n = len(flows)
        indices = np.r_[np.arange(n - 1), n - 1, np.arange(n - 2, -1, -1)]
        return flows.chain(indices, np.where(indices == n - 1, 1.0, 0.5), h, y)

    def flows_per_step(self, n_terms: int) -> int:
        return 2 * n_terms - 1
