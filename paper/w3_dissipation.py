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

import numpy as np

import integrators as it
import learn
import liepoisson as lp
from integrators import splitting as sp
from integrators.internals import figure, series_styles

from ._experiment import AbstractExperiment, fmt

H, STEPS, LONG_STEPS = 0.1, 1200, 10_000
ORDER_T, ORDER_H = 4.0, (0.025, 0.0125)
DATA_SEED, TRAIN_SEED = 0, 0


@dataclasses.dataclass(frozen=True)
class Scenario:
    system: lp.systems.DoubleBracket
    y0: np.ndarray
    sample: Callable[[np.random.Generator, int], np.ndarray]  # training initial conditions
    threshold: Callable[[np.ndarray], float]  # the flip energy, from heyoka's energies


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
        "rigid body": Scenario(body, y0, _body_sample, lambda H: separatrix),
        "heavy top": Scenario(top, np.r_[0.2, 0.1, 1.0, _unit([0.1, 0.2, 0.97])], _top_sample,
                              lambda H: 0.5 * (H[0] + H[-1])),
    }


def classical(system) -> dict[str, Callable[[float], it.AbstractStepMap]]:
    return {
        "Lie-Euler": lambda h: it.LieEuler(system, h),
        "CF2": lambda h: it.CommutatorFree2(system, h),
        "CF4": lambda h: it.CommutatorFree4(system, h),
        "Strang + CF2": lambda h: it.DampedSplitting(system, h, sp.Strang, it.CommutatorFree2),
        "TripleJump + CF4": lambda h: it.DampedSplitting(system, h, sp.TripleJump, it.CommutatorFree4),
        "RK4": lambda h: it.RK4(system, h),
    }


def flip_time(energy: np.ndarray, level: float, h: float = H) -> float:
    """The first time the energy falls below `level` (linear interpolation between outputs); NaN
    if it never does."""
    below = np.flatnonzero(energy < level)
    if below.size == 0 or below[0] == 0:
        return float("nan")
    k = int(below[0])
    return float((k - 1 + (energy[k - 1] - level) / (energy[k - 1] - energy[k])) * h)


def casimir_drift(system, y: np.ndarray) -> float:
    C = np.asarray(system.casimirs(y))
    return float(np.max(np.abs(C - C[0]))) if C.size else 0.0


def dissipation_rate(system, states: np.ndarray, images: np.ndarray, h: float = H) -> float:
    r"""$\hat\gamma$: least squares of $(H(y') - H(y))/h = -\hat\gamma\,|\mathbb B\nabla H|_K^2$
    at the midpoint $(y + y')/2$, over the pairs `(states, images)`."""
    rate = (np.asarray(system.hamiltonian(images)) - np.asarray(system.hamiltonian(states))) / h
    w = -np.asarray(system.energy_rate(0.5 * (states + images))) / system.gamma
    return float(-np.sum(rate * w) / np.sum(w * w))


def measure(scenario: Scenario, name: str, stepper, reference: np.ndarray, long: bool) -> dict[str, Any]:
    system = scenario.system
    y = np.asarray(stepper.rollout(scenario.y0, reference.shape[0] - 1))
    energy, energy_ref = np.asarray(system.hamiltonian(y)), np.asarray(system.hamiltonian(reference))
    span = energy_ref[0] - energy_ref[-1]
    row = {
        "model": name,
        "energy_error_rel": float(np.max(np.abs(energy - energy_ref) / np.abs(energy_ref))),
        "energy_error_span": float(np.max(np.abs(energy - energy_ref)) / span),
        "flip_time": flip_time(energy, scenario.threshold(energy_ref)),
        "casimir_drift": casimir_drift(system, y),
        "exact_flows_per_step": int(stepper.exact_flows_per_step),
        "gamma_hat": dissipation_rate(system, reference[:-1], np.asarray(_steps(stepper, reference[:-1]))),
        "energy": energy,
    }
    if long:  # 10^4 steps: the Casimir drift, and the cost per step once compiled
        np.asarray(stepper.rollout(scenario.y0, LONG_STEPS))
        start = time.perf_counter()
        far = np.asarray(stepper.rollout(scenario.y0, LONG_STEPS))
        row["step_us"] = (time.perf_counter() - start) / LONG_STEPS * 1e6
        row["casimir_drift_1e4"] = casimir_drift(system, far)
    return row


