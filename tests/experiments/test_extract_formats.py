"""The vendors' text exports (recordings/text_exports.py) and several racket markers: a
simulated session (``bounce simulate-recording``, 200 Hz, 0.5 mm noise) written in each
vendor's layout (as the vendors document their exports: section and unit lines, mm, the
vendor's way of writing gaps), then ``bounce extract --data`` with the format detected from the
header. The impacts must match the truth as the plain CSV does (RMS theta <= 1 deg, v <= 0.03
m/s: the README's accuracy (b))."""

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from bounce_cli.cli.commands import app
from bounce_cli.runtime.config import ConfigError
from bounce_cli.experiments.extract import ExtractConfig
from bounce_cli.data.recordings import read_recording
from bounce_cli.data.recordings.text_exports import detect_format

runner = CliRunner()
RATE = 200.0
#: three racket markers around the racket's centre (mm): their mean is the centre
RACKET_OFFSETS = (6.0, -4.0, -2.0)


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim") / "sim"
    result = runner.invoke(app, ["simulate-recording", "--out", str(out), "--quiet",
                                 "--set", "trials=1", "--set", "duration_s=12"])
    assert result.exit_code == 0, result.output
    rec = pd.read_csv(out / "recording.csv")
    assert np.allclose(np.diff(rec["t_s"]), 1.0 / RATE) and rec["t_s"].iloc[0] == 0.0
    return rec, out / "truth.csv"


def marker_columns(rec: pd.DataFrame):
    """(name, x, y, up) in mm per marker: three racket markers and the ball, the vertical
    coordinate ``up``, the others constant."""
    racket = rec["racket_x_m"].to_numpy() * 1000.0
    ball = rec["ball_x_m"].to_numpy() * 1000.0
    n = len(rec)
    out = [(f"RF{k + 1}", np.full(n, 100.0 * k), np.full(n, 50.0), racket + off)
           for k, off in enumerate(RACKET_OFFSETS)]
    return out + [("Ball", np.full(n, 10.0), np.full(n, -30.0), ball)]


def cell(v: float) -> str:
    return "" if np.isnan(v) else f"{v:.3f}"


def write_vicon(path, rec, gap_rows=()):
    markers = marker_columns(rec)
    lines = ["Trajectories", f"{RATE:g}",
             ",," + ",".join(f"Sub01:{name},," for name, *_ in markers).rstrip(","),
             "Frame,Sub Frame," + ",".join("X,Y,Z" for _ in markers),
             ",," + ",".join("mm,mm,mm" for _ in markers)]
    for i in range(len(rec)):
        values = []
        for k, (_, x, y, up) in enumerate(markers):
            triple = (x[i], y[i], up[i])
            if k == 0 and i in gap_rows:
                triple = (np.nan,) * 3  # Nexus leaves a gap's cells empty
            values += [cell(v) for v in triple]
        lines.append(f"{i + 1},0," + ",".join(values))
    path.write_text("\n".join(lines) + "\n\n")


def write_qtm(path, rec, gap_rows=()):
    markers = marker_columns(rec)
    names = [name for name, *_ in markers]
    head = [f"NO_OF_FRAMES\t{len(rec)}", "NO_OF_CAMERAS\t8", f"NO_OF_MARKERS\t{len(names)}",
            f"FREQUENCY\t{RATE:g}", "NO_OF_ANALOG\t0", "ANALOG_FREQUENCY\t0",
            "DESCRIPTIONS\t--", "TIME_STAMP\t2024-03-01, 10:15:02.123\t1234.567",
            "DATA_INCLUDED\t3D", "MARKER_NAMES\t" + "\t".join(names),
            "TRAJECTORY_TYPES\t" + "\t".join("Measured" for _ in names),
            "Frame\tTime\t" + "\t".join(f"{n} X\t{n} Y\t{n} Z" for n in names)]
    rows = []
    for i in range(len(rec)):
        values = []
        for k, (_, x, y, up) in enumerate(markers):
            triple = [x[i], y[i], up[i]]
            if k == len(markers) - 1 and i in gap_rows:
                triple = [0.0, 0.0, 0.0]  # QTM writes an unseen marker as zeros
            values += [f"{v:.3f}" for v in triple]
        rows.append(f"{i + 1}\t{i / RATE:.5f}\t" + "\t".join(values))
    path.write_text("\n".join(head + rows) + "\n")


