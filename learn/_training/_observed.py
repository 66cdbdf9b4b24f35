r"""Learning from observations (`integrators.Observations`): noisy states at uneven times.

A map is compared with the observations by rolling it out over segments of consecutive
observations, each interval $\Delta t$ run at the map's step $\Delta t$ (or in equal sub-steps of
at most `max_step`), so the step size is an input of every step. The loss is the mean squared
difference between the rolled-out and the observed states over every observation of every
segment.

Errors in variables (`latent=True`): the start of each segment is a fitted variable (the clean
state that the noisy first observation measures), fitted jointly with the map. A map that keeps
the Casimirs then moves on the leaf of its fitted start: the observations need not agree on
their Casimirs, and each trajectory's leaf is estimated from all its observations at once.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np

from integrators import Observations
from liepoisson.internals import positive_float, positive_int

#: A trajectory whose observations' Casimirs spread (standard deviation) by more than this
#: fraction of their scale |grad C| |y| fits no common leaf: the noise is of the order of the
#: state (or the trajectory mixes motions). Noise of relative size s spreads them by about s.
LEAF_SPREAD_MAX = 0.1


@dataclasses.dataclass(frozen=True)
class TrajectoryLoss:
    r"""How `learn.fit` compares a map with `integrators.Observations`.

    - `window`: intervals per segment (the map is rolled out `window` observations ahead from
      each segment's start; segments tile each trajectory); `None`: whole trajectories.
    - `latent`: errors in variables: each segment's start is fitted with the map (the clean
      state behind its first observation). `False`: segments start from their first
      observation as measured (its noise then enters every prediction of the segment).
    - `max_step`: each interval is run in $n$ equal steps, $n$ the smallest making every step
      $\le$ `max_step` (for the largest interval of the data); `None`: one step per interval.

    `TrajectoryLoss(window=1, latent=False)` is the one-step loss on consecutive pairs, each
    with its own $\Delta t$.
    """

    window: int | None = None
    latent: bool = True
    max_step: float | None = None

    def __post_init__(self):
        if self.window is not None:
            positive_int(self.window, "TrajectoryLoss.window")
        if not isinstance(self.latent, (bool, np.bool_)):
            raise TypeError(f"TrajectoryLoss.latent must be True or False; got {self.latent!r}")
        if self.max_step is not None:
            positive_float(self.max_step, "TrajectoryLoss.max_step")

    @property
    def name(self) -> str:
        window = "trajectory" if self.window is None else f"window {self.window}"
        return f"{window}, {'latent starts' if self.latent else 'observed starts'}"


class Segments(eqx.Module):
    """Observations cut into padded segments: `index` `(S,)` (the segment's row of fitted
    starts, -1 for a held-out one), `dt` `(S, L-1)`, `mask` `(S, L)` (observation present),
    `states` `(S, L, dim)`; `substeps` steps per interval."""

    index: jax.Array
    dt: jax.Array
    mask: jax.Array
    states: jax.Array
    substeps: int = eqx.field(static=True)


def check_leaves(observations: Observations, what: str = "observations") -> None:
    """Refuse trajectories whose observations fit no common Casimir leaf (see
    `LEAF_SPREAD_MAX`), naming the first."""
    system = observations.system
    if not system.n_casimirs:
        return
    for j, y in enumerate(observations.states):
        c = np.asarray(system.casimirs(y)).reshape(y.shape[0], -1)
        g = np.asarray(system.casimir_gradients(y)).reshape(y.shape[0], -1, y.shape[1])
        scale = np.mean(np.linalg.norm(g, axis=-1) * np.linalg.norm(y, axis=-1)[:, None], axis=0)
        spread = np.std(c, axis=0) / np.maximum(scale, np.finfo(float).tiny)
        if np.any(spread > LEAF_SPREAD_MAX):
            i = int(np.argmax(spread))
            raise ValueError(
                f"{what}: the observations of trajectory {j} spread over Casimir {i} by {spread[i]:.2g} of its scale "
                f"|grad C| |y| (more than {LEAF_SPREAD_MAX}): no common leaf fits them. The noise is of the size of "
                "the states, or the trajectory mixes several motions; check the data"
            )


def segments(observations: Observations, loss: TrajectoryLoss, substeps: int, held_out: bool = False) -> Segments:
    """Cut every trajectory into segments of `loss.window` intervals (padded to the longest)."""
    pieces = []
    for t, y in zip(observations.times, observations.states):
        n = t.size - 1
        w = n if loss.window is None else loss.window
        for start in range(0, n, w):
            stop = min(start + w, n)
            pieces.append((np.diff(t[start : stop + 1]), y[start : stop + 1]))
    length = max(p[1].shape[0] for p in pieces)
    dim = observations.dim
    fill = float(np.median(np.concatenate([p[0] for p in pieces])))  # a harmless step for padding
    dt = np.full((len(pieces), length - 1), fill)
    mask = np.zeros((len(pieces), length))
    states = np.zeros((len(pieces), length, dim))
    for s, (d, y) in enumerate(pieces):
        dt[s, : d.size] = d
        mask[s, : y.shape[0]] = 1.0
        states[s, : y.shape[0]] = y
        states[s, y.shape[0] :] = y[-1]
    index = np.full(len(pieces), -1) if held_out else np.arange(len(pieces))
    return Segments(jnp.asarray(index), jnp.asarray(dt), jnp.asarray(mask), jnp.asarray(states), substeps)


def substeps_for(observations: Observations, max_step: float | None) -> int:
    if max_step is None:
        return 1
    return max(1, math.ceil(float(np.max(observations.intervals()[2])) / max_step - 1e-12))


class Fitted(eqx.Module):
    """What the observation loss optimises: the map and, with errors in variables, the fitted
    start of every training segment `(S, dim)`."""

    model: Any
    starts: jax.Array | None

    @property
    def system(self):
        return self.model.system

    def hyperparameters(self):
        return self.model.hyperparameters()

    def reinitialised(self, key):
        return Fitted(self.model.reinitialised(key), self.starts)

    def warm_start(self):
        warm = self.model.warm_start()
        if warm is None:
            return None
        simpler, mapped = warm

        def to_this(fitted: Fitted, inputs: jax.Array) -> Fitted:
            # the map's warm start is mapped with the observed states, which `inputs` carries
            _, _, mask, states = unpack(inputs, self.model.system.dim)
            present = np.asarray(mask).reshape(-1) > 0
            return Fitted(mapped(fitted.model, states.reshape(-1, states.shape[-1])[present]), fitted.starts)

        return Fitted(simpler, self.starts), to_this


def advance(model: Any, y: jax.Array, dt: jax.Array, substeps: int) -> jax.Array:
    r"""$y$ carried over the time `dt` by `substeps` steps of the map at step `dt / substeps`."""
    m = eqx.tree_at(lambda m: m.h, model, dt / substeps, is_leaf=lambda v: v is None)
    if substeps == 1:
        return m.step(y)
    return jax.lax.fori_loop(0, substeps, lambda _, z: m.step(z), y)


def segment_predictions(model: Any, start: jax.Array, dt: jax.Array, mask: jax.Array, substeps: int) -> jax.Array:
    """The states `(L, dim)` of one segment rolled out from `start` over its intervals `dt`
    (padded intervals, `mask` 0, repeat the last state)."""

    def body(y, inputs):
        d, present = inputs
        y = jnp.where(present > 0, advance(model, y, d, substeps), y)
        return y, y

    _, ys = jax.lax.scan(body, start, (dt, mask[1:]))
    return jnp.concatenate([start[None], ys])


@dataclasses.dataclass(frozen=True)
class ObservationLoss:
    """`loss(fitted, inputs, targets)`: the mean squared difference over every present
    observation of the segments packed in `inputs` (`pack`), `targets` their observed states
    `(S, L, dim)`."""

    substeps: int

    def __call__(self, fitted: Fitted, inputs: jax.Array, targets: jax.Array) -> jax.Array:
        squared, mask = self.squared(fitted, inputs, targets)
        return jnp.sum(squared) / (jnp.sum(mask) * targets.shape[-1])

    def count(self, fitted: Fitted, inputs: jax.Array, targets: jax.Array) -> int:
        """How many residual components the loss averages: the present observations that are
        predictions (a start taken as observed is not), times the dimension."""
        index, _, mask, _ = unpack(jnp.asarray(inputs), targets.shape[-1])
        observed = np.ones(index.shape, bool) if fitted.starts is None else np.asarray(index) < 0
        present = np.asarray(mask).copy()
        present[:, 0] = np.where(observed, 0.0, present[:, 0])
        return round(float(np.sum(present))) * targets.shape[-1]

    def residuals(self, fitted: Fitted, inputs: jax.Array, targets: jax.Array) -> jax.Array:
        """Predicted minus observed states, every component of every segment `(S, L, dim)`,
        zero where no observation is."""
        return self.squared(fitted, inputs, targets, residuals=True)

    def jacobian(self, fitted: Fitted, inputs: jax.Array, targets: jax.Array) -> tuple[jax.Array, jax.Array]:
        r"""`(residuals (n,), Jacobian (n, p + S d))` with respect to the flat trainable leaves
        of `fitted` (the map's $p$ weights, then its $S$ starts of dimension $d$), built from
        its blocks: segment $s$ depends on the weights and on its own start only (training
        segments: `index` is their row), so $p + d$ forward passes (the same $d$ directions
        pushed into every start at once) instead of $p + Sd$ (`learn.LevenbergMarquardt`).
        Each start belongs to one segment, as `observed_objective` builds them."""
        params, static = eqx.partition(fitted.model, eqx.is_inexact_array)
        flat, unravel = jax.flatten_util.ravel_pytree(params)

        def residuals(w, s):
            return self.residuals(Fitted(eqx.combine(unravel(w), static), s), inputs, targets)

        r = residuals(flat, fitted.starts)
        by_weight = jax.jacfwd(residuals)(flat, fitted.starts)  # (S, L, dim, p)
        n_seg, dim = fitted.starts.shape

        def push(direction):
            return jax.jvp(lambda s: residuals(flat, s), (fitted.starts,), (jnp.broadcast_to(direction, (n_seg, dim)),))[1]

        by_start = jax.vmap(push, out_axes=-1)(jnp.eye(dim, dtype=flat.dtype))  # (S, L, dim, d)
        # segment s moves with the start of its row `index[s]` (none for a held-out one, -1)
        index = unpack(jnp.asarray(inputs), dim)[0].astype(jnp.int32)
        rows_of = jax.nn.one_hot(index, n_seg, dtype=flat.dtype)  # (S, n_starts), zero row for -1
        blocks = by_start[:, :, :, None, :] * rows_of[:, None, None, :, None]
        rows = r.size
        return r.reshape(-1), jnp.concatenate([by_weight.reshape(rows, -1), blocks.reshape(rows, -1)], axis=1)

    def squared(self, fitted: Fitted, inputs: jax.Array, targets: jax.Array, residuals: bool = False):
        """`(squared differences (S, L), mask (S, L))`, or the differences `(S, L, dim)`."""
        inputs, targets = jnp.asarray(inputs), jnp.asarray(targets)
        index, dt, mask, _ = unpack(inputs, targets.shape[-1])
        index = index.astype(jnp.int32)
        if fitted.starts is None:
            observed = jnp.ones(index.shape, bool)
            start = targets[:, 0]
        else:
            observed = index < 0
            start = jnp.where(observed[:, None], targets[:, 0], fitted.starts[jnp.clip(index, 0)])
        predicted = jax.vmap(segment_predictions, in_axes=(None, 0, 0, 0, None))(
            fitted.model, start, dt, mask, self.substeps)
        # a start taken as observed is not a prediction: it is left out of the mean
        mask = mask.at[:, 0].set(jnp.where(observed, 0.0, mask[:, 0]))
        difference = (predicted - targets) * mask[..., None]
        if residuals:
            return difference
        return jnp.sum(difference**2, axis=-1), mask


def unpack(inputs: jax.Array, dim: int) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array]:
    """`(index (S,), dt (S, L-1), mask (S, L), states (S, L, dim))` from `pack`'s inputs."""
    length = inputs.shape[1] // (dim + 2)
    return (inputs[:, 0], inputs[:, 1:length], inputs[:, length : 2 * length],
            inputs[:, 2 * length :].reshape(inputs.shape[0], length, dim))


def pack(seg: Segments) -> tuple[np.ndarray, np.ndarray]:
    """`(inputs, targets)` arrays of the segments for the optimisers (samples on axis 0):
    inputs `[index, dt (L-1), mask (L), states (L dim)]` per segment (the states for a warm
    start's mapping), targets the states `(S, L, dim)`."""
    states = np.asarray(seg.states)
    inputs = np.concatenate([np.asarray(seg.index, dtype=np.float64)[:, None], np.asarray(seg.dt),
                             np.asarray(seg.mask), states.reshape(states.shape[0], -1)], axis=1)
    return inputs, states


def observed_objective(model: Any, observations: Observations, loss: Any, h: float | None,
                       validation_fraction: float, seed: int):
    """`(fitted, (inputs, targets), (inputs_val, targets_val), loss_fn, settings)` for
    `learn.fit` on observations: training and held-out trajectories cut into segments; the
    map's `h` set (given `h`, its own, or the median interval of the data)."""
    if loss is None:
        loss = TrajectoryLoss()
    elif loss == "state":
        loss = TrajectoryLoss(window=1, latent=False)
    if not isinstance(loss, TrajectoryLoss):
        raise TypeError(f"with observations, loss must be a learn.TrajectoryLoss (or 'state', the one-step loss); "
                        f"got {loss!r}")
    if observations.system.dim != model.system.dim:
        raise ValueError(f"data has states of dimension {observations.system.dim} ({observations.system!r}); the "
                         f"model is for {model.system!r} (dimension {model.system.dim})")
    if model.conserves_casimirs:
        check_leaves(observations, "data")
    train, val = observations.split(validation_fraction, seed)
    substeps = substeps_for(observations, loss.max_step)
    dt = observations.intervals()[2]
    if h is not None:
        h = positive_float(h, "h")
    elif model.h is not None:
        h = float(model.h)
    else:
        h = float(np.median(dt))
    model = eqx.tree_at(lambda m: m.h, model, h, is_leaf=lambda v: v is None)
    seg = segments(train, loss, substeps)
    inputs, targets = pack(seg)
    if val is None:
        val_inputs, val_targets = np.zeros((0, inputs.shape[1])), np.zeros((0, *targets.shape[1:]))
    else:
        val_inputs, val_targets = pack(segments(val, loss, substeps, held_out=True))
    fitted = Fitted(model, jnp.asarray(targets[:, 0]) if loss.latent else None)
    settings = {
        "validation_fraction": float(validation_fraction), "seed": int(seed), "loss": loss.name,
        "max_step": loss.max_step, "substeps": substeps, "h": h,
        "n_train": int(train.n_observations), "n_val": 0 if val is None else int(val.n_observations),
    }
    return fitted, (inputs, targets), (val_inputs, val_targets), ObservationLoss(substeps), settings


def information_criterion(fitted: Fitted, loss_fn: ObservationLoss, inputs: np.ndarray, targets: np.ndarray
                          ) -> dict[str, float]:
    r"""The Bayesian information criterion of a map fitted to observations,
    $n\log(\mathrm{SSR}/n) + k\log n$: $n$ observed components, SSR the sum of squared
    residuals, $k$ the map's effective parameters (the numerical rank of the residuals'
    Jacobian with respect to its weights: redundant weights count once; the fitted starts,
    common to the maps compared, are left out). Lower is better."""
    inputs, targets = jnp.asarray(inputs), jnp.asarray(targets)
    params, static = eqx.partition(fitted.model, eqx.is_inexact_array)
    flat, unravel = jax.flatten_util.ravel_pytree(params)

    def residuals(x):
        model = eqx.combine(unravel(x), static)
        return loss_fn.residuals(Fitted(model, fitted.starts), inputs, targets).reshape(-1)

    r = residuals(flat)
    J = np.asarray(jax.jacfwd(residuals)(flat))
    n = int(np.sum(loss_fn.squared(fitted, inputs, targets)[1])) * targets.shape[-1]  # fitted components
    ssr = float(jnp.sum(r**2))
    singular = np.linalg.svd(J, compute_uv=False)
    # A direction of the weights that moves the residuals 1e8 times less than the best
    # determined one is not fitted by the data (redundant weights give 0 to round-off).
    k = int(np.sum(singular > 1e-8 * singular[0])) if singular.size else 0
    return {"bic": n * math.log(ssr / n) + k * math.log(n), "n": n, "ssr": ssr, "effective_parameters": k}
