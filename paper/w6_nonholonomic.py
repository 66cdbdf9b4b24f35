r"""W6 (beyond the paper): nonholonomic systems, the Suslov problem and the Chaplygin sleigh:
energy and constraint against time, the approach to the asymptotic motion and the cost of a
step, for heyoka, the classical integrators, a learned map that keeps the constraint and a
neural ODE ([Nonholonomic constraints][conventions-nonholonomic]).

Protocol (the issue's): the Suslov problem with I = (1, 2, 3), a = (1, 1, 1) (not an eigenvector
of the inertia) and the Chaplygin sleigh with m = 1, I = 1, a = 0.5. Training data: heyoka
(tolerance eps) from `n_train` random unit momenta projected onto the constraint, sampled every
h = 0.1 for `train_steps` steps, as **body velocities** (what a gyroscope or an odometer reads),
with Gaussian noise of a fraction `noise` of their RMS size. Test: `n_test` further starts to
t = `t_end` against heyoka, every model stepping h = 0.1: the classical integrators on the
momenta (RK4, the implicit midpoint rule, `integrators.GaussLegendre4`; the discrete
Lagrange-d'Alembert method, measured on its discrete velocities, which it keeps admissible, its
heading $\theta_{k+1} = \theta_k + h\omega_k$ its own reconstruction; its symmetric composition
by TripleJump in the velocities, `integrators.ComposedLagrangeDAlembert`, order 4, without a
heading), `learn.DAlembertMap`
(its constraint and learned energy kept for any weights; `lm_steps` Levenberg-Marquardt steps on
the trajectory loss), `learn.QuadraticDAlembertMap` (the family of every quadratic energy,
four parameters, stepped by its exact flow; fitted the same way; for the sleigh also with its
mirror symmetry, `reflection=0`) and `learn.NeuralODE` on the velocities (tanh; its hidden
layers and budget, at most `bfgs_steps` BFGS iterations, chosen on held-out training
trajectories: every study's rule, `paper._neural_ode.fit_neural_ode`). Beside the classical
integrators, the exact flow in closed form (`QuadraticDAlembertMap.from_system`).

Figures, each the largest over the test starts: the relative error of the true energy
$\tfrac12\xi^\top\mathbb M\xi$ against its value at the start (it is constant: the reaction
does no work), the relative constraint $|C\xi|/(|c_i||\xi|)$, the relative state error at $t_\text{end}$
(the asymptotic motion: the Suslov body's steady rotation, the sleigh's straight line), the
settling time (after which the state stays within 1% of its value at $t_\text{end}$) against
heyoka's, and the microseconds a step (a compiled rollout of the test starts, the faster of two,
divided by steps and starts; for heyoka its whole integration, the faster of two, divided by
the output steps). For
the sleigh also the speed at $t_\text{end}$ and the heading, unwrapped along the run and
reconstructed from the velocities by the trapezoid rule, $\theta_{n+1} = \theta_n +
\tfrac h2(\omega_n + \omega_{n+1})$ (the heading of `DAlembertMap.lifted_step`; heyoka's from
its configurations). The figure `nonholonomic.png` draws the energy error, the constraint and
the distance to the asymptotic state against time.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np

import integrators as it
import learn
import liepoisson as lp
from integrators.internals import figure, series_styles

from ._experiment import (
    AbstractExperiment,
    Column,
    fmt,
    row_from_json,
    row_to_json,
    saved_row,
    table_lines,
)
from ._neural_ode import fit_neural_ode

H = 0.1
SETTLED = 0.01  # the settling time: the state stays within this relative distance of its final value
EVERY = 10  # the series of the figure: every EVERY-th step
DATA_SEED, NOISE_SEED, TEST_SEED = 0, 1, 2
#: The basis direction of the admissible velocities a mirror symmetry flips, per system that has
#: one (`learn.QuadraticDAlembertMap(reflection=...)`): the sleigh's omega -> -omega.
MIRRORS = {"Chaplygin sleigh": 0}
CLASSICAL = {"RK4": it.RK4, "implicit midpoint": it.ImplicitMidpoint, "GaussLegendre4": it.GaussLegendre4}


@dataclasses.dataclass(frozen=True)
class Profile:
    n_train: int
    train_steps: int
    n_test: int
    t_end: float
    noises: tuple[float, ...]
    lm_steps: int
    bfgs_steps: int


PROFILES = {
    # "smoke" exercises the whole pipeline in seconds (tests); numbers are meaningless.
    "smoke": Profile(n_train=6, train_steps=5, n_test=2, t_end=2.0, noises=(0.0, 1e-3), lm_steps=2, bfgs_steps=2),
    "quick": Profile(n_train=100, train_steps=20, n_test=12, t_end=200.0, noises=(0.0, 1e-3), lm_steps=50,
                     bfgs_steps=100),
    "full": Profile(n_train=100, train_steps=20, n_test=12, t_end=200.0, noises=(0.0, 1e-3), lm_steps=200,
                    bfgs_steps=500),
}


def systems() -> dict[str, lp.systems.LiePoissonDAlembert]:
    """The study's systems, by name."""
    return {"Suslov": lp.systems.suslov((1.0, 2.0, 3.0), (1.0, 1.0, 1.0)),
            "Chaplygin sleigh": lp.systems.chaplygin_sleigh(1.0, 1.0, 0.5)}


