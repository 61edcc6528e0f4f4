"""The C3D reader (recordings/c3d_files.py) on files with a known answer that carry the quirks
of field files: each written here with the ``c3d`` package's writer, then degraded byte by
byte as the field file is (NUL padding, a repeated parameter, header and parameters that
disagree, no ANALOG:RATE with analog words in the frames, LABELS2, a first-frame offset, a
truncated data section, doubled labels, a moment stored as a point). Markers must come back
to float32 rounding (the file stores float32: relative 1e-6)."""

import os
import struct
from pathlib import Path

import numpy as np
import pytest

from bounce_cli.runtime.config import ConfigError
from bounce_cli.data.recordings import read_recording
from bounce_cli.data.recordings.c3d_files import _value, c3d_missing_hint, read_c3d_points
from bounce_cli.experiments.extract import ExtractConfig

c3d = pytest.importorskip("c3d")
RATE = 200.0


def truth_xyz(frames: int, points: int, seed: int = 1) -> np.ndarray:
    """Smooth marker paths in mm, a few gaps."""
    rng = np.random.default_rng(seed)
    t = np.arange(frames) / RATE
    xyz = (rng.uniform(-500, 1500, (1, points, 3))
           + 200 * np.sin(2 * np.pi * t[:, None, None] / 0.92 + rng.uniform(0, 6, (points, 3))))
    xyz[5, 0] = np.nan  # a gap
    return xyz


def write_c3d(path: Path, labels, xyz, *, units="mm", scale=-1.0, analog=0, edit=None) -> bytes:
    """Write ``xyz`` (frame, point, 3; NaN: invalid) with ``labels``; ``edit(writer)`` before
    writing; returns the file's bytes."""
    writer = c3d.Writer(point_rate=RATE, analog_rate=RATE if analog else 0.0, point_scale=scale,
                        point_units=units)
    writer.set_point_labels(labels)
    frames = []
    for frame in xyz:
        points = np.zeros((len(labels), 5), dtype=np.float32)
        invalid = np.isnan(frame).any(axis=1)
        points[:, :3] = np.where(np.isnan(frame), 0.0, frame)
        points[invalid, 3] = -1.0
        frames.append((points, np.full((analog, 1), 7.0, dtype=np.float32)))
    writer.add_frames(frames)
    if edit is not None:
        edit(writer)
    with open(path, "wb") as handle:
        writer.write(handle)
    return path.read_bytes()


def record_at(raw: bytes, group_id: int, name: bytes) -> int:
    """Byte offset of parameter ``name``'s record in group ``group_id``."""
    at = raw.find(bytes([len(name), group_id]) + name, 512)
    assert at > 0
    return at


def group_id(writer, name: str) -> int:
    return next(k for k, g in writer._groups.items() if isinstance(k, int) and g.name == name)


def assert_same(points, xyz):
    assert points.xyz.shape == xyz.shape
    assert np.array_equal(np.isnan(points.xyz), np.isnan(xyz))
    ok = ~np.isnan(xyz)
    np.testing.assert_allclose(points.xyz[ok], xyz[ok], rtol=1e-6)


def settings(**markers):
    return ExtractConfig.model_validate({"markers": markers})


def test_float_and_integer_files_are_read_to_float32_rounding(tmp_path):
    xyz = truth_xyz(60, 3)
    write_c3d(tmp_path / "f.c3d", ["a", "b", "c"], xyz)
    assert_same(read_c3d_points(tmp_path / "f.c3d", print), xyz)
    # integer words: the coordinates are rounded to POINT:SCALE (0.1 mm) by the writer
    write_c3d(tmp_path / "i.c3d", ["a", "b", "c"], xyz, scale=0.1)
    got = read_c3d_points(tmp_path / "i.c3d", print)
    ok = ~np.isnan(xyz)
    assert np.max(np.abs(got.xyz[ok] - xyz[ok])) <= 0.1 and np.isnan(got.xyz[5, 0]).all()


def test_nul_padded_units_are_millimetres(tmp_path):
    xyz = truth_xyz(60, 2)
    write_c3d(tmp_path / "m.c3d", ["racket", "ball"], xyz, units="mm\x00\x00")
    cfg = settings()
    (trial,) = read_recording(tmp_path / "m.c3d", cfg.columns, cfg.units, cfg.markers)
    np.testing.assert_allclose(trial.ball[6:], xyz[6:, 1, 2] / 1000.0, rtol=1e-6)


