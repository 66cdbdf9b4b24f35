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
from liepoisson import vmap_samples
from liepoisson.internals import casimir_scale, positive_float, positive_int

from .._models._base import AbstractCasimirConservingMap
from .._models._baseline import check_one_step
from .._solvers._compiled import compiled as _compiled
from .._solvers._levenberg_marquardt import check_size, residuals_of
from .._solvers._problem import AbstractLeastSquares, AbstractStructuredJacobian
from .._solvers._stage import Linearisation
from ._criterion import bic, effective_parameters
from ._losses import AbstractLoss
from ._problem import Description, Fitted, FittedProblem

#: A trajectory whose observations' Casimirs spread (standard deviation) by more than this
#: fraction of their scale |grad C| |y| fits no common leaf: the noise is of the order of the
#: state (or the trajectory mixes motions). Noise of relative size s spreads them by about s.
LEAF_SPREAD_MAX = 0.1


class TrajectoryLoss(AbstractLoss):
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

    window: int | None = eqx.field(static=True, default=None)
    latent: bool = eqx.field(static=True, default=True)
    max_step: float | None = eqx.field(static=True, default=None)

    def __check_init__(self):
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

    def problem(self, model, data: Observations, *, h, validation_fraction, seed, normalise) -> FittedProblem:
        """Training and held-out trajectories cut into segments; the map's `h` set (given `h`,
        its own, or the median interval of the data)."""
        if normalise:
            raise ValueError("normalise=True sets an MLP's scalings from pairs at one step; with observations, "
                             "build the map with its scalings (input_scaling=, output_scaling=) instead")
        if not isinstance(data, Observations):
            raise TypeError(f"learn.TrajectoryLoss compares a map with integrators.Observations; got "
                            f"{type(data).__name__} (pairs and Trajectories are fitted with the state loss)")
        if data.system.dim != model.system.dim:
            raise ValueError(f"data has states of dimension {data.system.dim} ({data.system!r}); the "
                             f"model is for {model.system!r} (dimension {model.system.dim})")
        data.check_system(model.system, "the model's system")  # the same bracket and Casimirs
        if isinstance(model, AbstractCasimirConservingMap):
            check_leaves(data, "data")
        model.check_data(np.concatenate(data.states), "data")
        train, val = data.split(validation_fraction, seed)
        substeps = substeps_for(data, self.max_step)
        if h is not None:
            h = positive_float(h, "h")
        elif model.h is not None:
            h = float(model.h)
        else:
            h = float(np.median(data.intervals()))
        check_one_step(model, data.intervals() / substeps, h if model.h is None else None, "data")
        # No step while fitting (each interval sets its own), so that data in other units
        # reuse what was compiled; `FittedProblem.map` gives the fitted map `h`.
        model = eqx.tree_at(lambda m: m.h, model, None, is_leaf=lambda v: v is None)
        seg = segments(train, self, substeps)
        held_out = None if val is None else segments(val, self, substeps, held_out=True)
        y0 = Fitted(model, seg.states[:, 0] if self.latent else None)
        description = Description(
            loss=f"observations: {self.name}", h=h, n_train=int(train.n_observations),
            n_val=0 if val is None else int(val.n_observations), seed=int(seed),
            validation_fraction=float(validation_fraction), max_step=self.max_step, substeps=substeps)
        return FittedProblem(SegmentsObjective(), y0, seg, held_out, description)


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
        scale = np.mean(casimir_scale(g, y), axis=0)
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
    return Segments(jnp.asarray(index, dtype=jnp.int32), jnp.asarray(dt), jnp.asarray(mask), jnp.asarray(states),
                    substeps)


def substeps_for(observations: Observations, max_step: float | None) -> int:
    if max_step is None:
        return 1
    return max(1, math.ceil(float(np.max(observations.intervals())) / max_step - 1e-12))


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


