"""The motion-capture vendors' text exports, each read by its own ``format:``.

* ``vicon``: Vicon Nexus CSV, its ``Trajectories`` section: the section line, the frame rate,
  a line of ``Subject:Marker`` names over each X column, ``Frame,Sub Frame,X,Y,Z,...``, a units
  line (``mm``); empty cells are gaps; frame 1 is t = 0.
* ``qtm``: Qualisys QTM 3D TSV: the ``NO_OF_FRAMES``, ``FREQUENCY``, ``MARKER_NAMES``, ...
  header, then ``Frame Time name X name Y name Z ...`` (or data without that line: frame and
  time columns, or none, told by the count); positions in mm; a marker whose three
  coordinates are all 0, or empty, is a gap (QTM writes both).
* ``motive``: OptiTrack Motive CSV: the metadata line (``Export Frame Rate``,
  ``Length Units``), the ``Type``, ``Name``, ``ID`` (and ``Parent``) rows, the category row
  (``Position``), ``Frame,Time (Seconds),X,Y,Z,...``; every Position triple (a marker, a
  rigid body's marker or centre) is a point named by the Name row; empty cells are gaps.
  Motive is Y-up.

Each is read by ``read_<format>(path, units, warn) -> MarkerSet``: ``units`` is the positions'
unit if set (``markers.units``), else the file's own; ``warn`` receives one line per note.
``detect_format`` tells them from the first line; every problem is one line naming the file
(``ConfigError``).
"""

from __future__ import annotations

import csv
import io
import math
import os
import re
import stat
from pathlib import Path
from typing import Callable

import numpy as np
import pandas as pd

from ...runtime.config import ConfigError
from .markers import MarkerSet

#: length unit names of the exports, in metres
UNIT_NAMES = {"m": 1.0, "cm": 0.01, "mm": 0.001, "meters": 1.0, "centimeters": 0.01,
              "millimeters": 0.001}
#: each export's vertical axis when ``markers.vertical_axis`` is not set
DEFAULT_VERTICAL = {"c3d": "z", "vicon": "z", "qtm": "z", "motive": "y"}


#: the largest recording read, bytes: each is read whole into memory (and a table parsed takes
#: several times its size); an hour at 1 kHz of 100 markers is about 1 GB of text
MAX_RECORDING_BYTES = 2_000_000_000


def check_recording_file(path: Path) -> None:
    """Refuse, before reading it, a recording that is not a regular file (a device such as
    ``/dev/zero``, a folder) or is larger than :data:`MAX_RECORDING_BYTES`, in one line with
    its size; a missing file is left to the reader (its own message).

    Parameters
    ----------
    path : Path
        The recording (or events or impacts table).
    """
    try:
        info = os.stat(path)
    except OSError:
        return
    if not stat.S_ISREG(info.st_mode):
        raise ConfigError(f"{path}: not a regular file (a device, a pipe or a folder): give a "
                          "recording file")
    if info.st_size > MAX_RECORDING_BYTES:
        raise ConfigError(f"{path}: {info.st_size:,} bytes ({info.st_size / 1e9:.1f} GB), "
                          f"larger than a recording may be ({MAX_RECORDING_BYTES / 1e9:g} GB): "
                          "split it into files of a few trials each")


def read_bytes(path: Path) -> bytes:
    """A file's bytes; a missing or unreadable file, or one ``check_recording_file`` refuses,
    is a one-line ConfigError."""
    check_recording_file(path)
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise ConfigError(f"{path}: file not found") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror}") from None


def read_text(path: Path) -> str:
    """A text file's content; missing, unreadable or binary (NUL bytes, a C3D header) is a
    one-line ConfigError; not UTF-8 is read as Latin-1."""
    raw = read_bytes(path)
    check_text(path, raw[:65536])
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def check_text(path: Path, head: bytes) -> None:
    """A file that starts with NUL bytes or a C3D header is not a text table: one line
    saying so (not a codec's message)."""
    if len(head) >= 512 and head[1] == 0x50 and 2 <= head[0] <= 64:
        raise ConfigError(f"{path}: a binary file, not a CSV table: it looks like C3D (name it "
                          "*.c3d or set format: c3d)")
    if b"\x00" in head:
        raise ConfigError(f"{path}: a binary file, not a CSV table (it holds NUL bytes)")


