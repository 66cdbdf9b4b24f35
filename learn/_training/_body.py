r"""Learning from what instruments measure of a body (`integrators.BodyObservations`):
configurations and body velocities, with the momenta latent.

A G-LPNet's step lifted to the configuration (`GLPNet.lifted_step`) is rolled out over each
trajectory from a fitted start $(g_0\exp(\delta), \mu_0)$; its body velocity is
$\xi = \nabla\widetilde H(\mu)$. The residuals compare the predicted configurations with the
observed ones (`group.difference`: radians for an attitude, positions relative to their RMS
size) and the predicted velocities with the observed ones (relative to their RMS size). The
momenta are never observed: $\mu_0$ of each trajectory is an unknown of the fit, like the
network's weights.

What is identifiable (conventions, [Observations of bodies][conventions-body-observations]):
scaling the momenta and the inverse of $\widetilde H$'s quadratic form together,
$\mu\to c\mu$, $\widetilde H(\mu)\to c\widetilde H(\mu/c)$, changes neither velocities nor
configurations; the fit starts with the inertia $\mathbb M$ ($\mu = \mathbb M\xi$) of trace $n$
and the criterion compares families at that gauge. Unlike from momenta, the part of
$\widetilde H$ along the Casimirs is seen: it moves the configuration.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from integrators import BodyObservations
from liepoisson import vmap_samples
from liepoisson.internals import positive_float, positive_int

from .._models._base import AbstractBodyMap, AbstractLearnedMap
from ._losses import AbstractLoss
from ._observed import SegmentsObjective
from ._problem import Description, Fitted, FittedProblem


class BodySegments(eqx.Module):
    r"""Body observations as a training problem's `args`, one segment per trajectory (padded to
    the longest): `index` `(S,)` (the row of fitted starts), `steps` `(S, N)` the sub-steps
    each trajectory is rolled out by (each interval in `ceil(interval / max_step)` equal ones,
    0 where padded), `at` `(S, L)` the sub-step after which each observation is reached (-1
    for the first), `mask` `(S, L)`, `first` `(S, size)` the first observed configuration (the
    identity without configurations), `configurations` `(S, L, size)`, `velocities`
    `(S, L, dim)`, `weights` `(dim,)` of the configuration residual, `velocity_scale`;
    `measured` which of the two are compared; `substeps`: each sub-step taken in this many
    equal steps (1; 2 for `discretisation_ssr`); `group` `(S,)` the group of each trajectory
    (`BodyObservations.group_index`); `bias`: a gyroscope bias $\beta_g$ `(dim,)` per group
    is fitted (`Fitted.shared`, `(G, dim)`), the velocity read as $\xi + \beta_g$."""

    index: jax.Array
    steps: jax.Array
    at: jax.Array
    mask: jax.Array
    first: jax.Array
    configurations: jax.Array
    velocities: jax.Array
    weights: jax.Array
    velocity_scale: jax.Array
    group: jax.Array
    substeps: int = eqx.field(static=True)
    measured: tuple[str, ...] = eqx.field(static=True)
    bias: bool = eqx.field(static=True, default=False)


def body_segments(data: BodyObservations, max_step: float | None, bias: bool = False) -> BodySegments:
    """Every trajectory of `data` as one segment, each interval in equal sub-steps of at most
    `max_step` (one per interval with `None`); `bias`: a gyroscope bias per group fitted."""
    group, dim = data.group, data.dim
    length = max(t.size for t in data.times)
    S = len(data)
    schedules = [sub_steps(np.diff(t), max_step) for t in data.times]
    n_steps = max(1, max(steps.size for steps, _ in schedules))
    steps = np.zeros((S, n_steps))
    at = np.full((S, length), -1)
    mask = np.zeros((S, length))
    gs = np.tile(group.identity(), (S, length, 1))
    vs = np.zeros((S, length, dim))
    for j, t in enumerate(data.times):
        h, reached = schedules[j]
        steps[j, : h.size] = h
        at[j, 1 : t.size] = reached
        at[j, t.size :] = at[j, t.size - 1]
        mask[j, : t.size] = 1.0
        if data.configurations is not None:
            gs[j, : t.size] = data.configurations[j]
            gs[j, t.size :] = data.configurations[j][-1]
        if data.velocities is not None:
            vs[j, : t.size] = data.velocities[j]
    weights = np.ones(dim)
    position = data.position_scale()
    if position is not None:  # positions relative to their RMS size, as their noise
        weights[3:] = 1.0 / position
    return BodySegments(jnp.arange(S, dtype=jnp.int32), jnp.asarray(steps), jnp.asarray(at, dtype=jnp.int32),
                        jnp.asarray(mask), jnp.asarray(gs[:, 0]), jnp.asarray(gs), jnp.asarray(vs),
                        jnp.asarray(weights), jnp.asarray(data.velocity_scale()),
                        jnp.asarray(data.group_index(), dtype=jnp.int32), 1, data.measured, bool(bias))


def sub_steps(intervals: np.ndarray, max_step: float | None) -> tuple[np.ndarray, np.ndarray]:
    """`(steps, reached)`: each interval in `ceil(interval / max_step)` equal sub-steps (one
    with `None`), one after the other; `reached[k]` the index of the sub-step that ends
    interval `k`. Each interval its own count, not the longest's for every interval."""
    counts = np.ones(intervals.size, dtype=int) if max_step is None else np.maximum(
        1, np.ceil(intervals / max_step - 1e-12).astype(int))
    return np.repeat(intervals / counts, counts), np.cumsum(counts) - 1


