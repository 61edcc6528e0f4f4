"""The Python API (bounce_cli.api): one code path with the CLI, errors raised (never an
exit), nothing written unless asked, and its docstring examples run as doctests."""

import doctest
import json
import subprocess
import sys
import warnings

import numpy as np
import pandas as pd
import pytest

import bounce_cli
from bounce_cli import api
from bounce_cli.runtime.artifacts import OutputDirError
from bounce_cli.runtime.config import ConfigError
from bounce_cli.model.params import NoFixedPointError

#: a basin small enough to run in a test, off the paper's grid
SMALL_BASIN = {"grid.theta0_deg.num": 9, "grid.v0_m_s.num": 7}
SMALL_BASIN_CLI = [arg for key, value in SMALL_BASIN.items() for arg in ("--set", f"{key}={value}")]


def test_the_docstring_examples_run():
    """Every example in the API's docstrings (the docs site shows them) gives what it says."""
    outcome = doctest.testmod(api, optionflags=doctest.ELLIPSIS, verbose=False)
    assert outcome.attempted >= 15  # the module and each public function have examples
    assert outcome.failed == 0


def test_importing_the_package_imports_no_numerics():
    """``import bounce_cli`` stays light (PEP 562 exports): numpy, pandas and the experiments
    load on first use of bounce_cli.run."""
    code = ("import sys, bounce_cli; heavy = {'numpy', 'pandas', 'bounce_cli.api'} & "
            "set(sys.modules); print(sorted(heavy)); print(bounce_cli.run.__module__)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split()
    assert out == ["[]", "bounce_cli.api"]
    assert set(bounce_cli.__all__) <= set(dir(bounce_cli))
    with pytest.raises(AttributeError, match="no_such_name"):
        bounce_cli.no_such_name  # noqa: B018


@pytest.mark.slow
def test_run_returns_what_the_cli_writes_and_out_writes_the_same_files(cli, tmp_path):
    """The frames in memory are the CSVs the command writes; with out= the API writes the
    command's files (manifest included), through the same run directory."""
    by_cli = tmp_path / "cli"
    result = cli("basin", "--quiet", "--jobs", "1", "--out", by_cli, *SMALL_BASIN_CLI)
    assert result.exit_code == 0, result.output
    in_memory = bounce_cli.run("basin", set=SMALL_BASIN)
    assert in_memory.frames["basin.csv"].shape[0] == 9 * 7
    for name, frame in in_memory.frames.items():
        written = pd.read_csv(by_cli / name)
        assert list(written.columns) == list(frame.columns), name
        for column in frame.columns:
            if pd.api.types.is_numeric_dtype(frame[column]):
                np.testing.assert_allclose(written[column], frame[column], rtol=1e-12,
                                           err_msg=f"{name}:{column}")
            else:
                assert list(written[column].astype(str)) == list(frame[column].astype(str))
    by_api = tmp_path / "api"
    bounce_cli.run("basin", set=[f"{k}={v}" for k, v in SMALL_BASIN.items()], out=by_api)
    names = sorted(p.name for p in by_cli.iterdir())
    assert sorted(p.name for p in by_api.iterdir()) == names
    for name in names:
        if name.endswith(".csv"):
            assert (by_api / name).read_bytes() == (by_cli / name).read_bytes(), name
    manifest_cli, manifest_api = (json.loads((d / "run.json").read_text())
                                  for d in (by_cli, by_api))
    assert manifest_api.keys() == manifest_cli.keys()
    for key in ("command", "config", "overrides", "config_file"):
        if key in manifest_cli:
            assert manifest_api[key] == manifest_cli[key], key
    # the CLI's guard against mixing configs holds for the API too, before any work
    with pytest.raises(OutputDirError):
        bounce_cli.run("basin", set={"grid.v0_m_s.num": 5}, out=by_api)


def test_run_with_out_returns_figures_too(tmp_path):
    """With out= the run directory draws the deferred figures where it writes them; what the
    API returns are still matplotlib Figures (saved again here, as a user would)."""
    from matplotlib.figure import Figure

    result = bounce_cli.run("basin", set=SMALL_BASIN, out=tmp_path / "run")
    assert (tmp_path / "run" / "basin_iterations.png").is_file()
    for name, figure in result.figures.items():
        assert isinstance(figure, Figure), name
        figure.savefig(tmp_path / name)
        assert (tmp_path / name).stat().st_size > 1000


def test_run_writes_nothing_without_out(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = bounce_cli.run("basin", set=SMALL_BASIN)
    assert set(result.figures) == {"basin.png", "basin_iterations.png"}
    from matplotlib.figure import Figure  # drawn, though the run defers them to its writer

    assert all(isinstance(f, Figure) for f in result.figures.values())
    assert result.summary and result.exit_code == 0
    assert list(tmp_path.iterdir()) == []


def test_user_errors_raise_the_cli_message_instead_of_exiting(cli, user_error):
    """A bad key raises ConfigError carrying the one line the CLI prints (not SystemExit)."""
    with pytest.raises(ConfigError) as raised:
        bounce_cli.run("basin", set={"grid.no_such_key": 1})
    result = cli("basin", "--quiet", "--set", "grid.no_such_key=1")
    user_error(result, "grid.no_such_key")
    assert result.stderr.strip() == f"bounce: error: {raised.value}"
    with pytest.raises(ConfigError, match="no experiment named 'basn'.*basin"):
        bounce_cli.run("basn")
    with pytest.raises(ConfigError, match="takes no data file"):
        bounce_cli.run("basin", data="impacts.csv")
    with pytest.raises(ConfigError, match="set: a mapping"):
        bounce_cli.run("basin", set="grid.v0_m_s.num=3")
    with pytest.raises(NoFixedPointError, match="model.racket_amplitude"):
        bounce_cli.run("basin", set={**SMALL_BASIN, "model.racket_amplitude": 0.01})


@pytest.mark.slow
def test_an_unstable_fixed_point_is_a_python_warning_with_the_cli_text(cli, tmp_path):
    unstable = {**SMALL_BASIN, "model.racket_period": 0.5}
    with pytest.warns(UserWarning, match="linearly unstable at these parameters") as caught:
        bounce_cli.run("basin", set=unstable)
    result = cli("basin", "--quiet", "--jobs", "1", "--out", tmp_path, *SMALL_BASIN_CLI,
                 "--set", "model.racket_period=0.5")
    assert result.exit_code == 0, result.output
    assert [line for line in result.stderr.splitlines() if line.startswith("bounce: ")] == [
        f"bounce: warning: {caught[0].message}"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the stable bundled parameters warn of nothing
        bounce_cli.run("basin", set=SMALL_BASIN)


def test_extract_reads_a_path_like_a_frame_and_needs_a_ball(tmp_path):
    session = bounce_cli.run("simulate-recording", set={"trials": 2, "duration_s": 6.0})
    recording = session.frames["recording.csv"]
    path = tmp_path / "recording.csv"
    recording.to_csv(path, index=False)
    read = bounce_cli.read_recording(path)
    pd.testing.assert_frame_equal(read[["t_s", "racket_x_m", "ball_x_m"]],
                                  recording[["t_s", "racket_x_m", "ball_x_m"]], rtol=1e-12)
    from_path, from_frame = bounce_cli.extract(path), bounce_cli.extract(recording)
    pd.testing.assert_frame_equal(from_path.drop(columns="trial"),
                                  from_frame.drop(columns="trial"))
    assert from_frame["trial"].nunique() == 2
    # each trial's impacts within 5 ms and 0.01 m/s of the simulated truth
    truth = session.frames["truth.csv"]
    for label, found in from_frame.groupby("trial"):
        true = truth[truth["trial"] == label]
        both = pd.merge_asof(found, true, on="t_s", tolerance=0.005, direction="nearest",
                             suffixes=("", "_true"))
        assert both["v_m_s_true"].notna().all() and len(both) >= len(true) - 1
        assert (both["v_m_s"] - both["v_m_s_true"]).abs().max() < 0.01
    with pytest.raises(ConfigError, match="no ball column"):
        bounce_cli.extract(recording.assign(ball_x_m=np.nan))
    with pytest.raises(ConfigError, match="no column 'racket_x_m'"):
        bounce_cli.extract(recording.drop(columns="racket_x_m"))
    with pytest.raises(ConfigError, match="extraction.acc_degree"):
        bounce_cli.extract(recording, extraction={"acc_degree": 1})
