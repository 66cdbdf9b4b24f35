r"""The step map: one interface for every integrator, classical or learned.

A step map is a one-step map $y_{n+1} = \Phi_h(y_n)$ of a Poisson system with a fixed step
size $h$: a classical splitting method bound to a system and $h$, an LPNet, a G-LPNet or an
unstructured baseline. All of them share one validated, compiled `rollout`, one
`poisson_defect` and one cost figure, so a learned map and a classical one are compared with
the same calls.
"""

from __future__ import annotations

import abc
import dataclasses
import math
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from liepoisson import vmap_samples
from liepoisson.internals import as_state, positive_float, positive_int, states
from liepoisson.internals import check_fits_in_memory as fits_in_memory
from liepoisson.systems import AbstractPoissonSystem

from ._diagnostics import per_state
from ._nonfinite import AbstractNonfinitePolicy, RaiseIfNonfinite, nonfinite_policy


@dataclasses.dataclass(frozen=True)
class StepCost:
    """What one step costs: `flops`, XLA's estimate of the floating-point operations of one
    compiled step on one state (the same count for every kind of map), and `exact_flows`, the
    number of exact sub-flows (test flows) it evaluates."""

    flops: float
    exact_flows: int


class AbstractStepMap(eqx.Module):
    r"""A one-step map $y \mapsto \Phi_h(y)$ of `system` with step size `h`.

    Final subclasses define `step` on one state (traceable: `jit`, `vmap`, `grad`) and
    `exact_flows_per_step`; everything else is shared: `rollout`, `poisson_defect`, `cost`.
    `h` is `None` only for a learned map that has not been fitted yet (it takes the data's
    step); such a map cannot be rolled out.
    """

    system: eqx.AbstractVar[AbstractPoissonSystem]
    h: eqx.AbstractVar[float | None]

    @abc.abstractmethod
    def step(self, y: jax.Array) -> jax.Array:
        """$\\Phi_h(y)$ for one state `y` of shape `(dim,)`."""

    @property
    @abc.abstractmethod
    def exact_flows_per_step(self) -> int:
        """How many exact sub-flows (test flows) one step evaluates."""

    # -- shared ------------------------------------------------------------------------------
    @property
    def label(self) -> str:
        """A short name for tables and messages (the class name; a bound splitting method
        says its method's)."""
        return type(self).__name__

    def with_h(self, h: float) -> AbstractStepMap:
        r"""The same map at step size `h` (> 0), everything else unchanged: $\Phi_h$ of a
        splitting method at another step, or a learned map run at a step it was not trained
        at (meaningful for maps whose step is a splitting of a learned Hamiltonian, e.g. a
        symmetric `learn.GLPNet`; an LPNet's $\alpha(y)$ was fitted to its training step, and
        at another step its test flow is only a first-order approximation)."""
        h = positive_float(h, "h")
        return eqx.tree_at(lambda m: m.h, self, h, is_leaf=lambda x: x is None)

    def _check_h(self) -> float:
        # Kept for the subclasses that call it; `check_h(self)` is the name to use.
        return check_h(self)

    def rollout(self, y0: ArrayLike, n_steps: int, *, save_every: int = 1,
                nonfinite: str | AbstractNonfinitePolicy = "raise") -> jax.Array:
        r"""Iterate the step: $y_k = \Phi_h^k(y_0)$ for $k = 0, s, 2s, \dots, n$ ($s$ =
        `save_every`, which must divide `n_steps`).

        **Arguments:** `y0` of shape `(dim,)` or `(n_traj, dim)`, finite; `n_steps` >= 0;
        `save_every` >= 1.

        **Returns:** `(n_steps // save_every + 1, dim)`, or `(n_traj, n_steps // save_every + 1,
        dim)` for many initial conditions; entry 0 is `y0`. Compiled once per map structure and
        shape of `y0`: every `n_steps`, `save_every` and `h` runs the same program, a piece of
        at most `chunk_size` saved states applied as often as needed (vectorised over
        trajectories with `jax.vmap`).

        A trajectory that leaves the finite range (a learned map far outside its training
        region, too large a step) raises `RolloutDivergedError` naming the trajectory, the steps
        between which it diverged and its last finite state (`nonfinite=RaiseIfNonfinite()`, or
        `"raise"`, the default); `nonfinite=ReturnNonfinite()` (or `"return"`) returns the
        states with their non-finite tail instead (`integrators.diagnostics` reports up to the
        first non-finite step).
        """
        check_h(self)
        dim = self.system.dim
        n_steps = positive_int(n_steps, "n_steps", minimum=0)
        save_every = positive_int(save_every, "save_every")
        if n_steps % save_every:
            raise ValueError(
                f"save_every must divide n_steps; got n_steps={n_steps}, save_every={save_every}"
            )
        nonfinite = nonfinite_policy(nonfinite)
        y0 = states(y0, "y0", dim)
        if y0.ndim > 2:
            raise ValueError(f"y0 must have shape ({dim},) or (n_traj, {dim}); got shape {y0.shape}")
        n_traj = 1 if y0.ndim == 1 else y0.shape[0]
        check_fits_in_memory((n_traj, n_steps // save_every + 1, dim),
                             "the rollout's states (n_traj, n_steps // save_every + 1, dim)",
                             "save fewer states with save_every= (a divisor of n_steps: every save_every-th "
                             "state is kept), or roll out fewer trajectories or steps at a time")
        Y = y0.reshape(-1, dim)
        step_map, every, chunk = traced_h(self), _traced_count(save_every), chunk_size(n_traj, dim)
        (host,) = _in_chunks(lambda c, count: _rollout_chunk(step_map, c, count, every, chunk),
                             _carry_compiled(step_map, jax.device_put(Y)), (Y,), n_steps // save_every, chunk)
        out = jax.device_put(host)  # not jnp.asarray: that compiles a copy per shape
        nonfinite.check(self, out, save_every)
        return jax.device_put(host[0]) if y0.ndim == 1 else out

    # -- the state between steps ------------------------------------------------------------
    # A rollout carries the state from step to step in the map's own representation (an
    # isospectral method: the matrix W), converting only the states it saves.
    def carry(self, y: jax.Array) -> Any:
        """The state `y` `(dim,)` as the map carries it between steps (default: `y`)."""
        return y

    def step_carry(self, c: Any) -> Any:
        """One step on a carried state (default: `step`)."""
        return self.step(c)

    def uncarry(self, c: Any) -> jax.Array:
        """The state `(dim,)` of a carried one (default: itself)."""
        return c

    def poisson_defect(self, y: ArrayLike) -> jax.Array:
        r"""$\max_{ab}|(J\,\mathbb B(y)\,J^\top - \mathbb B(\Phi_h(y)))_{ab}|$ per point, with
        $J = \partial\Phi_h/\partial y$ (forward-mode autodiff): zero, up to round-off, exactly
        when the step is a Poisson map. `y` of shape `(..., dim)`; returns `(...)`."""
        check_h(self)
        dim = self.system.dim
        y = states(y, "y", dim)
        # padded to a bucket of points (`per_state`): one compiled program for any number of them
        step_map = traced_h(self)
        return jax.device_put(per_state(lambda points: _defect_compiled(step_map, jnp.asarray(points)), np.asarray(y)))

    @property
    def divergence_hint(self) -> str:
        """What a `RolloutDivergedError` says may have gone wrong (maps with a failure mode of
        their own say so)."""
        return ("The map left the finite range (a learned map far outside its training data, or too "
                "large a step)")

    def cost(self) -> StepCost:
        """The cost of one step (see `StepCost`); `flops` from XLA's cost analysis of the
        compiled step (`step_flops`)."""
        check_h(self)
        return StepCost(flops=self.step_flops(), exact_flows=self.exact_flows_per_step)

    def step_flops(self) -> float:
        """XLA's flop count of one compiled step. XLA counts the body of a loop (`scan`,
        `fori_loop`) once, so maps that loop inside `step` override this with the count per
        iteration times the number of iterations."""
        return xla_flops(lambda m, y: m.step(y), traced_h(self), jnp.zeros(self.system.dim))


class AbstractReconstructingStepMap(AbstractStepMap):
    r"""A step map that also carries the configuration: $(g_{n+1}, \mu_{n+1}) =
    \Psi_h(g_n, \mu_n)$, whose momentum part is `step`. A composition of lifted test flows
    (a splitting method on `CollectiveTerm`s, a G-LPNet) reconstructs exactly: each piece moves
    $g \mapsto g\exp(t\alpha)$ with its frozen body velocity $\alpha$, so the spatial momentum
    $\mathrm{Ad}^*_{g^{-1}}\mu$ is kept to round-off and $g$ stays on the group."""

    @abc.abstractmethod
    def lifted_step(self, g: jax.Array, y: jax.Array) -> tuple[jax.Array, jax.Array]:
        r"""$(g_1, \mu_1)$ from one configuration `(group.size,)` and state `(dim,)`."""

    def lifted_rollout(self, g0: ArrayLike, y0: ArrayLike, n_steps: int, *,
                       save_every: int = 1) -> tuple[jax.Array, jax.Array]:
        r"""Iterate `lifted_step` from $(g_0, \mu_0)$: configurations and states at steps
        $0, s, 2s, \dots, n$ ($s$ = `save_every`, a divisor of `n_steps`).

        **Arguments:** `g0` `(group.size,)` or `(n_traj, group.size)` on `system.group` (unit
        quaternions, scalar last, for `liepoisson.Rotations`); `y0` `(dim,)` or `(n_traj, dim)`.

        **Returns:** `(configurations, states)`, `(n_traj, n_saved, group.size)` and
        `(n_traj, n_saved, dim)` (without the leading axis for one initial condition).
        A trajectory that leaves the finite range raises `RolloutDivergedError`. Compiled once
        per map structure and number of trajectories, as `rollout`."""
        check_h(self)
        group = self.system.require_group()
        dim = self.system.dim
        n_steps = positive_int(n_steps, "n_steps", minimum=0)
        save_every = positive_int(save_every, "save_every")
        if n_steps % save_every:
            raise ValueError(f"save_every must divide n_steps; got n_steps={n_steps}, save_every={save_every}")
        y0 = states(y0, "y0", dim)
        g0 = np.asarray(group.check(g0, "g0"))
        if y0.ndim > 2 or g0.ndim > 2:
            raise ValueError(f"y0 must have shape ({dim},) or (n_traj, {dim}) and g0 ({group.size},) or "
                             f"(n_traj, {group.size}); got shapes {y0.shape} and {g0.shape}")
        n_traj = max(1 if y0.ndim == 1 else y0.shape[0], 1 if g0.ndim == 1 else g0.shape[0])
        if (y0.ndim == 2 and y0.shape[0] != n_traj) or (g0.ndim == 2 and g0.shape[0] != n_traj):
            raise ValueError(f"g0 and y0 must hold as many initial conditions; got shapes {g0.shape} and {y0.shape}")
        check_fits_in_memory((n_traj, n_steps // save_every + 1, dim + group.size),
                             "the lifted rollout's configurations and states",
                             "save fewer with save_every= (a divisor of n_steps), or roll out fewer trajectories "
                             "or steps at a time")
        G = np.broadcast_to(g0, (n_traj, group.size))
        Y = np.broadcast_to(y0, (n_traj, dim))
        step_map, every, chunk = traced_h(self), _traced_count(save_every), chunk_size(n_traj, dim + group.size)
        gs, ys = _in_chunks(lambda c, count: _lifted_rollout_chunk(step_map, c, count, every, chunk),
                            jax.device_put((G, Y)), (G, Y), n_steps // save_every, chunk)
        # on the host: no small program compiled per length for the check or the slicing
        bad = ~(np.all(np.isfinite(ys), axis=(1, 2)) & np.all(np.isfinite(gs), axis=(1, 2)))
        if bool(np.any(bad)):
            RaiseIfNonfinite().check(self, np.where(np.isfinite(gs[..., :1]), ys, np.nan), save_every)
        single = y0.ndim == 1 and g0.ndim == 1
        return jax.device_put((gs[0], ys[0]) if single else (gs, ys))


def check_fits_in_memory(shape: tuple[int, ...], what: str, remedy: str) -> None:
    """`ValueError` (before anything is allocated) if a float64 array of `shape` would not fit
    in the memory one request may take (`liepoisson.internals.check_fits_in_memory`): `what`
    needs it, and `remedy` says how to ask for less. The one size check of every rollout and
    ground-truth request."""
    shape = tuple(int(k) for k in shape)
    fits_in_memory(8 * math.prod(shape), f"{what} of shape {shape}", remedy)


_FLOPS: dict[Any, float] = {}


def xla_flops(fn: Callable[..., Any], *args: Any) -> float:
    """XLA's cost-analysis flop count of `fn(*args)` compiled (array leaves traced, the rest
    static); NaN where the backend does not report it. Remembered per code of `fn`, static
    leaves and array shapes (a count does not depend on the arrays' values; pass maps through
    `traced_h` so that their step size is one of those arrays)."""
    dynamic, static = eqx.partition(args, eqx.is_array)
    key = None
    if getattr(fn, "__closure__", True) is None:  # a plain function or lambda: its code names it
        leaves, treedef = jax.tree_util.tree_flatten(static)
        shapes = tuple((x.shape, str(x.dtype)) for x in jax.tree_util.tree_leaves(dynamic))
        key = (fn.__code__, treedef, tuple(leaves), shapes)
        try:
            if key in _FLOPS:
                return _FLOPS[key]
        except TypeError:  # an unhashable static leaf: count without remembering
            key = None
    compiled = jax.jit(lambda d: fn(*eqx.combine(d, static))).lower(dynamic).compile()
    analysis = compiled.cost_analysis()
    if isinstance(analysis, (list, tuple)):  # older jax: one entry per device
        analysis = analysis[0] if analysis else {}
    flops = float((analysis or {}).get("flops", np.nan))
    if key is not None:
        _FLOPS[key] = flops
    return flops


def check_h(step_map: AbstractStepMap) -> float:
    """The step size of `step_map`, or a `ValueError` saying that a map without one (a learned
    map not fitted yet) cannot be stepped."""
    if step_map.h is None:
        raise ValueError(
            f"{type(step_map).__name__} has no step size h yet: fit it to data "
            "(learn.fit(model, data)) or construct it with h=..."
        )
    return step_map.h


def check_state(y: jax.Array, dim: int) -> jax.Array:
    """`y` as a float64 state of shape `(dim,)` (shapes are static, so this also works on
    traced values; `step` takes one state, `rollout` takes many)."""
    y = as_state(y, "y", dim)
    if y.shape != (dim,):
        raise ValueError(
            f"step takes one state of shape ({dim},); got shape {y.shape} (use rollout, or "
            "jax.vmap(map.step), for many)"
        )
    return y


def traced_h(step_map: AbstractStepMap) -> AbstractStepMap:
    """`step_map` with `h` as a 0-d float64 array, so that `eqx.filter_jit` traces it instead
    of baking it in: one compiled rollout (or defect) serves every step size of a map (a sweep
    over h compiles once per map and shape, not once per h)."""
    return eqx.tree_at(lambda m: m.h, step_map, jnp.asarray(step_map.h, dtype=jnp.float64))


#: The most states one compiled piece of a rollout saves: a rollout of any length runs the same
#: program as often as it needs (one compilation for every `n_steps`); the last piece stops at
#: the states asked for.
ROLLOUT_CHUNK = 128
#: The most bytes one piece's saved states take (many trajectories of a large system: fewer
#: states a piece).
CHUNK_BYTES = 2**26


def chunk_size(n_traj: int, width: int) -> int:
    """The states one piece of a rollout saves: `ROLLOUT_CHUNK`, or the largest power of two
    whose `(size, n_traj, width)` float64 states fit in `CHUNK_BYTES` (at least 1). Depends on
    the shape only, never on `n_steps`."""
    fits = CHUNK_BYTES // (8 * max(1, n_traj * width))
    return max(1, min(ROLLOUT_CHUNK, 1 << (fits.bit_length() - 1) if fits else 1))


def _traced_count(n: int) -> np.ndarray:
    """`n` as a 0-d integer array: traced by `eqx.filter_jit`, not a constant of the program."""
    return np.asarray(n, dtype=np.int32 if n < 2**31 else np.int64)


def _in_chunks(run: Callable[[Any, np.ndarray], tuple[Any, tuple[jax.Array, ...]]], carry: Any,
               firsts: tuple[np.ndarray, ...], n_saved: int, chunk: int) -> tuple[np.ndarray, ...]:
    """`(N, n_saved + 1, ...)` on the host for each of `firsts` `(N, ...)` (entry 0):
    `run(carry, count)` advances the carried state by `count` <= `chunk` saved states and
    returns them, `(chunk, N, ...)` of which the first `count` are meant. Each piece is
    dispatched before the previous one is copied out, so the pieces run back to back."""
    outs: list[np.ndarray] = []
    pending = None
    done = 0
    while done < n_saved or pending is not None:
        piece = None
        if done < n_saved:
            count = min(chunk, n_saved - done)
            carry, saved = run(carry, _traced_count(count))
            piece, done = (done, count, saved), done + count
        if pending is not None:
            start, count, saved = pending
            if not outs:
                outs = [np.empty((f.shape[0], n_saved + 1, *f.shape[1:]), dtype=np.result_type(f, s.dtype))
                        for f, s in zip(firsts, saved, strict=True)]
            for out, s in zip(outs, saved, strict=True):
                out[:, start + 1 : start + 1 + count] = np.swapaxes(np.asarray(s)[:count], 0, 1)
        pending = piece
    if not outs:  # n_saved = 0
        return tuple(np.array(f[:, None]) for f in firsts)
    for out, f in zip(outs, firsts, strict=True):
        out[:, 0] = f
    return tuple(outs)


def _saved_states(advance: Callable[[Any], Any], save: Callable[[Any], Any], c: Any, count: jax.Array,
                  save_every: jax.Array, chunk: int) -> tuple[Any, Any]:
    """`count` times: `save_every` times `advance`, then `save`; returns the carried state and
    the saved ones, `(chunk, ...)` (the first `count` written). `count` and `save_every` are
    traced: one program for every length and spacing."""
    shapes = jax.eval_shape(save, c)
    buffers = jax.tree_util.tree_map(lambda s: jnp.zeros((chunk, *s.shape), s.dtype), shapes)

    def body(k, state):
        c, saved = state
        c = jax.lax.fori_loop(0, save_every, lambda _, z: advance(z), c)
        return c, jax.tree_util.tree_map(lambda b, x: b.at[k].set(x), saved, save(c))

    return jax.lax.fori_loop(0, count, body, (c, buffers))


@eqx.filter_jit
def _carry_compiled(step_map: AbstractStepMap, y0: jax.Array) -> Any:
    """`y0` `(N, dim)` as the map carries it between steps."""
    return vmap_samples(step_map.carry)(y0)


@eqx.filter_jit
def _rollout_chunk(step_map: AbstractStepMap, c: Any, count: jax.Array, save_every: jax.Array,
                   chunk: int) -> tuple[Any, tuple[jax.Array]]:
    """The carried states `(N, ...)` advanced by `count * save_every` steps, and the states
    `(chunk, N, dim)` after every `save_every`-th step (the first `count`)."""
    step = vmap_samples(step_map.step_carry)
    uncarry = vmap_samples(step_map.uncarry)
    return _saved_states(step, lambda c: (uncarry(c),), c, count, save_every, chunk)


@eqx.filter_jit
def _lifted_rollout_chunk(step_map: AbstractReconstructingStepMap, gy: tuple[jax.Array, jax.Array],
                          count: jax.Array, save_every: jax.Array, chunk: int
                          ) -> tuple[tuple[jax.Array, jax.Array], tuple[jax.Array, jax.Array]]:
    """`_rollout_chunk` of `lifted_step` on configurations `(N, group.size)` and states
    `(N, dim)`."""
    step = jax.vmap(step_map.lifted_step)
    return _saved_states(lambda gy: step(*gy), lambda gy: gy, gy, count, save_every, chunk)


@eqx.filter_jit
def _defect_compiled(step_map: AbstractStepMap, y: jax.Array) -> jax.Array:
    """`y` `(N, dim)` -> `(N,)`."""

    def step_and_image(x):
        z = step_map.step(x)
        return z, z

    def one(x):
        J, z = jax.jacfwd(step_and_image, has_aux=True)(x)  # the step once, not twice
        B0 = step_map.system.poisson_tensor(x)
        B1 = step_map.system.poisson_tensor(z)
        return jnp.max(jnp.abs(J @ B0 @ J.T - B1))

    return vmap_samples(one)(y)
