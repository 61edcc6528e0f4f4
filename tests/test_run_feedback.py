"""run.json (stable, reproducible, with the --data file's path and SHA-256), timing.json, and
what a long run tells the user: plain progress lines off a terminal, the expected size of a
huge CSV, small work in-process."""

from __future__ import annotations

import hashlib
import json
import os

import pandas as pd
import pytest
from typer.testing import CliRunner

from bounce_cli.runtime import parallel
from bounce_cli.cli.commands import app
from bounce_cli.cli.progress import PlainProgress
from bounce_cli.experiments import basin
from bounce_cli.experiments.base import RunOptions

runner = CliRunner()
SMALL = ["--set", "grid.theta0_deg.num=30", "--set", "grid.v0_m_s.num=20"]


def run(*args):
    return runner.invoke(app, [str(a) for a in args])


def small_basin_config(n_theta=12, n_v=10):
    return basin.BasinConfig.model_validate(
        {"grid": {"theta0_deg": {"start": 0, "stop": 360, "num": n_theta},
                  "v0_m_s": {"start": 0, "stop": 10, "num": n_v}}})


# -- run.json and timing.json -----------------------------------------------------------------
@pytest.mark.slow
def test_rerunning_a_config_rewrites_run_json_byte_for_byte(tmp_path):
    out = tmp_path / "b"
    assert run("basin", *SMALL, "--out", out, "--quiet").exit_code == 0
    first = (out / "run.json").read_bytes()
    first_timing = json.loads((out / "timing.json").read_text())
    assert run("basin", *SMALL, "--out", out, "--quiet").exit_code == 0
    assert (out / "run.json").read_bytes() == first
    manifest = json.loads(first)
    for volatile in ("started", "wall_seconds", "git_commit", "host"):
        assert volatile not in manifest and volatile in first_timing
    assert set(manifest["versions"]) >= {"bounce", "numpy", "scipy", "pandas", "matplotlib",
                                         "pydantic"}
    assert "timing.json" not in manifest["files"]


def test_committed_results_ignore_timing_files():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    ignored = open(os.path.join(root, ".gitignore")).read().split()
    assert "results/*/timing.json" in ignored


def test_data_fit_records_the_file_and_no_seed(tmp_path):
    trials = tmp_path / "trials.csv"
    trials.write_text("a_r_m,tau_s,alpha,g\n0.10,0.50,0.5,9.81\n0.15,0.60,0.5,9.81\n"
                      "0.21,0.70,0.5,9.81\n0.28,0.80,0.5,9.81\n")
    os.chdir(tmp_path)  # a relative --data path, as a user types it
    result = run("regression", "--data", "trials.csv", "--out", tmp_path / "fit", "--quiet")
    assert result.exit_code == 0, result.output
    manifest = json.loads((tmp_path / "fit" / "run.json").read_text())
    assert manifest["data_file"] == {
        "path": str(trials.resolve()),
        "sha256": hashlib.sha256(trials.read_bytes()).hexdigest(),
    }
    assert manifest["seed"] is None


def test_a_simulation_records_its_seed_and_no_data_file(tmp_path):
    result = run("regression", "--out", tmp_path / "sim", "--quiet", "--set", "seed=5",
                 "--set", "design.subjects=2", "--set", "design.trials_per_height=2",
                 "--set", "stochastic_map.duration_s=8")
    assert result.exit_code == 0, result.output
    manifest = json.loads((tmp_path / "sim" / "run.json").read_text())
    assert manifest["seed"] == 5 and "data_file" not in manifest


# -- progress off a terminal ------------------------------------------------------------------
class FakeClock:
    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


def test_plain_progress_prints_a_line_per_interval_and_nothing_for_short_work(capsys):
    clock = FakeClock()
    progress = PlainProgress(interval=10.0, clock=clock)
    progress.start(1000, "basin: classifying")
    for _ in range(9):
        clock.now += 1.0
        progress.advance(10)
    assert capsys.readouterr().err == ""  # 9 s: nothing yet
    clock.now += 1.5
    progress.advance(150)  # 10.5 s, 240 of 1000
    clock.now += 2.0
    progress.advance(10)  # within the interval: no line
    lines = capsys.readouterr().err.splitlines()
    assert lines == ["basin: classifying: 24% (240 of 1,000), 10 s elapsed, about 33 s left"]


def test_off_a_terminal_the_cli_prints_plain_lines_not_a_live_bar(tmp_path, monkeypatch):
    monkeypatch.setattr(PlainProgress, "INTERVAL_S", 0.0)
    result = run("basin", *SMALL, "--out", tmp_path / "b")
    assert result.exit_code == 0, result.output
    lines = [line for line in result.stderr.splitlines() if "classifying" in line]
    assert lines and lines[-1].startswith("basin: classifying: 100% (600 of 600)")
    assert "\x1b" not in result.stderr and "\r" not in result.stderr


# -- huge grids and small work ----------------------------------------------------------------
def test_the_csv_size_estimate_matches_the_committed_basin(tmp_path):
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    csv = os.path.join(root, "results", "basin", "basin.csv")
    rows = len(pd.read_csv(csv))
    assert os.path.getsize(csv) == pytest.approx(rows * basin.CSV_BYTES_PER_ROW, rel=0.05)


