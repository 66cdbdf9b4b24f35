r"""W5 (beyond the paper): a learned isospectral map of Zeitlin's model (2D Euler on the
sphere, u(N)) at N = 16 and 32 (dimension 256 and 1024), against the isospectral midpoint at
the same step.

Protocol (the issue's): for each N, the step $H$ is quflow's, $0.1\pi\hbar/\|P\|_2$ of a
random field (`Zeitlin.random_state`, degrees <= 10, unit L2 norm; seed 0), so that the
classical method runs at the step its authors use. Training data: the isospectral midpoint at
the small step $H/16$ (tolerance 1e-14) from `n_train` other random fields, sampled every
$H$ for `train_steps` steps; pairs of consecutive samples. The learned map is
`learn.IsospectralPolynomial` of degree 1 (one coefficient: the classical method's cost)
and 3 ($B_\theta = \sum_{k\le 3}\theta_k S^k$, $S = \Delta_N^{-1}/\hbar$, a function of the
spherical degree $l$; two more Poisson solves an iteration), each started at the classical
method $\theta = (1, 0, ...)$ and fitted by Levenberg-Marquardt on the state loss; and an LPNet,
$W \mapsto e^{H A(W)^\dagger} W e^{-H A(W)^\dagger}$ with $\alpha(W)$ affine in $W$ (a network
without hidden layers: $N^4 + N^2$ weights, started at zero), fitted by L-BFGS-B on the state
loss from the data of `lpnet_fields` fields (the first `n_train` the others'). Test: `n_test`
further fields for `test_steps` steps of $H$, against the isospectral triple jump (order 4) at
$H/16$, tolerance 1e-14. Classical: the isospectral midpoint at $H$ (the same cost as the
learned map up to its two more Poisson solves an iteration) and at $H/2$ (twice the steps).

Figures, each the largest over the test fields: state error $\|W - W_{ref}\|_F/\|W_0\|_F$
after 10 steps of $H$ (the flow is chaotic: by the end the errors approach the size of the
field), at the end and over the run, energy error relative to $H(0)$, and for every map the relative
change of the Casimirs $\mathrm{tr}(iW)^k$, $k = 2..4$ (the issue asks <= 1e-12); the wall time
of a step (a rollout of all test fields, the fastest of three, divided by the steps and
fields) for the learned map and the midpoint at $H$.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from typing import Any

import numpy as np

import integrators as it
import learn
import liepoisson as lp

from ._experiment import (
    Column,
    Profile,
    fmt,
    profiles,
    row_from_json,
    row_to_json,
    saved_row,
    table_lines,
)
from ._runner import AbstractStudy
from ._study import AbstractStudyModel

FINE = 16  # the small step of the data and of the reference: H / FINE
TOL = 1e-14  # stage tolerance of the data, the reference and the learned map
DEGREES = (1, 3)  # degree 1: the classical cost (one Poisson solve an iteration); 3: two more
EARLY = 10  # the early state error: after this many steps of H (before the chaotic flow decorrelates)
STEP_SEED, TRAIN_SEED, TEST_SEED = 0, 100, 200


PROFILES = profiles(
    # lpnet_fields: the LPNet's training fields (the first n_train of them are the others');
    # lpnet_iterations: its L-BFGS-B iterations.
    # "smoke" exercises the whole pipeline in seconds (tests); numbers are meaningless.
    smoke=Profile(sizes=(6,), n_train=3, train_steps=5, n_test=2, test_steps=10, lm_steps=3, lpnet_fields=4,
                  lpnet_iterations=5),
    quick=Profile(sizes=(16, 32), n_train=8, train_steps=40, n_test=4, test_steps=100, lm_steps=30,
                  lpnet_fields=24, lpnet_iterations=100),
    full=Profile(sizes=(16, 32), n_train=12, train_steps=40, n_test=8, test_steps=400, lm_steps=50,
                 lpnet_fields=48, lpnet_iterations=250),
)


@dataclasses.dataclass(frozen=True)
class W5Row:
    N: int
    model: str
    h: float
    state_error_early: float
    state_error_final: float
    state_error_max: float
    energy_error_max: float
    casimir_drift_max: float
    ms_per_step: float | None
    theta: list[float] | None
    fit_seconds: float | None
    train_loss: float | None
    energy_error_early: float | None = None  # after EARLY steps (rows of runs before it: None)


def quflow_step(system: lp.systems.Zeitlin, seed: int = STEP_SEED) -> float:
    r"""quflow's step $0.1\pi\hbar/\|P\|_2$ of the random field of `seed`."""
    W = np.asarray(system.algebra.matrix(system.random_state(seed)))
    return float(0.1 * np.pi * system.hbar / np.linalg.norm(np.asarray(system.stream_matrix(W)), 2))


