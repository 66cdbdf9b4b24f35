r"""The `LevenbergMarquardt` stage of `learn.fit`: Levenberg-Marquardt on the residuals $r(x)$
of a least-squares objective (`learn.AbstractLeastSquares`: its `residuals(y, args)`, whose mean
square is the loss), over the flat trainable leaves $x$ of $y$.

Each step evaluates $r$ and its Jacobian $J$ once (one compiled call: `jax.jacfwd`, or the
objective's own `jacobian` where it knows a block structure (`learn.AbstractStructuredJacobian`),
e.g. fitted starts; past `DENSE_JACOBIAN` entries such an objective's $J^TJ$ and $J^Tr$ summed
from the blocks, never holding $J$), then solves the
damped normal equations $(J^TJ + \lambda D)\delta = -J^Tr$, $D = \mathrm{diag}(J^TJ)$ (the
largest seen: Marquardt's scaling, Moré 1978), by a lineax Cholesky, trying larger $\lambda$ until
the step lowers $\|r\|^2$; $\lambda$ is updated by Nielsen's rule. The loop runs on the host
between two small compiled functions, so a map is compiled twice (residuals, Jacobian), not
into one solver program: optimistix's `LevenbergMarquardt` on the same losses spends longer
compiling a G-LPNet fit than running it (benchmarks, [Levenberg-Marquardt on the trajectory
loss][levenberg-marquardt-on-the-trajectory-loss-learnlevenbergmarquardt]).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
from jax.flatten_util import ravel_pytree

from integrators.internals import serial_lapack_block
from liepoisson.internals import positive_int

from ._compiled import AbstractAtStructure, compiled
from ._loop import AbstractSolver, Step, iterate, losses_step
from ._problem import AbstractLeastSquares, AbstractProblem, AbstractStructuredJacobian
from ._stage import Context, Linearisation, Result

#: Trial steps per iteration at most (each multiplies the damping by a growing factor).
MAX_TRIALS = 30

#: The largest Jacobian (residuals x unknowns) a step may hold: 1.6 GB of float64.
MAX_JACOBIAN = 200_000_000

#: Past this many Jacobian entries (residuals x unknowns) a structured objective's normal
#: equations are summed block by block (`AbstractStructuredJacobian.normal_equations`), never
#: holding $J$: 20M (160 MB), above every W study's Jacobian, whose steps stay those of
#: $J^TJ$ from one matrix.
DENSE_JACOBIAN = 20_000_000

#: The most forward passes (Jacobian columns computed at once) a step may take: `jax.jacfwd`
#: holds every pass's intermediates together.
MAX_PASSES = 2000

#: The damping lambda is kept in this range (relative to the Marquardt scaling D).
LAMBDA_RANGE = (1e-16, 1e16)

#: `LevenbergMarquardt(rtol=...)` compares the loss with its value this many steps earlier.
WINDOW = 3

#: `LevenbergMarquardt(target=...)` judges the loss's rate after this many steps at the
#: earliest: the first steps, while the damping settles, say little about the rate.
TARGET_AFTER = 6


class _Residuals(AbstractAtStructure):
    r"""The residuals $r(x)$ `(n,)` and Jacobian $J(x)$ `(n, p)` of `objective` for the `y`
    whose flat trainable leaves are $x$, compiled once per structure. The Jacobian of a
    fit's last step travels in its result (`Result.linearisation`): the criterion and the
    discretisation error read the fitted map's residuals and Jacobian there (one evaluation
    fewer per fit; BENCHMARKS.md, "Every W4 fit under 2 minutes on 2 quiet cores")."""

    def __init__(self, objective: AbstractLeastSquares, y: Any):
        super().__init__(objective, y)
        self.residuals = jax.jit(self._residuals)
        self.jacobian = jax.jit(self._jacobian)
        self.normal_equations = jax.jit(self._normal_equations)

    def _residuals(self, x, args):
        return self.objective.residuals(self.model(x), args).reshape(-1)

    def _jacobian(self, x, args):
        return self.objective.jacobian(self.model(x), args)

    def _normal_equations(self, x, args):
        return self.objective.normal_equations(self.model(x), args)


def residuals_of(objective: AbstractLeastSquares, y: Any) -> _Residuals:
    """The compiled residuals and Jacobian of `objective` at `y`'s structure."""
    return compiled(("residuals", _Residuals(objective, y)), lambda: _Residuals(objective, y))


