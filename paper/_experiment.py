"""What every experiment of the paper shares: profiles, result files, the paper-vs-ours table."""

from __future__ import annotations

import abc
import contextvars
import dataclasses
import json
import math
import os
import time
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from types import MappingProxyType
from typing import Any

from integrators.internals import atomic_write_text, json_values

# The committed results of `python -m paper run ... --full`, quoted by the README and
# BENCHMARKS.md: read by `python -m paper table --reference`, never written by a run.
REFERENCE_DIR = Path(__file__).resolve().parent / "reference"
# Where runs write, relative to the working directory.
DEFAULT_OUT = Path("paper-results")

# The keys every experiment's metrics.json carries (issue 4), for ours and for the baseline.
METRIC_KEYS = (
    "train_loss",
    "val_loss",
    "energy_rel_err_max",
    "energy_rel_err_mean",
    "casimir_rel_drift_max",
    "traj_err_final",
    "poisson_defect_max",
    "wall_time_s",
)


# Rows for the G-LPNet trained on an LPNet experiment's data (`metrics["glpnet"]`).
GLPNET_ROWS = (
    ("glpnet.train_loss", "G-LPNet on the same data: training loss"),
    ("glpnet.energy_rel_err_max", "G-LPNet on the same data: max |rel. energy error|"),
    ("glpnet.traj_err_final", "G-LPNet on the same data: trajectory error at the end"),
    ("glpnet.poisson_defect_max", "G-LPNet on the same data: max Poisson defect"),
)
# The paper trains with Adam only; our LPNets are then refined by L-BFGS-B (see each experiment).
ADAM_ROWS = (
    ("adam_only.train_loss", "before L-BFGS-B (Adam only, the paper's optimiser): training loss"),
    ("adam_only.energy_rel_err_max", "before L-BFGS-B (Adam only): max |rel. energy error|"),
    ("adam_only.traj_err_final", "before L-BFGS-B (Adam only): trajectory error at the end"),
)


class Profile:
    """An experiment's budget at one of `python -m paper`'s profiles (smoke, quick, full): its
    settings by name, read as attributes (`P.epochs`), fixed once made. One type for every
    experiment and study; each makes its three with `profiles`, which checks that they set the
    same names."""

    __slots__ = ("_settings",)

    def __init__(self, **settings: Any):
        object.__setattr__(self, "_settings", MappingProxyType(dict(settings)))

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):  # `_settings` itself before it is set (unpickling), dunders
            raise AttributeError(name)
        try:
            return self._settings[name]
        except KeyError:
            raise AttributeError(f"the profile has no setting {name!r}; it has {', '.join(self._settings)}") from None

    def __setattr__(self, name: str, value: Any) -> None:
        raise dataclasses.FrozenInstanceError(f"a Profile is fixed once made: use P.replace({name}=...)")

    def __reduce__(self):
        return _profile, (dict(self._settings),)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Profile) and dict(self._settings) == dict(other._settings)

    __hash__ = None  # type: ignore[assignment]  (settings may be dicts)

    def __repr__(self) -> str:
        return f"Profile({', '.join(f'{k}={v!r}' for k, v in self._settings.items())})"

    def replace(self, **changes: Any) -> Profile:
        """This profile with `changes` (names it has only: `ValueError` otherwise)."""
        unknown = sorted(set(changes) - set(self._settings))
        if unknown:
            raise ValueError(f"Profile.replace: no setting(s) {unknown}; the profile has {', '.join(self._settings)}")
        return Profile(**{**self._settings, **changes})

    def as_dict(self) -> dict[str, Any]:
        """The settings as a dict (what metrics.json records as `profile_settings`)."""
        return dict(self._settings)


def _profile(settings: dict[str, Any]) -> Profile:
    return Profile(**settings)