def _traces(system: lp.systems.Zeitlin, ys: np.ndarray) -> np.ndarray:
    """tr (iW)^k, k = 2..4, of states `(..., dim)`: `(..., 3)`."""
    iW = 1j * np.asarray(system.algebra.matrix(ys))
    out, P = [], iW
    for _ in range(3):
        P = P @ iW
        out.append(np.real(np.trace(P, axis1=-2, axis2=-1)))
    return np.stack(out, axis=-1)


def measure(system, name: str, step_map, h: float, reference: np.ndarray, every: int, **extra) -> W5Row:
    """The figures of `step_map` (step `h`) against `reference` `(n_test, steps + 1, dim)` at
    steps of H, saving every `every`-th of its own steps."""
    n_steps = (reference.shape[1] - 1) * every
    best = np.inf
    for _ in range(3):
        start = time.perf_counter()
        ys = np.asarray(step_map.rollout(reference[:, 0], n_steps, save_every=every))
        best = min(best, time.perf_counter() - start)
    scale = np.linalg.norm(reference[:, :1], axis=-1)
    # |W|_F^2 = kappa |y|^2 for orthonormal coordinates: relative errors are the same in either
    errors = np.linalg.norm(ys - reference, axis=-1) / scale
    energy = np.asarray(system.hamiltonian(ys))
    energy_errors = np.abs(energy - energy[:, :1]) / np.abs(energy[:, :1])
    traces = _traces(system, ys)
    casimir = np.abs(traces - traces[:, :1]) / np.abs(traces[:, :1])
    early = min(EARLY, errors.shape[1] - 1)
    return W5Row(N=system.N, model=name, h=h, state_error_early=float(errors[:, early].max()),
                 state_error_final=float(errors[:, -1].max()),
                 state_error_max=float(errors.max()),
                 energy_error_max=float(energy_errors.max()),
                 energy_error_early=float(energy_errors[:, early].max()),
                 casimir_drift_max=float(casimir.max()),
                 ms_per_step=1e3 * best / (n_steps * reference.shape[0]), **extra)


def lpnet_start(system: lp.systems.Zeitlin, h: float) -> learn.LPNet:
    r"""W5's LPNet before its fit: $\alpha(W)$ affine in $W$ (`hidden=()`), from zero weights
    and bias (`init="zero"`: the constant mean step once normalised)."""
    return learn.LPNet(system, hidden=(), h=h, init="zero")


def training_trajectories(system: lp.systems.Zeitlin, H: float, fields: int, steps: int) -> np.ndarray:
    """The isospectral midpoint at $H$/`FINE` from `fields` random fields (seeds from
    `TRAIN_SEED`), sampled every $H$ for `steps` steps: `(fields, steps + 1, dim)`."""
    starts = np.stack([system.random_state(TRAIN_SEED + i) for i in range(fields)])
    data_map = it.IsospectralMidpoint(system, H / FINE, tol=TOL)
    return np.asarray(data_map.rollout(starts, steps * FINE, save_every=FINE))


def test_reference(system: lp.systems.Zeitlin, H: float, fields: int, steps: int) -> np.ndarray:
    """The isospectral triple jump at $H$/`FINE` from `fields` random fields (seeds from
    `TEST_SEED`), sampled every $H$ for `steps` steps: `(fields, steps + 1, dim)`."""
    tests = np.stack([system.random_state(TEST_SEED + i) for i in range(fields)])
    return np.asarray(it.IsospectralTripleJump(system, H / FINE, tol=TOL).rollout(tests, steps * FINE,
                                                                                   save_every=FINE))


class Condition:
    """A size N of W5 at a profile: the system, quflow's step `H`, the training trajectories and
    the test reference (computed when a row first needs them: a rerun that reads the rows
    integrates nothing)."""

    def __init__(self, N: int, P: Profile):
        self.N, self.P = N, P
        self.system = lp.systems.Zeitlin(N)

    @functools.cached_property
    def H(self) -> float:
        return quflow_step(self.system)

    @functools.cached_property
    def trajectories(self) -> np.ndarray:
        return training_trajectories(self.system, self.H, max(self.P.n_train, self.P.lpnet_fields), self.P.train_steps)

    @functools.cached_property
    def reference(self) -> np.ndarray:
        return test_reference(self.system, self.H, self.P.n_test, self.P.test_steps)

    def pairs(self, fields: int) -> tuple[np.ndarray, np.ndarray]:
        """Consecutive samples of the first `fields` training trajectories."""
        dim = self.system.dim
        return (self.trajectories[:fields, :-1].reshape(-1, dim), self.trajectories[:fields, 1:].reshape(-1, dim))


