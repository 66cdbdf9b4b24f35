r"""W3 (beyond the paper): double-bracket dissipation, where Poisson maps cannot follow.

A rigid body with a nutation damper keeps $|\Pi|$ while its energy decays (Explorer 1, 1958:
from a spin about its minor axis to a tumble about its major axis).
`liepoisson.systems.DoubleBracket` adds $\gamma\,\mathbb B K\mathbb B\nabla H$ to any
Lie-Poisson system: the motion stays on the coadjoint orbit, the energy decays. Two systems:

- **rigid body** $I = (2, 1, 2/3)$, $\gamma = 0.1$, from $\Pi \propto (0.05, 0.05, 1)$, $|\Pi| = 1$,
  near the minor axis: the flip is the crossing of the separatrix energy $|\Pi|^2/(2I_2)$;
- **heavy top** $I = (1, 1.5, 2.5)$, $mgl = 0.7$, $\chi = e_3$, $\gamma = 0.05$, from
  $\Pi = (0.2, 0.1, 1)$, $\Gamma \propto (0.1, 0.2, 0.97)$: the "flip" is the crossing of the
  energy halfway between its start and its end.

Every model steps $h = 0.1$ for 1200 steps ($t = 120$) against heyoka (tol = eps):

- **classical**: the Lie-group methods `LieEuler`, `CommutatorFree2`, `CommutatorFree4` on the
  whole generator; `DampedSplitting` (exact flows of the Hamiltonian's pieces + a Lie-group step
  of the dissipation) composed by Strang with CommutatorFree2 and by TripleJump with
  CommutatorFree4; RK4, which leaves the orbit. Observed orders against heyoka at $t = 4$,
  $h = 0.025, 0.0125$; Casimir drift over $10^4$ steps; cost per step.
- **learned**, from heyoka trajectories of other initial conditions (random on the sphere
  $|\Pi| \in [0.9, 1.1]$; for the top, $\Pi$ Gaussian and $\Gamma$ on the unit sphere), 20 steps
  each: an **LPNet** (`learn.LPNet`, paper architecture, normalised, Adam then L-BFGS-B), whose
  step moves along the orbit and can lose energy, and a **G-LPNet** (`learn.fit_splitting`), an
  exactly Poisson map, which cannot. For the rigid body also LPNets from the same trajectories
  observed with noise 1e-3 and 1e-2 (relative to the states' RMS size; `integrators.observe`):
  the one-step loss on consecutive observations (Adam, L-BFGS-B, unnormalised: the scalings
  come from exact pairs), then 30 Levenberg-Marquardt steps on whole trajectories from fitted
  clean starts (errors in variables).

Figures: max energy error against heyoka, relative to $H(t)$ (rigid body) and to the energy
dissipated $H(0) - H(\infty)$ (both systems); flip time; Casimir drift; the learned dissipation
rate $\hat\gamma$: the least-squares fit of $(H(\Phi(y)) - H(y))/h = -\hat\gamma\,
|\mathbb B\nabla H|_K^2$ (at the midpoint) over the test trajectory's states, beside the same
estimate from heyoka's exact steps (its $O(h^2)$ bias).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import numpy as np

import integrators as it
import learn
import liepoisson as lp
from integrators import splitting as sp
from integrators.internals import figure, save_figure, series_styles

from ._experiment import Column, Profile, fmt, optional, profiles, row_from_json, table_lines
from ._runner import AbstractStudy
from ._study import (
    AbstractStudyModel,
    ClassicalMap,
    ConservativePartModel,
    Fitted,
    LPNetModel,
    Training,
)

H, STEPS, LONG_STEPS = 0.1, 1200, 10_000
ORDER_T, ORDER_H = 4.0, (0.025, 0.0125)
DATA_SEED, TRAIN_SEED = 0, 0


@dataclasses.dataclass(frozen=True)
class Scenario:
    system: lp.systems.DoubleBracket
    y0: np.ndarray
    sample: Callable[[np.random.Generator, int], np.ndarray]  # training initial conditions
    threshold: Callable[[np.ndarray], float]  # the flip energy, from heyoka's energies
    noises: bool = False  # also LPNets from noisy observations (the profile's noises)


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def _body_sample(rng, n):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True) * rng.uniform(0.9, 1.1, size=(n, 1))


def _top_sample(rng, n):
    gamma = rng.normal(size=(n, 3))
    return np.hstack([0.7 * rng.normal(size=(n, 3)), gamma / np.linalg.norm(gamma, axis=1, keepdims=True)])


def scenarios() -> dict[str, Scenario]:
    body = lp.systems.damped_rigid_body(inertia=(2.0, 1.0, 2.0 / 3.0), gamma=0.1)
    y0 = _unit([0.05, 0.05, 1.0])
    separatrix = float(np.dot(y0, y0)) / (2.0 * 1.0)  # |Pi|^2 / (2 I_2), I_2 = 1 the middle moment
    top = lp.systems.damped_heavy_top(gamma=0.05)
    return {
        "rigid body": Scenario(body, y0, _body_sample, lambda H: separatrix, noises=True),
        "heavy top": Scenario(top, np.r_[0.2, 0.1, 1.0, _unit([0.1, 0.2, 0.97])], _top_sample,
                              lambda H: 0.5 * (H[0] + H[-1])),
    }


@dataclasses.dataclass(frozen=True)
class Classical(ClassicalMap):
    """A classical integrator of the study and the order it has in theory."""

    nominal_order: int = 0


def _damped(method, dissipation):
    """`integrators.DampedSplitting` by the splitting `method` with the Lie-group `dissipation`."""
    return lambda system, h: it.DampedSplitting(system, h, method, dissipation)


def classical() -> tuple[Classical, ...]:
    """The Lie-group methods on the whole generator, the damped splittings and RK4, at step `H`."""
    return (
        Classical("Lie-Euler", it.LieEuler, H, 1),
        Classical("CF2", it.CommutatorFree2, H, 2),
        Classical("CF4", it.CommutatorFree4, H, 4),
        Classical("Strang + CF2", _damped(sp.Strang(), it.CommutatorFree2), H, 2),
        Classical("TripleJump + CF4", _damped(sp.TripleJump(), it.CommutatorFree4), H, 4),
        Classical("RK4", it.RK4, H, 4),
    )


def flip_time(energy: np.ndarray, level: float, h: float = H) -> float:
    """The first time the energy falls below `level` (linear interpolation between outputs); NaN
    if it never does."""
    below = np.flatnonzero(energy < level)
    if below.size == 0 or below[0] == 0:
        return float("nan")
    k = int(below[0])
    return float((k - 1 + (energy[k - 1] - level) / (energy[k - 1] - energy[k])) * h)


def dissipation_rate(system, states: np.ndarray, images: np.ndarray, h: float = H) -> float:
    r"""$\hat\gamma$: least squares of $(H(y') - H(y))/h = -\hat\gamma\,|\mathbb B\nabla H|_K^2$
    at the midpoint $(y + y')/2$, over the pairs `(states, images)`."""
    rate = (np.asarray(system.hamiltonian(images)) - np.asarray(system.hamiltonian(states))) / h
    w = -np.asarray(system.energy_rate(0.5 * (states + images))) / system.gamma
    return float(-np.sum(rate * w) / np.sum(w * w))


@dataclasses.dataclass(frozen=True)
class W3Truth:
    r"""heyoka's relaxation: Casimir drift, the largest rise of the energy between outputs, the
    flip time, the energy at the start and the end, $\gamma$ and the $\hat\gamma$ of its exact
    steps (the estimate's $O(h^2)$ bias)."""

    casimir_drift: float
    max_energy_increase: float
    flip_time: float
    energy_start: float
    energy_end: float
    gamma: float
    gamma_hat: float


@dataclasses.dataclass(frozen=True)
class W3Row:
    r"""One model on one system, against heyoka over `STEPS` steps: max energy error relative to
    $H(t)$ and to the energy dissipated, flip time, Casimir drift, exact flows per step, the
    learned $\hat\gamma$; a classical map's Casimir drift over `LONG_STEPS` steps, cost per step
    (`integrators.step_timing`), observed and nominal order (`integrators.convergence`); a
    learned map's noise, fit time and training loss. A map that diverged has infinite figures."""

    system: str
    kind: str  # "classical" or "learned"
    model: str
    energy_error_rel: float
    energy_error_span: float
    flip_time: float | None
    casimir_drift: float
    exact_flows_per_step: int
    gamma_hat: float
    noise: float | None = optional()
    fit_seconds: float | None = optional()
    train_loss: float | None = optional()
    seconds_per_step: float | None = optional()
    casimir_drift_1e4: float | None = optional()
    order: float | None = optional()
    nominal_order: int | None = optional()


def measure(scenario: Scenario, key: str, kind: str, model: AbstractStudyModel, fitted: Fitted,
            reference: np.ndarray) -> tuple[W3Row, np.ndarray]:
    """The row of `fitted` (a `model`) on `scenario` against heyoka's `reference`, and its energy
    series (for the figure)."""
    system, step_map = scenario.system, fitted.step_map
    y = model.simulate(fitted, scenario.y0[None], reference.shape[0] - 1, H)[0]
    figures = it.rollout_figures(step_map, y, reference, defect_points=0)
    energy, energy_ref = figures.report.energy, np.asarray(system.hamiltonian(reference))
    if figures.divergence is None:
        error = np.abs(energy - energy_ref)
        relative, span = float(np.max(error / np.abs(energy_ref))), float(np.max(error) / (energy_ref[0] - energy_ref[-1]))
    else:
        relative = span = np.inf
    states = reference[:-1]
    row = W3Row(
        system=key, kind=kind, model=model.label, energy_error_rel=relative, energy_error_span=span,
        flip_time=flip_time(energy, scenario.threshold(energy_ref)),
        casimir_drift=figures.report.max_casimir_drift,
        exact_flows_per_step=int(step_map.exact_flows_per_step),
        gamma_hat=dissipation_rate(system, states, np.asarray(jax.jit(jax.vmap(step_map.step))(states))),
        train_loss=fitted.train_loss,
    )
    return row, energy


def measure_classical(scenario: Scenario, key: str, model: Classical, reference: np.ndarray) -> tuple[W3Row, np.ndarray]:
    """`measure`, and the classical figures: Casimir drift over `LONG_STEPS` steps, the cost per
    step, the observed order at `ORDER_T` for the step sizes `ORDER_H`."""
    system = scenario.system
    fitted = model.fit(system)
    row, energy = measure(scenario, key, "classical", model, fitted, reference)
    far = np.asarray(fitted.step_map.rollout(scenario.y0, LONG_STEPS, nonfinite="return"))
    order = it.convergence(lambda h: model.make(system, h), system, scenario.y0, t_final=ORDER_T, hs=ORDER_H).order
    row = dataclasses.replace(
        row,
        seconds_per_step=it.step_timing(fitted.step_map, scenario.y0).seconds_per_step,
        casimir_drift_1e4=it.rollout_figures(fitted.step_map, far, defect_points=0).report.max_casimir_drift,
        order=order, nominal_order=model.nominal_order,
    )
    return row, energy


PROFILES = profiles(
    # noises: the noisy observations of the scenarios that have them; lm_steps:
    # Levenberg-Marquardt on whole noisy trajectories, after the one-step fit
    Profile(glpnet_iterations=None, noises=(1e-3, 1e-2), lm_steps=30),
    smoke=Profile(systems=("rigid body",), n_train={"rigid body": 20}, train_steps=10, adam=200, lbfgs=50,
                  glpnet_iterations=30, noises=(1e-3,), lm_steps=3),
    quick=Profile(systems=("rigid body", "heavy top"), n_train={"rigid body": 100, "heavy top": 200}, train_steps=20,
                  adam=3000, lbfgs=1000),
    full=Profile(systems=("rigid body", "heavy top"), n_train={"rigid body": 200, "heavy top": 400}, train_steps=20,
                 adam=10_000, lbfgs=5000),
)


def lpnet(P: Profile) -> LPNetModel:
    """An LPNet (paper architecture, normalised) fitted to exact pairs by Adam, then L-BFGS-B."""
    return LPNetModel("LPNet", (Training((learn.Adam(P.adam), learn.KeepIfBetter(learn.ScipyLBFGSB(P.lbfgs))), normalise=True),),
                      key=TRAIN_SEED)


def noisy_lpnet(P: Profile, noise: float) -> LPNetModel:
    """An LPNet from noisy observations: the one-step loss on consecutive observations (Adam,
    then L-BFGS-B, unnormalised), then Levenberg-Marquardt on whole trajectories from fitted
    clean starts (errors in variables, `learn.TrajectoryLoss()`)."""
    return LPNetModel(f"LPNet, noise {noise:g}", (
        Training((learn.Adam(P.adam), learn.KeepIfBetter(learn.ScipyLBFGSB(P.lbfgs))), loss=learn.TrajectoryLoss(window=1, latent=False)),
        Training(learn.KeepIfBetter(learn.LevenbergMarquardt(P.lm_steps))),
    ), key=TRAIN_SEED, h=H)


def glpnet(P: Profile) -> ConservativePartModel:
    """A G-LPNet (`learn.fit_splitting` with the undamped bracket): an exactly Poisson map, which
    cannot follow the decay."""
    return ConservativePartModel("G-LPNet", iterations=P.glpnet_iterations)


class Condition:
    """A system of W3: its scenario, heyoka's relaxation (`reference` and its `truth`), the
    learned models with the data each is fitted to (exact trajectories, or noisy observations
    at `noise`), and the energy series of every row (for the figure)."""

    def __init__(self, key: str, scenario: Scenario, P: Profile):
        self.key, self.scenario = key, scenario
        system = scenario.system
        self.reference = np.asarray(it.ground_truth(system, scenario.y0, h=H, n_steps=STEPS).states[0])
        energy_ref = np.asarray(system.hamiltonian(self.reference))
        self.energies: dict[str, np.ndarray] = {"heyoka": energy_ref}
        self.truth = W3Truth(
            casimir_drift=it.diagnostics(self.reference, system).max_casimir_drift,
            max_energy_increase=float(np.max(np.diff(energy_ref))),
            flip_time=flip_time(energy_ref, scenario.threshold(energy_ref)),
            energy_start=float(energy_ref[0]), energy_end=float(energy_ref[-1]),
            gamma=system.gamma,
            gamma_hat=dissipation_rate(system, self.reference[:-1], self.reference[1:]),
        )
        starts = scenario.sample(np.random.default_rng(DATA_SEED), P.n_train[key])
        data = it.ground_truth(system, starts, h=H, n_steps=P.train_steps)
        self.learned: list[tuple[AbstractStudyModel, Any, float | None]] = [(lpnet(P), data, None)]
        if scenario.noises:
            times = np.arange(P.train_steps + 1) * H
            self.learned += [(noisy_lpnet(P, noise), it.observe(system, starts, times, noise=noise, seed=DATA_SEED + 1),
                              noise) for noise in P.noises]
        self.learned.append((glpnet(P), data, None))


class W3(AbstractStudy):
    id = "W3"
    title = "double-bracket dissipation: Casimir-keeping integrators and LPNets where Poisson maps cannot follow"
    profiles = PROFILES
    row_type = W3Row

    def conditions(self, P):
        all_scenarios = scenarios()
        for key in P.systems:
            yield Condition(key, all_scenarios[key], P)

    def announce(self, condition):
        t = condition.truth
        return (f"{condition.key}: heyoka flip at t = {t.flip_time:.3f}, Casimir drift {fmt(t.casimir_drift)}, "
                f"max energy increase {fmt(t.max_energy_increase)}")

    def models(self, P, condition):
        return [*classical(), *(model for model, _, _ in condition.learned)]

    def evaluate(self, condition, model, progress):
        sc, key = condition.scenario, condition.key
        if isinstance(model, Classical):
            row, energy = measure_classical(sc, key, model, condition.reference)
        else:
            data, noise = next((d, n) for m, d, n in condition.learned if m is model)
            begin = time.perf_counter()
            fitted = model.fit(sc.system, data, progress=progress and noise is None)
            fit_seconds = time.perf_counter() - begin
            row, energy = measure(sc, key, "learned", model, fitted, condition.reference)
            row = dataclasses.replace(row, noise=noise, fit_seconds=fit_seconds)
        condition.energies[row.model] = energy
        return row

    def line(self, row):
        return line(row)

    def verdict(self, rows, conditions):
        return verdict(rows, {c.key: c.truth for c in conditions})

    def figures(self, rows, conditions, out_dir):
        energies = {(c.key, model): energy for c in conditions for model, energy in c.energies.items()}
        return [_plot(energies, [c.key for c in conditions], out_dir)]

    def summary(self, P, rows, conditions):
        return {"truth": {c.key: dataclasses.asdict(c.truth) for c in conditions}, "h": H, "steps": STEPS,
                "training": {k: {"trajectories": P.n_train[k], "steps": P.train_steps} for k in P.systems}}

    def summary_rows(self, rows):
        return [(f"{r.system} {r.model} max energy error / H(t)", "—", fmt(r.energy_error_rel), "—")
                for r in rows if r.kind == "learned"]

    def description(self, metrics):
        return f"Every model steps h = {metrics.get('h')} for {metrics.get('steps')} steps against heyoka (tol = eps)."

    def sections(self, metrics, rows):
        truth = {k: row_from_json(W3Truth, t) for k, t in metrics.get("truth", {}).items()}
        return [("heyoka", table_lines(TRUTH_COLUMNS, truth.items())), ("Every model", table_lines(COLUMNS, rows))]


TRUTH_COLUMNS = (
    Column("system", lambda item: item[0]),
    Column("flip time", lambda item: _time(item[1].flip_time)),
    Column("Casimir drift", lambda item: item[1].casimir_drift),
    Column("max energy increase between outputs", lambda item: item[1].max_energy_increase),
    Column("gamma", lambda item: f"{item[1].gamma:g}"),
    Column("gamma-hat of exact steps", lambda item: f"{item[1].gamma_hat:.4f}"),
)
COLUMNS = (
    Column("system", lambda r: r.system),
    Column("model", lambda r: r.model),
    Column("max energy error / H(t)", lambda r: r.energy_error_rel),
    Column("/ energy dissipated", lambda r: r.energy_error_span),
    Column("flip time", lambda r: _time(r.flip_time)),
    Column("Casimir drift (1200 steps)", lambda r: r.casimir_drift),
    Column("Casimir drift (1e4 steps)", lambda r: r.casimir_drift_1e4),
    Column("observed order (nominal)", lambda r: "—" if r.order is None else f"{r.order:.2f} ({r.nominal_order})"),
    Column("flows per step", lambda r: str(r.exact_flows_per_step)),
    Column("us per step", lambda r: None if r.seconds_per_step is None else 1e6 * r.seconds_per_step),
    Column("gamma-hat", lambda r: _number(r.gamma_hat)),
    Column("fit [s]", lambda r: r.fit_seconds),
)


def _time(x) -> str:
    """A flip time, or "never" (NaN, stored as null)."""
    return "never" if x is None or np.isnan(x) else f"{x:.3f}"


def _number(x) -> str:
    return "—" if x is None or np.isnan(x) else f"{x:.4f}"


def line(row: W3Row) -> str:
    return (f"{row.system}, {row.model}: energy error {fmt(row.energy_error_rel)} of H(t), "
            f"{fmt(row.energy_error_span)} of the energy dissipated, flip at {_time(row.flip_time)}, "
            f"Casimir drift {fmt(row.casimir_drift)}" + (f", order {row.order:.2f}" if row.order is not None else ""))


def verdict(rows: list[W3Row], truth: dict[str, W3Truth]) -> list[str]:
    out = []
    for key, t in truth.items():
        out.append(f"{key}: heyoka keeps the Casimirs to {fmt(t.casimir_drift)} over the relaxation; its energy "
                   f"never rises by more than {fmt(max(t.max_energy_increase, 0.0))} between outputs")
        for r in (r for r in rows if r.system == key):
            missing = r.flip_time is None or np.isnan(r.flip_time)
            flip = np.nan if missing else abs(r.flip_time - t.flip_time) / t.flip_time
            drift = r.casimir_drift if r.casimir_drift_1e4 is None else r.casimir_drift_1e4
            text = (f"{key}, {r.model}: energy within {fmt(r.energy_error_rel)} of heyoka's "
                    f"({fmt(r.energy_error_span)} of the energy dissipated), flip time "
                    + ("never reached" if missing else f"{100 * flip:.2f}% off")
                    + f", Casimir drift {fmt(drift)}")
            if r.order is not None:
                text += f", observed order {r.order:.2f} (nominal {r.nominal_order})"
            if r.kind == "learned":
                text += (f", learned gamma-hat {_number(r.gamma_hat)} (exact steps: {_number(t.gamma_hat)}, "
                         f"gamma {t.gamma:g})")
            out.append(text)
    return out


# The models drawn in the figure, beside heyoka.
DRAWN = ("CF4", "Strang + CF2", "RK4", "LPNet", "G-LPNet", "LPNet, noise 0.01")


def _plot(energies: dict[tuple[str, str], np.ndarray], keys: list[str], out_dir: Path) -> str:
    """Per system: the energy against time (top) and its error against heyoka's (bottom, log)."""
    fig = figure(figsize=(6 * len(keys), 8))
    axes = np.asarray(fig.subplots(2, len(keys), sharex=True)).reshape(2, len(keys))
    for (top, bottom), key in zip(axes.T, keys):
        reference = energies[key, "heyoka"]
        t = np.arange(len(reference)) * H
        top.plot(t, reference, "k-", lw=2.5, label="heyoka")
        drawn = [m for (system, m) in energies if system == key and m in DRAWN]
        for model, style in zip(drawn, series_styles(len(drawn))):
            energy = energies[key, model]  # up to its divergence, if it diverged
            top.plot(t[: len(energy)], energy, label=model, color=style["color"], ls=style["ls"], lw=1.2)
            bottom.semilogy(t[1: len(energy)], np.abs(energy - reference[: len(energy)])[1:], label=model,
                            color=style["color"], ls=style["ls"], lw=1.2)
        top.set_ylabel("energy H")
        top.set_title(f"damped {key}")
        top.legend()
        bottom.set_xlabel("t")
        bottom.set_ylabel("|H - H heyoka|")
    fig.tight_layout()
    name = "energy.png"
    save_figure(fig, out_dir / name, dpi=120)
    return name


EXPERIMENT = W3()
