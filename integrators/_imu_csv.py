r"""Gyroscope records as phones and IMU loggers export them: a CSV file with a time column in
seconds and three angular-rate columns whose header names their units (phyphox writes
`"Time (s)","Gyroscope x (rad/s)",...`, others `wx,wy,wz` or `gyro_x [deg/s]`), one file
holding several flights cut by start/stop events or by time windows.
"""

from __future__ import annotations

import csv
import io
import math
import os
import re
from collections.abc import Sequence
from typing import Any

import numpy as np

from liepoisson import Rotations
from liepoisson.systems import AbstractLiePoissonSystem

from ._body_observations import BodyObservations, _check_system
from ._files import atomic_path

#: The units a rate column may carry, and the factor to rad/s.
RATE_UNITS = {"rad/s": 1.0, "deg/s": math.pi / 180.0}
#: Names of a time column, compared in lower case without the units: the first of these ranks
#: found wins (a column in `(s)`, then `seconds_elapsed`, then the plain names).
TIME_NAMES = ("t", "time", "seconds_elapsed", "elapsed_time", "timestamp")
#: Names of an event column, compared in lower case.
EVENT_NAMES = ("event", "events", "label", "marker")
_SECONDS = ("s", "sec", "seconds")
_RATE = re.compile(r"^(gyroscope|gyro|gyr|angularvelocity|angularrate|rotationrate|omega|w|)([xyz])$")
_UNIT = re.compile(r"^(.*?)\s*(?:\(([^()]*)\)|\[([^\[\]]*)\])$")
_DECIMAL_COMMA = re.compile(r"^\s*[+-]?\d*,\d+(?:[eE][+-]?\d+)?\s*$")


def _split_unit(column: str) -> tuple[str, str | None]:
    """`("Gyroscope x", "rad/s")` of `"Gyroscope x (rad/s)"`; `(column, None)` without units."""
    match = _UNIT.match(column.strip())
    if match is None:
        return column.strip(), None
    return match.group(1), (match.group(2) if match.group(2) is not None else match.group(3)).strip()


def _rate_unit(unit: str) -> str | None:
    """`"rad/s"` or `"deg/s"` for the spellings of these units, `None` for anything else."""
    u = unit.lower().replace(" ", "").replace("°", "deg").replace("⁻¹", "^-1")
    u = re.sub(r"[*.·]?s\^?-1$", "/s", u).replace("/sec", "/s").replace("degrees", "deg").replace("degree", "deg")
    u = {"dps": "deg/s", "rps": "rad/s"}.get(u, u)
    return u if u in RATE_UNITS else None


def _table(path: str) -> tuple[list[str], list[list[str]], list[int], str]:
    """`(header, rows, line numbers, delimiter)` of a CSV file in UTF-8 (a byte-order mark
    skipped), delimited by `,`, `;` or tabs (the one that splits the header most); blank lines
    skipped, no rows allowed."""
    with open(path, "rb") as f:
        data = f.read()
    if not data.lstrip(b"\xef\xbb\xbf").strip():
        raise ValueError(f"{path!r} is empty; expected a CSV file with a header and rows of gyroscope rates")
    if b"\x00" in data[:65536]:
        raise ValueError(f"{path!r} holds binary data (NUL bytes), not a CSV text file (a UTF-16 export: re-save it "
                         "as UTF-8)")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise ValueError(f"{path!r} is not UTF-8 text (byte {err.start}): not a CSV file, or re-save it as "
                         "UTF-8") from None
    first = next(line for line in text.splitlines() if line.strip())
    delimiter = max((",", ";", "\t"), key=lambda d: len(next(csv.reader([first], delimiter=d))))
    reader = csv.reader(io.StringIO(text, newline=""), delimiter=delimiter)
    header, rows, lines = None, [], []
    try:
        for row in reader:
            if not any(field.strip() for field in row):
                continue
            if header is None:
                header = [field.strip() for field in row]
                if len(header) < 2:
                    raise ValueError(f"{path!r} has the header {first.strip()[:80]!r}: one column; expected a time "
                                     "column and three rate columns separated by ',', ';' or tabs")
                continue
            if len(row) != len(header):
                hint = (" (a comma decimal separator? re-export with a dot as the decimal separator)"
                        if delimiter == "," and len(row) > len(header) else "")
                raise ValueError(f"{path!r}, line {reader.line_num}: {len(row)} fields; the header has "
                                 f"{len(header)}{hint}")
            rows.append(row)
            lines.append(reader.line_num)
    except csv.Error as err:
        raise ValueError(f"{path!r}, line {reader.line_num}: not CSV: {err}") from None
    if header is None:
        raise ValueError(f"{path!r} is empty (blank rows only); expected a header and rows of gyroscope rates")
    return header, rows, lines, delimiter


