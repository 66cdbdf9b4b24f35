"""SINDy (pysindy, extra `peers`) as a model of a study: a sparse polynomial vector field fitted to
observations, integrated by LSODA."""

from __future__ import annotations

import dataclasses
import importlib.util
import warnings
from typing import Any

import equinox as eqx
import jax
import numpy as np
from scipy.integrate import solve_ivp

import integrators as it
import liepoisson as lp

from ._study import AbstractStudyModel, Fitted

RTOL = 1e-12  # LSODA's tolerances, as `pysindy.SINDy.simulate`'s


def sindy_available() -> bool:
    return importlib.util.find_spec("pysindy") is not None


def _flow(model: Any, y: np.ndarray, t: np.ndarray, blow_up: float = np.inf) -> np.ndarray:
    """The states of the fitted vector field `model.predict` at the times `t` from `y` by LSODA,
    stopped once |y| exceeds `blow_up` (the rows after it are NaN)."""
    out = np.full((t.size, y.size), np.nan)

    def escape(_, z):
        return blow_up - np.linalg.norm(z)

    escape.terminal = True
    sol = solve_ivp(lambda _, z: model.predict(z[None])[0], (t[0], t[-1]), y, method="LSODA", t_eval=t,
                    rtol=RTOL, atol=RTOL, events=escape)
    out[: sol.y.shape[1]] = sol.y.T
    return out


class SINDyFlow(it.AbstractStepMap):
    """The flow over `h` of a fitted SINDy vector field (`model.predict`), by LSODA on the host
    (`jax.pure_callback`): a step map, so that its rollouts are measured like every other
    (`integrators.rollout_figures`). Not differentiable: it has no Poisson defect."""

    system: lp.systems.AbstractPoissonSystem
    h: float | None
    model: Any = eqx.field(static=True)

    def step(self, y: jax.Array) -> jax.Array:
        def flow(y, h):
            return _flow(self.model, np.asarray(y), np.array([0.0, float(h)]))[-1].astype(y.dtype)

        return jax.pure_callback(flow, jax.ShapeDtypeStruct(y.shape, y.dtype), y, self.h, vmap_method="sequential")

    @property
    def exact_flows_per_step(self) -> int:
        return 0


@dataclasses.dataclass(frozen=True)
class SINDyModel(AbstractStudyModel):
    """SINDy: polynomial library of degree 2, STLSQ; derivatives by smoothed finite differences
    (regular sampling: the smoother's window of 11 points, or the shortest trajectory's odd
    length) or finite differences (uneven: the smoother assumes even spacing). Simulated by
    LSODA over the whole time span at once (tolerance 1e-12, as `SINDy.simulate`), stopped, and
    reported as diverged, once |y| exceeds 100 times its start."""

    label: str = "SINDy"

    def fit(self, system, data, *, progress=False) -> Fitted:
        import pysindy as ps

        if data.is_regular():
            shortest = min(t.size for t in data.times)
            window = min(11, shortest if shortest % 2 else shortest - 1)
            derivative = ps.SmoothedFiniteDifference(smoother_kws={"window_length": window})
        else:
            derivative = ps.FiniteDifference()
        model = ps.SINDy(feature_library=ps.PolynomialLibrary(degree=2), optimizer=ps.STLSQ(),
                         differentiation_method=derivative)
        with warnings.catch_warnings():  # pysindy warns about ill-conditioned fits of noisy data
            warnings.simplefilter("ignore")
            model.fit(list(data.states), t=list(data.times))
        h = float(np.median(np.concatenate([np.diff(t) for t in data.times])))
        return Fitted(SINDyFlow(system, h, model))

    def simulate(self, fitted, y0, n_steps, h) -> np.ndarray:
        t = h * np.arange(n_steps + 1)
        y0 = np.asarray(y0, dtype=np.float64).reshape(-1, fitted.step_map.system.dim)
        return np.stack([_flow(fitted.step_map.model, y, t, 100.0 * max(float(np.linalg.norm(y)), 1e-3))
                         for y in y0])
