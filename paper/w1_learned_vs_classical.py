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
from integrators.internals import figure, save_figure, series_styles, span_decades

from ._cluster import map_trainings, on_cluster
from ._experiment import Column, Profile, fmt, optional, profiles, table_lines
from ._runner import AbstractStudy
from ._study import (
    AbstractStudyModel,
    ClassicalMap,
    Fitted,
    GLPNetModel,
    LPNetModel,
    Training,
    fit_all,
)
from ._study import (
    hamiltonian_mismatch as hamiltonian_mismatch,
)

PROFILES = profiles(
    # all_baselines: every classical map (else Strang and RK4); all_orderings: every Strang
    # ordering (else the default and its reverse)
    Profile(systems=("rigid body", "Kirchhoff"), all_baselines=True, all_orderings=True),
    # "quick" (< 10 min on 2 cores) spans the range with 3 of the 5 step sizes; "full" has all
    # 5 step sizes. Both time every Strang ordering: maps of equal work must measure equal.
    # "smoke" exercises the pipeline in seconds (tests): one system, one h, three baselines.
    smoke=Profile(hs=(0.1,), n_test=4, long_steps=200, save_every=10, lpnet_epochs=30, glpnet_iterations=20,
                  glpnet_starts=1, systems=("rigid body",), all_baselines=False),
    quick=Profile(hs=(0.025, 0.1, 0.4), n_test=100, long_steps=10_000, save_every=10, lpnet_epochs=3_000,
                  glpnet_iterations=400, glpnet_starts=1),
    full=Profile(hs=(0.025, 0.05, 0.1, 0.2, 0.4), n_test=100, long_steps=100_000, save_every=10,
                 lpnet_epochs=30_000, glpnet_iterations=3_000, glpnet_starts=2),
)
T_ERROR = 100.0  # global error measured at t = 100
N_OUTPUTS = 25  # outputs every 4.0 time units: every h in the list divides 4.0
DATA_SEED, TEST_SEED = 11, 110
TRANSFER_H = 0.1


@dataclasses.dataclass(frozen=True)
class Setting:
    """A system of the study, the cube its initial conditions are drawn from (`centre` +-
    `half_width` in every component), and whether its exact flow (`integrators.ExactFlow`: the
    rigid body's elliptic solution) is among the classical maps."""

    system: lp.systems.AbstractPoissonSystem
    centre: np.ndarray
    half_width: float
    exact_flow: bool = False


def settings() -> dict[str, Setting]:
    return {
        "rigid body": Setting(lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0)), np.zeros(3), 1.25, exact_flow=True),
        "Kirchhoff": Setting(
            lp.systems.Kirchhoff(inertia=(1.0, 2.0, 1.0), mass=(1.0, 2.0, 1.0)),
            np.array([1.0, 1.0, 1.0, -1.0, 1.0, 2.0]),
            0.1,
        ),
    }


@dataclasses.dataclass(frozen=True)
class W1Row:
    """One method at one step size: error and energy error at t = 100 against heyoka
    (`integrators.compare`), the Poisson defect, the cost per step relative to Strang's
    (`integrators.step_timing`, same run) and XLA's flop count, and the energy error and Casimir
    drift over the long run (`integrators.rollout_figures`); a learned map's training loss and
    time. A `diverged_at_step_*` is the first step at which the map stopped being finite."""

    system: str
    h: float
    method: str
    error_t100: float
    energy_error_t100: float
    poisson_defect: float
    cost_vs_strang: float
    flops_per_step: float
    diverged_at_step_t100: int | None
    energy_error_long: float
    casimir_drift_long: float
    diverged_at_step_long: int | None
    train_loss: float | None = optional()
    wall_time_s: float | None = optional()

    @property
    def learned(self) -> bool:
        return self.method in LEARNED


def _splitting(method: it.splitting.AbstractSplittingMethod):
    """`make(system, h)` of a classical splitting: `method` bound to the system's pieces and `h`."""
    return lambda system, h: it.Splitting(system, h, method)


