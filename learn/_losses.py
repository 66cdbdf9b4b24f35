"""The training losses of learned maps: means over pairs, functions `loss(model, inputs,
targets)` that a map names in `loss_function`."""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp

from liepoisson import vmap_samples


def state_mse(model: Any, y0: jax.Array, y1: jax.Array) -> jax.Array:
    """Mean squared error of one learned step over pairs `(N, dim)`: the state loss of every
    learned map (paper eqs. Loss_function, Loss_function_G_LPNets), through
    `training_prediction` (the explicit residual form of an implicit step)."""
    return jnp.mean((vmap_samples(model.training_prediction)(y0, y1) - y1) ** 2)


def alpha_mse(model: Any, y0: jax.Array, alpha: jax.Array) -> jax.Array:
    r"""MSE of an LPNet's $\alpha(y_0)$ against the pairs' parameters, in units of the output
    scale of its network (1 for a network without scalings)."""
    scale = jnp.asarray(model.network.output_scales())
    return jnp.mean(((jax.vmap(model.alpha)(y0) - alpha) / scale) ** 2)
