r"""Exact coadjoint flows $\mu(t) = \exp(t\,\mathbb{M}(\alpha))\,\mu(0)$ of linear Hamiltonians.

Every flow here follows the body convention (`sign = -1`; conventions,
[The Lie-Poisson bracket][the-lie-poisson-bracket]):
$\mathbb{M}(\alpha)_{ad} = -C_{abd}\,\alpha_b$, so that $\dot\mu = \mathbb{B}(\mu)\,\alpha$.
`LieAlgebra` converts other signs by reversing time. The generic path is the matrix
exponential; `RodriguesFlow` (so(3)) and `SE3Flow` (se(3)) are closed-form fast paths with
the same interface, tested against it. Each flow also knows its inverse, `parameters`: the
closed form of the shortest rotation for so(3), Gauss-Newton (`gauss_newton_parameters`)
otherwise; and its increment $\exp(t\,\mathbb{M}(\alpha))\mu - \mu$, `increment`, which the
closed forms give without the cancellation of the difference (a compensated composition adds
it to a state carried in two parts).
"""

from __future__ import annotations

import abc
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from ._expm import expm_action
from ._inverse import gauss_newton_parameters
from ._validation import is_traced

# Below this rotation angle the closed-form coefficients switch to their Taylor series; the
# first neglected term is O(theta^6) < 1e-18, far below round-off.
_SMALL_ANGLE = 1e-3
# Below this ratio |a x b| / (a . b) the shortest rotation's angle/sine uses its series
# (relative error O(r^6) < 1e-24).
_SMALL_RATIO = 1e-4
# |a x b| <= this * |a| |b| with a . b < 0: antiparallel, the rotation axis is not unique.
_ANTIPARALLEL = 1e-8


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


def rotation_increment(k: jax.Array, v: jax.Array) -> jax.Array:
    r"""$\exp(-\hat k)\,v - v = -\frac{\sin\theta}{\theta}\,k\times v
    + \frac{1-\cos\theta}{\theta^2}\,k\times(k\times v)$, $\theta = |k|$: the change
    `rotate` makes, with a rounding error of order $\epsilon\,\theta\,|v|$ (the difference
    `rotate(k, v) - v` carries the $\epsilon|v|$ of the rounded sum). Exactly zero for $k = 0$."""
    sinc, c1, _ = rotation_coefficients(jnp.sum(k * k, axis=-1))
    kv = _cross(k, v)
    return c1[..., None] * _cross(k, kv) - sinc[..., None] * kv


@jax.jit
def _shortest_rotation(a: jax.Array, b: jax.Array) -> jax.Array:
    r"""$\theta\,(a\times b)/|a\times b|$, $\theta = \operatorname{atan2}(|a\times b|, a\cdot b)$:
    the rotation vector $w$ of the shortest rotation, $\exp(\hat w)\,a = b$ for $|a| = |b|$.

    Zero when $a \times b = 0$ and $a\cdot b \ge 0$ (coinciding or zero vectors); the series
    $(1 - r^2/3 + r^4/5)/(a\cdot b)$, $r = |a\times b|/(a\cdot b)$, for small angles, so value
    and gradient stay finite at zero rotation (double `where`). Exactly antiparallel rows also
    give zero: callers reject them first (`_check_not_antiparallel`).
    """
    cross = jnp.cross(a, b)
    s2 = jnp.sum(cross * cross, axis=-1)
    c = jnp.sum(a * b, axis=-1)
    small = (c > 0) & (s2 < (_SMALL_RATIO * c) ** 2)
    degenerate = (s2 == 0) & ~small
    c_small = jnp.where(small, c, 1.0)
    r2 = jnp.where(small, s2, 0.0) / (c_small * c_small)
    s = jnp.sqrt(jnp.where(small | degenerate, 1.0, s2))
    factor = jnp.where(
        small,
        (1.0 - r2 / 3.0 + r2 * r2 / 5.0) / c_small,
        jnp.where(degenerate, 0.0, jnp.arctan2(s, c) / s),
    )
    return factor[..., None] * cross


def _check_not_antiparallel(a: Any, b: Any, names: tuple[str, str]) -> None:
    """`ValueError` naming the first antiparallel pair of rows (skipped for traced values)."""
    if is_traced(a) or is_traced(b):
        return
    a, b = np.asarray(a).reshape(-1, 3), np.asarray(b).reshape(-1, 3)
    s = np.linalg.norm(np.cross(a, b), axis=-1)
    c = np.einsum("ia,ia->i", a, b)
    anti = (s <= _ANTIPARALLEL * np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1)) & (c < 0)
    if np.any(anti):
        i = int(np.argmax(anti))
        raise ValueError(
            f"pair {i}: {names[0]} = {a[i].tolist()} and {names[1]} = {b[i].tolist()} are "
            "antiparallel; the rotation axis carrying one to the other is not unique"
        )


