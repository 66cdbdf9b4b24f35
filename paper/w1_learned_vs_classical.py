"""W1 (beyond the paper): learned against classical Lie-Poisson splitting at equal step size.

For the rigid body I = diag(1, 2, 3) on so(3)* and Kirchhoff's body on se(3)*, and each step
h in {0.025, 0.05, 0.1, 0.2, 0.4}: an LPNet (3x16, Adam) and a symmetric G-LPNet (the Strang
splitting of a learned sum of ridge Hamiltonians, BFGS with the identity warm start) are
trained on heyoka data at that h, then rolled out with every classical baseline from the same
100 held-out initial conditions. Per method and h: global error at t = 100 against heyoka,
max relative energy error and Casimir drift over the long run (10^4 steps quick, 10^5 full),
Poisson defect, and the wall time per step relative to Strang measured in the same run.
Also: the symmetric G-LPNet trained at h = 0.1 run at h/2 and h/4 (step-size transfer).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from pathlib import Path
from typing import Any

import jax
import numpy as np

import integrators as it
import learn
import liepoisson as lp
from integrators.internals import figure, series_styles, span_decades

from ._cluster import map_trainings, on_cluster
from ._experiment import AbstractExperiment, fmt


@dataclasses.dataclass(frozen=True)
class Profile:
    hs: tuple[float, ...]
    n_test: int
    long_steps: int
    save_every: int
    lpnet_epochs: int
    glpnet_iterations: int
    glpnet_restarts: int
    systems: tuple[str, ...] = ("rigid body", "Kirchhoff")
    all_baselines: bool = True
    all_orderings: bool = True  # every Strang ordering, or the default and its reverse


PROFILES = {
    # "quick" (< 10 min on 2 cores) spans the range with 3 of the 5 step sizes; "full" has all
    # 5 step sizes. Both time every Strang ordering: maps of equal work must measure equal.
    # "smoke" exercises the pipeline in seconds (tests): one system, one h, three baselines.
    "smoke": Profile((0.1,), n_test=4, long_steps=200, save_every=10, lpnet_epochs=30,
                     glpnet_iterations=20, glpnet_restarts=1, systems=("rigid body",), all_baselines=False),
    "quick": Profile((0.025, 0.1, 0.4), n_test=100, long_steps=10_000, save_every=10,
                     lpnet_epochs=3_000, glpnet_iterations=400, glpnet_restarts=1),
    "full": Profile((0.025, 0.05, 0.1, 0.2, 0.4), n_test=100, long_steps=100_000, save_every=10,
                    lpnet_epochs=30_000, glpnet_iterations=3_000, glpnet_restarts=2),
}
T_ERROR = 100.0  # global error measured at t = 100
N_OUTPUTS = 25  # outputs every 4.0 time units: every h in the list divides 4.0
DATA_SEED, TEST_SEED = 11, 110
TRANSFER_H = 0.1


def _systems() -> dict[str, tuple[lp.systems.AbstractPoissonSystem, np.ndarray, float]]:
    """name -> (system, centre of the initial conditions, half-width of the cube around it)."""
    return {
        "rigid body": (lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0)), np.zeros(3), 1.25),
        "Kirchhoff": (
            lp.systems.Kirchhoff(inertia=(1.0, 2.0, 1.0), mass=(1.0, 2.0, 1.0)),
            np.array([1.0, 1.0, 1.0, -1.0, 1.0, 2.0]),
            0.1,
        ),
    }


def _baselines(
    system: lp.systems.AbstractPoissonSystem, h: float, every: bool = True, orderings: bool = True
) -> dict[str, it.AbstractStepMap]:
    n = len(system.hamiltonian_splitting())
    maps: dict[str, it.AbstractStepMap] = {}
    if not every:
        return {"Strang": it.splitting.Strang(system, h), "RK4": it.RK4(system, h)}
    # Every ordering of the Strang splitting (Fasso 2003): 3! for the rigid body; for the four
    # pieces of Kirchhoff the cyclic shifts (4 of the 24).
    if not orderings:
        chosen = [tuple(range(n)), tuple(reversed(range(n)))]
    elif n <= 3:
        chosen = list(itertools.permutations(range(n)))
    else:
        chosen = [tuple(np.roll(range(n), k)) for k in range(n)]
    for p in chosen:
        label = "Strang" if tuple(p) == tuple(range(n)) else f"Strang{''.join(str(k + 1) for k in p)}"
        maps[label] = it.splitting.Strang(system, h, ordering=p)
    for cls in (it.splitting.LieTrotter, it.splitting.TripleJump, it.splitting.Suzuki,
                it.splitting.McLachlan4, it.splitting.Yoshida6):
        maps[cls.__name__] = cls(system, h)
    if n == 2:
        maps["BlanesMoan4"] = it.splitting.BlanesMoan4(system, h)
    maps["RK4"] = it.RK4(system, h)
    maps["ImplicitMidpoint"] = it.ImplicitMidpoint(system, h)
    if callable(getattr(system, "exact_flow", None)):
        maps["Exact (elliptic)"] = it.ExactFlow(system, h)
    return maps


def _long_run(m: it.AbstractStepMap, y0s: np.ndarray, P: Profile) -> dict[str, Any]:
    """Max relative energy error and Casimir drift over `long_steps` steps (sampled every
    `save_every` steps), infinite if the map diverged (`diverged_at_step_long` says where)."""
    y = np.asarray(m.rollout(y0s, P.long_steps, save_every=P.save_every, nonfinite="return"))
    figures = it.rollout_figures(m, y, save_every=P.save_every, defect_points=0)
    return {
        "energy_error_long": figures.energy_error_max,
        "casimir_drift_long": figures.casimir_drift_max,
        "diverged_at_step_long": figures.diverged_at_step,
    }


def _train(system, data, P: Profile, progress: bool):
    lpnet, lrec = learn.fit(
        learn.LPNet(system, key=0), data,
        optimiser=learn.Adam(P.lpnet_epochs, learning_rate=1e-3, final_learning_rate=1e-5),
        validation_fraction=0.2, seed=0, progress=progress,
    )
    gnet, grec = learn.fit(
        learn.GLPNet(system, n_modules=2 * system.dim, key=0, method=it.splitting.Strang), data,
        optimiser=learn.QuasiNewton(P.glpnet_iterations, "bfgs", restarts=P.glpnet_restarts, warm_start=True),
        validation_fraction=0.0, seed=0, progress=progress,
    )
    return (lpnet, lrec), (gnet, grec)


class W1(AbstractExperiment):
    id = "W1"
    title = "learned vs classical splitting: rigid body and Kirchhoff, h = 0.025 .. 0.4"
    paper_values = ()

    def run(self, profile: str, out_dir: Path, progress: bool):
        P = PROFILES[profile]
        rows: list[dict[str, Any]] = []
        transfer: dict[str, Any] = {}
        for name, (system, centre, width) in _systems().items():
            if name not in P.systems:
                continue
            rng = np.random.default_rng(DATA_SEED)
            data_y0 = centre + rng.uniform(-width, width, size=(50, system.dim))
            test_y0 = centre + np.random.default_rng(TEST_SEED).uniform(-width, width, size=(P.n_test, system.dim))
            reference = it.ground_truth(system, test_y0, h=T_ERROR / N_OUTPUTS, n_steps=N_OUTPUTS, seed=TEST_SEED)
            datasets = [it.ground_truth(system, data_y0, h=h, n_steps=20, seed=DATA_SEED) for h in P.hs]
            # The trainings at the step sizes are independent: on a cluster (--scheduler) they run at once.
            trainings = map_trainings(_train, [(system, data, P, progress and not on_cluster()) for data in datasets])
            for h, ((lpnet, lrec), (gnet, grec)) in zip(P.hs, trainings):
                maps = _baselines(system, h, P.all_baselines, P.all_orderings)
                maps["LPNet"] = lpnet
                maps["G-LPNet (sym.)"] = gnet
                comparison = it.compare(maps, system, test_y0, t_final=T_ERROR, n_outputs=N_OUTPUTS, reference=reference)
                strang = next(r for r in comparison.rows if r.label == "Strang")
                for r in comparison.rows:
                    row = {
                        "system": name, "h": h, "method": r.label,
                        "error_t100": r.error_final,
                        "energy_error_t100": r.energy_error_max,
                        "poisson_defect": r.poisson_defect_max,
                        "cost_vs_strang": r.seconds_per_step / strang.seconds_per_step,
                        "flops_per_step": r.flops_per_step,
                        "diverged_at_step_t100": r.diverged_at_step,
                        **_long_run(maps[r.label], test_y0, P),
                    }
                    if r.label == "LPNet":
                        row["train_loss"], row["wall_time_s"] = lrec.train_loss, lrec.wall_time_s
                    if r.label.startswith("G-LPNet"):
                        row["train_loss"], row["wall_time_s"] = grec.train_loss, grec.wall_time_s
                    rows.append(row)
                if math.isclose(h, TRANSFER_H):
                    transfer[name] = {
                        f"{hh:g}": _long_run(gnet.with_h(hh), test_y0, P)["energy_error_long"]
                        for hh in (h, h / 2, h / 4)
                    }
                    transfer[name].update(hamiltonian_mismatch(gnet.hamiltonian, system, test_y0))
                    gnet.save(out_dir / f"glpnet-{name.replace(' ', '_')}-h{h:g}.h5")
            # The classical maps' rollouts are compiled once per system (h is traced) and reused
            # across its step sizes; free them before the next system, or XLA's code memory grows
            # until LLVM cannot map more (seen at the fourth block when every block compiled anew).
            jax.clear_caches()
        figures = _plots(rows, out_dir)
        return {
            "figures": figures,
            "rows": rows,
            "transfer": transfer,
            "verdict": _verdict(rows),
            "model": "LPNet 3x16 and symmetric G-LPNet (2 dim modules)",
            "long_steps": P.long_steps,
            "test_initial_conditions": P.n_test,
        }

    def rows(self, metrics):  # the summary table: one line per system and h for the learned maps
        out = []
        for r in metrics.get("rows", []):
            if r["method"] in ("LPNet", "G-LPNet (sym.)"):
                out.append((f"{r['system']} h={r['h']:g} {r['method']} error(t=100)", "—",
                            fmt(r["error_t100"]), fmt(_strang(metrics["rows"], r)["error_t100"])))
        return out

    def markdown_table(self, metrics):
        P = metrics.get("profile")
        lines = [
            f"# {self.id}: {self.title}",
            "",
            f"Profile `{P}`; produced by `python -m paper run W1" + (" --full`" if P == "full" else "`")
            + f". {metrics.get('test_initial_conditions')} held-out initial conditions; error at "
            f"t = 100 against heyoka (max over trajectories of |y - y_ref|); energy error and Casimir "
            f"drift: max relative over {metrics.get('long_steps')} steps (sampled every 10), infinite for a "
            "map that diverged; cost: wall time per step / Strang's, same run (the fastest of 5 compiled "
            "rollouts of >= 50 ms each, `integrators.step_timing`); flops: XLA's count per step / Strang's.",
            "",
            "## Verdict",
            "",
            *[f"- {v}" for v in metrics.get("verdict", [])],
            "",
            "## Step-size transfer (symmetric G-LPNet trained at h = 0.1)",
            "",
            ("Energy error: max relative over the long run at each step size. H~ - H on the test states "
            "(relative to max abs(H)): raw up to a constant; modulo Casimirs (after a least-squares fit "
            "by polynomials of degree <= 2 in them, which move no trajectory); and the vector fields "
            "B grad H~ against B grad H."),
            "",
            ("| system | energy error at h=0.1 | h=0.05 | h=0.025 | H~ - H (raw) | H~ - H (mod Casimirs) "
            "| vector field |"),
            "|---|---|---|---|---|---|---|",
        ]
        for name, t in metrics.get("transfer", {}).items():
            lines.append(f"| {name} | {fmt(t.get('0.1'))} | {fmt(t.get('0.05'))} | {fmt(t.get('0.025'))} | "
                         f"{fmt(t.get('learned_hamiltonian_vs_H'))} | "
                         f"{fmt(t.get('learned_hamiltonian_vs_H_mod_casimirs'))} | "
                         f"{fmt(t.get('learned_vector_field_vs_H'))} |")
        lines += ["", "## Every method", "",
                  ("| system | h | method | error t=100 | max energy error (long) | Casimir drift (long) "
                   "| Poisson defect | cost / Strang | flops / Strang |"),
                  "|---|---|---|---|---|---|---|---|---|"]
        for r in metrics.get("rows", []):
            lines.append(
                f"| {r['system']} | {r['h']:g} | {r['method']} | {_diverged(r, 'error_t100', 'diverged_at_step_t100')} | "
                f"{_diverged(r, 'energy_error_long', 'diverged_at_step_long')} | {fmt(r['casimir_drift_long'])} | "
                f"{fmt(r['poisson_defect'])} | {r['cost_vs_strang']:.2f} | "
                f"{r['flops_per_step'] / _strang(metrics['rows'], r)['flops_per_step']:.2f} |"
            )
        return "\n".join(lines) + "\n"


def _diverged(row, key, step_key) -> str:
    """The figure `row[key]`, or "inf (diverged at step k)" for a map that stopped being finite."""
    step = row.get(step_key)
    return fmt(row[key]) if step is None else f"{fmt(row[key])} (diverged at step {step})"


def _strang(rows, r):
    return next(s for s in rows if s["system"] == r["system"] and s["h"] == r["h"] and s["method"] == "Strang")


def hamiltonian_mismatch(learned_hamiltonian, system, y) -> dict[str, float]:
    r"""How far a learned Hamiltonian $\widetilde H$ is from the system's $H$ on the states `y`:

    - `learned_hamiltonian_vs_H`: $\max|d - \bar d| / \max|H|$ with $d = \widetilde H - H$. A
      function of the Casimirs in $d$ shows here although it moves no trajectory;
    - `learned_hamiltonian_vs_H_mod_casimirs`: the same after subtracting from $d$ its
      least-squares fit by the polynomials of degree $\le 2$ in the Casimirs;
    - `learned_vector_field_vs_H`: $\max|X_{\widetilde H} - X_H| / \max|X_H|$ with
      $X_F = \mathbb B(y)\nabla F$: blind to Casimir terms by construction.
    """
    y = np.asarray(y, dtype=np.float64)
    H = np.asarray(system.hamiltonian(y))
    d = np.asarray(learned_hamiltonian(y)) - H
    C = np.asarray(system.casimirs(y))
    k = C.shape[-1]
    basis = np.stack([np.ones_like(d), *C.T, *(C[:, i] * C[:, j] for i in range(k) for j in range(i, k))], axis=-1)
    fit, *_ = np.linalg.lstsq(basis, d, rcond=None)
    grad = jax.vmap(jax.grad(lambda z: learned_hamiltonian(z[None])[0]))(y)
    X_learned = np.einsum("...ab,...b->...a", np.asarray(system.poisson_tensor(y)), np.asarray(grad))
    X = np.asarray(system.vector_field(y))
    return {
        "learned_hamiltonian_vs_H": float(np.max(np.abs(d - d.mean())) / np.max(np.abs(H))),
        "learned_hamiltonian_vs_H_mod_casimirs": float(np.max(np.abs(d - basis @ fit)) / np.max(np.abs(H))),
        "learned_vector_field_vs_H": float(
            np.max(np.linalg.norm(X_learned - X, axis=-1)) / np.max(np.linalg.norm(X, axis=-1))
        ),
    }


def _verdict(rows) -> list[str]:
    """Plain statements, computed from the rows: per system and h, where each learned map
    stands against Strang (same h) and against the best classical method at no more cost."""
    out = []

    def classical(r):
        return r["method"] not in ("LPNet", "G-LPNet (sym.)")

    for (name, h), group in itertools.groupby(rows, key=lambda r: (r["system"], r["h"])):
        group = list(group)
        strang = next(r for r in group if r["method"] == "Strang")
        for r in group:
            if classical(r):
                continue
            peers = [c for c in group if classical(c) and c["cost_vs_strang"] <= r["cost_vs_strang"]
                     and np.isfinite(c["error_t100"])]
            best = min(peers, key=lambda c: c["error_t100"]) if peers else strang
            wins = r["error_t100"] < best["error_t100"]
            out.append(
                f"{name}, h = {h:g}: {r['method']} error(t=100) {fmt(r['error_t100'])} vs Strang "
                f"{fmt(strang['error_t100'])}; best classical at <= its cost ({r['cost_vs_strang']:.1f}x "
                f"Strang): {best['method']} {fmt(best['error_t100'])} -> {'WINS' if wins else 'loses'}; "
                f"energy error {fmt(r['energy_error_long'])} vs Strang {fmt(strang['energy_error_long'])}"
            )
    return out


def _plots(rows, out_dir: Path) -> list[str]:
    """Per system: work-precision (error at t = 100 vs cost per unit time) and energy error vs h."""
    names = []
    for name in sorted({r["system"] for r in rows}):
        fig = figure(figsize=(12, 4.8))  # says how to install matplotlib if it is missing
        axes = fig.subplots(1, 2)
        sub = [r for r in rows if r["system"] == name]
        methods = list(dict.fromkeys(r["method"] for r in sub))
        for method, classical_style in zip(methods, series_styles(len(methods))):
            pts = sorted((r for r in sub if r["method"] == method), key=lambda r: r["h"])
            hs = np.array([r["h"] for r in pts])
            cost = np.array([r["cost_vs_strang"] / r["h"] for r in pts])  # work per unit time
            err = np.array([r["error_t100"] for r in pts])
            energy = np.array([r["energy_error_long"] for r in pts])
            learned = method in ("LPNet", "G-LPNet (sym.)")
            style = {"marker": "o", "lw": 2.6, "color": "black" if method == "LPNet" else "crimson"} if learned \
                else {**classical_style, "lw": 1.0, "ms": 4}
            axes[0].loglog(cost, np.maximum(err, 1e-17), label=method, **style)
            axes[1].loglog(hs, np.maximum(energy, 1e-17), label=method, **style)
        span_decades(axes[0], "x")
        axes[0].set_xlabel("cost per unit time (Strang steps of h = 1)")
        axes[0].set_ylabel("global error at t = 100")
        axes[0].set_title(f"{name}: work-precision")
        axes[1].set_xticks(sorted({r["h"] for r in sub}), [f"{h:g}" for h in sorted({r["h"] for r in sub})])
        axes[1].minorticks_off()
        axes[1].set_xlabel("h")
        axes[1].set_ylabel("max relative energy error")
        axes[1].set_title(f"{name}: energy error vs step size")
        axes[1].legend(fontsize=7, ncol=2)
        fig.tight_layout()
        names.append(f"work_precision_{name.replace(' ', '_')}.png")
        fig.savefig(out_dir / names[-1], dpi=120)
    return names


EXPERIMENT = W1()
