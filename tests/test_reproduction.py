"""CI regression of the reproduced figures: every bundled config is re-run and its CSVs
compared with the baseline committed in ``results/``; every figure is redrawn from the
committed CSVs alone; ``bounce verify`` passes on the baseline and fails on drifted data.

The tolerance is the one ``bounce reproduce`` uses
(``bounce_cli.reproduction.reproduce.table_drift``; stated there): rtol 1e-6 / atol 1e-9 for
floats, categorical columns exact but for the few stated exceptions, and the tables filled by
chaotic orbits compared by what reproduces of them (``bounce_cli.reproduction.chaotic_tables``;
``tests/test_chaotic_tables.py``).
"""

import io
import json
import shutil
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

from bounce_cli.cli.commands import app
from bounce_cli.runtime.config import bundled_config_path, load_config
from bounce_cli.experiments.base import RunOptions
from bounce_cli.experiments.registry import entry, reproduced
from bounce_cli.reproduction.reproduce import table_drift
from bounce_cli.runtime.artifacts import RunTables

EXPERIMENT_NAMES = [e.name for e in reproduced()]
#: re-runs too slow for the default suite (15-120 s each on a loaded 2-core machine): run
#: with -m slow (CI does)
SLOW_RERUNS = {"bifurcation", "control", "acf-data"}
SLOW_REDRAWS = {"control"}


def experiment_params(slow: set[str]) -> list:
    return [pytest.param(n, marks=pytest.mark.slow) if n in slow else n
            for n in EXPERIMENT_NAMES]

RESULTS = Path(__file__).resolve().parent.parent / "results"


def committed_frames(name: str) -> dict[str, pd.DataFrame]:
    return {p.name: pd.read_csv(p) for p in sorted((RESULTS / name).glob("*.csv"))}


@pytest.mark.parametrize("name", experiment_params(SLOW_RERUNS))
def test_bundled_config_reproduces_committed_results(name):
    experiment = entry(name).load()
    config = load_config(experiment.schema, bundled_config_path(entry(name).config))
    manifest = json.loads((RESULTS / name / "run.json").read_text())
    assert manifest["config"] == config.model_dump(mode="json"), (
        f"results/{name} was made from another config: rerun `bounce reproduce`")
    result = experiment.run(config, RunOptions(jobs=1))
    committed = committed_frames(name)
    assert sorted(result.frames) == sorted(committed)
    fresh = {csv_name: pd.read_csv(io.StringIO(frame.to_csv(index=False)))  # the CSV round trip
             for csv_name, frame in result.frames.items()}
    both_runs = RunTables(fresh, committed, manifest["config"])
    for csv_name in fresh:
        drift = table_drift(name, csv_name, fresh[csv_name], committed[csv_name], both_runs)
        assert not drift, "\n".join(drift)
    assert sorted(result.figures) == sorted(png for png, _ in entry(name).figures)


@pytest.mark.slow
@pytest.mark.parametrize("name", experiment_params(SLOW_REDRAWS))
def test_every_figure_redraws_from_its_csvs_alone(name, tmp_path):
    figures = entry(name).load().draw(committed_frames(name))
    assert sorted(figures) == sorted(p.name for p in (RESULTS / name).glob("*.png"))
    for png, figure in figures.items():
        out = tmp_path / png
        figure.savefig(out, format="png", dpi=60)
        assert out.stat().st_size > 5_000  # something was drawn
        labels = [ax.get_xlabel() for ax in figure.axes if ax.get_xlabel()]
        assert labels, f"{png}: no labelled axis"


runner = CliRunner()


def test_verify_passes_on_the_committed_baseline():
    result = runner.invoke(app, ["verify", "--results", str(RESULTS)])
    assert result.exit_code == 0, result.output
    assert "reproduced" in result.stdout


