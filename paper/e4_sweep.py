r"""E4's LPNet over seeds and training budgets: does the paper's model (MLP 3x32 sigmoid, 2404
parameters) reach the paper's 1-2% energy and 3-4% integral error over 2000 steps?

    python -m paper.e4_sweep [--out DIR] [--model lpnet] [--budgets ...] [--seeds 3] [--scheduler [ADDRESS]]
    python -m paper.e4_sweep --out DIR --report   # the table of the points finished so far

A `learn.sweep` over seed x budget on E4's data (one heyoka trajectory of 20000 points, 80/20
split): Adam with mini-batches of 1000 pairs for 45,000 and 90,000 steps (the committed E4 run is
seed 0 at 45,000), 90,000 Adam steps refined by 1000 iterations of full-batch L-BFGS-B, and the
paper's budget `paper2e5`: 2e5 full-batch Adam steps (about half an hour a seed on 2 cores).
Every point is checkpointed every 1000 Adam epochs, so an interrupted sweep resumes where it stopped.
`--model` picks the paper's LPNet (`lpnet`), the reversible LPNet (`reversible`) or the
reversible LPNet whose network is averaged over the sign symmetry -I (`reversible_equivariant`),
same MLP; the reversible ones are rolled out with 64 fixed-point iterations (16 do not converge
on E4: BENCHMARKS.md).
Every point is rolled out for 2000 steps from the data's last point against heyoka (as E4), and
the table `sweep.md` (and `e4-sweep.json`) lists the losses, the max relative energy and
integral errors, and whether they reach the paper's figures. Points are saved as they finish; a rerun skips them.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np

import integrators as it
import learn
import liepoisson as lp
from integrators.internals import atomic_write_text

from ._cluster import ENV, scheduler
from ._evaluate import measure_rollout
from ._experiment import fmt
from ._verdict import SEEDS_FILE
from .e4_charged_particle import HIDDEN, Y0

H = 0.1
N_POINTS, PREDICTION_STEPS = 20_000, 2000
BUDGETS = {  # name -> optimiser stages
    "adam45k": (learn.Adam(3000, learning_rate=1e-3, final_learning_rate=1e-5, batch_size=1000),),
    "adam90k": (learn.Adam(6000, learning_rate=1e-3, final_learning_rate=1e-5, batch_size=1000),),
    "adam90k+lbfgsb1k": (learn.Adam(6000, learning_rate=1e-3, final_learning_rate=1e-5, batch_size=1000),
                         learn.KeepIfBetter(learn.ScipyLBFGSB(1000))),
}
BUDGETS["paper2e5"] = (learn.Adam(200_000, learning_rate=1e-3, final_learning_rate=1e-5),)  # full batch
MODELS = ("lpnet", "reversible", "reversible_equivariant")
ROLLOUT_ITERATIONS = 64  # fixed-point iterations of a reversible step in the rollout
# Adam epochs between checkpoints of a point: every compiled chunk (learn's CHUNK = 1000 epochs),
# so that a mini-batch point (6000 epochs of 16 steps, hours for a reversible model) resumes too.
CHECKPOINT_EVERY = 1000
SMOKE = {"smoke": (learn.Adam(3, batch_size=1000),)}  # the pipeline in seconds (tests); not a default
PAPER_ENERGY, PAPER_INTEGRAL = 2e-2, 4e-2


def _make(point):
    system = lp.systems.ChargedParticle()
    parametrisation = learn.TestFlowParametrisation(system)
    model = point.get("model", "lpnet")
    if model == "reversible_equivariant":
        network = learn.GroupAveraged(learn.AffineMLP(system.dim, system.dim, HIDDEN, activation="sigmoid",
                                                      key=point["seed"]), lp.systems.sign_symmetries(system))
        return learn.Reversible(learn.LPNet(system, parametrisation=parametrisation, network=network))
    net = learn.LPNet(system, hidden=HIDDEN, activation="sigmoid", key=point["seed"], parametrisation=parametrisation)
    return learn.Reversible(net) if model == "reversible" else net


def _evaluate(model, point):
    """The rollout metrics of E4: 2000 steps from the data's last point against heyoka."""
    system = model.system
    if isinstance(model, it.AbstractImplicitStepMap):  # an implicit step: enough iterations to converge
        model = model.with_iterations(ROLLOUT_ITERATIONS)
    data = it.ground_truth(system, Y0, h=H, n_steps=N_POINTS - 1)
    reference = it.ground_truth(system, data.states[0, -1], h=H, n_steps=PREDICTION_STEPS)
    m = measure_rollout(model, None, system, reference.states,
                        integrals={"integral": system.angular_integral})["metrics"]
    return {"energy_rel_err_max": m["energy_rel_err_max"], "integral_rel_err_max": m["integral_rel_err_max"],
            "traj_err_final": m["traj_err_final"], "poisson_defect_max": m["poisson_defect_max"],
            **({"diverged_at_step": m["diverged_at_step"]} if "diverged_at_step" in m else {})}


