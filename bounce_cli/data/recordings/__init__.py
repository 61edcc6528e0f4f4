"""Reading lab recordings (racket and ball positions per trial) and event logs into SI arrays.

* CSV: one row per sample, columns named in the config's ``columns`` mapping (trial, time,
  racket, ball), units in ``units`` (length m | cm | mm, time s | ms). Several trials in one
  file; a file without a trial column is one trial (``columns.trial: null``); without ball
  data set ``columns.ball: null`` (then events must give the impacts). Empty cells are gaps.
  ``columns.racket`` may name several columns: the racket's height is their mean.
* Marker files, by ``format`` (``auto``: C3D by the ``.c3d`` suffix, the text exports by their
  first line): C3D (``c3d_files``; the ``c3d`` package's parts, ``pip install '.[c3d]'``),
  Vicon Nexus CSV, Qualisys QTM TSV, OptiTrack Motive CSV (``text_exports``). The racket and
  ball markers by their labels, the vertical axis by name (``markers`` block, ``markers.py``);
  the length unit from the file (or ``markers.units``); one file is one trial (named after the
  file); invalid points are gaps.
* Events CSV (``--events``): one row per impact (trial, time, optional alpha), as a virtual
  set-up logs them, columns in ``event_columns``, time in ``units.time``.

Every problem is one line naming the file and the column or trial (``ConfigError``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pandas as pd

from ...runtime.config import ConfigError
from .c3d_files import read_c3d_markers
from .markers import MarkerSet, marker_heights
from .text_exports import (
    DEFAULT_VERTICAL,
    check_recording_file,
    check_text,
    comment_lines,
    uncommented,
    detect_format,
    read_motive_csv,
    read_qtm_tsv,
    read_vicon_csv,
)

LENGTH_UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}
TIME_UNITS = {"s": 1.0, "ms": 0.001}
#: a trial needs at least this many samples (a few racket cycles at any sensible rate)
MIN_SAMPLES = 50


@dataclass(frozen=True)
class Trial:
    """One trial's samples in SI units; ``ball`` is None without ball data."""

    label: object
    t: np.ndarray
    racket: np.ndarray
    ball: np.ndarray | None


@dataclass(frozen=True)
class Events:
    """One trial's logged impacts: times (s) and, if logged, alpha."""

    t: np.ndarray
    alpha: np.ndarray | None


def read_table(path: Path, csv_format: Any = None) -> pd.DataFrame:
    """A CSV file as a DataFrame; a missing or unreadable file is a one-line ConfigError.
    ``csv_format`` (the config's ``csv`` block): separator (blank: runs of whitespace),
    decimal mark, rows to skip after the header; ``attrs["first_row"]`` is the file's line
    number of the first data row (for messages)."""
    separator = "," if csv_format is None else csv_format.separator
    decimal = "." if csv_format is None else csv_format.decimal
    skip = 0 if csv_format is None else csv_format.skip_rows
    check_recording_file(path)
    try:
        with open(path, "rb") as handle:
            head = handle.read(65536)
        check_text(path, head)
        notes = comment_lines(head)  # an export's "# ..." lines before the header
        skipped = [*range(notes), *range(notes + 1, notes + 1 + skip)]
        frame = pd.read_csv(path, sep=r"\s+" if not separator.strip() else separator,
                            decimal=decimal, skiprows=skipped or None,
                            engine="c" if len(separator) == 1 else "python")
        frame.columns = uncommented(frame.columns)  # a header written as "#trial,t_s,..."
        frame.attrs["first_row"] = 2 + notes + skip
        return frame
    except FileNotFoundError:
        raise ConfigError(f"{path}: file not found") from None
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: cannot read as CSV: not UTF-8 text (byte "
                          f"{exc.object[exc.start]:#04x} at offset {exc.start}): a binary "
                          "file, or save it as UTF-8") from None
    except (pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else "empty file"
        raise ConfigError(f"{path}: cannot read as CSV: {first}") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror}") from None


#: a number written with a decimal comma (a spreadsheet's export in many locales)
_DECIMAL_COMMA = re.compile(r"[-+]?\d+,\d+(?:[eE][-+]?\d+)?")


