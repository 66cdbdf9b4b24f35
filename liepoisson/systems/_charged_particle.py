"""A charged particle in the plane, in a magnetic field B = B3(x) e3 and a central potential."""

from __future__ import annotations

import numbers

import jax.numpy as jnp
import numpy as np

from .._validation import as_state, positive_float
from ._base import AbstractDefinedByParams
from ._terms import CollectiveTerm

# Below this |alpha_x| the field integral uses its a -> 0 limit, Phi = |x0| t (exact at 0;
# the neglected term is O(|a| t^2) < 1e-100).
_TINY = 1e-100


def _finite_float(x, name: str) -> float:
    if isinstance(x, (bool, str, bytes)) or not (
        isinstance(x, numbers.Real) or (isinstance(x, np.ndarray) and x.ndim == 0)
    ):
        raise TypeError(f"{name} must be a finite real number; got {type(x).__name__} {x!r}")
    if np.iscomplexobj(x):
        raise TypeError(f"{name} must be a finite real number; got {x!r}")
    value = float(x)
    if not np.isfinite(value):
        raise ValueError(f"{name} must be finite; got {value!r}")
    return value


def segment_field_integral(x0: jnp.ndarray, a: jnp.ndarray, t: jnp.ndarray) -> jnp.ndarray:
    r"""$\Phi(t) = \int_0^t |x_0 + a s|\,ds$ for planar $x_0, a$
    ([the paper](https://arxiv.org/abs/2308.15349), Sec. 5.3, eq. (55)).

    With $A = |a|$, $z = x\cdot a/A$, $d = |x_0\times a|/A$, $r = |x|$ and
    $G(z) = \tfrac12\left(z\sqrt{z^2+d^2} + d^2\operatorname{asinh}(z/d)\right)$,
    $\Phi = (G(z_1) - G(z_0))/A$. That difference quotient cancels catastrophically for small
    $At$ (its derivative in $a$ errs by $\epsilon|x_0|^2/A^2$), so it is evaluated as
    $\Phi = \tfrac t2\left(r_0 + r_1 - q\,(1 - \operatorname{asinh}(D)/D)\right)$ with
    $q = r_0 - z_0(z_0+z_1)/(r_0+r_1) \ge 0$ and $D = A t q/d^2$ (from
    $\operatorname{asinh}u - \operatorname{asinh}v = \operatorname{asinh}(u\sqrt{1+v^2} - v\sqrt{1+u^2})$),
    which has no division by $A$ beyond the direction of $a$. $A\to 0$, $d \to 0$ (a segment
    through the origin) and $t < 0$ are safe.
    """
    A2 = a[..., 0] ** 2 + a[..., 1] ** 2
    moving = A2 > _TINY**2
    # Unselected branches of `where` must stay finite in value and derivative (else their
    # zero cotangent times an infinite partial gives NaN gradients): a stand-in direction
    # when a ~ 0, and d^2 below 1e-100 r^2 treated as 0 (a segment through the origin), where
    # the neglected part of q (1 - asinh(D)/D) is below 1e-98 |x|.
    a_s = jnp.where(moving[..., None], a, jnp.array([1.0, 0.0]))
    A = jnp.sqrt(jnp.where(moving, A2, 1.0))
    # The unit direction of a: products of powers of A (A^4 ~ 1e-400 underflows, autodiff
    # of x / A^2 forms 1/A^4) would make the derivatives inf * 0 = NaN.
    e = a_s / A[..., None]
    x1 = x0 + a_s * t[..., None]
    r0 = jnp.sqrt(x0[..., 0] ** 2 + x0[..., 1] ** 2)
    r1 = jnp.sqrt(x1[..., 0] ** 2 + x1[..., 1] ** 2)
    z0 = x0[..., 0] * e[..., 0] + x0[..., 1] * e[..., 1]
    z1 = z0 + A * t
    rsum = r0 + r1
    rsum_s = jnp.where(rsum > 0, rsum, 1.0)
    q = jnp.where(rsum > 0, r0 - z0 * (z0 + z1) / rsum_s, 0.0)
    d2 = (x0[..., 0] * e[..., 1] - x0[..., 1] * e[..., 0]) ** 2
    has_d = d2 > 1e-100 * (r0 * r0 + r1 * r1)
    D = A * t * q / jnp.where(has_d, d2, 1.0)
    small = has_d & (jnp.abs(D) < 1e-3)
    huge = ~has_d | ~(jnp.abs(D) < 1e150)
    Ds = jnp.where(small | huge, 1.0, D)
    Dm = jnp.where(small, D, 0.0)
    # 1 - asinh(D)/D: series below 1e-3 (next term 5 D^6/112 < 1e-19), 1 for D -> infinity
    one_minus_s = jnp.where(
        small, Dm * Dm / 6.0 - 3.0 * Dm**4 / 40.0, jnp.where(huge, 1.0, 1.0 - jnp.arcsinh(Ds) / Ds)
    )
    phi_moving = 0.5 * t * (r0 + r1 - q * one_minus_s)
    # a -> 0: Phi = |x0| t + (x0 . a) t^2 / (2 |x0|) + O(|a|^2 t^3 / |x0|), exact to 1e-200
    r0s = jnp.where(r0 > 0, r0, 1.0)
    xa = x0[..., 0] * a[..., 0] + x0[..., 1] * a[..., 1]
    phi_still = r0 * t + jnp.where(r0 > 0, xa * t * t / (2.0 * r0s), 0.0)
    return jnp.where(moving, phi_moving, phi_still)


