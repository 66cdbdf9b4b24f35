r"""Unstructured baseline: a residual network $y_{n+1} = y_n + \mathrm{NN}(y_n)$, trained like
an LPNet on the state, to show what the Lie-Poisson structure buys (it conserves no Casimir)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax

from integrators._step_map import check_state
from liepoisson._validation import check_system, positive_float
from liepoisson.systems import AbstractPoissonSystem

from ._base import AbstractLearnedMap
from ._mlp import AffineMLP, Scaling, as_key, check_activation, check_hidden


class MLPBaseline(AbstractLearnedMap):
    r"""$y \mapsto y + s_\text{out}\odot\mathrm{MLP}((y - m_\text{in})/s_\text{in}) + m_\text{out}$,
    with fixed scalings (`learn.fit(normalise=True)` sets them from the data: inputs $y_0$,
    outputs $y_1 - y_0$). Trained on the state MSE only.

    **Arguments:** as `LPNet`, without a parametrisation.
    """

    network: AffineMLP
    system: AbstractPoissonSystem = eqx.field(static=True)
    h: float | None

    def __init__(
        self,
        system: AbstractPoissonSystem,
        hidden: Sequence[int] = (16, 16, 16),
        activation: str = "sigmoid",
        key: int | jax.Array = 0,
        h: float | None = None,
        input_scaling: Scaling | None = None,
        output_scaling: Scaling | None = None,
    ):
        self.system = check_system(system)
        self.network = AffineMLP(
            system.dim, system.dim, check_hidden(hidden), check_activation(activation), as_key(key),
            input_scaling, output_scaling,
        )
        self.h = None if h is None else positive_float(h, "h")

    def step(self, y: jax.Array) -> jax.Array:
        y = check_state(y, self.system.dim)
        return y + self.network(y)

    @property
    def exact_flows_per_step(self) -> int:
        return 0

    def hyperparameters(self) -> dict[str, Any]:
        return {
            **self.network.hyperparameters(),
        }
