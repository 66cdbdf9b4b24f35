"""SINDy and weak SINDy (pysindy, extra `peers`) as models of a study: a sparse polynomial vector
field fitted to observations (from their estimated derivatives, or in weak form: integrals
against test functions), integrated by LSODA.

Their settings are chosen on the training data by one rule, every study's
(`choose_sparse_field`; docs/conventions.md, "Peers"): every STLSQ threshold of `THRESHOLDS`,
the library with and without its constant, and SINDy's derivative (`DERIVATIVES`: finite
differences, on regular sampling also smoothed ones, and a smoothing spline's) or weak SINDy's
support width (`WINDOWS`), fitted to every training trajectory; each field rolled out over
every training trajectory's times from a start fitted to that trajectory (least squares from
its first observation, `START_ITERATIONS` Gauss-Newton steps: `fitted_start_error`), so that a
noisy first observation does not set the score; kept, among the fields whose mean relative RMS
error is within `TIE_RTOL` (or `TIE_ATOL`) of the lowest, the one of fewest terms (then the
lowest error). Never the test."""

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

from ._study import AbstractStateModel, Fitted

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


#: The grid of `choose_sparse_field`: STLSQ's thresholds (coefficients below are set to zero;
#: pysindy's default is 0.1), ...
THRESHOLDS = (0.0, 0.003, 0.01, 0.03, 0.1, 0.3)
#: ... weak SINDy's support widths, in median steps of a trajectory (`_half_width`), ...
WINDOWS = (5, 9, 17, 33)
#: ... and its number of test functions per observation of a trajectory (fixed: more only add
#: rows drawn from the same supports).
TEST_FUNCTIONS = 4
#: A training rollout error within this fraction of the lowest, or `TIE_ATOL` of it (LSODA's
#: own error at `RTOL` over a trajectory is far below), counts as a tie: the sparser field is
#: kept.
TIE_RTOL, TIE_ATOL = 0.1, 1e-9
#: SINDy's derivatives: pysindy's finite differences (second order, any times); on regular
#: sampling only (the smoother assumes even spacing), smoothed ones (Savitzky-Golay over
#: `SMOOTHING_WINDOW` observations, or the shortest trajectory's odd length); and, when every
#: trajectory has at least `SPLINE_OBSERVATIONS` observations (any times), the derivative of a
#: cubic smoothing spline of each component (`scipy.interpolate.make_smoothing_spline`, its
#: smoothing chosen by generalised cross-validation on that component's observations).
DERIVATIVES = ("finite differences", "smoothed finite differences", "smoothing spline")
SMOOTHING_WINDOW = 11
SPLINE_OBSERVATIONS = 5
#: A rollout is stopped, and scored inf, once |y| exceeds this multiple of its start.
BLOW_UP = 100.0


def _check_grid(values: Any, name: str, kind: type, least: float) -> tuple:
    """`values` as a tuple of `kind` (ints taken as floats), each >= `least`; else `ValueError`."""
    values = tuple(values) if isinstance(values, (tuple, list)) else (values,)
    kinds = (int, float) if kind is float else (int,)
    if not values or any(isinstance(v, bool) or not isinstance(v, kinds) or not v >= least for v in values):
        raise ValueError(f"{name} must be a non-empty sequence of {kind.__name__}s >= {least:g}; got {values!r}")
    return tuple(kind(v) for v in values)


def relative_rms(pred: np.ndarray, true: np.ndarray) -> float:
    """The RMS of `pred - true` over the RMS of `true` (`(m, dim)` each; inf if not finite)."""
    with np.errstate(invalid="ignore", over="ignore"):
        error = np.sqrt(np.mean(np.sum((pred - true) ** 2, axis=-1)) / np.mean(np.sum(true**2, axis=-1)))
    return float(error) if np.isfinite(error) else np.inf