def is_sleigh(system: lp.systems.LiePoissonDAlembert) -> bool:
    """Whether `system` moves on SE(2) (its heading and speed are reported)."""
    return system.group is not None and system.group.size == 9


def starts(system: lp.systems.LiePoissonDAlembert, n: int, seed: int) -> np.ndarray:
    """`n` random unit momenta projected onto the constraint, `(n, dim)`."""
    y = np.random.default_rng(seed).normal(size=(n, system.dim))
    return np.asarray(system.project(y / np.linalg.norm(y, axis=1, keepdims=True)))


def metric(system: lp.systems.LiePoissonDAlembert) -> np.ndarray:
    r"""$\mathbb M$ of $H = \tfrac12\mu^\top\mathbb M^{-1}\mu$: the true energy of a body
    velocity is $\tfrac12\xi^\top\mathbb M\xi$."""
    return system.kinetic_metric()


def observations(system, P: Profile, noise: float) -> it.Observations:
    """The training data: heyoka's body velocities every `H`, with Gaussian noise of a fraction
    `noise` of their RMS size."""
    xi = np.asarray(system.body_velocity(it.ground_truth(system, starts(system, P.n_train, DATA_SEED), H,
                                                          P.train_steps).states))
    rms = float(np.sqrt(np.mean(np.sum(xi**2, axis=-1))))
    noisy = xi + noise * rms * np.random.default_rng(NOISE_SEED).normal(size=xi.shape)
    return it.Observations(system, H * np.arange(P.train_steps + 1), list(noisy))


@dataclasses.dataclass(frozen=True)
class W6Row:
    system: str
    model: str
    kind: str  # "heyoka", "classical", "learned" or "baseline"
    noise: float | None
    energy_error_max: float
    constraint_max: float
    final_state_max: float
    final_state_mean: float
    settling_time_max: float  # the latest over the starts; inf if one never settles
    us_per_step: float | None
    fit_seconds: float | None
    diverged_at: float | None  # the first time a start left the finite range, or None
    speed_error_max: float | None  # the sleigh's, at t_end, relative
    heading_error_max_rad: float | None
    heading_error_max_rel: float | None  # relative to heyoka's angle turned
    # the figure's series (max over the starts, every EVERY-th step)
    energy_series: list[float]
    constraint_series: list[float]
    distance_series: list[float]


@dataclasses.dataclass(frozen=True)
class Truth:
    """heyoka's test trajectories of one system: velocities `(n, steps + 1, dim)`, headings
    unwrapped (the sleigh's; else None) and the seconds it took."""

    velocities: np.ndarray
    headings: np.ndarray | None
    seconds: float


def headings(omega: np.ndarray, h: float) -> np.ndarray:
    r"""The heading $\theta_n - \theta_0$ from angular velocities `(n, steps + 1)` by the
    trapezoid rule."""
    increments = 0.5 * h * (omega[:, 1:] + omega[:, :-1])
    return np.concatenate([np.zeros_like(omega[:, :1]), np.cumsum(increments, axis=1)], axis=1)


