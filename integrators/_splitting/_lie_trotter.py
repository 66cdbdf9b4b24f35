r"""Lie-Trotter splitting (order 1)."""

from __future__ import annotations

from .._step_map import check_state
from ._base import AbstractSplittingMethod


class LieTrotter(AbstractSplittingMethod):
    r"""$\Phi_h = \varphi^{[N]}_h\circ\cdots\circ\varphi^{[1]}_h$: the flow of $H_1$ first, then
    $H_2$, ..., $H_N$. Order 1 (Trotter 1959)."""

    order = 1

    def step(self, y):
        y = check_state(y, self.system.dim)
        for k in range(len(self.terms)):
            y = self.flow(k, self.h, y)
        return y

    @property
    def exact_flows_per_step(self) -> int:
        return len(self.terms)
