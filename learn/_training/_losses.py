r"""Losses: objects that build the training problem of a learned map from data
(`loss.problem(model, data, ...)`). A loss on pairs $(y_0, y_1)$ is a mean of squared residuals
and its own objective: a new one is one subclass of `AbstractPairsLoss` (its residuals, and its
targets if they are not $y_1$), with no edit of `learn.fit` or of any solver."""

from __future__ import annotations

import abc
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from integrators import Trajectories
from liepoisson import vmap_samples

from .._models._base import AbstractCasimirConservingMap, AbstractLearnedMap, AbstractOneFlowMap
from .._solvers._problem import AbstractLeastSquares
from ._data import PairData, prepare
from ._problem import Description, MapProblem


class AbstractLoss(eqx.Module):
    """How `learn.fit` compares a learned map with data: `problem` builds the training problem
    (targets, the held-out split, the objective)."""

    @abc.abstractmethod
    def problem(self, model: AbstractLearnedMap, data: Any, *, h: float | None, validation_fraction: float,
                seed: int, normalise: bool) -> MapProblem:
        """The problem of fitting `model` to `data`, its step set to the data's (or `h`)."""

    @property
    @abc.abstractmethod
    def name(self) -> str:
        """What the training record calls this loss."""


class Pairs(eqx.Module):
    """Data pairs as a training problem's `args`: `inputs` $y_0$ `(N, dim)` and the loss's
    `targets` `(N, k)`."""

    inputs: jax.Array
    targets: jax.Array


class AbstractPairsLoss(AbstractLoss, AbstractLeastSquares):
    r"""A least-squares loss on data pairs $(y_0, y_1)$ (an `integrators.Trajectories`, or
    `(y0, y1)` arrays with `h`): the mean over pairs and components of the squared
    `pair_residuals(model, y0, targets)`, `targets` what `targets(model, y0, y1, h)` makes of
    the pairs ($y_1$ by default)."""

    @abc.abstractmethod
    def pair_residuals(self, model: Any, y0: jax.Array, targets: jax.Array) -> jax.Array:
        """The residuals `(N, k)` of `model` on the pairs `y0` `(N, dim)`, `targets` `(N, k)`."""

    def targets(self, model: Any, y0: np.ndarray, y1: np.ndarray, h: float) -> np.ndarray:
        """What the residuals compare with: $y_1$."""
        return y1

    def normalised(self, model: Any, pairs: PairData, targets: np.ndarray) -> Any:
        """`model` with its fixed scalings set from the training pairs (outputs: from the
        pairs' states)."""
        return model.normalised(pairs.y0, pairs.y1, pairs.h, None)

    def residuals(self, y: Any, args: Pairs) -> jax.Array:
        return self.pair_residuals(y, args.inputs, args.targets)

    def __call__(self, y: Any, args: Pairs) -> jax.Array:
        return jnp.mean(self.residuals(y, args) ** 2)

    def count(self, y: Any, args: Pairs) -> int:
        """One residual per component of the targets."""
        return int(jax.eval_shape(self.residuals, y, args).size)

    def check_model(self, model: AbstractLearnedMap) -> None:
        """`ValueError` if this loss cannot train `model` (every map, unless a subclass says)."""

    @property
    def name(self) -> str:
        return type(self).__name__

    def problem(self, model, data: Trajectories | tuple[ArrayLike, ArrayLike], *, h, validation_fraction, seed,
                normalise) -> MapProblem:
        self.check_model(model)
        pairs = prepare(data, model.system, h, validation_fraction, seed,
                        conserves_casimirs=isinstance(model, AbstractCasimirConservingMap))
        model.check_data(np.concatenate([np.asarray(pairs.y0), np.asarray(pairs.y1)]), "data")
        if model.h is not None and abs(model.h - pairs.h) > 1e-12 * pairs.h:
            raise ValueError(
                f"the model's step h={model.h} differs from the data's h={pairs.h}; fit a model built "
                "with h=None (or the data's h), or data sampled at the model's step"
            )
        model = eqx.tree_at(lambda m: m.h, model, pairs.h, is_leaf=lambda x: x is None)
        targets = self.targets(model, pairs.y0, pairs.y1, pairs.h)
        if normalise:
            model = self.normalised(model, pairs, targets)
        validation = None
        if pairs.has_validation:
            validation = Pairs(jnp.asarray(pairs.y0_val), jnp.asarray(self.targets(model, pairs.y0_val, pairs.y1_val,
                                                                                   pairs.h)))
        description = Description(loss=self.name, h=pairs.h, n_train=int(pairs.y0.shape[0]),
                                  n_val=int(pairs.y0_val.shape[0]), seed=int(seed),
                                  validation_fraction=float(validation_fraction), normalise=bool(normalise))
        return MapProblem(self, model, Pairs(jnp.asarray(pairs.y0), jnp.asarray(targets)), validation, description)