def settling_times(xi: np.ndarray, h: float) -> np.ndarray:
    """Per trajectory `(n, steps + 1, dim)`: the time after which the state stays within
    `SETTLED` of its last value, relative to its size (inf if it is not finite)."""
    with np.errstate(invalid="ignore", over="ignore"):  # a diverged trajectory: inf, never settled
        distance = np.linalg.norm(xi - xi[:, -1:], axis=-1) / np.linalg.norm(xi[:, -1:], axis=-1)
    out = np.full(xi.shape[0], np.inf)
    for i, d in enumerate(distance):
        if np.all(np.isfinite(d)):
            far = np.nonzero(d > SETTLED)[0]
            out[i] = 0.0 if far.size == 0 else (far[-1] + 1) * h
    return out


def measure(system_label: str, system, name: str, kind: str, xi: np.ndarray, truth: Truth, *, noise: float | None = None,
            us_per_step: float | None = None, fit_seconds: float | None = None,
            heading: np.ndarray | None = None) -> W6Row:
    """The figures of velocities `xi` `(n, steps + 1, dim)` (non-finite after a divergence)
    against heyoka's; the sleigh's `heading` `(n, steps + 1)` reconstructed from `xi` unless
    given (heyoka's own, from its configurations)."""
    reference = truth.velocities
    M, C = metric(system), np.asarray(system.constraints)
    finite = np.all(np.isfinite(xi), axis=-1)
    bad = np.nonzero(~np.all(finite, axis=0))[0]
    diverged_at = float(bad[0] * H) if bad.size else None

    def energy(x):
        return 0.5 * np.einsum("...a,ab,...b->...", x, M, x)

    with np.errstate(invalid="ignore", over="ignore"):
        # the energy is constant: every model's (and heyoka's own) error against the start's
        energy_error = np.where(finite, np.abs(energy(xi) / energy(reference[:, :1]) - 1.0), np.inf)
        size = np.linalg.norm(xi, axis=-1)
        constraint = np.where(finite, np.max(np.abs(xi @ C.T) / np.linalg.norm(C, axis=1), axis=-1)
                              / np.where(size > 0, size, 1.0), np.inf)
        asymptote = reference[:, -1:]
        distance = np.where(finite, np.linalg.norm(xi - asymptote, axis=-1) / np.linalg.norm(asymptote, axis=-1),
                            np.inf)
    final = distance[:, -1]
    speed = heading_max = heading_rel = None
    if truth.headings is not None:
        with np.errstate(invalid="ignore", over="ignore"):
            speed = float(np.max(np.where(finite[:, -1], np.abs(xi[:, -1, 1] - reference[:, -1, 1])
                                          / np.abs(reference[:, -1, 1]), np.inf)))
            heading = headings(xi[..., 0], H) if heading is None else heading
            turn = np.abs(heading[:, -1] - truth.headings[:, -1])
        turn = np.where(finite[:, -1], turn, np.inf)
        heading_max = float(np.max(turn))
        turned = np.abs(truth.headings[:, -1])
        with np.errstate(divide="ignore", invalid="ignore"):  # a start that does not turn: 0 of 0, else inf
            heading_rel = float(np.max(np.where(turn == 0.0, 0.0, turn / turned)))

    def series(x):  # for the figure: four digits
        return [float(f"{v:.4g}") for v in np.max(x, axis=0)[::EVERY]]

    return W6Row(system=system_label, model=name, kind=kind, noise=noise,
                 energy_error_max=float(np.max(energy_error)), constraint_max=float(np.max(constraint)),
                 final_state_max=float(np.max(final)), final_state_mean=float(np.mean(final)),
                 settling_time_max=float(np.max(settling_times(xi, H))), us_per_step=us_per_step,
                 fit_seconds=fit_seconds, diverged_at=diverged_at, speed_error_max=speed,
                 heading_error_max_rad=heading_max, heading_error_max_rel=heading_rel,
                 energy_series=series(energy_error), constraint_series=series(constraint),
                 distance_series=series(distance))


