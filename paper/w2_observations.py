"""W2 (beyond the paper): learning from observations, noisy and unevenly sampled, of a system
whose Hamiltonian the learner is not given.

For the rigid body I = (2, 1, 2/3) on so(3)*, Kirchhoff's body (the paper's E5) on se(3)* and
a body on the 4-dimensional "diamond" algebra outside the catalogue (given by its structure
constants): trajectories observed with Gaussian noise of standard deviation 0, 1e-3 and 1e-2
times the states' RMS size, at a regular h = 0.1 or at steps drawn from [0.05, 0.3]
(`integrators.observe`). Fitted to the same observations:

- **G-LPNet**: `learn.fit_splitting(system, observations)`: a TripleJump G-LPNet (one module
  per basis direction) fitted by trajectory least squares with the initial states (errors in
  variables), the family of its learned Hamiltonian chosen by the Bayesian information
  criterion (quadratic even, quadratic, general);
- **limit**: the true model family (`learn.ParametricHamiltonian`: the Hamiltonian's form
  with its coefficients unknown, RK4 with 10 sub-steps) fitted the same way: what the data
  allow at best;
- **SINDy** (pysindy, extra `peers`; skipped without it): polynomial library of degree 2,
  STLSQ, derivatives by smoothed finite differences (regular sampling; BENCHMARKS.md compares
  them with plain ones) or finite differences (uneven: the smoother assumes even spacing),
  integrated by LSODA;
- **MLP**: the unstructured residual MLP (3x16) on consecutive pairs, Adam then L-BFGS-B
  (regular sampling only: its step has no step-size input).

Every model is rolled out 1000 steps of 0.1 (t = 100) from 12 held-out initial conditions and
compared with heyoka: mean state error at t = 100, max relative energy error, Casimir drift
(max |C(t) - C(0)| over |grad C| |y|), fit time; for the rigid body, the identified
1/I_i - 1/I_j (`learn.quadratic_part`); for the G-LPNet, its learned Hamiltonian against the
true one modulo functions of the Casimirs (W1's `hamiltonian_mismatch`: max |H~ - H - f(C)| /
max |H| on the observed states, f the least-squares quadratic in the Casimirs).

Each row is saved (`<out>/W2/rows/`) as soon as it is measured; a rerun into the same folder
reads the saved rows and fits only the missing ones, so an interrupted `--full` run resumes.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import itertools
import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax.numpy as jnp
import numpy as np

import integrators as it
import learn
import liepoisson as lp
from integrators.internals import atomic_write_text, figure, series_styles, span_decades

from ._experiment import AbstractExperiment, _jsonable, fmt
from .w1_learned_vs_classical import hamiltonian_mismatch

H_TEST, STEPS_TEST, N_TEST = 0.1, 1000, 12
DATA_SEED, TEST_SEED, TRAIN_SEED = 1, 100, 0
UNEVEN = (0.05, 0.3)


def diamond() -> lp.systems.LiePoissonSystem:
    """A body on the 4-dimensional solvable "diamond" algebra: [p, q] = z, [n, p] = p,
    [n, q] = -q, z central; Casimirs z and pq + zn; H = (p^2 + q^2 + n^2)/2 + 0.1 exp(-z^2),
    bounded motion on the orbits with z != 0. Built from structure constants, as a user would."""
    C = np.zeros((4, 4, 4))
    for a, b, d, v in ((0, 1, 2, 1.0), (3, 0, 0, 1.0), (3, 1, 1, -1.0)):
        C[a, b, d], C[b, a, d] = v, -v
    g = lp.LieAlgebra(C, "diamond", ("p", "q", "z", "n"))
    return lp.systems.LiePoissonSystem(
        g, lambda m, xp: 0.5 * (m[0] ** 2 + m[1] ** 2 + m[3] ** 2) + 0.1 * xp.exp(-(m[2] ** 2)), name="diamond"
    )


def _sphere(n: int, rng: np.random.Generator) -> np.ndarray:
    y = rng.normal(size=(n, 3))
    return y / np.linalg.norm(y, axis=1, keepdims=True)


def _cube(dim: int) -> Callable[[int, np.random.Generator], np.ndarray]:
    return lambda n, rng: rng.uniform(-1.0, 1.0, size=(n, dim))


def _diagonal(y, theta):
    return 0.5 * jnp.sum(theta * y**2)


def _diamond_family(y, theta):
    return 0.5 * (theta[0] * y[0] ** 2 + theta[1] * y[1] ** 2 + theta[2] * y[3] ** 2) + theta[3] * jnp.exp(-y[2] ** 2)


@dataclasses.dataclass(frozen=True)
class Protocol:
    """A study's system, its observations (trajectories x observations from `initial`) and
    the true model family `family(y, theta)` with its true parameters."""

    system: lp.systems.AbstractPoissonSystem
    n_trajectories: int
    n_observations: int
    initial: Callable[[int, np.random.Generator], np.ndarray]
    family: Callable[[Any, Any], Any]
    true_theta: tuple[float, ...]


def protocols() -> dict[str, Protocol]:
    return {
        "rigid body": Protocol(lp.systems.RigidBody(inertia=(2.0, 1.0, 2.0 / 3.0)), 30, 21, _sphere, _diagonal,
                               (0.5, 1.0, 1.5)),
        "Kirchhoff": Protocol(lp.systems.Kirchhoff(inertia=(1.0, 2.0, 1.0), mass=(1.0, 2.0, 1.0)), 40, 21, _cube(6),
                              _diagonal, (1.0, 0.5, 1.0, 1.0, 0.5, 1.0)),
        "diamond": Protocol(diamond(), 40, 21, _cube(4), _diamond_family, (1.0, 1.0, 1.0, 0.1)),
    }


def observations(protocol: Protocol, noise: float, sampling: str, seed: int = DATA_SEED,
                 n_trajectories: int | None = None, n_observations: int | None = None) -> it.Observations:
    """The protocol's observations: initial states, times and noise all from `seed`."""
    n = protocol.n_trajectories if n_trajectories is None else n_trajectories
    m = protocol.n_observations if n_observations is None else n_observations
    y0 = protocol.initial(n, np.random.default_rng(seed))
    times = H_TEST * np.arange(m) if sampling == "regular" else it.uneven_times(n, m, UNEVEN, seed=seed)
    return it.observe(protocol.system, y0, times, noise=noise, seed=seed)


