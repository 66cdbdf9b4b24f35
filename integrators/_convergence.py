r"""Observed order of convergence: the global error of a family of step maps against heyoka at
several step sizes, and the slope of its log-log fit."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike

from liepoisson.internals import check_system, positive_float, states
from liepoisson.systems import AbstractPoissonSystem

from ._ground_truth import ground_truth
from ._step_map import AbstractStepMap


@dataclasses.dataclass(frozen=True)
class Convergence:
    """Global error at `t_final` (max over trajectories) for each step size `hs`, and the
    observed `order`: the slope of a least-squares line through $(\\log h, \\log e)$. Its
    figure: `plot_convergence`."""

    hs: np.ndarray
    errors: np.ndarray
    order: float


def convergence(
    make: Callable[[float], AbstractStepMap],
    system: AbstractPoissonSystem,
    y0s: ArrayLike,
    *,
    t_final: float,
    hs: Sequence[float],
) -> Convergence:
    r"""The error at `t_final` of `make(h)` for each `h` in `hs` against heyoka, and the
    observed order. `make(h)` returns a step map of `system` with step `h` (a splitting
    method, `lambda h: Strang(system, h)`, or a learned map run at another step than it was
    trained at, `lambda h: eqx.tree_at(lambda m: m.h, net, h)`); each `h` must divide
    `t_final`."""
    system = check_system(system)
    t_final = positive_float(t_final, "t_final")
    y0s = states(y0s, "y0s", system.dim).reshape(-1, system.dim)
    hs = np.asarray([positive_float(h, f"hs[{i}]") for i, h in enumerate(hs)])
    if len(hs) < 2:
        raise ValueError(f"hs must hold at least 2 step sizes to fit an order; got {len(hs)}")
    truth = ground_truth(system, y0s, h=t_final, n_steps=1).states[:, -1]
    errors = []
    for i, h in enumerate(hs):
        n = round(t_final / h)
        if n < 1 or not math.isclose(n * h, t_final, rel_tol=1e-9):
            raise ValueError(f"hs[{i}] = {h:g} must divide t_final = {t_final:g}")
        m = make(float(h))
        if not isinstance(m, AbstractStepMap) or m.system != system:
            raise TypeError(f"make({h:g}) must return an integrators.AbstractStepMap of {system!r}; got {m!r}")
        y = np.asarray(m.rollout(y0s, n, save_every=n, nonfinite="return"))[:, -1]
        errors.append(float(np.max(np.linalg.norm(y - truth, axis=-1))))
    errors = np.asarray(errors)
    usable = errors > 0
    if usable.sum() < 2 or not np.all(np.isfinite(errors)):
        raise ValueError(f"cannot fit an order: errors {errors.tolist()} (need 2 finite, non-zero)")
    order = float(np.polyfit(np.log(hs[usable]), np.log(errors[usable]), 1)[0])
    return Convergence(hs, errors, order)
