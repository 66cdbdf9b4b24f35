"""SINDy and weak SINDy (pysindy, extra `peers`) as models of a study: a sparse polynomial vector
field fitted to observations (from their finite differences, or in weak form: integrals against
test functions), integrated by LSODA."""

from __future__ import annotations

import abc
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


class _AbstractSINDyModel(AbstractStudyModel):
    """A sparse polynomial vector field fitted to observations: `vector_field(data)` is the
    fitted field (anything with pysindy's `predict`, `(n, dim) -> (n, dim)`); the rest is shared.
    Simulated by LSODA over the whole time span at once (tolerance 1e-12, as `SINDy.simulate`),
    stopped, and reported as diverged, once |y| exceeds 100 times its start."""

    @abc.abstractmethod
    def vector_field(self, data: Any) -> Any:
        """The fitted vector field of `data` (an `integrators.Observations`)."""

    def fit(self, system, data, *, progress=False) -> Fitted:
        with warnings.catch_warnings():  # pysindy warns about ill-conditioned fits of noisy data
            warnings.simplefilter("ignore")
            model = self.vector_field(data)
        h = float(np.median(np.concatenate([np.diff(t) for t in data.times])))
        return Fitted(SINDyFlow(system, h, model))

    def simulate(self, fitted, y0, n_steps, h) -> np.ndarray:
        t = h * np.arange(n_steps + 1)
        y0 = np.asarray(y0, dtype=np.float64).reshape(-1, fitted.step_map.system.dim)
        return np.stack([_flow(fitted.step_map.model, y, t, 100.0 * max(float(np.linalg.norm(y)), 1e-3))
                         for y in y0])


@dataclasses.dataclass(frozen=True)
class SINDyModel(_AbstractSINDyModel):
    """SINDy: polynomial library of degree 2, STLSQ; derivatives by smoothed finite differences
    (regular sampling: the smoother's window of 11 points, or the shortest trajectory's odd
    length) or finite differences (uneven: the smoother assumes even spacing); `threshold`,
    STLSQ's (pysindy's default 0.1)."""

    label: str = "SINDy"
    threshold: float = 0.1

    def vector_field(self, data):
        import pysindy as ps

        if data.is_regular():
            shortest = min(t.size for t in data.times)
            window = min(11, shortest if shortest % 2 else shortest - 1)
            derivative = ps.SmoothedFiniteDifference(smoother_kws={"window_length": window})
        else:
            derivative = ps.FiniteDifference()
        model = ps.SINDy(feature_library=ps.PolynomialLibrary(degree=2), optimizer=ps.STLSQ(threshold=self.threshold),
                         differentiation_method=derivative)
        return model.fit(list(data.states), t=list(data.times))


class PolynomialField:
    r"""The polynomial vector field $\dot y = \Theta(y)\,\Xi$ of identified coefficients: the
    monomials of a fitted `pysindy.PolynomialLibrary` (their `powers`, `(n_features, dim)`, and
    `names`) times `coefficients` `(dim, n_features)`, with pysindy's `predict` signature. What
    a weak-form fit identifies is integrated as this field (pysindy's weak library evaluates
    integrals over a time grid, not the field at a state)."""

    def __init__(self, library: Any, coefficients: np.ndarray):
        self.powers = np.asarray(library.powers_)
        self.names = tuple(library.get_feature_names())
        self.coefficients = np.asarray(coefficients, dtype=np.float64)

    def coefficient(self, component: int, powers: tuple[int, ...]) -> float:
        """The coefficient of the monomial `prod_i y_i^powers[i]` in `dot y[component]`."""
        (row,) = np.flatnonzero(np.all(self.powers == np.asarray(powers), axis=1))
        return float(self.coefficients[component, row])

    def predict(self, y: np.ndarray) -> np.ndarray:
        y = np.asarray(y, dtype=np.float64)
        return np.prod(y[:, None, :] ** self.powers, axis=2) @ self.coefficients.T