def test_set(protocol: Protocol, n: int = N_TEST, steps: int = STEPS_TEST) -> tuple[np.ndarray, np.ndarray]:
    """`n` held-out initial conditions and heyoka's states at t = 0.1 k, k = 0..steps."""
    y0 = protocol.initial(n, np.random.default_rng(TEST_SEED))
    return y0, it.ground_truth(protocol.system, y0, H_TEST, steps).states


def figures(system, states: np.ndarray, reference: np.ndarray) -> dict[str, float]:
    """Mean state error at the end, max relative energy error and Casimir drift of rollouts
    `(n, steps + 1, dim)` against the reference (infinite for a rollout that diverged).

    The issue's protocol, not `integrators.rollout_figures`'s: the mean over initial conditions
    (not the max), energy relative to E(0), Casimirs in units of |grad C| |y| (a Casimir may
    vanish on the data); and SINDy's rollouts are not a step map's."""
    if not np.all(np.isfinite(states)):
        return {"state_error": float("inf"), "energy_error": float("inf"), "casimir_drift": float("inf")}
    err = float(np.mean(np.linalg.norm(states[:, -1] - reference[:, -1], axis=-1)))
    energy = np.asarray(system.hamiltonian(states))
    energy0 = np.asarray(system.hamiltonian(reference[:, :1]))
    out = {"state_error": err, "energy_error": float(np.max(np.abs(energy - energy0) / np.abs(energy0)))}
    if system.n_casimirs:
        c = np.asarray(system.casimirs(states)).reshape(*states.shape[:2], -1)
        g = np.asarray(system.casimir_gradients(states[:, :1])).reshape(states.shape[0], 1, -1, states.shape[-1])
        scale = np.linalg.norm(g, axis=-1) * np.linalg.norm(states[:, :1], axis=-1)[..., None]
        out["casimir_drift"] = float(np.max(np.abs(c - c[:, :1]) / np.maximum(scale, np.finfo(float).tiny)))
    return out