def _column(path: str, header: list[str], name: str, argument: str) -> int:
    """The index of the column `name` (compared without surrounding spaces; with or without its
    units, `"c"` finds `"c (deg/s)"`), named by `argument`."""
    found = ([i for i, h in enumerate(header) if h == name.strip()]
             or [i for i, h in enumerate(header) if _split_unit(h)[0] == name.strip()])
    if len(found) != 1:
        what = "has no column" if not found else "has more than one column"
        raise ValueError(f"{path!r} {what} {name!r} ({argument}); its columns are {header}")
    return found[0]


def _time_column(path: str, header: list[str], time: str | None) -> int:
    if time is not None:
        index = _column(path, header, time, "time=")
    else:
        found = {}
        for i, h in enumerate(header):
            base, unit = _split_unit(h)
            base = re.sub(r"[\s-]+", "_", base.lower())
            if base in TIME_NAMES and (unit is not None or base != "timestamp"):
                found.setdefault(0 if (unit or "").lower() in _SECONDS else 1 if base == "seconds_elapsed" else 2, []).append(i)
        if not found:
            raise ValueError(f"{path!r} has no time column (one of {list(TIME_NAMES)}, optionally with '(s)'); its "
                             f"columns are {header}: pass time= naming the column of times in seconds")
        best = found[min(found)]
        if len(best) > 1:
            raise ValueError(f"{path!r} has several time columns {[header[i] for i in best]}: pass time= naming "
                             "the one in seconds")
        index = best[0]
    unit = _split_unit(header[index])[1]
    if unit is not None and unit.lower() not in _SECONDS:
        raise ValueError(f"{path!r}: the time column {header[index]!r} is in {unit!r}; expected seconds (convert "
                         "the times, or pass time= naming a column in seconds)")
    return index


def _rate_columns(path: str, header: list[str], rates: Sequence[str] | None) -> list[int]:
    if rates is not None:
        if isinstance(rates, str) or len(rates) != 3:
            raise TypeError(f"rates must name three columns (x, y, z); got {rates!r}")
        return [_column(path, header, name, "rates=") for name in rates]
    sets: dict[str, dict[str, list[int]]] = {}
    for i, h in enumerate(header):
        match = _RATE.match(re.sub(r"[^a-z]", "", _split_unit(h)[0].lower()))
        if match:
            sets.setdefault(match.group(1), {}).setdefault(match.group(2), []).append(i)
    complete = [axes for axes in sets.values() if len(axes) == 3]
    if len(complete) != 1 or any(len(columns) > 1 for columns in complete[0].values()):
        what = "no" if not complete else "more than one set of"
        raise ValueError(f"{path!r} has {what} gyroscope rate columns (x, y, z: e.g. 'Gyroscope x (rad/s)', "
                         f"'gyro_x [deg/s]', 'wx'); its columns are {header}: pass rates=(x, y, z) naming them")
    return [complete[0][axis][0] for axis in "xyz"]


def _units(path: str, header: list[str], columns: list[int], units: str | None) -> str:
    if units is not None:
        if units not in RATE_UNITS:
            raise ValueError(f"units must be one of {list(RATE_UNITS)}; got {units!r}")
        return units
    found = {header[i]: _split_unit(header[i])[1] for i in columns}
    read = {_rate_unit(u) if u is not None else None for u in found.values()}
    if len(read) != 1 or None in read:
        raise ValueError(f"{path!r}: the units of the rate columns {list(found)} are missing, unknown or differ "
                         f"(read {list(found.values())}; known: {list(RATE_UNITS)}): pass units='rad/s' or "
                         "units='deg/s'")
    return read.pop()


def _numbers(path: str, header: list[str], rows: list[list[str]], lines: list[int], index: int) -> np.ndarray:
    """Column `index` as float64, or a `ValueError` naming the line and column of the first
    field that is not a finite number."""
    values = []
    for row, line in zip(rows, lines):
        field = row[index]
        try:
            value = float(field)
        except ValueError:
            where = f"{path!r}, line {line}, column {header[index]!r}"
            if _DECIMAL_COMMA.match(field):
                raise ValueError(f"{where}: {field!r} has a comma as decimal separator; re-export the file with a "
                                 "dot as the decimal separator (e.g. 0.123, not 0,123)") from None
            raise ValueError(f"{where}: {field!r} is not a number" if field.strip() else
                             f"{where} is empty; drop the row (missing values are not masked)") from None
        if not math.isfinite(value):
            raise ValueError(f"{path!r}, line {line}, column {header[index]!r} is {field.strip()!r}; values must be "
                             "finite (drop the row)")
        values.append(value)
    return np.array(values, dtype=np.float64)