#: A trajectory gives weak-form rows if a test function's support can hold two of its
#: observations strictly inside (`pysindy.WeakPDELibrary` redraws a support until it does).
MIN_WEAK_OBSERVATIONS = 4


def _half_width(t: np.ndarray, window: int) -> float:
    """The half-width of the test functions' supports on the times `t`: `window` median steps
    wide, at most 0.98 of the span (a support lies inside the span), widened to that if no
    support of the narrower width holds two observations strictly inside (very uneven times)."""
    span = float(t[-1] - t[0])
    widest = 0.49 * span
    h = min(0.5 * window * float(np.median(np.diff(t))), widest)
    # the support (a, a + 2h) with a in [t0, t_end - 2h] holds t_i < t_{i+1} strictly inside iff
    # a lies in (t_{i+1} - 2h, t_i): some consecutive pair of interior times must allow it
    lo = np.maximum(t[2:-1] - 2.0 * h, t[0])
    hi = np.minimum(t[1:-2], t[-1] - 2.0 * h)
    return h if np.any(lo < hi) else widest


@dataclasses.dataclass(frozen=True)
class WeakSINDyModel(_AbstractSINDyModel):
    r"""Weak SINDy: the coefficients $\Xi$ of $\dot y = \Theta(y)\,\Xi$ (the polynomial library
    of degree 2, as SINDy's) fitted in weak form, $-\int y\,\phi_k'\,dt = \int \Theta(y)\,\phi_k\,dt\;\Xi$
    for test functions $\phi_k$ (pysindy's `WeakPDELibrary` on a 1-D grid of the times: $(1 -
    s^2)^4$ on supports drawn at random; the integrals are those of the piecewise-linear
    interpolants of $y$ and $\Theta(y)$ between observations, exact on any grid), by STLSQ (pysindy's defaults, as SINDy's); no derivative of the data is
    taken. Then simulated as the polynomial field with those coefficients (`PolynomialField`).

    pysindy's library has one time grid, so each trajectory has its own library on its own
    times (`window` median steps per support, `test_functions` times its number of
    observations of them, `K`; the draws seeded by `seed` and the trajectory's index) and the rows of all trajectories are stacked
    into one STLSQ fit, unweighted (a wider support, more observations averaged, weighs more).
    Uneven times are therefore taken as they are, no resampling: `accepts` every sampling. A trajectory of fewer
    than `MIN_WEAK_OBSERVATIONS` observations gives no row; data without a longer one are not
    accepted."""

    label: str = "weak SINDy"
    window: int = 9
    test_functions: int = 4
    seed: int = 0

    def __post_init__(self):
        for name, least in (("window", 2), ("test_functions", 1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < least:
                raise ValueError(f"{name} must be an int >= {least}; got {value!r}")

    def accepts(self, data) -> bool:
        return any(t.size >= MIN_WEAK_OBSERVATIONS for t in data.times)

    def vector_field(self, data):
        import pysindy as ps

        if not self.accepts(data):
            raise ValueError(f"weak SINDy needs a trajectory of at least {MIN_WEAK_OBSERVATIONS} observations; "
                             f"the longest has {max(t.size for t in data.times)}")
        features, targets = [], []
        for j, (t, y) in enumerate(zip(data.times, data.states)):
            if t.size < MIN_WEAK_OBSERVATIONS:
                continue
            state = np.random.get_state()  # the library draws its supports from numpy's global stream
            np.random.seed(self.seed + j)
            try:
                library = ps.WeakPDELibrary(function_library=ps.PolynomialLibrary(degree=2),
                                            spatiotemporal_grid=t, K=self.test_functions * t.size,
                                            H_xt=_half_width(t, self.window))
            finally:
                np.random.set_state(state)
            features.append(np.asarray(library.fit_transform(y)))
            targets.append(np.asarray(library.convert_u_dot_integral(y)))
        optimizer = ps.STLSQ().fit(np.concatenate(features), np.concatenate(targets))
        return PolynomialField(library.function_library, optimizer.coef_)
