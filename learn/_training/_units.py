r"""The units of a data set: a fit's starting weights are drawn for unit-free data and carried
to the data's units, so the same measurements in seconds or milliseconds, in radians per second
or per hour, give the same learned motion (conventions, [Units][units])."""

from __future__ import annotations

import numpy as np

from integrators import Observations
from liepoisson.systems import AbstractLiePoissonSystem, AbstractPoissonSystem

#: One unit of time is this many median steps between observations: for the steps of 0.1 the
#: starting weights were tuned on, one unit of time.
STEPS_PER_TIME_UNIT = 10.0


def observation_units(system: AbstractPoissonSystem, data: Observations) -> tuple[float, float]:
    r"""`(time, size)`: `STEPS_PER_TIME_UNIT` median steps of `data`, and the states' RMS size
    $\sqrt{\operatorname{mean}|y|^2}$ on a Lie-Poisson system (its bracket is linear in $y$,
    so scaling the states is a change of units; 1 on another Poisson system, whose bracket has
    its own scale)."""
    steps = data.intervals()[2]
    time = STEPS_PER_TIME_UNIT * float(np.median(steps))
    size = data.rms_size() if isinstance(system, AbstractLiePoissonSystem) else 1.0
    if not size > 0.0:  # every state 0: nothing sets a scale
        size = 1.0
    return time, size
