r"""A training problem, as optimistix poses one: minimise $f(y, \text{args})$ over a pytree $y$.

$y$ is *what is trained*: a learned map (its inexact array leaves move, the rest is fixed), or
with observations the map and the fitted initial states (`learn.Fitted`); `args` the data as
a pytree whose leaves have the samples on axis 0 (pairs, segments of observations). The
objective $f$ is an `AbstractObjective`; what a solver can exploit of it (residuals, a
structured Jacobian) is a subclass, never probed with `hasattr`. The solvers of `learn.fit`
know only this module's classes, nothing of learned maps.
"""

from __future__ import annotations

import abc
import dataclasses
import math
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.flatten_util
import numpy as np

from ._compiled import FlatObjective, compiled, flat_objective


class AbstractObjective(eqx.Module):
    r"""$f(y, \text{args})$: a scalar training loss, a mean over the samples of `args`.
    Objectives enter compiled code: equal objectives (same fields) share compiled functions."""

    @abc.abstractmethod
    def __call__(self, y: Any, args: Any) -> jax.Array:
        """The loss of `y` on the data `args` (a scalar)."""


class AbstractLeastSquares(AbstractObjective):
    r"""An objective that is a mean of squared residuals,
    $f = \sum_i r_i(y)^2 / n$: `learn.LevenbergMarquardt` minimises $\|r\|^2$ itself."""

    @abc.abstractmethod
    def residuals(self, y: Any, args: Any) -> jax.Array:
        """The residuals $r(y)$ (any shape; zero where a component is not counted)."""

    @abc.abstractmethod
    def count(self, y: Any, args: Any) -> int:
        r"""$n$: how many residual components the mean is over ($f = \|r\|^2 / n$)."""

    def jacobian(self, y: Any, args: Any) -> tuple[jax.Array, jax.Array]:
        r"""`(r (n,), J (n, p))`: the residuals flattened and their Jacobian with respect to the
        $p$ flat trainable leaves of `y` (`jax.jacfwd`: $p$ forward passes).
        `AbstractStructuredJacobian` builds it from blocks."""
        params, static = eqx.partition(y, eqx.is_inexact_array)
        x, unravel = jax.flatten_util.ravel_pytree(params)

        def r(z):
            value = self.residuals(eqx.combine(unravel(z), static), args).reshape(-1)
            return value, value

        # The residuals as the auxiliary output of the Jacobian's own forward pass: one
        # evaluation, not two. Two in one program also ran concurrently on XLA's CPU threads,
        # and two batches of LAPACK calls at once (the LU of an isospectral step) deadlocked.
        J, value = jax.jacfwd(r, has_aux=True)(x)
        return value, J

    def forward_passes(self, y: Any) -> int:
        """How many forward passes one Jacobian takes: one per trainable scalar of `y`."""
        return int(sum(a.size for a in jax.tree_util.tree_leaves(eqx.filter(y, eqx.is_inexact_array))))


class AbstractStructuredJacobian(AbstractLeastSquares):
    r"""A least-squares objective whose Jacobian has a block structure that saves forward
    passes (e.g. segments that each depend on their own fitted start): it overrides
    `jacobian` and `forward_passes`, and may give the normal equations $J^TJ$, $J^Tr$ from the
    blocks without holding $J$ (`normal_equations`, `block_entries`)."""

    @abc.abstractmethod
    def jacobian(self, y: Any, args: Any) -> tuple[jax.Array, jax.Array]:
        """`(r (n,), J (n, p))`, built from the blocks."""

    @abc.abstractmethod
    def forward_passes(self, y: Any) -> int:
        """The forward passes the blocks need."""

    def normal_equations(self, y: Any, args: Any) -> tuple[jax.Array, jax.Array, jax.Array]:
        r"""`(r (n,), A (p, p), g (p,))`: $A = J^TJ$ and $g = J^Tr$, summed block by block where
        the objective knows how (the same sums as from `jacobian`, in another order); by
        default from `jacobian`."""
        r, J = self.jacobian(y, args)
        return r, J.T @ J, J.T @ r

    def block_entries(self, y: Any, args: Any) -> int:
        """How many numbers `normal_equations` holds at once (its blocks and $A$); by default
        the whole Jacobian's (nothing saved: `learn.LevenbergMarquardt` then uses `jacobian`)."""
        n = math.prod(jax.eval_shape(lambda: self.residuals(y, args)).shape)
        return n * int(sum(a.size for a in jax.tree_util.tree_leaves(eqx.filter(y, eqx.is_inexact_array))))


@dataclasses.dataclass(frozen=True)
class Losses:
    """The losses of one `y`: `train`, `validation` (NaN without validation data) and
    `selection`, the one that decides between candidates (validation, else training; `inf`
    when not finite)."""

    train: float
    validation: float
    selection: float


class AbstractProblem(abc.ABC):
    r"""Minimise `objective(y, args)` from `y0` on the data `train`; `validation` (or `None`)
    selects between candidates. What only the problem's builder knows (fresh weights for a
    restart, a simpler problem to start from, how a checkpoint file is identified) are its
    abstract methods."""

    objective: AbstractObjective
    y0: Any
    train: Any
    validation: Any | None
    #: What progress bars and messages call the thing trained (e.g. "GLPNet").
    name: str

    @abc.abstractmethod
    def with_start(self, y0: Any) -> AbstractProblem:
        """The same problem from another start."""

    @abc.abstractmethod
    def reinitialised(self, key: jax.Array) -> Any:
        """A fresh start: `y0` with new random weights from `key`."""

    @abc.abstractmethod
    def warm_start(self) -> tuple[AbstractProblem, Callable[[Any], Any]] | None:
        """`(simpler, to_this)`: a simpler problem to solve first and the map from its
        solution to a start of this one; `None` if there is none."""

    @abc.abstractmethod
    def file_attributes(self) -> dict[str, Any]:
        """What identifies `y0`'s structure in a checkpoint file."""

    @abc.abstractmethod
    def read_checkpoint(self, path: str) -> tuple[dict[str, Any], dict[str, Any]]:
        """`(attrs, groups)` of the training checkpoint at `path`; `ValueError` unless it was
        written for this structure (class, system, architecture)."""

    def step_size(self, y: Any) -> Any:
        """Where `y` holds a step size that compiled code should take as an input (so that
        one compilation serves every step size): `y.h` for a map; `None` (the default) for
        none."""
        return None

    @property
    def has_validation(self) -> bool:
        return self.validation is not None

    def flat(self) -> FlatObjective:
        """The objective as a function of the flat trainable leaves of `y0` (compiled once per
        structure and objective, see `FlatObjective`)."""
        return flat_objective(self.objective, self.y0, self.step_size(self.y0) is not None)

    def losses(self, y: Any) -> Losses:
        """Training, validation and selection losses of `y`."""
        flat = self.flat()
        evaluate = compiled(("evaluate", flat), lambda: jax.jit(flat))
        x, h = flat.ravel(y)
        train = float(evaluate(x, (self.train, h)))
        validation = float(evaluate(x, (self.validation, h))) if self.has_validation else float("nan")
        selection = validation if self.has_validation else train
        return Losses(train, validation, selection if np.isfinite(selection) else np.inf)