def _classical_maps(setting: Setting, h: float, every: bool = True, orderings: bool = True) -> list[ClassicalMap]:
    n = len(setting.system.hamiltonian_splitting())
    if not every:
        return [ClassicalMap("Strang", _splitting(it.splitting.Strang()), h), ClassicalMap("RK4", it.RK4, h)]
    # Every ordering of the Strang splitting (Fasso 2003): 3! for the rigid body; for the four
    # pieces of Kirchhoff the cyclic shifts (4 of the 24).
    if not orderings:
        chosen = [tuple(range(n)), tuple(reversed(range(n)))]
    elif n <= 3:
        chosen = list(itertools.permutations(range(n)))
    else:
        chosen = [tuple(np.roll(range(n), k)) for k in range(n)]
    maps = []
    for p in chosen:
        label = "Strang" if tuple(p) == tuple(range(n)) else f"Strang{''.join(str(k + 1) for k in p)}"
        maps.append(ClassicalMap(label, _splitting(it.splitting.Strang(ordering=p)), h))
    for method in (it.splitting.LieTrotter(), it.splitting.TripleJump(), it.splitting.Suzuki(),
                   it.splitting.McLachlan4(), it.splitting.Yoshida6()):
        maps.append(ClassicalMap(type(method).__name__, _splitting(method), h))
    if n == 2:
        maps.append(ClassicalMap("BlanesMoan4", _splitting(it.splitting.BlanesMoan4()), h))
    maps.append(ClassicalMap("RK4", it.RK4, h))
    maps.append(ClassicalMap("ImplicitMidpoint", it.ImplicitMidpoint, h))
    if setting.exact_flow:
        maps.append(ClassicalMap("Exact (elliptic)", it.ExactFlow, h))
    return maps


def _learned_models(P: Profile) -> list[AbstractStudyModel]:
    """An LPNet (3x16, Adam) and a symmetric G-LPNet (Strang of 2 dim ridge Hamiltonians, BFGS
    from the identity warm start)."""
    return [
        LPNetModel("LPNet", (Training(learn.Adam(P.lpnet_epochs, learning_rate=1e-3, final_learning_rate=1e-5),
                                      validation_fraction=0.2, seed=0),)),
        GLPNetModel("G-LPNet (sym.)", (Training(
            learn.KeepIfBetter(learn.Restarts(learn.WarmStart(learn.ScipyBFGS(P.glpnet_iterations)), P.glpnet_starts)),
            validation_fraction=0.0, seed=0),),
                    method=it.splitting.Strang()),
    ]


LEARNED = ("LPNet", "G-LPNet (sym.)")


def _long_run(m: it.AbstractStepMap, y0s: np.ndarray, P: Profile) -> it.RolloutFigures:
    """The figures of `long_steps` steps (sampled every `save_every` steps): the energy error
    and Casimir drift are infinite if the map diverged (`diverged_at_step` says where)."""
    y = np.asarray(m.rollout(y0s, P.long_steps, save_every=P.save_every, nonfinite="return"))
    return it.rollout_figures(m, y, save_every=P.save_every, defect_points=0)


class SystemBlock:
    """A system of W1 at a profile: its held-out initial conditions and heyoka's reference from
    them, its training data at each step size, and the learned models fitted to each (`fitted`:
    the trainings at the step sizes are independent, so on a cluster, `--scheduler`, they run
    at once)."""

    def __init__(self, name: str, setting: Setting, P: Profile):
        self.name, self.setting, self.P = name, setting, P
        system, centre, width = setting.system, setting.centre, setting.half_width
        rng = np.random.default_rng(DATA_SEED)
        data_y0 = centre + rng.uniform(-width, width, size=(50, system.dim))
        self.test_y0 = centre + np.random.default_rng(TEST_SEED).uniform(-width, width, size=(P.n_test, system.dim))
        self.reference = it.ground_truth(system, self.test_y0, h=T_ERROR / N_OUTPUTS, n_steps=N_OUTPUTS,
                                         seed=TEST_SEED)
        self.datasets = [it.ground_truth(system, data_y0, h=h, n_steps=20, seed=DATA_SEED) for h in P.hs]
        self.learned = _learned_models(P)
        self._fitted: list[list[Fitted]] | None = None

    def fitted(self, progress: bool) -> list[list[Fitted]]:
        """The learned models fitted at each step size (fitted on first call)."""
        if self._fitted is None:
            self._fitted = map_trainings(fit_all, [(self.learned, self.setting.system, data,
                                                    progress and not on_cluster()) for data in self.datasets])
        return self._fitted


@dataclasses.dataclass
class Condition:
    """A system and a step size of W1 (the `index`-th of the profile's); `transfer`: the
    step-size transfer measured there (at `TRANSFER_H` only)."""

    block: SystemBlock
    index: int
    h: float
    transfer: dict[str, Any] | None = None