class SegmentsObjective(AbstractStructuredJacobian):
    """`f(fitted, segments)`: the mean squared difference over every present observation of the
    segments (a `Segments`) between the map rolled out from each segment's start (fitted, or
    observed) and the observed states."""

    def __call__(self, fitted: Fitted, args: Segments) -> jax.Array:
        squared, mask = self._squared(fitted, args)
        return jnp.sum(squared) / (jnp.sum(mask) * args.states.shape[-1])

    def count(self, fitted: Fitted, args: Segments) -> int:
        """How many residual components the loss averages: the present observations that are
        predictions (a start taken as observed is not), times the dimension."""
        observed = np.ones(args.index.shape, bool) if fitted.starts is None else np.asarray(args.index) < 0
        present = np.asarray(args.mask).copy()
        present[:, 0] = np.where(observed, 0.0, present[:, 0])
        return round(float(np.sum(present))) * args.states.shape[-1]

    def residuals(self, fitted: Fitted, args: Segments) -> jax.Array:
        """Predicted minus observed states, every component of every segment `(S, L, dim)`,
        zero where no observation is."""
        return self._differences(fitted, args)[0]

    def forward_passes(self, fitted: Fitted) -> int:
        """The map's weights and one pass per state direction (not per fitted start)."""
        weights = sum(a.size for a in jax.tree_util.tree_leaves(eqx.filter(fitted.model, eqx.is_inexact_array)))
        shared = 0 if fitted.shared is None else fitted.shared.size
        return int(weights + shared + (0 if fitted.starts is None else fitted.starts.shape[-1]))

    def jacobian(self, fitted: Fitted, args: Segments) -> tuple[jax.Array, jax.Array]:
        r"""`(residuals (n,), Jacobian (n, p + S d))` with respect to the flat trainable leaves
        of `fitted` (the map's $p$ weights, then its $S$ starts of dimension $d$), built from
        its blocks: segment $s$ depends on the weights and on its own start only (training
        segments: `index` is their row), so $p + d$ forward passes (the same $d$ directions
        pushed into every start at once) instead of $p + Sd$. Each start belongs to one
        segment, as `TrajectoryLoss.problem` builds them; without fitted starts, `jax.jacfwd`.
        Unknowns the segments share (`Fitted.shared`, $q$ of them) are the last columns,
        pushed like the weights."""
        if fitted.starts is None:
            return AbstractLeastSquares.jacobian(self, fitted, args)
        r, by_weight, by_start, rows_of = self._blocks(fitted, args)
        rows, p = r.size, self._n_weights(fitted)
        blocks = by_start[:, :, :, None, :] * rows_of[:, None, None, :, None]
        dense = by_weight.reshape(rows, -1)
        return r.reshape(-1), jnp.concatenate([dense[:, :p], blocks.reshape(rows, -1), dense[:, p:]], axis=1)

    def normal_equations(self, fitted: Fitted, args: Segments) -> tuple[jax.Array, jax.Array, jax.Array]:
        r"""`(r (n,), A, g)` of the unknowns of `jacobian` (weights $w$, then starts): with the
        weight block $J_w$ and each segment's start block $J_s$, $A_{ww} = J_w^TJ_w$,
        $A_{ws} = J_w^TJ_s$ per start, $A_{ss}$ block-diagonal ($d\times d$ per start),
        $g = (J_w^Tr, J_s^Tr_s)$: $n(p + d)$ numbers where $J$ has $n(p + Sd)$. Shared
        unknowns (`Fitted.shared`) are dense like the weights, and last, as in `jacobian`."""
        if fitted.starts is None:
            r, J = AbstractLeastSquares.jacobian(self, fitted, args)
            return r, J.T @ J, J.T @ r
        r, by_weight, by_start, rows_of = self._blocks(fitted, args)
        n_seg, n_starts, dim = r.shape[0], rows_of.shape[1], by_start.shape[-1]
        Jw = by_weight.reshape(n_seg, -1, by_weight.shape[-1])  # (S, m, p)
        Js = by_start.reshape(n_seg, -1, dim)  # (S, m, d)
        rs = r.reshape(n_seg, -1)
        p = Jw.shape[-1]
        A_ww = jnp.einsum("smp,smq->pq", Jw, Jw)
        A_ws = jnp.einsum("smp,smd,sj->pjd", Jw, Js, rows_of).reshape(p, n_starts * dim)
        diagonal = jnp.einsum("smd,sme,sj->jde", Js, Js, rows_of)  # (S starts, d, d)
        A_ss = (jnp.eye(n_starts, dtype=r.dtype)[:, None, :, None] * diagonal[:, :, None, :]).reshape(
            n_starts * dim, n_starts * dim)
        A = jnp.block([[A_ww, A_ws], [A_ws.T, A_ss]])
        g = jnp.concatenate([jnp.einsum("smp,sm->p", Jw, rs), jnp.einsum("smd,sm,sj->jd", Js, rs, rows_of).reshape(-1)])
        weights = self._n_weights(fitted)
        if weights < p:  # shared unknowns after the weights in the blocks: last among the unknowns
            order = jnp.concatenate([jnp.arange(weights), p + jnp.arange(n_starts * dim), jnp.arange(weights, p)])
            A, g = A[order][:, order], g[order]
        return r.reshape(-1), A, g

    def block_entries(self, fitted: Fitted, args: Segments) -> int:
        """The blocks' numbers ($n(p + d)$, one column per forward pass) and $A$'s; without
        fitted starts, the whole Jacobian's (no blocks to save)."""
        if fitted.starts is None:
            return AbstractStructuredJacobian.block_entries(self, fitted, args)
        n = math.prod(jax.eval_shape(lambda: self.residuals(fitted, args)).shape)
        unknowns = sum(a.size for a in jax.tree_util.tree_leaves(eqx.filter(fitted, eqx.is_inexact_array)))
        return n * self.forward_passes(fitted) + unknowns**2

    def weight_jacobian(self, fitted: Fitted, args: Segments) -> tuple[jax.Array, jax.Array]:
        """`(r (n,), J_w (n, p))`: the residuals and their Jacobian with respect to the map's
        weights alone (the starts held)."""
        r, by_weight, _, _ = self._blocks(fitted, args)
        return r.reshape(-1), by_weight.reshape(r.size, -1)[:, : self._n_weights(fitted)]

    @staticmethod
    def _n_weights(fitted: Fitted) -> int:
        """The map's trainable numbers $p$ (the shared unknowns not counted)."""
        return sum(a.size for a in jax.tree_util.tree_leaves(eqx.filter(fitted.model, eqx.is_inexact_array)))

    def _blocks(self, fitted: Fitted, args: Any) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array]:
        """`(r (S, ...), by weight (S, ..., p), by start (S, ..., d), rows_of (S, S starts))`:
        the residuals, their derivatives along each weight (then each shared unknown) and along
        each direction of the segment's own start, and which start each segment moves with (a
        zero row for a held-out segment, `index` -1)."""
        params, static = eqx.partition((fitted.model, fitted.shared), eqx.is_inexact_array)
        flat, unravel = jax.flatten_util.ravel_pytree(params)

        def residuals(w, s):
            model, shared = eqx.combine(unravel(w), static)
            return self.residuals(Fitted(model, s, shared), args)

        def with_value(w, s):
            value = residuals(w, s)
            return value, value

        # the residuals from the weight Jacobian's own forward pass (one evaluation fewer; see
        # `AbstractLeastSquares.jacobian` for the deadlock two concurrent ones caused)
        by_weight, r = jax.jacfwd(with_value, has_aux=True)(flat, fitted.starts)  # (S, ..., p)
        n_seg, dim = fitted.starts.shape

        def push(direction):
            return jax.jvp(lambda s: residuals(flat, s), (fitted.starts,), (jnp.broadcast_to(direction, (n_seg, dim)),))[1]

        by_start = jax.vmap(push, out_axes=-1)(jnp.eye(dim, dtype=flat.dtype))  # (S, ..., d)
        # segment s moves with the start of its row `index[s]` (none for a held-out one, -1)
        rows_of = jax.nn.one_hot(args.index.astype(jnp.int32), n_seg, dtype=flat.dtype)  # zero row for -1
        return r, by_weight, by_start, rows_of

    def _differences(self, fitted: Fitted, args: Segments) -> tuple[jax.Array, jax.Array]:
        """`(differences (S, L, dim), mask (S, L))`: zero where no prediction is compared."""
        index, dt, mask, targets = args.index.astype(jnp.int32), args.dt, args.mask, args.states
        if fitted.starts is None:
            observed = jnp.ones(index.shape, bool)
            start = targets[:, 0]
        else:
            observed = index < 0
            start = jnp.where(observed[:, None], targets[:, 0], fitted.starts[jnp.clip(index, 0)])
        # over the segments as samples: the coadjoint flows take `expm_action`'s paths for the
        # whole batch (Taylor on vectors at a data step), not the matrix exponential of each
        model, substeps = fitted.model, args.substeps
        predicted = vmap_samples(lambda s, d, m: segment_predictions(model, s, d, m, substeps))(start, dt, mask)
        # a start taken as observed is not a prediction: it is left out of the mean
        mask = mask.at[:, 0].set(jnp.where(observed, 0.0, mask[:, 0]))
        return (predicted - targets) * mask[..., None], mask

    def _squared(self, fitted: Fitted, args: Segments) -> tuple[jax.Array, jax.Array]:
        """`(squared differences (S, L), mask (S, L))`."""
        difference, mask = self._differences(fitted, args)
        return jnp.sum(difference**2, axis=-1), mask