class AbstractCoadjointFlow(abc.ABC):
    """How to evaluate $\\exp(t\\,\\mathbb{M}(\\alpha))\\mu$ for one algebra (body convention),
    and its inverse."""

    @abc.abstractmethod
    def __call__(
        self, structure_constants: np.ndarray, alpha: jax.Array, t: jax.Array, mu: jax.Array
    ) -> jax.Array:
        """`alpha`, `mu` of shape `(..., n)` and `t` of shape `(...)`, already broadcast."""

    def increment(
        self, structure_constants: np.ndarray, alpha: jax.Array, t: jax.Array, mu: jax.Array
    ) -> jax.Array:
        r"""$\exp(t\,\mathbb{M}(\alpha))\mu - \mu$, shapes as `__call__`. Here the
        difference of the flow and `mu` (its rounding error is $\epsilon|\mu|$, that of the
        flow's last sum); a closed form overrides it with one whose error is of order
        $\epsilon\,|t\,\mathbb{M}(\alpha)|\,|\mu|$, what a compensated composition
        (`integrators.splitting.Compensated`) gains by."""
        return self(structure_constants, alpha, t, mu) - mu

    @abc.abstractmethod
    def parameters(
        self,
        structure_constants: np.ndarray,
        mu0: jax.Array,
        mu1: jax.Array,
        t: ArrayLike,
        casimir_gradients: jax.Array,
    ) -> jax.Array:
        r"""The parameters $\alpha$ with $\exp(t\,\mathbb{M}(\alpha))\,\mu_0 = \mu_1$ and
        $\langle\alpha, \nabla C_j(\mu_0)\rangle = 0$ for the Casimirs $C_j$
        ([the paper](https://arxiv.org/abs/2308.15349), Sec. 4, eq. (26)).

        **Arguments:** `mu0`, `mu1` of shape `(N, n)` on one coadjoint orbit; `t` a non-zero
        scalar of either sign (body convention: `LieAlgebra` passes `-sign * t`);
        `casimir_gradients` `(N, k, n)`, the gradients at `mu0` of the algebra's Casimirs in
        its order (a closed form orthogonal to them by construction may ignore them).

        **Returns:** `alpha` `(N, n)` with `self(C, alpha, t, mu0) == mu1`. May raise
        `ValueError` naming a pair whose solution is not unique; otherwise unchecked: use
        `LieAlgebra.coadjoint_flow_parameters`, which validates the input, compares the
        Casimirs of each pair and checks the residual.
        """

    # A flow without state is defined by its type: equal flows share compiled code (the
    # structure constants are an argument). A flow with state compares by identity.
    def __eq__(self, other):
        if self is other:
            return True
        return type(self) is type(other) and not vars(self) and not vars(other)

    def __hash__(self):
        return hash(type(self)) if not vars(self) else id(self)


class MatrixExponentialFlow(AbstractCoadjointFlow):
    r"""Generic path: $\exp(t\,\mathbb{M}(\alpha))\,\mu$ by `expm_action` (Taylor on vectors
    for moderate $|t\,\mathbb M(\alpha)|$ under `vmap_samples`, else scaling and squaring);
    inverse by Gauss-Newton (`gauss_newton_parameters`)."""

    def __call__(self, structure_constants, alpha, t, mu):
        C = jnp.asarray(structure_constants)
        M = -jnp.einsum("abd,...b->...ad", C, alpha)
        return expm_action(t[..., None, None] * M, mu)

    def parameters(self, structure_constants, mu0, mu1, t, casimir_gradients):
        flow = jax.tree_util.Partial(self, structure_constants)
        return gauss_newton_parameters(flow, mu0, mu1, t, casimir_gradients)

    def __repr__(self):
        return "MatrixExponentialFlow()"


