r"""LPNets ([the paper](https://arxiv.org/abs/2308.15349), Sec. 4, "A general application to
finite-dimensional Lie groups"): a network predicts the parameters $\alpha(y)$ of an exact
Poisson step, $y_{n+1} = \mathbb T(\alpha(y_n))\,y_n$ (eq. (27))."""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from integrators import AbstractReconstructingStepMap
from integrators.internals import check_h, check_state
from liepoisson.internals import check_system, positive_float, refuse_nonholonomic
from liepoisson.systems import AbstractPoissonSystem

from ._base import AbstractCasimirConservingMap, AbstractOneFlowMap
from ._equivariant import check_group_law
from ._mlp import AffineMLP, Scaling
from ._network_spec import network_from_spec
from ._networks import AbstractNetwork, check_network, network_or_default
from ._parametrisation import (
    AbstractLiftedParametrisation,
    AbstractStepParametrisation,
    default_parametrisation,
    parametrisation_from_name,
)


class LPNet(AbstractCasimirConservingMap, AbstractOneFlowMap, AbstractReconstructingStepMap):
    r"""Local Lie-Poisson network: $y \mapsto \mathbb T(h, \alpha(y))\,y$, a system, an
    $\alpha$-network and a parametrisation $\mathbb T$ of exact steps.

    Every step is an exact test flow for fixed $\alpha$, so the Casimirs are conserved to
    round-off whatever the weights. The map is *not* exactly Poisson, because $\alpha$
    depends on the point (conventions, [What is exactly Poisson, and what is
    not][what-is-exactly-poisson-and-what-is-not]): `poisson_defect` measures by how much, and
    its energy error drifts, over $N$ steps like $N$ times the one-step error. Variants are
    built by composition: an equivariant LPNet has a `learn.GroupAveraged` network, a
    reversible one is `learn.Reversible(lpnet)`; a G-LPNet (`learn.GLPNet`) is exactly
    Poisson.

    **Arguments:** `system`; `hidden` layer widths (default and paper: (16, 16, 16), 659
    parameters for the rigid body), `activation` (default and paper: sigmoid), `key` (int seed
    or PRNG key, default 0), `input_scaling`, `output_scaling` (`(shift, scale)` pairs, default
    identity; `learn.fit` with `normalise=True` sets them from the data): the default network,
    an `AffineMLP`
    $\alpha(y) = s_\text{out}\odot\mathrm{MLP}((y - m_\text{in})/s_\text{in}) + m_\text{out}$;
    or `network`, any `learn.AbstractNetwork` from `dim` to `n_params` instead (then none of
    those may be given); `parametrisation` (an `AbstractStepParametrisation` or its class name;
    default `default_parametrisation(system)`); `h`, the time step (`None`: set by `learn.fit`
    from the data); `phase`: a network from states to one rate per Casimir, the part of the
    configuration's motion that momenta cannot fix (`lifted_step`; `learn.fit_phase` fits it
    to configurations; `None`: no lifted step); `init` (keyword): the default network's start,
    `"random"` (default) or `"zero"` ($\alpha$ starts at the constant $m_\text{out}$; see
    `AffineMLP`).
    """

    network: AbstractNetwork
    phase: AbstractNetwork | None
    parametrisation: AbstractStepParametrisation = eqx.field(static=True)
    system: AbstractPoissonSystem = eqx.field(static=True)
    h: float | None

    def __init__(
        self,
        system: AbstractPoissonSystem,
        hidden: Sequence[int] | None = None,
        activation: str | None = None,
        key: int | jax.Array | None = None,
        parametrisation: AbstractStepParametrisation | str | None = None,
        h: float | None = None,
        input_scaling: Scaling | None = None,
        output_scaling: Scaling | None = None,
        *,
        network: AbstractNetwork | None = None,
        phase: AbstractNetwork | None = None,
        init: str | None = None,
    ):
        self.system = check_system(system)
        refuse_nonholonomic(system, "an LPNet")
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
        network = network_or_default(
            network, functools.partial(AffineMLP, system.dim, parametrisation.n_params), hidden=hidden,
            activation=activation, key=key, input_scaling=input_scaling, output_scaling=output_scaling, init=init)
        in_size = system.dim + 1 if isinstance(network, AbstractNetwork) and network.in_size == system.dim + 1 \
            else system.dim
        network = check_network(network, in_size, parametrisation.n_params,
                                f"states (or states and the step, dim + 1) to the parameters of "
                                f"{type(parametrisation).__name__}")
        for group in network.sign_groups():  # every GroupAveraged, at any depth
            check_group_law(system, parametrisation, group)
        self.network = network
        if phase is not None and not isinstance(parametrisation, AbstractLiftedParametrisation):
            raise ValueError(f"phase= turns the configuration of a lifted step, which {type(parametrisation).__name__} "
                             "has not (its parameters are not a body velocity); use the TestFlowParametrisation")
        self.phase = None if phase is None else check_network(
            phase, system.dim, system.n_casimirs, "states to one phase rate per Casimir (phase=)")
        self.h = None if h is None else positive_float(h, "h")

    @property
    def takes_step(self) -> bool:
        r"""Whether the network sees the step size: $\alpha(y, h)$ (a network of `dim + 1`
        inputs)."""
        return self.network.in_size == self.system.dim + 1

    def network_inputs(self, y: jax.Array) -> jax.Array:
        """What the network sees: the state `(..., dim)`, and the step as a last input if
        `takes_step`."""
        if not self.takes_step:
            return y
        h = jnp.broadcast_to(jnp.asarray(check_h(self), dtype=y.dtype), (*y.shape[:-1], 1))
        return jnp.concatenate([y, h], axis=-1)

    def alpha(self, y: jax.Array) -> jax.Array:
        r"""The step parameters $\alpha(y)$ for one state `(dim,)`; $\alpha(y, h)$ for a
        network that takes the step (`dim + 1` inputs).

        Why the step enters $\alpha$, and how: the step is the test flow of
        $\langle\alpha, y\rangle$ for time $h$, $y_1 = \exp(h\,\alpha^\sharp)\cdot y$, so a
        network trained at one $h$ learns $\alpha = \nabla H + O(h)$, the $O(h)$ part (the
        modified parameter of this first-order flow) depending on that $h$. At another $h$ the
        fixed network is first-order accurate at best; with $h$ as an input, the network fits
        the parameter as a function of the step, and a map trained on uneven steps rolls out
        at any step in its range. The time of the flow stays $h$, so $h \to 0$ is the
        identity whatever the network."""
        return self.network(self.network_inputs(y))

    def step(self, y: jax.Array) -> jax.Array:
        y = check_state(y, self.system.dim)
        return self.parametrisation.step(self.alpha(y), y, self.h)

    def phase_velocity(self, y: jax.Array) -> jax.Array:
        r"""$\sum_k\beta_k(y)\nabla C_k(y)$ `(dim,)` for one state: the body velocity along the
        Casimir gradients that the step's configuration moves with besides $\alpha(y)$ (zero
        without a phase network or Casimirs)."""
        if self.phase is None or self.system.n_casimirs == 0:
            return jnp.zeros_like(y)
        return self.phase(y) @ self.system.casimir_gradients(y)

    def lifted_step(self, g: jax.Array, y: jax.Array) -> tuple[jax.Array, jax.Array]:
        r"""The step on $(g, \mu)$: $g \mapsto g\exp(h\,\beta(\mu)\cdot\nabla C(\mu))
        \exp(h\,\alpha(\mu))$, $\mu \mapsto \mathrm{Ad}^*_{\exp(h\alpha)}\mu$. The test flow
        fixes the configuration's step only up to the stabiliser of $\mu$, whose directions
        at a regular point are the Casimir gradients (turning $g$ along them moves no
        momentum): for a rigid body, the rotation about the angular momentum. The phase
        network $\beta$ gives that part (`learn.fit_phase`, from configurations). Each factor
        is an exact lifted flow, so the spatial momentum is kept to round-off for any weights.
        `ValueError` without a phase network on a system with Casimirs (conventions,
        [Configurations][conventions-configurations])."""
        group = self.system.require_group()
        if self.phase is None and self.system.n_casimirs:
            raise ValueError(
                "this LPNet has no phase network: fitted to momenta, its step fixes the configuration's motion only "
                "up to the Casimir gradients (for a rigid body, the rotation about the angular momentum), which "
                "momenta cannot see. Fit that part to configurations: net, _ = learn.fit_phase(net, trajectories) "
                "with trajectories holding configurations (integrators.ground_truth(..., g0=...))")
        y = check_state(y, self.system.dim)
        h = check_h(self)
        if not isinstance(self.parametrisation, AbstractLiftedParametrisation):
            raise ValueError(  # noqa: TRY004 (a right-type net without the capability)
                f"{type(self.parametrisation).__name__} does not carry a configuration; an LPNet with the "
                             "TestFlowParametrisation (one test flow a step) does")
        g = group.right_exp(group.check(g, "g"), h * self.phase_velocity(y))
        return self.parametrisation.lifted_step(self.alpha(y), g, y, h)

    @property
    def exact_flows_per_step(self) -> int:
        return self.parametrisation.exact_flows

    def body_records_hint(self) -> str:
        """An LPNet reads no body velocity: `learn.BodyLPNet` wraps it for body records."""
        return ("an LPNet reads no body velocity: wrap it, learn.BodyLPNet(lpnet), or start one with "
                "learn.BodyLPNet.at_quadratic(system, *learn.weak_form_quadratic(data)[:2])")

    def hyperparameters(self) -> dict[str, Any]:
        out = {"network": self.network.spec(), "parametrisation": type(self.parametrisation).__name__}
        return out if self.phase is None else {**out, "phase": self.phase.spec()}

    @property
    def output_scales(self) -> jax.Array:
        return jnp.asarray(self.network.output_scales())

    def params_from_pair(self, y0: np.ndarray, y1: np.ndarray, h: float) -> np.ndarray:
        """`parametrisation.params_from_pair` ([the paper](https://arxiv.org/abs/2308.15349),
        Sec. 4, eqs. (25) and (26))."""
        return self.parametrisation.params_from_pair(y0, y1, h)

    def reinitialised(self, key):
        return eqx.tree_at(lambda m: m.network, self, self.network.reinitialised(key))

    @classmethod
    def from_hyperparameters(cls, system, hyperparameters, *, key=0, h=None):
        network = network_from_spec(hyperparameters["network"], key)
        phase = None if "phase" not in hyperparameters else network_from_spec(hyperparameters["phase"], key)
        return cls(system, parametrisation=hyperparameters["parametrisation"], h=h, network=network, phase=phase)

    def normalised(self, y0, y1, h, targets=None, *, fraction: float = 1.0):
        r"""Scalings from the data: inputs the mean/std of $y_0$, outputs those of `targets`
        (the alpha loss's parameters) or else of the first-order estimate of $\alpha$
        (`params_estimate`) times `fraction` (a map that takes several steps of this LPNet
        per step passes its share)."""
        outputs = fraction * self.parametrisation.params_estimate(y0, y1, h) if targets is None else targets
        inputs = y0 if not self.takes_step else np.concatenate([y0, np.full((y0.shape[0], 1), h)], axis=1)
        return eqx.tree_at(lambda m: m.network, self, self.network.rescaled(inputs, outputs))