def test_verify_fails_on_drifted_or_missing_results(tmp_path):
    copy = tmp_path / "results"
    shutil.copytree(RESULTS, copy, ignore=shutil.ignore_patterns("basin.csv", "*.png"))
    # the basin grid is missing: that claim is 'missing' and verify fails
    result = runner.invoke(app, ["verify", "--results", str(copy)])
    assert result.exit_code == 1 and "basin_no_100" in result.stderr
    shutil.copy(RESULTS / "basin" / "basin.csv", copy / "basin" / "basin.csv")
    assert runner.invoke(app, ["verify", "--results", str(copy)]).exit_code == 0
    # a drifted theoretical SD is no longer the documented discrepancy: verify fails
    summary = pd.read_csv(copy / "acf" / "summary.csv")
    summary.loc[(summary.quantity == "sd_v") & (summary.source == "theory_eq19"), "ours"] = 0.09
    summary.to_csv(copy / "acf" / "summary.csv", index=False)
    result = runner.invoke(app, ["verify", "--results", str(copy)])
    assert result.exit_code == 1 and "sd_v" in result.stderr


def test_reproduce_gallery_lists_every_figure_and_flags_missing_ones(tmp_path):
    from bounce_cli.reproduction.claims import markdown_table, verify
    from bounce_cli.reproduction.reproduce import gallery_markdown

    copy = tmp_path / "results"
    shutil.copytree(RESULTS, copy, ignore=shutil.ignore_patterns("*.csv", "basin.png"))
    text = gallery_markdown(copy, markdown_table(verify(copy)))
    for e in reproduced():
        for png, caption in e.figures:
            if png == "basin.png":
                assert f"*(missing: {e.name}/{png})*" in text
            else:
                assert f"![{png}]({e.name}/{png})" in text and caption in text
    assert "| claim | paper | ours | tolerance | status |" in text
    assert text == gallery_markdown(copy, markdown_table(verify(copy)))
    # the committed gallery is what reproduce writes for the committed results
    assert (RESULTS / "README.md").read_text() == gallery_markdown(
        RESULTS, markdown_table(verify(RESULTS)))


@pytest.mark.slow
def test_verify_refuses_results_made_from_another_config(tmp_path):
    copy = tmp_path / "results"
    shutil.copytree(RESULTS, copy, ignore=shutil.ignore_patterns("*.png"))
    small = runner.invoke(app, ["basin", "--set", "grid.theta0_deg.num=12", "--set",
                                "grid.v0_m_s.num=12", "--out", str(copy / "basin"), "--force",
                                "--quiet", "--jobs", "1"])
    assert small.exit_code == 0, small.output
    result = runner.invoke(app, ["verify", "--results", str(copy)])
    assert result.exit_code == 1
    assert "basin_no_100" in result.stderr and "fig3_initial_conditions" in result.stderr
    assert "other config" in result.stdout


@pytest.mark.slow
def test_registry_is_the_one_list_the_cli_and_experiments_follow():
    from bounce_cli.runtime.config import ExperimentConfig
    from bounce_cli.experiments.registry import EXPERIMENTS

    commands = {c.name for c in app.registered_commands}
    for e in EXPERIMENTS:
        assert e.name in commands
        experiment = e.load()
        assert experiment.name == e.name
        assert issubclass(experiment.schema, ExperimentConfig)
        assert callable(experiment.run) and callable(experiment.draw)
        assert bundled_config_path(e.config).is_file()
        if e.data_help is not None:
            assert "data" in experiment.schema.model_fields
        help_text = runner.invoke(app, [e.name, "--help"]).stdout
        assert ("--data" in help_text) == (e.data_help is not None)


def _reproduce_trajectory(results: Path, *extra: str):
    result = runner.invoke(app, ["reproduce", "trajectory", "--out", str(results), *extra])
    assert result.exit_code == 0, result.output
    return result.stdout