def timed_rollout(step_map: it.AbstractStepMap, y0: np.ndarray, n_steps: int) -> tuple[np.ndarray, float]:
    """Every step of `step_map` from `y0` `(n, dim)` (non-finite after a divergence) and the
    microseconds a step and start (compiled; the faster of two runs)."""
    best, ys = np.inf, None
    for _ in range(2):
        begin = time.perf_counter()
        ys = np.asarray(step_map.rollout(y0, n_steps, nonfinite="return"))
        best = min(best, time.perf_counter() - begin)
    return ys, 1e6 * best / (n_steps * y0.shape[0])


def ground_truth(system, P: Profile) -> Truth:
    """heyoka from the test starts to `t_end`, every step (the sleigh with its configurations)."""
    n_steps = round(P.t_end / H)
    y0 = starts(system, P.n_test, TEST_SEED)
    g0 = np.tile(np.eye(3).reshape(1, 9), (P.n_test, 1)) if is_sleigh(system) else None
    seconds = np.inf
    for _ in range(2):  # the faster of two: the first compiles heyoka's integrator
        begin = time.perf_counter()
        truth = it.ground_truth(system, y0, H, n_steps, **({"g0": g0} if g0 is not None else {}))
        seconds = min(seconds, time.perf_counter() - begin)
    velocities = np.asarray(system.body_velocity(truth.states))
    heading = None
    if g0 is not None:
        heading = np.unwrap(lp.systems.sleigh_pose(np.asarray(truth.configurations))[..., 0], axis=1)
        heading = heading - heading[:, :1]
    return Truth(velocities, heading, seconds)


def run_system(name: str, P: Profile, rows_dir: Path, progress: bool) -> list[W6Row]:
    """Every row of one system, each saved as it is done (an interrupted run resumes)."""
    system = systems()[name]
    n_steps = round(P.t_end / H)
    truth_cache: list[Truth] = []

    def truth() -> Truth:
        if not truth_cache:
            truth_cache.append(ground_truth(system, P))
        return truth_cache[0]

    slug = name.lower().replace(" ", "_")
    rows = []

    def keep(key: str, compute) -> None:
        row = saved_row(W6Row, rows_dir / f"{slug}_{key}.json", compute)
        rows.append(row)
        if progress:
            print(line(row), flush=True)

    keep("heyoka", lambda: measure(name, system, "heyoka", "heyoka", truth().velocities, truth(),
                                   us_per_step=1e6 * truth().seconds / (n_steps * P.n_test),
                                   heading=truth().headings))
    momenta0 = starts(system, P.n_test, TEST_SEED)
    for label, make in CLASSICAL.items():
        def classical(make=make, label=label):
            mu, us = timed_rollout(make(system, H), momenta0, n_steps)
            return measure(name, system, label, "classical", np.asarray(system.body_velocity(mu)), truth(),
                           us_per_step=us)
        keep(label.lower().replace(" ", "_"), classical)

    def discrete_lagrange_dalembert():
        method = it.DiscreteLagrangeDAlembert(system, H)
        p, us = timed_rollout(method, momenta0, n_steps)
        xi = np.asarray(method.velocity(p))  # its discrete velocities, the ones it keeps admissible
        heading = None
        if truth().headings is not None:  # g_{k+1} = g_k exp(h xi_k): theta_{k+1} = theta_k + h omega_k
            heading = np.concatenate([np.zeros_like(xi[:, :1, 0]), np.cumsum(H * xi[:, :-1, 0], axis=1)], axis=1)
        return measure(name, system, "discrete Lagrange-d'Alembert", "classical", xi, truth(), us_per_step=us,
                       heading=heading)
    keep("discrete_lagrange_dalembert", discrete_lagrange_dalembert)

    def composed_lagrange_dalembert():  # no heading: its sub-steps' poses are not kept
        mu, us = timed_rollout(it.ComposedLagrangeDAlembert(system, H), momenta0, n_steps)
        return measure(name, system, "DLA, TripleJump", "classical", np.asarray(system.body_velocity(mu)), truth(),
                       us_per_step=us)
    keep("dla_triplejump", composed_lagrange_dalembert)

    def exact_flow():
        xi, us = timed_rollout(learn.QuadraticDAlembertMap.from_system(system, H), truth().velocities[:, 0], n_steps)
        return measure(name, system, "exact flow", "classical", xi, truth(), us_per_step=us)
    keep("exact_flow", exact_flow)
    for noise in P.noises:
        models = [
            ("DAlembertMap", "learned", lambda: learn.DAlembertMap(system, key=DATA_SEED, h=H),
             learn.KeepIfBetter(learn.LevenbergMarquardt(P.lm_steps))),
            ("QuadraticDAlembertMap", "learned", lambda: learn.QuadraticDAlembertMap(system, h=H),
             learn.KeepIfBetter(learn.LevenbergMarquardt(P.lm_steps))),
            ("neural ODE", "baseline", None, None)]  # its size and budget chosen by fit_neural_ode
        if name in MIRRORS:  # the family with the body's mirror symmetry
            models.insert(2, ("QuadraticDAlembertMap, mirror", "learned",
                              lambda: learn.QuadraticDAlembertMap(system, h=H, reflection=MIRRORS[name]),
                              learn.KeepIfBetter(learn.LevenbergMarquardt(P.lm_steps))))
        for label, kind, make, optimiser in models:
            def learned(label=label, kind=kind, make=make, optimiser=optimiser, noise=noise):
                data = observations(system, P, noise)
                begin = time.perf_counter()
                if make is None:
                    fitted = fit_neural_ode(data, P.bfgs_steps, key=DATA_SEED, seed=DATA_SEED).net
                else:
                    fitted, _ = learn.fit(make(), data, optimiser=optimiser, validation_fraction=0.0,
                                          progress=progress)
                seconds = time.perf_counter() - begin
                xi, us = timed_rollout(fitted, truth().velocities[:, 0], n_steps)
                return measure(name, system, label, kind, xi, truth(), noise=noise, us_per_step=us, fit_seconds=seconds)
            keep(f"{label.lower().replace(',', '').replace(' ', '_')}_noise{noise:g}", learned)
    return rows


