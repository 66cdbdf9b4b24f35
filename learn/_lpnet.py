r"""LPNets (paper section "A general application to finite-dimensional Lie groups"):
a network predicts the parameters $\alpha(y)$ of an exact Poisson step, $y_{n+1} =
\mathbb T(\alpha(y_n))\,y_n$ (eq. sol_eval_iteration)."""

from __future__ import annotations

from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._mlp_map import AbstractMLPMap
from ._parametrisation import (
    AbstractStepParametrisation,
    LieAlgebraParametrisation,
    SO3Rotation,
    default_parametrisation,
)
from ._rollout import state_mse
from ._validation import check_system

_PARAMETRISATIONS = {"SO3Rotation": SO3Rotation, "LieAlgebraParametrisation": LieAlgebraParametrisation}


class LPNet(AbstractMLPMap):
    r"""Local Lie-Poisson network: $y \mapsto \mathbb T(h, \alpha(y))\,y$ with
    $\alpha(y) = s_\text{out}\odot\mathrm{MLP}((y - m_\text{in})/s_\text{in}) + m_\text{out}$.

    Every step is an exact test flow, so the Casimirs are conserved to round-off whatever the
    weights. The map is *not* exactly Poisson, because $\alpha$ depends on the point
    (DESIGN.md section 2): `poisson_defect` measures by how much.

    The affine scalings $m, s$ are fixed (not trained): the identity unless the first `fit`
    is called with `normalise=True`, which sets them from the training data (inputs:
    mean/std of $y_0$; outputs: mean/std of the pairs' parameters).

    **Arguments:** `system`; `hidden` layer widths (paper: (16, 16, 16), 659 parameters for
    the rigid body); `activation` (paper: sigmoid); `key` (int seed or PRNG key);
    `parametrisation` (default `default_parametrisation(system)`); `h`, the time step (set by
    `fit` from the data).
    """

    parametrisation: AbstractStepParametrisation = eqx.field(static=True)

    _losses: ClassVar[tuple[str, ...]] = ("state", "alpha")

    def __init__(
        self,
        system: Any,
        hidden: Any = (16, 16, 16),
        activation: str = "sigmoid",
        key: Any = 0,
        parametrisation: AbstractStepParametrisation | None = None,
        h: float | None = None,
    ):
        self.system = check_system(system)
        if parametrisation is None:
            parametrisation = default_parametrisation(system)
        if not isinstance(parametrisation, AbstractStepParametrisation):
            raise TypeError(
                "parametrisation must be a learn.AbstractStepParametrisation; got "
                f"{type(parametrisation).__name__}"
            )
        if parametrisation.system is not system:
            raise ValueError("parametrisation must be built for the same system object as the LPNet")
        self.parametrisation = parametrisation
        self._init_network(hidden, activation, key, h, parametrisation.n_params)

    def alpha(self, y: jax.Array) -> jax.Array:
        """The step parameters $\\alpha(y)$ for one sample `(dim,)`."""
        return self._network(y)

    def _step(self, y):
        return self.parametrisation.step(self.alpha(y), y, self.h)

    def _own_hyperparameters(self):
        return {
            "parametrisation": type(self.parametrisation).__name__,
            "parametrisation_hyperparameters": self.parametrisation.hyperparameters(),
        }

    @classmethod
    def _skeleton(cls, system, hp):
        kind = _PARAMETRISATIONS.get(hp["parametrisation"])
        if kind is None:
            raise ValueError(
                f"cannot rebuild the parametrisation {hp['parametrisation']!r}; known: "
                f"{sorted(_PARAMETRISATIONS)}"
            )
        param = kind(system, **hp["parametrisation_hyperparameters"])
        return cls(system, tuple(hp["hidden"]), hp["activation"], 0, param)._restore_scalings(hp)

    def _build(self, pairs, loss, set_scalings):
        p = self.parametrisation
        if loss == "state":
            net = self
            if set_scalings:  # first-order parameters of the pairs
                net = self._with_scalings(pairs.y0, p.params_estimate(pairs.y0, pairs.y1, pairs.h))
            return net, (pairs.y0, pairs.y1), (pairs.y0_val, pairs.y1_val), state_mse
        targets = p.params_from_pair(pairs.y0, pairs.y1, pairs.h)
        targets_val = (
            p.params_from_pair(pairs.y0_val, pairs.y1_val, pairs.h) if pairs.has_validation
            else np.zeros((0, p.n_params))
        )
        net = self._with_scalings(pairs.y0, targets) if set_scalings else self
        return net, (pairs.y0, targets), (pairs.y0_val, targets_val), _alpha_mse


def _alpha_mse(model: LPNet, y0: jax.Array, alpha: jax.Array) -> jax.Array:
    """MSE of $\\alpha(y_0)$ against target parameters, in units of the output scale."""
    scale = jnp.asarray(model.output_scale)
    return jnp.mean(((jax.vmap(model.alpha)(y0) - alpha) / scale) ** 2)