def write_motive(path, rec, gap_rows=()):
    markers = marker_columns(rec)
    n = len(markers)
    lines = [f"Format Version,1.23,Take Name,{path.stem},Take Notes,,Capture Frame Rate,"
             f"{RATE:.6f},Export Frame Rate,{RATE:.6f},Capture Start Time,2024-03-01 10.15.02"
             f".123 AM,Total Frames in Take,{len(rec)},Total Exported Frames,{len(rec)},"
             "Rotation Type,Quaternion,Length Units,Millimeters,Coordinate Space,Global", "",
             ",Type," + ",".join("Marker,Marker,Marker" for _ in range(n)),
             ",Name," + ",".join(f"Racket:{m[0]},Racket:{m[0]},Racket:{m[0]}" if m[0] != "Ball"
                                 else "Ball,Ball,Ball" for m in markers),
             ",ID," + ",".join(f"{k},{k},{k}" for k in range(n)),
             ",Parent," + ",".join(",," for _ in range(n)).replace(",,,", ",,"),
             ",," + ",".join("Position,Position,Position" for _ in range(n)),
             "Frame,Time (Seconds)," + ",".join("X,Y,Z" for _ in range(n))]
    lines[5] = ",Parent," + ",".join([""] * (3 * n))
    for i in range(len(rec)):
        values = []
        for k, (_, x, y, up) in enumerate(markers):
            # Motive is Y-up: the vertical coordinate in the Y column
            triple = (x[i], up[i], y[i])
            if k == len(markers) - 1 and i in gap_rows:
                triple = (np.nan,) * 3
            values += [cell(v) for v in triple]
        lines.append(f"{i},{i / RATE:.6f}," + ",".join(values))
    path.write_text("\n".join(lines) + "\n")


WRITERS = {"vicon": write_vicon, "qtm": write_qtm, "motive": write_motive}


@pytest.mark.slow
@pytest.mark.parametrize("fmt", sorted(WRITERS))
def test_each_export_recovers_the_simulated_truth(session, tmp_path, fmt):
    rec, truth = session
    path = tmp_path / ("1.tsv" if fmt == "qtm" else "1.csv")  # trial label 1, as the truth
    WRITERS[fmt](path, rec)
    assert detect_format(path) == fmt
    out = tmp_path / "ex"
    result = runner.invoke(app, [
        "extract", "--data", str(path), "--out", str(out), "--quiet",
        "--set", f"truth={truth}", "--set", "markers.racket=[RF1, RF2, RF3]",
        "--set", "markers.ball=Ball"])
    assert result.exit_code == 0, result.output
    acc = pd.read_csv(out / "accuracy.csv").set_index("quantity")
    assert acc.loc["theta_deg", "rms_error"] <= 1.0 and acc.loc["v_m_s", "rms_error"] <= 0.03
    assert acc.loc["impacts_found", "max_abs_error"] <= 1


@pytest.mark.parametrize("fmt", sorted(WRITERS))
def test_gaps_as_each_vendor_writes_them(session, tmp_path, fmt):
    rec, _ = session
    rec = rec.iloc[:200]
    path = tmp_path / "take.csv"
    WRITERS[fmt](path, rec, gap_rows=(10, 11))
    cfg = ExtractConfig.model_validate({"markers": {"racket": ["RF1", "RF2", "RF3"],
                                                    "ball": "Ball"}})
    (trial,) = read_recording(path, cfg.columns, cfg.units, cfg.markers)
    np.testing.assert_allclose(trial.t, rec["t_s"], atol=1e-6)
    racket, ball = rec["racket_x_m"].to_numpy(), rec["ball_x_m"].to_numpy()
    gap = np.isin(np.arange(len(rec)), (10, 11))
    got = trial.racket if fmt == "vicon" else trial.ball
    assert np.isnan(got[gap]).all() and not np.isnan(got[~gap]).any()
    # the racket is the mean of its three markers: their offsets cancel (written to 1 um)
    ok = ~np.isnan(trial.racket)
    np.testing.assert_allclose(trial.racket[ok], racket[ok], atol=2e-6)
    ok = ~np.isnan(trial.ball)
    np.testing.assert_allclose(trial.ball[ok], ball[ok], atol=2e-6)


def test_one_racket_marker_alone_is_off_by_its_offset(session, tmp_path):
    rec, _ = session
    path = tmp_path / "take.csv"
    write_vicon(path, rec.iloc[:100])
    cfg = ExtractConfig.model_validate({"markers": {"racket": "RF1", "ball": "Sub01:Ball"}})
    (trial,) = read_recording(path, cfg.columns, cfg.units, cfg.markers)
    np.testing.assert_allclose(trial.racket - rec["racket_x_m"].iloc[:100],
                               RACKET_OFFSETS[0] / 1000.0, atol=2e-6)


