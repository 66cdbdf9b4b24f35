r"""se(3)*: a rotation followed by a shear, a two-flow step with a closed-form inverse.

With $\mu = (\Pi, p)$ and $\alpha = (A, b)$, the step is
$\mathbb T_{(0,b)}\,\mathbb T_{(A,0)}\,\mu$, each factor an exact test flow of se(3)* for time
$t$ (`LieAlgebra.coadjoint_flow`): $\mathbb T_{(A,0)}$ rotates $\Pi$ and $p$ by the same
rotation $R$ (angle $|tA|$ about $A$), $\mathbb T_{(0,b)}$ is the shear
$\Pi \mapsto \Pi - \tau\,b\times p$, $p$ fixed, with $\tau = -\mathrm{sign}\cdot t$ the body
time. Both are Poisson maps, so the step conserves $|p|^2$ and $\Pi\cdot p$ exactly. This is
the paper's data preparation for Kirchhoff's equations, re-derived; it is not a single
$\exp(t\mathbb M(\alpha))$.
"""

from __future__ import annotations

import functools
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from ._catalogue import se3, se3_structure_constants
from ._coadjoint import SE3Flow, _check_not_antiparallel, _shortest_rotation
from ._inverse import checked_flow_parameters
from ._validation import as_scalar_time, as_state, broadcast_batch

_FLOW = SE3Flow()
_C = se3_structure_constants()


def _check_sign(sign: Any) -> int:
    if isinstance(sign, bool) or sign not in (-1, 1):
        raise ValueError(f"sign must be -1 (body) or +1 (spatial); got {sign!r}")
    return int(sign)


@functools.cache
def _algebra(sign: int):
    return se3(sign)


def _body_rotation_shear(alpha: jax.Array, tau: jax.Array, mu: jax.Array) -> jax.Array:
    zero = jnp.zeros_like(alpha[..., :3])
    rotated = _FLOW(_C, jnp.concatenate([alpha[..., :3], zero], axis=-1), tau, mu)
    return _FLOW(_C, jnp.concatenate([zero, alpha[..., 3:]], axis=-1), tau, rotated)


def se3_rotation_shear(alpha: ArrayLike, t: ArrayLike, mu: ArrayLike, *, sign: int = -1) -> jax.Array:
    r"""One rotation-then-shear step $\mathbb T_{(0,b)}\,\mathbb T_{(A,0)}\,\mu$ on se(3)*.

    **Arguments:** `alpha` $= (A, b)$ and `mu` $= (\Pi, p)$ of shape `(..., 6)`, `t` a scalar or
    array, broadcast against each other; `sign`: the algebra's convention, $-1$ body, $+1$
    spatial (`LieAlgebra.sign`). Usable inside `jax.jit`, `jax.vmap` and `jax.grad`.

    **Returns:** the state after the step, `(..., 6)`; for a fixed `alpha` a Poisson map.
    """
    sign = _check_sign(sign)
    alpha = as_state(alpha, "alpha", 6)
    mu = as_state(mu, "mu", 6)
    t = as_scalar_time(t)
    batch = broadcast_batch(6, alpha=alpha.shape[:-1], mu=mu.shape[:-1], t=t.shape)
    alpha = jnp.broadcast_to(alpha, batch + (6,))
    mu = jnp.broadcast_to(mu, batch + (6,))
    return _body_rotation_shear(alpha, jnp.broadcast_to(-sign * t, batch), mu)


def _body_rotation_shear_parameters(mu0, mu1, tau):
    r"""Closed form in body time $\tau$: $A = -w/\tau$ with $w$ the shortest rotation carrying
    $p^0$ to $p^1$ (so $A\perp p^0$); then $d = R\Pi^0 - \Pi^1 = \tau\,b\times p^1$ and the
    minimum-norm $b = p^1\times d/(\tau|p^1|^2)$, $b\perp p^1$ ($d\perp p^1$ exactly when
    $\Pi\cdot p$ agrees: $R\Pi^0\cdot p^1 = \Pi^0\cdot p^0$)."""
    p0, p1, Pi1 = mu0[:, 3:], mu1[:, 3:], mu1[:, :3]
    norm_p1 = np.linalg.norm(p1, axis=-1)
    if np.any(norm_p1 == 0.0):
        i = int(np.argmax(norm_p1 == 0.0))
        raise ValueError(
            f"pair {i}: p = 0; the rotation is not determined by p (a rigid-body pair: use "
            "LieAlgebra.coadjoint_flow_parameters)"
        )
    _check_not_antiparallel(p0, p1, ("p0", "p1"))
    A = -_shortest_rotation(p0, p1) / tau
    rotated = _FLOW(
        _C, jnp.concatenate([A, jnp.zeros_like(A)], axis=-1), jnp.full(len(A), tau), mu0
    )
    d = rotated[:, :3] - Pi1
    b = jnp.cross(p1, d) / (tau * norm_p1[:, None] ** 2)
    return jnp.concatenate([A, b], axis=-1)


def se3_rotation_shear_parameters(
    mu0: ArrayLike, mu1: ArrayLike, t: ArrayLike, *, sign: int = -1, rtol: float = 1e-10, names: tuple[str, str] = ("mu0", "mu1")
) -> np.ndarray:
    r"""The parameters $(A, b)$ with `se3_rotation_shear((A, b), t, mu0, sign=sign) == mu1`.

    Closed form: $A$ the shortest rotation carrying $p^0$ to $p^1$ (axis $p^0\times p^1$,
    angle $\operatorname{atan2}(|p^0\times p^1|, p^0\cdot p^1)$), so $A\perp p^0$; $b$ the
    minimum-norm shear, $b\perp p^1$. Four effective parameters of six, like the
    Casimir-projected coadjoint flow.

    **Arguments:** `mu0`, `mu1` of shape `(..., 6)`; `t` a finite, non-zero scalar; `sign` as
    in `se3_rotation_shear`; `rtol`: the relative Casimir mismatch beyond which a pair is
    rejected; `names`: how error messages call the two states.

    **Returns:** `(..., 6)`. Raises `ValueError` naming the pair when a Casimir ($|p|^2$,
    $\Pi\cdot p$) differs, when $p = 0$ or when $p^0$ and $p^1$ are antiparallel.
    """
    sign = _check_sign(sign)
    algebra = _algebra(sign)
    return checked_flow_parameters(
        mu0,
        mu1,
        t,
        rtol,
        dim=6,
        names=names,
        flow=functools.partial(se3_rotation_shear, sign=sign),
        casimirs=algebra.casimirs,
        casimir_gradients=algebra.casimir_gradients,
        solve=lambda a, b, t, G: _body_rotation_shear_parameters(a, b, -sign * t),
    )
