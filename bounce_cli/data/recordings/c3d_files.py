"""C3D files (Vicon, Qualisys, OptiTrack, Motion Analysis, ...): the markers' vertical coordinate.

The header and the parameter section are parsed here with the ``c3d`` package's building blocks
(``Header``, ``Param``, ``Group``, its processor types Intel, DEC and SGI/MIPS), tolerating what
field files carry and the package's own ``Reader`` refuses; each tolerance is one warning:

* strings padded with NUL bytes (``POINT:UNITS`` ``'mm\\x00\\x00'``, labels);
* a parameter repeated in its group (Vicon Plug-in Gait's ``PROCESSING:BODYMASS``): the first
  is kept;
* a parameter whose description byte is missing (OptiTrack) or a parameter section that breaks
  off (a negative offset to the next parameter): the parameters read so far are kept;
* header and parameters that disagree on the analog words per frame or the point count (Peak
  Performance, MotionMonitor): the count that fits the file's data section is used; on the
  scale or the rate: the parameter (``POINT:SCALE``, ``POINT:RATE``) is used.
* ``POINT:UNITS`` cut short (``'mete'``) or spelt out (``'millimeters'``): the start of the
  names of one length unit only is that unit (``length_unit``); one that begins the names of
  several (``'mi'``: millimetres, micrometres) is refused like an unknown one.

The data section is read in one piece (``read_points``): integer words times ``POINT:SCALE``,
or floats (IEEE, DEC or big-endian); a negative residual word or a non-finite coordinate is a
gap. Labels come from ``POINT:LABELS``, ``POINT:LABELS2``, ... in order. Time is
``(frame - 1) / POINT:RATE`` on the capture clock: the first frame is
``TRIAL:ACTUAL_START_FIELD`` (two 16-bit words) or the header's. Refused, each with its reason:
a file that is empty or not C3D, a truncated data section, no points, a rate, scale or count
parameter that is inf or NaN, no or a non-length ``POINT:UNITS`` (unless ``c3d.units`` is
set), a marker named twice, a marker that is a non-position channel (listed in
``POINT:ANGLES``, ``FORCES``, ``MOMENTS``, ``POWERS`` or another group named in
``POINT:TYPE_GROUPS``).
"""

from __future__ import annotations

import io
import math
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ...runtime.config import ConfigError

#: length units a C3D file's POINT:UNITS may give, in metres
C3D_LENGTH_UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}
#: the names a POINT:UNITS string may be (the start of, when a writer cut it short: 'mete'),
#: each with its unit: a unit of C3D_LENGTH_UNITS, or None for a length unit bounce does not
#: read (there only so that a prefix of its name and of a known one, 'mi', is ambiguous)
UNIT_SPELLINGS: dict[str, str | None] = {
    **{f"{stem}{end}": unit for unit, stems in (("m", ("metre", "meter")),
                                                ("cm", ("centimetre", "centimeter")),
                                                ("mm", ("millimetre", "millimeter")))
       for stem in stems for end in ("", "s")},
    **{name: None for name in ("micrometre", "micrometres", "micrometer", "micrometers",
                               "micron", "microns", "decimetre", "decimeter", "kilometre",
                               "kilometer", "inch", "inches", "foot", "feet")},
}
#: POINT groups that hold channels other than positions (Vicon's model outputs); a file may
#: name more in POINT:TYPE_GROUPS
NON_POSITION_GROUPS = ("ANGLES", "FORCES", "MOMENTS", "POWERS", "SCALARS", "REACTIONS")
#: the c3d parameter section's processor byte: Intel, DEC, SGI/MIPS
PROCESSORS = {84: "Intel", 85: "DEC", 86: "SGI/MIPS"}


def c3d_missing_hint() -> str:
    """How to install the ``c3d`` extra: in a source checkout ``pip install '.[c3d]'``,
    when installed from an index ``pip install 'bounce-cli[c3d]'``."""
    root = Path(__file__).resolve().parents[3]
    if (root / "pyproject.toml").is_file() and (root / "bounce_cli").is_dir():
        return f"pip install '{root}[c3d]' (this checkout), or pip install 'bounce-cli[c3d]'"
    return "pip install 'bounce-cli[c3d]'"


