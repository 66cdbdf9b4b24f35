r"""Casimir values, gradients and their scale: the one evaluation of polynomial Casimirs shared by
Lie algebras and Poisson systems."""

from __future__ import annotations

from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from ._polynomial import Polynomial


def casimir_values(polynomials: Sequence[Polynomial], y: jax.Array) -> jax.Array:
    r"""$C_j(y)$ for each polynomial, shape `(..., k)` for `y` of shape `(..., dim)` (`k` may be 0)."""
    comps = [y[..., i] for i in range(y.shape[-1])]
    vals = [jnp.broadcast_to(p.evaluate(comps), y.shape[:-1]) for p in polynomials]
    return jnp.stack(vals, axis=-1) if vals else jnp.zeros(y.shape[:-1] + (0,))


def casimir_gradient_values(gradients: Sequence[Sequence[Polynomial]], y: jax.Array) -> jax.Array:
    r"""$\partial C_j/\partial y$ from the gradient polynomials of each Casimir (`p.gradient()`),
    shape `(..., k, dim)` for `y` of shape `(..., dim)`."""
    comps = [y[..., i] for i in range(y.shape[-1])]
    rows = [
        jnp.stack([jnp.broadcast_to(g.evaluate(comps), y.shape[:-1]) for g in grads], axis=-1)
        for grads in gradients
    ]
    return jnp.stack(rows, axis=-2) if rows else jnp.zeros(y.shape[:-1] + (0, y.shape[-1]))


def casimir_scale(gradients: ArrayLike, y: ArrayLike) -> np.ndarray:
    r"""$|\nabla C_j(y)|\,|y|$, the size against which a change of the Casimir $C_j$ at $y$ is
    measured (a change of $y$ by $\delta$ changes $C_j$ by at most about $|\nabla C_j||\delta|$).

    **Arguments:** `gradients` `(..., k, dim)`, the Casimir gradients at `y` (`casimir_gradients(y)`);
    `y` `(..., dim)`.

    **Returns:** `(..., k)`.
    """
    return np.linalg.norm(gradients, axis=-1) * np.linalg.norm(y, axis=-1)[..., None]
