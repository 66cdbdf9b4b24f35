r"""Trajectory least squares for a learned stream operator (`learn.StreamOperator`) on
observed vorticity fields, at any size: the operator's parameters $\theta$ (its spectrum, the
rotation) and one fitted initial field $s_j$ per trajectory minimise

$$\sum_j\sum_k \big|\Phi_\theta(t_{jk} - t_{j0};\,s_j) - y_{jk}\big|^2,$$

$\Phi_\theta$ the model rolled out over the observed (uneven) intervals, $y_{jk}$ the
observations (every one, the first included). The starts make the unknowns $p + J\,n$ ($n =
N^2$, up to 16,384 per start), so the Jacobian is never formed and neither is any $n\times n$
block: Levenberg-Marquardt on the normal equations

$$\begin{pmatrix}A + \lambda D_\theta & B^\top\\ B & G + \lambda D_s\end{pmatrix}
\begin{pmatrix}\delta\theta\\ \delta s\end{pmatrix} = -\begin{pmatrix}g_\theta\\ c\end{pmatrix},
\quad A = J_\theta^\top J_\theta,\; B = J_s^\top J_\theta,\; G = J_s^\top J_s
\;(\text{block diagonal}),$$

eliminating $\theta$ (a $p\times p$ solve): the starts' reduced system
$(G + \lambda D_s - B(A + \lambda D_\theta)^{-1}B^\top)\,\delta s = -(c - B(A +
\lambda D_\theta)^{-1}g_\theta)$ is solved by conjugate gradients (lineax), each iteration one
linearised rollout forward and its transpose back per trajectory (`jax.linearize`,
`jax.linear_transpose`); $J_\theta$ by $p$ forward passes per trajectory, reduced at once to
$A$ and $B_j = J_{s_j}^\top J_{\theta,j}$ (`(n, p)`). The standard errors of $\theta$ are
those of the Gauss-Newton covariance at the solution with the starts profiled out,
$\hat\sigma^2\big(A - \sum_j B_j^\top G_j^{-1}B_j\big)^{-1}$ ($G_j^{-1}B_j$ by conjugate
gradients), $\hat\sigma^2$ the residual sum of squares over its degrees of freedom.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
from jax.flatten_util import ravel_pytree

from integrators import Observations
from liepoisson.internals import check_fits_in_memory, positive_float, positive_int
from liepoisson.systems import Zeitlin

from .._models._spectrum import AbstractGaugedSpectrum, AbstractSpectrum
from .._models._stream_operator import StreamOperator

#: The damping lambda (relative to the Marquardt scaling) is kept in this range.
LAMBDA_RANGE = (1e-16, 1e16)
#: Trial dampings per Levenberg-Marquardt iteration at most.
MAX_TRIALS = 30
#: The most quasi-Newton iterations per step the fit raises `iterations` to when a rollout of
#: the start is not finite (a step whose stage has not converged is NaN).
MAX_STAGE_ITERATIONS = 24


@dataclasses.dataclass(frozen=True)
class StreamOperatorFit:
    r"""What `learn.fit_stream_operator` found.

    - `model`: the fitted `learn.StreamOperator` (its `h` the data's median interval over
      `substeps`).
    - `spectrum`: its fitted spectrum (`model.spectrum`); `values` what it reports
      (`spectrum.values()`: the eigenvalues per degree $\lambda_1..\lambda_{N-1}$, per harmonic,
      or the quasi-geostrophic $F$) and `standard_errors` theirs (NaN where not computed).
    - `rotation`, `rotation_standard_error`: the fitted angular velocity and its standard error
      (`None` without a rotation term).
    - `starts`: the fitted initial fields `(n_trajectories, N^2)` (u(N) coordinates).
    - `covariance`: `(p, p)` of the parameters (flattened as the model's array leaves), the
      Gauss-Newton covariance with the starts profiled out; `noise`: $\hat\sigma$, the
      residuals' root mean square over their degrees of freedom (per component).
    - `losses`: the mean squared residual after each accepted iteration (the first at the
      start); `iterations`; `stopped`: why the fit stopped; `substeps`: steps per interval.
    """

    model: StreamOperator
    spectrum: AbstractSpectrum
    values: np.ndarray
    standard_errors: np.ndarray
    rotation: float | None
    rotation_standard_error: float | None
    starts: np.ndarray
    covariance: np.ndarray
    noise: float
    losses: list[float]
    iterations: int
    stopped: str
    substeps: int


class _Data(eqx.Module):
    """Observations padded to one length: `states` `(J, L, n)`, `intervals` `(J, L - 1)` (0 past
    a trajectory's end: steps that repeat the state), `mask` `(J, L)`."""

    states: jax.Array
    intervals: jax.Array
    mask: jax.Array


def _padded(data: Observations) -> _Data:
    L = max(y.shape[0] for y in data.states)
    J, n = data.n_trajectories, data.system.dim
    check_fits_in_memory(8 * J * L * n * 2, f"data: {J} trajectories of up to {L} fields of {n} components",
                         "fit fewer or shorter trajectories")
    states = np.zeros((J, L, n))
    intervals = np.zeros((J, L - 1))
    mask = np.zeros((J, L))
    for j, (t, y) in enumerate(zip(data.times, data.states)):
        states[j, :len(t)] = y
        intervals[j, :len(t) - 1] = np.diff(t)
        mask[j, :len(t)] = 1.0
    return _Data(jnp.asarray(states), jnp.asarray(intervals), jnp.asarray(mask))


def check_stream_data(model: Any, data: Any) -> None:
    """`TypeError`/`ValueError` naming `model` or `data` unless `model` is a `StreamOperator`
    and `data` `integrators.Observations` of Zeitlin's model of the same N."""
    if not isinstance(model, StreamOperator):
        raise TypeError(f"model must be a learn.StreamOperator; got {type(model).__name__}")
    if not isinstance(data, Observations):
        raise TypeError(f"data must be integrators.Observations (vorticity fields at their times: "
                        f"integrators.read_vorticity_snapshots); got {type(data).__name__}")
    if not isinstance(data.system, Zeitlin):
        raise ValueError(  # noqa: TRY004 (observations of another system: a value, not a type, is wrong)
            f"data must be observations of liepoisson.systems.Zeitlin(N) (fields on the sphere); got "
            f"observations of {data.system!r}")
    if data.system.N != model.N:
        raise ValueError(f"data holds fields of N = {data.system.N} (dimension {data.system.dim}); the model is for "
                         f"N = {model.N} (dimension {model.system.dim}): build the model on the data's "
                         f"Zeitlin({data.system.N})")


def fit_stream_operator(model: StreamOperator, data: Observations, *, max_step: float | None = None,
                        iterations: int = 50, rtol: float = 1e-10, cg_rtol: float = 1e-8,
                        cg_max_steps: int = 200, standard_errors: bool = True, starts: Any = None,
                        progress: bool = False) -> StreamOperatorFit:
    r"""Fit `model`'s stream operator and one initial field per trajectory to `data` by
    trajectory least squares (module docstring: Levenberg-Marquardt with the starts eliminated
    by conjugate gradients; nothing of size $N^2\times N^2$ is formed).

    **Arguments:**

    - `model`: a `learn.StreamOperator` (its parameters are the start; its `iterations` are
      raised, up to `MAX_STAGE_ITERATIONS`, until the start's rollouts are finite).
    - `data`: `integrators.Observations` of `liepoisson.systems.Zeitlin(N)`, N the model's;
      trajectories of any lengths, uneven times.
    - `max_step`: every interval is run in the same number of equal steps, the fewest that
      keep each step of the longest interval at most `max_step` (`None`: one step per
      interval).
    - `iterations`: Levenberg-Marquardt iterations at most; `rtol`: stop once an iteration
      lowers the loss by less than `rtol` of it.
    - `cg_rtol`, `cg_max_steps`: the conjugate gradients' relative tolerance and step cap (a
      step whose solve stops at the cap is still tried: the loss decides; a standard error
      whose solve does not converge is NaN).
    - `standard_errors`: compute the parameters' covariance at the solution ($p$ conjugate
      gradient solves per trajectory; `False`: NaN).
    - `starts`: the initial fields to start from `(n_trajectories, N^2)` (default: each
      trajectory's first observation), e.g. a previous fit's `starts`.
    - `progress`: print each iteration's loss.

    **Returns:** a `learn.StreamOperatorFit`.
    """
    check_stream_data(model, data)
    iterations = positive_int(iterations, "iterations")
    if isinstance(rtol, bool) or not isinstance(rtol, (int, float)) or not 0 <= rtol < 1:
        raise ValueError(f"rtol must be a number in [0, 1); got {rtol!r}")
    cg_rtol = positive_float(cg_rtol, "cg_rtol")
    cg_max_steps = positive_int(cg_max_steps, "cg_max_steps")
    all_intervals = data.intervals()
    if max_step is None:
        substeps = 1
    else:
        substeps = max(1, math.ceil(float(all_intervals.max()) / positive_float(max_step, "max_step") - 1e-12))
    padded = _padded(data)
    if starts is None:
        starts = np.stack([y[0] for y in data.states])
    else:
        starts = np.asarray(starts, dtype=np.float64)
        expected = (data.n_trajectories, data.system.dim)
        if starts.shape != expected:
            raise ValueError(f"starts must have shape {expected} (one field per trajectory); got {starts.shape}")
        if not np.all(np.isfinite(starts)):
            raise ValueError("starts must be finite")
    starts = jnp.asarray(starts)
    model = _with_converging_iterations(model, starts, padded, substeps)
    model = eqx.tree_at(lambda m: m.h, model, None, is_leaf=lambda v: v is None)  # one compilation for every h
    x, rebuild = _flat(model)
    params, _ = eqx.partition(model, _trained(model))
    unravel = ravel_pytree(params)[1]
    p = x.size
    counts = jnp.sum(padded.mask, axis=1)  # observations per trajectory: the starts' scaling
    n_residuals = int(np.sum(np.asarray(counts))) * data.system.dim

    state = _linearise(rebuild(x), starts, padded, substeps)
    if not np.isfinite(float(state.cost)):
        raise FloatingPointError("fit_stream_operator: the loss at the start is not finite; check the data and the "
                                 "model's start (a step too large for the stage iteration: use max_step=)")
    D_theta = _scaling(state.A)
    lam, nu = 1e-3, 2.0
    losses = [float(state.cost) / n_residuals]
    stopped, done = "iterations", 0
    for _ in range(iterations):
        D_theta = jnp.maximum(D_theta, _scaling(state.A))
        accepted = False
        for _ in range(MAX_TRIALS):
            dx, dS = _solve(rebuild(x), starts, padded, state, D_theta, counts, jnp.asarray(lam), substeps, cg_rtol,
                            cg_max_steps)
            if bool(jnp.all(jnp.isfinite(dx)) and jnp.all(jnp.isfinite(dS))):
                cost_new = float(_cost(rebuild(x + dx), starts + dS, padded, substeps))
                g_delta = float(state.g_theta @ dx + jnp.sum(state.c * dS))
                damped = float(dx @ (D_theta * dx) + jnp.sum(counts[:, None] * dS * dS))
                predicted = -g_delta + lam * damped
                if np.isfinite(cost_new) and cost_new < float(state.cost) and predicted > 0:
                    rho = (float(state.cost) - cost_new) / predicted
                    lam = max(lam * max(1 / 3, 1 - (2 * rho - 1) ** 3), LAMBDA_RANGE[0])
                    nu = 2.0
                    before = float(state.cost)
                    x, starts = x + dx, starts + dS
                    state = _linearise(rebuild(x), starts, padded, substeps)
                    accepted = True
                    break
            lam = min(lam * nu, LAMBDA_RANGE[1])
            nu *= 2
        if not accepted:
            stopped = "no damping lowers the loss"
            break
        done += 1
        losses.append(float(state.cost) / n_residuals)
        if progress:
            print(f"fit_stream_operator: iteration {done}, loss {losses[-1]:.6e}, lambda {lam:.1e}")
        if before - float(state.cost) <= rtol * before:
            stopped = "converged"
            break

    fitted = rebuild(x)
    dof = n_residuals - p - starts.size
    sigma2 = float(state.cost) / dof if dof > 0 else float("nan")
    if standard_errors:
        covariance = sigma2 * np.linalg.inv(np.asarray(_profiled(fitted, starts, padded, state, counts, substeps, cg_rtol,
                                                                  cg_max_steps)))
    else:
        covariance = np.full((p, p), np.nan)
    variances = np.diag(covariance)
    se = unravel(jnp.asarray(np.where(variances >= 0, np.sqrt(np.abs(variances)), np.nan)))
    h = float(np.median(all_intervals)) / substeps
    fitted = eqx.tree_at(lambda m: m.h, fitted, h, is_leaf=lambda v: v is None)
    return StreamOperatorFit(
        model=fitted, spectrum=fitted.spectrum, values=fitted.spectrum.values(),
        standard_errors=fitted.spectrum.standard_errors(se.spectrum),
        rotation=None if fitted.rotation is None else float(fitted.rotation),
        rotation_standard_error=None if fitted.rotation is None else float(se.rotation),
        starts=np.asarray(starts), covariance=np.asarray(covariance), noise=math.sqrt(sigma2),
        losses=losses, iterations=done, stopped=stopped, substeps=substeps)


def _scaling(A: jax.Array) -> jax.Array:
    """Marquardt's scaling: the diagonal of $A$, a parameter the residuals do not see given a
    scale from the others (MINPACK's rule)."""
    diag = jnp.diag(A)
    return jnp.maximum(diag, jnp.finfo(A.dtype).eps * jnp.maximum(jnp.max(diag), jnp.finfo(A.dtype).tiny))


def _with_converging_iterations(model: StreamOperator, starts: jax.Array, data: _Data,
                                substeps: int) -> StreamOperator:
    """`model` with the fewest stage iterations (from its own, up to `MAX_STAGE_ITERATIONS`)
    whose rollouts from `starts` over the data's intervals are finite, plus one (the
    parameters move)."""
    k = model.iterations
    while True:
        trial = StreamOperator(model.system, model.spectrum, rotation=None if model.rotation is None else
                               float(model.rotation), tol=model.tol, iterations=k, max_iter=model.max_iter)
        ys = _rollouts(trial, starts, data.intervals, substeps)
        if bool(jnp.all(jnp.isfinite(ys))):
            if k == model.iterations:
                return trial
            return StreamOperator(model.system, model.spectrum, rotation=None if model.rotation is None else
                                  float(model.rotation), tol=model.tol, iterations=k + 1, max_iter=model.max_iter)
        if k >= MAX_STAGE_ITERATIONS:
            raise ValueError(
                f"model: a step's stage iteration does not meet tol={model.tol:g} in {MAX_STAGE_ITERATIONS} "
                "iterations on the data's intervals (steps too large for the fields' speed): give max_step= "
                "smaller than the intervals, or a larger tol")
        k += 2


@eqx.filter_jit
def _rollouts(model: StreamOperator, starts: jax.Array, intervals: jax.Array, substeps: int) -> jax.Array:
    return jax.vmap(lambda s, dt: model.rollout_intervals(s, dt, substeps))(starts, intervals)


class _Linearisation(eqx.Module):
    r"""At `(x, S)`: `cost` (sum of squares), `A` $= J_\theta^\top J_\theta$, `g_theta` $=
    J_\theta^\top r$, `B` `(J, n, p)` $= J_{s_j}^\top J_{\theta,j}$, `c` `(J, n)` $= J_{s_j}^\top
    r_j$."""

    cost: jax.Array
    A: jax.Array
    g_theta: jax.Array
    B: jax.Array
    c: jax.Array


def _trained(model: StreamOperator) -> Any:
    """The filter of what a fit moves: the model's inexact arrays but a gauged spectrum's fixed
    inverse eigenvalue."""
    spec = jax.tree_util.tree_map(eqx.is_inexact_array, model)
    if isinstance(model.spectrum, AbstractGaugedSpectrum):
        spec = eqx.tree_at(lambda m: m.spectrum.reference_inverse, spec, False)
    return spec


def _flat(model: StreamOperator):
    """`(x, rebuild)`: the model's parameters flat and the map back to a model."""
    params, static = eqx.partition(model, _trained(model))
    x, unravel = ravel_pytree(params)
    return x, lambda z: eqx.combine(unravel(z), static)


def _residuals(model, s, y, dt, mask, substeps):
    return (model.rollout_intervals(s, dt, substeps) - y) * mask[:, None]


@eqx.filter_jit
def _cost(model, S, data, substeps):
    r = jax.vmap(lambda s, y, dt, m: _residuals(model, s, y, dt, m, substeps))(
        S, data.states, data.intervals, data.mask)
    return jnp.sum(r * r)


def _one(model, s, y, dt, mask, substeps):
    x, rebuild = _flat(model)

    def f(z):
        r = _residuals(rebuild(z), s, y, dt, mask, substeps).reshape(-1)
        return r, r

    J_theta, r = jax.jacfwd(f, has_aux=True)(x)  # (L n, p)
    _, pullback = jax.vjp(lambda z: _residuals(model, z, y, dt, mask, substeps).reshape(-1), s)
    B = jax.vmap(lambda column: pullback(column)[0], in_axes=1, out_axes=1)(J_theta)  # (n, p)
    c = pullback(r)[0]
    return r @ r, J_theta.T @ J_theta, J_theta.T @ r, B, c


@eqx.filter_jit
def _linearise(model, S, data, substeps):
    # one trajectory at a time (lax.map): at most one J_theta (L n x p) held
    cost, A, g, B, c = jax.lax.map(lambda a: _one(model, *a, substeps), (S, data.states, data.intervals, data.mask))
    return _Linearisation(jnp.sum(cost), jnp.sum(A, 0), jnp.sum(g, 0), B, c)


def _gram(model, S, data, substeps):
    r"""$V \mapsto G V$, $G$ the starts' block-diagonal $J_s^\top J_s$ (each trajectory
    linearised once)."""
    def one(s, y, dt, mask, v):
        _, forward = jax.linearize(lambda z: _residuals(model, z, y, dt, mask, substeps), s)
        backward = jax.linear_transpose(forward, s)
        return backward(forward(v))[0]

    return lambda V: jax.vmap(one)(S, data.states, data.intervals, data.mask, V)


@eqx.filter_jit
def _solve(model, S, data, lin, D_theta, counts, lam, substeps, cg_rtol, cg_max_steps):
    A_lam = lin.A + lam * jnp.diag(D_theta)
    gram = _gram(model, S, data, substeps)
    d = (1.0 + lam) * counts[:, None]  # the starts' scaling (the flow about keeps norms: G ~ counts)

    def reduced(V):
        w = jnp.linalg.solve(A_lam, jnp.einsum("jnp,jn->p", lin.B, V))
        return gram(V) + lam * counts[:, None] * V - jnp.einsum("jnp,p->jn", lin.B, w)

    structure = jax.eval_shape(lambda: S)
    operator = lx.FunctionLinearOperator(reduced, structure, tags=lx.positive_semidefinite_tag)
    preconditioner = lx.FunctionLinearOperator(lambda V: V / d, structure, tags=lx.positive_semidefinite_tag)
    rhs = -(lin.c - jnp.einsum("jnp,p->jn", lin.B, jnp.linalg.solve(A_lam, lin.g_theta)))
    sol = lx.linear_solve(operator, rhs, lx.CG(rtol=cg_rtol, atol=0.0, max_steps=cg_max_steps),
                          options={"preconditioner": preconditioner}, throw=False)
    dS = sol.value  # an inexact step (CG stopped at max_steps) is still a step: the loss judges it
    dx = -jnp.linalg.solve(A_lam, lin.g_theta + jnp.einsum("jnp,jn->p", lin.B, dS))
    return dx, dS


@eqx.filter_jit
def _profiled(model, S, data, lin, counts, substeps, cg_rtol, cg_max_steps):
    r"""$A - \sum_j B_j^\top G_j^{-1}B_j$: the parameters' Gauss-Newton matrix with the starts
    profiled out ($G_j^{-1}B_j$ by conjugate gradients, one per column)."""
    gram = _gram(model, S, data, substeps)

    structure = jax.eval_shape(lambda: S)
    operator = lx.FunctionLinearOperator(gram, structure, tags=lx.positive_semidefinite_tag)
    preconditioner = lx.FunctionLinearOperator(lambda V: V / counts[:, None], structure,
                                               tags=lx.positive_semidefinite_tag)

    def solve_column(column):  # column (J, n): G^{-1} column, the trajectories at once
        sol = lx.linear_solve(operator, column, lx.CG(rtol=cg_rtol, atol=0.0, max_steps=cg_max_steps),
                              options={"preconditioner": preconditioner}, throw=False)
        return jnp.where(sol.result == lx.RESULTS.successful, sol.value, jnp.nan)

    X = jax.lax.map(solve_column, jnp.moveaxis(lin.B, 2, 0))  # (p, J, n)
    return lin.A - jnp.einsum("jnp,qjn->pq", lin.B, X)
