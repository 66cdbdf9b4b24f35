"""`learn.sweep`: one `learn.fit` per point of a grid (seeds x widths x step sizes ...), in this
process or on the workers of a Dask cluster, each result saved as it finishes, a rerun skipping
the points already done."""

from __future__ import annotations

import dataclasses
import hashlib
import inspect
import itertools
import json
import math
import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from integrators import Trajectories
from integrators.internals import atomic_write_text, check_client, map_unordered
from liepoisson.internals import positive_int, progress_bar, show_progress

from .._models._base import AbstractLearnedMap, check_learned_map
from .._models._load import load
from .._solvers._adam import Adam
from .._solvers._checkpoint import Checkpoint
from .._solvers._record import TrainingRecord
from .._solvers._stage import AbstractStage
from ._fit import fit

#: The keys of a grid point that are passed on to `learn.fit` (as well as to `make_model`).
FIT_KEYS = ("seed", "epochs", "optimiser", "loss", "normalise", "validation_fraction")
_RESULT = "result.json"
_CHECKPOINT = "adam-checkpoint.h5"


def grid_points(grid: Mapping[str, Sequence[Any]] | Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """The points of `grid`: the Cartesian product of a `{name: values}` mapping (last name
    varying fastest), or a sequence of point dicts as given."""
    if isinstance(grid, Mapping):
        for name, values in grid.items():
            if not isinstance(name, str):
                raise TypeError(f"grid keys must be strings (the names of the swept settings); got {name!r}")
            if isinstance(values, (str, bytes)) or not isinstance(values, Sequence) or len(values) == 0:
                raise TypeError(f"grid[{name!r}] must be a non-empty list of values; got {values!r}")
        return [dict(zip(grid, values)) for values in itertools.product(*grid.values())]
    if isinstance(grid, Sequence) and not isinstance(grid, (str, bytes)) and grid and all(
        isinstance(p, Mapping) and all(isinstance(k, str) for k in p) for p in grid
    ):
        return [dict(p) for p in grid]
    raise TypeError(
        "grid must be a {name: [values, ...]} mapping (the Cartesian product is swept) or a non-empty list of "
        f"{{name: value}} dicts; got {grid!r}"
    )


def point_key(point: Mapping[str, Any]) -> str:
    """A stable name for a point (its folder): readable settings and a hash of all of them."""
    text = json.dumps(point, sort_keys=True, default=repr)
    digest = hashlib.sha1(text.encode()).hexdigest()[:10]
    readable = "-".join(
        f"{k}={v}" for k, v in sorted(point.items()) if isinstance(v, (int, float, str)) and len(str(v)) <= 12
    )
    safe = "".join(c if c.isalnum() or c in "=-_." else "_" for c in readable)[:80]
    return f"{safe}-{digest}" if safe else digest


@dataclasses.dataclass(frozen=True)
class SweepResult:
    """One trained point of a sweep: its settings, the `fit` seed used, the metrics (training
    and validation loss, wall time, and what `evaluate` returned) and the folder holding
    `model.h5` and `record.h5`."""

    point: dict[str, Any]
    seed: int
    metrics: dict[str, float]
    path: str
    model_class: str

    def model(self, system: Any = None) -> AbstractLearnedMap:
        """The trained map, read from `path` (`system` as in `LPNet.load`)."""
        return load(os.path.join(self.path, "model.h5"), system)

    def record(self) -> TrainingRecord:
        """The `TrainingRecord` of the fit."""
        return TrainingRecord.load(os.path.join(self.path, "record.h5"))


class Sweep(Sequence[SweepResult]):
    """The results of `learn.sweep`, in grid order; also `Sweep.load(out)` of a folder."""

    def __init__(self, out: str | os.PathLike, results: Sequence[SweepResult]):
        self.out = os.fspath(out)
        self.results = tuple(results)

    def __len__(self) -> int:
        return len(self.results)

    def __getitem__(self, i):  # type: ignore[override]
        return self.results[i]

    def __repr__(self) -> str:
        return f"Sweep({self.out!r}, {len(self)} points)"

    def best(self, metric: str = "val_loss") -> SweepResult:
        """The point with the smallest finite `metric`."""
        finite = [r for r in self.results if math.isfinite(r.metrics.get(metric, math.nan))]
        if not finite:
            raise ValueError(f"no point of the sweep has a finite {metric!r}; metrics are {sorted(self[0].metrics)}")
        return min(finite, key=lambda r: r.metrics[metric])

    def table(self, metrics: Sequence[str] | None = None) -> str:
        """A markdown table: one row per point, its settings and `metrics` (default all)."""
        names = sorted({k for r in self.results for k in r.point} - {"seed"})  # the fit's seed has its column
        metrics = list(metrics) if metrics is not None else sorted({k for r in self.results for k in r.metrics})
        lines = ["| " + " | ".join([*names, "seed", *metrics]) + " |", "|" + "---|" * (len(names) + 1 + len(metrics))]
        for r in self.results:
            cells = [str(r.point.get(n, "")) for n in names] + [str(r.seed)]
            cells += [f"{r.metrics[m]:.4g}" if m in r.metrics else "" for m in metrics]
            lines.append("| " + " | ".join(cells) + " |")
        return "\n".join(lines)

    @classmethod
    def load(cls, out: str | os.PathLike) -> Sweep:
        """The finished points saved in the folder `out` by `learn.sweep` (grid order)."""
        out = Path(out)
        try:
            keys = json.loads((out / "sweep.json").read_text())["points"]
        except FileNotFoundError as err:
            raise FileNotFoundError(f"{os.fspath(out)!r} holds no sweep (no sweep.json): {err}") from err
        except (ValueError, KeyError, TypeError) as err:
            raise ValueError(f"{os.fspath(out / 'sweep.json')!r} is not a sweep index: {err}") from err
        return cls(out, [r for r in (_read_result(out / "points" / k) for k in keys) if r is not None])


def _index(out: Path) -> list[str]:
    """The point keys listed in `out/sweep.json` (none if it is missing or unreadable)."""
    try:
        keys = json.loads((out / "sweep.json").read_text())["points"]
    except (OSError, ValueError, KeyError, TypeError):
        return []
    return [k for k in keys if isinstance(k, str)] if isinstance(keys, list) else []


def _read_result(folder: Path) -> SweepResult | None:
    try:
        data = json.loads((folder / _RESULT).read_text())
        return SweepResult(data["point"], data["seed"], data["metrics"], os.fspath(folder), data["model_class"])
    except FileNotFoundError:
        return None
    except (ValueError, KeyError, TypeError):  # damaged (a crash cannot cause this: written atomically)
        return None


def _train(make_model, data, fit_kwargs, evaluate, point, checkpoint=None):
    """On a worker: build, fit and evaluate one point. Returns `(model, record, metrics)`.
    `checkpoint`: the `Checkpoint` of the point's Adam stage, or None."""
    model = check_learned_map(make_model(point), f"make_model({point!r}) must return")
    pairs = data(point) if callable(data) else data
    kwargs = {**fit_kwargs, **{k: point[k] for k in FIT_KEYS if k in point}, "progress": False}
    if checkpoint is not None:
        kwargs["checkpoint"] = checkpoint
    model, record = fit(model, pairs, **kwargs)
    metrics = {"train_loss": record.train_loss, "val_loss": record.val_loss, "wall_time_s": record.wall_time_s}
    if evaluate is not None:
        extra = evaluate(model, point)
        if not isinstance(extra, Mapping):
            raise TypeError(f"evaluate(model, point) must return a dict of numbers; got {extra!r}")
        metrics.update({str(k): float(v) for k, v in extra.items()})
    return model, record, metrics


def sweep(
    make_model: Callable[[dict[str, Any]], AbstractLearnedMap],
    grid: Mapping[str, Sequence[Any]] | Sequence[Mapping[str, Any]],
    data: Trajectories | tuple[Any, Any] | Callable[[dict[str, Any]], Any],
    *,
    out: str | os.PathLike,
    client: Any = None,
    evaluate: Callable[[AbstractLearnedMap, dict[str, Any]], Mapping[str, float]] | None = None,
    progress: bool | None = None,
    checkpoint_every: int | None = None,
    **fit_kwargs: Any,
) -> Sweep:
    r"""Train one model per point of `grid` with `learn.fit`, here or on a Dask cluster.

    **Arguments:**

    - `make_model(point) -> model`: the untrained map of a point (a dict of the grid's
      settings), e.g. `lambda p: learn.LPNet(system, hidden=(p["width"],) * 3, key=p["seed"])`.
    - `grid`: `{name: [values]}` (the Cartesian product) or a list of point dicts. The keys
      `seed`, `epochs`, `optimiser`, `loss`, `normalise`, `validation_fraction` are also
      passed to `learn.fit` (`seed` defaults to `fit`'s 0 and is recorded per point).
    - `data`: a `Trajectories` or `(y0, y1)` pairs for every point, or `data(point)`.
    - `out`: the folder of results: `out/points/<key>/` holds `model.h5`, `record.h5` and
      `result.json` (written last, so a point is done exactly when it exists) for each point
      as soon as it finishes; `out/sweep.json` lists the points of every grid run in `out`.
      A rerun skips done points.
    - `client`: a `dask.distributed.Client` (extra `dask`): the points are trained on its
      workers (`make_model`, `data`, `evaluate` are sent with cloudpickle; shared data once
      per worker). Without one, in this process one after the other. The numbers are the
      same either way.
    - `evaluate(model, point) -> {name: number}`: extra metrics, computed where it trained.
    - `progress`: a bar over the points (`None`: on a terminal).
    - `checkpoint_every`: for long points, write each point's Adam state to
      `out/points/<key>/adam-checkpoint.h5` every so many epochs and resume from it when the
      sweep is rerun (a `learn.Checkpoint(..., resume=True)`; bit-identical to an
      uninterrupted point; removed when the point is done). Points whose optimiser has no
      single Adam stage (or `epochs=`) train without one. With a `client`, `out` must be on a file system the
      workers share.
    - `fit_kwargs`: the arguments of `learn.fit` common to all points (e.g. `optimiser=`,
      `h=`); a point's own setting of the same name wins.

    **Returns** a `Sweep` of this grid's `SweepResult`s in grid order (`.table()`,
    `.best(metric)`, `.model()`, `.record()`); `learn.Sweep.load(out)` reads back every
    finished point in `out`, of this grid and earlier ones.
    """
    points = grid_points(grid)
    if not callable(make_model):
        raise TypeError(f"make_model must be a function point -> model; got {make_model!r}")
    if evaluate is not None and not callable(evaluate):
        raise TypeError(f"evaluate must be a function (model, point) -> dict; got {evaluate!r}")
    if not (callable(data) or isinstance(data, (Trajectories, tuple))):
        raise TypeError(f"data must be Trajectories, (y0, y1) pairs, or a function point -> data; got {data!r}")
    allowed = set(inspect.signature(fit).parameters) - {"model", "data", "progress", "callback"}
    unknown = sorted(set(fit_kwargs) - allowed)
    if unknown:
        raise TypeError(f"unknown keyword argument(s) {unknown} of learn.sweep; learn.fit takes {sorted(allowed)}")
    if "checkpoint" in fit_kwargs:
        raise ValueError("checkpoint= is per training; give learn.sweep checkpoint_every=N instead (each point "
                         "then has its own checkpoint file in its folder)")
    if checkpoint_every is not None:
        positive_int(checkpoint_every, "checkpoint_every")
    show_progress(progress)
    client = check_client(client)
    if not isinstance(out, (str, os.PathLike)):
        raise TypeError(f"out must be a folder name (str or os.PathLike); got {type(out).__name__}")
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(f"out={os.fspath(out)!r} is a file; give a folder for the sweep's results")
    keys = [point_key(p) for p in points]
    if len(set(keys)) != len(keys):
        raise ValueError("grid has repeated points; every point must differ in some setting")
    (out / "points").mkdir(parents=True, exist_ok=True)
    # The index keeps the points of earlier grids in this folder (a rerun on a smaller or
    # different grid must not hide them from `Sweep.load`), then this grid's new ones.
    atomic_write_text(out / "sweep.json", json.dumps({"points": list(dict.fromkeys([*_index(out), *keys]))}, indent=1))

    results: dict[str, SweepResult] = {}
    todo = []
    for key, point in zip(keys, points):
        done = _read_result(out / "points" / key)
        if done is not None:
            results[key] = done
        else:
            todo.append((key, (point, _checkpoint(out / "points" / key, point, fit_kwargs, checkpoint_every))))
    shared = (make_model, data, fit_kwargs, evaluate)
    by_key = dict(zip(keys, points))
    with progress_bar(len(points), "sweep", "fit", progress, initial=len(results)) as bar:
        for key, (model, record, metrics) in map_unordered(_train, iter(todo), client=client, shared=shared):
            results[key] = _save(out / "points" / key, by_key[key], model, record, metrics)
            (out / "points" / key / _CHECKPOINT).unlink(missing_ok=True)
            bar.update(1)
    return Sweep(out, [results[k] for k in keys])


def _checkpoint(folder: Path, point, fit_kwargs, every: int | None) -> Checkpoint | None:
    """The point's resumable Adam checkpoint (in its folder), if `every` is set and its
    optimiser has exactly one Adam stage."""
    if every is None:
        return None
    stages = point.get("optimiser", fit_kwargs.get("optimiser"))
    if stages is None and point.get("epochs", fit_kwargs.get("epochs")) is not None:
        stages = Adam(1)
    stages = (stages,) if isinstance(stages, AbstractStage) else tuple(stages or ())
    if sum(isinstance(s, Adam) for s in stages) != 1:
        return None
    folder.mkdir(parents=True, exist_ok=True)
    return Checkpoint(folder / _CHECKPOINT, every=every, resume=True)


def _save(folder: Path, point, model, record, metrics) -> SweepResult:
    folder.mkdir(parents=True, exist_ok=True)
    model.save(folder / "model.h5")
    record.save(folder / "record.h5")
    result = {"point": point, "seed": record.seed, "metrics": metrics, "model_class": type(model).__name__}
    atomic_write_text(folder / _RESULT, json.dumps(result, indent=1, default=repr))
    return _read_result(folder)