def summary_lines(rows: list[dict]) -> list[str]:
    """Per model and budget: how many seeds reach the paper's energy, integral and both, with
    the median and range of each error."""
    groups: dict[tuple[str, str], list[dict]] = {}
    for r in rows:
        groups.setdefault((r["model"], r["budget"]), []).append(r)
    out = []
    for (model, budget), rs in groups.items():
        e = [r["energy_rel_err_max"] for r in rs]
        i = [r["integral_rel_err_max"] for r in rs]
        both = [r["seed"] for r in rs if r["energy_rel_err_max"] <= PAPER_ENERGY
                and r["integral_rel_err_max"] <= PAPER_INTEGRAL]
        out.append(
            f"- `{model}` at `{budget}`: {sum(v <= PAPER_ENERGY for v in e)} of {len(rs)} seeds reach the energy "
            f"figure, {sum(v <= PAPER_INTEGRAL for v in i)} the integral's, "
            f"{len(both)} both{' (seeds ' + ', '.join(map(str, both)) + ')' if both else ''}; "
            f"energy error median {_pct(np.median(e))} ({_pct(min(e))} to {_pct(max(e))}), "
            f"integral error median {_pct(np.median(i))} ({_pct(min(i))} to {_pct(max(i))})."
        )
    out.append("- Beside them, the symmetric G-LPNet of `python -m paper run E4 --full` (12 free modules, "
               "exactly Poisson, same pairs): its row `G-LPNet on the same data` in E4's `table.md`.")
    return out


def _pct(v: float) -> str:
    return f"{100 * v:.3g}%" if np.isfinite(v) else "inf"


def paper_budget_seeds(rows: list[dict]) -> dict | None:
    """The errors of the paper's LPNet at `paper2e5` per seed (None if the sweep has none):
    `{"model", "budget", "seeds", "metrics": {metric: [value per seed]}}`."""
    rs = [r for r in rows if r["model"] == "lpnet" and r["budget"] == "paper2e5"]
    if not rs:
        return None
    return {
        "model": "the paper's LPNet (MLP 3x32 sigmoid)",
        "budget": "2e5 full-batch Adam steps, learning rate 1e-3 -> 1e-5",
        "source": "python -m paper.e4_sweep --budgets paper2e5 (sweep.md)",
        "seeds": [r["seed"] for r in rs],
        "metrics": {k: [r[k] for r in rs] for k in ("energy_rel_err_max", "integral_rel_err_max",
                                                    "train_loss", "val_loss")},
    }


def _trajectory_error(m: dict) -> str:
    """The table's trajectory error, or the step at which the rollout stopped being finite (its
    errors are then infinite: see `measure_rollout`)."""
    step = m.get("diverged_at_step")
    return fmt(m["traj_err_final"]) if step is None else f"diverged at step {int(step)}"


def _data(point):
    return it.ground_truth(lp.systems.ChargedParticle(), Y0, h=H, n_steps=N_POINTS - 1)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m paper.e4_sweep", description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("paper-results") / "E4-sweep")
    parser.add_argument("--model", choices=MODELS, default="lpnet")
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--budgets", nargs="+", choices=[*BUDGETS, *SMOKE], default=list(BUDGETS))
    parser.add_argument("--scheduler", nargs="?", const="local", default=os.environ.get(ENV), metavar="ADDRESS")
    parser.add_argument("--report", action="store_true",
                        help="train nothing: write the table of the points already finished in --out")
    args = parser.parse_args(argv)
    if args.report and not (args.out / "points").is_dir():
        parser.error(f"--report: no sweep in {args.out} (no points/ folder)")
    # The paper's LPNet's points carry no "model" key (their folders predate the others).
    model = {} if args.model == "lpnet" else {"model": args.model}
    grid = [{"budget": b, "seed": s, **model} for b in args.budgets for s in range(args.seeds)]
    if not args.report:
        data = _data(None)
        with scheduler(args.scheduler) as where:
            if where:
                print(f"trainings on the {where}")
            learn.sweep(
                _make, [dict(p, optimiser={**BUDGETS, **SMOKE}[p["budget"]]) for p in grid], data, out=args.out,
                evaluate=_evaluate, validation_fraction=0.2, checkpoint_every=CHECKPOINT_EVERY,
            )
    lines = [
        "# E4 sweep: the paper's LPNet (MLP 3x32, 2404 parameters) and its reversible variants over seeds and budgets",
        "",
        "Produced by `python -m paper.e4_sweep " + " ".join(argv if argv is not None else sys.argv[1:]) + "`. "
        "Energy and integral errors: max relative over 2000 steps from the data's last point (as E4). "
        "The paper: energy 1-2%, integral 3-4%, losses < 1e-5. Fit times are wall times on the machine "
        "that ran the point, shared with other runs or paused at times: not speed figures.",
        "",
        ("| model | budget | seed | train loss | val loss | max energy error | max integral error | trajectory error (t=200) "
         "| reaches the paper's energy / integral | fit time [s] |"),
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    rows = []
    # The table lists every point finished in --out, also those of earlier (larger) grids.
    for r in learn.Sweep.load(args.out):
        m = r.metrics
        ok = f"{'yes' if m['energy_rel_err_max'] <= PAPER_ENERGY else 'no'} / " \
             f"{'yes' if m['integral_rel_err_max'] <= PAPER_INTEGRAL else 'no'}"
        lines.append(f"| {r.point.get('model', 'lpnet')} | {r.point['budget']} | {r.seed} | {fmt(m['train_loss'])} | {fmt(m['val_loss'])} | "
                     f"{fmt(m['energy_rel_err_max'])} | {fmt(m['integral_rel_err_max'])} | {_trajectory_error(m)} | "
                     f"{ok} | {m['wall_time_s']:.0f} |")
        rows.append({"model": r.point.get("model", "lpnet"), "budget": r.point["budget"], "seed": r.seed, **m})
    lines += ["", *summary_lines(rows)]
    text = "\n".join(lines) + "\n"
    atomic_write_text(args.out / "sweep.md", text)
    atomic_write_text(args.out / "e4-sweep.json", json.dumps(rows, indent=1) + "\n")
    seeds = paper_budget_seeds(rows)
    if seeds is not None:
        atomic_write_text(args.out / SEEDS_FILE, json.dumps(seeds, indent=1) + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
