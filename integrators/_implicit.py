r"""Implicit step maps: a step that solves an equation $z = G(c, z)$ by a fixed number of
iterations, with one non-convergence policy for all of them.

A step whose last iteration still moves $z$ by more than $2^{10}\varepsilon\max(1, |z|_\infty)$
has not converged: it returns NaN, never its last iterate, so a rollout stops there and
`RolloutDivergedError` names the step, the state and what to do (`with_iterations`).
"""

from __future__ import annotations

import abc
import copy
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from liepoisson.internals import positive_int

from ._step_map import AbstractStepMap, check_state, traced_h, xla_flops

#: A last iteration that moved the solution by more than this (relative to max(1, |z|_inf)) has
#: not converged: 2^10 eps, the round-off of a few hundred operations on the state.
CONVERGENCE_RTOL = 2.0**10 * float(np.finfo(np.float64).eps)


class AbstractImplicitStepMap(AbstractStepMap):
    r"""A step map whose step is the solution $z$ of $z = G(c, z)$, found by `iterations`
    iterations $z_{k+1} = G(c, z_k)$ from a start $z_0$, where $(c, z_0)$ = `start(y)` holds
    what the iteration needs of $y$ (a Newton step is such a $G$).

    Final subclasses define `start`, `iterate` and `iterations` (a static field). `step` runs
    the iteration and returns NaN where it has not converged (see the module's policy).
    """

    iterations: eqx.AbstractVar[int]

    @abc.abstractmethod
    def start(self, y: jax.Array) -> tuple[Any, jax.Array]:
        """`(context, z0)` for one state `y`: what every iteration needs, and the first iterate."""

    @abc.abstractmethod
    def iterate(self, context: Any, z: jax.Array) -> jax.Array:
        """One iteration $z \\mapsto G(c, z)$."""

    def finish(self, context: Any, z: jax.Array) -> jax.Array:
        """The next state from the converged iterate: `z` itself unless the iteration is on
        something else (a Runge-Kutta method's stages)."""
        return z

    def step(self, y: jax.Array) -> jax.Array:
        context, z = self.start(check_state(y, self.system.dim))
        z, converged = self.solve(context, z)
        return jnp.where(converged, self.finish(context, z), jnp.nan)

    def solve(self, context: Any, z: jax.Array) -> tuple[jax.Array, jax.Array]:
        """`(z, converged)`: the iterate after `iterations` iterations from `z`, and whether the
        last one moved it by at most the module's tolerance."""
        z = jax.lax.fori_loop(0, self.iterations - 1, lambda _, z: self.iterate(context, z), z)
        z_next = self.iterate(context, z)
        moved = jnp.max(jnp.abs(z_next - z))
        return z_next, moved <= CONVERGENCE_RTOL * jnp.maximum(1.0, jnp.max(jnp.abs(z_next)))

    def with_iterations(self, iterations: int) -> AbstractImplicitStepMap:
        """The same map with another iteration count (a large step contracts slowly)."""
        # A static field (a loop bound at trace time), which eqx.tree_at cannot replace; a
        # shallow copy shares the weights, and the new count recompiles the step.
        new = copy.copy(self)
        object.__setattr__(new, "iterations", positive_int(iterations, "iterations"))
        return new

    @property
    def divergence_hint(self) -> str:
        return (f"The map left the finite range, or its implicit iteration did not converge in "
                f"iterations={self.iterations} (a step that has not converged is NaN, never its last "
                f"iterate): try .with_iterations({4 * self.iterations}) or a smaller h")

    def step_flops(self) -> float:
        """The start plus `iterations` iterations (XLA counts a loop body once)."""
        y = jnp.zeros(self.system.dim)
        context, z = self.start(y)
        first = xla_flops(_start, traced_h(self), y)
        return first + self.iterations * xla_flops(_iterate, traced_h(self), context, z)


def _start(step_map: AbstractImplicitStepMap, y: jax.Array) -> Any:
    return step_map.start(y)


def _iterate(step_map: AbstractImplicitStepMap, context: Any, z: jax.Array) -> jax.Array:
    return step_map.iterate(context, z)