def differences(theta) -> np.ndarray:
    """theta_i - theta_j for i < j (for the rigid body, the identified 1/I_i - 1/I_j)."""
    theta = np.asarray(theta)
    i, j = np.triu_indices(theta.size, 1)
    return theta[i] - theta[j]


def fit_glpnet(protocol: Protocol, data: it.Observations, seed: int, iterations: int | None = None, **kwargs):
    model, records = learn.fit_splitting(protocol.system, data, key=seed, seed=seed, validation_fraction=0.0,
                                         iterations=iterations, progress=False, **kwargs)
    chosen = records[-1].stages[-1].details
    extra: dict[str, Any] = {"train_loss": records[-1].train_loss, "family": chosen.get("family"),
                             "bic": {r.stages[-1].details.get("family"): r.stages[-1].details.get("bic")
                                     for r in records}}
    states = np.concatenate(data.states)
    # H~ against the true H, modulo functions of the Casimirs (which move nothing), on the data
    extra.update(hamiltonian_mismatch(model.hamiltonian, protocol.system, states))
    if protocol.system.name == "RigidBody":
        extra["differences"] = learn.quadratic_part(model.hamiltonian, protocol.system, states).diagonal_differences()
    return model, extra


def fit_limit(protocol: Protocol, data: it.Observations, seed: int, iterations: int = 200):
    model = learn.ParametricHamiltonian(protocol.system, protocol.family, np.ones(len(protocol.true_theta)),
                                        substeps=10)
    fitted, record = learn.fit(model, data, loss=learn.TrajectoryLoss(),
                               optimiser=learn.LevenbergMarquardt(iterations, rtol=1e-12), validation_fraction=0.0,
                               seed=seed, progress=False)
    extra: dict[str, Any] = {"train_loss": record.train_loss, "theta": np.asarray(fitted.theta)}
    if protocol.system.name == "RigidBody":
        extra["differences"] = differences(fitted.theta)
    return fitted, extra


class SindyModel:
    """A fitted SINDy model rolled out like a step map: its ODE integrated by LSODA (tolerance
    1e-12, as `SINDy.simulate`), stopped (and reported as diverged) once |y| exceeds 100 times
    its start."""

    def __init__(self, model):
        self.model = model

    def simulate(self, y0: np.ndarray, steps: int) -> np.ndarray:
        from scipy.integrate import solve_ivp

        t = H_TEST * np.arange(steps + 1)
        out = np.full((y0.shape[0], t.size, y0.shape[1]), np.nan)
        for i, y in enumerate(y0):
            limit = 100.0 * max(float(np.linalg.norm(y)), 1e-3)

            def blow_up(_, z, limit=limit):
                return limit - np.linalg.norm(z)

            blow_up.terminal = True
            sol = solve_ivp(lambda _, z: self.model.predict(z[None])[0], (0.0, t[-1]), y, method="LSODA", t_eval=t,
                            rtol=1e-12, atol=1e-12, events=blow_up)
            out[i, : sol.y.shape[1]] = sol.y.T
        return out


def simulate(model: Any, y0: np.ndarray, steps: int) -> np.ndarray:
    """`steps` steps of 0.1 from `y0` `(n, dim)`: a step map's rollout at that step (any step
    map: the step is an input of the learned ones), or a model's own `simulate`."""
    if hasattr(model, "simulate"):
        return model.simulate(y0, steps)
    return np.asarray(model.with_h(H_TEST).rollout(y0, steps, nonfinite="return"))


def sindy_available() -> bool:
    return importlib.util.find_spec("pysindy") is not None


