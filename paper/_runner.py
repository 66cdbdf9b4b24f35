"""One runner for the studies beyond the paper (W1-W7).

A study declares its grid (`conditions`: what it varies, each condition carrying what its rows
need: system, data, test set), its `models` (instances of `paper._study.AbstractStudyModel`,
learned and peer alike), how one model is measured on one condition (`evaluate`, returning the
study's typed row) and its table's `columns`; the runner owns the rest: the rows in order, each
saved as it is measured and read back by a rerun into the same folder (an interrupted run
resumes; atomic writes; a rerun with other settings of the profile is refused, not mixed with
them: `check_settings`), the progress lines, the verdict, the figures and the tables. A new row
of a study is one model in its `models`; a new study is one subclass.

Processes that run the same study into the same folder share its rows (`paper._claims`): each
computes the rows no other holds, then reads the others' as they are saved. So a long study
uses every core when started once per core: `python -m paper run W8 --full --out DIR &` twice.
"""

from __future__ import annotations

import abc
import dataclasses
import json
import time
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

from integrators.internals import atomic_write_text, json_values

from ._claims import claim, holder, release
from ._experiment import (
    AbstractExperiment,
    Column,
    Profile,
    read_row,
    row_from_json,
    row_to_json,
    saved_row,
    table_lines,
)
from ._mappings import release_compiled_programs
from ._study import AbstractStudyModel

#: Seconds between two looks at a row another process is computing (`AbstractStudy.run`).
POLL_SECONDS = 30.0


@dataclasses.dataclass(frozen=True)
class _Elsewhere:
    """A row another process claimed (`paper._claims`): read once it is saved at `path`, or
    computed here by `compute` if that process ends without saving it."""

    path: Path
    compute: Callable[[], Any]