def rollout_error(field: Any, times: list[np.ndarray], states: list[np.ndarray], cutoff: float = np.inf,
                  flow: Any = _flow) -> float:
    """The mean over trajectories of the relative RMS error (`relative_rms`) of the field's
    rollout (`flow(field, y0, t, blow_up)`, LSODA by default) from each trajectory's first
    observation over its times, against its observations; inf once the running sum passes
    `cutoff` times their number (it cannot be below `cutoff` then). The neural ODE's score of
    held-out trajectories (`paper._neural_ode`); SINDy's rule scores from fitted starts
    (`fitted_start_error`): on noisy data this one is dominated by the first observation's
    error."""
    total = 0.0
    for t, y in zip(times, states):
        y = np.asarray(y, dtype=np.float64)
        pred = flow(field, y[0], np.asarray(t, dtype=np.float64), BLOW_UP * max(float(np.linalg.norm(y[0])), 1e-3))
        total += relative_rms(pred, y)
        if total > cutoff * len(times):
            return np.inf
    return total / len(times)


#: Gauss-Newton steps on each training trajectory's start (`fitted_start_error`), ...
START_ITERATIONS = 3
#: ... its Jacobian by forward differences of this step relative to the start's size (LSODA's
#: error at `RTOL` over a trajectory leaves the Jacobian ~1e-6 relative, ample for the steps).
START_DELTA = 1e-6


def _stacked_flow(field: Any, starts: np.ndarray, spans: np.ndarray, s: np.ndarray,
                  blow_up: np.ndarray) -> np.ndarray:
    """The states `(s.size, k, dim)` of `field` from each of the `starts` `(k, dim)` over its own
    span (`spans` `(k,)`), at the scaled times `s` in [0, 1] (t = t_0 + s span), by one LSODA on
    the stacked system (its Jacobian banded: each copy depends on itself only), at `RTOL`;
    stopped once some |y_j| exceeds `blow_up[j]` (the rows after it are NaN)."""
    k, dim = starts.shape
    out = np.full((s.size, k, dim), np.nan)

    def rhs(_, z):
        return (spans[:, None] * field.predict(z.reshape(k, dim))).ravel()

    def escape(_, z):
        return float(np.min(blow_up - np.linalg.norm(z.reshape(k, dim), axis=1)))

    escape.terminal = True
    sol = solve_ivp(rhs, (0.0, 1.0), starts.ravel(), method="LSODA", t_eval=s, rtol=RTOL, atol=RTOL,
                    events=escape, lband=dim - 1, uband=dim - 1)
    out[: sol.y.shape[1]] = sol.y.T.reshape(-1, k, dim)
    return out