def lifted_segment(model, g0: jax.Array, mu0: jax.Array, steps: jax.Array, at: jax.Array,
                   substeps: int = 1) -> tuple[jax.Array, jax.Array]:
    """`(configurations (L, size), momenta (L, dim))` of one segment rolled out by
    `model.lifted_step` from `(g0, mu0)` over its sub-steps `steps` (each in `substeps` equal
    steps; a padded sub-step, 0, keeps the state), read after the sub-steps `at` (-1: the
    start)."""

    def body(gy, h):
        m = eqx.tree_at(lambda m: m.h, model, h / substeps, is_leaf=lambda v: v is None)
        if substeps == 1:
            moved = m.lifted_step(*gy)
        else:
            moved = jax.lax.fori_loop(0, substeps, lambda _, z: m.lifted_step(*z), gy)
        gy = jax.tree_util.tree_map(lambda new, old: jnp.where(h > 0, new, old), moved, gy)
        return gy, gy

    _, (gs, ys) = jax.lax.scan(body, (g0, mu0), steps)
    return jnp.concatenate([g0[None], gs])[at + 1], jnp.concatenate([mu0[None], ys])[at + 1]


class BodyObjective(SegmentsObjective):
    r"""The mean squared residual over every observation of every trajectory: configuration
    (`group.difference` of observed and predicted, weighted) and velocity ($\nabla\widetilde H(\mu)$
    less the observed, over its RMS size), as measured. The fitted starts are $(\mu_0, \delta)$
    per trajectory, $g_0 = g_\text{obs}(t_0)\exp(\delta)$ ($\mu_0$ alone without configurations);
    the Jacobian's blocks are `SegmentsObjective`'s (each trajectory depends on its own start)."""

    def __call__(self, fitted: Fitted, args: BodySegments) -> jax.Array:
        r = self.residuals(fitted, args)
        per = args.velocities.shape[-1] * len(args.measured)
        return jnp.sum(r**2) / (jnp.sum(args.mask) * per)

    def count(self, fitted: Fitted, args: BodySegments) -> int:
        """Every present observation times the components compared."""
        per = args.velocities.shape[-1] * len(args.measured)
        return round(float(np.sum(np.asarray(args.mask)))) * per

    def residuals(self, fitted: Fitted, args: BodySegments) -> jax.Array:
        """`(S, L, k)`: configuration then velocity residuals, zero where nothing is observed."""
        model = fitted.model
        group = model.system.require_group()
        dim = args.velocities.shape[-1]
        mu0 = fitted.starts[:, :dim]
        has_g = "configurations" in args.measured
        g0 = group.right_exp(args.first, fitted.starts[:, dim : 2 * dim]) if has_g else args.first
        substeps = args.substeps  # over the segments as samples (see `SegmentsObjective`)
        gs, mus = vmap_samples(lambda g, m, steps, at: lifted_segment(model, g, m, steps, at, substeps))(
            g0, mu0, args.steps, args.at)
        parts = []
        if has_g:
            parts.append(group.difference(args.configurations, gs) * args.weights)
        if "velocities" in args.measured:
            xi = jax.vmap(jax.vmap(model.body_velocity))(mus)
            if args.bias:  # the gyroscope reads xi + beta, one beta per group of trajectories
                xi = xi + fitted.shared[args.group][:, None, :]
            parts.append((xi - args.velocities) / args.velocity_scale)
        return jnp.concatenate(parts, axis=-1) * args.mask[..., None]