def _steps(stepper, states):
    import jax

    return jax.jit(jax.vmap(stepper.step))(states)


def observed_order(system, make, reference: np.ndarray, y0: np.ndarray) -> float:
    errors = [np.linalg.norm(np.asarray(make(h).rollout(y0, round(ORDER_T / h)))[-1] - reference) for h in ORDER_H]
    return float(np.log2(errors[0] / errors[1]))


@dataclasses.dataclass(frozen=True)
class Profile:
    systems: tuple[str, ...]
    n_train: dict[str, int]
    train_steps: int
    adam: int
    lbfgs: int
    glpnet_iterations: int | None = None
    noises: tuple[float, ...] = (1e-3, 1e-2)  # the rigid body's noisy observations
    lm_steps: int = 30  # Levenberg-Marquardt on whole noisy trajectories, after the one-step fit


PROFILES = {
    "smoke": Profile(("rigid body",), {"rigid body": 20}, 10, adam=200, lbfgs=50, glpnet_iterations=30,
                     noises=(1e-3,), lm_steps=3),
    "quick": Profile(("rigid body", "heavy top"), {"rigid body": 100, "heavy top": 200}, 20, adam=3000, lbfgs=1000),
    "full": Profile(("rigid body", "heavy top"), {"rigid body": 200, "heavy top": 400}, 20, adam=10_000, lbfgs=5000),
}


def fit_noisy(sc: Scenario, noise: float, P: Profile, reference: np.ndarray) -> dict[str, Any]:
    """An LPNet from noisy observations of the training trajectories (`integrators.observe`,
    noise relative to the states' RMS size): the one-step loss on consecutive observations
    (Adam, then L-BFGS-B), then Levenberg-Marquardt on whole trajectories from fitted clean
    starts (errors in variables, `learn.TrajectoryLoss()`)."""
    system = sc.system
    starts = sc.sample(np.random.default_rng(DATA_SEED), P.n_train["rigid body"])
    data = it.observe(system, starts, np.arange(P.train_steps + 1) * H, noise=noise, seed=DATA_SEED + 1)
    begin = time.perf_counter()
    model, _ = learn.fit(learn.LPNet(system, key=TRAIN_SEED, h=H), data, progress=False,
                         loss=learn.TrajectoryLoss(window=1, latent=False),
                         optimiser=(learn.Adam(P.adam), learn.QuasiNewton(P.lbfgs)))
    model, record = learn.fit(model, data, optimiser=learn.LevenbergMarquardt(P.lm_steps), progress=False)
    return {**measure(sc, f"LPNet, noise {noise:g}", model, reference, long=False),
            "fit_s": time.perf_counter() - begin, "train_loss": record.train_loss}