@dataclass(frozen=True)
class C3DPoints:
    """A C3D file's points: ``xyz`` (frame, point, 3) in the file's unit with NaN for gaps,
    the labels, the rate (Hz), the first frame's number, the parameters (``"GROUP:NAME"`` ->
    ``c3d`` Param) and the processor's name."""

    xyz: np.ndarray
    labels: list[str]
    rate: float
    first_frame: int
    parameters: dict[str, Any]
    processor: str

    def strings(self, key: str) -> list[str]:
        """A string parameter (or array) as stripped strings; [] if absent."""
        param = self.parameters.get(key)
        if param is None:
            return []
        return [clean_string(s) for s in np.ravel(param.string_array)]


def clean_string(value) -> str:
    """A C3D string without its padding (blanks and NUL bytes both)."""
    return str(value).replace("\x00", " ").strip()


def read_c3d_points(path: Path, warn: Callable[[str], None]) -> C3DPoints:
    """The points of a C3D file, tolerating field files' quirks with a warning (module doc).

    Parameters
    ----------
    path : Path
        The file.
    warn : callable
        Receives one line per tolerated quirk.

    Returns
    -------
    C3DPoints
    """
    try:
        import c3d  # type: ignore[import-untyped]
    except ImportError:
        raise ConfigError(f"{path}: reading C3D needs the c3d package: "
                          f"{c3d_missing_hint()}") from None
    from .text_exports import read_bytes

    raw = read_bytes(path)
    if len(raw) < 512:
        raise ConfigError(f"{path}: cannot read as C3D: " + (
            "empty file" if not raw else f"{len(raw)} bytes, shorter than a C3D header"))
    if raw[1] != 0x50 or raw[0] < 2 or len(raw) < raw[0] * 512:
        raise ConfigError(f"{path}: cannot read as C3D (not a C3D file: its header has no "
                          "C3D signature)")
    processor = raw[(raw[0] - 1) * 512 + 3]
    if processor not in PROCESSORS:
        raise ConfigError(f"{path}: cannot read as C3D (damaged or not a C3D file: processor "
                          f"byte {processor}, expected 84, 85 or 86)")
    notes: list[str] = []
    try:
        header, dtypes, parameters = _parse(c3d, raw, notes)
    except (struct.error, ValueError, TypeError, KeyError, IndexError) as exc:
        reason = " ".join(str(exc).split()) or type(exc).__name__
        raise ConfigError(f"{path}: cannot read as C3D (damaged parameter section: "
                          f"{reason})") from None
    for note in notes:
        warn(f"{path}: {note}")
    return _points(c3d, path, raw, header, dtypes, parameters, PROCESSORS[processor], warn)


