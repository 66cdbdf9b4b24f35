r"""LPNets (paper section "A general application to finite-dimensional Lie groups"):
a network predicts the parameters $\alpha(y)$ of an exact Poisson step, $y_{n+1} =
\mathbb T(\alpha(y_n))\,y_n$ (eq. sol_eval_iteration)."""

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
from ._parametrisation import (
    AbstractStepParametrisation,
    default_parametrisation,
    parametrisation_from_name,
)


class LPNet(AbstractLearnedMap):
    r"""Local Lie-Poisson network: $y \mapsto \mathbb T(h, \alpha(y))\,y$ with
    $\alpha(y) = s_\text{out}\odot\mathrm{MLP}((y - m_\text{in})/s_\text{in}) + m_\text{out}$.

    Every step is an exact test flow, so the Casimirs are conserved to round-off whatever the
    weights. The map is *not* exactly Poisson, because $\alpha$ depends on the point
    (DESIGN.md section 2): `poisson_defect` measures by how much. Its energy error therefore
    drifts: over $N$ steps it grows like $N$ times the one-step error, so long rollouts need a
    small loss. Refine Adam with L-BFGS-B, `optimiser=(Adam(20_000), QuasiNewton(30_000))`:
    on the so(3) rigid body (`benchmarks/lpnet_accuracy/`, seeds 0-2) that took the max
    energy error over 2000 steps from 4e-2..2e-1 to 4e-4..1.2e-3. Where accuracy over long
    times matters more than the paper's architecture, a G-LPNet (`learn.fit_splitting`) is
    exactly Poisson.

    The affine scalings $m, s$ are fixed (not trained): the identity unless `learn.fit` is
    called with `normalise=True`, which sets them from the training data (inputs: mean/std of
    $y_0$; outputs: mean/std of the pairs' parameters).

    **Arguments:** `system`; `hidden` layer widths (paper: (16, 16, 16), 659 parameters for
    the rigid body); `activation` (paper: sigmoid); `key` (int seed or PRNG key);
    `parametrisation` (an `AbstractStepParametrisation` or its class name; default
    `default_parametrisation(system)`); `h`, the time step (`None`: set by `learn.fit` from the
    data); `input_scaling`, `output_scaling`: `(shift, scale)` pairs (default identity).
    """

    network: AffineMLP
    parametrisation: AbstractStepParametrisation = eqx.field(static=True)
    system: AbstractPoissonSystem = eqx.field(static=True)
    h: float | None

    def __init__(
        self,
        system: AbstractPoissonSystem,
        hidden: Sequence[int] = (16, 16, 16),
        activation: str = "sigmoid",
        key: int | jax.Array = 0,
        parametrisation: AbstractStepParametrisation | str | None = None,
        h: float | None = None,
        input_scaling: Scaling | None = None,
        output_scaling: Scaling | None = None,
    ):
        self.system = check_system(system)
        if parametrisation is None:
            parametrisation = default_parametrisation(system)
        elif isinstance(parametrisation, str):
            parametrisation = parametrisation_from_name(parametrisation, system)
        if not isinstance(parametrisation, AbstractStepParametrisation):
            raise TypeError(
                "parametrisation must be a learn.AbstractStepParametrisation or its class name; got "
                f"{type(parametrisation).__name__}"
            )
        if parametrisation.system is not system:
            raise ValueError("parametrisation must be built for the same system object as the LPNet")
        self.parametrisation = parametrisation
        self.network = AffineMLP(
            system.dim, parametrisation.n_params, check_hidden(hidden), check_activation(activation),
            as_key(key), input_scaling, output_scaling,
        )
        self.h = None if h is None else positive_float(h, "h")

    def alpha(self, y: jax.Array) -> jax.Array:
        """The step parameters $\\alpha(y)$ for one state `(dim,)`."""
        return self.network(y)

    def step(self, y: jax.Array) -> jax.Array:
        y = check_state(y, self.system.dim)
        return self.parametrisation.step(self.alpha(y), y, self.h)

    @property
    def exact_flows_per_step(self) -> int:
        return self.parametrisation.exact_flows

    def hyperparameters(self) -> dict[str, Any]:
        return {
            **self.network.hyperparameters(),
            "parametrisation": type(self.parametrisation).__name__,
        }