class AbstractStudy(AbstractExperiment):
    """A study: rows of `row_type` (a frozen dataclass, written by `row_to_json`), one per
    model and condition. Subclasses set `id`, `title`, `profiles`, `row_type`, `columns` and
    implement `conditions`, `models`, `evaluate`, `description`; the rest has defaults."""

    paper_values = ()
    #: The study's budgets by profile name (smoke, quick, full).
    profiles: dict[str, Profile]
    row_type: type
    #: The columns of the table of every row (`sections`' default).
    columns: tuple[Column, ...] = ()

    @abc.abstractmethod
    def conditions(self, P: Profile) -> Iterable[Any]:
        """The grid at profile `P`, in the order of the rows."""

    @abc.abstractmethod
    def models(self, P: Profile, condition: Any) -> Sequence[AbstractStudyModel]:
        """The models fitted on `condition`, in the order of its rows."""

    @abc.abstractmethod
    def evaluate(self, condition: Any, model: AbstractStudyModel, progress: bool) -> Any:
        """The row of `model` fitted and measured on `condition`."""

    @abc.abstractmethod
    def description(self, metrics: dict[str, Any]) -> str:
        """The protocol in a paragraph, above the table."""

    def admits(self, condition: Any, model: AbstractStudyModel) -> bool:
        """Whether `model` has a row on `condition` (`model.accepts` the condition's `data`, if it
        has some)."""
        data = getattr(condition, "data", None)
        return data is None or model.accepts(data)

    def row_name(self, profile: str, condition: Any, model: AbstractStudyModel) -> str | None:
        """The file of the row under `<out>/<id>/rows/` (`None`: the row is not saved, the study
        does not resume)."""
        return None

    def condition_rows(self, profile: str, condition: Any, models: Sequence[AbstractStudyModel], out_dir: Path,
                       progress: bool) -> list[Any]:
        """The rows of `models` on `condition`, each read from its file if an earlier run saved
        it (`row_name`), else evaluated (and saved), or, while another process holds its claim,
        an `_Elsewhere` that `run` reads when that process has saved it. A study whose models
        are measured together (W1: timings relative to one of them) overrides this."""
        rows: list[Any] = []
        for model in models:
            name = self.row_name(profile, condition, model)
            if name is None:
                rows.append(self.evaluate(condition, model, progress))
            else:
                row = self._saved_or_claimed(out_dir / "rows" / name,
                                             lambda model=model: self.evaluate(condition, model, progress))
                rows.append(row)
                if isinstance(row, _Elsewhere):
                    if progress:
                        who = holder(row.path) or "released since"
                        print(f"  {name}: computed by another process ({who}); read when saved", flush=True)
                    continue
            if progress:
                print(self.line(rows[-1]), flush=True)
            release_compiled_programs()  # a long study compiles thousands of programs: paper._mappings
        return rows

    def _saved_or_claimed(self, path: Path, compute: Callable[[], Any]) -> Any:
        """The row saved at `path`, else computed here and saved if this process can claim it,
        else an `_Elsewhere`."""
        if (row := read_row(self.row_type, path, warn=False)) is not None:
            return row
        if not claim(path):  # a missing row, or one of another format, is refitted by one process
            return _Elsewhere(path, compute)
        try:
            return saved_row(self.row_type, path, compute)  # looks again: saved meanwhile, it is read
        finally:
            release(path)

    def _awaited(self, row: _Elsewhere, progress: bool) -> Any:
        """The row another process claimed: read when saved, computed here if it never is."""
        while True:
            found = self._saved_or_claimed(row.path, row.compute)
            if not isinstance(found, _Elsewhere):
                if progress:
                    print(self.line(found), flush=True)
                return found
            time.sleep(POLL_SECONDS)

    def announce(self, condition: Any) -> str | None:
        """A line printed (with progress) before the condition's rows (`None`: nothing)."""
        return None

    def line(self, row: Any) -> str:
        """A row in words (progress)."""
        return ", ".join(f"{k}={v}" for k, v in row_to_json(row).items())

    def verdict(self, rows: list[Any], conditions: list[Any]) -> list[str]:
        """Plain statements computed from the rows."""
        return []

    def figures(self, rows: list[Any], conditions: list[Any], out_dir: Path) -> list[str]:
        """The figures drawn into `out_dir`, by file name."""
        return []

    def summary(self, P: Profile, rows: list[Any], conditions: list[Any]) -> dict[str, Any]:
        """What metrics.json records besides the rows, the verdict and the figures."""
        return {}

    def check_settings(self, profile: str, out_dir: Path) -> None:
        """`ValueError` if `out_dir` holds what a run of `profile` saved with other settings than
        the profile has now (`<out_dir>/<profile>-settings.json`, written by `run`): its rows and
        data would be read back beside new ones as if they were alike."""
        path = Path(out_dir) / f"{profile}-settings.json"
        if not path.exists():
            return
        try:
            saved = json.loads(path.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
            raise ValueError(f"{path}: not a settings file of this library ({err}); delete {out_dir} to recompute "
                             "its rows, or run into another folder (--out)") from None
        now = _settings(self.profiles[profile])
        if saved != now:
            changed = sorted(k for k in {*saved, *now} if saved.get(k) != now.get(k))
            what = "; ".join(f"{k}: {saved.get(k)!r} then, {now.get(k)!r} now" for k in changed)
            raise ValueError(f"{out_dir} holds the {profile} profile's rows of other settings ({what}): run into "
                             f"another folder (--out), or delete {out_dir} to recompute them")

    def run(self, profile: str, out_dir: Path, progress: bool) -> dict[str, Any]:
        P = self.profiles[profile]
        self.check_settings(profile, out_dir)
        settings = Path(out_dir) / f"{profile}-settings.json"
        if not settings.exists():
            atomic_write_text(settings, json.dumps(_settings(P), indent=2) + "\n")
        rows: list[Any] = []
        seen: list[Any] = []
        for condition in self.conditions(P):
            seen.append(condition)
            if progress and (text := self.announce(condition)) is not None:
                print(text, flush=True)
            models = [m for m in self.models(P, condition) if self.admits(condition, m)]
            rows += self.condition_rows(profile, condition, models, out_dir, progress)
            release_compiled_programs()
        rows = [self._awaited(r, progress) if isinstance(r, _Elsewhere) else r for r in rows]
        figures = self.figures(rows, seen, out_dir)
        return {"rows": [row_to_json(r) for r in rows], "verdict": self.verdict(rows, seen),
                **({"figures": figures} if figures else {}), **self.summary(P, rows, seen)}

    def saved_rows(self, metrics: dict[str, Any]) -> list[Any]:
        """The typed rows of `metrics` (a run's metrics.json)."""
        return [row_from_json(self.row_type, r) for r in metrics.get("rows", [])]

    def summary_rows(self, rows: list[Any]) -> list[tuple[str, str, str, str]]:
        """The study's lines of `python -m paper table --long`: (label, paper, ours, baseline)."""
        return []

    def rows(self, metrics):
        return self.summary_rows(self.saved_rows(metrics))

    def sections(self, metrics: dict[str, Any], rows: list[Any]) -> list[tuple[str, list[str]]]:
        """The table's sections below the verdict: `(heading, lines)`."""
        return [("Every fit", table_lines(self.columns, rows))]

    def markdown_table(self, metrics):
        return self.study_markdown(metrics, self.description(metrics), self.sections(metrics, self.saved_rows(metrics)))


#: The first columns of a study whose grid is system x sampling x noise (W2, W4), and the model.
GRID_COLUMNS = (
    Column("system", lambda r: r.system),
    Column("sampling", lambda r: r.sampling),
    Column("noise", lambda r: f"{r.noise:g}"),
    Column("model", lambda r: r.model),
)


def peer(rows: Iterable[Any], row: Any, model: str) -> Any | None:
    """The row of `model` on `row`'s condition (its `condition` property), or `None`."""
    return next((r for r in rows if r.condition == row.condition and r.model == model), None)


def _settings(P: Profile) -> dict[str, Any]:
    """`P`'s settings as a settings file holds them (JSON values; anything else by its repr)."""
    return json.loads(json.dumps(json_values(P.as_dict()), default=repr))
