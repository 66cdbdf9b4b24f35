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


class AbstractAtStructure:
    """A function of the flat trainable leaves `x` of a `y` of one structure: the objective,
    the fixed (non-trainable) part of `y`, and the layout of its leaves. Equal (same hash) for
    the same objective, fixed part and layout, so that what is compiled for it is compiled once
    per structure, not once per fit; an objective holding arrays is equal only to itself."""

    def __init__(self, objective: Any, y: Any):
        params, static = eqx.partition(y, eqx.is_inexact_array)
        self.objective = objective
        self.static = static
        self.layout = (jax.tree_util.tree_structure(params),
                       tuple((a.shape, str(a.dtype)) for a in jax.tree_util.tree_leaves(params)))
        self.unravel = ravel_pytree(params)[1]

    def _key(self):
        return (type(self), self.objective, self.static, self.layout)

    def __hash__(self):
        try:
            return hash(self._key())
        except TypeError:  # an objective holding arrays: compiled per fit
            return id(self)

    def __eq__(self, other):
        if self is other:
            return True
        try:
            return isinstance(other, AbstractAtStructure) and bool(self._key() == other._key())
        except TypeError:
            return False

    def model(self, x: jax.Array) -> Any:
        """The `y` whose flat trainable leaves are `x`."""
        return eqx.combine(self.unravel(x), self.static)


class FlatObjective(AbstractAtStructure):
    r"""`f(x, (args, h))`: the objective at the `y` whose flat trainable leaves are `x`, with the
    step size `h` of `y` traced (when `y` has one), so that one compilation serves every step
    size."""

    def __init__(self, objective: Any, y: Any, has_h: bool):
        super().__init__(objective, y)
        self.has_h = has_h
        if has_h:
            self.static = eqx.tree_at(lambda m: m.h, self.static, 0.0, is_leaf=lambda v: v is None)

    def ravel(self, y: Any) -> tuple[jax.Array, jax.Array]:
        """`(x, h)` of `y` (`h` 0 when `y` has no step size)."""
        x = ravel_pytree(eqx.filter(y, eqx.is_inexact_array))[0]
        h = y.h if self.has_h and y.h is not None else 0.0
        return x, jnp.asarray(h, dtype=jnp.float64)

    def __call__(self, x: jax.Array, args_h: tuple[Any, jax.Array]) -> jax.Array:
        args, h = args_h
        y = self.model(x)
        if self.has_h:
            y = eqx.tree_at(lambda m: m.h, y, h)
        return self.objective(y, args)


def flat_objective(objective: Any, y: Any, has_h: bool) -> FlatObjective:
    """The `FlatObjective` of `objective` at `y`'s structure, one instance per structure."""
    return compiled(("flat", FlatObjective(objective, y, has_h)), lambda: FlatObjective(objective, y, has_h))
