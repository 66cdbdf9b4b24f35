"""A small multilayer perceptron with fixed (non-trainable) affine input/output scalings."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp

from ._validation import positive_int

ACTIVATIONS = {
    "sigmoid": jax.nn.sigmoid,
    "tanh": jnp.tanh,
    "relu": jax.nn.relu,
    "softplus": jax.nn.softplus,
    "gelu": jax.nn.gelu,
    "silu": jax.nn.silu,
    "elu": jax.nn.elu,
    # G-LPNet modules with the identity are flows of quadratics phi(s) = a s^2/2 + b s.
    "identity": lambda x: x,
}


def as_key(key: Any) -> jax.Array:
    """An int seed or a JAX PRNG key."""
    if isinstance(key, bool):
        raise TypeError(f"key must be an int seed or a jax.random key; got {key!r}")
    if isinstance(key, int):
        return jax.random.PRNGKey(key)
    if isinstance(key, jax.Array):
        return key
    raise TypeError(f"key must be an int seed or a jax.random key; got {type(key).__name__}")


def check_hidden(hidden: Any) -> tuple[int, ...]:
    if isinstance(hidden, int):
        hidden = (hidden,)
    try:
        hidden = tuple(hidden)
    except TypeError as err:
        raise TypeError(f"hidden must be a sequence of layer widths; got {hidden!r}") from err
    return tuple(positive_int(w, f"hidden[{i}]") for i, w in enumerate(hidden))


def check_activation(activation: Any) -> str:
    if activation not in ACTIVATIONS:
        raise ValueError(f"activation must be one of {sorted(ACTIVATIONS)}; got {activation!r}")
    return activation


class MLP(eqx.Module):
    """$x \\mapsto W_L\\,\\sigma(\\ldots\\sigma(W_1 x + b_1)\\ldots) + b_L$ for one sample."""

    layers: tuple[eqx.nn.Linear, ...]
    activation: str = eqx.field(static=True)

    def __init__(self, in_size: int, out_size: int, hidden: Sequence[int], activation: str, key):
        sizes = (in_size, *hidden, out_size)
        keys = jax.random.split(key, len(sizes) - 1)
        self.layers = tuple(
            eqx.nn.Linear(a, b, key=k, dtype=jnp.float64) for a, b, k in zip(sizes[:-1], sizes[1:], keys)
        )
        self.activation = activation

    def __call__(self, x: jax.Array) -> jax.Array:
        act = ACTIVATIONS[self.activation]
        for layer in self.layers[:-1]:
            x = act(layer(x))
        return self.layers[-1](x)


def affine(values, dim: int) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Per-component (mean, scale) of samples `(N, dim)`; tiny spreads are floored so that a
    (near-)constant component does not blow up the scaling."""
    import numpy as np

    values = np.asarray(values, dtype=np.float64).reshape(-1, dim)
    mean = values.mean(axis=0)
    std = values.std(axis=0)
    floor = max(1e-3 * float(np.max(std, initial=0.0)), 1e-12)
    std = np.maximum(std, floor)
    if not np.all(np.isfinite(mean)) or not np.all(np.isfinite(std)):
        raise ValueError("the training data give non-finite scalings")
    return tuple(float(v) for v in mean), tuple(float(v) for v in std)