def _parse(c3d, raw: bytes, notes: list[str]):
    """(header, data types, {"GROUP:NAME": Param}) of a C3D file's first blocks."""
    handle = io.BytesIO(raw)
    header = c3d.c3d.Header(handle)
    start = (header.parameter_block - 1) * 512
    _, _, blocks, processor = struct.unpack("BBBB", raw[start:start + 4])
    dtypes = c3d.c3d.DataTypes(processor)
    header._processor_convert(dtypes, handle)
    order = ">" if dtypes.is_mips else "<"
    # some writers count the parameter blocks short (the parameters run on to the data)
    end = min(max(start + 512 * max(blocks, 1), (header.data_block - 1) * 512), len(raw))
    position = start + 4
    group_names: dict[int, str] = {}
    found: dict[tuple[int, str], Any] = {}
    repeated: dict[int, list[str]] = {}
    problems: list[tuple[int, str, str]] = []  # (group, parameter, what)
    problems_seen: set[str] = set()
    while position + 2 <= end:
        chars, group_id = struct.unpack("bb", raw[position:position + 2])
        if chars == 0 or group_id == 0:
            break
        name = clean_string(dtypes.decode_string(raw[position + 2:position + 2 + abs(chars)]))
        name = name.upper()
        position += 2 + abs(chars)
        if position + 2 > end:
            notes.append("the parameter section breaks off after a name; read what came "
                         "before it")
            break
        offset, = struct.unpack(order + "h", raw[position:position + 2])
        if offset < 0 or position + offset > end:
            swapped, = struct.unpack(("<" if order == ">" else ">") + "h",
                                     raw[position:position + 2])
            if 0 <= swapped and position + swapped <= end:
                offset = swapped  # an SGI file written with Intel-order offsets
                if "swapped" not in problems_seen:
                    problems_seen.add("swapped")
                    notes.append("parameter offsets in the other byte order than the "
                                 "processor's (tolerated)")
            else:
                problems.append((group_id, name, f"is damaged (offset {offset} to the next "
                                 "parameter); the parameters before it are read"))
                break
        body = raw[position + 2:position + offset] if offset else raw[position + 2:end]
        position = position + offset if offset else end
        if group_id < 0:
            group_names[-group_id] = name
            continue
        if (group_id, name) in found:
            repeated.setdefault(group_id, []).append(name)
            continue
        param = c3d.c3d.Param(name, dtypes)
        try:
            param.read(io.BytesIO(body))
        except struct.error:
            if len(param.bytes) != param.total_bytes:
                problems.append((group_id, name, "is cut short; left out"))
                continue
            problems.append((group_id, name, "has no description byte (tolerated)"))
        found[(group_id, name)] = param
    parameters = {f"{group_names.get(g, str(g))}:{n}": p for (g, n), p in found.items()}
    for g, n, what in problems:
        notes.append(f"parameter {group_names.get(g, str(g))}:{n} {what}" if g > 0 else
                     f"the record of group {n!r} {what}")
    for g, names in repeated.items():
        unique = list(dict.fromkeys(names))
        notes.append(f"{len(unique)} parameter(s) of group {group_names.get(g, str(g))} appear "
                     f"more than once ({', '.join(unique[:4])}{', ...' if len(unique) > 4 else ''}"
                     "); the first of each is used")
    return header, dtypes, parameters


#: the parameters read as numbers and the element size the C3D standard gives them
STANDARD_SIZES = {"POINT:SCALE": 4, "POINT:RATE": 4, "ANALOG:RATE": 4, "POINT:USED": 2,
                  "POINT:DATA_START": 2, "ANALOG:USED": 2}
SIZE_NAMES = {4: "a float", 2: "a 16-bit integer", 1: "a byte", -1: "text"}


def _value(parameters: dict[str, Any], key: str, default: float,
           warn: Callable[[str], None] = lambda message: None) -> float:
    """A numeric parameter as a float, whatever type the file stored it as (float, 16-bit
    or 8-bit integer, or digits in a string; another type than the standard's is a
    warning); ``default`` if absent or empty."""
    param = parameters.get(key)
    if param is None or param.total_bytes == 0:
        return float(default)
    size = param.bytes_per_element
    if size == 4:
        value = float(param.float_value)
    elif size == 2:
        value = float(param.uint16_value)
    elif size == 1:
        value = float(param.uint8_value)
    else:
        try:
            value = float(clean_string(param.string_value))
        except ValueError:
            return float(default)
    if key in STANDARD_SIZES and size != STANDARD_SIZES[key]:
        warn(f"{key} is stored as {SIZE_NAMES.get(size, f'type {size}')} (the standard: "
             f"{SIZE_NAMES[STANDARD_SIZES[key]]}); read as {value:g}")
    return value