class StateLoss(AbstractPairsLoss):
    r"""The loss of [the paper](https://arxiv.org/abs/2308.15349) (Sec. 5.1 for an LPNet;
    Sec. 6.1, eq. (74), for a G-LPNet): the mean squared error of one learned step,
    `training_prediction(y0, y1)` (the step of $y_0$; the explicit residual form of an
    implicit step, `learn.Reversible`) against $y_1$."""

    def pair_residuals(self, model, y0, targets):
        return vmap_samples(model.training_prediction)(y0, targets) - targets

    @property
    def name(self) -> str:
        return "state"


class AlphaLoss(AbstractPairsLoss):
    r"""An LPNet's loss on its parameters: the MSE of $\alpha(y_0)$ against the parameters of
    the exact step that carries $y_0$ to $y_1$ (`parametrisation.params_from_pair`;
    [the paper](https://arxiv.org/abs/2308.15349), Sec. 4, eqs. (25) and (26)), in units of
    the network's output scale."""

    def check_model(self, model):
        if not isinstance(model, AbstractOneFlowMap):
            raise ValueError(  # noqa: TRY004 (a map of the wrong kind for this loss)
                "loss='alpha' fits alpha to the parameters of one test flow per pair, the step of a "
                f"learn.AbstractOneFlowMap (an LPNet); a {type(model).__name__} is not one (a Reversible makes two "
                "flows per step, whose parameters no pair determines): use loss='state'"
            )

    def targets(self, model, y0, y1, h):
        return model.params_from_pair(y0, y1, h)

    def normalised(self, model, pairs, targets):
        return model.normalised(pairs.y0, pairs.y1, pairs.h, targets)

    def pair_residuals(self, model, y0, targets):
        scale = jnp.asarray(model.output_scales)
        return (jax.vmap(model.alpha)(y0) - targets) / scale

    @property
    def name(self) -> str:
        return "alpha"


class MeanSquares(AbstractPairsLoss):
    r"""A least-squares loss on pairs from a function: `residuals(model, y0, y1)` `(N, k)`, named
    `name`."""

    function: Callable[[Any, jax.Array, jax.Array], jax.Array]
    label: str = eqx.field(static=True, default="mean squares")

    def pair_residuals(self, model, y0, targets):
        return self.function(model, y0, targets)

    @property
    def name(self) -> str:
        return self.label


def state_mse(model: Any, y0: ArrayLike, y1: ArrayLike) -> jax.Array:
    r"""The state loss of `model` on the pairs `y0`, `y1` `(N, dim)`: the mean squared error of
    its step (`learn.StateLoss`)."""
    return StateLoss()(model, Pairs(jnp.asarray(y0), jnp.asarray(y1)))


def alpha_mse(model: Any, y0: ArrayLike, alpha: ArrayLike) -> jax.Array:
    r"""The alpha loss of an LPNet on `y0` `(N, dim)` and the pairs' parameters `alpha`
    (`learn.AlphaLoss`)."""
    return AlphaLoss()(model, Pairs(jnp.asarray(y0), jnp.asarray(alpha)))