class BodyLoss(AbstractLoss):
    r"""How `learn.fit` compares a G-LPNet with `integrators.BodyObservations`: whole
    trajectories rolled out by its lifted step from fitted starts $(g_0\exp(\delta), \mu_0)$
    (`BodyObjective`). `max_step`: each interval in the fewest equal steps of at most this,
    counted per interval (`sub_steps`; `None`: one step per interval); `TrajectoryLoss` takes
    the largest interval's count for every interval. No held-out trajectories: their momenta
    would be unknowns too (the information criterion chooses between families,
    `learn.fit_splitting`). `bias`: the gyroscope reads $\xi + \beta_g$, one unknown bias
    $\beta_g$ per group of trajectories (`BodyObservations.groups`, e.g. a recording session;
    each trajectory its own without groups), fitted with the map and the starts and kept on
    the record (`learn.gyro_bias`)."""

    max_step: float | None = eqx.field(static=True, default=None)
    bias: bool = eqx.field(static=True, default=False)

    def __check_init__(self):
        if self.max_step is not None:
            positive_float(self.max_step, "BodyLoss.max_step")
        if not isinstance(self.bias, (bool, np.bool_)):
            raise TypeError(f"BodyLoss.bias must be True or False; got {self.bias!r}")

    @property
    def name(self) -> str:
        return "body observations: latent momenta"

    def problem(self, model, data: BodyObservations, *, h, validation_fraction, seed, normalise) -> FittedProblem:
        """The trajectories as `BodySegments`, the starts from `latent_starts`."""
        if not isinstance(data, BodyObservations):
            raise TypeError(f"learn.BodyLoss compares a map with integrators.BodyObservations; got {type(data).__name__}")
        if not isinstance(model, AbstractBodyMap):
            hint = model.body_records_hint() if isinstance(model, AbstractLearnedMap) else ""
            hint = f" ({hint})" if hint else ""
            raise TypeError(f"learning from body observations needs a map that carries the configuration and reads "
                            f"a body velocity (learn.GLPNet, learn.Dissipative, learn.BodyLPNet); got "
                            f"{type(model).__name__}{hint}")
        if normalise:
            raise ValueError("normalise=True is for an MLP on pairs; not for body observations")
        if model.system.group != data.group:
            raise ValueError(f"the model's system moves configurations on {model.system.group!r}; the observations "
                             f"are on {data.group!r}")
        substeps = substeps_for_body(data, self.max_step)  # the most of any interval (described)
        h = positive_float(h, "h") if h is not None else (
            float(model.h) if model.h is not None else float(np.median(data.intervals())))
        model = eqx.tree_at(lambda m: m.h, model, None, is_leaf=lambda v: v is None)
        if self.bias and "velocities" not in data.measured:
            raise ValueError("BodyLoss(bias=True) fits a gyroscope bias, but these observations hold no velocities")
        args = body_segments(data, self.max_step, self.bias)
        description = Description(loss=self.name, h=h, n_train=int(data.n_observations), n_val=0, seed=int(seed),
                                  validation_fraction=0.0, max_step=self.max_step, substeps=substeps)
        starts = latent_starts(model, data)
        shared = jnp.zeros((data.n_groups, data.dim), dtype=starts.dtype) if self.bias else None
        return FittedProblem(BodyObjective(), Fitted(model, starts, shared), args, None, description)


def substeps_for_body(data: BodyObservations, max_step: float | None) -> int:
    """The most sub-steps of any interval (`sub_steps`)."""
    return int(sub_steps(np.array([float(np.max(data.intervals()))]), max_step)[1][-1]) + 1


def first_velocities(data: BodyObservations) -> np.ndarray:
    """The body velocity at the first time of each trajectory `(S, dim)`: observed, or from the
    first interval's configurations."""
    if data.velocities is not None:
        return np.stack([v[0] for v in data.velocities])
    return np.stack([data.group_velocities(j)[0] for j in range(len(data))])


