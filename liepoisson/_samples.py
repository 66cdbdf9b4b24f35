"""The sample axis: the library maps over samples (training pairs, trajectories) with
`vmap_samples`, a `vmap` whose axis carries a name, so that code under it can take a maximum
over the whole batch and branch on it for real; and `common_path_first`, the execution policy
that compiles training with `expm_action`'s common path alone and falls back to every path."""

from __future__ import annotations

import contextvars
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp

# The library maps over samples (training pairs, trajectories) with `vmap_samples`, a `vmap`
# whose axis carries this name. Code under it can take a maximum over the whole batch
# (`lax.pmax`) and branch on it for real: a branch on a per-sample value under a plain `vmap`
# evaluates every branch.
SAMPLE_AXIS = "liepoisson_samples"


def vmap_samples(fun):
    """`jax.vmap(fun)` over the leading axis, named `SAMPLE_AXIS` (see `expm_action`)."""
    return jax.vmap(fun, axis_name=SAMPLE_AXIS)


def sample_max(x: jax.Array) -> jax.Array | None:
    """`max(x)` over the arrays' axes and the named sample axis (unbatched), or `None` when
    not traced under `vmap_samples`."""
    x = jax.lax.stop_gradient(jnp.max(x))
    try:
        return jax.lax.pmax(x, SAMPLE_AXIS)
    except NameError:  # not under vmap_samples: the maximum would be per sample
        return None


# Set while `common_path_first` traces its first attempt (read at trace time by `expm_action`).
COMMON_PATH_ONLY: contextvars.ContextVar[bool] = contextvars.ContextVar("common_path_only", default=False)


def common_path_first(fun: Callable, ok: Callable[[Any], bool]) -> Callable:
    r"""`jax.jit(fun)` that runs `expm_action` on its common path only, and again with every
    path where that was not enough.

    Under `vmap_samples`, `expm_action` branches on the batch's largest $|A|_1$; reverse mode
    through that branch carries the other paths along, in the same compiled program, and costs
    more than the straight-line common path (benchmarks,
    [Any Lie algebra][any-lie-algebra-four-algebras-outside-the-catalogue-benchmarksany_algebrapy]).
    The first attempt is compiled with the common path alone, as straight-line code, and
    gives NaN wherever a batch is beyond its bound; when `ok(outputs)` (host values) is false,
    the call is
    repeated with the full `expm_action` (compiled on first need), and so are all later calls
    (norms beyond the bound tend to stay: without this, a G-LPNet on sl(3) would compute every
    gradient twice). Either way the result is
    that of `jax.jit(fun)`, so `fun` must be a pure function of its arguments, and `ok` must
    reject every output that went through a NaN (e.g. require a finite loss).
    """
    first = jax.jit(lambda *args: fun(*args))  # two function objects: two caches of traces
    every = jax.jit(lambda *args: fun(*args))

    rejected = False

    def call(*args):
        nonlocal rejected
        if rejected:
            return every(*args)
        token = COMMON_PATH_ONLY.set(True)
        try:
            out = first(*args)
        finally:
            COMMON_PATH_ONLY.reset(token)
        if ok(out):
            return out
        rejected = True
        return every(*args)

    return call