def line(r: W6Row) -> str:
    """One row in words (progress and verdict)."""
    text = (f"{r.system}, {r.model}" + (f" (noise {r.noise:g})" if r.noise is not None else "")
            + f": energy {fmt(r.energy_error_max)}, constraint {fmt(r.constraint_max)}, state at the end "
            f"{fmt(r.final_state_max)}, settled by t = {_time(r.settling_time_max)}")
    if r.heading_error_max_rad is not None:
        text += (f", speed {fmt(r.speed_error_max)}, heading {fmt(r.heading_error_max_rad)} rad "
                 f"({fmt(r.heading_error_max_rel)} of the turn)")
    if r.diverged_at is not None:
        text += f", diverged at t = {r.diverged_at:g}"
    return text


def verdict(rows: list[W6Row]) -> list[str]:
    out = []
    for name in dict.fromkeys(r.system for r in rows):
        mine = [r for r in rows if r.system == name]
        heyoka = next(r for r in mine if r.kind == "heyoka")
        out.append(f"{name}: heyoka keeps the constraint to {fmt(heyoka.constraint_max)} and settles (within "
                   f"{SETTLED:g}) by t = {_time(heyoka.settling_time_max)}")
        for r in mine:
            if r.kind == "heyoka":
                continue
            text = line(r) + f" (heyoka settles by {_time(heyoka.settling_time_max)})"
            if r.kind == "learned":
                checks = [f"constraint {'<=' if r.constraint_max <= 1e-13 else 'NOT <='} 1e-13",
                          f"energy {'within' if r.energy_error_max <= 0.01 else 'NOT within'} 1%",
                          f"asymptotic state {'within' if r.final_state_max <= 0.01 else 'NOT within'} 1%"]
                if r.heading_error_max_rel is not None:
                    checks += [f"speed {'within' if r.speed_error_max <= 0.01 else 'NOT within'} 1%",
                               f"heading {'within' if r.heading_error_max_rel <= 0.01 else 'NOT within'} 1%"]
                text += " [" + "; ".join(checks) + "]"
            out.append(text)
    return out


