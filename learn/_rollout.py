"""Compiled evaluation of learned maps: batched steps, rollouts (lax.scan), Poisson defects."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp


@eqx.filter_jit
def batched_step(model, y: jax.Array) -> jax.Array:
    """`y` `(N, dim)` -> `(N, dim)`."""
    return jax.vmap(model._step)(y)


@eqx.filter_jit
def rollout(model, y0: jax.Array, n_steps: int) -> jax.Array:
    """`y0` `(N, dim)` -> `(N, n_steps+1, dim)`."""
    step = jax.vmap(model._step)

    def body(y, _):
        y = step(y)
        return y, y

    _, ys = jax.lax.scan(body, y0, None, length=n_steps)
    return jnp.concatenate([y0[:, None], jnp.swapaxes(ys, 0, 1)], axis=1)


@eqx.filter_jit
def poisson_defect(model, y: jax.Array) -> jax.Array:
    """`y` `(N, dim)` -> `(N,)`: max |J B(y) J^T - B(T y)|."""

    def step_and_image(x):
        y = model._step(x)
        return y, y

    def one(x):
        J, y = jax.jacfwd(step_and_image, has_aux=True)(x)  # the step once, not twice
        B0 = model.system.poisson_tensor(x)
        B1 = model.system.poisson_tensor(y)
        return jnp.max(jnp.abs(J @ B0 @ J.T - B1))

    return jax.vmap(one)(y)


def state_mse(model, y0: jax.Array, y1: jax.Array) -> jax.Array:
    """Mean squared error of one learned step over pairs `(N, dim)`: the state loss of every
    learned map (paper eqs. Loss_function, Loss_function_G_LPNets). Traceable, not jitted."""
    return jnp.mean((jax.vmap(model._step)(y0) - y1) ** 2)
