r"""Unstructured baseline: a residual network $y_{n+1} = y_n + \mathrm{NN}(y_n)$, trained like
an LPNet on the state, to show what the Lie-Poisson structure buys (it conserves no Casimir)."""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from integrators.internals import check_h, check_state, rk4_steps
from liepoisson.internals import check_system, positive_float, positive_int
from liepoisson.systems import AbstractPoissonSystem

from ._base import AbstractLearnedMap
from ._mlp import AffineMLP, Scaling
from ._network_spec import network_from_spec
from ._networks import AbstractNetwork, check_network, network_or_default

#: Relative spread of steps that still count as one step (as `Observations.is_regular`).
STEP_RTOL = 1e-9


class AbstractFixedStepMap(AbstractLearnedMap):
    r"""A learned map defined at one step only: its `step` ignores $h$ (an `MLPBaseline` maps a
    state to the next at the step of its training data, whatever $h$ says). It can be fitted
    only to data at one step, the $h$ it is labelled with (`check_one_step`)."""


def check_one_step(model: AbstractLearnedMap, steps: ArrayLike, h: float | None = None, what: str = "data") -> None:
    r"""`ValueError` if `model` is an `AbstractFixedStepMap` and the `steps` it would be trained
    at (observations' intervals, divided by any sub-steps) are not one step (to `STEP_RTOL`),
    giving their range, or are not `h`, the step the fitted map is labelled with; nothing for
    any other map (their step takes $h$ as an input)."""
    if not isinstance(model, AbstractFixedStepMap):
        return
    steps = np.asarray(steps, dtype=np.float64).reshape(-1)
    if steps.size == 0:
        return
    low, high = float(np.min(steps)), float(np.max(steps))
    name = type(model).__name__
    if high - low > STEP_RTOL * high:
        raise ValueError(
            f"{what} has uneven steps, from {low:g} to {high:g}; {name} maps a state to the next at one fixed "
            f"step (its step ignores h), so it cannot follow observations at several steps. Resample them at one "
            f"step, or fit a map that takes the step as an input (LPNet, GLPNet, learn.fit_splitting)"
        )
    if h is not None and abs(float(h) - high) > STEP_RTOL * high:
        raise ValueError(
            f"h = {float(h):g}, but {what} has steps of {high:g}; {name} maps a state to the next at one fixed step "
            f"(its step ignores h), which is the data's: give h={high:g} or leave h unset"
        )


def state_network(system: AbstractPoissonSystem, network: AbstractNetwork | None, role: str, **default: Any
                  ) -> AbstractNetwork:
    """`network`, or the default `AffineMLP` from `dim` to `dim` built from `default` (`hidden`,
    `activation`, `key`, scalings), checked to map `dim` to `dim` (`role` says what it maps)."""
    network = network_or_default(network, functools.partial(AffineMLP, system.dim, system.dim), **default)
    return check_network(network, system.dim, system.dim, role)


class MLPBaseline(AbstractFixedStepMap):
    r"""$y \mapsto y + s_\text{out}\odot\mathrm{MLP}((y - m_\text{in})/s_\text{in}) + m_\text{out}$,
    with fixed scalings (`learn.fit(normalise=True)` sets them from the data: inputs $y_0$,
    outputs $y_1 - y_0$). Trained on the state MSE only; it conserves no Casimir, so `learn.fit`
    takes any pairs for it. Its step ignores $h$: it is the map at the one step of its training
    data (an `AbstractFixedStepMap`).

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
        self.network = state_network(system, network, "states to increments", hidden=hidden, activation=activation,
                                     key=key, input_scaling=input_scaling, output_scaling=output_scaling)
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


class NeuralODE(AbstractLearnedMap):
    r"""A neural ODE without structure: $\dot y = s_\text{out}\odot\mathrm{MLP}((y -
    m_\text{in})/s_\text{in}) + m_\text{out}$, one step of $h$ being `substeps` classical
    Runge-Kutta steps (RK4). Unlike `MLPBaseline` it takes the step as an input, so it follows
    observations at uneven times (`learn.fit` on `integrators.Observations`, its trajectory
    loss); like it, it conserves no Casimir and is no Poisson map: the baseline that shows
    what the Lie-Poisson structure buys on the same data.

    **Arguments:** as `MLPBaseline`'s (`hidden`, `activation`, `key`, scalings, or `network`
    from `dim` to `dim`); `substeps`; `h`. `learn.fit(normalise=True)` sets the scalings:
    inputs $y_0$, outputs $(y_1 - y_0)/h$ (the field's size).
    """

    network: AbstractNetwork
    system: AbstractPoissonSystem = eqx.field(static=True)
    substeps: int = eqx.field(static=True)
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
        substeps: int = 4,
        network: AbstractNetwork | None = None,
    ):
        self.system = check_system(system)
        self.network = state_network(system, network, "states to their time derivative", hidden=hidden,
                                     activation=activation, key=key, input_scaling=input_scaling,
                                     output_scaling=output_scaling)
        self.substeps = positive_int(substeps, "substeps")
        self.h = None if h is None else positive_float(h, "h")

    def vector_field(self, y: jax.Array) -> jax.Array:
        r"""$\dot y$ `(..., dim)` of the learned field."""
        y = jnp.asarray(y)
        return jax.vmap(self.network)(y.reshape(-1, self.system.dim)).reshape(y.shape)

    def step(self, y: jax.Array) -> jax.Array:
        y = check_state(y, self.system.dim)
        return rk4_steps(self.network, y, check_h(self), self.substeps)

    @property
    def exact_flows_per_step(self) -> int:
        return 0

    def hyperparameters(self) -> dict[str, Any]:
        return {"network": self.network.spec(), "substeps": self.substeps}

    @classmethod
    def from_hyperparameters(cls, system, hyperparameters, *, key=0, h=None):
        return cls(system, h=h, substeps=hyperparameters["substeps"],
                   network=network_from_spec(hyperparameters["network"], key))

    def reinitialised(self, key):
        return eqx.tree_at(lambda m: m.network, self, self.network.reinitialised(key))

    def normalised(self, y0, y1, h, targets=None):
        """Scalings from the data: inputs the mean/std of $y_0$, outputs those of
        $(y_1 - y_0)/h$."""
        rates = (np.asarray(y1) - np.asarray(y0)) / np.reshape(np.asarray(h, dtype=np.float64), (-1, 1))
        return eqx.tree_at(lambda m: m.network, self, self.network.rescaled(y0, rates))