@pytest.mark.slow
def test_reproduce_leaves_tables_within_tolerance_as_committed_and_rewrites_changed_ones(
        tmp_path):
    """Another CPU or BLAS build moves the last digits (seen: 2e-7 relative): reproduce then
    leaves the committed table, its figures, run.json and the gallery as they are (a clean
    git status); a table beyond the tolerance is rewritten and its figures redrawn."""
    results = tmp_path / "results"
    shutil.copytree(RESULTS / "trajectory", results / "trajectory")
    folder = results / "trajectory"
    _reproduce_trajectory(results)  # the gallery of this partial copy, once
    csv, png = folder / "impacts.csv", folder / "trajectory.png"
    table = pd.read_csv(csv)
    table["v_m_s"] *= 1.0 + 3e-8  # last digits, as another machine writes them
    table.to_csv(csv, index=False)
    png.write_bytes(b"not redrawn")
    before = {p.name: p.read_bytes() for p in results.rglob("*") if p.is_file()
              and p.name != "timing.json"}
    out = _reproduce_trajectory(results)
    assert "trajectory: within tolerance (left as committed): impacts.csv" in out
    after = {p.name: p.read_bytes() for p in results.rglob("*") if p.is_file()
             and p.name != "timing.json"}
    assert after == before  # the table, the figure, run.json and README.md untouched

    table["v_m_s"] *= 1.0 + 1e-5  # beyond rtol 1e-6: a real change
    table.to_csv(csv, index=False)
    changed = csv.read_bytes()
    out = _reproduce_trajectory(results)
    assert "trajectory: changed: impacts.csv, trajectory.png" in out
    assert csv.read_bytes() != changed
    assert not table_drift("trajectory", "impacts.csv", pd.read_csv(csv),
                           pd.read_csv(RESULTS / "trajectory" / "impacts.csv"))
    assert png.read_bytes().startswith(b"\x89PNG")  # redrawn
    # what this machine wrote is identical now (the tables still as committed may differ from
    # this machine's in their last digits: another libm)
    status = next(line for line in _reproduce_trajectory(results).splitlines()
                  if line.startswith("trajectory: "))
    assert "changed" not in status and "impacts.csv" not in status, status

    png.write_bytes(b"not redrawn")  # --force-regen redraws what agrees
    out = _reproduce_trajectory(results, "--force-regen")
    assert png.read_bytes().startswith(b"\x89PNG") and "trajectory.png" in out


def test_table_drift_names_the_column_and_respects_the_stated_exceptions():
    committed = pd.DataFrame({"x": [1.0, 2.0, 3.0], "state": ["flight", "stuck", "flight"]})
    assert table_drift("e", "t.csv", committed.assign(x=committed.x * (1 + 5e-7)),
                       committed) == []
    drift = table_drift("e", "t.csv", committed.assign(x=[1.0, 2.0, 3.00001]), committed)
    assert len(drift) == 1 and "e/t.csv column x: 1 of 3" in drift[0]
    assert table_drift("e", "t.csv", committed.assign(state=["flight"] * 3), committed)
    assert "columns" in table_drift("e", "t.csv", committed[["x"]], committed)[0]
    grid = pd.DataFrame({"outcome": ["period-1"] * 20_000})
    flipped = grid.copy()
    flipped.loc[0, "outcome"] = "sticking"  # 1 in 2 10^4: a point on a basin boundary
    assert table_drift("basin", "basin.csv", flipped, grid) == []
    assert table_drift("other", "basin.csv", flipped, grid)


def test_a_run_keeps_the_files_that_agree_within_the_reproduction_tolerance(tmp_path):
    """RunDirectory.commit with reproduce's rule: a table within tolerance of the previous
    one is not rewritten, nor are the figures (unless missing) or run.json; a table beyond it
    is rewritten and the figures redrawn."""
    import matplotlib.pyplot as plt

    from bounce_cli.runtime.artifacts import RunDirectory
    from bounce_cli.reproduction.reproduce import tables_agree

    out = tmp_path / "demo"
    reproduce_rule = tables_agree("demo")

    def commit(x, agrees=reproduce_rule):
        run = RunDirectory(out, command="demo", resolved_config={"a": 1}, overrides=[],
                           config_path=None)
        run.add_csv("data.csv", pd.DataFrame({"x_m": x}))
        figure, ax = plt.subplots()
        ax.plot(x)
        run.add_figure("fig.png", figure)
        run.commit(agrees)
        plt.close(figure)
        return run.comparison

    x = [1.0, 2.0, 1.0 / 3.0]
    assert commit(x) == {"data.csv": "new", "fig.png": "new"}
    files = {p.name: p.read_bytes() for p in out.iterdir() if p.name != "timing.json"}
    assert commit([v * (1 + 3e-8) for v in x]) == {"data.csv": "within tolerance",
                                                   "fig.png": "kept"}
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.name != "timing.json"} == files
    assert commit(x) == {"data.csv": "identical", "fig.png": "kept"}
    (out / "fig.png").unlink()  # a missing figure is drawn
    assert commit(x)["fig.png"] == "new"
    changed = commit([v * (1 + 1e-5) for v in x])
    assert changed["data.csv"] == "changed" and changed["fig.png"] != "kept"
    assert pd.read_csv(out / "data.csv").x_m.iloc[0] == pytest.approx(1.0 + 1e-5, rel=1e-12)
    assert commit(x, agrees=None)["fig.png"] != "kept"  # --force-regen: all rewritten


