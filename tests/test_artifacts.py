"""Run directories: atomic writes, refusal to overwrite another config's results, run.json."""

import json

import matplotlib.pyplot as plt
import pandas as pd
import pytest

from bounce_cli.artifacts import OutputDirError, RunDirectory, atomic_write


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