def profiles(defaults: Profile | None = None, **by_name: Profile) -> dict[str, Profile]:
    """`{name: profile}` for each `name=profile` (smoke, quick, full), each with the settings of
    `defaults` it does not give: `ValueError` naming the profile and the settings if one lacks a
    name another sets (a misspelt setting)."""
    base = {} if defaults is None else defaults.as_dict()
    made = {name: Profile(**{**base, **P.as_dict()}) for name, P in by_name.items()}
    names = set().union(*(set(P.as_dict()) for P in made.values()))
    for name, P in made.items():
        missing = sorted(names - set(P.as_dict()))
        if missing:
            raise ValueError(f"profiles: the {name!r} profile lacks {missing}, which another profile sets; give them "
                             "in every profile or in defaults")
    return made


@dataclasses.dataclass(frozen=True)
class PaperValue:
    """A number the paper reports (`text` as the paper writes it) and how ours is judged
    against it (`kind`, see `paper._verdict`): `"upper"` (an error, a loss: lower is better),
    `"roundoff"` (the paper reports round-off or exactly 0), `"approx"` (a rate: about equal),
    `"count"` (a number of parameters: equal)."""

    metric: str
    value: float
    text: str
    kind: str = "upper"


def _jsonable(x: Any) -> Any:
    return json_values(x)  # NaN as JSON null: "not measured" (e.g. no validation set)


def metric_value(metrics: dict[str, Any], key: str) -> Any:
    """`metrics[key]`, a dotted key `glpnet.x` reading a nested block; None if absent."""
    d: Any = metrics
    for part in key.split("."):
        if not isinstance(d, dict) or part not in d:
            return None
        d = d[part]
    return d


def markdown_row(cells) -> str:
    """One row of a Markdown table; a "|" inside a cell (|rel. energy error|) is escaped, or
    it would end the cell."""
    return "| " + " | ".join(str(cell).replace("|", "\\|") for cell in cells) + " |"


def fmt(x: Any) -> str:
    if x is None:
        return "—"
    if isinstance(x, str):
        return x
    if isinstance(x, (list, tuple)):
        return "[" + ", ".join(fmt(v) for v in x) + "]"
    x = float(x)
    if math.isnan(x):
        return "—"
    if x == 0:
        return "0"
    if 1e-3 <= abs(x) < 1e4:
        return f"{x:.4g}"
    return f"{x:.2e}"


def optional(default: Any = None) -> Any:
    """A field of a typed row that is left out of metrics.json while it is `None` (a figure
    measured for some rows only: the training loss of a learned map, the order of a classical one)."""
    return dataclasses.field(default=default, metadata={"optional": True})


def row_to_json(row: Any) -> dict[str, Any]:
    """A typed row (a dataclass) as a JSON object: every field, those declared `optional()` only
    when set."""
    return {
        f.name: _jsonable(getattr(row, f.name))
        for f in dataclasses.fields(row)
        if not (f.metadata.get("optional") and getattr(row, f.name) is None)
    }


def row_from_json(cls: type, values: dict[str, Any]) -> Any:
    """The typed row of class `cls` that `row_to_json` wrote as `values` (an infinite figure,
    stored as the string "inf", is a float again; a figure that may be `None` and that an
    older file does not record is `None`)."""
    def value(v: Any) -> Any:
        return float(v) if v in ("inf", "-inf") else v

    def absent(f: dataclasses.Field) -> bool:  # a figure an older file did not record, where None is allowed
        return f.name not in values and f.default is dataclasses.MISSING and "None" in str(f.type)

    return cls(**{f.name: value(values[f.name]) if f.name in values else None
                  for f in dataclasses.fields(cls) if f.name in values or absent(f)})


#: Rows `read_row` read, not computed, during the current `execute` (its metrics'
#: `resumed_rows`): saved by an earlier run, or by another process running the same study into
#: the same folder (`paper._claims`). `total_time_s` is this run's time: its own rows, and its
#: waits for the other process's.
_RESUMED: contextvars.ContextVar[list[Path] | None] = contextvars.ContextVar("resumed_rows", default=None)