@jax.jit
def _normal_equations(r, J):
    return J.T @ J, J.T @ r


@jax.jit
def _damped_step(A, g, D, lam):
    r"""$\delta$ solving $(A + \lambda\,\mathrm{diag}(D))\delta = -g$ (lineax Cholesky; NaN where
    the damped matrix is not positive definite to round-off)."""
    operator = lx.MatrixLinearOperator(A + lam * jnp.diag(D), lx.positive_semidefinite_tag)
    return lx.linear_solve(operator, -g, lx.Cholesky(), throw=False).value


@dataclasses.dataclass(frozen=True)
class LevenbergMarquardt(AbstractSolver):
    r"""Levenberg-Marquardt on the residuals $r$ of a least-squares objective
    (`learn.AbstractLeastSquares`: the state and alpha losses, `learn.TrajectoryLoss`). Each
    step evaluates $r$ and its Jacobian $J$ once and solves
    $(J^TJ + \lambda D)\delta = -J^Tr$ by a lineax Cholesky, $D$ the largest
    $\mathrm{diag}(J^TJ)$ seen (Marquardt's scaling), $\lambda$ by Nielsen's rule; the loop
    runs on the host between two compiled functions: optimistix's `LevenbergMarquardt`, one
    compiled program, takes longer to compile a G-LPNet fit than to run it.

    For a few dozen to a few hundred unknowns it reaches the minimum of a least-squares loss
    in tens of steps where BFGS takes hundreds (benchmarks, [Levenberg-Marquardt on the
    trajectory loss][levenberg-marquardt-on-the-trajectory-loss-learnlevenbergmarquardt]);
    each step costs $p$ forward passes for $p$ weights ($p + d$ with fitted starts: a
    structured Jacobian), so for the thousands of weights of an MLP use `learn.ScipyLBFGSB`
    (a step that would hold more than 2000 passes is refused).

    `iterations`: steps at most; `rtol`: stop once the loss has fallen by less than `rtol` of
    its value over the last 3 steps (0: only when no damping lowers it); `target`: a loss that
    only matters if reached (a fit that must beat another's information criterion): stop once,
    falling at its rate over the last 3 steps for all the steps left, the loss would stay
    above it, or, where that rate is lower than over the 3 steps before, falling by decreases
    that keep shrinking in that ratio (Aitken's extrapolation of a linearly converging fit's
    limit) (judged after 6 steps). A fit whose decreases shrink more slowly than that, or grow
    again, is stopped early by the second rule (BENCHMARKS.md, "Every W4 fit under 2
    minutes"). Every accepted step lowers the training loss; the result is the last step's
    (`learn.KeepIfBetter` keeps it only if it lowers the selection loss; `learn.WarmStart`
    first fits the simpler problem a G-LPNet offers). Its result carries the residuals and
    Jacobian of its last step (`Result.linearisation`). Deterministic; resumable with a
    `learn.Checkpoint`.
    """

    iterations: int = 200
    rtol: float = 1e-10
    target: float | None = None
    resumable: ClassVar[bool] = True

    def __post_init__(self):
        positive_int(self.iterations, "LevenbergMarquardt.iterations")
        if isinstance(self.rtol, bool) or not isinstance(self.rtol, (int, float)) or not 0 <= self.rtol < 1:
            raise ValueError(f"LevenbergMarquardt.rtol must be a number in [0, 1); got {self.rtol!r}")
        if self.target is not None and (isinstance(self.target, bool) or not isinstance(self.target, (int, float))
                                        or not self.target >= 0):
            raise ValueError(f"LevenbergMarquardt.target must be None or a loss >= 0; got {self.target!r}")

    def check(self, problem: AbstractProblem, context: Context) -> None:
        super().check(problem, context)
        if not isinstance(problem.objective, AbstractLeastSquares):
            raise ValueError(f"learn.LevenbergMarquardt needs a least-squares loss (a learn.AbstractLeastSquares, "  # noqa: TRY004
                             f"with residuals); {problem.objective!r} is not one: use learn.ScipyBFGS")
        check_size(problem.objective, problem.y0, problem.train)

    def run(self, problem: AbstractProblem, context: Context) -> Result:
        self.check(problem, context)
        # JAX's Cholesky each step runs in SciPy's OpenBLAS, whose idle workers spin on the
        # cores the Jacobian's XLA threads need (BENCHMARKS.md, "W2 `--full`: seven systems")
        with serial_lapack_block():
            return iterate(self, problem, context)

    def init(self, problem: AbstractProblem, context: Context) -> Any:
        return self._at(problem, problem.y0, context.desc or f"{problem.name} Levenberg-Marquardt")

    def _at(self, problem: AbstractProblem, model: Any, desc: str) -> Any:
        """The state at `model`: its residuals and Jacobian (or normal equations)."""
        args, objective = problem.train, problem.objective
        fn = residuals_of(objective, model)
        x = ravel_pytree(eqx.filter(model, eqx.is_inexact_array))[0]
        state = _State(fn, args, check_size(objective, model, args), float(objective.count(model, args)), desc, x)
        state.linearise(x)
        if not np.isfinite(state.cost):
            raise FloatingPointError(f"{desc}: the loss at the start is not finite; check the weights and the data")
        return state

    def resume(self, problem: AbstractProblem, context: Context, state: Any, attrs: dict[str, Any],
               groups: dict[str, Any], weights: Any) -> Any:
        lam, nu, D = groups["optimizer"]
        state = self._at(problem, weights, state.desc)  # from the same number: the Jacobian's call
        state.D, state.lam, state.nu = jnp.asarray(np.asarray(D)), float(lam), float(nu)
        return state

    def optimizer_leaves(self, state: Any) -> list[Any]:
        return [np.asarray(state.lam), np.asarray(state.nu), np.asarray(state.D)]

    def terminate(self, problem: AbstractProblem, state: Any, losses: list[float]) -> bool:
        return not np.isfinite(state.cost) or _converged(losses, self.rtol) or \
            _out_of_reach(losses, self.target, self.iterations)

    def step(self, problem: AbstractProblem, state: Any) -> tuple[Any, Step]:
        A, g = state.J if state.blockwise else _normal_equations(state.r, state.J)
        if not bool(jnp.all(jnp.isfinite(A)) and jnp.all(jnp.isfinite(g))):
            raise FloatingPointError(f"{state.desc}: the Jacobian after step {state.done} is not finite (the map's "
                                     "derivatives overflow at these weights); try fewer iterations or another start")
        diag = jnp.diag(A)
        # a weight the residuals do not see gets a scale from the others (MINPACK's rule)
        diag = jnp.maximum(diag, jnp.finfo(A.dtype).eps * jnp.maximum(jnp.max(diag), jnp.finfo(A.dtype).tiny))
        state.D = diag if state.D is None else jnp.maximum(state.D, diag)
        lam, nu = state.lam, state.nu
        for _ in range(MAX_TRIALS):
            delta = _damped_step(A, g, state.D, lam)
            if bool(jnp.all(jnp.isfinite(delta))):
                x_new = state.x + delta
                r_new = state.fn.residuals(x_new, state.args)
                cost_new = float(r_new @ r_new)
                predicted = -float(2 * g @ delta + delta @ (A @ delta))  # model decrease of sum r^2
                if np.isfinite(cost_new) and cost_new < state.cost and predicted > 0:
                    rho = (state.cost - cost_new) / predicted
                    state.lam = max(lam * max(1 / 3, 1 - (2 * rho - 1) ** 3), LAMBDA_RANGE[0])
                    state.nu = 2.0
                    state.linearise(x_new)
                    state.done += 1
                    return state, losses_step(state.done - 1, [state.cost / state.scale])
            lam = min(lam * nu, LAMBDA_RANGE[1])
            nu *= 2
        # no damping lowers the loss: a minimum to round-off
        state.lam, state.nu = lam, nu
        return state, losses_step(state.done, [], stop="no damping lowers the loss")

    def current(self, state: Any) -> Any:
        return state.fn.model(state.x)

    def postprocess(self, problem: AbstractProblem, state: Any, best: Any, stopped: str):
        linearisation = None
        if not state.blockwise and state.J.size <= DENSE_JACOBIAN:
            linearisation = Linearisation(state.x, state.args, state.r, state.J)
        return state.fn.model(state.x), {}, linearisation