class W1(AbstractStudy):
    id = "W1"
    title = "learned vs classical splitting: rigid body and Kirchhoff, h = 0.025 .. 0.4"
    profiles = PROFILES
    row_type = W1Row

    def conditions(self, P):
        for name, setting in settings().items():
            if name not in P.systems:
                continue
            block = SystemBlock(name, setting, P)
            for index, h in enumerate(P.hs):
                yield Condition(block, index, h)
            # The classical maps' rollouts are compiled once per system (h is traced) and reused
            # across its step sizes; free them before the next system, or XLA's code memory grows
            # until LLVM cannot map more (seen at the fourth block when every block compiled anew).
            jax.clear_caches()

    def models(self, P, condition):
        block = condition.block
        return [*_classical_maps(block.setting, condition.h, P.all_baselines, P.all_orderings), *block.learned]

    def evaluate(self, condition, model, progress):
        raise NotImplementedError("W1 measures a condition's models together (condition_rows)")

    def condition_rows(self, profile, condition, models, out_dir, progress):
        """Every model at one step size, measured together: `integrators.compare` times each
        against Strang in the same run."""
        block, h = condition.block, condition.h
        system, test_y0, P = block.setting.system, block.test_y0, block.P
        learned = dict(zip((m.label for m in block.learned), block.fitted(progress)[condition.index]))
        fits: dict[str, Fitted] = {m.label: learned[m.label] if m.label in learned else m.fit(system) for m in models}
        maps = {label: f.step_map for label, f in fits.items()}
        comparison = it.compare(maps, system, test_y0, t_final=T_ERROR, n_outputs=N_OUTPUTS, reference=block.reference)
        strang = next(r for r in comparison.rows if r.label == "Strang")
        rows = []
        for r in comparison.rows:
            long = _long_run(maps[r.label], test_y0, P)
            rows.append(W1Row(
                system=block.name, h=h, method=r.label,
                error_t100=r.error_final,
                energy_error_t100=r.energy_error_max,
                poisson_defect=r.poisson_defect_max,
                cost_vs_strang=r.seconds_per_step / strang.seconds_per_step,
                flops_per_step=r.flops_per_step,
                diverged_at_step_t100=r.diverged_at_step,
                energy_error_long=long.energy_error_max,
                casimir_drift_long=long.casimir_drift_max,
                diverged_at_step_long=long.diverged_at_step,
                train_loss=fits[r.label].train_loss,
                wall_time_s=fits[r.label].wall_time_s,
            ))
        gnet = fits["G-LPNet (sym.)"].step_map
        if math.isclose(h, TRANSFER_H):
            condition.transfer = {f"{hh:g}": _long_run(gnet.with_h(hh), test_y0, P).energy_error_max
                                  for hh in (h, h / 2, h / 4)}
            condition.transfer.update(hamiltonian_mismatch(gnet.hamiltonian, system, test_y0))
            gnet.save(out_dir / f"glpnet-{block.name.replace(' ', '_')}-h{h:g}.h5")
        return rows

    def verdict(self, rows, conditions):
        return _verdict(rows)

    def figures(self, rows, conditions, out_dir):
        return _plots(rows, out_dir)

    def summary(self, P, rows, conditions):
        return {
            "transfer": {c.block.name: c.transfer for c in conditions if c.transfer is not None},
            "model": "LPNet 3x16 and symmetric G-LPNet (2 dim modules)",
            "long_steps": P.long_steps,
            "test_initial_conditions": P.n_test,
        }

    def summary_rows(self, rows):  # the summary table: one line per system and h for the learned maps
        return [(f"{r.system} h={r.h:g} {r.method} error(t=100)", "—", fmt(r.error_t100),
                 fmt(_strang(rows, r).error_t100)) for r in rows if r.learned]

    def description(self, metrics):
        return (
            f"{metrics.get('test_initial_conditions')} held-out initial conditions; error at "
            f"t = 100 against heyoka (max over trajectories of |y - y_ref|); energy error and Casimir "
            f"drift: max relative over {metrics.get('long_steps')} steps (sampled every 10), infinite for a "
            "map that diverged; cost: wall time per step / Strang's, same run (the fastest of 5 compiled "
            "rollouts of >= 50 ms each, `integrators.step_timing`); flops: XLA's count per step / Strang's.")

    def sections(self, metrics, rows):
        transfer = [
            ("Energy error: max relative over the long run at each step size. H~ - H on the test states "
             "(relative to max abs(H)): raw up to a constant; modulo Casimirs (after a least-squares fit "
             "by polynomials of degree <= 2 in them, which move no trajectory); and the vector fields "
             "B grad H~ against B grad H."),
            "",
            *table_lines(TRANSFER_COLUMNS, metrics.get("transfer", {}).items()),
        ]
        return [("Step-size transfer (symmetric G-LPNet trained at h = 0.1)", transfer),
                ("Every method", table_lines(_method_columns(rows), rows))]


TRANSFER_COLUMNS = (
    Column("system", lambda item: item[0]),
    Column("energy error at h=0.1", lambda item: item[1].get("0.1")),
    Column("h=0.05", lambda item: item[1].get("0.05")),
    Column("h=0.025", lambda item: item[1].get("0.025")),
    Column("H~ - H (raw)", lambda item: item[1].get("learned_hamiltonian_vs_H")),
    Column("H~ - H (mod Casimirs)", lambda item: item[1].get("learned_hamiltonian_vs_H_mod_casimirs")),
    Column("vector field", lambda item: item[1].get("learned_vector_field_vs_H")),
)