def latent_momenta(model, xi: ArrayLike, iterations: int = 20) -> jax.Array:
    r"""The momenta $\mu$ `(..., dim)` with $\nabla\widetilde H(\mu) = \xi$ for body velocities
    `xi` `(..., dim)` (what a gyroscope reads): the latent state a learned map starts from
    (Newton's method on `model.body_velocity` from $\mu = 0$, least squares per step; exact
    after one step for a quadratic $\widetilde H$). In the gauge of the fit (conventions,
    [Observations of bodies][conventions-body-observations]).

    At most `iterations` (>= 1) Newton steps per sample; a sample stops once its step is at
    round-off, $|\Delta\mu|_\infty \le$ `NEWTON_TOLERANCE` $|\mu|_\infty$. Compiled once per
    structure of `model` and shape of `xi` (the weights, `h` and `iterations` are traced),
    vectorised over the samples; not reverse-differentiable (a `jax.lax.while_loop`)."""
    iterations = positive_int(iterations, "iterations")
    dim = model.system.dim
    values = np.asarray(xi, dtype=np.float64)
    if values.ndim < 1 or values.shape[-1] != dim or not np.all(np.isfinite(values)):
        raise ValueError(f"xi must be finite body velocities of shape (..., {dim}); got shape {values.shape}")
    # h does not enter the velocity: an array (traced), so that no h, nor None, recompiles
    h = np.nan if model.h is None else model.h
    model = eqx.tree_at(lambda m: m.h, model, np.asarray(h, dtype=np.float64), is_leaf=lambda v: v is None)
    return _newton_momenta(model, values, np.asarray(iterations, dtype=np.int32))


#: `latent_momenta` stops a sample once its Newton step is at most this times its momentum
#: (sup norms): with the error squared each step, the next step would move it by round-off.
NEWTON_TOLERANCE = 1e-10


@eqx.filter_jit
def _newton_momenta(model, xi: jax.Array, iterations: jax.Array) -> jax.Array:
    """`(..., dim)` momenta of the body velocities `xi` `(..., dim)` (`latent_momenta`)."""

    def velocity_twice(mu):
        v = model.body_velocity(mu)
        return v, v

    def one(target):
        def newton(state):
            k, mu, _ = state
            hessian, velocity = jax.jacfwd(velocity_twice, has_aux=True)(mu)
            change = jnp.linalg.pinv(hessian) @ (velocity - target)
            mu = mu - change
            done = jnp.max(jnp.abs(change)) <= NEWTON_TOLERANCE * jnp.max(jnp.abs(mu))
            return k + 1, mu, done

        def more(state):
            k, _, done = state
            return (k < iterations) & ~done

        start = (jnp.zeros((), iterations.dtype), jnp.zeros_like(target), jnp.zeros((), bool))
        return jax.lax.while_loop(more, newton, start)[1]

    return jax.vmap(one)(xi.reshape(-1, xi.shape[-1])).reshape(xi.shape)


def latent_starts(model, data: BodyObservations) -> jax.Array:
    r"""Starts `(S, dim)` or `(S, 2 dim)`: `latent_momenta` of each trajectory's first velocity,
    then $\delta = 0$ when configurations are observed."""
    mu = latent_momenta(model, first_velocities(data))
    if "configurations" in data.measured:
        return jnp.concatenate([mu, jnp.zeros_like(mu)], axis=1)
    return mu


#: Samples under each test function of `body_quadratic_estimate`'s weak form; the windows of a
#: longer trajectory overlap by half. Chosen among 5, 9, 15 and 41 on W4's bodies (BENCHMARKS.md,
#: "The vehicle at noise 1e-2 fixed: the inertia estimate in weak form").
WEAK_WINDOW = 15

# Gauss-Legendre nodes per interval: exact for a test function of degree 4 times a cubic
_GAUSS = np.polynomial.legendre.leggauss(4)