class ChargedParticle(AbstractDefinedByParams):
    r"""Planar charged particle, $y = (p_1, p_2, x_1, x_2)$:
    $\dot p = q\,v\times B - q\nabla\varphi$, $\dot x = v = p/m$, with
    $B = b_0\,r\,e_3$ and $\varphi = k/r$, $r = |x|$ (paper defaults $q = m = b_0 = 1$,
    $k = 1/100$). $H = |p|^2/(2m) + q\varphi$,
    $\mathbb{B} = \begin{pmatrix}-q\hat B & -I\\ I & 0\end{pmatrix}$, no Casimirs; the second
    integral is $I = x_1p_2 - x_2p_1 + q b_0 r^3/3$
    ([the paper](https://arxiv.org/abs/2308.15349), Sec. 5.3, eq. (53)).

    The paper writes $-\tfrac{q}{m}\hat B$ in the tensor; with $\partial H/\partial p = p/m$
    the Lorentz force needs $-q\hat B$. Both agree for the paper's $q = m = 1$.
    """

    name = "ChargedParticle"
    dim = 4

    def __init__(self, charge=1.0, mass=1.0, field_strength=1.0, potential_strength=0.01):
        self.charge = _finite_float(charge, "charge")
        if self.charge == 0:
            raise ValueError(f"charge must be finite and non-zero; got {charge!r}")
        self.mass = positive_float(mass, "mass")
        self.field_strength = _finite_float(field_strength, "field_strength")
        self.potential_strength = _finite_float(potential_strength, "potential_strength")

    @property
    def params(self):
        return {
            "charge": self.charge,
            "mass": self.mass,
            "field_strength": self.field_strength,
            "potential_strength": self.potential_strength,
        }

    @property
    def state_names(self):
        return ("p1", "p2", "x1", "x2")

    def hamiltonian_components(self, y, xp):
        p1, p2, x1, x2 = y
        r = xp.sqrt(x1**2 + x2**2)
        return (p1**2 + p2**2) / (2.0 * self.mass) + self.charge * self.potential_strength / r

    def poisson_tensor_components(self, y):
        _, _, x1, x2 = y
        qB = self.charge * self.field_strength * (x1**2 + x2**2) ** 0.5
        return [
            [0.0, qB, -1.0, 0.0],
            [-1.0 * qB, 0.0, 0.0, -1.0],
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
        ]

    @property
    def casimir_polynomials(self):
        return ()

    singular_reason = "the potential k/r (and the field's |x|) is singular at the origin x = 0"

    def singular(self, y):
        return y[..., 2] ** 2 + y[..., 3] ** 2 == 0  # r^2 underflowing to 0 is the origin to float64

    def angular_integral(self, y) -> jnp.ndarray:
        r"""$I = x_1p_2 - x_2p_1 + q b_0 r^3/3$, conserved by the true flow."""
        y = as_state(y, "y", 4)
        p1, p2, x1, x2 = (y[..., i] for i in range(4))
        r = jnp.sqrt(x1**2 + x2**2)
        return x1 * p2 - x2 * p1 + self.charge * self.field_strength * r**3 / 3.0

    def _test_flow(self, alpha, t, y):
        r"""$H = a\cdot p + \beta\cdot x$: $x(t) = x_0 + a t$,
        $p(t) = p_0 + q b_0\,\Phi(t)\,(a_2, -a_1) - \beta t$ with $\Phi = \int_0^t |x(s)|\,ds$.
        (The paper's $\mathbb{T}_1$ is $\beta = 0$, $\mathbb{T}_2$ is $a = 0$; its
        $x_2(t) = \alpha_2 t + x_1(0)$ is a typo.)"""
        a, beta = alpha[..., :2], alpha[..., 2:]
        x0 = y[..., 2:]
        qphi = self.charge * self.field_strength * segment_field_integral(x0, a, t)
        p1 = y[..., 0] + qphi * a[..., 1] - beta[..., 0] * t
        p2 = y[..., 1] - qphi * a[..., 0] - beta[..., 1] * t
        x = x0 + a * t[..., None]
        return jnp.concatenate([jnp.stack([p1, p2], -1), x], axis=-1)

    def hamiltonian_splitting(self):
        r"""$p_1^2/(2m)$, $p_2^2/(2m)$ (each exact: the other momentum's shear by the field)
        and $q\varphi(x)$ (a kick; $x_1, x_2$ commute)."""
        m, qk = self.mass, self.charge * self.potential_strength
        eye = np.eye(4)
        return (
            CollectiveTerm(eye[0], lambda s: s[0] ** 2 / (2.0 * m), "P1"),
            CollectiveTerm(eye[1], lambda s: s[0] ** 2 / (2.0 * m), "P2"),
            CollectiveTerm(eye[2:], lambda s: qk / jnp.sqrt(s[0] ** 2 + s[1] ** 2), "V"),
        )