def test_a_repeated_parameter_keeps_the_first_with_one_warning(tmp_path):
    def edit(writer):
        group = writer.get_create("PROCESSING")
        group.set("BODYMASS", "mass", 4, "<f", 71.0)
        group.set("BODYMASX", "mass again", 4, "<f", 99.0)

    raw = write_c3d(tmp_path / "p.c3d", ["a"], truth_xyz(60, 1), edit=edit)
    (tmp_path / "p.c3d").write_bytes(raw.replace(b"BODYMASX", b"BODYMASS"))
    notes = []
    got = read_c3d_points(tmp_path / "p.c3d", notes.append)
    assert got.parameters["PROCESSING:BODYMASS"].float_value == 71.0
    assert len(notes) == 1 and "PROCESSING" in notes[0] and "BODYMASS" in notes[0]
    with pytest.raises(KeyError, match="already exists"):  # the package's own reader refuses
        with open(tmp_path / "p.c3d", "rb") as handle:
            c3d.Reader(handle)


def test_a_header_analog_count_that_does_not_fit_is_overruled_with_a_warning(tmp_path):
    xyz = truth_xyz(60, 2)
    raw = bytearray(write_c3d(tmp_path / "a.c3d", ["a", "b"], xyz, analog=3))
    raw[4:6] = struct.pack("<H", 3 * 7)  # MotionMonitor: header word 3 disagrees
    (tmp_path / "a.c3d").write_bytes(bytes(raw))
    notes = []
    assert_same(read_c3d_points(tmp_path / "a.c3d", notes.append), xyz)
    assert len(notes) == 1 and "fit the file" in notes[0]


def test_analog_words_without_analog_rate_are_skipped_not_read_as_points(tmp_path):
    """A BTS/Elite file: frames hold analog words, ANALOG:RATE is absent (the header's one
    sample per frame counts): a reader that assumes no analog words shifts every frame after
    the first (ezc3d 1.7 does on BTKData's 561xxa01_anonym.C3D)."""
    xyz = truth_xyz(60, 2)
    holder = {}

    def edit(writer):
        holder["analog"] = group_id(writer, "ANALOG")

    raw = write_c3d(tmp_path / "b.c3d", ["a", "b"], xyz, analog=6, edit=edit)
    at = record_at(raw, holder["analog"], b"RATE")
    raw = raw[:at + 2] + b"RATX" + raw[at + 6:]
    (tmp_path / "b.c3d").write_bytes(raw)
    got = read_c3d_points(tmp_path / "b.c3d", print)
    assert "ANALOG:RATE" not in got.parameters
    assert_same(got, xyz)


def test_labels2_and_the_first_frame_offset(tmp_path):
    xyz = truth_xyz(60, 3)

    def edit(writer):
        writer.point_group.remove_param("LABELS")
        writer.set_point_labels(["a", "b"])
        packed, size = c3d.Writer.pack_labels(["ball"])
        writer.point_group.add_str("LABELS2", "more labels", packed, size, 1)
        writer.set_start_frame(1001)

    write_c3d(tmp_path / "l.c3d", ["a", "b", "ball"], xyz, edit=edit)
    got = read_c3d_points(tmp_path / "l.c3d", print)
    assert got.labels == ["a", "b", "ball"] and got.first_frame == 1001
    cfg = settings(racket="a", ball="ball")
    (trial,) = read_recording(tmp_path / "l.c3d", cfg.columns, cfg.units, cfg.markers)
    # frame 1001 is t = 1000 / rate on the capture clock, not 0
    np.testing.assert_allclose(trial.t[:2], [1000.0 / RATE, 1001.0 / RATE])
    np.testing.assert_allclose(trial.ball, xyz[:, 2, 2] / 1000.0, rtol=1e-6)


