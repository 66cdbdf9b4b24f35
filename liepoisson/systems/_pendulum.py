"""The extended pendulum of Jin et al. (2022): an affine, non-Lie-Poisson bracket."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .._coadjoint import rotation_coefficients
from .._polynomial import Polynomial
from ._base import AbstractDefinedByParams
from ._terms import CollectiveTerm


class ExtendedPendulum(AbstractDefinedByParams):
    r"""Pendulum extended by a constant $c$ and written in $y = (u, v, r) = (p, q, p^2+q^2+c)$:

    $\mathbb{B}(y) = \begin{pmatrix}0&-1&-2v\\1&0&2u\\2v&-2u&0\end{pmatrix}$,
    $K = \tfrac12u^2 - \cos v + ur - u^3 - uv^2$, Casimir $C = r - u^2 - v^2$
    ([the paper](https://arxiv.org/abs/2308.15349), Sec. 5.2, eqs. (34) to (36)).
    """

    name = "ExtendedPendulum"
    dim = 3
    _casimir = Polynomial(3, ((1.0, (0, 0, 1)), (-1.0, (2, 0, 0)), (-1.0, (0, 2, 0))))

    @property
    def params(self):
        return {}

    @property
    def state_names(self):
        return ("u", "v", "r")

    def hamiltonian_components(self, y, xp):
        u, v, r = y
        return 0.5 * u**2 - xp.cos(v) + u * r - u**3 - u * v**2

    def poisson_tensor_components(self, y):
        u, v, _ = y
        return [[0.0, -1.0, -2.0 * v], [1.0, 0.0, 2.0 * u], [2.0 * v, -2.0 * u, 0.0]]

    @property
    def casimir_polynomials(self):
        return (self._casimir,)

    def _test_flow(self, alpha, t, y):
        r"""$H = \alpha\cdot y$: $(u, v)$ rotates with $\omega = 2\alpha_3$ about a fixed centre,
        $\dot z = \omega J z + (-\alpha_2, \alpha_1)$, solved as
        $z(t) = R(\omega t) z_0 + t\,[\mathrm{sinc}(\theta) I + \theta\,c_1(\theta) J]\,(-\alpha_2, \alpha_1)$;
        then $r$ follows from the conserved Casimir, $r = C_0 + u^2 + v^2$.
        (The paper's $\mathbb{T}_{1,2,3}$ are the special cases with one non-zero $\alpha_a$.)
        """
        u, v, r = y[..., 0], y[..., 1], y[..., 2]
        theta = 2.0 * alpha[..., 2] * t
        sinc, c1, _ = rotation_coefficients(theta * theta)
        cos, sin = 1.0 - theta * theta * c1, theta * sinc
        cu, cv = -alpha[..., 1], alpha[..., 0]
        a, b = t * sinc, t * theta * c1  # int_0^t R(omega s) ds = a I + b J
        u1 = cos * u - sin * v + a * cu - b * cv
        v1 = sin * u + cos * v + b * cu + a * cv
        casimir = r - u * u - v * v
        return jnp.stack([u1, v1, casimir + u1 * u1 + v1 * v1], axis=-1)

    def hamiltonian_splitting(self):
        r"""$K = (\tfrac12 u^2 + uC) + (-\cos v)$ with the Casimir $C = r - u^2 - v^2$ frozen:
        each piece is a function of one coordinate and of $C$, hence exactly solvable."""
        e_u, e_v = np.eye(3)[0], np.eye(3)[1]
        return (
            CollectiveTerm(e_u, lambda s, c: 0.5 * s[0] ** 2 + s[0] * c[0], "U", uses_casimirs=True),
            CollectiveTerm(e_v, lambda s: -jnp.cos(s[0]), "V"),
        )
