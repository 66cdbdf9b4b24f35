r"""Exact coadjoint flows $\mu(t) = \exp(t\,\mathbb{M}(\alpha))\,\mu(0)$ of linear Hamiltonians.

Every flow here follows the body convention of DESIGN.md (`sign = -1`):
$\mathbb{M}(\alpha)_{ad} = -C_{abd}\,\alpha_b$, so that $\dot\mu = \mathbb{B}(\mu)\,\alpha$.
`LieAlgebra` converts other signs by reversing time. The generic path is the matrix
exponential; `RodriguesFlow` (so(3)) and `SE3Flow` (se(3)) are closed-form fast paths with
the same interface, tested against it.
"""

from __future__ import annotations

import abc

import jax
import jax.numpy as jnp
import numpy as np

# Below this rotation angle the closed-form coefficients switch to their Taylor series; the
# first neglected term is O(theta^6) < 1e-18, far below round-off.
_SMALL_ANGLE = 1e-3


def _cross(a: jax.Array, b: jax.Array) -> jax.Array:
    return jnp.cross(a, b)


def rotation_coefficients(theta2: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
    r"""$(\sin\theta/\theta,\ (1-\cos\theta)/\theta^2,\ (\theta-\sin\theta)/\theta^3)$ from $\theta^2$.

    Safe (finite value and gradient) at $\theta = 0$: the double-`where` keeps the
    unselected branch away from the singular point.
    """
    small = theta2 < _SMALL_ANGLE**2
    t2 = jnp.where(small, 1.0, theta2)
    theta = jnp.sqrt(t2)
    s = jnp.sin(theta)
    half = jnp.sin(0.5 * theta)
    sinc = jnp.where(small, 1.0 - theta2 / 6.0 + theta2**2 / 120.0, s / theta)
    c1 = jnp.where(small, 0.5 - theta2 / 24.0 + theta2**2 / 720.0, 2.0 * half * half / t2)
    c2 = jnp.where(small, 1.0 / 6.0 - theta2 / 120.0 + theta2**2 / 5040.0, (theta - s) / (t2 * theta))
    return sinc, c1, c2


def rotate(k: jax.Array, v: jax.Array) -> jax.Array:
    r"""$\exp(-\hat k)\,v$: rotation of $v$ by the angle $-|k|$ about $k$ (Rodrigues).

    $\exp(-\hat k) = I - \frac{\sin\theta}{\theta}\hat k + \frac{1-\cos\theta}{\theta^2}\hat k^2$,
    $\theta = |k|$.
    """
    sinc, c1, _ = rotation_coefficients(jnp.sum(k * k, axis=-1))
    kv = _cross(k, v)
    return v - sinc[..., None] * kv + c1[..., None] * _cross(k, kv)


class AbstractCoadjointFlow(abc.ABC):
    """How to evaluate $\\exp(t\\,\\mathbb{M}(\\alpha))\\mu$ for one algebra (body convention)."""

    @abc.abstractmethod
    def __call__(
        self, structure_constants: np.ndarray, alpha: jax.Array, t: jax.Array, mu: jax.Array
    ) -> jax.Array:
        """`alpha`, `mu` of shape `(..., n)` and `t` of shape `(...)`, already broadcast."""


# `jax.scipy.linalg.expm` is inaccurate for 1-norms above ~5 (its Pade-13 branch: errors of
# 1e-9 at norm 10 for a rotation generator, jax-ml/jax#26802) and slow to compile and
# differentiate. Scale to 1-norm <= 1/2, where the Taylor polynomial of degree 18 is exact to
# 0.5^19/19! < 1e-22 and backward stable (all terms are bounded by e^{1/2}), then square back.
# The squarings run in a loop of static length (masked), so jit and reverse mode work.
_EXPM_NORM = 0.5
_TAYLOR_DEGREE = 18
_MAX_SQUARINGS = 48


def _square_if(i, carry):
    E, s = carry
    return jnp.where(i < s, E @ E, E), s


@jax.jit
def _expm(A: jax.Array) -> jax.Array:
    """Matrix exponential of a batch `(m, n, n)` of matrices by scaling and squaring."""
    norm = jax.lax.stop_gradient(jnp.max(jnp.sum(jnp.abs(A), axis=-2), axis=-1))
    s = jnp.clip(jnp.ceil(jnp.log2(jnp.maximum(norm, 1e-300) / _EXPM_NORM)), 0, _MAX_SQUARINGS)
    X = A * jnp.exp2(-s)[:, None, None]
    eye = jnp.broadcast_to(jnp.eye(A.shape[-1], dtype=A.dtype), A.shape)
    E = eye
    for k in range(_TAYLOR_DEGREE, 0, -1):  # Horner: I + X (I + X/2 (I + X/3 (...)))
        E = eye + (X @ E) / k
    E, _ = jax.lax.fori_loop(0, _MAX_SQUARINGS, _square_if, (E, s[:, None, None]))
    return E


class MatrixExponentialFlow(AbstractCoadjointFlow):
    r"""Generic path: $\exp(t\,\mathbb{M}(\alpha))\,\mu$ by scaling and squaring."""

    def __call__(self, structure_constants, alpha, t, mu):
        C = jnp.asarray(structure_constants)
        M = -jnp.einsum("abd,...b->...ad", C, alpha)
        A = t[..., None, None] * M
        batch = A.shape[:-2]
        n = A.shape[-1]
        E = _expm(A.reshape((-1, n, n))).reshape(batch + (n, n))
        return jnp.einsum("...ad,...d->...a", E, mu)

    def __repr__(self):
        return "MatrixExponentialFlow()"


class RodriguesFlow(AbstractCoadjointFlow):
    r"""so(3): $\dot\Pi = -\alpha\times\Pi$, the rotation $\Pi(t) = \exp(-t\hat\alpha)\Pi(0)$."""

    def __call__(self, structure_constants, alpha, t, mu):
        return rotate(t[..., None] * alpha, mu)

    def __repr__(self):
        return "RodriguesFlow()"


class SE3Flow(AbstractCoadjointFlow):
    r"""se(3)* with $\mu = (\Pi, p)$, $\alpha = (A, b)$: closed form of
    $\dot\Pi = -A\times\Pi - b\times p$, $\dot p = -A\times p$.

    With $R = \exp(-t\hat A)$ and $V = \int_0^1 \exp(-s\,t\hat A)\,ds
    = I - \frac{1-\cos\theta}{\theta^2}\hat k + \frac{\theta-\sin\theta}{\theta^3}\hat k^2$
    ($k = tA$, $\theta = |k|$): $p(t) = R p$, $\Pi(t) = R\Pi - (t V b)\times p(t)$.
    """

    def __call__(self, structure_constants, alpha, t, mu):
        k = t[..., None] * alpha[..., :3]
        Pi, p = mu[..., :3], mu[..., 3:]
        sinc, c1, c2 = rotation_coefficients(jnp.sum(k * k, axis=-1))
        p_t = p - sinc[..., None] * _cross(k, p) + c1[..., None] * _cross(k, _cross(k, p))
        Pi_r = Pi - sinc[..., None] * _cross(k, Pi) + c1[..., None] * _cross(k, _cross(k, Pi))
        tb = t[..., None] * alpha[..., 3:]
        ktb = _cross(k, tb)
        Vtb = tb - c1[..., None] * ktb + c2[..., None] * _cross(k, ktb)
        return jnp.concatenate([Pi_r - _cross(Vtb, p_t), p_t], axis=-1)

    def __repr__(self):
        return "SE3Flow()"


class DirectSumFlow(AbstractCoadjointFlow):
    """Blockwise flow of a direct sum: each summand keeps its own (fast) path."""

    def __init__(self, flows, dims, structure_constants):
        self.flows = tuple(flows)
        self.dims = tuple(int(d) for d in dims)
        self.blocks = tuple(np.asarray(c) for c in structure_constants)

    def __call__(self, structure_constants, alpha, t, mu):
        out, start = [], 0
        for flow, n, C in zip(self.flows, self.dims, self.blocks):
            sl = slice(start, start + n)
            out.append(flow(C, alpha[..., sl], t, mu[..., sl]))
            start += n
        return jnp.concatenate(out, axis=-1)

    def __repr__(self):
        return f"DirectSumFlow({list(self.flows)})"