def test_a_run_that_changed_rewrites_its_tables_within_tolerance_too(tmp_path):
    """One table beyond the tolerance, another within it: both are rewritten (the folder
    holds the tables of one run, as the rules that read one table beside another assume),
    and reproduce says which were rewritten along."""
    from bounce_cli.reproduction.reproduce import experiment_status, tables_agree
    from bounce_cli.runtime.artifacts import RunDirectory

    out = tmp_path / "demo"

    def commit(x, y):
        run = RunDirectory(out, command="demo", resolved_config={"a": 1}, overrides=[],
                           config_path=None)
        run.add_csv("data.csv", pd.DataFrame({"x_m": x}))
        run.add_csv("other.csv", pd.DataFrame({"y_m": y}))
        run.commit(tables_agree("demo"))
        return run.comparison

    commit([1.0, 2.0], [1.0 / 3.0])
    assert commit([1.0, 2.0], [1.0 / 3.0 * (1 + 3e-8)]) == {
        "data.csv": "identical", "other.csv": "within tolerance"}
    comparison = commit([1.0, 2.00001], [1.0 / 3.0 * (1 + 3e-8)])
    assert comparison == {"data.csv": "changed", "other.csv": "rewritten"}
    assert pd.read_csv(out / "other.csv").y_m.iloc[0] == 1.0 / 3.0 * (1 + 3e-8)
    assert experiment_status(comparison) == (
        "changed: data.csv (rewritten with them, within tolerance: other.csv)")
    # into a folder of no earlier run every file is new, and said so (it read "changed")
    assert experiment_status({"data.csv": "new", "a.png": "new"}) == (
        "new (no earlier results there): a.png, data.csv")
    assert experiment_status({"data.csv": "changed", "a.png": "new", "b.csv": "identical"}
                             ) == "changed: data.csv; new: a.png"


def test_reproduce_refuses_an_unknown_experiment_before_running_any(cli, user_error, tmp_path):
    result = cli("reproduce", "trajectory", "trajectry", "--out", tmp_path / "r")
    user_error(result, "reproduce trajectry", "no such reproduced experiment", "trajectory")
    assert not (tmp_path / "r").exists()


def test_an_adaptive_table_is_compared_by_the_branches_it_traces():
    """Continuation's branches.csv: one step more on a branch (another BLAS kernel's last bit
    in a corrector) is the same result; a branch more or of another period is not."""
    import pandas as pd

    from bounce_cli.reproduction.reproduce import table_drift

    committed = pd.read_csv(RESULTS / "continuation" / "branches.csv")
    extra = pd.concat([committed, committed.iloc[[3]]], ignore_index=True)
    assert table_drift("continuation", "branches.csv", extra, committed) == []
    other = committed.assign(period=committed["period"].where(committed["branch"] != 0, 3))
    assert table_drift("continuation", "branches.csv", other, committed)
    # elsewhere a row more is a drift
    assert table_drift("continuation", "bifurcations.csv", extra, committed)


