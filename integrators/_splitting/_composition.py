r"""Symmetric compositions of the Strang step: $\Phi_h = S_{\gamma_s h}\circ\cdots\circ
S_{\gamma_1 h}$ with $S$ the Strang step and a palindromic table $\gamma$ (Hairer, Lubich,
Wanner, *Geometric Numerical Integration*, 2nd ed., Sec. II.4 and V.3). Each method is its
table."""

from __future__ import annotations

import abc

import jax
import jax.numpy as jnp
import numpy as np

from ._base import AbstractSplittingMethod, symmetric_coefficients
from ._strang import Strang


class AbstractCompositionMethod(AbstractSplittingMethod):
    r"""$\Phi_h = S_{\gamma_s h}\circ\cdots\circ S_{\gamma_1 h}$, $\sum_i\gamma_i = 1$, with a
    symmetric table ($\gamma_i = \gamma_{s+1-i}$) so that only odd-order conditions remain.
    Final subclasses give `order` and the table `coefficients` (class attributes); `ordering`
    orders the pieces of every Strang step."""

    @property
    @abc.abstractmethod
    def coefficients(self) -> np.ndarray:
        r"""The table $\gamma_1, \dots, \gamma_s$ (a class attribute of final methods)."""

    def compose_in_order(self, flows, y, h):
        # A scan over the table, not a Python loop: one Strang step is traced and compiled
        # once (7x less code for Yoshida6, and for its Jacobian in `poisson_defect`).
        strang = Strang()

        def body(y, gamma):
            return strang.compose_in_order(flows, y, gamma * h), None

        y, _ = jax.lax.scan(body, y, jnp.asarray(self.coefficients))
        return y

    def flows_per_step(self, n_terms: int) -> int:
        return len(self.coefficients) * Strang().flows_per_step(n_terms)

    def stages(self):
        return Strang(ordering=self.ordering), len(self.coefficients)


_CBRT2 = 2.0 ** (1.0 / 3.0)
_CBRT4 = 4.0 ** (1.0 / 3.0)


class TripleJump(AbstractCompositionMethod):
    r"""Order 4, three Strang steps: $\gamma_1 = \gamma_3 = 1/(2 - 2^{1/3})$,
    $\gamma_2 = -2^{1/3}/(2 - 2^{1/3})$ (Creutz & Gocksch 1989; Suzuki 1990; Yoshida 1990)."""

    order = 4
    coefficients = symmetric_coefficients((1.0 / (2.0 - _CBRT2), -_CBRT2 / (2.0 - _CBRT2)))


class Suzuki(AbstractCompositionMethod):
    r"""Order 4, five Strang steps (Suzuki's fractal, Phys. Lett. A 146 (1990) 319):
    $\gamma_{1,2,4,5} = p = 1/(4 - 4^{1/3})$, $\gamma_3 = 1 - 4p$."""

    order = 4
    coefficients = symmetric_coefficients((1.0 / (4.0 - _CBRT4),) * 2 + (1.0 - 4.0 / (4.0 - _CBRT4),))


class McLachlan4(AbstractCompositionMethod):
    r"""Order 4, five Strang steps with small error constants: McLachlan's symmetric
    composition (R. I. McLachlan, SIAM J. Sci. Comput. 16 (1995) 151-168), in the form of
    Hairer-Lubich-Wanner Sec. V.3.2: $\gamma_1 = \gamma_5 = 0.28$,
    $\gamma_2 = \gamma_4 = 0.62546642846767004501$, $\gamma_3 = 1 - 2(\gamma_1 + \gamma_2)$.
    $\gamma_2$ is the root of the order-4 condition $\sum_i\gamma_i^3 = 0$ for $\gamma_1 = 0.28$
    (McLachlan's rounded optimum)."""

    order = 4
    coefficients = symmetric_coefficients(
        (0.28, 0.62546642846767004501, 1.0 - 2.0 * (0.28 + 0.62546642846767004501))
    )


class Yoshida6(AbstractCompositionMethod):
    r"""Order 6, seven Strang steps: Yoshida's solution A (H. Yoshida, Phys. Lett. A 150 (1990)
    262, Table 1): $w_1 = -1.17767998417887$, $w_2 = 0.235573213359357$,
    $w_3 = 0.784513610477560$, $w_0 = 1 - 2(w_1 + w_2 + w_3)$; $\gamma = (w_3, w_2, w_1, w_0,
    w_1, w_2, w_3)$. (The 15 published digits satisfy the order conditions to ~1e-14, an error
    term far below round-off at any usable step.)"""

    order = 6
    _w = (0.784513610477560, 0.235573213359357, -1.17767998417887)
    coefficients = symmetric_coefficients(_w + (1.0 - 2.0 * sum(_w),))
