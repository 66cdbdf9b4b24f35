r"""The abstract splitting method: a one-step map $y_{n+1} = \Phi_h(y_n)$ composed of the exact
flows $\varphi^{[k]}_t$ of the pieces $H = \sum_k H_k$ given by `system.hamiltonian_splitting()`."""

from __future__ import annotations

import abc
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from liepoisson._validation import as_state, positive_float
from liepoisson.systems import AbstractPoissonSystem, CollectiveTerm

from .._ground_truth import check_n_steps


class AbstractSplittingMethod(eqx.Module):
    r"""A splitting method $\Phi_h$ for a system with an exactly solvable splitting.

    Every sub-flow is exact, Poisson and Casimir-preserving (a frozen-parameter test flow),
    so $\Phi_h$ is a Poisson map that conserves every Casimir to round-off, whatever its order.

    Subclasses give `order` and `_step(terms, y, h)`, the map on one state `(dim,)`; `step` and
    `rollout` validate, vectorise (`jax.vmap`) and compile (`jax.jit`, `jax.lax.scan`).

    **Arguments:** `system`, an `AbstractPoissonSystem` whose `hamiltonian_splitting()` gives
    the pieces.
    """

    system: AbstractPoissonSystem = eqx.field(static=True)
    order: ClassVar[int]

    def __check_init__(self):
        if not isinstance(self.system, AbstractPoissonSystem):
            raise TypeError(f"system must be an AbstractPoissonSystem; got {type(self.system).__name__}")
        terms = self.system.hamiltonian_splitting()
        if not terms or not all(isinstance(t, CollectiveTerm) for t in terms):
            raise TypeError(
                f"{self.system!r}.hamiltonian_splitting() must return CollectiveTerms; got {terms!r}"
            )

    @property
    def terms(self) -> tuple[CollectiveTerm, ...]:
        """The pieces $H_1, \\dots, H_N$ (their flows are applied in this order)."""
        return tuple(self.system.hamiltonian_splitting())

    def flow(self, k: int, t: Any, y: jax.Array) -> jax.Array:
        r"""Exact flow $\varphi^{[k]}_t(y)$ of the $k$-th piece."""
        return self.terms[k].flow(self.system, t, y)

    @abc.abstractmethod
    def _step(self, y: jax.Array, h: jax.Array) -> jax.Array:
        """One step from a single state `(dim,)` (traced)."""

    # -- public, validated ------------------------------------------------------------------
    def step(self, y: Any, h: float) -> jax.Array:
        """One step of size `h` from `y` of shape `(dim,)` or `(n, dim)`."""
        h = positive_float(h, "h")
        y = as_state(y, "y", self.system.dim)
        if y.ndim > 2:
            raise ValueError(f"y must have shape ({self.system.dim},) or (n, {self.system.dim}); got {y.shape}")
        return _jit_step(self, y, jnp.float64(h))

    def rollout(self, y0: Any, h: float, n_steps: int) -> jax.Array:
        """`n_steps` steps of size `h`: `(n_steps + 1, dim)` from `y0` of shape `(dim,)`, or
        `(n_traj, n_steps + 1, dim)` from `(n_traj, dim)`; entry 0 is `y0`."""
        h = positive_float(h, "h")
        n_steps = check_n_steps(n_steps)
        y0 = as_state(y0, "y0", self.system.dim)
        if y0.ndim > 2:
            raise ValueError(
                f"y0 must have shape ({self.system.dim},) or (n_traj, {self.system.dim}); got {y0.shape}"
            )
        out = _jit_rollout(self, y0, jnp.float64(h), n_steps)
        return out


def _batched_step(method: AbstractSplittingMethod, y: jax.Array, h: jax.Array) -> jax.Array:
    return jax.vmap(method._step, in_axes=(0, None))(y, h) if y.ndim == 2 else method._step(y, h)


@eqx.filter_jit
def _jit_step(method, y, h):
    return _batched_step(method, y, h)


@eqx.filter_jit
def _jit_rollout(method, y0, h, n_steps):
    def body(y, _):
        y = _batched_step(method, y, h)
        return y, y

    _, ys = jax.lax.scan(body, y0, None, length=n_steps)
    ys = jnp.concatenate([y0[None], ys], axis=0)  # (n_steps + 1, [n_traj,] dim)
    return jnp.moveaxis(ys, 0, -2) if y0.ndim == 2 else ys


def symmetric_coefficients(half: tuple[float, ...]) -> np.ndarray:
    """The palindrome `half + reversed(half[:-1])` as float64 (symmetric composition tables)."""
    half_arr = np.asarray(half, dtype=np.float64)
    return np.concatenate([half_arr, half_arr[-2::-1]])