def test_the_crosscheck_fit_at_the_rounding_floor_is_compared_within_its_stated_precision():
    """stability's crosscheck fits a deviation's decay down to the rounding floor: where it
    first drops below the floor, and so the fitted rate, moves with the last bits (an emulated
    Nehalem gave 319 impacts and rate 0.934924 where the committed table has 318 and
    0.934882, so `bounce reproduce` rewrote crosscheck.csv and git status was dirty). Moving
    g by a few ulps shows the same; such rows agree within their stated precision, eq. 10's
    and the Jacobian's radius keep the full tolerance (CROSSCHECK_ESTIMATES)."""
    from bounce_cli.experiments.base import NullProgress
    from bounce_cli.experiments.stability import (CrosscheckBlock, CrosscheckPoint,
                                                  crosscheck_frame)
    from bounce_cli.reproduction.reproduce import RTOL

    block = CrosscheckBlock(points=[CrosscheckPoint(alpha=0.8, ac_g=-1.006, racket_period=0.6)])
    committed = crosscheck_frame(block, 9.81, NullProgress())
    moved = [crosscheck_frame(block, 9.81 * (1.0 + ulps * 2.2e-16), NullProgress())
             for ulps in (-6, -3, -1, 1, 3, 6)]
    for fresh in moved:
        assert table_drift("stability", "crosscheck.csv", fresh, committed) == []
    # the Nehalem's row: beyond rtol 1e-6 in the fit's columns only, and accepted
    nehalem = committed.assign(impacts_fitted=committed.impacts_fitted + 1,
                               radius_empirical=committed.radius_empirical * (1 + 4.5e-5))
    assert abs(nehalem.radius_empirical / committed.radius_empirical - 1).max() > 10 * RTOL
    assert table_drift("stability", "crosscheck.csv", nehalem, committed) == []
    assert table_drift("other", "crosscheck.csv", nehalem, committed)  # the full tolerance
    off = committed.assign(radius_fd_jacobian=committed.radius_fd_jacobian * (1 + 1e-5))
    assert table_drift("stability", "crosscheck.csv", off, committed)


def test_reproduce_runs_experiments_side_by_side_and_reports_them_in_order(tmp_path):
    """--jobs 2: two lanes (runtime.forked.ForkedLanes) take the experiments, and each
    experiment's lines (its header, summary, files written, status) come in the registry's
    order, whichever lane finished first. An experiment that fails is reported in its turn
    with its one line, and the run stops with its status."""
    results = tmp_path / "results"
    order = ["trajectory", "learning"]  # the registry's order
    result = runner.invoke(app, ["reproduce", *reversed(order), "--jobs", "2",
                                 "--out", str(results)])
    assert result.exit_code == 0, result.output
    assert [line.split(":")[0] for line in result.stdout.splitlines()
            if line.split(":")[0] in order] == order
    said = result.stderr
    assert [line for line in said.splitlines() if line.startswith("bounce ")] == [
        f"bounce {name}" for name in order]
    assert said.index("bounce trajectory") < said.index(f"to {results}/trajectory/") \
        < said.index("bounce learning") < said.index(f"to {results}/learning/")
    assert (results / "README.md").is_file()

    shutil.rmtree(results / "learning")
    (results / "learning").write_text("in the way")  # learning cannot be written
    result = runner.invoke(app, ["reproduce", *order, "--jobs", "2", "--out", str(results)])
    assert result.exit_code == 2
    assert "bounce: error: --out" in result.stderr and "learning" in result.stderr
    assert [line.split(":")[0] for line in result.stdout.splitlines()] == ["trajectory"]


def test_reproduce_needs_no_click_package(tmp_path, monkeypatch):
    """typer >= 0.20 vendors click: a fresh `pip install .` has no `click` package, and
    reproduce's `import click` ended every run with a traceback (the test extra's Dask
    brings click along, so the suite had not seen it)."""
    import sys

    monkeypatch.setitem(sys.modules, "click", None)  # `import click` raises ImportError
    result = runner.invoke(app, ["reproduce", "trajectory", "--jobs", "1",
                                 "--out", str(tmp_path / "r")])
    assert result.exit_code == 0, result.output
    assert "trajectory: new" in result.stdout