def comment_lines(head: bytes) -> int:
    """How many lines at the start of a text table to skip before its header, from its first
    bytes ``head``: an export's notes, lines starting with ``#`` (after a byte-order mark and
    blanks; blank lines between them too), ``# exported by ...``. Where the last ``#`` line
    holds names only, as many as the fields of the line after it, which holds a number, it
    is the header written as a comment (``#trial,t_s,...``) and is kept: the caller removes
    the ``#`` from the first column's name (``uncommented``)."""
    text = head.removeprefix(b"\xef\xbb\xbf")
    lines = text.split(b"\n")
    count = 0
    for i, line in enumerate(lines):
        stripped = line.strip()
        if stripped.startswith(b"#"):
            count = i + 1
        elif stripped:
            break
    if count and count < len(lines):
        following = _fields(next((line for line in lines[count:] if line.strip()), b""))
        last = _fields(lines[count - 1].strip().lstrip(b"#"))
        if (len(last) == len(following) > 1 and not any(map(_number, last))
                and any(map(_number, following))):  # names above a row of data
            return count - 1
    return count


def uncommented(columns) -> list[str]:
    """Column names with a header written as a comment undone: ``#trial`` -> ``trial``."""
    names = [str(c) for c in columns]
    if names and names[0].lstrip().startswith("#"):
        names[0] = names[0].lstrip().lstrip("#").strip()
    return names


def _fields(line: bytes) -> list[bytes]:
    return [f for f in re.split(rb"[,;\t ]+", line.strip()) if f]


def _number(field: bytes) -> bool:
    try:
        float(field)
    except ValueError:
        return False
    return True


def detect_format(path: Path) -> str:
    """``c3d`` by the suffix; else a text export's format from its first line: ``vicon``
    (a ``Trajectories`` or ``Devices`` section line), ``qtm`` (``NO_OF_FRAMES``), ``motive``
    (``Format Version``), else ``csv``."""
    if path.suffix.lower() == ".c3d":
        return "c3d"
    check_recording_file(path)
    try:
        with open(path, "rb") as handle:
            head = handle.read(4096)
    except OSError:
        return "csv"  # the reader says what is wrong with the file
    check_text(path, head)
    first = head.decode("latin-1").lstrip("\ufeff\xef\xbb\xbf").splitlines()[:1]
    cell = first[0].split(",")[0].split("\t")[0].strip() if first else ""
    if cell in ("Trajectories", "Devices", "Model Outputs", "Joints", "Segments"):
        return "vicon"
    if cell == "NO_OF_FRAMES":
        return "qtm"
    if cell == "Format Version":
        return "motive"
    return "csv"


def _numbers(path: Path, lines: list[str], first_line: int, width: int, sep: str) -> np.ndarray:
    """Data lines as a float array (lines, width); empty cells NaN, other text or a line of
    more cells than ``width`` (a ragged row) an error naming the line."""
    try:
        frame = pd.read_csv(io.StringIO("\n".join(lines)), sep=sep, header=None,
                            names=range(width), dtype=str, keep_default_na=False,
                            skip_blank_lines=False, engine="python")
    except pd.errors.ParserError as exc:
        ragged = next(((k, len(cells)) for k, cells in enumerate(csv.reader(
            lines, delimiter=sep)) if len(cells) > width), None)
        if ragged is None:  # another problem (an open quote): pandas' words for it
            raise ConfigError(f"{path}: cannot read the data lines: "
                              f"{str(exc).strip().splitlines()[0]}") from None
        raise ConfigError(f"{path}: line {first_line + ragged[0]}: {ragged[1]} cells, more "
                          f"than the {width} columns of the header (a ragged row: export the "
                          "file again, or mend that line)") from None
    cells = frame.apply(lambda c: c.str.strip())
    values = cells.apply(pd.to_numeric, errors="coerce")
    bad = values.isna() & (cells != "") & cells.notna()
    if bad.to_numpy().any():
        row, col = np.argwhere(bad.to_numpy())[0]
        raise ConfigError(f"{path}: line {first_line + row}, column {col + 1}: not a number "
                          f"({cells.iat[row, col]!r})")
    return values.to_numpy(float)