@pytest.mark.parametrize("content, needles", [
    ("Trajectories\n200\n,,S:a,,\nFrame,Sub Frame,X,Y,Z\n,,deg,deg,deg\n" + "1,0,1,2,3\n" * 60,
     ("unit of 'S:a' is 'deg'", "set markers.units")),
    ("Trajectories\n200\n,,S:a,,\nFrame,Sub Frame,X,Y,Z\n,,mm,mm,mm\n" + "1,0,1,x,3\n" * 60,
     ("line 6, column 4", "'x'")),
    ("NO_OF_FRAMES\t2\nFREQUENCY\t200\nFrame\tTime\n", ("no MARKER_NAMES",)),
    ("Format Version,1.23,Export Frame Rate,200\n,Name,a,a,a\n,,Position,Position,Position\n"
     "Frame,Time (Seconds),X,Y,Z\n" + "0,0,1,2,3\n" * 60, ("no 'Length Units'",)),
    # issue 36: each of these was a traceback (ValueError, pandas' ParserError)
    ("Format Version,1.23,Export Frame Rate,fast,Length Units,Millimeters\n,Name,a,a,a\n"
     ",,Position,Position,Position\nFrame,Sample,X,Y,Z\n" + "0,0,1,2,3\n" * 60,
     ("Export Frame Rate", "'fast'", "not a number")),
    ("NO_OF_FRAMES\t60\nFREQUENCY\t200\nMARKER_NAMES\t\t\n" + "1\t2\t3\n" * 60,
     ("MARKER_NAMES", "names no marker")),
    ("Trajectories\n200\n,,S:a,,\nFrame,Sub Frame,X,Y,Z\n,,mm,mm,mm\n" + "1,0,1,2,3\n" * 30
     + "31,0,1,2,3,4,5\n" + "1,0,1,2,3\n" * 30, ("line 36", "7 cells", "5 columns")),
    ("NO_OF_FRAMES\t60\nFREQUENCY\t200\nMARKER_NAMES\ta\nFrame\tTime\ta X\ta Y\ta Z\n"
     + "1\t0\t1\t2\t3\n" * 10 + "1\t0\t1\t2\t3\t4\n" + "1\t0\t1\t2\t3\n" * 50,
     ("line 15", "6 cells", "5 columns")),
    ("Format Version,1.23,Export Frame Rate,200,Length Units,Millimeters\n,Name,a,a,a\n"
     ",,Position,Position,Position\nFrame,Time (Seconds),X,Y,Z\n" + "0,0,1,2,3\n" * 20
     + "0,0,1,2,3,,9\n" + "0,0,1,2,3\n" * 40, ("line 25", "7 cells", "5 columns")),
    ("Trajectories\n0\n,,S:a,,\nFrame,Sub Frame,X,Y,Z\n,,mm,mm,mm\n" + "1,0,1,2,3\n" * 60,
     ("frame rate", "0", "not a rate")),
])
def test_bad_exports_are_one_line_errors(tmp_path, content, needles):
    path = tmp_path / "take.csv"
    path.write_text(content)
    cfg = ExtractConfig.model_validate({"markers": {"racket": "a", "ball": None}})
    with pytest.raises(ConfigError) as info:
        read_recording(path, cfg.columns, cfg.units, cfg.markers)
    assert "\n" not in str(info.value) and str(path) in str(info.value)
    for needle in needles:
        assert needle in str(info.value), str(info.value)


