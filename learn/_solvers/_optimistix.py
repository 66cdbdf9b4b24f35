r"""Any optimistix solver as a stage of `learn.fit`: `learn.Optimistix(optx.BFGS(rtol, atol))`,
`learn.Optimistix(optx.LevenbergMarquardt(rtol, atol))`. The whole solve is one compiled
program (optimistix's design); where the library's own stages are faster on its problems is in
the benchmarks ([Solver stages: optimistix beside the library's
own][solver-stages-optimistix-beside-the-librarys-own-issue-39-benchmarkssolver_stagespy])."""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import equinox as eqx
import optimistix as optx

from liepoisson.internals import positive_int

from ._problem import AbstractLeastSquares, AbstractProblem
from ._stage import AbstractStage, Context, Result, finished_record, history


@dataclasses.dataclass(frozen=True)
class Optimistix(AbstractStage):
    r"""An optimistix solver as a stage: a minimiser (`optx.BFGS`, `optx.NonlinearCG`,
    `optx.OptaxMinimiser`, ...) on the loss, or a least-squares solver
    (`optx.LevenbergMarquardt`, `optx.GaussNewton`, ...) on the residuals of a
    `learn.AbstractLeastSquares` objective; at most `max_steps` steps; the result is the
    solver's (`learn.KeepIfBetter` keeps it only if it lowers the selection loss), its record's
    `details["result"]` optimistix's `RESULTS`. The history holds the final loss only (the
    solve is one compiled program)."""

    solver: Any
    max_steps: int = 1000

    def __post_init__(self):
        if not isinstance(self.solver, (optx.AbstractMinimiser, optx.AbstractLeastSquaresSolver)):
            raise TypeError("Optimistix.solver must be an optimistix minimiser or least-squares solver (e.g. "
                            f"optx.BFGS(rtol=1e-12, atol=1e-14)); got {type(self.solver).__name__}")
        positive_int(self.max_steps, "Optimistix.max_steps")

    @property
    def budget(self) -> int:
        return self.max_steps

    def with_budget(self, budget: int) -> Optimistix:
        return dataclasses.replace(self, max_steps=budget)

    def check(self, problem: AbstractProblem, context: Context) -> None:
        if isinstance(self.solver, optx.AbstractLeastSquaresSolver) and \
                not isinstance(problem.objective, AbstractLeastSquares):
            raise ValueError(f"{type(self.solver).__name__} is a least-squares solver; {problem.objective!r} has no "  # noqa: TRY004
                             "residuals (not a learn.AbstractLeastSquares): use an optimistix minimiser")

    def run(self, problem: AbstractProblem, context: Context) -> Result:
        self.check(problem, context)
        params, static = eqx.partition(problem.y0, eqx.is_inexact_array)
        objective = problem.objective
        start = time.perf_counter()
        if isinstance(self.solver, optx.AbstractLeastSquaresSolver):
            def residuals(p, args):
                return objective.residuals(eqx.combine(p, static), args)

            solution = optx.least_squares(residuals, self.solver, params, args=problem.train,
                                          max_steps=self.max_steps, throw=False)
        else:
            def value(p, args):
                return objective(eqx.combine(p, static), args)

            solution = optx.minimise(value, self.solver, params, args=problem.train, max_steps=self.max_steps,
                                     throw=False)
        y = eqx.combine(solution.value, static)
        steps = int(solution.stats["num_steps"])
        loss = float(objective(y, problem.train))
        record = finished_record(problem, self, steps, start, y, {"result": str(solution.result)})
        record = dataclasses.replace(record, settings={"solver": type(self.solver).__name__,
                                                       "max_steps": self.max_steps})
        return Result(y, record, history([loss], [steps]))