def discretisation_ssr(problem: FittedProblem, fitted: Fitted, linearisation: Linearisation | None = None) -> float:
    r"""The sum of squared differences between the map's predictions of the training
    observations at the problem's sub-steps per interval and at twice as many: its own
    discretisation error to leading order (for a method of order $p$, $(1 - 2^{-p})^2$ of its
    sum of squares),
    in the units of the residuals' sum of squares. Exact data fitted to within it are fitted
    as far as the step allows. `linearisation`: the fit's last residuals and Jacobian
    (`Result.linearisation`), read where they are `fitted`'s."""
    objective, args = problem.objective, problem.train
    compiled = residuals_of(objective, fitted)
    x = jax.flatten_util.ravel_pytree(eqx.filter(fitted, eqx.is_inexact_array))[0]
    finer = dataclasses.replace(args, substeps=2 * args.substeps)
    return float(jnp.sum((_residuals(compiled, x, args, linearisation) - compiled.residuals(x, finer)) ** 2))


def residual_ssr(problem: FittedProblem, fitted: Fitted, linearisation: Linearisation | None = None) -> float:
    """The sum of squared residuals of `fitted` on the training observations (compiled, as
    Levenberg-Marquardt evaluates them; `linearisation` as `discretisation_ssr`'s)."""
    compiled = residuals_of(problem.objective, fitted)
    x = jax.flatten_util.ravel_pytree(eqx.filter(fitted, eqx.is_inexact_array))[0]
    return float(jnp.sum(_residuals(compiled, x, problem.train, linearisation) ** 2))