def test_a_binary_file_given_as_csv_is_one_line(tmp_path):
    path = tmp_path / "take.csv"
    path.write_bytes(bytes(range(256)) * 8)
    result = runner.invoke(app, ["extract", "--data", str(path), "--out", str(tmp_path / "o")])
    assert result.exit_code == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "binary file" in lines[0] and "codec" not in lines[0]
    latin = tmp_path / "latin.csv"
    latin.write_bytes(b"t_s,racket\xe9\n" + b"0,1\n" * 60)
    result = runner.invoke(app, ["extract", "--data", str(latin), "--out", str(tmp_path / "p")])
    assert result.exit_code == 2 and "codec" not in result.stderr
    assert "not UTF-8 text" in result.stderr and len(result.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("name, head", [
    ("big.csv", "trial,t_s,racket_x_m,ball_x_m\n" + "1,0.0,0.0,0.5\n" * 6000),
    ("big.c3d", "\x02\x50" + "\x00" * 510),
    ("vicon.csv", "Trajectories\n200\n,,S:a,,\nFrame,Sub Frame,X,Y,Z\n,,mm,mm,mm\n"
     + "1,0,1,2,3\n" * 8000),
])
def test_a_recording_larger_than_the_limit_is_refused_before_it_is_read(tmp_path, cli,
                                                                        user_error, name, head):
    """A 3 GiB recording (sparse: no disk) is one line with its size, exit 2, nothing written:
    before, it was read whole (MemoryError, or minutes of parsing)."""
    path = tmp_path / name
    with open(path, "w") as handle:
        handle.write(head)
        handle.truncate(3 * 2**30)
    out = tmp_path / "out"
    user_error(cli("extract", "--data", path, "--out", out), str(path), "3,221,225,472 bytes",
               "2 GB")
    assert not out.exists()


def test_a_device_as_recording_is_one_line(tmp_path, cli, user_error):
    out = tmp_path / "out"
    user_error(cli("extract", "--data", "/dev/zero", "--out", out), "/dev/zero",
               "not a regular file")
    assert not out.exists()


def test_an_export_s_comment_lines_before_the_header_are_skipped(session, tmp_path):
    """"# exported by ..." lines before the header gave pandas' tokenizer error ("Expected 2
    fields in line 3, saw 4") with no hint and no setting to skip them. Lines starting with
    # before the header are skipped: the same impacts as the plain file, and a bad cell's
    line number is the file's. An impacts table with such lines reads too."""
    rec, _ = session
    plain, noted = tmp_path / "plain.csv", tmp_path / "noted.csv"
    rec.to_csv(plain, index=False)
    with open(noted, "w") as handle:
        handle.write("# exported by LabSystem 3.2\n#   subject S07, 2026-01-01\n")
        rec.to_csv(handle, index=False)
    tables = {}
    for path in (plain, noted):
        out = tmp_path / f"out_{path.stem}"
        result = runner.invoke(app, ["extract", "--data", str(path), "--out", str(out),
                                     "--quiet"])
        assert result.exit_code == 0, result.output
        tables[path.stem] = pd.read_csv(out / "impacts.csv")
    pd.testing.assert_frame_equal(tables["plain"], tables["noted"])
    text = noted.read_text().splitlines()
    text[9] = text[9].replace(text[9].split(",")[1], "oops", 1)  # file line 10
    noted.write_text("\n".join(text) + "\n")
    result = runner.invoke(app, ["extract", "--data", str(noted), "--out",
                                 str(tmp_path / "bad")])
    assert result.exit_code == 2 and "row 10" in " ".join(result.output.split()), result.output
    impacts = tmp_path / "impacts.csv"
    with open(impacts, "w") as handle:
        handle.write("# impacts of S07\n")
        tables["plain"].to_csv(handle, index=False)
    from bounce_cli.data.impacts import read_impacts

    assert len(read_impacts(impacts).frame) == len(tables["plain"])


@pytest.mark.parametrize("layout", ["bom", "commented header", "blank between", "bom header"])
def test_comment_lines_with_a_bom_a_commented_header_or_blank_lines(session, tmp_path, layout):
    """A review found three exports the first version misread: a byte-order mark (Excel's
    'CSV UTF-8') before '# ...' lines, the header itself written as a comment
    ('#trial,t_s,...': the first data row became the header), and a blank line between two
    comment lines (the second became the header). Each gives the plain file's impacts."""
    rec, _ = session
    plain = tmp_path / "plain.csv"
    rec.to_csv(plain, index=False)
    body = plain.read_text()
    header, rows = body.split("\n", 1)
    text = {"bom": "\ufeff# exported by LabX 2.1\n" + body,
            "commented header": "# exported by LabX 2.1\n#" + header + "\n" + rows,
            "blank between": "# exported by LabX 2.1\n\n# subject S07\n" + body,
            "bom header": "\ufeff" + body}[layout]
    noted = tmp_path / "noted.csv"
    noted.write_text(text, encoding="utf-8")
    tables = []
    for path in (plain, noted):
        out = tmp_path / f"out_{path.stem}"
        result = runner.invoke(app, ["extract", "--data", str(path), "--out", str(out),
                                     "--quiet"])
        assert result.exit_code == 0, result.output
        tables.append(pd.read_csv(out / "impacts.csv"))
    pd.testing.assert_frame_equal(*tables)