def fitted_start_error(field: Any, times: list[np.ndarray], states: list[np.ndarray],
                       iterations: int = START_ITERATIONS) -> float:
    """The mean over trajectories of the relative RMS error (`relative_rms`) of the field's
    rollout (LSODA) over each trajectory's times against its observations, from a start FITTED
    to them: least squares over the start (its `dim` components), from the first
    observation, by `iterations` Gauss-Newton steps (the Jacobian by forward differences,
    `START_DELTA`; a step that does not lower the residual is taken back half-way instead),
    each trajectory keeping its start of lowest residual. As the G-LPNet and the
    limit fit their starts: a noisy first observation no longer sets the score. All
    trajectories (and their differenced copies) in one LSODA run (`_stacked_flow`); inf if a
    rollout from the first observations passes `BLOW_UP` times its start."""
    times = [np.asarray(t, dtype=np.float64) for t in times]
    states = [np.asarray(y, dtype=np.float64) for y in states]
    k, dim = len(states), states[0].shape[-1]
    spans = np.array([t[-1] - t[0] for t in times])
    scaled = [(t - t[0]) / span if span > 0 else np.zeros_like(t) for t, span in zip(times, spans)]
    s = np.unique(np.concatenate(scaled))
    rows = [np.searchsorted(s, si) for si in scaled]
    y0 = np.stack([y[0] for y in states])
    norms = np.maximum(np.linalg.norm(y0, axis=1), 1e-3)
    delta = START_DELTA * norms
    best, errors, best_start = np.full(k, np.inf), np.full(k, np.inf), y0.copy()
    eye = np.eye(dim)
    for i in range(iterations + 1):
        last = i == iterations
        copies = y0[:, None] if last else np.concatenate([y0[:, None], y0[:, None] + delta[:, None, None] * eye], 1)
        n = copies.shape[1]
        out = _stacked_flow(field, copies.reshape(-1, dim), np.repeat(spans, n), s, np.repeat(BLOW_UP * norms, n))
        out = out.reshape(s.size, k, n, dim)
        if i == 0 and not np.all(np.isfinite(out[:, :, 0])):
            return np.inf
        for j, (y, r) in enumerate(zip(states, rows)):
            pred = out[r, j, 0]
            residual = pred - y
            ssr = float(np.sum(residual**2))
            if not ssr < best[j]:  # a step that did not lower the residual: back half-way to the best start
                y0[j] = 0.5 * (y0[j] + best_start[j])
                continue
            best[j], errors[j], best_start[j] = ssr, relative_rms(pred, y), y0[j]
            if not last:
                jacobian = (out[r, j, 1:] - pred[:, None]) / delta[j]  # (m, dim perturbed, dim)
                jacobian = jacobian.transpose(0, 2, 1).reshape(-1, dim)
                if np.all(np.isfinite(jacobian)):
                    y0[j] = y0[j] + np.linalg.lstsq(jacobian, -residual.ravel(), rcond=None)[0]
    return float(np.mean(errors))


class PolynomialField:
    r"""The polynomial vector field $\dot y = \Theta(y)\,\Xi$ of identified coefficients: the
    monomials `powers` `(n_features, dim)` (named `names`) times `coefficients`
    `(dim, n_features)`, with pysindy's `predict` signature. What a weak-form fit identifies
    is integrated as this field (pysindy's weak library evaluates integrals over a time grid,
    not the field at a state)."""

    def __init__(self, powers: np.ndarray, names: tuple[str, ...], coefficients: np.ndarray):
        self.powers = np.asarray(powers)
        self.names = tuple(names)
        self.coefficients = np.asarray(coefficients, dtype=np.float64)

    @property
    def terms(self) -> int:
        """The number of nonzero coefficients."""
        return int(np.count_nonzero(self.coefficients))

    def coefficient(self, component: int, powers: tuple[int, ...]) -> float:
        """The coefficient of the monomial `prod_i y_i^powers[i]` in `dot y[component]` (0 for a
        monomial not in the library)."""
        rows = np.flatnonzero(np.all(self.powers == np.asarray(powers), axis=1))
        return float(self.coefficients[component, rows[0]]) if rows.size else 0.0

    def predict(self, y: np.ndarray) -> np.ndarray:
        y = np.asarray(y, dtype=np.float64)
        return np.prod(y[:, None, :] ** self.powers, axis=2) @ self.coefficients.T


def _monomials(dim: int) -> tuple[np.ndarray, tuple[str, ...]]:
    """The powers and names of pysindy's polynomial library of degree 2 in `dim` variables (the
    constant first)."""
    import pysindy as ps

    library = ps.PolynomialLibrary(degree=2).fit(np.zeros((2, dim)))
    return np.asarray(library.powers_), tuple(library.get_feature_names())


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