def _method_columns(rows: list[W1Row]) -> tuple[Column, ...]:
    return (
        Column("system", lambda r: r.system),
        Column("h", lambda r: f"{r.h:g}"),
        Column("method", lambda r: r.method),
        Column("error t=100", lambda r: _diverged(r.error_t100, r.diverged_at_step_t100)),
        Column("max energy error (long)", lambda r: _diverged(r.energy_error_long, r.diverged_at_step_long)),
        Column("Casimir drift (long)", lambda r: r.casimir_drift_long),
        Column("Poisson defect", lambda r: r.poisson_defect),
        Column("cost / Strang", lambda r: f"{r.cost_vs_strang:.2f}"),
        Column("flops / Strang", lambda r: f"{r.flops_per_step / _strang(rows, r).flops_per_step:.2f}"),
    )


def _diverged(value, step) -> str:
    """The figure `value`, or "inf (diverged at step k)" for a map that stopped being finite."""
    return fmt(value) if step is None else f"{fmt(value)} (diverged at step {step})"


def _strang(rows: list[W1Row], r: W1Row) -> W1Row:
    return next(s for s in rows if s.system == r.system and s.h == r.h and s.method == "Strang")


def _verdict(rows: list[W1Row]) -> list[str]:
    """Plain statements, computed from the rows: per system and h, where each learned map
    stands against Strang (same h) and against the best classical method at no more cost."""
    out = []
    for (name, h), group in itertools.groupby(rows, key=lambda r: (r.system, r.h)):
        group = list(group)
        strang = next(r for r in group if r.method == "Strang")
        for r in group:
            if not r.learned:
                continue
            peers = [c for c in group if not c.learned and c.cost_vs_strang <= r.cost_vs_strang
                     and np.isfinite(c.error_t100)]
            best = min(peers, key=lambda c: c.error_t100) if peers else strang
            wins = r.error_t100 < best.error_t100
            out.append(
                f"{name}, h = {h:g}: {r.method} error(t=100) {fmt(r.error_t100)} vs Strang "
                f"{fmt(strang.error_t100)}; best classical at <= its cost ({r.cost_vs_strang:.1f}x "
                f"Strang): {best.method} {fmt(best.error_t100)} -> {'WINS' if wins else 'loses'}; "
                f"energy error {fmt(r.energy_error_long)} vs Strang {fmt(strang.energy_error_long)}"
            )
    return out


def _plots(rows: list[W1Row], out_dir: Path) -> list[str]:
    """Per system: work-precision (error at t = 100 vs cost per unit time) and energy error vs h."""
    names = []
    for name in sorted({r.system for r in rows}):
        fig = figure(figsize=(12, 4.8))  # says how to install matplotlib if it is missing
        axes = fig.subplots(1, 2)
        sub = [r for r in rows if r.system == name]
        methods = list(dict.fromkeys(r.method for r in sub))
        for method, classical_style in zip(methods, series_styles(len(methods))):
            pts = sorted((r for r in sub if r.method == method), key=lambda r: r.h)
            hs = np.array([r.h for r in pts])
            cost = np.array([r.cost_vs_strang / r.h for r in pts])  # work per unit time
            err = np.array([r.error_t100 for r in pts])
            energy = np.array([r.energy_error_long for r in pts])
            learned = method in LEARNED
            style = {"marker": "o", "lw": 2.6, "color": "black" if method == "LPNet" else "crimson"} if learned \
                else {**classical_style, "lw": 1.0, "ms": 4}
            axes[0].loglog(cost, np.maximum(err, 1e-17), label=method, **style)
            axes[1].loglog(hs, np.maximum(energy, 1e-17), label=method, **style)
        span_decades(axes[0], "x")
        axes[0].set_xlabel("cost per unit time (Strang steps of h = 1)")
        axes[0].set_ylabel("global error at t = 100")
        axes[0].set_title(f"{name}: work-precision")
        axes[1].set_xticks(sorted({r.h for r in sub}), [f"{h:g}" for h in sorted({r.h for r in sub})])
        axes[1].minorticks_off()
        axes[1].set_xlabel("h")
        axes[1].set_ylabel("max relative energy error")
        axes[1].set_title(f"{name}: energy error vs step size")
        axes[1].legend(fontsize=7, ncol=2)
        fig.tight_layout()
        names.append(f"work_precision_{name.replace(' ', '_')}.png")
        save_figure(fig, out_dir / names[-1], dpi=120)
    return names


EXPERIMENT = W1()
