"""The one-screen verdict: one row per number the paper reports (each experiment's
`paper_values`), ours beside it, and whether it is reproduced, beaten or not reached."""

from __future__ import annotations

import math
import statistics
from typing import Any

from ._experiment import AbstractExperiment, PaperValue, fmt, markdown_row, metric_value

#: "round-off" as the paper uses it: ours counts as round-off below this (relative drifts and
#: defects of float64 computations over thousands of steps, ~1e4 eps).
ROUNDOFF = 1e-12
#: An "about" figure (a rate) is reproduced within this factor either way.
APPROX_FACTOR = 1.5
#: An error or loss is "beaten" when ours is below the paper's by at least this factor.
BEATEN_FACTOR = 10.0


def judge(claim: PaperValue, ours: Any) -> str:
    """`"reproduced"`, `"beaten"` or `"not reached"` (with how far) for our value of a claim."""
    if isinstance(ours, list) and ours and all(isinstance(v, (int, float)) for v in ours):
        ours = max(ours)  # a value per trajectory: the claim holds for every one
    if isinstance(ours, str):  # a formatted count, "21,638"
        try:
            ours = float(ours.replace(",", ""))
        except ValueError:
            return "not measured"
    if ours is None or not isinstance(ours, (int, float)) or math.isnan(ours):
        return "not measured"
    ours = float(ours)
    if claim.kind == "roundoff":
        return "reproduced" if abs(ours) <= ROUNDOFF else f"not reached ({fmt(ours)} > round-off {ROUNDOFF:g})"
    if claim.kind == "count":
        return "reproduced" if ours == claim.value else f"differs ({ours / claim.value - 1:+.1%})"
    if claim.kind == "approx":
        ratio = ours / claim.value
        return "reproduced" if 1 / APPROX_FACTOR <= ratio <= APPROX_FACTOR else f"differs ({ratio:.2g}x)"
    if claim.kind != "upper":
        raise ValueError(f"unknown PaperValue kind {claim.kind!r} for {claim.metric}")
    if ours <= claim.value / BEATEN_FACTOR:
        return f"beaten ({claim.value / max(ours, 1e-300):.2g}x lower)"
    if ours <= claim.value:
        return "reproduced"
    return f"not reached ({ours / claim.value:.3g}x the paper's)"


#: The verdict of a claim a smaller profile does not reach but the committed `--full` reference
#: does: the budget, not the method, is what is missing.
NEEDS_FULL = "needs --full: reached there"


#: The key under which `load_results` puts an experiment's `paper-budget-seeds.json`: the paper's
#: own model trained at the paper's budget over seeds (E4: `python -m paper.e4_sweep`).
SEEDS_KEY = "paper_budget_seeds"
#: The file of an experiment's results folder that holds them.
SEEDS_FILE = "paper-budget-seeds.json"


def _seed_evidence(claim: PaperValue, seeds: dict) -> str:
    """"the paper's model at the paper's budget reaches it in k of n seeds (median m)"."""
    values = [float(v) for v in seeds["metrics"][claim.metric]]
    k = sum(not judge(claim, v).startswith(("not", "differs")) for v in values)
    median = statistics.median(values)
    return (f"at the paper's budget ({seeds.get('budget', '?')}) the paper's model reaches it in {k} of "
            f"{len(values)} seeds (median {fmt(median)})")


def verdict_rows(experiments: dict[str, AbstractExperiment], results: dict[str, dict],
                 reference: dict[str, dict] | None = None) -> list[tuple[str, ...]]:
    """`(experiment (profile), quantity, paper, ours, verdict)` for every claim of every
    experiment in `results`. A claim not reached at a profile other than `full` that the
    `full` results in `reference` (`paper/reference/`) reach is judged `NEEDS_FULL`, with
    the reference's figure."""
    rows = []
    for exp_id, metrics in results.items():
        exp = experiments[exp_id]
        full = (reference or {}).get(exp_id)
        seeds = metrics.get(SEEDS_KEY) or (full or {}).get(SEEDS_KEY)
        for claim in exp.paper_values:
            ours = metric_value(metrics, claim.metric)
            verdict = judge(claim, ours)
            if (verdict.startswith("not reached") and metrics.get("profile") != "full" and full
                    and full.get("profile") == "full"):
                there = metric_value(full, claim.metric)
                if not judge(claim, there).startswith(("not", "differs")):
                    verdict = f"{NEEDS_FULL} ({fmt(there)})"
            if verdict.startswith("not reached") and seeds and claim.metric in seeds.get("metrics", {}):
                verdict += "; " + _seed_evidence(claim, seeds)
            rows.append((f"{exp_id} ({metrics.get('profile')})", exp.label(claim.metric), claim.text, fmt(ours),
                         verdict))
    return rows


def verdict_table(experiments: dict[str, AbstractExperiment], results: dict[str, dict],
                  reference: dict[str, dict] | None = None) -> str:
    """The verdict as a markdown table, and a count of each verdict (`reference`: see
    `verdict_rows`)."""
    rows = verdict_rows(experiments, results, reference)
    lines = ["| experiment | quantity | paper | ours | verdict |", "|---|---|---|---|---|"]
    lines += [markdown_row(r) for r in rows]
    counts: dict[str, int] = {}
    for r in rows:
        key = r[-1].split(" (")[0]
        counts[key] = counts.get(key, 0) + 1
    summary = ", ".join(f"{n} {k}" for k, n in sorted(counts.items(), key=lambda kv: -kv[1]))
    return "\n".join(lines) + f"\n\n{len(rows)} claims: {summary}.\n"