@pytest.mark.parametrize("case, needles", [
    ("truncated", ("truncated", "of its 60 frames")),
    ("doubled", ("'ball' is named 2 times", "points 2, 3")),
    ("moment", ("'LHipMoment' is listed in POINT:MOMENTS", "markers.ball")),
    ("no units", ("no POINT:UNITS", "set markers.units")),
    ("degrees", ("POINT:UNITS is 'deg'", "not a length unit", "set markers.units")),
    ("not c3d", ("not a C3D file",)),
])
def test_files_that_cannot_give_the_markers_say_why(tmp_path, case, needles):
    path = tmp_path / "x.c3d"
    labels = ["racket", "ball", "ball" if case == "doubled" else "LHipMoment"]

    def edit(writer):
        if case == "moment":
            packed, size = c3d.Writer.pack_labels(["LHipMoment"])
            writer.point_group.add_str("MOMENTS", "moments", packed, size, 1)

    raw = write_c3d(path, labels, truth_xyz(60, 3), units="deg " if case == "degrees" else "mm",
                    edit=edit)
    if case == "truncated":
        path.write_bytes(raw[:len(raw) - 1024])
    if case == "no units":
        path.write_bytes(raw.replace(b"UNITS", b"UNITX", 1))
    if case == "not c3d":
        path.write_bytes(b"trial,t_s\n" * 100)
    cfg = settings(ball="LHipMoment" if case == "moment" else "ball")
    with pytest.raises(ConfigError) as info:
        read_recording(path, cfg.columns, cfg.units, cfg.markers)
    message = str(info.value)
    assert str(path) in message and "\n" not in message and "damaged" not in message
    for needle in needles:
        assert needle in message, message


def test_markers_units_overrides_a_file_without_a_length_unit(tmp_path):
    xyz = truth_xyz(60, 2)
    write_c3d(tmp_path / "d.c3d", ["racket", "ball"], xyz, units="deg ")
    cfg = settings(units="mm")
    notes = []
    (trial,) = read_recording(tmp_path / "d.c3d", cfg.columns, cfg.units, cfg.markers,
                              warn=notes.append)
    np.testing.assert_allclose(trial.racket[6:], xyz[6:, 0, 2] / 1000.0, rtol=1e-6)
    assert len(notes) == 1 and "'deg'" in notes[0]


def test_a_parameter_stored_as_another_type_is_read_by_its_size():
    dtypes = c3d.c3d.DataTypes(84)
    as_float = c3d.c3d.Param("RATE", dtypes, bytes_per_element=4, bytes=struct.pack("<f", 250))
    as_int = c3d.c3d.Param("RATE", dtypes, bytes_per_element=2, bytes=struct.pack("<H", 250))
    as_text = c3d.c3d.Param("RATE", dtypes, bytes_per_element=-1, dimensions=[4],
                            bytes=b"250\x00")
    warned = []
    for param in (as_float, as_int, as_text):
        notes: list[str] = []
        assert _value({"POINT:RATE": param}, "POINT:RATE", 1.0, notes.append) == 250.0
        warned.append(notes)
    assert warned[0] == [] and "a 16-bit integer" in warned[1][0] and "text" in warned[2][0]
    assert _value({}, "POINT:RATE", 1.0) == 1.0


def test_the_missing_extra_hint_names_the_checkout_and_the_package():
    hint = c3d_missing_hint()
    assert "bounce-cli[c3d]" in hint
    # this test runs from a checkout: the hint says how to install the extra from it
    assert "[c3d]' (this checkout)" in hint


COLLECTION = os.environ.get("BOUNCE_C3D_SAMPLES")


@pytest.mark.slow
@pytest.mark.skipif(not COLLECTION, reason="set BOUNCE_C3D_SAMPLES to BTKData's C3DSamples")
def test_the_btkdata_collection_is_read():
    """BTKData's Input/C3DSamples (with the c3d.org samples): every file but the empty one and
    the analog-only EMG file gives its points (README: the fraction read), and the Elite
    file ezc3d misreads gives smooth marker paths (no frame shifted by analog words)."""
    files = sorted(p for p in Path(COLLECTION).rglob("*") if p.suffix.lower() == ".c3d")
    refused = {}
    for path in files:
        try:
            read_c3d_points(path, lambda message: None)
        except ConfigError as exc:
            refused[path.name] = str(exc)
    assert set(refused) <= {"Empty.c3d", "1123x01EMG.c3d"}, refused
    elite = next(p for p in files if p.name == "561xxa01_anonym.C3D")
    xyz = read_c3d_points(elite, lambda message: None).xyz
    step = np.nanmedian(np.abs(np.diff(xyz, axis=0)))
    assert step < 5.0  # mm per frame at 100 Hz: a walking subject, not shuffled words
    # the c3d.org samples store one capture for Intel, DEC and SGI processors: the same
    # markers from each (the SGI integer file bit for bit, the others within one integer
    # step of POINT:SCALE: each was rounded to integers on its own)
    for folder, names in (("sample01", ("Eb015pi", "Eb015si", "Eb015vi", "Eb015pr", "Eb015sr",
                                        "Eb015vr")),
                          ("sample02", ("pc_int", "sgi_int", "DEC_INT", "pc_real", "sgi_real",
                                        "Dec_real"))):
        found = {p.stem: p for p in files if p.parent.name == folder}
        reference = read_c3d_points(found[names[0]], lambda message: None)
        step = abs(_value(reference.parameters, "POINT:SCALE", 1.0))
        for name in names[1:]:
            other = read_c3d_points(found[name], lambda message: None)
            assert other.labels == reference.labels
            assert np.array_equal(np.isnan(other.xyz), np.isnan(reference.xyz))
            error = np.nanmax(np.abs(other.xyz - reference.xyz))
            assert error <= (0.0 if name.startswith("sgi_int") or name == "Eb015si"
                             else step + 1e-3), name


