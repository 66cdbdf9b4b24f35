"""`python -m paper`: reproduce the paper's experiments and print the paper's numbers beside ours.

    python -m paper                   # every experiment at the quick profile, then the summary
    python -m paper run E1 --full     # one (or more) experiments at the paper's budget
    python -m paper list              # what is available
    python -m paper table             # the summary of the results already on disk
"""

from __future__ import annotations

import argparse
import json
import sys
import time

from ._experiment import RESULTS_DIR, atomic_write_text
from ._registry import EXPERIMENTS


def summary_table(results: dict[str, dict]) -> str:
    lines = [
        "| experiment | metric | paper | ours | baseline |",
        "|---|---|---|---|---|",
    ]
    for exp_id, metrics in results.items():
        exp = EXPERIMENTS[exp_id]
        for label, paper, ours, base in exp.rows(metrics):
            lines.append(f"| {exp_id} ({metrics.get('profile')}) | {label} | {paper} | {ours} | {base} |")
    return "\n".join(lines) + "\n"


def _load_saved() -> dict[str, dict]:
    out = {}
    for exp_id in EXPERIMENTS:
        path = RESULTS_DIR / exp_id / "metrics.json"
        if path.exists():
            try:
                out[exp_id] = json.loads(path.read_text())
            except json.JSONDecodeError as err:
                print(f"warning: {path} is not valid JSON ({err}); rerun `python -m paper run {exp_id}`")
    return out


def _run(ids: list[str], profile: str, progress: bool) -> int:
    unknown = [i for i in ids if i not in EXPERIMENTS]
    if unknown:
        print(f"unknown experiment(s) {unknown}; available: {', '.join(EXPERIMENTS)}", file=sys.stderr)
        return 2
    results = {}
    t0 = time.perf_counter()
    for exp_id in ids:
        exp = EXPERIMENTS[exp_id]
        print(f"== {exp_id}: {exp.title} ({profile} profile)")
        t = time.perf_counter()
        results[exp_id] = exp.execute(profile=profile, progress=progress)
        print(f"   done in {time.perf_counter() - t:.0f} s -> {RESULTS_DIR / exp_id}")
    table = summary_table(results)
    print()
    print(table)
    print(f"total {time.perf_counter() - t0:.0f} s")
    atomic_write_text(RESULTS_DIR / "summary.md", table)
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m paper", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command")
    run = sub.add_parser("run", help="run experiments")
    run.add_argument("ids", nargs="+", help=f"experiment ids ({', '.join(EXPERIMENTS)})")
    run.add_argument("--full", action="store_true", help="the paper's training budget")
    run.add_argument("--no-progress", action="store_true", help="no progress bars")
    run.add_argument("--profile", choices=("smoke", "quick", "full"), help=argparse.SUPPRESS)
    sub.add_parser("list", help="list the experiments")
    sub.add_parser("table", help="print the summary of saved results")
    args = parser.parse_args(argv)

    if args.command == "list":
        for exp_id, exp in EXPERIMENTS.items():
            print(f"{exp_id}: {exp.title}")
        return 0
    if args.command == "table":
        saved = _load_saved()
        if not saved:
            print("no results yet: run `python -m paper`")
            return 0
        print(summary_table(saved))
        return 0
    if args.command == "run":
        profile = args.profile or ("full" if args.full else "quick")
        return _run(args.ids, profile, not args.no_progress)
    return _run(list(EXPERIMENTS), "quick", True)


if __name__ == "__main__":
    sys.exit(main())