class W6(AbstractExperiment):
    id = "W6"
    title = "Nonholonomic systems: the Suslov problem and the Chaplygin sleigh"
    paper_values = ()

    def run(self, profile: str, out_dir: Path, progress: bool):
        P = PROFILES[profile]
        rows_dir = out_dir / "rows"
        rows_dir.mkdir(parents=True, exist_ok=True)
        rows: list[W6Row] = []
        for name in systems():
            print(f"W6: {name}", flush=True)
            rows += run_system(name, P, rows_dir, progress)
        return {"rows": [row_to_json(r) for r in rows], "verdict": verdict(rows),
                "figures": [plot(rows, out_dir)], "profile_settings": dataclasses.asdict(P), "h": H,
                "settled": SETTLED}

    def rows(self, metrics):
        return [(f"{r.system} {r.model}" + (f" (noise {r.noise:g})" if r.noise is not None else "")
                 + ": state error at the end", "—", fmt(r.final_state_max), "—") for r in _rows(metrics)]

    def markdown_table(self, metrics):
        P = metrics.get("profile_settings", {})
        description = (f"Every model steps h = {metrics.get('h')} to t = {P.get('t_end')} from {P.get('n_test')} "
                       f"starts against heyoka (tol = eps); learned maps from {P.get('n_train')} trajectories x "
                       f"{P.get('train_steps')} steps of body velocities. Figures: the largest over the starts. "
                       f"Figure: `nonholonomic.png`.")
        return self.study_markdown(metrics, description, [("Every model", table_lines(COLUMNS, _rows(metrics)))])


COLUMNS = (
    Column("system", lambda r: r.system),
    Column("model", lambda r: r.model),
    Column("noise", lambda r: "—" if r.noise is None else f"{r.noise:g}"),
    Column("energy error, max", lambda r: r.energy_error_max),
    Column("constraint, max", lambda r: r.constraint_max),
    Column("state error at the end, max (mean)", lambda r: f"{fmt(r.final_state_max)} ({fmt(r.final_state_mean)})"),
    Column("settled by t", lambda r: _time(r.settling_time_max)),
    Column("sleigh: speed, heading [rad] at the end", lambda r: "—" if r.heading_error_max_rad is None else
           f"{fmt(r.speed_error_max)}, {fmt(r.heading_error_max_rad)}"),
    Column("us a step", lambda r: r.us_per_step),
    Column("fit [s]", lambda r: r.fit_seconds),
)


def _time(x: float) -> str:
    return "never" if not np.isfinite(x) else f"{x:.1f}"


def _rows(metrics) -> list[W6Row]:
    return [row_from_json(W6Row, r) for r in metrics.get("rows", [])]


def plot(rows: list[W6Row], out_dir: Path) -> str:
    """Per system (columns): the energy error, the constraint and the distance to heyoka's
    asymptotic state against time (rows, log scale), the largest over the starts."""
    names = list(dict.fromkeys(r.system for r in rows))
    fig = figure(figsize=(6 * len(names), 11))
    axes = np.asarray(fig.subplots(3, len(names), sharex=True)).reshape(3, len(names))
    labels = ("relative energy error", "relative constraint", "distance to the asymptotic state")
    for column, name in zip(axes.T, names):
        mine = [r for r in rows if r.system == name]
        for r, style in zip(mine, series_styles(len(mine))):
            label = r.model + (f", noise {r.noise:g}" if r.noise else "")
            for ax, values in zip(column, (r.energy_series, r.constraint_series, r.distance_series)):
                v = np.asarray(values, dtype=float)
                t = np.arange(len(v)) * EVERY * H
                # zeros (exact starts) are drawn at round-off, not dropped
                ax.semilogy(t, np.maximum(v, 1e-17), label=label, color=style["color"], ls=style["ls"], lw=1.2)
        column[0].set_title(name)
        column[0].legend(fontsize=7)
        for ax, label in zip(column, labels):
            ax.set_ylabel(label)
        column[-1].set_xlabel("t")
    fig.tight_layout()
    name = "nonholonomic.png"
    fig.savefig(out_dir / name, dpi=110)
    return name


EXPERIMENT = W6()