class AbstractZeitlinModel(AbstractStudyModel):
    """A model of W5: `fit(condition, pairs)` returns its map at the condition's step (or a
    fraction of it) and the training record (`None`: nothing fitted)."""

    #: The map's step is H / `divisor`; its rollout saves every `divisor`-th step.
    divisor: int = 1

    def pairs(self, condition: Condition) -> tuple[np.ndarray, np.ndarray] | None:
        """The training pairs (`None`: nothing to fit)."""
        return None

    def theta(self, fitted: Any) -> list[float] | None:
        """The fitted coefficients the row reports (`None`: none)."""
        return None


@dataclasses.dataclass(frozen=True)
class IsospectralPolynomialModel(AbstractZeitlinModel):
    """`learn.IsospectralPolynomial` of `degree`, from the classical method, fitted by
    Levenberg-Marquardt (`lm_steps`) on the state loss."""

    degree: int
    lm_steps: int

    @property
    def label(self) -> str:
        return f"learned, degree {self.degree}"

    def pairs(self, condition):
        return condition.pairs(condition.P.n_train)

    def theta(self, fitted):
        return [float(t) for t in np.asarray(fitted.theta)]

    def fit(self, condition, data, *, progress=False):
        return learn.fit(learn.IsospectralPolynomial(condition.system, degree=self.degree, h=condition.H, tol=TOL),
                         data, h=condition.H, optimiser=learn.KeepIfBetter(learn.LevenbergMarquardt(self.lm_steps)),
                         validation_fraction=0.2, progress=progress)


@dataclasses.dataclass(frozen=True)
class ZeitlinLPNetModel(AbstractZeitlinModel):
    r"""The LPNet: $\alpha(W)$ affine in $W$ (a network without hidden layers, dim^2 + dim
    weights: the stream function is linear in W), its step the conjugation by $\exp(H\alpha)$;
    L-BFGS-B (`iterations`) on the state loss from normalised scalings and zero weights, so that
    directions the data do not reach keep no random weights (from the default random ones, at
    N = 32 the fit reached its training loss and was off the test fields at once: error 1.4
    after 10 steps), on the pairs of `fields` fields, more than the isospectral polynomial's
    three coefficients need (with 12 fields at N = 16 it fitted the training pairs and not the
    test fields: 65,792 weights, 98,304 residuals)."""

    fields: int
    iterations: int
    label: str = "learned LPNet, alpha affine in W"

    def pairs(self, condition):
        return condition.pairs(self.fields)

    def fit(self, condition, data, *, progress=False):
        return learn.fit(lpnet_start(condition.system, condition.H), data, h=condition.H,
                         optimiser=learn.KeepIfBetter(learn.ScipyLBFGSB(self.iterations)), validation_fraction=0.2,
                         normalise=True, progress=progress)


@dataclasses.dataclass(frozen=True)
class MidpointModel(AbstractZeitlinModel):
    """The isospectral midpoint at H / `divisor` (nothing fitted)."""

    divisor: int = 1

    @property
    def label(self) -> str:
        return f"isospectral midpoint, h = H/{self.divisor}" if self.divisor > 1 else "isospectral midpoint"

    def fit(self, condition, data, *, progress=False):
        return it.IsospectralMidpoint(condition.system, condition.H / self.divisor, tol=TOL), None


def models(P: Profile) -> list[AbstractZeitlinModel]:
    """W5's models at each N, in the order of its rows."""
    return [*(IsospectralPolynomialModel(degree, P.lm_steps) for degree in DEGREES),
            ZeitlinLPNetModel(P.lpnet_fields, P.lpnet_iterations), MidpointModel(1), MidpointModel(2)]


COLUMNS = (
    Column("N", lambda r: str(r.N)),
    Column("model", lambda r: r.model),
    Column("h", lambda r: f"{r.h:.4g}"),
    Column("state error after 10 steps", lambda r: r.state_error_early),
    Column("state error at the end", lambda r: r.state_error_final),
    Column("state error, max", lambda r: r.state_error_max),
    Column("energy error after 10 steps", lambda r: r.energy_error_early),
    Column("energy error, max", lambda r: r.energy_error_max),
    Column("Casimir drift, max", lambda r: r.casimir_drift_max),
    Column("ms a step", lambda r: r.ms_per_step),
    Column("theta", lambda r: "—" if r.theta is None else "(" + ", ".join(f"{t:.4g}" for t in r.theta) + ")"),
    Column("fit s", lambda r: r.fit_seconds),
)


