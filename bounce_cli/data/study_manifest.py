"""The study manifest (``bounce study --manifest study.csv``): one row per recording.

Columns:

=========================  =====================================================================
``file``                   a recording (any format ``bounce extract`` reads: CSV/TSV or C3D) or
                           an impacts table (``impacts.csv``); relative paths are relative to the
                           manifest's folder
``subject``                the subject (required): a unit of the study is a subject x condition
``events`` (optional)      the events file of a recording (a virtual set-up's log)
``condition``, ``session``, factors carried into every output; ``trial`` numbers a recording in
``trial`` and any other    its subject's series (the learning trend's x axis); an empty cell is
column                     the factor's value ``""`` (printed as ``-``)
``extract.<key>``          a per-row override of the study's extraction settings, e.g.
                           ``extract.markers.ball`` (an empty cell: no override)
=========================  =====================================================================

Read before anything runs: a missing column, a column given twice, a file that does not exist
or is not a recording (a folder, a device, a system file), a recording listed twice (the same
file with the same ``extract.*`` settings), or a factor value that cannot name a folder is one
line naming the manifest, the line and the reason (never the bytes of a file). When the units
are formed (:meth:`Manifest.units`), two recordings of a unit with one ``trial`` label, and two
units whose folders differ only in case (one folder on macOS and Windows), are such a line too.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd
import yaml

from ..runtime.config import ConfigError

#: columns every manifest has
REQUIRED_COLUMNS = ("file", "subject")
#: columns that are not factors
FILE_COLUMNS = ("file", "events")
#: prefix of the columns that override the extraction's settings per row
OVERRIDE_PREFIX = "extract."
#: folders of the operating system's own files: a manifest row pointing into one (or a link
#: resolving there, e.g. to /etc/passwd) is refused before the file is read
SYSTEM_FOLDERS = ("/etc", "/proc", "/sys", "/dev", "/boot", "/run", "/var/log", "/private/etc",
                  "/private/var/log")
#: a factor value names a folder: letters, digits and . _ - (and spaces inside)
_SAFE = re.compile(r"^[A-Za-z0-9._\-][A-Za-z0-9._\- ]*$")


def names_a_folder(value: str) -> bool:
    """Whether a factor value (a subject, a condition) can name a folder of the study's
    outputs: letters, digits, '.', '_', '-' and spaces inside, and not '.' or '..' (which
    name the folder itself or its parent). The sessions ``bounce virtual`` writes take the
    same rule, so that a session's manifest is one the study reads."""
    return bool(_SAFE.match(value)) and value not in (".", "..")


@dataclass(frozen=True)
class ManifestRow:
    """One recording of the study: its file (absolute), events file, factors (column ->
    value, as written) and extraction overrides (``key=value`` texts, ``--set`` style)."""

    line: int
    file: Path
    events: Path | None
    factors: dict[str, str]
    overrides: tuple[str, ...] = ()


@dataclass(frozen=True)
class Unit:
    """The recordings analysed together: one value per grouping factor."""

    key: tuple[str, ...]
    grouping: tuple[str, ...]
    rows: tuple[ManifestRow, ...] = field(default_factory=tuple)

    @property
    def label(self) -> str:
        """``subject s1, condition vision``."""
        return ", ".join(f"{name} {value or '-'}" for name, value in zip(self.grouping, self.key))

    @property
    def folder(self) -> str:
        """The unit's folder under ``--out``: ``<subject>/<condition>``."""
        return "/".join(value or "-" for value in self.key)

    def factors(self) -> dict[str, str]:
        """The factors constant over the unit's rows (the grouping factors among them)."""
        common = dict(self.rows[0].factors)
        for row in self.rows[1:]:
            for name in list(common):
                if row.factors.get(name) != common[name]:
                    del common[name]
        return {**common, **dict(zip(self.grouping, self.key))}


