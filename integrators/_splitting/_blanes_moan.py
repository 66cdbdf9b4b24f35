r"""Blanes & Moan's optimised 4th-order partitioned method for two-part splittings."""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from ._base import AbstractSplittingMethod

# S. Blanes, P. C. Moan, "Practical symplectic partitioned Runge-Kutta and Runge-Kutta-Nystrom
# methods", J. Comput. Appl. Math. 142 (2002) 313-330, Table 2, PRK_6 order 4 (BAB form).
_A = (0.0792036964311957, 0.353172906049774, -0.0420650803577195)
_B = (0.209515106613362, -0.143851773179818)
_A_FULL = np.array(_A + (1.0 - 2.0 * sum(_A),) + _A[::-1])
_B_FULL = np.array(_B + (0.5 - sum(_B),) + (0.5 - sum(_B),) + _B[::-1])


class BlanesMoan4(AbstractSplittingMethod):
    r"""Order 4 for $H = H_A + H_B$ (Blanes & Moan 2002, $\mathrm{PRK}_6$, Table 2):
    $\Phi_h = \varphi^A_{a_1h}\varphi^B_{b_1h}\varphi^A_{a_2h}\varphi^B_{b_2h}\varphi^A_{a_3h}
    \varphi^B_{b_3h}\varphi^A_{a_4h}\varphi^B_{b_3h}\varphi^A_{a_3h}\varphi^B_{b_2h}
    \varphi^A_{a_2h}\varphi^B_{b_1h}\varphi^A_{a_1h}$ with
    $a_1 = 0.0792036964311957$, $a_2 = 0.353172906049774$, $a_3 = -0.0420650803577195$,
    $a_4 = 1 - 2(a_1 + a_2 + a_3)$, $b_1 = 0.209515106613362$, $b_2 = -0.143851773179818$,
    $b_3 = 1/2 - (b_1 + b_2)$. $H_A$ is the first piece (of `terms` or `hamiltonian_splitting()`, in `ordering`).

    Raises `ValueError` for a splitting that does not have exactly two pieces.
    """

    order = 4
    a: ClassVar[np.ndarray] = _A_FULL
    b: ClassVar[np.ndarray] = _B_FULL

    def check_terms(self, n_terms: int, what: str) -> None:
        if n_terms != 2:
            raise ValueError(
                f"BlanesMoan4 needs a two-part splitting H = H_A + H_B; {what} has {n_terms} pieces"
            )
        super().check_terms(n_terms, what)

    def compose_in_order(self, flows, y, h):
        indices = np.arange(len(self.a) + len(self.b)) % 2  # A, B, A, ..., A
        weights = np.empty(len(indices))
        weights[0::2], weights[1::2] = self.a, self.b
        return flows.chain(indices, weights, h, y)

    def flows_per_step(self, n_terms: int) -> int:
        return len(self.a) + len(self.b)
