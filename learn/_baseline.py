r"""Unstructured baseline: a residual network $y_{n+1} = y_n + \mathrm{NN}(y_n)$, trained like
an LPNet on the state, to show what the Lie-Poisson structure buys (it conserves no Casimir)."""

from __future__ import annotations

from typing import Any, ClassVar

from ._mlp_map import AbstractMLPMap
from ._rollout import state_mse
from ._validation import check_system


class MLPBaseline(AbstractMLPMap):
    r"""$y \mapsto y + s_\text{out}\odot\mathrm{MLP}((y - m_\text{in})/s_\text{in}) + m_\text{out}$,
    with fixed scalings set by the first `fit` (inputs $y_0$, outputs $y_1 - y_0$).

    **Arguments:** as `LPNet` (without a parametrisation). `fit` trains on the state MSE only
    (`loss="state"`).
    """

    _losses: ClassVar[tuple[str, ...]] = ("state",)

    def __init__(
        self,
        system: Any,
        hidden: Any = (16, 16, 16),
        activation: str = "sigmoid",
        key: Any = 0,
        h: float | None = None,
    ):
        self.system = check_system(system)
        self._init_network(hidden, activation, key, h, system.dim)

    def _step(self, y):
        return y + self._network(y)

    def _own_hyperparameters(self):
        return {}

    @classmethod
    def _skeleton(cls, system, hp):
        return cls(system, tuple(hp["hidden"]), hp["activation"], 0)._restore_scalings(hp)

    def _build(self, pairs, loss, set_scalings):
        net = self._with_scalings(pairs.y0, pairs.y1 - pairs.y0) if set_scalings else self
        return net, (pairs.y0, pairs.y1), (pairs.y0_val, pairs.y1_val), state_mse
