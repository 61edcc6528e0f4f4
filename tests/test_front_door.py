"""One front door (issue 34): every way of running an experiment goes through
``experiments.runner.execute`` — ``bounce_cli.run``, each ``bounce <name>``, ``bounce
reproduce`` and each unit of ``bounce study`` (its extraction and its analyses, the unit's
impacts held in memory: no temporary file).

The calls are seen as they happen (a profile hook on ``execute``'s code object), whatever
name a caller imported it under: nothing is replaced.
"""

from __future__ import annotations

import subprocess
import sys
from contextlib import contextmanager
from pathlib import Path

import pytest
from typer.testing import CliRunner

import bounce_cli
from bounce_cli.cli.commands import app
from bounce_cli.experiments import runner


@contextmanager
def executions():
    """The experiments ``execute`` ran while the block ran (their names, in order), with
    whether each was given impacts in memory."""
    seen: list[tuple[str, bool]] = []
    code = runner.execute.__code__
    previous = sys.getprofile()

    def hook(frame, event, arg):
        if event == "call" and frame.f_code is code:
            entry = frame.f_locals["entry"]
            seen.append((entry if isinstance(entry, str) else entry.name,
                         frame.f_locals["impacts"] is not None))

    sys.setprofile(hook)
    try:
        yield seen
    finally:
        sys.setprofile(previous)


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


def test_the_python_api_runs_through_execute():
    with executions() as seen:
        result = bounce_cli.run("basin", set={"grid.theta0_deg.num": 4, "grid.v0_m_s.num": 3})
    assert seen == [("basin", False)]
    assert len(result.frames["basin.csv"]) == 12


def test_a_command_runs_through_execute_and_writes_what_the_api_writes(tmp_path):
    small = ["grid.theta0_deg.num=4", "grid.v0_m_s.num=3"]
    with executions() as seen:
        result = invoke("basin", "--quiet", "--jobs", "1", "--out", tmp_path / "cli",
                        *[x for s in small for x in ("--set", s)])
    assert result.exit_code == 0, result.output
    assert seen == [("basin", False)]
    bounce_cli.run("basin", set=small, out=tmp_path / "api")
    assert ((tmp_path / "cli" / "basin.csv").read_bytes()
            == (tmp_path / "api" / "basin.csv").read_bytes())


def test_print_config_loads_without_running():
    with executions() as seen:
        result = invoke("basin", "--print-config")
    assert result.exit_code == 0 and "grid:" in result.output
    assert seen == []


def test_reproduce_runs_each_experiment_through_execute(tmp_path):
    with executions() as seen:
        result = invoke("reproduce", "trajectory", "--quiet", "--jobs", "1", "--out", tmp_path)
    assert result.exit_code == 0, result.output
    assert seen == [("trajectory", False)]
    assert (tmp_path / "trajectory").is_dir() and (tmp_path / "README.md").is_file()


def test_the_study_runs_its_units_extraction_and_analyses_through_execute(tmp_path):
    sim = tmp_path / "sim"
    made = invoke("simulate-study", "--quiet", "--out", sim, "--set", "subjects.count=1",
                  "--set", "conditions=[{name: a}]", "--set", "trials=3",
                  "--set", "duration_s=10", "--set", "perturbations.every=5",
                  "--set", "perturbations.alphas=[0.4, 0.6]")
    assert made.exit_code == 0, made.output
    with executions() as seen:
        result = invoke("study", "--manifest", sim / "study.csv", "--out", tmp_path / "study",
                        "--jobs", "1", "--quiet", "--figures", "none",
                        "--set", "analyses=[regression, control]",
                        "--set", "model.alpha=0.5", "--set", "model.g=9.81")
    assert result.exit_code in (0, 1), result.output
    assert seen[0] == ("study", False)
    assert seen[1:4] == [("extract", False)] * 3  # one per recording
    assert seen[4:] == [("regression", True), ("control", True)]  # the unit's table in memory
    summary = (tmp_path / "study" / "summary.txt")
    if summary.is_file():  # the study's control names the unit, not a temporary file
        assert "/tmp" not in summary.read_text()


def test_a_validated_config_is_neither_overridden_nor_written():
    _, _, cfg = runner.load_run_config(runner.find_entry("basin"), None, [])
    with pytest.raises(ValueError):
        runner.execute("basin", cfg, ["grid.v0_m_s.num=3"], write=False)
    with pytest.raises(ValueError):
        runner.execute("basin", cfg)


def test_the_command_line_imports_no_numpy_until_a_command_runs():
    """``bounce --help`` and the app's import stay light: typer and rich, the registry, the
    standard library (issue 34: ``cli/`` imports no numpy at module level)."""
    code = ("import sys; import bounce_cli.cli.commands; "
            "print(sorted(m for m in ('numpy', 'pandas', 'scipy', 'matplotlib', 'pydantic') "
            "if m in sys.modules))")
    shown = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                           check=True)
    assert shown.stdout.strip() == "[]"


def test_a_suggested_command_names_the_run_directory_as_a_shell_takes_it(tmp_path):
    import re
    import shlex

    out = tmp_path / "sessions of 'today'"  # a space and quotes: the path must be quoted
    made = invoke("simulate-study", "--out", out, "--set", "subjects.count=1",
                  "--set", "conditions=[{name: a}]", "--set", "trials=1",
                  "--set", "duration_s=5")
    assert made.exit_code == 0, made.output
    suggested = re.search(r"run `(bounce study [^`]+)`", made.stderr)
    assert suggested is not None, made.stderr
    words = shlex.split(suggested.group(1))
    assert words[:3] == ["bounce", "study", "--manifest"]
    assert Path(words[3]) == out / "study.csv" and Path(words[3]).is_file()
    # the study beside the session, so that the next session's study does not collide
    assert words[4:] == ["--out", f"{out}-study"]
    assert "<out>" not in made.stderr
    # run without a directory (the API without out): the placeholder is left as it is
    unwritten = bounce_cli.run("simulate-study", set={"subjects.count": 1, "trials": 1,
                                                      "duration_s": 5,
                                                      "conditions": [{"name": "a"}]})
    assert "--manifest <out>/study.csv" in unwritten.summary[0]