class RodriguesFlow(AbstractCoadjointFlow):
    r"""so(3): $\dot\Pi = -\alpha\times\Pi$, the rotation $\Pi(t) = \exp(-t\hat\alpha)\Pi(0)$.

    `parameters` is the closed form of the shortest rotation carrying $\Pi^0$ to $\Pi^1$:
    $t\alpha = -\theta\,(\Pi^0\times\Pi^1)/|\Pi^0\times\Pi^1|$ with $\theta =
    \operatorname{atan2}(|\Pi^0\times\Pi^1|, \Pi^0\cdot\Pi^1)$, so $\alpha\perp\Pi^0$, the
    Casimir gradient (as [the paper](https://arxiv.org/abs/2308.15349)'s
    $A = \Pi^0\times\Pi^1/h$, Sec. 5.1, eq. (30), but with the exact angle instead of
    $\sin\theta$). Zero for coinciding points; `ValueError` for antiparallel ones.
    """

    def __call__(self, structure_constants, alpha, t, mu):
        return rotate(t[..., None] * alpha, mu)

    def increment(self, structure_constants, alpha, t, mu):
        return rotation_increment(t[..., None] * alpha, mu)

    def parameters(self, structure_constants, mu0, mu1, t, casimir_gradients):
        _check_not_antiparallel(mu0, mu1, ("mu0", "mu1"))
        # exp(-t hat(alpha)) = exp(hat w) for t alpha = -w
        return -_shortest_rotation(mu0, mu1) / t

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

    def increment(self, structure_constants, alpha, t, mu):
        r"""$(R\Pi - \Pi - (tVb)\times p(t),\ Rp - p)$, the rotations' parts as in
        `rotation_increment`."""
        k = t[..., None] * alpha[..., :3]
        Pi, p = mu[..., :3], mu[..., 3:]
        sinc, c1, c2 = rotation_coefficients(jnp.sum(k * k, axis=-1))
        kp, kPi = _cross(k, p), _cross(k, Pi)
        dp = c1[..., None] * _cross(k, kp) - sinc[..., None] * kp
        dPi = c1[..., None] * _cross(k, kPi) - sinc[..., None] * kPi
        tb = t[..., None] * alpha[..., 3:]
        ktb = _cross(k, tb)
        Vtb = tb - c1[..., None] * ktb + c2[..., None] * _cross(k, ktb)
        return jnp.concatenate([dPi - _cross(Vtb, p + dp), dp], axis=-1)

    def parameters(self, structure_constants, mu0, mu1, t, casimir_gradients):
        # One exp(t M(A, b)) has no simple closed-form inverse (`se3_rotation_shear` is a
        # different, two-flow step that has one).
        flow = jax.tree_util.Partial(self, structure_constants)
        return gauss_newton_parameters(flow, mu0, mu1, t, casimir_gradients)

    def __repr__(self):
        return "SE3Flow()"


class DirectSumFlow(AbstractCoadjointFlow):
    """Blockwise flow of a direct sum: each summand keeps its own (fast) path.

    `n_casimirs`, the number of Casimirs of each summand (the algebra's Casimirs are the
    summands' in order, as `direct_sum` builds them), makes the inverse blockwise too; without
    it the inverse is Gauss-Newton on the whole sum.
    """

    def __init__(self, flows, dims, structure_constants, n_casimirs=None):
        self.flows = tuple(flows)
        self.dims = tuple(int(d) for d in dims)
        self.blocks = tuple(np.asarray(c) for c in structure_constants)
        self.n_casimirs = None if n_casimirs is None else tuple(int(k) for k in n_casimirs)

    def __call__(self, structure_constants, alpha, t, mu):
        out, start = [], 0
        for flow, n, C in zip(self.flows, self.dims, self.blocks):
            sl = slice(start, start + n)
            out.append(flow(C, alpha[..., sl], t, mu[..., sl]))
            start += n
        return jnp.concatenate(out, axis=-1)

    def increment(self, structure_constants, alpha, t, mu):
        out, start = [], 0
        for flow, n, C in zip(self.flows, self.dims, self.blocks):
            sl = slice(start, start + n)
            out.append(flow.increment(C, alpha[..., sl], t, mu[..., sl]))
            start += n
        return jnp.concatenate(out, axis=-1)

    def parameters(self, structure_constants, mu0, mu1, t, casimir_gradients):
        k = casimir_gradients.shape[-2]
        if self.n_casimirs is None or sum(self.n_casimirs) != k:
            flow = jax.tree_util.Partial(self, structure_constants)
            return gauss_newton_parameters(flow, mu0, mu1, t, casimir_gradients)
        # Each summand's Casimirs depend on its own block only: the problem separates.
        out, start, row = [], 0, 0
        for flow, n, k, C in zip(self.flows, self.dims, self.n_casimirs, self.blocks):
            sl, rows = slice(start, start + n), slice(row, row + k)
            grads = casimir_gradients[..., rows, sl]
            out.append(flow.parameters(C, mu0[..., sl], mu1[..., sl], t, grads))
            start, row = start + n, row + k
        return jnp.concatenate(out, axis=-1)

    def __repr__(self):
        return f"DirectSumFlow({list(self.flows)})"
