"""Compare every figure of two `python -m paper` result folders (before and after a change).

    python tools/compare_paper_results.py BEFORE_DIR AFTER_DIR [--rtol 1e-12]

Walks each experiment's `metrics.json` in both folders and prints every number that differs by
more than `rtol` (relative), every string that differs and every key found in one only. Timings
(keys with `time`, `seconds` or `wall`, `fit_s`, `..._us`, W1's `cost_vs_strang`, and the
cost ratios "(N.Nx Strang)" inside W1's verdict text) are left out. W1's `rows` are
matched by (system, h, method), so runs with different sets of maps compare on the rows they
share. Exit status 1 if anything differs. Standard library only.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from pathlib import Path

#: A measured cost ratio written inside a text (W1's verdicts: "at <= its cost (4.6x Strang)").
COST_RATIO = re.compile(r"\(\d+(\.\d+)?x Strang\)")
TIMING = re.compile(r"(time|seconds|wall|cost_vs_strang|^fit_s$|_us$)", re.IGNORECASE)


def _rows_by_key(rows: list) -> dict | list:
    if rows and all(isinstance(r, dict) and {"system", "h", "method"} <= set(r) for r in rows):
        return {f"({r['system']}, h={r['h']}, {r['method']})": r for r in rows}
    return rows


def walk(x, y, path: str, rtol: float, out: list[str]) -> None:
    if isinstance(x, list) and isinstance(y, list) and path.endswith("/rows"):
        x, y = _rows_by_key(x), _rows_by_key(y)
        if isinstance(x, dict) and isinstance(y, dict):
            only = sorted(set(x) ^ set(y))
            if only:
                out.append(f"{path}: {len(only)} rows in one run only (not compared)")
            for k in sorted(set(x) & set(y)):
                walk(x[k], y[k], f"{path}{k}", rtol, out)
            return
    if isinstance(x, dict) and isinstance(y, dict):
        for k in sorted(set(x) | set(y)):
            if TIMING.search(k):
                continue
            if k not in x or k not in y:
                out.append(f"{path}/{k}: only {'before' if k in x else 'after'}")
                continue
            walk(x[k], y[k], f"{path}/{k}", rtol, out)
    elif isinstance(x, list) and isinstance(y, list):
        if len(x) != len(y):
            out.append(f"{path}: {len(x)} entries before, {len(y)} after")
            return
        for i, (u, v) in enumerate(zip(x, y)):
            walk(u, v, f"{path}[{i}]", rtol, out)
    elif isinstance(x, (int, float)) and isinstance(y, (int, float)) and not isinstance(x, bool):
        if x == y or (isinstance(x, float) and isinstance(y, float) and math.isnan(x) and math.isnan(y)):
            return
        rel = abs(x - y) / max(abs(x), abs(y))
        if not rel <= rtol:
            out.append(f"{path}: {x!r} -> {y!r} (relative {rel:.1e})")
    elif isinstance(x, str) and isinstance(y, str):
        if COST_RATIO.sub("(cost)", x) != COST_RATIO.sub("(cost)", y):
            out.append(f"{path}: {x!r} -> {y!r}")
    elif x != y:
        out.append(f"{path}: {x!r} -> {y!r}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("before", type=Path)
    parser.add_argument("after", type=Path)
    parser.add_argument("--rtol", type=float, default=1e-12)
    args = parser.parse_args(argv)
    total = 0
    for path in sorted(args.before.glob("*/metrics.json")):
        other = args.after / path.parent.name / "metrics.json"
        if not other.exists():
            print(f"{path.parent.name}: no metrics.json after")
            total += 1
            continue
        out: list[str] = []
        walk(json.loads(path.read_text()), json.loads(other.read_text()), path.parent.name, args.rtol, out)
        print(f"{path.parent.name}: {len(out)} difference(s)")
        for line in out:
            print("  " + line)
        total += len(out)
    return 1 if total else 0


if __name__ == "__main__":
    sys.exit(main())