@dataclasses.dataclass
class _State:
    r"""Where a Levenberg-Marquardt run is: `x` and its residuals `r`, Jacobian `J` (or the
    normal equations $(J^TJ, J^Tr)$ from the blocks: `blockwise`) and sum of squares `cost`;
    the Marquardt scaling `D`, the damping `lam` and its growth factor `nu`; `scale` the
    residuals' count (sum of squares -> loss)."""

    fn: _Residuals
    args: Any
    blockwise: bool
    scale: float
    desc: str
    x: jax.Array
    r: Any = None
    J: Any = None
    cost: float = float("nan")
    D: Any = None
    lam: float = 1e-3
    nu: float = 2.0
    done: int = 0

    def linearise(self, x: jax.Array) -> None:
        """Move to `x`: `(r, J)` there, or `(r, (J^T J, J^T r))` from the Jacobian's blocks."""
        self.x = x
        if self.blockwise:
            r, A, g = self.fn.normal_equations(x, self.args)
            self.r, self.J = r, (A, g)
        else:
            self.r, self.J = self.fn.jacobian(x, self.args)
        self.cost = float(self.r @ self.r)  # always from the Jacobian's call


def check_size(objective: AbstractLeastSquares, y: Any, args: Any) -> bool:
    """Whether a Levenberg-Marquardt step on `y` sums its normal equations block by block (a
    structured objective whose Jacobian has more than `DENSE_JACOBIAN` entries); `ValueError`
    if it would hold too much for memory (`MAX_JACOBIAN` numbers, of the Jacobian or of the
    blocks and the normal equations) or take more than `MAX_PASSES` forward passes."""
    fn = residuals_of(objective, y)
    x = ravel_pytree(eqx.filter(y, eqx.is_inexact_array))[0]
    n_unknowns = x.size
    n_residuals = jax.eval_shape(fn.residuals, x, args).shape[0]
    passes = objective.forward_passes(y)
    entries = n_residuals * n_unknowns
    blockwise = False
    if isinstance(objective, AbstractStructuredJacobian) and entries > DENSE_JACOBIAN:
        blocks = objective.block_entries(y, args)
        blockwise = blocks < entries
        entries = min(entries, blocks)
    if entries > MAX_JACOBIAN or passes > MAX_PASSES:
        held = f"{entries} numbers of its blocks and normal equations" if blockwise else "the whole Jacobian"
        raise ValueError(
            f"learn.LevenbergMarquardt: the Jacobian would be {n_residuals} residuals x {n_unknowns} unknowns, "
            f"{passes} forward passes (at most {MAX_PASSES}), holding {held} (at most {MAX_JACOBIAN}, "
            f"{8 * MAX_JACOBIAN / 1e9:.1f} GB); it suits maps of a few hundred weights (a G-LPNet); for an MLP use "
            "learn.ScipyLBFGSB or learn.Adam"
        )
    return blockwise