def weak_form_weights(t: np.ndarray, window: int = WEAK_WINDOW) -> tuple[np.ndarray, np.ndarray]:
    r"""`(W, W')` `(n_windows, len(t))`: $W_{rk} = \int\phi_r s_k\,dt$ and
    $W'_{rk} = \int\phi_r' s_k\,dt$, so that $W f \approx \int\phi_r f\,dt$ for samples $f_k =
    f(t_k)$ of a smooth $f$ (the integral of their cubic spline, not-a-knot; $s_k$ its
    cardinal functions). The test functions $\phi_r = \psi_r^2$,
    $\psi_r = (t - a)(b - t)/((b - a)/2)^2$, vanish with their derivative at the ends of
    windows $[a, b]$ of `window` consecutive samples (of half a shorter trajectory, at least
    three), overlapping by half, so
    $\int\phi_r\dot f\,dt = -\int\phi_r' f\,dt$: no difference of noisy samples is taken."""
    from scipy.interpolate import CubicSpline

    k = t.size
    width = min(window, max(3, k // 2), k)  # a short trajectory: two or more windows, if it can
    starts = list(range(0, k - width + 1, max(1, width // 2)))
    if starts[-1] != k - width:
        starts.append(k - width)  # the tail of the trajectory under a test function too
    x, w = _GAUSS
    W, dW = np.zeros((len(starts), k)), np.zeros((len(starts), k))
    for r, s in enumerate(starts):
        tk = t[s : s + width]
        a, b = tk[0], tk[-1]
        lo, hi = tk[:-1, None], tk[1:, None]
        nodes = (0.5 * (lo + hi) + 0.5 * (hi - lo) * x).ravel()
        weights = (0.5 * (hi - lo) * w).ravel()
        cardinal = CubicSpline(tk, np.eye(width))(nodes)  # (nodes, width)
        psi = (nodes - a) * (b - nodes) / (0.5 * (b - a)) ** 2
        dpsi = (a + b - 2.0 * nodes) / (0.5 * (b - a)) ** 2
        W[r, s : s + width] = (weights * psi**2) @ cardinal
        dW[r, s : s + width] = (weights * 2.0 * psi * dpsi) @ cardinal
    return W, dW


def body_quadratic_estimate(data: BodyObservations, linear: bool = True, diagonal: bool = False
                            ) -> tuple[np.ndarray, np.ndarray]:
    r"""`(A, b)` of a quadratic $\widetilde H = \tfrac12\mu^\top A\mu + b^\top\mu$ from body
    velocities alone (`weak_form_quadratic`, which also gives its misfit)."""
    A, b, _ = weak_form_quadratic(data, linear, diagonal)
    return A, b


def weak_form_quadratic(data: BodyObservations, linear: bool = True, diagonal: bool = False
                        ) -> tuple[np.ndarray, np.ndarray, float]:
    r"""`(A, b, misfit)`: `(A, b)` of a quadratic $\widetilde H = \tfrac12\mu^\top A\mu + b^\top\mu$ from body
    velocities alone: with the inertia $\mathbb M = A^{-1}$, $\mu = \mathbb M(\xi - b)$, the
    Lie-Poisson equations $\dot\mu = \mathbb B(\mu)\xi$ read
    $\mathbb M\dot\xi = \mathbb B(\mathbb M\xi - c)\,\xi$ with $c = \mathbb Mb$: homogeneous and
    linear in $(\mathbb M, c)$. In weak form against test functions $\phi_r$ on windows of
    the velocities (observed, or from the configurations; `weak_form_weights`),
    $-\mathbb M\int\phi_r'\xi\,dt = \int\phi_r\,\mathbb B(\mathbb M\xi - c)\,\xi\,dt$, solved
    by the smallest singular vector: the noise of the velocities is integrated, not
    differenced. $\mathbb M$ made positive definite (eigenvalues clipped at 1e-3 of the
    largest: a start, not a result). Scale (not identifiable): $\operatorname{tr}\mathbb M = n$.
    `misfit`: the squared smallest singular value of the weak-form equations (columns of unit
    norm), their least residual: a family of fewer coefficients (`diagonal`, no `linear`) has
    a subset of the columns, so its misfit is never below the fuller family's."""
    A, b, _, misfit = _weak_form(data, linear, diagonal, None)
    return A, b, misfit


def weak_form_drag(data: BodyObservations, kind: str = "quadratic", linear: bool = False, diagonal: bool = False
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    r"""`(A, b, D, misfit)`: `weak_form_quadratic` with a drag $-w(\xi)D\xi$ in the equations,
    $\mathbb M\dot\xi = \mathbb B(\mathbb M\xi - c)\,\xi - w(\xi)D\xi$ ($w = 1$ for
    `kind="linear"`, $|\xi|$ for `"quadratic"`; $D$ diagonal), still homogeneous and linear in
    $(\mathbb M, c, D)$: the same weak form with $n$ more columns, in the scale
    $\operatorname{tr}\mathbb M = n$ (so $D$ is relative to the inertia, as the data fix it; made
    $\ge 0$). Its `misfit` against `weak_form_quadratic`'s tells whether the data lose energy
    to something a drag explains (`learn.fit_splitting(dissipation="auto")`)."""
    if kind not in ("linear", "quadratic"):
        raise ValueError(f"kind must be 'linear' or 'quadratic'; got {kind!r}")
    return _weak_form(data, linear, diagonal, kind)


def _weak_form(data: BodyObservations, linear: bool, diagonal: bool, drag: str | None):
    """The weak-form estimate of `weak_form_quadratic` / `weak_form_drag`: `(A, b, D, misfit)`."""
    system = data.system
    n = system.dim
    C = np.asarray(system.algebra.structure_constants)
    xis, Ls, Ws, dWs = [], [], [], []
    for j, t in enumerate(data.times):
        if data.velocities is not None:
            v, tt = data.velocities[j], t
        else:
            v, tt = data.group_velocities(j), 0.5 * (t[1:] + t[:-1])
        if v.shape[0] < 2:
            continue
        W, dW = weak_form_weights(tt)
        xis.append(v)
        Ls.append(float(system.algebra.sign) * np.einsum("abd,kb->kad", C, v))  # B(mu) xi = L mu
        Ws.append(W)
        dWs.append(dW)
    unknowns = (n if diagonal else n * (n + 1) // 2) + (n if linear else 0) + (n if drag else 0)
    windows = sum(W.shape[0] for W in Ws)
    if windows * n < 2 * unknowns:
        raise ValueError(f"the data give {windows} windows of consecutive velocities ({windows * n} equations); "
                         f"estimating {unknowns} coefficients of the inertia needs at least {2 * unknowns} equations "
                         "(more trajectories of two or more observations, or longer ones)")
    i, j = np.diag_indices(n) if diagonal else np.triu_indices(n)
    columns = []
    for a, c in zip(i, j, strict=True):
        E = np.zeros((n, n))
        E[a, c] = E[c, a] = 1.0
        columns.append(np.concatenate([
            (-dW @ (xi @ E) - W @ np.einsum("kpq,qr,kr->kp", L, E, xi)).reshape(-1)
            for xi, L, W, dW in zip(xis, Ls, Ws, dWs, strict=True)]))
    if linear:  # + B(c) xi = L c
        columns.extend(np.concatenate([(W @ L[:, :, q]).reshape(-1) for L, W in zip(Ls, Ws, strict=True)])
                       for q in range(n))
    if drag is not None:  # + int phi w(xi) D xi, D diagonal: component q of the equations
        for q in range(n):
            blocks = []
            for xi, W in zip(xis, Ws, strict=True):
                weight = np.ones(len(xi)) if drag == "linear" else np.linalg.norm(xi, axis=1)
                block = np.zeros((W.shape[0], n))
                block[:, q] = W @ (weight * xi[:, q])
                blocks.append(block.reshape(-1))
            columns.append(np.concatenate(blocks))
    design = np.stack(columns, axis=1)
    norms = np.linalg.norm(design, axis=0)
    norms = np.where(norms > 0, norms, 1.0)
    _, singular, vt = np.linalg.svd(design / norms, full_matrices=False)
    theta = vt[-1] / norms
    M = np.zeros((n, n))
    M[i, j] = M[j, i] = theta[: i.size]
    c = theta[i.size : i.size + n] if linear else np.zeros(n)
    drag_diagonal = theta[i.size + (n if linear else 0):] if drag else np.zeros(n)
    # the singular vector's sign is arbitrary: the one with the larger positive part; then the
    # inertia made positive definite (noise, or motions that do not fix every direction, leave
    # eigenvalues near zero or below: clipped at 1e-3 of the largest) and scaled to trace n
    values, vectors = np.linalg.eigh(M)
    if values.max() < -values.min():
        values, c, drag_diagonal = -values[::-1], -c, -drag_diagonal
        vectors = vectors[:, ::-1]
    values = np.maximum(values, 1e-3 * values.max())
    scale = n / values.sum()
    M, c = (vectors * (values * scale)) @ vectors.T, c * scale
    A = np.linalg.inv(M)
    return A, A @ c, np.diag(np.maximum(drag_diagonal * scale, 0.0)), float(singular[-1] ** 2)