def _rate(path: Path, text: str, where: str) -> float:
    """A frame rate as the file writes it (Hz): a finite number > 0, else one line naming
    ``where`` it is."""
    try:
        rate = float(text)
    except ValueError:
        raise ConfigError(f"{path}: {where} is {text.strip()!r}, not a number (the frame "
                          "rate in Hz)") from None
    if not (math.isfinite(rate) and rate > 0.0):
        raise ConfigError(f"{path}: {where} is {text.strip()!r}, not a rate (a frame rate in "
                          "Hz is a number > 0)")
    return rate


def _unit(path: Path, name: str, where: str) -> float:
    key = name.strip().lower()
    if key not in UNIT_NAMES:
        raise ConfigError(f"{path}: {where} is {name.strip()!r}, not a length unit (mm, cm, m): "
                          "if the positions are in one, set markers.units")
    return UNIT_NAMES[key]


def read_vicon_csv(path: Path, units: str | None, warn: Callable[[str], None]) -> MarkerSet:
    """The ``Trajectories`` section of a Vicon Nexus CSV export (module doc); the file's own
    unit: its units line."""
    lines = read_text(path).splitlines()
    starts = [i for i, line in enumerate(lines) if line.split(",")[0].strip() == "Trajectories"]
    if not starts:
        raise ConfigError(f"{path}: no 'Trajectories' section (export the trajectories from "
                          "Nexus, or set format)")
    s = starts[0]
    if len(lines) < s + 6:
        raise ConfigError(f"{path}: the 'Trajectories' section ends before its data")
    rate = _rate(path, lines[s + 1].split(",")[0], f"line {s + 2}: the frame rate")
    names, header, unit_row = (next(csv.reader([lines[s + k]])) for k in (2, 3, 4))
    if header[:2] != ["Frame", "Sub Frame"]:
        raise ConfigError(f"{path}: line {s + 4}: expected 'Frame,Sub Frame,X,Y,Z,...', found "
                          f"{','.join(header[:5])!r}")
    end = next((i for i in range(s + 5, len(lines)) if not lines[i].strip(", ")), len(lines))
    data = _numbers(path, lines[s + 5:end], s + 6, len(header), ",")
    labels, columns, scales = [], [], []
    for j, name in enumerate(names):
        if not name.strip():
            continue
        if header[j:j + 3] != ["X", "Y", "Z"]:
            raise ConfigError(f"{path}: line {s + 4}: marker {name.strip()!r} is not over "
                              "X,Y,Z columns")
        labels.append(name.strip())
        columns.append(j)
        scales.append(UNIT_NAMES[units] if units is not None else _unit(
            path, unit_row[j] if j < len(unit_row) else "", f"the unit of {name.strip()!r}"))
    if not labels:
        raise ConfigError(f"{path}: line {s + 3}: no marker names over the X,Y,Z columns")
    xyz = np.stack([data[:, j:j + 3] * scale for j, scale in zip(columns, scales)], axis=1)
    t = (data[:, 0] - 1.0) / rate
    return MarkerSet(labels, xyz, t)