def _out_of_reach(values, target, iterations) -> bool:
    r"""Whether the loss would stay above `target` (judged after `TARGET_AFTER` steps): falling
    by its factor over the last `WINDOW` steps again every `WINDOW` steps until `iterations`;
    or, once its decrease over the last `WINDOW` steps is smaller than over the `WINDOW`
    before, by decreases that keep shrinking in that ratio $\rho$ (a linearly converging fit:
    $\log L$ falls by $d\rho + d\rho^2 + \dots = d\rho/(1 - \rho)$ more, Aitken's extrapolation
    of its limit; capped at the steady pace)."""
    if target is None or len(values) < max(TARGET_AFTER, WINDOW + 1) or values[-1] <= target:
        return False
    before = values[-1 - WINDOW]
    if not before > 0 or not values[-1] > 0:
        return False
    decrease = math.log(max(before / values[-1], 1.0))  # of log L, per WINDOW steps
    left = (iterations - len(values)) / WINDOW
    fall = decrease * left  # at a steady pace
    if len(values) > 2 * WINDOW and values[-1 - 2 * WINDOW] > 0:
        earlier = math.log(max(values[-1 - 2 * WINDOW] / before, 1.0))
        if decrease < earlier:  # slowing: a geometric series of ratio decrease / earlier
            fall = min(fall, decrease * decrease / (earlier - decrease))
    return values[-1] * math.exp(-fall) > target


def _converged(values, rtol) -> bool:
    """Whether the loss fell by less than `rtol` of its value over the last `WINDOW` steps."""
    if rtol <= 0 or len(values) <= WINDOW:
        return False
    before = values[-1 - WINDOW]
    return before - values[-1] <= rtol * abs(before)