def read_row(cls: type, path: Path, *, warn: bool = True) -> Any | None:
    """The row of type `cls` an earlier run saved at `path`, or `None` if there is none or the
    file is of another format (with a warning unless `warn` is False: it will be refitted)."""
    if not path.exists():
        return None
    try:
        row = row_from_json(cls, json.loads(path.read_text()))
    except (TypeError, UnicodeDecodeError, json.JSONDecodeError) as err:
        if warn:
            import sys

            print(f"warning: refitting {path}: not a row of this version ({err})", file=sys.stderr)
        return None
    if (resumed := _RESUMED.get()) is not None:
        resumed.append(path)
    return row


def saved_row(cls: type, path: Path, compute: Callable[[], Any]) -> Any:
    """The row of type `cls` an earlier run saved at `path` (an interrupted study resumes: each
    row is saved when it is done), else `compute()`, saved there first. A file of another
    format is refitted, with a warning."""
    if (row := read_row(cls, path)) is not None:
        return row
    row = compute()
    atomic_write_text(path, json.dumps(row_to_json(row), indent=2) + "\n")
    return row


@dataclasses.dataclass(frozen=True)
class Column:
    """A column of a table of typed rows: its `header` and the `cell` of a row (a number is
    written by `fmt`, a string as it is)."""

    header: str
    cell: Callable[[Any], Any]


def table_lines(columns: Sequence[Column], rows: Iterable[Any]) -> list[str]:
    """The Markdown table of `rows`, one line each, under the `columns`' headers."""
    lines = [markdown_row(c.header for c in columns), "|" + "---|" * len(columns)]
    lines += [markdown_row(fmt(c.cell(r)) for c in columns) for r in rows]
    return lines


def check_out_dir(out_dir: Path, name: str = "out_dir") -> None:
    """`ValueError` naming `out_dir` (as `name`) and why, if a run cannot write into it: it lies
    inside the committed reference results, it (or a folder above it) exists and is not a
    folder, or the nearest existing folder is not writable. Creates nothing."""
    resolved = Path(out_dir).resolve()
    if resolved == REFERENCE_DIR or REFERENCE_DIR in resolved.parents:
        raise ValueError(
            f"{name} {str(out_dir)!r} is inside {REFERENCE_DIR}, the committed reference results, "
            "which a run never overwrites; write elsewhere (python -m paper --out DIR)"
        )
    existing = resolved
    while not os.path.exists(existing) and existing != existing.parent:
        existing = existing.parent
    where = "" if existing == resolved else f"cannot be created: {str(existing)!r} "
    if not os.path.isdir(existing):
        raise ValueError(f"{name} {str(out_dir)!r} {where}exists and is not a folder; give a folder for the "
                         "results (python -m paper --out DIR)")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise ValueError(f"{name} {str(out_dir)!r} {where}is not writable (permission denied); give a folder you "
                         "can write to (python -m paper --out DIR)")


