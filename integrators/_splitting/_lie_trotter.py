r"""Lie-Trotter splitting (order 1)."""

from __future__ import annotations

from ._base import AbstractSplittingMethod


class LieTrotter(AbstractSplittingMethod):
    r"""$\Phi_h = \varphi^{[N]}_h\circ\cdots\circ\varphi^{[1]}_h$: the flow of $H_1$ first, then
    $H_2$, ..., $H_N$. Order 1 (Trotter 1959)."""

    order = 1

    def _step(self, y, h):
        for k in range(len(self.terms)):
            y = self.flow(k, h, y)
        return y