def test_a_huge_grid_warns_of_its_csv_size_before_computing(monkeypatch):
    heard, computed = [], []

    class Heard(Exception):
        pass

    def warn(message):
        heard.append(message)
        raise Heard  # stop here: 10^8 points are not computed in a test

    monkeypatch.setattr(basin, "classify_grid", lambda *a, **k: computed.append(1))
    cfg = basin.BasinConfig.model_validate(
        {"grid": {"theta0_deg": {"start": 0, "stop": 360, "num": 10_000},
                  "v0_m_s": {"start": 0, "stop": 10, "num": 10_000}}})
    with pytest.raises(Heard):
        basin.run(cfg, RunOptions(jobs=1, warn=warn))
    assert computed == []  # the warning came first
    assert len(heard) == 1 and "basin.csv will be about 6.7 GB" in heard[0]
    assert "100,000,000 rows" in heard[0] and "grid.v0_m_s.num" in heard[0]
    assert "--set output.format=npz" in heard[0] and "2.7 GB" in heard[0]  # the binary way
    heard.clear()
    monkeypatch.undo()
    basin.run(small_basin_config(), RunOptions(jobs=1, warn=warn))  # small: no warning
    assert heard == []


def test_cli_prints_the_warning_line(tmp_path, monkeypatch):
    monkeypatch.setattr(basin, "CSV_WARN_BYTES", 1000)
    result = run("basin", *SMALL, "--out", tmp_path / "b", "--quiet")
    assert result.exit_code == 0
    assert result.stderr.startswith("bounce: warning: basin.csv will be about 40.2 kB")


class RecordingPool(parallel.LocalPool):
    started = 0

    def __enter__(self):
        RecordingPool.started += 1
        return super().__enter__()


def test_small_grids_run_in_process_large_ones_on_the_pool(monkeypatch):
    """The numpy kernel's worker processes cost a start-up that small grids do not repay."""
    monkeypatch.setenv("BOUNCE_KERNEL", "numpy")
    monkeypatch.setattr(parallel, "LocalPool", RecordingPool)
    assert 400 * 400 < basin.POOL_MIN_POINTS  # the bundled grid runs in-process
    cfg = small_basin_config(30, 20)
    in_process = basin.run(cfg, RunOptions(jobs=2))
    assert RecordingPool.started == 0
    monkeypatch.setattr(basin, "POOL_MIN_POINTS", 100)
    pooled = basin.run(cfg, RunOptions(jobs=2))
    assert RecordingPool.started == 1
    for name in ("basin.csv", "fractions.csv", "markers.csv"):
        pd.testing.assert_frame_equal(pooled.frames[name], in_process.frames[name])


def test_the_compiled_kernel_classifies_large_grids_in_threads(monkeypatch):
    pytest.importorskip("numba")
    monkeypatch.setenv("BOUNCE_KERNEL", "auto")
    from bounce_cli.model import native

    calls = []
    original = native.classify_arrays  # the machine code without numba, or numba's dispatcher
    monkeypatch.setattr(native, "classify_arrays",
                        lambda *args: calls.append(1) or original(*args))
    started = []
    real = parallel.Threads.__enter__
    monkeypatch.setattr(parallel.Threads, "__enter__",
                        lambda self: started.append(self.workers) or real(self))
    monkeypatch.setattr(parallel, "LocalPool", RecordingPool)
    monkeypatch.setattr(RecordingPool, "started", 0)
    cfg = small_basin_config(30, 20)
    small = basin.run(cfg, RunOptions(jobs=2))  # below COMPILED_MIN_POINTS: numpy, in-process
    assert started == [] and calls == [] and RecordingPool.started == 0
    monkeypatch.setattr(basin, "COMPILED_MIN_POINTS", 100)
    threaded = basin.run(cfg, RunOptions(jobs=2))
    assert started == [2] and calls and RecordingPool.started == 0
    for name in ("basin.csv", "fractions.csv", "markers.csv"):
        pd.testing.assert_frame_equal(threaded.frames[name], small.frames[name])
    monkeypatch.setenv("BOUNCE_KERNEL", "numpy")
    numpy_run = basin.run(cfg, RunOptions(jobs=1))
    for name in ("basin.csv", "fractions.csv", "markers.csv"):
        pd.testing.assert_frame_equal(threaded.frames[name], numpy_run.frames[name])


@pytest.mark.slow
def test_rerunning_a_bundled_config_changes_no_committed_byte_of_its_manifest(tmp_path):
    """What keeps `git status` clean after `bounce reproduce` on a clean checkout: rerun over
    the committed results, run.json comes out byte-identical to results/, also where the
    installed packages are newer than the ones that made them (run.json keeps those;
    timing.json, ignored by git, has this run's), and every CSV within the reproduction
    tolerance (its last digits are the machine's libm and CPU: reproduce leaves such a table
    as committed, a plain run rewrites it)."""
    import shutil

    import pandas as pd

    from bounce_cli.reproduction.reproduce import table_drift

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    committed = os.path.join(root, "results", "trajectory")
    shutil.copytree(committed, tmp_path / "trajectory")
    result = run("trajectory", "--out", tmp_path / "trajectory", "--quiet")
    assert result.exit_code == 0, result.output
    for name in sorted(os.listdir(committed)):
        fresh, before = tmp_path / "trajectory" / name, os.path.join(committed, name)
        if name == "run.json":
            with open(before, "rb") as handle:
                assert fresh.read_bytes() == handle.read(), name
        elif name.endswith(".csv"):
            assert not table_drift("trajectory", name, pd.read_csv(fresh), pd.read_csv(before))
