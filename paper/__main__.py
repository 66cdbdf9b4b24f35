"""`python -m paper`: reproduce the paper's experiments and print the paper's numbers beside ours.

    python -m paper                         # the paper's experiments E1-E6 (quick profile), then the summary
    python -m paper run E1 --full           # one (or more) experiments at the paper's budget
    python -m paper run W1                  # the learned-vs-classical study (beyond the paper)
    python -m paper run W2 W3               # learning from observations; dissipation (beyond the paper)
    python -m paper run W4                  # attitude, pose and velocities in, momenta latent (beyond the paper)
    python -m paper run W5                  # Zeitlin's fluid at N = 16, 32: a learned isospectral map (beyond the paper)
    python -m paper --profile smoke         # E1-E6 in seconds (meaningless numbers)
    python -m paper list                    # what is available
    python -m paper table                   # the verdict: each of the paper's claims, ours, reproduced?
    python -m paper table --reference       # the same for the committed --full results (paper/reference/)
    python -m paper table --long            # every figure beside the paper's
    python -m paper run E1 --scheduler      # the independent trainings on a local Dask cluster

Runs write into `--out DIR` (default `./paper-results`, one folder per experiment); the
committed reference results in `paper/reference/` are never written by a run.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
import time
from pathlib import Path

from integrators.internals import atomic_write_text

from ._cluster import ENV, THREADS, scheduler
from ._experiment import DEFAULT_OUT, REFERENCE_DIR, check_out_dir, markdown_row
from ._mappings import release_compiled_programs
from ._registry import EXPERIMENTS, PAPER_EXPERIMENTS
from ._verdict import SEEDS_FILE, SEEDS_KEY, verdict_table

PROFILES = ("smoke", "quick", "full")


def summary_table(results: dict[str, dict]) -> str:
    lines = [
        "| experiment | metric | paper | ours | baseline |",
        "|---|---|---|---|---|",
    ]
    for exp_id, metrics in results.items():
        exp = EXPERIMENTS[exp_id]
        try:
            rows = list(exp.rows(metrics))
        except (KeyError, TypeError, ValueError, IndexError, AttributeError) as err:
            print(f"warning: skipping {exp_id}: its metrics.json lacks or garbles what the table needs "
                  f"({type(err).__name__}: {err}); rerun `python -m paper run {exp_id}`", file=sys.stderr)
            continue
        for label, paper, ours, base in rows:
            lines.append(markdown_row((f"{exp_id} ({metrics.get('profile')})", label, paper, ours, base)))
    return "\n".join(lines) + "\n"


def load_results(folder: Path) -> dict[str, dict]:
    """The `metrics.json` of every experiment found in `folder`; a file that is not a JSON
    object is skipped with a warning naming it."""
    out = {}
    for exp_id in EXPERIMENTS:
        path = folder / exp_id / "metrics.json"
        if not path.exists():
            continue
        try:
            metrics = json.loads(path.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
            print(f"warning: skipping {path}: not valid JSON ({err}); rerun `python -m paper run {exp_id}`",
                  file=sys.stderr)
            continue
        if not isinstance(metrics, dict):
            print(f"warning: skipping {path}: expected a JSON object, got {type(metrics).__name__}", file=sys.stderr)
            continue
        seeds = folder / exp_id / SEEDS_FILE
        if seeds.exists():
            try:
                evidence = json.loads(seeds.read_text())
            except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
                print(f"warning: skipping {seeds}: not valid JSON ({err})", file=sys.stderr)
            else:
                if isinstance(evidence, dict) and isinstance(evidence.get("metrics"), dict):
                    metrics[SEEDS_KEY] = evidence
                else:
                    print(f"warning: skipping {seeds}: expected an object with a 'metrics' object "
                          "(written by python -m paper.e4_sweep)", file=sys.stderr)
        out[exp_id] = metrics
    return out


def _run(ids: list[str], profile: str, progress: bool | None, out: Path) -> int:
    unknown = [i for i in ids if i not in EXPERIMENTS]
    if unknown:
        print(f"unknown experiment(s) {unknown}; available: {', '.join(EXPERIMENTS)}", file=sys.stderr)
        return 2
    for folder in (out, *(out / i for i in ids)):  # before any experiment runs, one line if it fails
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as err:  # what check_out_dir cannot foresee: a dangling link, too long a name, a race
            why = (f"it is a link to {os.readlink(folder)!r}, which does not exist" if os.path.islink(folder) else
                   err.strerror or str(err))
            print(f"python -m paper: error: --out {str(folder)!r} cannot be created ({why}); give a folder you can "
                  "write to (python -m paper --out DIR)", file=sys.stderr)
            return 2
    for exp_id in ids:  # results saved there with other settings: before anything runs
        try:
            EXPERIMENTS[exp_id].check_settings(profile, out / exp_id)
        except ValueError as err:
            print(f"python -m paper: error: {err}", file=sys.stderr)
            return 2
    results = {}
    t0 = time.perf_counter()
    for exp_id in ids:
        exp = EXPERIMENTS[exp_id]
        print(f"== {exp_id}: {exp.title} ({profile} profile)")
        t = time.perf_counter()
        results[exp_id] = exp.execute(profile=profile, progress=progress, out_dir=out / exp_id)
        print(f"   done in {time.perf_counter() - t:.0f} s -> {out / exp_id}")
        release_compiled_programs()  # paper._mappings
    table = summary_table(results)
    atomic_write_text(out / "summary.md", table)
    verdict = verdict_table(EXPERIMENTS, {k: v for k, v in results.items() if EXPERIMENTS[k].paper_values},
                            load_results(REFERENCE_DIR))
    atomic_write_text(out / "verdict.md", verdict)
    print()
    if verdict.count("\n|") > 1:
        print(verdict)
    print(f"every figure beside the paper's: {out / 'summary.md'}; per experiment: {out}/<id>/table.md")
    print(f"total {time.perf_counter() - t0:.0f} s; results in {out}")
    return 0


def _options(parser: argparse.ArgumentParser, top: bool) -> None:
    # On the top level and on `run` alike; the subcommand's value wins when given there.
    default = (lambda v: v) if top else (lambda v: argparse.SUPPRESS)
    parser.add_argument("--out", type=Path, default=default(DEFAULT_OUT),
                        help="folder for the results (default ./paper-results)")
    parser.add_argument("--profile", choices=PROFILES, default=default(None),
                        help="training budget: smoke (seconds), quick (default, < 10 min), full (the paper's)")
    parser.add_argument("--full", action="store_true", default=default(False), help="short for --profile full")
    parser.add_argument("--no-progress", action="store_true", default=default(False), help="no progress bars")
    parser.add_argument(
        "--scheduler", nargs="?", const="local", default=default(os.environ.get(ENV) or THREADS), metavar="ADDRESS",
        help="where the independent trainings (seeds, baselines, G-LPNets, step sizes) run: 'threads' "
             "(threads of this process, one per core), 'processes' (worker processes on this machine, one per "
             "core), 'none' (this process, one after the other), "
             "a Dask scheduler address (tcp://host:8786), or no value for a Dask LocalCluster sized to this "
             f"machine (extra 'dask'); default ${ENV}, else 'threads'",
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m paper", description=__doc__.splitlines()[0])
    _options(parser, top=True)
    sub = parser.add_subparsers(dest="command")
    run = sub.add_parser("run", help="run experiments")
    run.add_argument("ids", nargs="+", help=f"experiment ids ({', '.join(EXPERIMENTS)})")
    _options(run, top=False)
    sub.add_parser("list", help="list the experiments")
    table = sub.add_parser("table", help="print the summary of saved results")
    table.add_argument("--out", type=Path, default=argparse.SUPPRESS, help="folder to read (default ./paper-results)")
    table.add_argument("--reference", action="store_true", help=f"the committed reference results ({REFERENCE_DIR})")
    table.add_argument("--long", action="store_true", help="every figure beside the paper's, not only the verdict")
    args = parser.parse_args(argv)

    if args.command == "list":
        for exp_id, exp in EXPERIMENTS.items():
            print(f"{exp_id}: {exp.title}")
        return 0
    if args.command == "table":
        folder = REFERENCE_DIR if args.reference else args.out
        saved = load_results(folder)
        if not saved:
            print(f"no results in {folder}: run `python -m paper --out {folder}` (or read the committed "
                  "ones with `python -m paper table --reference`)")
            return 0
        if args.long:
            print(summary_table(saved))
        else:
            print(verdict_table(EXPERIMENTS, {k: v for k, v in saved.items() if EXPERIMENTS[k].paper_values},
                                None if args.reference else load_results(REFERENCE_DIR)))
            print(f"(every figure: python -m paper table --long{' --reference' if args.reference else ''})")
        return 0
    if args.profile and args.full and args.profile != "full":
        parser.error(f"--full and --profile {args.profile} disagree")
    profile = args.profile or ("full" if args.full else "quick")
    ids = args.ids if args.command == "run" else list(PAPER_EXPERIMENTS)
    try:  # before the scheduler starts and any experiment runs: the folder and each experiment's
        for out in (args.out, *(args.out / i for i in ids)):
            check_out_dir(out, "--out")
    except ValueError as err:  # argparse's parser.error, on one line
        print(f"{parser.prog}: error: {err}", file=sys.stderr)
        return 2
    with contextlib.ExitStack() as stack:
        try:
            where = stack.enter_context(scheduler(args.scheduler))
        except (ImportError, ValueError) as err:  # no dask extra, unreachable scheduler (not a run's error)
            print(f"--scheduler: {err}", file=sys.stderr)
            return 2
        if where:
            print(f"trainings on the {where}")
        return _run(ids, profile, False if args.no_progress else None, args.out)  # None: bars on a terminal only


if __name__ == "__main__":
    sys.exit(main())