def _event_segments(path: str, header: list[str], rows: list[list[str]], lines: list[int],
                    index: int) -> list[tuple[int, int]]:
    """The rows `(first, last)` of each segment from `start` to `stop` of the event column."""
    segments, start = [], None
    for k, (row, line) in enumerate(zip(rows, lines)):
        value = row[index].strip().lower()
        if value == "start" and start is None:
            start = k
        elif value == "stop" and start is not None:
            segments.append((start, k))
            start = None
        elif value:
            what = ("'start' again before a 'stop'" if value == "start" else "'stop' without a 'start'"
                    if value == "stop" else f"{row[index].strip()!r}; expected 'start', 'stop' or nothing")
            raise ValueError(f"{path!r}, line {line}, column {header[index]!r}: {what}")
    if start is not None:
        raise ValueError(f"{path!r}, line {lines[start]}, column {header[index]!r}: 'start' with no 'stop' after it")
    return segments


def _increasing(path: str, t: np.ndarray, lines: list[int], column: str) -> None:
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        k = int(bad[0]) + 1
        what = "repeats" if t[k] == t[k - 1] else "is before"
        raise ValueError(f"{path!r}, line {lines[k]}, column {column!r}: time {float(t[k])!r} {what} {float(t[k - 1])!r} on line "
                         f"{lines[k - 1]}; times must be strictly increasing (sort the rows, drop repeated ones)")


def read_gyro_csv(path: str | os.PathLike, system: AbstractLiePoissonSystem, *, time: str | None = None,
                  rates: Sequence[str] | None = None, units: str | None = None,
                  segments: Sequence[tuple[float, float]] | None = None,
                  events: str | None = None, group: str | int | None = None) -> BodyObservations:
    r"""Gyroscope rates $\Omega(t)$ from a CSV export of a phone or an IMU logger, as
    `BodyObservations` holding velocities only.

    **Arguments:**

    - `path`: a UTF-8 CSV file (a byte-order mark is skipped), delimited by `,`, `;` or tabs,
      with a header; a comma decimal separator is refused.
    - `system`: a body turning in `liepoisson.Rotations` (e.g. `liepoisson.systems.RigidBody`):
      its body velocity is the angular velocity, read in the body frame.
    - `time`: the column of times in seconds; by default the one named `t`, `time`,
      `seconds_elapsed`, `elapsed_time` or `time (s)` (a column marked `(s)` first).
    - `rates`: the three columns $(\Omega_x, \Omega_y, \Omega_z)$; by default those named
      `Gyroscope x`, `gyro_x`, `wx`, `omega_x`, `x`, ... (any case, spaces and underscores).
    - `units`: `"rad/s"` or `"deg/s"`; by default read from the rate columns' header,
      `name (unit)` or `name [unit]`. Rates in deg/s are multiplied by $\pi/180$.
    - `segments`: time windows `[(t0, t1), ...]`, each the trajectory of the rows with
      $t_0 \le t \le t_1$. Without it, the rows from each `start` to the next `stop` of the
      event column (default: the column named `event`, `events`, `label` or `marker`; or
      `events=` names it) are one trajectory each; without events, the whole file is one.

    - `group`: a label (e.g. the recording session) given to every trajectory of the file
      (`BodyObservations.groups`); `None`: none. Sessions read one file each are joined by
      `BodyObservations.concatenate`.

    Times must be strictly increasing within each trajectory (and across the file when cut
    by windows), every time and rate finite, each trajectory at least two rows. The metadata
    record the file's name, the units read and each trajectory's window `[t0, t1]` and lines.
    """
    system = _check_system(system)
    if not isinstance(system.group, Rotations):
        raise TypeError(f"system must be a rotating body (group liepoisson.Rotations, body velocity the angular "
                        f"velocity) for gyroscope rates; got {system!r} with group {system.group!r}")
    if group is not None and (isinstance(group, bool) or not isinstance(group, (str, int))):
        raise TypeError(f"group must be a label, a string or an integer (the recording session); got {group!r}")
    if segments is not None and events is not None:
        raise ValueError(f"give segments= (time windows) or events= (an event column), not both; got segments="
                         f"{segments!r} and events={events!r}")
    path = os.fspath(path)
    header, rows, lines, _ = _table(path)
    t_index = _time_column(path, header, time)
    r_index = _rate_columns(path, header, rates)
    unit = _units(path, header, r_index, units)
    if not rows:
        raise ValueError(f"{path!r} has a header and no rows")
    t = _numbers(path, header, rows, lines, t_index)
    rad = np.stack([_numbers(path, header, rows, lines, i) for i in r_index], axis=1) * RATE_UNITS[unit]
    if segments is not None:
        _increasing(path, t, lines, header[t_index])
        windows = [_window(w, j) for j, w in enumerate(_sequence(segments))]
        picks = [np.flatnonzero((t >= t0) & (t <= t1)) for t0, t1 in windows]
    else:
        if events is not None:
            e_index = _column(path, header, events, "events=")
        else:
            found = [i for i, h in enumerate(header) if h.lower() in EVENT_NAMES]
            if len(found) > 1:
                raise ValueError(f"{path!r} has several event columns {[header[i] for i in found]}: pass events= "
                                 "naming the one of start/stop events")
            e_index = found[0] if found else None
        cuts = _event_segments(path, header, rows, lines, e_index) if e_index is not None else []
        picks = [np.arange(a, b + 1) for a, b in cuts] or [np.arange(len(rows))]
        for rows_of in picks:
            _increasing(path, t[rows_of], [lines[k] for k in rows_of], header[t_index])
        windows = [(float(t[k[0]]), float(t[k[-1]])) for k in picks]
    for j, (k, (t0, t1)) in enumerate(zip(picks, windows)):
        if k.size < 2:
            raise ValueError(f"{path!r}: segment {j} (t from {t0!r} to {t1!r}) holds {k.size} row(s); a trajectory "
                             "needs at least two")
    metadata = {"source": "integrators.read_gyro_csv", "file": os.path.basename(path), "units": unit,
                "time": header[t_index], "rates": [header[i] for i in r_index],
                "segments": [[t0, t1] for t0, t1 in windows], "lines": [[lines[k[0]], lines[k[-1]]] for k in picks]}
    return BodyObservations(system, [t[k] for k in picks], velocities=[rad[k] for k in picks], metadata=metadata,
                            groups=None if group is None else [group] * len(picks))