@dataclass(frozen=True)
class Manifest:
    """A checked manifest: its rows in file order and its factor columns."""

    path: Path
    rows: tuple[ManifestRow, ...]
    factor_columns: tuple[str, ...]

    def units(self, grouping: tuple[str, ...]) -> list[Unit]:
        """The units by ``grouping`` (factors the manifest must have), in order of first
        appearance; a unit's rows are ordered by their ``trial`` factor where it is a number,
        else as listed."""
        missing = [g for g in grouping if g not in self.factor_columns]
        if missing:
            raise ConfigError(f"grouping: manifest {self.path} has no column "
                              f"{', '.join(map(repr, missing))} (its factors: "
                              f"{', '.join(self.factor_columns)})")
        groups: dict[tuple[str, ...], list[ManifestRow]] = {}
        for row in self.rows:
            groups.setdefault(tuple(row.factors[g] for g in grouping), []).append(row)
        units = [Unit(key, tuple(grouping), tuple(sorted(rows, key=_trial_order)))
                 for key, rows in groups.items()]
        where = f"manifest {self.path}"
        folders: dict[str, Unit] = {}
        for unit in units:
            other = folders.setdefault(unit.folder.casefold(), unit)
            if other is not unit:
                raise ConfigError(
                    f"{where}: lines {other.rows[0].line} and {unit.rows[0].line}: units "
                    f"{other.folder!r} and {unit.folder!r} differ only in case: on macOS and "
                    "Windows they would write into one folder (spell the values alike, or "
                    "differently)")
            lines: dict[str, int] = {}
            for row in unit.rows:
                trial = row.factors.get("trial", "")
                if trial and lines.setdefault(trial, row.line) != row.line:
                    first, second = sorted((lines[trial], row.line))
                    raise ConfigError(
                        f"{where}: lines {first} and {second}: {unit.label}: trial {trial!r} "
                        "twice (each recording of a unit has its own trial label)")
        return units

    def trial_order_notes(self, unit: Unit) -> list[str]:
        """Warnings for a unit whose ``trial`` labels mix numbers with other text (or an
        empty cell): those recordings are ordered after the numbered ones, so that the
        learning trend's trial numbers are not the labels."""
        labels = [row.factors.get("trial") for row in unit.rows]
        if "trial" not in self.factor_columns or not any(_is_number(t) for t in labels):
            return []
        return [f"{unit.label}: trial {_shown(row.factors['trial'])} (manifest line "
                f"{row.line}) is not a number: ordered after the numbered trials, as trial "
                f"{position} of {len(unit.rows)}"
                for position, row in enumerate(unit.rows, start=1)
                if not _is_number(row.factors["trial"])]


def _shown(trial: str) -> str:
    return repr(trial) if trial else "(an empty cell)"


def _is_number(text: str | None) -> bool:
    try:
        return text is not None and math.isfinite(float(text))
    except ValueError:
        return False


def _trial_order(row: ManifestRow) -> tuple[float, int]:
    try:
        return float(row.factors.get("trial", "")), row.line
    except ValueError:
        return float("inf"), row.line


