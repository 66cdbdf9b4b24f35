r"""The units of a data set: a fit starts from a least-squares estimate in the data's own units
and scales its pieces' inputs by the states' size, so the same measurements in seconds or
milliseconds, in radians per second or per hour, give the same learned motion (conventions,
[Units][units])."""

from __future__ import annotations

from integrators import Observations
from liepoisson.systems import AbstractLiePoissonSystem, AbstractPoissonSystem


def state_size(system: AbstractPoissonSystem, data: Observations) -> float:
    r"""The states' RMS size $\sqrt{\operatorname{mean}|y|^2}$ on a Lie-Poisson system (its
    bracket is linear in $y$, so scaling the states is a change of units); 1 on another Poisson
    system, whose bracket has its own scale, and when every state is 0 (nothing sets a scale)."""
    size = data.rms_size() if isinstance(system, AbstractLiePoissonSystem) else 1.0
    return size if size > 0.0 else 1.0
