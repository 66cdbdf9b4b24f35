"""The JSON file every benchmark writes: what was run (command, options, commit, machine) and
what it measured."""

from __future__ import annotations

import datetime
import json
import os
import platform
import shlex
import subprocess
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from integrators.internals import json_values

#: Where the benchmarks write by default; BENCHMARKS.md quotes the files committed here.
RESULTS = Path(__file__).resolve().parent / "results"


def jsonable(value: Any) -> Any:
    """`value` as JSON values (`integrators.internals.json_values`), a NaN as the string "nan"."""
    return json_values(value, nan="nan")


def _commit() -> str | None:
    """`git describe --always --dirty` of the repository (None outside a git checkout)."""
    try:
        out = subprocess.run(["git", "describe", "--always", "--dirty"], cwd=RESULTS.parent, capture_output=True,
                             text=True, check=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() or None


def default_out(name: str) -> Path:
    """`benchmarks/results/<name>.json`."""
    return RESULTS / f"{name}.json"


def add_output_arguments(parser: Any, name: str) -> None:
    """`--out` (default `default_out(name)`) and `--report` (print the saved table and stop),
    the options every benchmark shares."""
    parser.add_argument("--out", default=default_out(name))
    parser.add_argument("--report", action="store_true", help="print the table of the results saved in --out and stop")


def saved_results(out: str | os.PathLike) -> Any:
    """The `results` of the JSON file `write_json` wrote to `out`."""
    return json.loads(Path(out).read_text())["results"]


def write_json(out: str | os.PathLike, options: Any, results: Any) -> Path:
    """Write `results` with the command line, the parsed `options` (an `argparse.Namespace`
    or a dict), the commit and the machine to `out` (its folder created); returns the path."""
    path = Path(out)
    path.parent.mkdir(parents=True, exist_ok=True)
    options = vars(options) if not isinstance(options, Mapping) else options
    payload = {
        "command": shlex.join(["python", *getattr(sys, "orig_argv", sys.argv)[1:]]),
        "options": {k: v for k, v in options.items() if k != "out"},
        "commit": _commit(),
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version()},
        "results": results,
    }
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(jsonable(payload), indent=1) + "\n")
    tmp.replace(path)
    print(f"wrote {path}")
    return path