def _column(frame: pd.DataFrame, path: Path, name: str, key: str) -> np.ndarray:
    if name not in frame.columns:
        have = ", ".join(map(str, frame.columns[:12]))
        other = next((sep for sep in (";", "\t", "|", " ") if any(
            sep in str(c) and name in str(c).split(sep) for c in frame.columns)), None)
        hint = ("; another separator? set csv.separator" if other is not None
                else f"; set {key}")
        raise ConfigError(f"{path}: no column {name!r} (the file has: {have}{hint})")
    values = pd.to_numeric(frame[name], errors="coerce")
    bad = values.isna() & frame[name].notna()
    if bad.any():
        row = int(np.flatnonzero(bad.to_numpy())[0])
        cell = str(frame[name].iloc[row]).strip()
        if _DECIMAL_COMMA.fullmatch(cell):
            hint = " (a decimal comma? set csv.decimal=comma)"
        elif row == 0:
            hint = " (a row of units? set csv.skip_rows)"
        else:
            hint = ""
        raise ConfigError(f"{path}: column {name!r}, row {row + frame.attrs.get('first_row', 2)}"
                          f": not a number ({frame[name].iloc[row]!r}){hint}")
    return values.to_numpy(float)


def _groups(frame: pd.DataFrame, path: Path, trial_column: str | None, key: str):
    """(label, row indices) per trial, in order of first appearance."""
    if trial_column is None:
        return [(1, np.arange(len(frame)))]
    if trial_column not in frame.columns:
        have = ", ".join(map(str, frame.columns[:12]))
        raise ConfigError(f"{path}: no column {trial_column!r} (set {key}, or null for a "
                          f"single trial; the file has: {have})")
    labels = frame[trial_column]
    if labels.isna().any():
        row = int(np.flatnonzero(labels.isna().to_numpy())[0])
        raise ConfigError(f"{path}: column {trial_column!r}, row {row + 2}: empty trial label")
    return [(label, np.flatnonzero((labels == label).to_numpy()))
            for label in pd.unique(labels)]


def check_trial(path: Path, label, t: np.ndarray, time_column: str) -> None:
    """Time must increase strictly and a trial needs ``MIN_SAMPLES`` samples."""
    if len(t) < MIN_SAMPLES:
        raise ConfigError(f"{path}: trial {label}: only {len(t)} samples (at least "
                          f"{MIN_SAMPLES} needed)")
    if not np.all(np.isfinite(t)):
        raise ConfigError(f"{path}: trial {label}: column {time_column!r} has empty cells")
    step = np.diff(t)
    if np.any(step <= 0.0):
        i = int(np.flatnonzero(step <= 0.0)[0])
        verb = "runs backwards" if step[i] < 0.0 else "repeats a time"
        raise ConfigError(f"{path}: trial {label}: column {time_column!r} {verb} at sample "
                          f"{i + 2} ({t[i]:g} -> {t[i + 1]:g})")


#: consecutive samples of a height column with one exact value (0, -9999, ...) that read as a
#: dropout written as that value
ZERO_RUN_SAMPLES = 3
#: a run of one value is a dropout where the height beside it is this many of the column's
#: typical sample-to-sample steps from it: a jump (a marker lost); a racket resting (at 0: a
#: mouse not yet moved in the virtual set-up) leaves and enters its rest in steps of the usual
#: size
ZERO_RUN_JUMP_STEPS = 5.0


def _dropout_runs(values: np.ndarray) -> np.ndarray:
    """Start indices of the runs of ``ZERO_RUN_SAMPLES`` samples or more of one exact value
    that the column jumps into and out of (``ZERO_RUN_JUMP_STEPS``; at the column's ends, into
    or out of), or of zeros with no height beside them at all."""
    if values.size < ZERO_RUN_SAMPLES:
        return np.zeros(0, dtype=int)
    same = np.concatenate(([False], values[1:] == values[:-1], [False]))  # NaN: never
    edges = np.flatnonzero(np.diff(same.astype(np.int8)))
    # a run of samples a..b (each equal to the one before from a + 1 on) rises at a, falls at b
    starts, ends = edges[::2], edges[1::2] + 1  # ends: one past the run
    long = ends - starts >= ZERO_RUN_SAMPLES
    starts, ends = starts[long], ends[long]
    if not starts.size:
        return starts
    steps = np.abs(np.diff(values))
    steps = steps[np.isfinite(steps) & (steps > 0.0)]
    typical = float(np.median(steps)) if steps.size else 0.0
    padded = np.concatenate(([np.nan], values, [np.nan]))
    level = values[starts]
    beside = np.abs(np.stack([padded[starts], padded[ends + 1]]) - level)  # before, after
    # a dropout jumps away and back: a jump on every side that has a height (a plateau of a
    # held signal beside a dropout jumps on one side only, towards the dropout)
    known = np.isfinite(beside)
    jump = np.all(~known | (beside > ZERO_RUN_JUMP_STEPS * typical), axis=0) & known.any(axis=0)
    alone = ~known.any(axis=0) & (level == 0.0)  # a column of zeros
    return starts[jump | alone]


