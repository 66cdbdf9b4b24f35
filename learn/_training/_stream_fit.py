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

$$\big(J_s^\top(1 - J_\theta A_\lambda^{-1}J_\theta^\top)J_s + \lambda D_s\big)\,\delta s =
-\big(c - J_s^\top J_\theta A_\lambda^{-1}g_\theta\big), \qquad A_\lambda = A + \lambda D_\theta$$

(the Schur complement $G + \lambda D_s - BA_\lambda^{-1}B^\top$) is solved by conjugate
gradients (lineax), the rollouts linearised once per solve (`jax.linearize`): each iteration
one linearised rollout forward and its transpose back per trajectory, $J_\theta$ (`(L n, p)` per
trajectory, kept) applied as a matrix, $B$ never formed. The solves are inexact (an inexact
Newton method: the relative tolerance the square root of the last iteration's relative
decrease of the loss, at most `FORCING_MAX`). The cost and the gradient $g_\theta, c$ are
exact at every point (one reverse pass per trajectory); $J_\theta$ costs $p$ forward passes
per trajectory (`jax.jacfwd`, one rollout's primal shared by the $p$ tangents) and is
recomputed only where it pays: after an iteration that more than halved the loss or whose
gain ratio was below 1/4, before a step whose loss is finite is refused, and before the fit
stops. Near the
minimum the parameters hardly move, and a $J_\theta$ from a nearby point only shapes the steps
(the exact gradient fixes where they lead). The standard errors of $\theta$ are those of the
Gauss-Newton covariance at the solution with the starts profiled out,
$\hat\sigma^2\big(A - \sum_j B_j^\top G_j^{-1}B_j\big)^{-1}$ ($B$ by $p$ transposed passes,
$G_j^{-1}B_j$ by conjugate gradients, a column at a time, the product formed so that its error
is second order in the solves': they run to `se_rtol`), $\hat\sigma^2$ the residual sum of
squares over its degrees of freedom.

A model rolled out in steps $h$ carries the step's error $e = \Phi^h_\theta - \Phi_\theta$
into its fitted parameters: to first order by the Gauss-Newton step of the residual $e$ with
the starts profiled out, $\delta\theta = -S_p^{-1}\big(J_\theta^\top e - \sum_j B_j^\top
G_j^{-1}J_{s_j}^\top e_j\big)$, $S_p$ the profiled matrix above (its solves $X = G^{-1}B$
reused). $e$ is estimated by Richardson's rule from the same rollouts at half the step,
$e \approx (\Phi^h - \Phi^{h/2})\,2^q/(2^q - 1)$ at order $q$: one more rollout and one
reverse pass per trajectory (`StreamOperatorFit.step_bias`).
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx
import scipy.stats
from jax.flatten_util import ravel_pytree

from integrators import Observations
from liepoisson.internals import check_fits_in_memory, positive_float, positive_int
from liepoisson.systems import Zeitlin

from .._models._spectrum import AbstractGaugedSpectrum, AbstractSpectrum
from .._models._stream_operator import StreamOperator
from .._solvers._checkpoint import Checkpoint
from . import _stream_checkpoint as _checkpoint

#: The damping lambda (relative to the Marquardt scaling) is kept in this range.
LAMBDA_RANGE = (1e-16, 1e16)
#: Trial dampings per Levenberg-Marquardt iteration at most.
MAX_TRIALS = 30
#: The most quasi-Newton iterations per step the fit raises `iterations` to when a rollout of
#: the start is not finite (a step whose stage has not converged is NaN).
MAX_STAGE_ITERATIONS = 24
#: The conjugate gradients' relative tolerance is the square root of the last iteration's
#: relative decrease of the loss (an inexact Newton method's forcing term), at most this and at
#: least `cg_rtol` and the square root of the least relative decrease the stopping rules count.
FORCING_MAX = 0.1


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
    - `step_bias`, `rotation_step_bias`: the bias of `values` and `rotation` the step's error
      puts in them, estimated (module docstring; NaN without standard errors): compare it with
      the standard errors, and give a smaller `max_step` where it is not well below them.
    - `wald_test(values, rotation)`: a hypothesised operator (the truth, Euler's $F = 0$)
      against the fit, every parameter at once (`WaldTest`).
    - `losses`: the mean squared residual after each accepted iteration (the first at the
      start); `iterations`; `stopped`: why the fit stopped; `substeps`: steps per interval;
      `seconds`: the fit's wall time (resumed from a checkpoint: the time saved in it, that
      of every process that ran the fit to its last write, plus this call's).
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
    seconds: float
    step_bias: np.ndarray
    rotation_step_bias: float | None

    def wald_test(self, values: Any, rotation: float | None = None) -> WaldTest:
        r"""How far a hypothesised operator lies from the fitted one in the fit's error bars:
        $d^2 = \delta^\top C^{-1}\delta$, $\delta$ the fitted parameters (as fitted: inverse
        eigenvalues, $F$, the rotation) less the hypothesis's, $C$ = `covariance`. If the
        hypothesis is the truth, $d^2 \sim \chi^2_p$ (Gaussian noise, the model linear in its
        parameters over the error bars): one test of every parameter at once, with their
        correlations, where "each within 3 standard errors" fails by chance with many of them
        (p = 0.0027 each). `values` as `values` reports them: a spectrum per degree or harmonic
        in any gauge (moved into the fit's; on a rotating sphere the gauge is no symmetry, so
        the held eigenvalue must be the fit's), or $(F,)$; `rotation` the hypothesis's if the
        fit has one."""
        if not np.all(np.isfinite(self.covariance)):
            raise ValueError("wald_test needs the fit's covariance: fit with standard_errors=True")
        spectrum = self.spectrum
        if self.rotation is None:  # on a sphere at rest the gauge is a symmetry
            values = spectrum.in_gauge_of(values)
        if (rotation is None) != (self.rotation is None):
            raise ValueError("rotation must be given exactly when the fit has one (the hypothesis's angular "
                             f"velocity); the fit's is {self.rotation!r}, got {rotation!r}")
        hypothesis = eqx.tree_at(lambda m: m.spectrum, self.model, spectrum.with_values(values))
        if rotation is not None:
            if isinstance(rotation, (bool, np.bool_, str, bytes)) or np.ndim(rotation) != 0 \
                    or not np.isfinite(float(rotation)):
                raise ValueError(f"rotation must be a finite real number; got {rotation!r}")
            hypothesis = eqx.tree_at(lambda m: m.rotation, hypothesis, jnp.asarray(float(rotation)))
        delta = np.asarray(_flat(self.model)[0]) - np.asarray(_flat(hypothesis)[0])
        statistic = float(delta @ np.linalg.solve(self.covariance, delta))
        return WaldTest(statistic, delta.size, float(scipy.stats.chi2.sf(statistic, delta.size)))


@dataclasses.dataclass(frozen=True)
class WaldTest:
    r"""`StreamOperatorFit.wald_test`'s answer: Wald's `statistic` $d^2$, its degrees of
    freedom `dof` (the parameters fitted) and `p_value`, $P(\chi^2_{dof} \ge d^2)$."""

    statistic: float
    dof: int
    p_value: float


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
                        iterations: int = 50, rtol: float = 1e-10, chi2_tol: float = 0.01,
                        cg_rtol: float = 1e-8,
                        cg_max_steps: int = 200, standard_errors: bool = True, se_rtol: float = 1e-3,
                        se_coarse_degree: int = 5, se_start: Checkpoint | str | os.PathLike | None = None,
                        starts: Any = None, checkpoint: Checkpoint | None = None,
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
      lowers the loss by less than `rtol` of it; `chi2_tol`: stop once it lowers $\chi^2 =
      \mathrm{SSR}/\hat\sigma^2$ by less than `chi2_tol` ($\hat\sigma^2$ the residual sum of
      squares over its degrees of freedom): a step that lowers $\chi^2$ by $\epsilon$ moves the
      parameters by about $\sqrt\epsilon$ standard errors, so the default 0.01 stops where the
      estimate changes by a tenth of its error bar (`0`: only `rtol` stops, e.g. exact data).
    - `cg_rtol`, `cg_max_steps`: the conjugate gradients' tightest relative tolerance (the
      steps' solves start looser, `FORCING_MAX`, and tighten as the loss settles, to no
      tighter than $\sqrt{\max(\mathtt{rtol}, \mathtt{chi2\_tol}/\mathrm{dof})}$, what an
      iteration the stopping rules still count needs) and step cap (a step whose solve stops
      at the cap is still tried: the loss decides; a standard error whose solve does not
      converge is NaN).
    - `standard_errors`: compute the parameters' covariance at the solution ($p$ conjugate
      gradient solves, the fit's largest cost at N = 32; `False`: NaN); `se_rtol` their
      relative tolerance: the covariance is second order in the solves' error (`_profiled`),
      so a loose 1e-3 gives them nearly as a tight one would at about half the steps
      (BENCHMARKS.md, "The step's order": the standard errors' solves); `se_coarse_degree`
      their preconditioner's degrees: block Jacobi with the spherical harmonics of degrees 1 to
      it solved exactly ($(d + 1)^2 - 1$ passes per fit, once; on a sphere the low degrees hold
      most of the solves' spread, BENCHMARKS.md, the same place; 0: none; not built where its
      passes outnumber ten per parameter, more than it saves the solves (BENCHMARKS.md): a fit of one parameter
      solves faster without it); `se_start`: the checkpoint (a `learn.Checkpoint` or its path)
      of an earlier fit of the same data and parameters whose standard errors are done, e.g.
      this fit at a longer step: its solves start this fit's conjugate gradients and its
      preconditioner block is reused (a fit refined in a shorter step moves $G^{-1}B$ little,
      so each solve takes far fewer steps, BENCHMARKS.md). A checkpoint written with other
      `se_rtol`, `se_coarse_degree` or `se_start` keeps its iterations and recomputes the
      standard errors.
    - `starts`: the initial fields to start from `(n_trajectories, N^2)` (default: each
      trajectory's first observation), e.g. a previous fit's `starts`.
    - `checkpoint`: a `learn.Checkpoint`: the fit's state is written to its file (HDF5, a
      temporary renamed into place) every `every` accepted iterations and every `every`
      standard errors' columns (each a conjugate gradient solve: minutes at N = 64; give
      `every=1` for such fits: `Checkpoint`'s default writes almost only at the end), and when
      the iterations end; with `resume`, a fit of the same data, model, start and settings
      continues from the file bit for bit as the uninterrupted fit (a file of another fit, or
      of an older library's algorithm, is refused, saying what differs). A finished fit's file
      returns its result at once. Files of the standard errors' phase keep no $J_\theta$ (the
      resumed fit recomputes it at their point, the same bits; most of a file's size).
    - `progress`: print each iteration's loss, and each trial step's conjugate gradient steps,
      loss and time (wall and CPU).

    **Returns:** a `learn.StreamOperatorFit`.
    """
    begin = time.perf_counter()
    check_stream_data(model, data)
    if checkpoint is not None and not isinstance(checkpoint, Checkpoint):
        raise TypeError(f"checkpoint must be a learn.Checkpoint (its file, how often, whether to resume) or None; "
                        f"got {type(checkpoint).__name__}")
    iterations = positive_int(iterations, "iterations")
    if isinstance(rtol, bool) or not isinstance(rtol, (int, float)) or not 0 <= rtol < 1:
        raise ValueError(f"rtol must be a number in [0, 1); got {rtol!r}")
    if isinstance(chi2_tol, bool) or not isinstance(chi2_tol, (int, float)) or not 0 <= chi2_tol < math.inf:
        raise ValueError(f"chi2_tol must be a finite number >= 0 (the least decrease of chi^2 worth an "
                         f"iteration, e.g. 0.01); got {chi2_tol!r}")
    cg_rtol, se_rtol = positive_float(cg_rtol, "cg_rtol"), positive_float(se_rtol, "se_rtol")
    for name, value in (("cg_rtol", cg_rtol), ("se_rtol", se_rtol)):
        if value >= 1:
            raise ValueError(f"{name} must be below 1 (a relative residual: 1 or more asks the conjugate gradients "
                             f"for no step at all); got {value!r}")
    cg_max_steps = positive_int(cg_max_steps, "cg_max_steps")
    if isinstance(se_coarse_degree, bool) or not isinstance(se_coarse_degree, (int, np.integer)) or se_coarse_degree < 0:
        raise ValueError(f"se_coarse_degree must be an integer >= 0 (the highest spherical-harmonic degree of the "
                         f"standard errors' preconditioner; 0: none); got {se_coarse_degree!r}")
    se_coarse_degree = int(se_coarse_degree)
    if se_start is not None:
        if not isinstance(se_start, (Checkpoint, str, os.PathLike)):
            raise TypeError(f"se_start must be a learn.Checkpoint or the path of one (an earlier fit's, its standard "
                            f"errors done) or None; got {type(se_start).__name__}")
        guess = _checkpoint.read_solves(se_start.path if isinstance(se_start, Checkpoint) else se_start)
    else:
        guess = None
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
    L = padded.states.shape[1]
    check_fits_in_memory(8 * data.n_trajectories * L * data.system.dim * p,
                         f"J_theta: {data.n_trajectories} trajectories of up to {L} fields of {data.system.dim} "
                         f"components by {p} parameters", "fit fewer or shorter trajectories, or fewer parameters")
    counts = jnp.sum(padded.mask, axis=1)  # observations per trajectory: the starts' scaling
    n_residuals = int(np.sum(np.asarray(counts))) * data.system.dim
    dof = n_residuals - p - data.n_trajectories * data.system.dim

    # the least relative decrease of the loss the stopping rules count: `rtol`, or `chi2_tol`
    # of chi^2 (`cost / dof` per unit)
    least = max(rtol, chi2_tol / dof if dof > 0 else 0.0)

    def negligible(decrease: float, cost: float) -> bool:
        """Whether lowering the residual sum of squares `cost` by `decrease` is below both
        stopping rules."""
        return decrease <= least * cost

    # no solve tighter than the forcing term of an iteration that lowers the loss by `least`:
    # one that lowers it by less stops the fit anyway (at N = 128 the solves of 1e-6 and 3e-8
    # took 82 s and 112 s, against 40 s at 2e-3)
    floor = max(cg_rtol, math.sqrt(least))

    settings = {"iterations": iterations, "rtol": rtol, "chi2_tol": chi2_tol, "cg_rtol": cg_rtol,
                "cg_max_steps": cg_max_steps, "standard_errors": standard_errors, "se_rtol": se_rtol,
                "se_coarse_degree": se_coarse_degree, "substeps": substeps}
    if guess is not None:
        X0, C0 = guess
        if X0.shape != (p, *starts.shape):
            raise ValueError(f"se_start's solves have shape {X0.shape}, this fit's {(p, *starts.shape)} (parameters, "
                             "trajectories, field components): give the checkpoint of a fit of the same data and "
                             "parameters")
        settings["se_start"] = _checkpoint.fingerprint(X0, C0)
    keys = {} if checkpoint is None else {"data": _checkpoint.fingerprint(padded),
                                          "model": _checkpoint.fingerprint(x, eqx.partition(model, _trained(model))[1]),
                                          "start": _checkpoint.fingerprint(starts)}
    saved = _checkpoint.read(checkpoint.path, keys, settings) if checkpoint is not None and checkpoint.resumable() \
        else None
    if saved is None:
        state = _linearisation(rebuild(x), starts, padded, substeps, None)
        if not np.isfinite(float(state.cost)):
            raise FloatingPointError("fit_stream_operator: the loss at the start is not finite; check the data and "
                                     "the model's start (a step too large for the stage iteration: use max_step=)")
        D_theta = _scaling(state.A)
        lam, nu = 1e-3, 2.0
        losses = [float(state.cost) / n_residuals]
        stopped, done, fresh, forcing, phase, before_seconds = "iterations", 0, True, FORCING_MAX, "iterations", 0.0
    else:
        x, starts, D_theta = jnp.asarray(saved.x), jnp.asarray(saved.starts), jnp.asarray(saved.D_theta)
        if saved.state is None:  # the standard errors' phase: the linearisation of its point, the same bits afresh
            state = _linearisation(rebuild(x), starts, padded, substeps, None)
        else:
            state = _Linearisation(**{name: jnp.asarray(value) for name, value in saved.state.items()})
        lam, nu, losses = saved.lam, saved.nu, saved.losses
        stopped, done, fresh, forcing, phase, before_seconds = (saved.stopped, saved.done, saved.fresh, saved.forcing,
                                                                saved.phase, saved.seconds)
        if progress:
            print(f"fit_stream_operator: resumed from {os.fspath(checkpoint.path)!r} ({phase}, {done} iterations, "
                  f"{saved.columns} standard errors' columns done)", flush=True)

    def save(columns: int = 0, profiled: tuple | None = None) -> None:
        """The fit's state to the checkpoint's file (`columns` of the standard errors done,
        `profiled` their `(B, X, GX, steps, C)`)."""
        _checkpoint.write(checkpoint.path, _checkpoint.FitState(
            phase, np.asarray(x), np.asarray(starts), lam, nu, forcing, fresh, done, losses, np.asarray(D_theta),
            {name: np.asarray(getattr(state, name)) for name in _checkpoint.STATE}
            if _checkpoint.kept_state(phase) else None, stopped,
            before_seconds + time.perf_counter() - begin, columns, *(profiled or (None,) * 5)), keys, settings)

    def relinearised(why: str) -> _Linearisation:
        clock = _clock()
        new = _linearisation(rebuild(x), starts, padded, substeps, None)
        if progress:
            print(f"fit_stream_operator:   J_theta and gradient afresh ({why}) {_since(clock)}", flush=True)
        return new

    for _ in range(done, iterations) if phase == "iterations" else ():
        D_theta = jnp.maximum(D_theta, _scaling(state.A))
        accepted = False
        for _ in range(MAX_TRIALS):
            clock = _clock()
            step_fresh = fresh  # the step is made with a J_theta of this point
            step = _solve(rebuild(x), starts, padded, state, D_theta, counts, jnp.asarray(lam), substeps,
                          jnp.asarray(max(forcing, floor)), cg_max_steps)
            cost_new = float(_cost(rebuild(x + step.dx), starts + step.dS, padded, substeps))
            predicted = float(step.predicted)
            if progress:
                print(f"fit_stream_operator:   lambda {lam:.1e}: {int(step.cg_steps)} conjugate gradient steps "
                      f"(rtol {max(forcing, floor):.0e}), loss {cost_new / n_residuals:.6e}, "
                      f"{_since(clock)}", flush=True)
            if np.isfinite(cost_new) and cost_new < float(state.cost) and predicted > 0:
                rho = (float(state.cost) - cost_new) / predicted
                lam = max(lam * max(1 / 3, 1 - (2 * rho - 1) ** 3), LAMBDA_RANGE[0])
                nu = 2.0
                before = float(state.cost)
                x, starts = x + step.dx, starts + step.dS
                decrease = (before - cost_new) / before
                # far from the minimum (the loss halved) or mispredicted: a new J_theta; else the
                # old one with the gradient at the new point
                fresh = decrease > 0.5 or rho < 0.25
                clock = _clock()
                state = _linearisation(rebuild(x), starts, padded, substeps, None if fresh else state)
                if progress:
                    print(f"fit_stream_operator:   {'J_theta and ' if fresh else ''}gradient "
                          f"{_since(clock)}", flush=True)
                accepted = True
                break
            if not fresh and np.isfinite(cost_new):
                # refused with a kept J_theta (not for a step so long that the rollout broke
                # down: that is the damping's to fix): linearise afresh, same damping
                state = relinearised("a step refused")
                fresh = True
                continue
            if np.isfinite(cost_new) and 0 <= predicted and negligible(predicted, float(state.cost)):
                # refused with a fresh J_theta, and the step's model promised less than the
                # stopping rule asks: the loss is at its floor (round-off decides the trials;
                # at N = 128 each costs a minute)
                break
            if lam >= LAMBDA_RANGE[1]:
                break
            lam = min(lam * nu, LAMBDA_RANGE[1])
            nu *= 2
        if not accepted:
            converged = np.isfinite(cost_new) and 0 <= predicted and negligible(predicted, float(state.cost))
            stopped = "converged (no step the linear model says can lower the loss by rtol or chi2_tol)" if converged else \
                "no damping lowers the loss"
            break
        done += 1
        losses.append(float(state.cost) / n_residuals)
        if progress:
            print(f"fit_stream_operator: iteration {done}, loss {losses[-1]:.6e}, lambda {lam:.1e}", flush=True)
        forcing = min(FORCING_MAX, math.sqrt(max(decrease, 0.0)))
        if negligible(before - float(state.cost), before):
            # judged by a step made with a fresh J_theta (the state after it keeps the step's
            # J_theta: asking whether that is fresh relinearised after every later iteration)
            if step_fresh:
                stopped = "converged"
                break
            if not fresh:
                state = relinearised("a negligible step made with an older one")
                fresh = True
        if checkpoint is not None and done % checkpoint.every == 0:
            save()

    fitted = rebuild(x)
    if phase == "iterations":
        if standard_errors and not fresh:
            state = _linearisation(fitted, starts, padded, substeps, None)
            fresh = True
        phase = "standard errors"
        if checkpoint is not None:
            save()
    sigma2 = float(state.cost) / dof if dof > 0 else float("nan")
    if standard_errors:
        clock = _clock()

        def after(k: int, *profiled) -> None:
            if progress:
                print(f"fit_stream_operator:   standard errors: column {k + 1} of {p}, {int(profiled[3][k])} conjugate "
                      f"gradient steps, {_since(clock)}", flush=True)
            if checkpoint is not None and ((k + 1) % checkpoint.every == 0 or k + 1 == p):
                save(k + 1, profiled)

        partial = None if saved is None or saved.B is None else (saved.B, saved.X, saved.GX, saved.steps,
                                                                   saved.coarse, saved.columns)
        profiled, cg_steps, X = _profiled(fitted, starts, padded, state.J_theta, state.A, counts, substeps,
                                          jnp.asarray(se_rtol), cg_max_steps, se_coarse_degree, partial=partial,
                                          after=after, guess=guess)
        covariance = sigma2 * np.linalg.inv(np.asarray(profiled))
        bias = _step_bias(fitted, starts, padded, substeps, np.asarray(profiled), X)
        if progress:
            print(f"fit_stream_operator: standard errors: {p} solves of {int(np.min(cg_steps))}-"
                  f"{int(np.max(cg_steps))} conjugate gradient steps (rtol {se_rtol:.0e}), "
                  f"{_since(clock)}", flush=True)
    else:
        covariance = np.full((p, p), np.nan)
        bias = np.full(p, np.nan)
    variances = np.diag(covariance)
    se = unravel(jnp.asarray(np.where(variances >= 0, np.sqrt(np.abs(variances)), np.nan)))
    h = float(np.median(all_intervals)) / substeps
    fitted = eqx.tree_at(lambda m: m.h, fitted, h, is_leaf=lambda v: v is None)
    # the bias of what the fit reports: the values the biased parameters give, less the fitted
    # ones (its sign kept; to first order, as the bias itself)
    known = bool(np.all(np.isfinite(bias)))
    biased = rebuild(x + jnp.asarray(np.where(np.isfinite(bias), bias, 0.0)))
    values_bias = biased.spectrum.values() - fitted.spectrum.values() if known else \
        np.full(np.shape(fitted.spectrum.values()), np.nan)
    if progress and known:
        z = float(np.max(np.abs(bias) / np.sqrt(np.abs(variances))))
        print(f"fit_stream_operator: the step's estimated bias: at most {z:.2g} standard errors"
              + (": give a smaller max_step" if z > 1 else ""), flush=True)
    return StreamOperatorFit(
        model=fitted, spectrum=fitted.spectrum, values=fitted.spectrum.values(),
        standard_errors=fitted.spectrum.standard_errors(se.spectrum),
        rotation=None if fitted.rotation is None else float(fitted.rotation),
        rotation_standard_error=None if fitted.rotation is None else float(se.rotation),
        starts=np.asarray(starts), covariance=np.asarray(covariance), noise=math.sqrt(sigma2),
        losses=losses, iterations=done, stopped=stopped, substeps=substeps,
        seconds=before_seconds + time.perf_counter() - begin,
        step_bias=np.asarray(values_bias, dtype=np.float64),
        rotation_step_bias=None if fitted.rotation is None else
        (float(biased.rotation) - float(fitted.rotation) if known else math.nan))


def _clock() -> tuple[float, float]:
    return time.perf_counter(), time.process_time()


def _since(clock: tuple[float, float]) -> str:
    """The wall and CPU time since `clock` (`_clock()`; the CPU time of every thread: a measure
    that a loaded machine does not inflate)."""
    return f"{time.perf_counter() - clock[0]:.2f} s ({time.process_time() - clock[1]:.2f} s CPU)"


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
    def with_iterations(k: int) -> StreamOperator:
        return StreamOperator(model.system, model.spectrum, rotation=None if model.rotation is None else
                              float(model.rotation), composition=model.composition, tol=model.tol, iterations=k,
                              max_iter=model.max_iter)

    k = model.iterations
    while True:
        trial = with_iterations(k)
        ys = _rollouts(trial, starts, data.intervals, substeps)
        if bool(jnp.all(jnp.isfinite(ys))):
            return trial if k == model.iterations else with_iterations(k + 1)
        if k >= MAX_STAGE_ITERATIONS:
            raise ValueError(
                f"model: a step's stage iteration does not meet tol={model.tol:g} in {MAX_STAGE_ITERATIONS} "
                "iterations on the data's intervals (steps too large for the fields' speed): give max_step= "
                "smaller than the intervals, or a larger tol")
        k += 2


@eqx.filter_jit
def _rollouts(model: StreamOperator, starts: jax.Array, intervals: jax.Array, substeps: int) -> jax.Array:
    return jax.vmap(lambda s, dt: model.rollout_intervals(s, dt, substeps))(starts, intervals)


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


def _all_residuals(model, S, data, substeps):
    """The residuals `(J, L, n)` of every trajectory (its padding 0)."""
    return jax.vmap(lambda s, y, dt, m: _residuals(model, s, y, dt, m, substeps))(
        S, data.states, data.intervals, data.mask)


@eqx.filter_jit
def _cost(model, S, data, substeps):
    r = _all_residuals(model, S, data, substeps)
    return jnp.sum(r * r)


class _Linearisation(eqx.Module):
    r"""At `(x, S)`: `cost` (sum of squares), `g_theta` $= J_\theta^\top r$ and `c` `(J, n)` $=
    J_{s_j}^\top r_j$ (one reverse pass per trajectory: exact), `J_theta` `(J, L n, p)` and
    `A` $= J_\theta^\top J_\theta$ (of this point or of an earlier one: `_linearisation`)."""

    cost: jax.Array
    g_theta: jax.Array
    c: jax.Array
    J_theta: jax.Array
    A: jax.Array


@eqx.filter_jit
def _pullback(model, S, data, substeps, E=None):
    r"""`(cost, g_theta, c)`: $g_\theta = J_\theta^\top E$, $c = J_s^\top E$ for residual-shaped
    `E` `(J, L, n)`, or the residuals $r$ themselves (`None`: the cost's half-gradient), and
    the cost $|r|^2$: one rollout and one reverse pass per trajectory (one trajectory at a
    time, `lax.map`: one's reverse-mode residuals held)."""
    x, rebuild = _flat(model)

    def one(a):
        s, y, dt, m, *e = a
        r, pullback = jax.vjp(lambda z, s: _residuals(rebuild(z), s, y, dt, m, substeps), x, s)
        g, c = pullback(r if E is None else e[0])
        return jnp.sum(r * r), g, c

    cost, g, c = jax.lax.map(one, (S, data.states, data.intervals, data.mask, *(() if E is None else (E,))))
    return jnp.sum(cost), jnp.sum(g, 0), c


@eqx.filter_jit
def _theta_jacobian(model, S, data, substeps):
    r"""`(J_theta, A)`: $J_{\theta,j}$ `(L n, p)` of every trajectory by `jax.jacfwd` ($p$
    tangents batched through one rollout: no reverse pass), one trajectory at a time."""
    x, rebuild = _flat(model)

    def one(a):
        s, y, dt, m = a
        return jax.jacfwd(lambda z: _residuals(rebuild(z), s, y, dt, m, substeps).reshape(-1))(x)

    J_theta = jax.lax.map(one, (S, data.states, data.intervals, data.mask))
    return J_theta, jnp.einsum("jip,jiq->pq", J_theta, J_theta)


def _linearisation(model, S, data, substeps, previous: _Linearisation | None) -> _Linearisation:
    r"""The cost and exact gradient at `(model, S)`; $J_\theta$ and $A$ computed there
    (`previous` `None`: $p$ forward passes per trajectory, the fit's largest cost) or kept
    from `previous` (its point near: the gradient, exact, fixes the minimum; $J_\theta$ only
    shapes the steps towards it)."""
    cost, g_theta, c = _pullback(model, S, data, substeps)
    J_theta, A = _theta_jacobian(model, S, data, substeps) if previous is None else (previous.J_theta, previous.A)
    return _Linearisation(cost, g_theta, c, J_theta, A)


class _Step(eqx.Module):
    """A Levenberg-Marquardt step: `dx`, `dS`, the decrease of the sum of squares its linear
    model predicts (`predicted`) and the conjugate gradient steps it took."""

    dx: jax.Array
    dS: jax.Array
    predicted: jax.Array
    cg_steps: jax.Array


def _scaled_cg(operator, rhs, rtol, max_steps, preconditioner=None, y0=None):
    r"""$x$ with $\|Mx - b\|_2 \le$ `rtol` $\|b\|_2$ (and the last step's change as small) by
    conjugate gradients (lineax) on the positive semidefinite `operator` $M$, whose diagonal
    is about 1 (scaled by the caller: Jacobi's preconditioner), with `preconditioner` (a
    function approximating $M^{-1}$, positive definite) if given, from `y0` (default 0):
    `(x, steps)`, `x` the last iterate at `max_steps` too."""
    structure = jax.eval_shape(lambda: rhs)
    M = lx.FunctionLinearOperator(operator, structure, tags=lx.positive_semidefinite_tag)
    solver = lx.CG(rtol=0.0, atol=rtol * jnp.sqrt(jnp.sum(rhs * rhs)), norm=optx.two_norm, max_steps=max_steps)
    options = {} if preconditioner is None else \
        {"preconditioner": lx.FunctionLinearOperator(preconditioner, structure, tags=lx.positive_semidefinite_tag)}
    if y0 is not None:
        options["y0"] = y0
    sol = lx.linear_solve(M, rhs, solver, throw=False, options=options)
    return sol.value, sol.stats["num_steps"], sol.result == lx.RESULTS.successful


@eqx.filter_jit
def _solve(model, S, data, lin, D_theta, counts, lam, substeps, cg_rtol, cg_max_steps) -> _Step:
    r"""The damped step (module docstring): $\theta$ eliminated,

    $$\big(J_s^\top (1 - J_\theta A_\lambda^{-1}J_\theta^\top) J_s + \lambda D_s\big)\,\delta s
    = -\big(c - J_s^\top J_\theta A_\lambda^{-1} g_\theta\big), \quad
    \delta\theta = -A_\lambda^{-1}(g_\theta + J_\theta^\top J_s\,\delta s),$$

    $A_\lambda = A + \lambda D_\theta$, $D_s = $ counts (the flow keeps norms: $G_j \approx$
    counts$_j$), by conjugate gradients on the system scaled by $((1 + \lambda)D_s)^{-1/2}$
    (the rollouts linearised once: each step one forward pass and its transpose per
    trajectory; $J_\theta$ applied as the matrix it is). `cg_rtol` the relative residual
    (the fit's forcing term)."""
    lu = jax.scipy.linalg.lu_factor(lin.A + lam * jnp.diag(D_theta))
    r, forward = jax.linearize(lambda Z: _all_residuals(model, Z, data, substeps), S)
    transpose = jax.linear_transpose(forward, S)

    def theta_part(u):  # J_theta A_lam^{-1} J_theta^T u, u (J, L, n)
        w = jax.scipy.linalg.lu_solve(lu, jnp.einsum("jip,ji->p", lin.J_theta, u.reshape(u.shape[0], -1)))
        return jnp.einsum("jip,p->ji", lin.J_theta, w).reshape(u.shape)

    scale = 1.0 / jnp.sqrt((1.0 + lam) * counts)[:, None]

    def reduced(Z):
        V = scale * Z
        u = forward(V)
        return scale * (transpose(u - theta_part(u))[0] + lam * counts[:, None] * V)

    v = jax.scipy.linalg.lu_solve(lu, lin.g_theta)
    rhs = -(lin.c - transpose(jnp.einsum("jip,p->ji", lin.J_theta, v).reshape(r.shape))[0])
    Z, steps, _ = _scaled_cg(reduced, scale * rhs, cg_rtol, cg_max_steps)
    dS = scale * Z  # an inexact step (CG stopped at max_steps) is still a step: the loss judges it
    u = forward(dS)
    dx = -jax.scipy.linalg.lu_solve(lu, lin.g_theta + jnp.einsum("jip,ji->p", lin.J_theta, u.reshape(u.shape[0], -1)))
    # the decrease of the model the step minimises, |r|^2 + 2 g.delta + |J delta|^2 (g exact, J
    # with J_theta as kept)
    change = u + jnp.einsum("jip,p->ji", lin.J_theta, dx).reshape(u.shape)
    return _Step(dx, dS, -2.0 * (lin.g_theta @ dx + jnp.sum(lin.c * dS)) - jnp.sum(change * change), steps)


def _profiled(model, S, data, J_theta, A, counts, substeps, cg_rtol, cg_max_steps, coarse_degree: int = 0, *,
              partial: tuple | None = None, after: Callable[..., None] | None = None, guess: tuple | None = None):
    r"""`(S_p, steps)`: $S_p = A - \sum_j B_j^\top G_j^{-1}B_j$, $B_j = J_{s_j}^\top J_{\theta,j}$,
    the parameters' Gauss-Newton matrix with the starts profiled out, and the conjugate gradient
    steps of each column's solve `(p,)`. $B$ by $p$ transposed passes, $X \approx G^{-1}B$ by
    conjugate gradients, one column after another (`_profiled_column`; NaN where a solve does
    not converge; a batch of columns runs to its slowest column's steps and costs as much as its
    columns one by one: BENCHMARKS.md, the standard errors' solves), preconditioned on the
    spherical harmonics of degrees 1 to `coarse_degree` (`_coarse`; 0: none; none where its
    $k$ passes outnumber $10p$: what it saves the solves, BENCHMARKS.md); the
    product taken as $B^\top X + X^\top B - X^\top GX$, whose error is $-E^\top GE$ for the
    solves' error $E = X - G^{-1}B$: second order in it (the first-order $B^\top X$ is off by
    $B^\top E$), so that solves to a relative residual $\epsilon$ give $S_p$ to about
    $\epsilon^2$ (one more pass per column for $GX$, and one rollout to linearise at). `partial`:
    `(B, X, GX, steps, C, k)` of an earlier call whose first `k` columns are done (a
    checkpoint's; `C` its coarse block, `None`: computed afresh); `after(k, B, X, GX, steps, C)`
    is called once column `k` is; `guess`: `(X0, C0)` of an earlier fit (`se_start`), X0 the
    solves' start (its non-finite columns 0), C0 the block if of this basis's size."""
    p = J_theta.shape[-1]
    if len(_coarse_basis(model.system, coarse_degree)) > 10 * p:
        coarse_degree = 0
    V = jnp.asarray(_coarse_basis(model.system, coarse_degree))
    kept = [np.asarray(c) for c in (None if partial is None else partial[4], None if guess is None else guess[1])
            if c is not None and np.shape(c) == (S.shape[0], V.shape[0], V.shape[0])]
    C = kept[0] if kept else _coarse_block(model, S, data, counts, substeps, coarse_degree)
    if partial is None:
        shape = (p, *S.shape)
        B, X, GX, steps, first = np.zeros(shape), np.zeros(shape), np.zeros(shape), np.zeros(p, np.int64), 0
    else:
        B, X, GX, steps = (np.array(a) for a in partial[:4])
        first = int(partial[5])
    C_inv = jnp.asarray(np.linalg.inv(C)) if C.shape[-1] else jnp.asarray(C)
    X0 = np.zeros((p, *S.shape)) if guess is None else np.where(np.isfinite(guess[0]), guess[0], 0.0)
    for k in range(first, p):
        b, x, gx, n = _profiled_column(model, S, data, J_theta[:, :, k], counts, substeps, cg_rtol, cg_max_steps,
                                       V, C_inv, jnp.asarray(X0[k]))
        B[k], X[k], GX[k], steps[k] = b, x, gx, n
        if after is not None:
            after(k, B, X, GX, steps, C)
    B, X, GX = B.reshape(p, -1), X.reshape(p, -1), GX.reshape(p, -1)
    BX = B @ X.T
    return np.asarray(A) - (BX + BX.T - X @ GX.T), steps, X


def _coarse_basis(system: Zeitlin, degree: int) -> np.ndarray:
    r"""An orthonormal basis `(k, n)` of the fields of the spherical harmonics of degrees 1 to
    `degree` ($k = (\min(\mathtt{degree}, N - 1) + 1)^2 - 1$; none for 0)."""
    lmax = min(degree, system.N - 1)
    k = (lmax + 1) ** 2 - 1
    if k <= 0:
        return np.zeros((0, system.dim))
    T = np.stack([system.state_from_harmonics(np.eye(system.dim)[i]) for i in range(1, k + 1)], axis=1)
    return np.linalg.qr(T)[0].T


def _coarse_block(model, S, data, counts, substeps, degree: int) -> np.ndarray:
    r"""$C_j = V^\top M_j V$ `(J, k, k)`, $M_j$ trajectory $j$'s $G_j$ scaled by its counts
    (`_profiled_column`), $V$ `_coarse_basis`: $k$ passes, once per fit."""
    V = jnp.asarray(_coarse_basis(model.system, degree))
    if V.shape[0] == 0:
        return np.zeros((S.shape[0], 0, 0))
    return np.asarray(_coarse_product(model, S, data, counts, substeps, V))


@eqx.filter_jit
def _coarse_product(model, S, data, counts, substeps, V):
    _, forward = jax.linearize(lambda Z: _all_residuals(model, Z, data, substeps), S)
    transpose = jax.linear_transpose(forward, S)
    scale = 1.0 / jnp.sqrt(counts)[:, None]
    MV = jax.lax.map(lambda v: scale * transpose(forward(scale * jnp.broadcast_to(v, S.shape)))[0], V)  # (k, J, n)
    C = jnp.einsum("in,kjn->jik", V, MV)
    return 0.5 * (C + jnp.swapaxes(C, 1, 2))


@eqx.filter_jit
def _step_error(model, S, data, substeps):
    r"""The step's error of the rollouts, $e \approx (\Phi^h - \Phi^{h/2})\,2^q/(2^q - 1)$ at
    order $q$ (Richardson), `(J, L, n)`, the padding 0."""
    coarse = jax.vmap(lambda s, dt: model.rollout_intervals(s, dt, substeps))(S, data.intervals)
    fine = jax.vmap(lambda s, dt: model.rollout_intervals(s, dt, 2 * substeps))(S, data.intervals)
    return (coarse - fine) * data.mask[..., None] * (2.0**model.order / (2.0**model.order - 1.0))


def _step_bias(model, S, data, substeps, profiled: np.ndarray, X: np.ndarray) -> np.ndarray:
    r"""The flat parameters' bias from the step's error (module docstring),
    $-S_p^{-1}(J_\theta^\top e - X J_s^\top e)$, `X` $= G^{-1}B$ `(p, J n)` of `_profiled`."""
    E = _step_error(model, S, data, substeps)
    _, g, c = _pullback(model, S, data, substeps, E)
    return -np.linalg.solve(profiled, np.asarray(g) - X @ np.asarray(c).reshape(-1))


@eqx.filter_jit
def _profiled_column(model, S, data, Jp, counts, substeps, cg_rtol, cg_max_steps, V, C_inv, x0):
    r"""`(b, x, Gx, steps)` of one column `Jp` `(J, L n)` of $J_\theta$: $b = J_s^\top$ `Jp`,
    $x \approx G^{-1}b$ by conjugate gradients from `x0` on $G$ scaled by counts$^{-1/2}$ (NaN if they
    do not converge), $Gx$ and their steps (`_profiled`). Preconditioned by block Jacobi on the
    orthonormal fields `V` `(k, n)` and their complement: $P^{-1} = V C_j^{-1} V^\top + 1 -
    VV^\top$, `C_inv` the $C_j^{-1}$ of `_coarse_block` (`k` = 0: none). On a sphere the low
    degrees hold most of $G$'s spread: a field's rotation by its degree-1 part moves every
    later snapshot (BENCHMARKS.md, "The step's order": the standard errors' solves)."""
    r, forward = jax.linearize(lambda Z: _all_residuals(model, Z, data, substeps), S)
    transpose = jax.linear_transpose(forward, S)
    scale = 1.0 / jnp.sqrt(counts)[:, None]
    b = transpose(Jp.reshape(r.shape))[0]

    def precondition(R):
        VR = jnp.einsum("in,jn->ji", V, R)
        return R + jnp.einsum("in,ji->jn", V, jnp.einsum("jik,jk->ji", C_inv, VR) - VR)

    Z, steps, ok = _scaled_cg(lambda Z: scale * transpose(forward(scale * Z))[0], scale * b, cg_rtol, cg_max_steps,
                              precondition if V.shape[0] else None, x0 / scale)
    x = jnp.where(ok, scale * Z, jnp.nan)
    return b, x, transpose(forward(x))[0], steps
