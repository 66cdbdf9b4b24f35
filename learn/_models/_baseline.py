r"""Unstructured baseline: a residual network $y_{n+1} = y_n + \mathrm{NN}(y_n)$, trained like
an LPNet on the state, to show what the Lie-Poisson structure buys (it conserves no Casimir)."""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax

from integrators.internals import check_state
from liepoisson.internals import check_system, positive_float
from liepoisson.systems import AbstractPoissonSystem

from ._base import AbstractLearnedMap
from ._mlp import AffineMLP, Scaling
from ._network_spec import network_from_spec
from ._networks import AbstractNetwork, check_network, network_or_default


class MLPBaseline(AbstractLearnedMap):
    r"""$y \mapsto y + s_\text{out}\odot\mathrm{MLP}((y - m_\text{in})/s_\text{in}) + m_\text{out}$,
    with fixed scalings (`learn.fit(normalise=True)` sets them from the data: inputs $y_0$,
    outputs $y_1 - y_0$). Trained on the state MSE only; it conserves no Casimir, so `learn.fit`
    takes any pairs for it.

    **Arguments:** as `LPNet`'s default network (`hidden`, `activation`, `key`, scalings), or
    `network`, any `learn.AbstractNetwork` from `dim` to `dim`; `h`.
    """

    network: AbstractNetwork
    system: AbstractPoissonSystem = eqx.field(static=True)
    h: float | None

    def __init__(
        self,
        system: AbstractPoissonSystem,
        hidden: Sequence[int] | None = None,
        activation: str | None = None,
        key: int | jax.Array | None = None,
        h: float | None = None,
        input_scaling: Scaling | None = None,
        output_scaling: Scaling | None = None,
        *,
        network: AbstractNetwork | None = None,
    ):
        self.system = check_system(system)
        network = network_or_default(
            network, functools.partial(AffineMLP, system.dim, system.dim), hidden=hidden, activation=activation,
            key=key, input_scaling=input_scaling, output_scaling=output_scaling)
        self.network = check_network(network, system.dim, system.dim, "states to increments")
        self.h = None if h is None else positive_float(h, "h")

    def step(self, y: jax.Array) -> jax.Array:
        y = check_state(y, self.system.dim)
        return y + self.network(y)

    @property
    def exact_flows_per_step(self) -> int:
        return 0

    def hyperparameters(self) -> dict[str, Any]:
        return {"network": self.network.spec()}

    def reinitialised(self, key):
        return eqx.tree_at(lambda m: m.network, self, self.network.reinitialised(key))

    @classmethod
    def from_hyperparameters(cls, system, hyperparameters, *, key=0, h=None):
        return cls(system, h=h, network=network_from_spec(hyperparameters["network"], key))

    def normalised(self, y0, y1, h, targets=None):
        """Scalings from the data: inputs the mean/std of $y_0$, outputs those of $y_1 - y_0$."""
        return eqx.tree_at(lambda m: m.network, self, self.network.rescaled(y0, y1 - y0))