def _points(c3d, path: Path, raw: bytes, header, dtypes, parameters, processor: str,
            warn: Callable[[str], None]) -> C3DPoints:
    def note(message: str) -> None:
        warn(f"{path}: {message}")

    def finite(key: str, value: float) -> float:
        """``value`` of parameter ``key``; inf or NaN (a damaged file) is one line."""
        if not math.isfinite(value):
            raise ConfigError(f"{path}: {key} is {value:g}, not a finite number: the file is "
                              "damaged (export it again from the capture software)")
        return value

    scale = finite("POINT:SCALE", _value(parameters, "POINT:SCALE",
                                         float(header.scale_factor), note))
    if not np.isclose(scale, header.scale_factor, rtol=1e-6):
        warn(f"{path}: POINT:SCALE {scale:g} differs from the header's {header.scale_factor:g}; "
             "POINT:SCALE used")
    rate = finite("POINT:RATE", _value(parameters, "POINT:RATE", float(header.frame_rate),
                                       note))
    if not rate > 0.0:
        rate = finite("POINT:RATE", float(header.frame_rate))
    if not np.isclose(rate, header.frame_rate, rtol=1e-6):
        warn(f"{path}: POINT:RATE {rate:g} Hz differs from the header's "
             f"{header.frame_rate:g} Hz; POINT:RATE used")
    first = int(header.first_frame)
    start_field = parameters.get("TRIAL:ACTUAL_START_FIELD")
    if start_field is not None and start_field.total_bytes >= 4:
        words = start_field.uint16_array.ravel()
        first = int(words[0]) + 65536 * int(words[1])
    last = int(header.last_frame)
    end_field = parameters.get("TRIAL:ACTUAL_END_FIELD")
    if end_field is not None and end_field.total_bytes >= 4:
        words = end_field.uint16_array.ravel()
        last = max(last, int(words[0]) + 65536 * int(words[1]))
    if last >= 65535:
        # the header's 16-bit last frame overflowed (a long capture): POINT:FRAMES counts them
        last = max(last, first - 1 + int(finite("POINT:FRAMES",
                                                _value(parameters, "POINT:FRAMES", 0))))
    frames = max(last - first + 1, 0)
    is_float = scale < 0.0
    word = 4 if is_float else 2
    data_start = (int(finite("POINT:DATA_START", _value(
        parameters, "POINT:DATA_START", header.data_block, note))) - 1) * 512
    if not 0 < data_start < len(raw):
        data_start = (header.data_block - 1) * 512
    available = len(raw) - data_start
    used = int(finite("POINT:USED", _value(parameters, "POINT:USED", header.point_count, note)))
    analog_rate = finite("ANALOG:RATE", _value(parameters, "ANALOG:RATE",
                                               header.analog_per_frame * rate, note))
    per_frame = rate and analog_rate / rate
    channels = finite("ANALOG:USED", _value(
        parameters, "ANALOG:USED", header.analog_count // max(header.analog_per_frame, 1), note))
    analog_words = int(channels * round(per_frame))
    counts = dict.fromkeys([(used, analog_words), (used, int(header.analog_count)),
                            (int(header.point_count), analog_words),
                            (int(header.point_count), int(header.analog_count))])
    # the counts that fit the data section, the closest fit first (a file pads its last block)
    fitting = sorted((c for c in counts if frames * (4 * c[0] + c[1]) * word <= available),
                     key=lambda c: available - frames * (4 * c[0] + c[1]) * word)
    if fitting and (header.point_count, header.analog_count) != (used, analog_words):
        warn(f"{path}: the header ({header.point_count} points, {header.analog_count} analog "
             f"words per frame) and the parameters ({used} points, {analog_words} analog words) "
             f"disagree; {fitting[0][0]} points and {fitting[0][1]} analog words per frame fit "
             "the file and are used")
    points, analog = fitting[0] if fitting else (used, analog_words)
    frame_bytes = (4 * points + analog) * word
    if points == 0:
        raise ConfigError(f"{path}: the file has no points (POINT:USED is 0: analog channels "
                          "only), so no racket or ball marker")
    if frames * frame_bytes > available:
        whole = available // frame_bytes if frame_bytes else 0
        raise ConfigError(f"{path}: truncated C3D file: the data section holds {whole} of its "
                          f"{frames} frames")
    xyz = read_points(c3d, raw[data_start:data_start + frames * frame_bytes], dtypes,
                      frames, points, analog, scale)
    labels = point_labels(parameters, points)
    return C3DPoints(xyz, labels, float(rate), first, parameters, processor)


def read_points(c3d, data: bytes, dtypes, frames: int, points: int, analog_words: int,
                scale: float) -> np.ndarray:
    """The data section's coordinates (frame, point, 3), NaN where the residual word is
    negative (an invalid point) or a coordinate is not finite.

    Parameters
    ----------
    c3d : module
        The ``c3d`` package (its DEC float conversion).
    data : bytes
        The data section, ``frames`` whole frames.
    dtypes : c3d.c3d.DataTypes
        The file's processor's types.
    frames, points, analog_words : int
        Frames, points per frame, analog words per frame.
    scale : float
        POINT:SCALE: negative for float data, else the integer words' scale.

    Returns
    -------
    numpy.ndarray
    """
    words_per_frame = 4 * points + analog_words
    if scale < 0.0:
        if dtypes.is_dec:
            values = np.asarray(c3d.c3d.DEC_to_IEEE_BYTES(data), dtype=np.float32)
        else:
            values = np.frombuffer(data, dtype=dtypes.float32)
        block = values.reshape(frames, words_per_frame)[:, :4 * points].reshape(frames, points, 4)
        coordinates = block[:, :, :3].astype(float)
        # the residual word is an integer stored as a float: negative means invalid
        residual = block[:, :, 3].astype(float)
    else:
        values = np.frombuffer(data, dtype=dtypes.int16)
        block = values.reshape(frames, words_per_frame)[:, :4 * points].reshape(frames, points, 4)
        coordinates = block[:, :, :3].astype(float) * scale
        residual = block[:, :, 3].astype(float)
    invalid = (residual < 0.0) | ~np.all(np.isfinite(coordinates), axis=2)
    coordinates[invalid] = np.nan
    return coordinates


def point_labels(parameters: dict[str, Any], points: int) -> list[str]:
    """POINT:LABELS, then LABELS2, LABELS3, ... (files with more than 255 points), cut to the
    points the file holds; a point without a label gets ''."""
    labels: list[str] = []
    key, n = "POINT:LABELS", 1
    while key in parameters:
        labels += [clean_string(s) for s in np.ravel(parameters[key].string_array)]
        n += 1
        key = f"POINT:LABELS{n}"
    return (labels + [""] * points)[:points]


def length_unit(stored: str) -> str | None:
    """The unit of :data:`C3D_LENGTH_UNITS` a POINT:UNITS string names: the unit itself
    (``'mm'``), or a name of one (``'millimeters'``) or the start of names of one unit only
    (``'mete'``, ``'mil'``: a writer that cut the string short); None for a string that
    begins names of several units (``'mi'``: millimetres or micrometres) or of none.

    Parameters
    ----------
    stored : str
        POINT:UNITS as stored, stripped of its padding, in lower case.

    Returns
    -------
    str or None
        ``'m'``, ``'cm'``, ``'mm'``, or None.

    Examples
    --------
    >>> length_unit("mete"), length_unit("mil"), length_unit("mi")
    ('m', 'mm', None)
    """
    if stored in C3D_LENGTH_UNITS:
        return stored
    units = {unit for name, unit in UNIT_SPELLINGS.items() if stored and name.startswith(stored)}
    return units.pop() if len(units) == 1 else None


def read_c3d_markers(path: Path, units: str | None, warn: Callable[[str], None]):
    """A C3D file's markers as a ``MarkerSet`` in metres (the unit from POINT:UNITS, or
    ``units`` when set), with the points of non-position groups marked.

    Parameters
    ----------
    path : Path
        The file.
    units : str or None
        The positions' length unit if set (``markers.units``), else the file's POINT:UNITS.
    warn : callable
        Receives one line per tolerated quirk.

    Returns
    -------
    MarkerSet
    """
    from .markers import MarkerSet

    data = read_c3d_points(path, warn)
    file_units = " ".join(data.strings("POINT:UNITS")).lower()
    if units is None:
        if not file_units:
            raise ConfigError(f"{path}: the file has no POINT:UNITS, so the positions' length "
                              "unit is unknown: set markers.units (m | cm | mm)")
        units = length_unit(file_units)
        if units is None:
            raise ConfigError(f"{path}: POINT:UNITS is {file_units!r}, not a length unit "
                              f"({', '.join(C3D_LENGTH_UNITS)}): if the positions are in one, "
                              "set markers.units")
        if units != file_units:
            warn(f"{path}: POINT:UNITS is {file_units!r}, read as {units} (the start of one "
                 "length unit's name); set markers.units if it is another")
    elif file_units and file_units != units:
        warn(f"{path}: POINT:UNITS is {file_units!r}; markers.units = {units} used")
    groups = dict.fromkeys(NON_POSITION_GROUPS + tuple(
        s.upper() for s in data.strings("POINT:TYPE_GROUPS")))
    kinds = {name: f"POINT:{group}" for group in groups
             for name in data.strings(f"POINT:{group}")}
    t = (data.first_frame - 1 + np.arange(data.xyz.shape[0])) / data.rate
    return MarkerSet(data.labels, data.xyz * C3D_LENGTH_UNITS[units], t, kinds)