def _heights(frame: pd.DataFrame, path: Path, name: str, key: str, missing: list[float],
             time_name: str, warn: Callable[[str], None]) -> np.ndarray:
    """A height column as written, the values of ``missing`` (``csv.missing_heights``) as
    gaps; runs of ``ZERO_RUN_SAMPLES`` samples or more of one value (0, -9999, ...) that the
    column jumps into and out of (:func:`_dropout_runs`) are read as heights and warned of (a
    system that writes a dropout as such a value makes phantom contacts of it, and k counts
    them: a ball or racket at that height)."""
    values = _column(frame, path, name, key)
    if missing:
        values = np.where(np.isin(values, missing), np.nan, values)
    runs = _dropout_runs(values)
    if runs.size:
        value = float(values[runs[0]])
        same = runs[values[runs] == value]
        written = f"{value:g}"
        where = (f"{path}: column {name!r} is exactly {written} in {same.size} run(s) of "
                 f"{ZERO_RUN_SAMPLES} samples or more (the first at {time_name} = "
                 f"{frame[time_name].iloc[runs[0]]})")
        if _far_outside(values, value):  # a code: no ball or racket was ever there
            values = np.where(values == value, np.nan, values)
            warn(f"{where}, far outside the column's other heights: a marker dropout "
                 f"written as {written}, read as gaps (--set "
                 f"'csv.missing_heights=[{written}]' says so and silences this)")
        else:
            warn(f"{where}: a marker dropout written as {written}? They are read as "
                 f"heights; --set 'csv.missing_heights=[{written}]' reads them as gaps")
    return values


def _far_outside(values: np.ndarray, value: float) -> bool:
    """``value`` lies beyond the column's other (finite) values by more than their whole
    range: -9999 beside heights of 0-2000 mm; not 0 beside heights of 0.1-2 m (a dropout
    written as 0 may be a height: warned of, read as one)."""
    rest = values[np.isfinite(values) & (values != value)]
    if rest.size < 2:
        return False
    low, high = float(rest.min()), float(rest.max())
    span = high - low
    return span > 0.0 and (value < low - span or value > high + span)


def read_csv_recording(path: Path, columns, units, csv_format=None,
                       warn: Callable[[str], None] = lambda message: None) -> list[Trial]:
    """Trials of a CSV recording (``columns``: trial, time, racket (one name or several:
    their mean, a gap where one is missing), ball names; ``units``: length and time units;
    ``csv_format``: see ``read_table``, and its ``missing_heights``: the values of a height
    column that are gaps; ``warn`` hears of runs of exact zeros, :func:`_heights`)."""
    frame = read_table(path, csv_format)
    length, time = LENGTH_UNITS[units.length], TIME_UNITS[units.time]
    t_all = _column(frame, path, columns.time, "columns.time") * time
    missing = list(getattr(csv_format, "missing_heights", None) or [])
    racket_names = [columns.racket] if isinstance(columns.racket, str) else columns.racket
    racket_all = np.mean([_heights(frame, path, name, "columns.racket", missing,
                                   columns.time, warn) for name in racket_names], axis=0) * length
    ball_all = (_heights(frame, path, columns.ball, "columns.ball", missing, columns.time,
                         warn) * length if columns.ball is not None else None)
    trials = []
    for label, rows in _groups(frame, path, columns.trial, "columns.trial"):
        t = t_all[rows]
        check_trial(path, label, t, columns.time)
        trials.append(Trial(label, t, racket_all[rows],
                            None if ball_all is None else ball_all[rows]))
    return trials


#: the marker-file formats and their readers: (path, length unit or None, warn) -> MarkerSet
MARKER_READERS: dict[str, Callable[..., MarkerSet]] = {
    "c3d": read_c3d_markers, "vicon": read_vicon_csv, "qtm": read_qtm_tsv,
    "motive": read_motive_csv}


