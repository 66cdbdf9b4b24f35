r"""A small multilayer perceptron, and the same with fixed (non-trainable) affine scalings
$N(y) = s_\text{out}\odot\mathrm{MLP}((y - m_\text{in})/s_\text{in}) + m_\text{out}$."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from liepoisson.internals import positive_int

from ._networks import AbstractNetwork

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


def activation_antiderivative(activation: str):
    r"""$A$ with $A' = \sigma$ as `A(x, xp)` on a math namespace (numpy, JAX or heyoka), for the
    activations whose antiderivative is elementary: sigmoid ($\log(1 + e^x)$), tanh
    ($\log\cosh x$), identity ($x^2/2$). `ValueError` for the others."""
    if activation == "sigmoid":
        return lambda x, xp: jax.nn.softplus(x) if xp.name == "jax" else xp.log(1.0 + xp.exp(x))
    if activation == "tanh":
        return lambda x, xp: (
            jnp.logaddexp(x, -x) - np.log(2.0) if xp.name == "jax" else xp.log(0.5 * (xp.exp(x) + xp.exp(-x)))
        )
    if activation == "identity":
        return lambda x, xp: 0.5 * x * x
    raise ValueError(
        f"the learned Hamiltonian needs an activation with an elementary antiderivative "
        f"('sigmoid', 'tanh' or 'identity'); got {activation!r}"
    )


INITS = ("random", "zero")


def check_init(init: Any) -> str:
    if init not in INITS:
        raise ValueError(f"init must be one of {INITS}; got {init!r}")
    return init


def check_activation(activation: Any) -> str:
    if activation not in ACTIVATIONS:
        raise ValueError(f"activation must be one of {sorted(ACTIVATIONS)}; got {activation!r}")
    return activation


class MLP(eqx.Module):
    """$x \\mapsto W_L\\,\\sigma(\\ldots\\sigma(W_1 x + b_1)\\ldots) + b_L$ for one sample;
    `init="zero"` starts with $W_L = 0$, $b_L = 0$ (the other layers random)."""

    layers: tuple[eqx.nn.Linear, ...]
    activation: str = eqx.field(static=True)

    def __init__(self, in_size: int, out_size: int, hidden: Sequence[int], activation: str, key,
                 init: str = "random"):
        sizes = (in_size, *hidden, out_size)
        keys = jax.random.split(key, len(sizes) - 1)
        layers = [eqx.nn.Linear(a, b, key=k, dtype=jnp.float64) for a, b, k in zip(sizes[:-1], sizes[1:], keys)]
        if init == "zero":
            last = layers[-1]
            layers[-1] = eqx.tree_at(lambda l: (l.weight, l.bias), last,
                                     (jnp.zeros_like(last.weight), jnp.zeros_like(last.bias)))
        self.layers = tuple(layers)
        self.activation = activation

    def __call__(self, x: jax.Array) -> jax.Array:
        act = ACTIVATIONS[self.activation]
        for layer in self.layers[:-1]:
            x = act(layer(x))
        return self.layers[-1](x)


def affine(values: np.ndarray, dim: int) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Per-component (mean, scale) of samples `(N, dim)`; tiny spreads are floored so that a
    (near-)constant component does not blow up the scaling."""
    values = np.asarray(values, dtype=np.float64).reshape(-1, dim)
    mean = values.mean(axis=0)
    std = values.std(axis=0)
    floor = max(1e-3 * float(np.max(std, initial=0.0)), 1e-12)
    std = np.maximum(std, floor)
    if not np.all(np.isfinite(mean)) or not np.all(np.isfinite(std)):
        raise ValueError("the training data give non-finite scalings")
    return tuple(float(v) for v in mean), tuple(float(v) for v in std)


Scaling = tuple[tuple[float, ...], tuple[float, ...]]


def _scaling(value: Scaling | None, size: int, name: str) -> Scaling:
    """`(shift, scale)` of `size` finite floats each (scales > 0); `None` is the identity."""
    if value is None:
        return (0.0,) * size, (1.0,) * size
    try:
        shift, scale = (tuple(float(v) for v in part) for part in value)
    except (TypeError, ValueError) as err:
        raise TypeError(f"{name} must be a pair (shift, scale) of {size} numbers each; got {value!r}") from err
    if len(shift) != size or len(scale) != size:
        raise ValueError(f"{name} must hold {size} shifts and {size} scales; got {len(shift)} and {len(scale)}")
    if not all(np.isfinite(shift)) or not all(np.isfinite(scale)) or min(scale) <= 0.0:
        raise ValueError(f"{name} must be finite with scales > 0; got {value!r}")
    return shift, scale