def fit_sindy(protocol: Protocol, data: it.Observations, seed: int):
    import warnings

    import pysindy as ps

    if data.is_regular():
        # the smoother's default window of 11 points, or the shortest trajectory's (odd) length
        shortest = min(t.size for t in data.times)
        window = min(11, shortest if shortest % 2 else shortest - 1)
        derivative = ps.SmoothedFiniteDifference(smoother_kws={"window_length": window})
    else:  # Savitzky-Golay smoothing assumes even spacing; finite differences take any times
        derivative = ps.FiniteDifference()
    model = ps.SINDy(feature_library=ps.PolynomialLibrary(degree=2), optimizer=ps.STLSQ(),
                     differentiation_method=derivative)
    with warnings.catch_warnings():  # pysindy warns about ill-conditioned fits of noisy data
        warnings.simplefilter("ignore")
        model.fit(list(data.states), t=list(data.times))
    return SindyModel(model), {}


def fit_mlp(protocol: Protocol, data: it.Observations, seed: int, iterations: int = 1000):
    """The residual MLP on consecutive pairs: Adam (10 epochs per iteration, learning rate
    1e-3 decaying to 1e-5, full batch), then L-BFGS-B (`iterations`)."""
    model = learn.MLPBaseline(protocol.system, hidden=(16, 16, 16), key=seed)
    optimiser = (learn.Adam(10 * iterations, learning_rate=1e-3, final_learning_rate=1e-5),
                 learn.QuasiNewton(iterations, "lbfgsb"))
    fitted, record = learn.fit(model, data, loss=learn.TrajectoryLoss(window=1, latent=False), optimiser=optimiser,
                               validation_fraction=0.0, seed=seed, progress=False)
    return fitted, {"train_loss": record.train_loss}


MODELS = {"G-LPNet": fit_glpnet, "limit": fit_limit, "SINDy": fit_sindy, "MLP": fit_mlp}


def applies(name: str, sampling: str) -> bool:
    """Whether model `name` is fitted to data of this sampling: the MLP's step has no
    step-size input, so it is fitted to regular samples only."""
    return name != "MLP" or sampling == "regular"


def evaluate(protocol: Protocol, name: str, data: it.Observations, y0: np.ndarray, reference: np.ndarray,
             seed: int = TRAIN_SEED, **kwargs) -> dict[str, Any]:
    """Fit model `name` to `data` and measure its rollouts against `reference`."""
    start = time.perf_counter()
    model, extra = MODELS[name](protocol, data, seed, **kwargs)
    fit_s = time.perf_counter() - start
    states = simulate(model, y0, reference.shape[1] - 1)
    row = {"model": name, "fit_s": fit_s, **figures(protocol.system, states, reference), **extra}
    if "differences" in row:
        row["difference_error"] = np.abs(np.asarray(row["differences"]) - differences(protocol.true_theta))
    return row


@dataclasses.dataclass(frozen=True)
class Profile:
    systems: tuple[str, ...]
    noises: tuple[float, ...]
    samplings: tuple[str, ...]
    iterations: int  # the MLP's L-BFGS-B iterations (after 10x as many Adam epochs)
    steps: int = 200  # Levenberg-Marquardt steps per stage: the G-LPNet and the limit
    n_trajectories: int | None = None  # the protocol's when None
    n_observations: int | None = None
    test_steps: int = STEPS_TEST


PROFILES = {
    # "smoke" exercises the pipeline in seconds (tests): one system, small data, few iterations.
    "smoke": Profile(("rigid body",), (1e-3,), ("regular",), iterations=30, steps=20, n_trajectories=6,
                     n_observations=6, test_steps=50),
    "quick": Profile(("rigid body",), (0.0, 1e-3, 1e-2), ("regular", "uneven"), iterations=1000),
    "full": Profile(("rigid body", "Kirchhoff", "diamond"), (0.0, 1e-3, 1e-2), ("regular", "uneven"),
                    iterations=1000),
}