def derivative_rows(times: list[np.ndarray], states: list[np.ndarray], derivative: str,
                    rates: list[np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
    r"""SINDy's least-squares rows: $\Theta(y)$ of every observation (the degree-2 library,
    constant included) and its rate, given (`rates`) or estimated by `derivative` (one of
    `DERIVATIVES`) on each trajectory's times."""
    import pysindy as ps

    features = ps.PolynomialLibrary(degree=2).fit_transform(np.concatenate(states))
    if rates is not None:
        return np.asarray(features), np.concatenate(rates)
    if derivative == "finite differences":
        method = ps.FiniteDifference()
    elif derivative == "smoothed finite differences":
        shortest = min(t.size for t in times)
        window = min(SMOOTHING_WINDOW, shortest if shortest % 2 else shortest - 1)
        method = ps.SmoothedFiniteDifference(smoother_kws={"window_length": window})
    elif derivative == "smoothing spline":
        from scipy.interpolate import make_smoothing_spline

        def method(y, t):
            return np.stack([make_smoothing_spline(t, y[:, k]).derivative()(t) for k in range(y.shape[1])], axis=1)
    else:
        raise ValueError(f"derivative must be one of {DERIVATIVES}; got {derivative!r}")
    targets = np.concatenate([method(np.asarray(y, dtype=np.float64), t=np.asarray(t, dtype=np.float64))
                              for t, y in zip(times, states)])
    return np.asarray(features), targets


def weak_rows(times: list[np.ndarray], states: list[np.ndarray], window: int, test_functions: int = TEST_FUNCTIONS,
              seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    r"""Weak SINDy's least-squares rows, $-\int y\,\phi_k'\,dt$ against $\int \Theta(y)\,\phi_k\,dt$
    (the degree-2 library, constant included), for test functions $\phi_k$ (pysindy's
    `WeakPDELibrary` on a 1-D grid of the times: $(1 - s^2)^4$ on supports drawn at random; the
    integrals are those of the piecewise-linear interpolants of $y$ and $\Theta(y)$ between
    observations, exact on any grid). pysindy's library has one time grid, so each trajectory
    has its own library on its own times (`window` median steps per support, `test_functions`
    times its number of observations of them; the draws seeded by `seed` plus the trajectory's
    index), the rows of all stacked, unweighted. A trajectory of fewer than
    `MIN_WEAK_OBSERVATIONS` observations gives no row."""
    import pysindy as ps

    features, targets = [], []
    for j, (t, y) in enumerate(zip(times, states)):
        t = np.asarray(t, dtype=np.float64)
        if t.size < MIN_WEAK_OBSERVATIONS:
            continue
        state = np.random.get_state()  # the library draws its supports from numpy's global stream
        np.random.seed(seed + j)
        try:
            library = ps.WeakPDELibrary(function_library=ps.PolynomialLibrary(degree=2), spatiotemporal_grid=t,
                                        K=test_functions * t.size, H_xt=_half_width(t, window))
        finally:
            np.random.set_state(state)
        features.append(np.asarray(library.fit_transform(np.asarray(y))))
        targets.append(np.asarray(library.convert_u_dot_integral(np.asarray(y))))
    if not features:
        raise ValueError(f"weak SINDy needs a trajectory of at least {MIN_WEAK_OBSERVATIONS} observations; "
                         f"the longest has {max(np.size(t) for t in times)}")
    return np.concatenate(features), np.concatenate(targets)


@dataclasses.dataclass(frozen=True)
class SparseField:
    """The field `choose_sparse_field` kept, and how: its `setting` (SINDy's derivative, or weak
    SINDy's support width), STLSQ's `threshold`, whether the library has its `constant`, and
    its training rollout error (the rule's score, `fitted_start_error` by default). Predicts as
    its field."""

    field: PolynomialField
    setting: str
    threshold: float
    constant: bool
    train_error: float

    def predict(self, y: np.ndarray) -> np.ndarray:
        return self.field.predict(y)

    def describe(self) -> str:
        return (f"{self.setting}, threshold {self.threshold:g}, {'with' if self.constant else 'no'} constant, "
                f"{self.field.terms} terms, training rollout error {self.train_error:.3g}")


def choose_sparse_field(times: list[np.ndarray], states: list[np.ndarray],
                        rows: dict[str, tuple[np.ndarray, np.ndarray]],
                        thresholds: tuple[float, ...] = THRESHOLDS, score: Any = fitted_start_error) -> SparseField:
    """The rule of every study's SINDy and weak SINDy (docs/conventions.md, "Peers"): for each
    setting's least-squares `rows` (`(features, targets)`, the degree-2 library with its constant
    first), each threshold of `thresholds`, with and without the constant, STLSQ (pysindy's:
    ridge `alpha` 0.05, then least squares on the terms kept); each field scored by `score`
    on the training trajectories (`times`, `states`): by default `fitted_start_error`, its
    rollouts over their times from starts fitted to them; kept: among the fields within
    `TIE_RTOL` (or `TIE_ATOL`) of the lowest score, the one of fewest terms, then of lowest
    score (on a tie, the first tried). `score=rollout_error` is the former rule (rollouts from
    the first observations)."""
    import pysindy as ps

    thresholds = _check_grid(thresholds, "thresholds", float, 0.0)
    powers, names = _monomials(np.asarray(states[0]).shape[-1])
    tried: dict[bytes, float] = {}  # fields already scored, by their coefficients
    candidates = []
    best = np.inf
    with warnings.catch_warnings():  # pysindy warns about ill-conditioned fits of noisy data
        warnings.simplefilter("ignore")
        for setting, (features, targets) in rows.items():
            for constant in (False, True):
                keep = slice(None) if constant else slice(1, None)
                for threshold in thresholds:
                    coefficients = np.zeros((targets.shape[1], powers.shape[0]))
                    coefficients[:, keep] = ps.STLSQ(threshold=threshold).fit(features[:, keep], targets).coef_
                    key = coefficients.tobytes()
                    if key not in tried:
                        field = PolynomialField(powers, names, coefficients)
                        tried[key] = score(field, times, states)
                        best = min(best, tried[key])
                        candidates.append(SparseField(field, setting, threshold, constant, tried[key]))
    eligible = [c for c in candidates if c.train_error <= (1.0 + TIE_RTOL) * best + TIE_ATOL] or candidates[:1]
    return min(eligible, key=lambda c: (c.field.terms, c.train_error))


def fit_sindy(times: list[np.ndarray], states: list[np.ndarray], rates: list[np.ndarray] | None = None,
              thresholds: tuple[float, ...] = THRESHOLDS) -> SparseField:
    """SINDy by the rule (`choose_sparse_field`): the derivatives of `DERIVATIVES` (smoothed
    finite differences on regular sampling only, the smoothing spline on trajectories of at
    least `SPLINE_OBSERVATIONS` observations only), or the `rates` given."""
    with warnings.catch_warnings():  # pysindy's warnings about its arrays' axes
        warnings.simplefilter("ignore")
        if rates is not None:
            rows = {"rates given": derivative_rows(times, states, "", rates)}
        else:
            steps = np.concatenate([np.diff(t) for t in times])
            regular = bool(np.ptp(steps) <= 1e-9 * np.max(steps))
            spline = min(np.size(t) for t in times) >= SPLINE_OBSERVATIONS
            derivatives = [DERIVATIVES[0]] + [DERIVATIVES[1]] * regular + [DERIVATIVES[2]] * spline
            rows = {d: derivative_rows(times, states, d) for d in derivatives}
    return choose_sparse_field(times, states, rows, thresholds)


def fit_weak_sindy(times: list[np.ndarray], states: list[np.ndarray], windows: tuple[int, ...] = WINDOWS,
                   test_functions: int = TEST_FUNCTIONS, seed: int = 0,
                   thresholds: tuple[float, ...] = THRESHOLDS) -> SparseField:
    """Weak SINDy by the rule (`choose_sparse_field`): every support width of `windows`."""
    with warnings.catch_warnings():  # pysindy's warnings about its arrays' axes
        warnings.simplefilter("ignore")
        rows = {f"window {w}": weak_rows(times, states, w, test_functions, seed) for w in windows}
    return choose_sparse_field(times, states, rows, thresholds)


class _AbstractSINDyModel(AbstractStateModel):
    """A sparse polynomial vector field fitted to observations: `vector_field(data)` is the
    fitted field (a `SparseField`, chosen by the rule of `choose_sparse_field`); the rest is
    shared. Simulated by LSODA over the whole time span at once (tolerance 1e-12, as
    `SINDy.simulate`), stopped, and reported as diverged, once |y| exceeds `BLOW_UP` times its
    start."""

    @abc.abstractmethod
    def vector_field(self, data: Any) -> SparseField:
        """The fitted vector field of `data` (an `integrators.Observations`)."""

    def fit(self, system, data, *, progress=False) -> Fitted:
        model = self.vector_field(data)
        if progress:
            print(f"{self.label}: {model.describe()}", flush=True)
        h = float(np.median(np.concatenate([np.diff(t) for t in data.times])))
        return Fitted(SINDyFlow(system, h, model))

    def simulate(self, fitted, y0, n_steps, h) -> np.ndarray:
        t = h * np.arange(n_steps + 1)
        y0 = np.asarray(y0, dtype=np.float64).reshape(-1, fitted.step_map.system.dim)
        return np.stack([_flow(fitted.step_map.model, y, t, BLOW_UP * max(float(np.linalg.norm(y)), 1e-3))
                         for y in y0])


@dataclasses.dataclass(frozen=True)
class SINDyModel(_AbstractSINDyModel):
    """SINDy: polynomial library of degree 2 (with or without its constant), STLSQ, derivatives
    by finite differences, (regular sampling) smoothed ones or a smoothing spline's
    (`DERIVATIVES`); the library, the threshold (of
    `thresholds`) and the derivative chosen on the training trajectories' rollouts
    (`fit_sindy`, `choose_sparse_field`)."""

    label: str = "SINDy"
    thresholds: tuple[float, ...] = THRESHOLDS

    def __post_init__(self):
        object.__setattr__(self, "thresholds", _check_grid(self.thresholds, "thresholds", float, 0.0))

    def vector_field(self, data):
        return fit_sindy(list(data.times), list(data.states), thresholds=self.thresholds)


@dataclasses.dataclass(frozen=True)
class WeakSINDyModel(_AbstractSINDyModel):
    r"""Weak SINDy: the coefficients $\Xi$ of $\dot y = \Theta(y)\,\Xi$ (the polynomial library
    of degree 2, with or without its constant) fitted in weak form (`weak_rows`: pysindy's
    `WeakPDELibrary` on each trajectory's own times, the rows stacked; no derivative of the
    data is taken; uneven times taken as they are, so it `accepts` every sampling), by STLSQ;
    the support width (of `windows`, median steps), the threshold (of `thresholds`) and the
    constant chosen on the training trajectories' rollouts (`fit_weak_sindy`,
    `choose_sparse_field`); `test_functions` per observation, drawn seeded by `seed`. Then
    simulated as the polynomial field with those coefficients (`PolynomialField`). A
    trajectory of fewer than `MIN_WEAK_OBSERVATIONS` observations gives no row; data without a
    longer one are not accepted."""

    label: str = "weak SINDy"
    windows: tuple[int, ...] = WINDOWS
    test_functions: int = TEST_FUNCTIONS
    seed: int = 0
    thresholds: tuple[float, ...] = THRESHOLDS

    def __post_init__(self):
        object.__setattr__(self, "windows", _check_grid(self.windows, "windows", int, 2))
        object.__setattr__(self, "thresholds", _check_grid(self.thresholds, "thresholds", float, 0.0))
        if isinstance(self.test_functions, bool) or not isinstance(self.test_functions, int) or self.test_functions < 1:
            raise ValueError(f"test_functions must be an int >= 1; got {self.test_functions!r}")

    def accepts(self, data) -> bool:
        return any(t.size >= MIN_WEAK_OBSERVATIONS for t in data.times)

    def vector_field(self, data):
        return fit_weak_sindy(list(data.times), list(data.states), self.windows, self.test_functions, self.seed,
                              self.thresholds)