def read_marker_recording(path: Path, file_format: str, markers,
                          warn: Callable[[str], None]) -> list[Trial]:
    """One trial (named after the file) from a marker file of ``file_format``: the racket's
    height (the mean of ``markers.racket``'s), the ball's, along ``markers.vertical_axis``
    (or the format's vertical axis)."""
    found = MARKER_READERS[file_format](path, markers.units, warn)
    racket_names = [markers.racket] if isinstance(markers.racket, str) else markers.racket
    axis = markers.vertical_axis or DEFAULT_VERTICAL[file_format]
    racket, ball = marker_heights(path, found, racket_names, markers.ball, axis)
    time_source = {"c3d": "POINT:RATE", "vicon": "Frame", "qtm": "Time",
                   "motive": "Time (Seconds)"}[file_format]
    check_trial(path, path.stem, found.t, time_source)
    return [Trial(path.stem, found.t, racket, ball)]


def read_recording(path: Path, columns, units, markers, csv_format=None, file_format="auto",
                   warn: Callable[[str], None] = lambda message: None) -> list[Trial]:
    """A recording in ``file_format`` (``auto``: ``detect_format``): a CSV table or a marker
    file (C3D, Vicon, QTM, Motive)."""
    path = Path(path)
    if file_format == "auto":
        file_format = detect_format(path)
    if file_format == "csv":
        trials = read_csv_recording(path, columns, units, csv_format, warn)
    else:
        trials = read_marker_recording(path, file_format, markers, warn)
    if not trials:
        raise ConfigError(f"{path}: no samples (a header and no rows?)")
    return trials


#: the extraction's config keys that its errors name ("set columns.racket", "set csv.separator")
_READING_KEY = re.compile(
    r"\bset (['\"]?)(?=(?:columns|event_columns|events_shift_s|csv|units|markers|format|"
    r"extraction)\b)")


def reading_keys_in_block(text: str, block: str) -> str:
    """``text`` (a reading error's or warning's) with the keys it names as a command whose
    reading settings sit in ``block`` takes them: "set columns.racket" is "set
    extract.columns.racket" in ``bounce study`` (its ``extract:`` block) and "set
    replay.columns.racket" in ``bounce virtual --racket replay:FILE``; "--set
    'csv.missing_heights=[0]'" is "--set 'extract.csv.missing_heights=[0]'"."""
    return _READING_KEY.sub(rf"set \g<1>{block}.", text)


def keys_in_block(exc: ConfigError, block: str) -> ConfigError:
    """``exc`` (a reading error) with its keys as :func:`reading_keys_in_block` names them."""
    return ConfigError(reading_keys_in_block(str(exc), block))


def read_events(path: Path, event_columns, units, trials: list[Trial],
                csv_format=None, shift_s: float = 0.0) -> dict[str, Events]:
    """Logged impacts per trial label (every trial of the recording gets an entry), each
    time plus ``shift_s`` (s: ``events_shift_s``, a log on a clock of its own)."""
    path = Path(path)
    frame = read_table(path, csv_format)
    time = TIME_UNITS[units.time]
    t_all = _column(frame, path, event_columns.time, "event_columns.time") * time + shift_s
    alpha_all = None
    if event_columns.alpha is not None and event_columns.alpha in frame.columns:
        alpha_all = _column(frame, path, event_columns.alpha, "event_columns.alpha")
    known = {_key(trial.label): trial.label for trial in trials}
    if event_columns.trial is None:
        if len(trials) != 1:
            raise ConfigError(f"{path}: no trial column but the recording has {len(trials)} "
                              "trials (set event_columns.trial)")
        groups = [(trials[0].label, np.arange(len(frame)))]
    else:
        groups = _groups(frame, path, event_columns.trial, "event_columns.trial")
    events = {_key(trial.label): Events(np.array([]), None) for trial in trials}
    for label, rows in groups:
        if _key(label) not in known:
            raise ConfigError(f"{path}: trial {label} is not in the recording")
        t = t_all[rows]
        if np.any(np.diff(t) <= 0.0) or not np.all(np.isfinite(t)):
            raise ConfigError(f"{path}: trial {label}: column {event_columns.time!r} does not "
                              "increase")
        events[_key(label)] = Events(t, None if alpha_all is None else alpha_all[rows])
    return events


def _key(label) -> str:
    """Trial labels compare as text (1 and '1' are the same trial in two files)."""
    return str(label)