class W2(AbstractExperiment):
    id = "W2"
    title = "learning from observations: noisy, unevenly sampled trajectories, against SINDy and the parametric limit"
    paper_values = ()

    def run(self, profile: str, out_dir: Path, progress: bool):
        P = PROFILES[profile]
        models = [m for m in MODELS if m != "SINDy" or sindy_available()]
        rows: list[dict[str, Any]] = []
        all_protocols = protocols()
        for system in P.systems:
            protocol = all_protocols[system]
            y0, reference = test_set(protocol, steps=P.test_steps)
            for sampling, noise in itertools.product(P.samplings, P.noises):
                data = observations(protocol, noise, sampling, n_trajectories=P.n_trajectories,
                                    n_observations=P.n_observations)
                for name in models:
                    if not applies(name, sampling):
                        continue
                    saved = out_dir / "rows" / f"{profile}-{system}-{sampling}-{noise:g}-{name}.json".replace(" ", "_")
                    if saved.exists():  # a row of an interrupted run: each row is saved when it is done
                        row = json.loads(saved.read_text())
                    else:
                        kwargs = {"SINDy": {}, "MLP": {"iterations": P.iterations}}.get(name, {"iterations": P.steps})
                        row = _jsonable({"system": system, "noise": noise, "sampling": sampling,
                                         **evaluate(protocol, name, data, y0, reference, **kwargs)})
                        atomic_write_text(saved, json.dumps(row, indent=2) + "\n")
                    rows.append(row)
                    if progress:
                        print(line(row), flush=True)
        return {
            "rows": rows,
            "verdict": verdict(rows),
            "figures": _plots(rows, out_dir),
            "seeds": {"data": DATA_SEED, "test": TEST_SEED, "training": TRAIN_SEED},
            "sindy": "pysindy " + _version("pysindy") if sindy_available() else "not installed (extra peers)",
            "model": "G-LPNet (TripleJump, family by BIC)",
            "test_steps": P.test_steps,
        }

    def rows(self, metrics):
        return [(f"{r['system']} {r['sampling']} noise {r['noise']:g} G-LPNet state error(t=100)", "—",
                 fmt(r["state_error"]), fmt(_peer(metrics["rows"], r, "limit").get("state_error")))
                for r in metrics.get("rows", []) if r["model"] == "G-LPNet"]

    def markdown_table(self, metrics):
        lines = [
            f"# {self.id}: {self.title}",
            "",
            f"Profile `{metrics.get('profile')}`; produced by `python -m paper run W2"
            + (" --full`" if metrics.get("profile") == "full" else "`")
            + f". Seeds: {metrics.get('seeds')}. SINDy: {metrics.get('sindy')}. Figures: means over "
            f"{N_TEST} held-out initial conditions, rolled out {metrics.get('test_steps')} steps of 0.1 against heyoka; energy: max "
            "relative error of the true H; Casimir drift: max |C(t) - C(0)| / (|grad C| |y|).",
            "",
            "## Verdict",
            "",
            *[f"- {v}" for v in metrics.get("verdict", [])],
            "",
            "## Every fit",
            "",
            ("| system | sampling | noise | model | state error t=100 | max energy error | Casimir drift | fit [s] "
             "| H~ family | H~ - H mod Casimirs | max error of 1/I_i - 1/I_j |"),
            "|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for r in metrics.get("rows", []):
            diff = r.get("difference_error")
            lines.append(
                f"| {r['system']} | {r['sampling']} | {r['noise']:g} | {r['model']} | {fmt(r['state_error'])} | "
                f"{fmt(r['energy_error'])} | {fmt(r.get('casimir_drift', float('nan')))} | {r['fit_s']:.1f} | "
                f"{r.get('family') or '—'} | {fmt(r.get('learned_hamiltonian_vs_H_mod_casimirs'))} | "
                f"{fmt(max(diff)) if diff is not None else '—'} |")
        return "\n".join(lines) + "\n"


def _version(name: str) -> str:
    from importlib.metadata import version

    return version(name)


def _peer(rows, row, model) -> dict[str, Any]:
    for r in rows:
        if (r["system"], r["sampling"], r["noise"], r["model"]) == (row["system"], row["sampling"], row["noise"], model):
            return r
    return {}


def line(row: dict) -> str:
    extra = ""
    if "difference_error" in row:
        extra = f", max |error of 1/I_i - 1/I_j| {np.max(row['difference_error']):.1e}"
    if row.get("family"):
        extra += f", H~ {row['family']}"
    if "learned_hamiltonian_vs_H_mod_casimirs" in row:
        extra += f", H~ - H mod Casimirs {fmt(row['learned_hamiltonian_vs_H_mod_casimirs'])}"
    return (f"{row['system']}, {row['sampling']}, noise {row['noise']:g}, {row['model']}: state error (t=100) "
            f"{fmt(row['state_error'])}, energy {fmt(row['energy_error'])}, Casimir "
            f"{fmt(row.get('casimir_drift', float('nan')))}, fit {row['fit_s']:.1f} s{extra}")


def verdict(rows: list[dict[str, Any]]) -> list[str]:
    """Per system, sampling and noise: the G-LPNet against SINDy and the parametric limit."""
    out = []
    for r in rows:
        if r["model"] != "G-LPNet":
            continue
        limit, sindy = _peer(rows, r, "limit"), _peer(rows, r, "SINDy")
        parts = [f"{r['system']}, {r['sampling']}, noise {r['noise']:g}: G-LPNet state error {fmt(r['state_error'])}"]
        if limit and r["noise"] == 0:
            parts.append(f"the limit {fmt(limit['state_error'])} (exact data: the true family is exact up to its "
                         "RK4; the G-LPNet's error is that of its splitting)")
        elif limit:
            parts.append(f"{r['state_error'] / limit['state_error']:.2f}x the limit's ({fmt(limit['state_error'])}), "
                         f"energy error {r['energy_error'] / limit['energy_error']:.2f}x")
        if sindy:
            below = r["state_error"] < sindy["state_error"]
            parts.append(f"{'below' if below else 'ABOVE'} SINDy's {fmt(sindy['state_error'])}")
        parts.append(f"Casimir drift {fmt(r.get('casimir_drift', float('nan')))}")
        out.append("; ".join(parts))
    return out


def _plots(rows, out_dir: Path) -> list[str]:
    """Per system and sampling: state error at t = 100 against the noise, one line per model."""
    names = []
    for system in dict.fromkeys(r["system"] for r in rows):
        samplings = list(dict.fromkeys(r["sampling"] for r in rows if r["system"] == system))
        fig = figure(figsize=(5.5 * len(samplings), 4.5))
        axes = np.atleast_1d(fig.subplots(1, len(samplings)))
        for ax, sampling in zip(axes, samplings):
            sub = [r for r in rows if r["system"] == system and r["sampling"] == sampling]
            models = list(dict.fromkeys(r["model"] for r in sub))
            for model, style in zip(models, series_styles(len(models))):
                pts = sorted((r for r in sub if r["model"] == model), key=lambda r: r["noise"])
                noise = np.array([max(r["noise"], 1e-4) for r in pts])  # noise 0 drawn at 1e-4
                ax.loglog(noise, [r["state_error"] for r in pts], label=model, **style)
            ax.set_xlabel("noise (relative; 0 drawn at 1e-4)")
            ax.set_ylabel("mean state error at t = 100")
            ax.set_title(f"{system}, {sampling} sampling")
            span_decades(ax, "y")
            ax.legend()
        name = f"state_error_{system.replace(' ', '_')}.png"
        fig.savefig(out_dir / name, dpi=120)
        names.append(name)
    return names


EXPERIMENT = W2()


def bootstrap_differences(protocol: Protocol, data: it.Observations, n: int, seed: int = 0,
                          iterations: int | None = None) -> np.ndarray:
    """The rigid body's identified 1/I_i - 1/I_j from `n` G-LPNets, each fitted to the
    trajectories of `data` resampled with replacement (seeded): `(n, 3)`, their spread the
    uncertainty of the recovered differences."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        sample = data.select(rng.integers(0, len(data), len(data)))
        out.append(fit_glpnet(protocol, sample, TRAIN_SEED, iterations)[1]["differences"])
    return np.asarray(out)