@pytest.mark.parametrize("stored, metres", [("mete", 1.0), ("mil", 0.001), ("centim", 0.01),
                                            ("millimeters", 0.001)])
def test_a_truncated_unit_that_names_one_length_unit_is_read_with_a_warning(tmp_path, stored,
                                                                            metres):
    """A field file's POINT:UNITS cut short ('mete' for metres): a unique prefix of one length
    unit's name is that unit, with one warning naming the file and the string stored."""
    xyz = truth_xyz(60, 2)
    path = tmp_path / "t.c3d"
    write_c3d(path, ["racket", "ball"], xyz, units=stored)
    cfg = settings()
    notes: list[str] = []
    (trial,) = read_recording(path, cfg.columns, cfg.units, cfg.markers, warn=notes.append)
    np.testing.assert_allclose(trial.ball[6:], xyz[6:, 1, 2] * metres, rtol=1e-6)
    assert len(notes) == 1 and str(path) in notes[0] and repr(stored) in notes[0], notes


@pytest.mark.parametrize("stored", ["mi", "furlong", "milesx"])
def test_an_ambiguous_or_unknown_unit_is_still_refused(tmp_path, stored):
    """'mi' begins millimetres and micrometres alike: refused, as an unknown string is."""
    path = tmp_path / "u.c3d"
    write_c3d(path, ["racket", "ball"], truth_xyz(60, 2), units=stored)
    cfg = settings()
    with pytest.raises(ConfigError) as info:
        read_recording(path, cfg.columns, cfg.units, cfg.markers)
    message = str(info.value)
    assert "\n" not in message and str(path) in message
    assert f"POINT:UNITS is {stored!r}" in message and "set markers.units" in message


def with_rate(raw: bytes, group: int, name: bytes, value: float) -> bytes:
    """``raw`` with the float parameter ``name`` of group ``group`` set to ``value``."""
    at = record_at(raw, group, name) + 2 + len(name) + 2
    assert raw[at:at + 2] == bytes([4, 0])  # a float scalar: type 4, no dimensions
    return raw[:at + 2] + struct.pack("<f", value) + raw[at + 6:]


@pytest.mark.parametrize("group, value", [("POINT", float("inf")), ("POINT", float("nan")),
                                          ("ANALOG", float("inf")), ("ANALOG", float("nan"))])
def test_a_rate_that_is_not_finite_is_one_line(tmp_path, cli, user_error, group, value):
    """POINT:RATE or ANALOG:RATE inf or NaN (a damaged file): one line naming the parameter,
    exit 2, nothing written (was an OverflowError or ValueError in the reader)."""
    holder = {}

    def edit(writer):
        holder["id"] = group_id(writer, group)

    path = tmp_path / "r.c3d"
    raw = write_c3d(path, ["racket", "ball"], truth_xyz(60, 2), analog=3, edit=edit)
    path.write_bytes(with_rate(raw, holder["id"], b"RATE", value))
    out = tmp_path / "out"
    result = cli("extract", "--data", path, "--out", out, "--set", "markers.racket=racket",
                 "--set", "markers.ball=ball")
    user_error(result, str(path), f"{group}:RATE", "not a finite")
    assert not out.exists()
