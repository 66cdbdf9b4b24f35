r"""LPNets (paper section "A general application to finite-dimensional Lie groups"):
a network predicts the parameters $\alpha(y)$ of an exact Poisson step, $y_{n+1} =
\mathbb T(\alpha(y_n))\,y_n$ (eq. sol_eval_iteration)."""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from liepoisson.systems import AbstractPoissonSystem

from ._base import AbstractLearnedMap, TrainingRecord, check_system, replace
from ._fit import fit_gradient
from ._mlp import MLP, affine, as_key, check_activation, check_hidden
from ._parametrisation import (
    AbstractStepParametrisation,
    LieAlgebraParametrisation,
    SO3Rotation,
    default_parametrisation,
)
from ._validation import positive_float

_PARAMETRISATIONS = {"SO3Rotation": SO3Rotation, "LieAlgebraParametrisation": LieAlgebraParametrisation}


class LPNet(AbstractLearnedMap):
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

    mlp: MLP
    system: AbstractPoissonSystem = eqx.field(static=True)
    parametrisation: AbstractStepParametrisation = eqx.field(static=True)
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
        self.hidden = check_hidden(hidden)
        n, m = system.dim, parametrisation.n_params
        self.mlp = MLP(n, m, self.hidden, check_activation(activation), as_key(key))
        self.h = None if h is None else positive_float(h, "h")
        self.input_shift, self.input_scale = (0.0,) * n, (1.0,) * n
        self.output_shift, self.output_scale = (0.0,) * m, (1.0,) * m
        self.record = None

    @property
    def activation(self) -> str:
        return self.mlp.activation

    def alpha(self, y: jax.Array) -> jax.Array:
        """The step parameters $\\alpha(y)$ for one sample `(dim,)`."""
        x = (y - jnp.asarray(self.input_shift)) / jnp.asarray(self.input_scale)
        return jnp.asarray(self.output_shift) + jnp.asarray(self.output_scale) * self.mlp(x)

    def _step(self, y):
        return self.parametrisation.step(self.alpha(y), y, self.h)

    def hyperparameters(self):
        return {
            "hidden": list(self.hidden),
            "activation": self.activation,
            "parametrisation": type(self.parametrisation).__name__,
            "parametrisation_hyperparameters": self.parametrisation.hyperparameters(),
            "input_shift": list(self.input_shift),
            "input_scale": list(self.input_scale),
            "output_shift": list(self.output_shift),
            "output_scale": list(self.output_scale),
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
        net = cls(system, tuple(hp["hidden"]), hp["activation"], 0, param)
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
    ) -> LPNet:
        r"""Train on data pairs; returns the fitted network (a new object) with the weights of
        the best validation loss, `.history`, `.train_loss`, `.val_loss`, `.h`, `.wall_time_s`.

        **Arguments:**

        - `data`: an `integrators.Trajectories`, or `(y0, y1)` arrays `(N, dim)` with `h`.
        - `epochs`; `learning_rate` and `final_learning_rate` (Adam with exponential decay
          from one to the other over all steps; constant if `final_learning_rate` is None).
        - `batch_size`: None for full batch, else seeded shuffled mini-batches (remainder dropped
          per epoch).
        - `validation_fraction` of the pairs held out (random, seeded by `seed`).
        - `loss`: `"state"` (default, the paper's: MSE between $\mathbb T(\alpha(y_0))y_0$ and
          $y_1$, through the exact flow) or `"alpha"` (MSE between $\alpha(y_0)$ and
          `parametrisation.params_from_pair(y0, y1, h)`, divided by the output scale).
        - `checkpoint`: HDF5 path written every `checkpoint_every` epochs and at the end;
          `resume=True` continues from it (epoch, optimiser state, best weights).
        - `progress`: tqdm bar with the losses; `log_every`: history resolution in epochs
          (default epochs // 1000).
        - `normalise`: on the first fit, set the fixed input/output scalings from the
          training data (True) or keep the identity (False, default: a plain MLP as in the
          paper). On E1 normalising reaches a lower loss (1.6e-11 vs 3-4e-11 after 1e5 epochs)
          but the 10,000-step rollout drifts more in energy (2e-3..0.6 vs 4e-4..7e-4).
        """
        return fit_gradient(
            self, data, epochs=epochs, learning_rate=learning_rate,
            final_learning_rate=final_learning_rate, batch_size=batch_size,
            validation_fraction=validation_fraction, seed=seed, loss=loss, h=h,
            checkpoint=checkpoint, resume=resume, progress=progress, log_every=log_every,
            checkpoint_every=checkpoint_every, normalise=normalise, losses=("state", "alpha"), build=_build,
        )


def _build(net: LPNet, pairs, loss: str, normalise: bool):
    p = net.parametrisation
    h = pairs.h
    if loss == "alpha":
        targets = p.params_from_pair(pairs.y0, pairs.y1, h)
        targets_val = (
            p.params_from_pair(pairs.y0_val, pairs.y1_val, h) if pairs.has_validation
            else np.zeros((0, p.n_params))
        )
    if net.record is None and normalise:  # first fit: scalings from the training data
        in_shift, in_scale = affine(pairs.y0, net.system.dim)
        estimate = targets if loss == "alpha" else p.params_estimate(pairs.y0, pairs.y1, h)
        out_shift, out_scale = affine(estimate, p.n_params)
        net = replace(net, input_shift=in_shift, input_scale=in_scale, output_shift=out_shift,
                      output_scale=out_scale)
    net = replace(net, h=h)
    if loss == "state":

        def loss_fn(model, x, t):
            return jnp.mean((jax.vmap(model._step)(x) - t) ** 2)

        return net, (pairs.y0, pairs.y1), (pairs.y0_val, pairs.y1_val), loss_fn

    def loss_fn(model, x, t):
        scale = jnp.asarray(model.output_scale)
        return jnp.mean(((jax.vmap(model.alpha)(x) - t) / scale) ** 2)

    return net, (pairs.y0, targets), (pairs.y0_val, targets_val), loss_fn
