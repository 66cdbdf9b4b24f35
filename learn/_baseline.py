r"""Unstructured baseline: a residual network $y_{n+1} = y_n + \mathrm{NN}(y_n)$, trained like
an LPNet on the state, to show what the Lie-Poisson structure buys (it conserves no Casimir)."""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp

from liepoisson.systems import AbstractPoissonSystem

from ._base import AbstractLearnedMap, TrainingRecord, check_system, replace
from ._fit import fit_gradient
from ._mlp import MLP, affine, as_key, check_activation, check_hidden
from ._validation import positive_float


class MLPBaseline(AbstractLearnedMap):
    r"""$y \mapsto y + s_\text{out}\odot\mathrm{MLP}((y - m_\text{in})/s_\text{in}) + m_\text{out}$,
    with fixed scalings set by the first `fit` (inputs $y_0$, outputs $y_1 - y_0$).

    **Arguments:** as `LPNet` (without a parametrisation).
    """

    mlp: MLP
    system: AbstractPoissonSystem = eqx.field(static=True)
    h: float | None = eqx.field(static=True)
    input_shift: tuple[float, ...] = eqx.field(static=True)
    input_scale: tuple[float, ...] = eqx.field(static=True)
    output_shift: tuple[float, ...] = eqx.field(static=True)
    output_scale: tuple[float, ...] = eqx.field(static=True)
    hidden: tuple[int, ...] = eqx.field(static=True)
    record: TrainingRecord | None = eqx.field(static=True)

    def __init__(
        self,
        system: Any,
        hidden: Any = (16, 16, 16),
        activation: str = "sigmoid",
        key: Any = 0,
        h: float | None = None,
    ):
        self.system = check_system(system)
        self.hidden = check_hidden(hidden)
        n = system.dim
        self.mlp = MLP(n, n, self.hidden, check_activation(activation), as_key(key))
        self.h = None if h is None else positive_float(h, "h")
        self.input_shift, self.input_scale = (0.0,) * n, (1.0,) * n
        self.output_shift, self.output_scale = (0.0,) * n, (1.0,) * n
        self.record = None

    @property
    def activation(self) -> str:
        return self.mlp.activation

    def _step(self, y):
        x = (y - jnp.asarray(self.input_shift)) / jnp.asarray(self.input_scale)
        return y + jnp.asarray(self.output_shift) + jnp.asarray(self.output_scale) * self.mlp(x)

    def hyperparameters(self):
        return {
            "hidden": list(self.hidden),
            "activation": self.activation,
            "input_shift": list(self.input_shift),
            "input_scale": list(self.input_scale),
            "output_shift": list(self.output_shift),
            "output_scale": list(self.output_scale),
        }

    @classmethod
    def _skeleton(cls, system, hp):
        net = cls(system, tuple(hp["hidden"]), hp["activation"], 0)
        return replace(
            net,
            input_shift=tuple(hp["input_shift"]),
            input_scale=tuple(hp["input_scale"]),
            output_shift=tuple(hp["output_shift"]),
            output_scale=tuple(hp["output_scale"]),
        )

    def fit(
        self,
        data: Any,
        epochs: int = 100_000,
        learning_rate: float = 1e-3,
        final_learning_rate: float | None = None,
        batch_size: int | None = None,
        validation_fraction: float = 0.2,
        seed: int = 0,
        loss: str = "state",
        h: float | None = None,
        checkpoint: Any = None,
        resume: bool = False,
        progress: bool = True,
        log_every: int | None = None,
        checkpoint_every: int = 10_000,
        normalise: bool = False,
    ) -> MLPBaseline:
        """Train on the state MSE; same arguments and results as `LPNet.fit` (only
        `loss="state"`)."""
        return fit_gradient(
            self, data, epochs=epochs, learning_rate=learning_rate,
            final_learning_rate=final_learning_rate, batch_size=batch_size,
            validation_fraction=validation_fraction, seed=seed, loss=loss, h=h,
            checkpoint=checkpoint, resume=resume, progress=progress, log_every=log_every,
            checkpoint_every=checkpoint_every, normalise=normalise, losses=("state",), build=_build,
        )


def _build(net: MLPBaseline, pairs, loss: str, normalise: bool):
    if net.record is None and normalise:
        in_shift, in_scale = affine(pairs.y0, net.system.dim)
        out_shift, out_scale = affine(pairs.y1 - pairs.y0, net.system.dim)
        net = replace(net, input_shift=in_shift, input_scale=in_scale, output_shift=out_shift,
                      output_scale=out_scale)
    net = replace(net, h=pairs.h)

    def loss_fn(model, x, t):
        return jnp.mean((jax.vmap(model._step)(x) - t) ** 2)

    return net, (pairs.y0, pairs.y1), (pairs.y0_val, pairs.y1_val), loss_fn