class W3(AbstractExperiment):
    id = "W3"
    title = "double-bracket dissipation: Casimir-keeping integrators and LPNets where Poisson maps cannot follow"
    paper_values = ()

    def run(self, profile: str, out_dir: Path, progress: bool):
        P = PROFILES[profile]
        all_scenarios = scenarios()
        rows, truth = [], {}
        for key in P.systems:
            sc = all_scenarios[key]
            system = sc.system
            reference = np.asarray(it.ground_truth(system, sc.y0, h=H, n_steps=STEPS).states[0])
            energy_ref = np.asarray(system.hamiltonian(reference))
            truth[key] = {
                "casimir_drift": casimir_drift(system, reference),
                "max_energy_increase": float(np.max(np.diff(energy_ref))),
                "flip_time": flip_time(energy_ref, sc.threshold(energy_ref)),
                "energy_start": float(energy_ref[0]), "energy_end": float(energy_ref[-1]),
                "gamma": system.gamma,
                "gamma_hat": dissipation_rate(system, reference[:-1], reference[1:]),
                "energy": energy_ref,
            }
            if progress:
                print(f"{key}: heyoka flip at t = {truth[key]['flip_time']:.3f}, Casimir drift "
                      f"{fmt(truth[key]['casimir_drift'])}, max energy increase {fmt(truth[key]['max_energy_increase'])}",
                      flush=True)
            end = np.asarray(it.ground_truth(system, sc.y0, h=ORDER_T, n_steps=1).states[0, -1])
            for name, make in classical(system).items():
                row = {"system": key, "kind": "classical", **measure(sc, name, make(H), reference, long=True)}
                row["order"] = observed_order(system, make, end, sc.y0)
                row["nominal_order"] = int(getattr(make(H), "order", 4))
                rows.append(row)
                if progress:
                    print(line(row), flush=True)
            data = it.ground_truth(system, sc.sample(np.random.default_rng(DATA_SEED), P.n_train[key]), h=H,
                                   n_steps=P.train_steps)
            start = time.perf_counter()
            lpnet, record = learn.fit(learn.LPNet(system, key=TRAIN_SEED), data, normalise=True, progress=progress,
                                      optimiser=(learn.Adam(P.adam), learn.QuasiNewton(P.lbfgs)))
            fit_s = time.perf_counter() - start
            row = {"system": key, "kind": "learned", **measure(sc, "LPNet", lpnet, reference, long=False),
                   "fit_s": fit_s, "train_loss": record.train_loss}
            rows.append(row)
            if progress:
                print(line(row), flush=True)
            if key == "rigid body":
                for noise in P.noises:
                    row = {"system": key, "kind": "learned", "noise": noise,
                           **fit_noisy(sc, noise, P, reference)}
                    rows.append(row)
                    if progress:
                        print(line(row), flush=True)
            start = time.perf_counter()
            glpnet, _ = learn.fit_splitting(system, data, iterations=P.glpnet_iterations, progress=progress)
            row = {"system": key, "kind": "learned", **measure(sc, "G-LPNet", glpnet, reference, long=False),
                   "fit_s": time.perf_counter() - start}
            rows.append(row)
            if progress:
                print(line(row), flush=True)
        figures = [_plot(rows, truth, out_dir)]
        for r in [*rows, *truth.values()]:  # drawn; the table needs the figures only
            del r["energy"]
        return {
            "truth": truth,
            "rows": rows,
            "verdict": verdict(rows, truth),
            "figures": figures,
            "h": H, "steps": STEPS,
            "training": {k: {"trajectories": P.n_train[k], "steps": P.train_steps} for k in P.systems},
        }

    def rows(self, metrics):
        return [(f"{r['system']} {r['model']} max energy error / H(t)", "—", fmt(r["energy_error_rel"]), "—")
                for r in metrics.get("rows", []) if r["kind"] == "learned"]

    def markdown_table(self, metrics):
        lines = [
            f"# {self.id}: {self.title}",
            "",
            f"Profile `{metrics.get('profile')}`; produced by `python -m paper run W3"
            + (" --full`" if metrics.get("profile") == "full" else "`")
            + f". Every model steps h = {metrics.get('h')} for {metrics.get('steps')} steps against heyoka (tol = eps).",
            "",
            "## Verdict",
            "",
            *[f"- {v}" for v in metrics.get("verdict", [])],
            "",
            "## heyoka",
            "",
            "| system | flip time | Casimir drift | max energy increase between outputs | gamma | gamma-hat of exact steps |",
            "|---|---|---|---|---|---|",
            *[f"| {k} | {_time(t['flip_time'])} | {fmt(t['casimir_drift'])} | {fmt(t['max_energy_increase'])} | "
              f"{t['gamma']:g} | {t['gamma_hat']:.4f} |" for k, t in metrics.get("truth", {}).items()],
            "",
            "## Every model",
            "",
            ("| system | model | max energy error / H(t) | / energy dissipated | flip time | Casimir drift (1200 steps) "
             "| Casimir drift (1e4 steps) | observed order (nominal) | flows per step | us per step | gamma-hat | fit [s] |"),
            "|---|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for r in metrics.get("rows", []):
            order = f"{r['order']:.2f} ({r['nominal_order']})" if "order" in r else "—"
            lines.append(
                f"| {r['system']} | {r['model']} | {fmt(r['energy_error_rel'])} | {fmt(r['energy_error_span'])} | "
                f"{_time(r['flip_time'])} | {fmt(r['casimir_drift'])} | {fmt(r.get('casimir_drift_1e4'))} | {order} | "
                f"{r['exact_flows_per_step']} | {fmt(r.get('step_us'))} | {_number(r['gamma_hat'])} | {fmt(r.get('fit_s'))} |")
        return "\n".join(lines) + "\n"


def _time(x) -> str:
    """A flip time, or "never" (NaN, stored as null)."""
    return "never" if x is None or np.isnan(x) else f"{x:.3f}"


def _number(x) -> str:
    return "—" if x is None or np.isnan(x) else f"{x:.4f}"


def line(row) -> str:
    return (f"{row['system']}, {row['model']}: energy error {fmt(row['energy_error_rel'])} of H(t), "
            f"{fmt(row['energy_error_span'])} of the energy dissipated, flip at {_time(row['flip_time'])}, "
            f"Casimir drift {fmt(row['casimir_drift'])}" + (f", order {row['order']:.2f}" if "order" in row else ""))


def verdict(rows, truth) -> list[str]:
    out = []
    for key, t in truth.items():
        out.append(f"{key}: heyoka keeps the Casimirs to {fmt(t['casimir_drift'])} over the relaxation; its energy "
                   f"never rises by more than {fmt(max(t['max_energy_increase'], 0.0))} between outputs")
        for r in (r for r in rows if r["system"] == key):
            missing = r["flip_time"] is None or np.isnan(r["flip_time"])
            flip = np.nan if missing else abs(r["flip_time"] - t["flip_time"]) / t["flip_time"]
            text = (f"{key}, {r['model']}: energy within {fmt(r['energy_error_rel'])} of heyoka's "
                    f"({fmt(r['energy_error_span'])} of the energy dissipated), flip time "
                    + ("never reached" if missing else f"{100 * flip:.2f}% off")
                    + f", Casimir drift {fmt(r.get('casimir_drift_1e4', r['casimir_drift']))}")
            if "order" in r:
                text += f", observed order {r['order']:.2f} (nominal {r['nominal_order']})"
            if r["kind"] == "learned":
                text += (f", learned gamma-hat {_number(r['gamma_hat'])} (exact steps: {_number(t['gamma_hat'])}, "
                         f"gamma {t['gamma']:g})")
            out.append(text)
    return out


def _plot(rows, truth, out_dir: Path) -> str:
    """Per system: the energy against time (top) and its error against heyoka's (bottom, log)."""
    keys = list(truth)
    fig = figure(figsize=(6 * len(keys), 8))
    axes = np.asarray(fig.subplots(2, len(keys), sharex=True)).reshape(2, len(keys))
    for (top, bottom), key in zip(axes.T, keys):
        reference = truth[key]["energy"]
        t = np.arange(len(reference)) * H
        top.plot(t, reference, "k-", lw=2.5, label="heyoka")
        sub = [r for r in rows if r["system"] == key and r["model"] in ("CF4", "Strang + CF2", "RK4", "LPNet", "G-LPNet",
                                                                         "LPNet, noise 0.01")]
        for r, style in zip(sub, series_styles(len(sub))):
            top.plot(t, r["energy"], label=r["model"], color=style["color"], ls=style["ls"], lw=1.2)
            bottom.semilogy(t[1:], np.abs(r["energy"] - reference)[1:], label=r["model"], color=style["color"],
                            ls=style["ls"], lw=1.2)
        top.set_ylabel("energy H")
        top.set_title(f"damped {key}")
        top.legend()
        bottom.set_xlabel("t")
        bottom.set_ylabel("|H - H heyoka|")
    fig.tight_layout()
    name = "energy.png"
    fig.savefig(out_dir / name, dpi=120)
    return name


EXPERIMENT = W3()
