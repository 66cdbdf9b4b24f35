"""Compiled functions kept across fits: one cache for every solver, and the objective as a
function of flat parameters, equal for equal structures so that it compiles once."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree

#: Entries kept at most: a long sweep over many structures starts afresh past this.
CACHE_SIZE = 64

_CACHE: dict[Any, Any] = {}


def compiled(key: Any, build: Callable[[], Any]) -> Any:
    """`build()` once per `key` (by equality: a compiled function kept for later fits of the
    same structure); an unhashable key builds anew."""
    try:
        if key not in _CACHE:
            if len(_CACHE) >= CACHE_SIZE:
                _CACHE.clear()
            _CACHE[key] = build()
        return _CACHE[key]
    except TypeError:
        return build()


class FlatObjective:
    r"""`f(x, (args, h))`: the objective at the `y` whose flat trainable leaves are `x`, with the
    step size `h` of `y` traced (when `y` has one): equal (same hash) for the same objective,
    structure and parameter layout whatever the step size, so that `jax.jit` caches and the
    solvers compile once per structure, not once per fit."""

    def __init__(self, objective: Any, y: Any, has_h: bool):
        params, static = eqx.partition(y, eqx.is_inexact_array)
        self.objective = objective
        self.has_h = has_h
        self.static = eqx.tree_at(lambda m: m.h, static, 0.0, is_leaf=lambda v: v is None) if has_h else static
        self.layout = (jax.tree_util.tree_structure(params),
                       tuple((a.shape, str(a.dtype)) for a in jax.tree_util.tree_leaves(params)))
        self.unravel = ravel_pytree(params)[1]

    def _key(self):
        return (self.objective, self.static, self.layout)

    def __hash__(self):
        try:
            return hash(self._key())
        except TypeError:  # an objective holding arrays: equal only to itself, compiled per fit
            return id(self)

    def __eq__(self, other):
        if self is other:
            return True
        try:
            return isinstance(other, FlatObjective) and bool(self._key() == other._key())
        except TypeError:
            return False

    def ravel(self, y: Any) -> tuple[jax.Array, jax.Array]:
        """`(x, h)` of `y` (`h` 0 when `y` has no step size)."""
        x = ravel_pytree(eqx.filter(y, eqx.is_inexact_array))[0]
        h = y.h if self.has_h and y.h is not None else 0.0
        return x, jnp.asarray(h, dtype=jnp.float64)

    def unflatten(self, x: jax.Array, h: Any = None) -> Any:
        """The `y` of flat leaves `x` (and step size `h`)."""
        y = eqx.combine(self.unravel(x), self.static)
        if self.has_h:
            y = eqx.tree_at(lambda m: m.h, y, h)
        return y

    def __call__(self, x: jax.Array, args_h: tuple[Any, jax.Array]) -> jax.Array:
        args, h = args_h
        return self.objective(self.unflatten(x, h), args)


def flat_objective(objective: Any, y: Any, has_h: bool) -> FlatObjective:
    """The `FlatObjective` of `objective` at `y`'s structure, one instance per structure."""
    return compiled(("flat", FlatObjective(objective, y, has_h)), lambda: FlatObjective(objective, y, has_h))