class AbstractExperiment(abc.ABC):
    """One experiment of the paper: `run(profile)` returns its metrics (ours and baseline)."""

    id: str
    title: str
    paper_values: tuple[PaperValue, ...]
    # Rows of the summary table: (metric key in metrics.json, label).
    table_rows: tuple[tuple[str, str], ...] = (
        ("train_loss", "training loss (MSE)"),
        ("val_loss", "validation loss (MSE)"),
        ("energy_rel_err_max", "max |rel. energy error|"),
        ("energy_rel_err_mean", "mean |rel. energy error|"),
        ("casimir_rel_drift_max", "max |rel. Casimir drift|"),
        ("traj_err_final", "trajectory error at the end"),
        ("poisson_defect_max", "max Poisson defect"),
        ("wall_time_s", "training wall time [s]"),
    )

    def check_settings(self, profile: str, out_dir: Path) -> None:
        """`ValueError` if `out_dir` holds results saved with other settings of `profile` than
        it has now (nothing saved to resume from: nothing to check; studies override this)."""

    @abc.abstractmethod
    def run(self, profile: str, out_dir: Path, progress: bool) -> dict[str, Any]:
        """Run at `profile` ("quick" or "full"), write figures into `out_dir`, return metrics."""

    def execute(self, profile: str = "quick", progress: bool = True, out_dir: Path | None = None):
        """Run, then write `metrics.json` and `table.md` (and the figures, data sets and models)
        into `out_dir` (default `./paper-results/<id>`); returns the metrics."""
        out_dir = Path(DEFAULT_OUT / self.id if out_dir is None else out_dir)
        check_out_dir(out_dir)
        try:
            out_dir.mkdir(parents=True, exist_ok=True)
        except OSError as err:  # made unwritable or a file since the check
            raise ValueError(f"out_dir {str(out_dir)!r}: cannot create the folder ({err.strerror})") from err
        t0 = time.perf_counter()
        resumed: list[Path] = []
        token = _RESUMED.set(resumed)
        try:
            metrics = self.run(profile, out_dir, progress)
        finally:
            _RESUMED.reset(token)
        metrics["experiment"] = self.id
        metrics["profile"] = profile
        metrics["total_time_s"] = time.perf_counter() - t0
        if resumed:  # the time of the rows computed now; the others' are in their own files
            metrics["resumed_rows"] = len(resumed)
        metrics = _jsonable(metrics)
        atomic_write_text(out_dir / "metrics.json", json.dumps(metrics, indent=2) + "\n")
        atomic_write_text(out_dir / "table.md", self.markdown_table(metrics))
        return metrics

    def paper_value(self, key: str) -> PaperValue | None:
        for pv in self.paper_values:
            if pv.metric == key:
                return pv
        return None

    def rows(self, metrics: dict[str, Any]) -> list[tuple[str, str, str, str]]:
        """(label, paper, ours, baseline); a dotted key `glpnet.x` reads a nested block."""

        base = metrics.get("baseline", {}) or {}
        out = []
        for key, label in self.table_rows:
            ours = metric_value(metrics, key)
            if ours is None:
                continue
            pv = self.paper_value(key)
            out.append((label, pv.text if pv else "—", fmt(ours), fmt(metric_value(base, key))))
        return out

    def label(self, key: str) -> str:
        """The table label of the metric `key` (the key itself if it has none)."""
        return dict(self.table_rows).get(key, key)

    def provenance(self, metrics: dict[str, Any]) -> str:
        """The profile and the command that produced `metrics`."""
        full = " --full" if metrics.get("profile") == "full" else ""
        return f"Profile `{metrics.get('profile')}`; produced by `python -m paper run {self.id}{full}`"

    def study_markdown(self, metrics: dict[str, Any], description: str, sections: list[tuple[str, list[str]]]) -> str:
        """A study's table: title, provenance and `description`, the verdict, then each
        `(heading, lines)` of `sections`."""
        lines = [f"# {self.id}: {self.title}", "", f"{self.provenance(metrics)}. {description}", "", "## Verdict", "",
                 *[f"- {v}" for v in metrics.get("verdict", [])]]
        for heading, body in sections:
            lines += ["", f"## {heading}", "", *body]
        return "\n".join(lines) + "\n"

    def markdown_table(self, metrics: dict[str, Any]) -> str:
        lines = [
            f"# {self.id}: {self.title}",
            "",
            self.provenance(metrics),
            "",
            f"| metric | paper | ours ({metrics.get('model', 'LPNet')}) | baseline ({metrics.get('baseline_model', 'MLP')}) |",
            "|---|---|---|---|",
        ]
        lines += [markdown_row(row) for row in self.rows(metrics)]
        notes = metrics.get("notes")
        if notes:
            lines += ["", *[f"- {n}" for n in notes]]
        return "\n".join(lines) + "\n"


#: The table of an experiment that trains LPNets over seeds (Adam, then L-BFGS-B) and a G-LPNet
#: on the same data: the common rows with the medians over seeds beside them.
SEEDED_LPNET_ROWS = AbstractExperiment.table_rows[:3] + (
    ("energy_rel_err_max_median", "max |rel. energy error|, median over seeds"),
) + AbstractExperiment.table_rows[3:] + ADAM_ROWS + (
    ("adam_only_energy_median", "before L-BFGS-B (Adam only): max |rel. energy error|, median over seeds"),
) + GLPNET_ROWS