def read_manifest(path: str | Path) -> Manifest:
    """The manifest at ``path``, checked (see the module docstring).

    Parameters
    ----------
    path : str or Path
        The manifest CSV.

    Returns
    -------
    Manifest
        Rows with absolute file paths, factors and per-row extraction overrides.

    Raises
    ------
    ConfigError
        One line naming the manifest (and the line) for every problem found before the study
        runs.
    """
    path = Path(path)
    where = f"manifest {path}"
    try:
        frame = pd.read_csv(path, dtype=str, keep_default_na=False, skipinitialspace=True)
    except FileNotFoundError:
        raise ConfigError(f"{where}: file not found") from None
    except (OSError, pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ConfigError(f"{where}: cannot read as CSV: {first}") from None
    header = _header(path, where)
    twice = sorted({c for c in header if header.count(c) > 1})
    if twice:  # pandas has renamed the second one (subject.1): this header as written
        raise ConfigError(f"{where}: column(s) {', '.join(twice)} given twice (give each "
                          "column once)")
    frame.columns = header
    missing = [c for c in REQUIRED_COLUMNS if c not in frame.columns]
    if missing:
        raise ConfigError(f"{where}: missing column(s) {', '.join(missing)} (a manifest has "
                          f"one row per recording: file, subject[, condition, trial, ...])")
    if frame.empty:
        raise ConfigError(f"{where}: no rows (one row per recording)")
    overrides = [c for c in frame.columns if c.startswith(OVERRIDE_PREFIX)]
    factors = tuple(c for c in frame.columns if c not in FILE_COLUMNS and c not in overrides)
    rows: list[ManifestRow] = []
    seen: dict[tuple, int] = {}
    base = path.parent
    for i, record in enumerate(frame.to_dict("records"), start=2):
        text = record["file"].strip()
        if not text:
            raise ConfigError(f"{where}: line {i}: empty file cell")
        file = _existing(base, text, where, i, "file")
        events_text = record.get("events", "").strip()
        events = _existing(base, events_text, where, i, "events") if events_text else None
        values = {name: record[name].strip() for name in factors}
        if not values["subject"]:
            raise ConfigError(f"{where}: line {i}: empty subject cell")
        for name, value in values.items():
            if value and not names_a_folder(value):
                raise ConfigError(f"{where}: line {i}: {name} {value!r}: a factor value names a "
                                  "folder (use letters, digits, '.', '_', '-' and spaces)")
        texts = []
        for column in overrides:
            cell = record[column].strip()
            if cell:
                key = column[len(OVERRIDE_PREFIX):]
                try:
                    yaml.safe_load(cell)
                except yaml.YAMLError:
                    raise ConfigError(f"{where}: line {i}: {column}: cannot parse {cell!r} as a "
                                      "YAML value") from None
                texts.append(f"{key}={cell}")
        # one file twice is one recording counted twice (its impacts pooled twice), unless
        # its rows read it differently (extract.* settings: two balls in one recording)
        identity = (file, tuple(texts))
        if identity in seen:
            raise ConfigError(f"{where}: line {i}: file {text!r}: the same recording as line "
                              f"{seen[identity]} (list each recording once; one file read "
                              "twice needs other extract.* settings per row)")
        seen[identity] = i
        rows.append(ManifestRow(i, file, events, values, tuple(texts)))
    return Manifest(path, tuple(rows), factors)


def _header(path: Path, where: str) -> list[str]:
    """The manifest's column names as written, stripped (``pd.read_csv`` renames a second
    ``subject`` to ``subject.1``, hiding that it was given twice)."""
    try:
        first = pd.read_csv(path, header=None, nrows=1, dtype=str, keep_default_na=False,
                            skipinitialspace=True)
    except (OSError, pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError):
        raise ConfigError(f"{where}: cannot read its header as CSV") from None
    return [str(c).strip() for c in first.iloc[0]]


def _existing(base: Path, text: str, where: str, line: int, column: str) -> Path:
    """The row's file, resolved (symbolic links followed); one line naming the manifest's line
    and the cell where it does not exist, is no regular file, or is a system file (under
    :data:`SYSTEM_FOLDERS`). The file is not opened here: no message holds its bytes."""
    file = Path(text)
    file = file if file.is_absolute() else base / file
    if not file.exists():
        raise ConfigError(f"{where}: line {line}: {column} {text!r}: no such file "
                          f"(paths are relative to the manifest's folder)")
    resolved = file.resolve()
    system = next((f for f in SYSTEM_FOLDERS if resolved.is_relative_to(f)), None)
    if system is not None:
        link = f" (a link to {resolved})" if str(resolved) != text else ""
        raise ConfigError(f"{where}: line {line}: {column} {text!r}{link}: a system file, not "
                          f"a recording (under {system}); give the recording's path")
    if not resolved.is_file():
        raise ConfigError(f"{where}: line {line}: {column} {text!r}: not a regular file (a "
                          "folder, a device or a pipe); give a recording's path")
    return resolved
