"""`bounce basin` (Fig. 4) through the CLI at a reduced resolution."""

import math

import numpy as np
import pandas as pd
from typer.testing import CliRunner

from bounce_cli.cli import app
from bounce_cli.experiments import basin

runner = CliRunner()
SMALL = ["--set", "grid.theta0_deg.num=40", "--set", "grid.v0_m_s.num=40"]


def run(*args):
    return runner.invoke(app, [str(a) for a in args])


def test_basin_cli_small_grid_jobs_independent(tmp_path, paper_params):
    out1, out2 = tmp_path / "j1", tmp_path / "j2"
    r1 = run("basin", *SMALL, "--jobs", 1, "--out", out1, "--quiet")
    r2 = run("basin", *SMALL, "--jobs", 2, "--out", out2, "--quiet")
    assert r1.exit_code == 0, r1.output
    assert r2.exit_code == 0, r2.output
    assert (out1 / "basin.csv").read_bytes() == (out2 / "basin.csv").read_bytes()
    for name in ("basin.csv", "fractions.csv", "markers.csv", "basin.png",
                 "basin_iterations.png", "run.json"):
        assert (out1 / name).is_file()

    df = pd.read_csv(out1 / "basin.csv")
    assert list(df.columns) == ["theta0_rad", "theta0_deg", "v0_m_s", "outcome", "iterations"]
    assert len(df) == 1600
    np.testing.assert_allclose(df.theta0_rad, np.deg2rad(df.theta0_deg))
    assert sorted(df.theta0_deg.unique()) == list(np.linspace(0, 360, 40))
    assert sorted(df.v0_m_s.unique()) == list(np.linspace(0, 10, 40))
    assert set(df.outcome) <= set(basin.OUTCOMES)

    fr = pd.read_csv(out1 / "fractions.csv")
    assert list(fr.outcome) == list(basin.OUTCOMES)
    assert fr["count"].sum() == 1600 and math.isclose(fr.fraction.sum(), 1.0)
    counts = dict(zip(fr.outcome, fr["count"]))
    assert counts == df.outcome.value_counts().reindex(basin.OUTCOMES, fill_value=0).to_dict()
    # independent route to the black region: v0 not above the racket velocity
    below = (df.v0_m_s <= paper_params.racket_velocity(df.theta0_rad)).sum()
    assert counts["below_racket"] == below
    # regression: fractions of this 40 x 40 grid as first computed (commit "bounce basin")
    assert counts == {"period1": 518, "sticking": 966, "below_racket": 116, "undecided": 0}

    markers = pd.read_csv(out1 / "markers.csv").set_index("marker")
    assert markers.loc["fig3_period1", "outcome"] == "period1"
    assert markers.loc["fig3_sticking", "outcome"] == "sticking"
    assert markers.loc["fixed_point", "outcome"] == "period1"
    assert math.isclose(markers.loc["fixed_point", "v0_m_s"], paper_params.fixed_point().v_m_s)


def test_basin_figures_redraw_from_csv(tmp_path):
    out = tmp_path / "b"
    assert run("basin", *SMALL, "--jobs", 1, "--out", out, "--quiet").exit_code == 0
    frames = {name: pd.read_csv(out / name) for name in ("basin.csv", "markers.csv")}
    figures = basin.draw(frames)
    assert set(figures) == {"basin.png", "basin_iterations.png"}
    image = figures["basin.png"].axes[0].images[0].get_array()
    df = frames["basin.csv"].sort_values(["v0_m_s", "theta0_deg"])
    codes = df.outcome.map({o: i for i, o in enumerate(basin.OUTCOMES)}).to_numpy()
    np.testing.assert_array_equal(np.asarray(image), codes.reshape(40, 40))
    ax = figures["basin.png"].axes[0]
    assert "deg" in ax.get_xlabel() and "m/s" in ax.get_ylabel() and "Fig. 4" in ax.get_title()
    labels = [t.get_text() for t in figures["basin.png"].legends[0].get_texts()]
    assert any("undecided" in t for t in labels) and any("Fig. 3" in t for t in labels)
    iters = figures["basin_iterations.png"].axes[0].images[0].get_array()
    assert iters.max() == df.iterations.max()


def test_basin_grid_limit_and_bad_grid_are_one_line_errors(tmp_path):
    for args, needle in [
        (["--set", "limits.max_points=1000"], "limits.max_points"),
        (["--set", "grid.v0_m_s.num=1"], "grid.v0_m_s.num"),
        (["--set", "grid.theta0_deg.stop=-1"], "grid.theta0_deg"),
        (["--set", "classify.tolerance=0"], "classify.tolerance"),
    ]:
        result = run("basin", *args, "--out", tmp_path / "x", "--quiet")
        assert result.exit_code == 2, result.output
        lines = [line for line in result.stderr.splitlines() if line.strip()]
        assert len(lines) == 1 and needle in lines[0], result.stderr
        assert "Traceback" not in result.output


def test_draw_accepts_rows_in_any_order_and_subsamples_large_grids(monkeypatch):
    th, v = np.meshgrid(np.linspace(0, 360, 30), np.linspace(0, 10, 20))
    outcome = np.where(v > 5, "period1", "sticking").astype(object)
    outcome[v < 1] = "below_racket"
    df = pd.DataFrame({"theta0_rad": np.deg2rad(th.ravel()), "theta0_deg": th.ravel(),
                       "v0_m_s": v.ravel(), "outcome": outcome.ravel(),
                       "iterations": (v * 3).astype(int).ravel()})
    markers = pd.DataFrame({"marker": ["fixed_point"], "theta0_deg": [42.8], "v0_m_s": [4.5],
                            "outcome": ["period1"], "iterations": [1]})
    ordered = basin.draw({"basin.csv": df, "markers.csv": markers})
    shuffled = basin.draw({"basin.csv": df.sample(frac=1, random_state=1),
                           "markers.csv": markers})
    for name in ordered:
        np.testing.assert_array_equal(ordered[name].axes[0].images[0].get_array(),
                                      shuffled[name].axes[0].images[0].get_array())
    monkeypatch.setattr(basin, "MAX_IMAGE_CELLS", 8)
    small = basin.draw({"basin.csv": df, "markers.csv": markers})["basin.png"]
    assert small.axes[0].images[0].get_array().shape == (7, 8)  # every 3rd v0, 4th theta0


def test_run_reports_progress_per_tile_and_summary():
    from bounce_cli.experiments.base import RunOptions

    class Recorder:
        def __init__(self):
            self.total, self.done = None, []

        def start(self, total, description):
            self.total = total

        def advance(self, n=1):
            self.done.append(n)

    cfg = basin.BasinConfig.model_validate(
        {"grid": {"theta0_deg": {"start": 0, "stop": 360, "num": 12},
                  "v0_m_s": {"start": 0, "stop": 10, "num": 10}}}
    )
    progress = Recorder()
    result = basin.run(cfg, RunOptions(jobs=1, progress=progress))
    assert progress.total == 120 and sum(progress.done) == 120
    assert len(result.frames["basin.csv"]) == 120
    assert any("max impacts" in line for line in result.summary)
