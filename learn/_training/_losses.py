"""The training losses of learned maps: means of squared residuals over pairs, called as
`loss(model, inputs, targets)`, that a map names in `loss_function`."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp

from liepoisson import vmap_samples


@dataclasses.dataclass(frozen=True)
class MeanSquares:
    r"""A least-squares loss: `loss(model, inputs, targets)` is the mean of the squared
    components of `residuals(model, inputs, targets)`; `learn.LevenbergMarquardt` minimises
    the residuals themselves, every other optimiser the mean."""

    residuals: Callable[[Any, jax.Array, jax.Array], jax.Array]
    name: str

    def __call__(self, model: Any, inputs: jax.Array, targets: jax.Array) -> jax.Array:
        return jnp.mean(self.residuals(model, inputs, targets) ** 2)

    def count(self, model: Any, inputs: jax.Array, targets: jax.Array) -> int:
        """How many residual components the mean is over (one per component of the targets)."""
        return int(jax.eval_shape(self.residuals, model, inputs, targets).size)

    def __repr__(self) -> str:
        return f"MeanSquares({self.name})"


def _state_residuals(model: Any, y0: jax.Array, y1: jax.Array) -> jax.Array:
    return vmap_samples(model.training_prediction)(y0, y1) - y1


def _alpha_residuals(model: Any, y0: jax.Array, alpha: jax.Array) -> jax.Array:
    scale = jnp.asarray(model.network.output_scales())
    return (jax.vmap(model.alpha)(y0) - alpha) / scale


state_mse = MeanSquares(_state_residuals, "state_mse")
r"""Mean squared error of one learned step over pairs `(N, dim)`: the state loss of every
learned map (paper eqs. Loss_function, Loss_function_G_LPNets), through `training_prediction`
(the explicit residual form of an implicit step); its residuals are the predicted minus the
observed $y_1$."""

alpha_mse = MeanSquares(_alpha_residuals, "alpha_mse")
r"""MSE of an LPNet's $\alpha(y_0)$ against the pairs' parameters, in units of the output scale of
its network (1 for a network without scalings)."""