def _sequence(segments: Any) -> list[Any]:
    if isinstance(segments, (str, bytes)) or not isinstance(segments, (Sequence, np.ndarray)) or len(segments) == 0:
        raise TypeError(f"segments must be a non-empty list of time windows [(t0, t1), ...]; got {segments!r}")
    return list(segments)


def _window(window: Any, j: int) -> tuple[float, float]:
    try:
        t0, t1 = (float(v) for v in window)
    except (TypeError, ValueError):
        raise TypeError(f"segments[{j}] must be a time window (t0, t1) of two numbers; got {window!r}") from None
    if not (math.isfinite(t0) and math.isfinite(t1) and t0 < t1):
        raise ValueError(f"segments[{j}] must be a window (t0, t1) with finite t0 < t1; got {window!r}")
    return t0, t1


def write_gyro_csv(path: str | os.PathLike, data: BodyObservations, *, units: str = "rad/s") -> None:
    """Write the velocities of `data` (a rotating body's angular velocities) as `read_gyro_csv`
    reads them, atomically: the header `time (s),gyro_x (<units>),gyro_y (<units>),gyro_z
    (<units>),event`, then one row per observation, the trajectories one after the other,
    the event `start` on each trajectory's first row and `stop` on its last. Numbers are
    written at `repr` precision, so reading the file back gives the same times and rad/s rates
    exactly (deg/s rates to a rounding of the conversion)."""
    if not isinstance(data, BodyObservations):
        raise TypeError(f"data must be integrators.BodyObservations; got {type(data).__name__}")
    if data.velocities is None or not isinstance(data.group, Rotations):
        raise ValueError(f"data must hold the angular velocities of a rotating body (group liepoisson.Rotations); "
                         f"got {data!r}")
    if units not in RATE_UNITS:
        raise ValueError(f"units must be one of {list(RATE_UNITS)}; got {units!r}")
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8", newline="") as f:
        writer = csv.writer(f, lineterminator="\n")
        writer.writerow(["time (s)", *(f"gyro_{axis} ({units})" for axis in "xyz"), "event"])
        for t, omega in zip(data.times, data.velocities):
            omega = omega if units == "rad/s" else omega / RATE_UNITS[units]
            for k in range(t.size):
                event = "start" if k == 0 else "stop" if k == t.size - 1 else ""
                writer.writerow([repr(float(t[k])), *(repr(float(w)) for w in omega[k]), event])