def read_qtm_tsv(path: Path, units: str | None, warn: Callable[[str], None]) -> MarkerSet:
    """A Qualisys QTM 3D TSV export (module doc); the file's own unit: mm, as QTM writes
    them."""
    lines = read_text(path).splitlines()
    header: dict[str, list[str]] = {}
    i = 0
    while i < len(lines):
        cells = lines[i].rstrip("\r").split("\t")
        key = cells[0].strip()
        if not key or key == "Frame" or key[0] in "0123456789-.":
            break
        header[key] = [c.strip() for c in cells[1:]]
        i += 1
    for key in ("FREQUENCY", "MARKER_NAMES"):
        if not header.get(key):
            raise ConfigError(f"{path}: no {key} line in the QTM header")
    rate = _rate(path, header["FREQUENCY"][0], "FREQUENCY")
    labels = [name for name in header["MARKER_NAMES"] if name]
    if not labels:
        raise ConfigError(f"{path}: MARKER_NAMES names no marker (export the 3D data with "
                          "its labelled trajectories)")
    scale = UNIT_NAMES[units] if units is not None else 0.001
    columns = None
    if i < len(lines) and lines[i].split("\t")[0].strip() == "Frame":
        columns = [c.strip() for c in lines[i].split("\t")]
        i += 1
    while i < len(lines) and not lines[i].strip():
        i += 1
    body = [line for line in lines[i:] if line.strip()]
    if not body:
        raise ConfigError(f"{path}: no data rows after the QTM header")
    width = len(body[0].split("\t"))
    if columns is not None:
        where = []
        for name in labels:
            if f"{name} X" not in columns:
                raise ConfigError(f"{path}: the column line has no '{name} X' for marker "
                                  f"{name!r} of MARKER_NAMES")
            where.append(columns.index(f"{name} X"))
        time_column = columns.index("Time") if "Time" in columns else None
        width = max(width, len(columns))
    else:
        prefix = width - 3 * len(labels)
        if prefix not in (0, 2):
            raise ConfigError(f"{path}: {width} columns for {len(labels)} markers (expected "
                              f"{3 * len(labels)}, or 2 more for frame and time)")
        where = [prefix + 3 * k for k in range(len(labels))]
        time_column = 1 if prefix == 2 else None
    data = _numbers(path, body, i + 1, width, "\t")
    xyz = np.stack([data[:, j:j + 3] for j in where], axis=1) * scale
    # QTM writes a marker it did not see as 0, 0, 0 (or empty cells)
    xyz[np.all(xyz == 0.0, axis=2)] = np.nan
    frames = header.get("NO_OF_FRAMES", [""])[0]
    if frames.isdigit() and int(frames) != len(data):
        warn(f"{path}: NO_OF_FRAMES is {frames} but the file has {len(data)} rows; the rows used")
    t = data[:, time_column] if time_column is not None else np.arange(len(data)) / rate
    return MarkerSet(labels, xyz, t)


def read_motive_csv(path: Path, units: str | None, warn: Callable[[str], None]) -> MarkerSet:
    """An OptiTrack Motive CSV export (module doc): every ``Position`` X, Y, Z triple is a
    point named by the ``Name`` row; the file's own unit: the metadata's ``Length Units``."""
    lines = read_text(path).splitlines()
    rows = list(csv.reader(lines))
    meta_cells = rows[0] if rows else []
    meta = {meta_cells[k].strip(): meta_cells[k + 1].strip()
            for k in range(0, len(meta_cells) - 1, 2)}
    frame_row = next((i for i, r in enumerate(rows) if r[:1] == ["Frame"]), None)
    by_title = {r[1].strip(): i for i, r in enumerate(rows[:frame_row or 0]) if len(r) > 1
                and not r[0].strip() and r[1].strip()}
    if frame_row is None or "Name" not in by_title:
        raise ConfigError(f"{path}: not a Motive CSV export: no 'Name' row and "
                          "'Frame,Time (Seconds),X,Y,Z,...' row")
    if units is not None:
        scale = UNIT_NAMES[units]
    elif "Length Units" in meta:
        scale = _unit(path, meta["Length Units"], "Length Units")
    else:
        raise ConfigError(f"{path}: the metadata line has no 'Length Units': set markers.units "
                          "(m | cm | mm)")
    header, names = rows[frame_row], rows[by_title["Name"]]
    category = rows[frame_row - 1]
    data = _numbers(path, lines[frame_row + 1:], frame_row + 2, len(header), ",")
    labels, columns = [], []
    for j in range(2, len(header) - 2):
        if header[j:j + 3] == ["X", "Y", "Z"] and j < len(category) \
                and category[j].strip() == "Position" and j < len(names):
            labels.append(names[j].strip())
            columns.append(j)
    if not labels:
        raise ConfigError(f"{path}: no Position X,Y,Z columns")
    time_column = next((j for j, c in enumerate(header) if c.startswith("Time")), None)
    xyz = np.stack([data[:, j:j + 3] for j in columns], axis=1) * scale
    if time_column is not None:
        t = data[:, time_column]
    else:
        key = next((k for k in ("Export Frame Rate", "Capture Frame Rate") if k in meta), None)
        if key is None:
            raise ConfigError(f"{path}: no 'Time (Seconds)' column and no 'Export Frame Rate' "
                              "in the metadata line: export the time column")
        t = data[:, 0] / _rate(path, meta[key], key)
    return MarkerSet(labels, xyz, t)