class AffineMLP(AbstractNetwork):
    r"""$N(y) = s_\text{out}\odot\mathrm{MLP}((y - m_\text{in})/s_\text{in}) + m_\text{out}$
    for one sample. The scalings are Python floats, not arrays: never trained, compiled in as
    constants.

    **Arguments:** `in_size`, `out_size`; `hidden` layer widths; `activation` (a name of
    `ACTIVATIONS`); `key` (int seed or PRNG key); `input_scaling`/`output_scaling`:
    `(shift, scale)` pairs (`None`: identity; `learn.fit(normalise=True)` sets them); `init`:
    `"random"` (default: every layer at equinox's uniform start) or `"zero"` (the last layer
    at zero weights and bias, so the network starts as the constant $m_\text{out}$, the
    data's mean output once normalised, and a fit moves only directions the data reach:
    the start for a network with more weights than data, such as an affine $\alpha(W)$ on
    Zeitlin's model). `init` is part of the architecture (`spec`, `reinitialised`); without
    hidden layers a zero start has no random part, so restarts (`learn.Restarts`) repeat one
    fit.
    """

    mlp: MLP
    input_shift: tuple[float, ...]
    input_scale: tuple[float, ...]
    output_shift: tuple[float, ...]
    output_scale: tuple[float, ...]
    init: str = eqx.field(static=True)

    def __init__(
        self,
        in_size: int,
        out_size: int,
        hidden: Sequence[int] = (16, 16, 16),
        activation: str = "sigmoid",
        key: int | jax.Array = 0,
        input_scaling: Scaling | None = None,
        output_scaling: Scaling | None = None,
        init: str = "random",
    ):
        in_size, out_size = positive_int(in_size, "in_size"), positive_int(out_size, "out_size")
        self.init = check_init(init)
        self.mlp = MLP(in_size, out_size, check_hidden(hidden), check_activation(activation), as_key(key), init)
        self.input_shift, self.input_scale = _scaling(input_scaling, in_size, "input_scaling")
        self.output_shift, self.output_scale = _scaling(output_scaling, out_size, "output_scaling")

    def __call__(self, y: jax.Array) -> jax.Array:
        x = (y - jnp.asarray(self.input_shift)) / jnp.asarray(self.input_scale)
        return jnp.asarray(self.output_shift) + jnp.asarray(self.output_scale) * self.mlp(x)

    def output_scales(self) -> tuple[float, ...]:
        return self.output_scale

    def reinitialised(self, key: int | jax.Array) -> AffineMLP:
        return AffineMLP(self.in_size, self.out_size, self.hidden, self.activation, key,
                         (self.input_shift, self.input_scale), (self.output_shift, self.output_scale), self.init)

    @property
    def in_size(self) -> int:
        return self.mlp.layers[0].in_features

    @property
    def out_size(self) -> int:
        return self.mlp.layers[-1].out_features

    @property
    def hidden(self) -> tuple[int, ...]:
        return tuple(layer.out_features for layer in self.mlp.layers[:-1])

    @property
    def activation(self) -> str:
        return self.mlp.activation

    def spec(self) -> dict[str, Any]:
        out = {
            "kind": "AffineMLP",
            "in_size": self.in_size,
            "out_size": self.out_size,
            "hidden": list(self.hidden),
            "activation": self.activation,
            "input_scaling": [list(self.input_shift), list(self.input_scale)],
            "output_scaling": [list(self.output_shift), list(self.output_scale)],
        }
        # files written before `init` existed have none: a default network's stays the same
        return out if self.init == "random" else {**out, "init": self.init}

    def rescaled(self, inputs: np.ndarray, outputs: np.ndarray) -> AffineMLP:
        in_shift, in_scale = affine(inputs, len(self.input_shift))
        out_shift, out_scale = affine(outputs, len(self.output_shift))
        return eqx.tree_at(
            lambda n: (n.input_shift, n.input_scale, n.output_shift, n.output_scale),
            self,
            (in_shift, in_scale, out_shift, out_scale),
        )
