r"""Sub-steps from the data: a fitted map's own discretisation error kept below its misfit.

A map fitted at a step $h$ fits the data with the modified Hamiltonian of its method at that
step, not with the system's: at $h|\xi| \sim 0.1$ (a 10-ms interval at 10 rad/s) a Strang
step's error is comparable to gyroscope noise, and the learned inertia moves by the error.
The map's own discretisation error is measurable on the fit (`discretisation_ssr`: its
predictions at the fit's sub-steps against twice as many); while it is above `STEP_ERROR_RATIO`
of the fit's residuals, the sub-steps are doubled and the map refitted from where it was."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

from ._observed import discretisation_ssr, residual_ssr

#: The largest discretisation error a fit keeps, as a fraction of its residuals' sum of squares:
#: 0.1 of the sum of squares is a third of the residuals' RMS, so the step moves the fit by
#: less than the noise does.
STEP_ERROR_RATIO = 0.1

#: At most this many doublings of the sub-steps (8x the first).
MAX_DOUBLINGS = 3


@dataclasses.dataclass(frozen=True)
class StepCheck:
    """The sub-steps a fit ended with (`substeps` per sub-interval of at most `max_step`), its
    discretisation error and residuals' sums of squares, and how many doublings it took."""

    substeps: int
    discretisation_ssr: float
    ssr: float
    doublings: int

    @property
    def within_noise(self) -> bool:
        return self.discretisation_ssr <= STEP_ERROR_RATIO * self.ssr


def solve_within_noise(problem: Any, stages: Sequence[Any], context: Any, *,
                       ratio: float = STEP_ERROR_RATIO, doublings: int = MAX_DOUBLINGS
                       ) -> tuple[Any, list[Any], StepCheck]:
    """`solve(problem, stages, context)`, then, while the fitted map's discretisation error is
    above `ratio` of its residuals' sum of squares, the sub-steps doubled and the stages run
    again from the fit (at most `doublings` times); `(problem, results, StepCheck)`."""
    from ._fit import solve

    problem, results = solve(problem, stages, context)
    for k in range(doublings + 1):
        fitted = problem.y0
        ssr = residual_ssr(problem, fitted, results[-1].linearisation)
        error = discretisation_ssr(problem, fitted, results[-1].linearisation)
        check = StepCheck(problem.train.substeps, error, ssr, k)
        if error <= ratio * ssr or k == doublings:
            return problem, results, check
        train = dataclasses.replace(problem.train, substeps=2 * problem.train.substeps)
        description = dataclasses.replace(problem.description, substeps=train.substeps * (
            problem.description.substeps or 1) // problem.train.substeps)
        problem = dataclasses.replace(problem, train=train, description=description)
        problem, more = solve(problem, stages, context)
        results = results + more
    return problem, results, check