def _residuals(compiled: Any, x: jax.Array, args: Any, linearisation: Linearisation | None) -> jax.Array:
    """The residuals at `x` on `args`: the linearisation's where it is at them, else computed."""
    if linearisation is not None and linearisation.at(x, args):
        return linearisation.residuals
    return compiled.residuals(x, args)


def information_criterion(problem: FittedProblem, fitted: Fitted,
                          linearisation: Linearisation | None = None) -> dict[str, float]:
    r"""The Bayesian information criterion of a map fitted to observations,
    $n\log(\mathrm{SSR}/n) + k\log n$: $n$ observed components, SSR the sum of squared
    residuals, $k$ the map's effective parameters (the numerical rank of the residuals'
    Jacobian with respect to its weights: redundant weights count once; the fitted starts,
    common to the maps compared, are left out). Lower is better. `linearisation`: the fit's
    last residuals and Jacobian (`Result.linearisation`), read where they are `fitted`'s."""
    objective, args = problem.objective, problem.train
    # The residuals and Jacobian compiled for this structure (those Levenberg-Marquardt used):
    # the map's weights are the first columns, the fitted starts the rest.
    compiled = residuals_of(objective, fitted)
    x = jax.flatten_util.ravel_pytree(eqx.filter(fitted, eqx.is_inexact_array))[0]
    weights = jax.flatten_util.ravel_pytree(eqx.filter(fitted.model, eqx.is_inexact_array))[0].size
    if check_size(objective, fitted, args):  # J is not held whole: its weights' block alone
        by_weights = _compiled(("weight jacobian", compiled), lambda: jax.jit(
            lambda z, a: objective.weight_jacobian(compiled.model(z), a)))
        r, J = by_weights(x, args)
    elif linearisation is not None and linearisation.at(x, args):
        r, J = linearisation.residuals, linearisation.jacobian
    else:
        r, J = compiled.jacobian(x, args)
    J = np.asarray(J)[:, :weights]
    n = objective.count(fitted, args)  # fitted components
    ssr = float(jnp.sum(r**2))
    k = effective_parameters(J)
    return {"bic": bic(ssr, n, k), "n": n, "ssr": ssr, "effective_parameters": k}