def verdict(rows: list[W5Row]) -> list[str]:
    out = []
    for N in sorted({r.N for r in rows}):
        midpoint = next(r for r in rows if r.N == N and r.model == "isospectral midpoint")
        half = next((r for r in rows if r.N == N and r.model.endswith("H/2")), None)
        for learned in (r for r in rows if r.N == N and r.model.startswith("learned")):
            ratio = midpoint.state_error_early / learned.state_error_early
            line = (f"N = {N}, {learned.model}: state error after {EARLY} steps {fmt(learned.state_error_early)} "
                    f"against the isospectral midpoint's {fmt(midpoint.state_error_early)} at the same step "
                    f"({'better' if ratio > 1 else 'worse'} by {ratio if ratio > 1 else 1 / ratio:.3g}x; at the end "
                    f"{fmt(learned.state_error_final)} vs {fmt(midpoint.state_error_final)})")
            if half is not None:
                line += (f"; the midpoint at H/2: {fmt(half.state_error_early)} after {EARLY} steps of H, "
                         f"{fmt(half.state_error_final)} at the end")
            if learned.energy_error_early is not None and midpoint.energy_error_early is not None:
                line += (f"; energy error after {EARLY} steps {fmt(learned.energy_error_early)} vs "
                         f"{fmt(midpoint.energy_error_early)}")
            line += (f"; energy error over the run {fmt(learned.energy_error_max)} vs {fmt(midpoint.energy_error_max)}; Casimirs "
                     f"kept to {fmt(learned.casimir_drift_max)} relative "
                     f"({'within' if learned.casimir_drift_max <= 1e-12 else 'NOT within'} the 1e-12 asked)")
            if learned.ms_per_step is not None and midpoint.ms_per_step is not None:
                cost = learned.ms_per_step / midpoint.ms_per_step
                line += f"; {learned.ms_per_step:.3g} ms a step vs {midpoint.ms_per_step:.3g} ({cost:.2g}x the cost)"
                if half is not None and half.ms_per_step is not None:
                    line += f", the midpoint at H/2 {2 * half.ms_per_step:.3g} ms per H"
            out.append(line + ".")
    return out


class W5(AbstractStudy):
    id = "W5"
    title = "Zeitlin's model at N = 16 and 32: learned maps (isospectral, LPNet) vs the isospectral midpoint"
    profiles = PROFILES
    row_type = W5Row
    columns = COLUMNS

    def conditions(self, P):
        for N in P.sizes:
            print(f"W5: Zeitlin N = {N}", flush=True)
            yield Condition(N, P)

    def models(self, P, condition):
        return models(P)

    def evaluate(self, condition, model, progress):
        data = model.pairs(condition)
        begin = time.perf_counter()
        fitted, record = model.fit(condition, data, progress=progress)
        fit_seconds = time.perf_counter() - begin
        return measure(condition.system, model.label, fitted, condition.H / model.divisor, condition.reference,
                       model.divisor, theta=model.theta(fitted),
                       fit_seconds=None if record is None else fit_seconds,
                       train_loss=None if record is None else float(record.train_loss))

    def condition_rows(self, profile, condition, models, out_dir, progress):
        """The rows of one N, saved together as `rows/N<N>.json` (the format of earlier runs)."""
        def compute():
            return _Rows([row_to_json(self.evaluate(condition, m, progress)) for m in models], True)

        saved = saved_row(_Rows, out_dir / "rows" / f"N{condition.N}.json", compute)
        return [row_from_json(W5Row, r) for r in saved.rows]

    def verdict(self, rows, conditions):
        return verdict(rows)

    def summary(self, P, rows, conditions):
        return {"profile_settings": P.as_dict(), "fine": FINE, "tol": TOL, "degrees": list(DEGREES), "early": EARLY}

    def summary_rows(self, rows):
        return [(f"N = {r.N} {r.model}: state error at the end", "—", fmt(r.state_error_final), "—") for r in rows]

    def description(self, metrics):
        P = metrics.get("profile_settings", {})
        return (f"Zeitlin's model at quflow's step H; data: the isospectral midpoint at H/{metrics.get('fine')} "
                f"({P.get('n_train')} fields x {P.get('train_steps')} steps); reference: the isospectral triple "
                f"jump at H/{metrics.get('fine')}; {P.get('n_test')} test fields x {P.get('test_steps')} steps.")

    def sections(self, metrics, rows):
        return [("Every model", table_lines(COLUMNS, rows))]


@dataclasses.dataclass(frozen=True)
class _Rows:
    """The rows of one N, saved together (a study interrupted after N = 16 resumes at 32).
    `with_lpnet`: written by a run that fits the LPNet (files of earlier runs lack it and are
    refitted, not resumed without its row)."""

    rows: list
    with_lpnet: bool


EXPERIMENT = W5()
