"""`bounce basin` (Fig. 4) through the CLI at a reduced resolution."""

import math

import numpy as np
import pandas as pd
import pytest

import bounce_cli
from bounce_cli.experiments import basin

SMALL = ["--set", "grid.theta0_deg.num=40", "--set", "grid.v0_m_s.num=40"]


def cell_codes(image) -> np.ndarray:
    """The outcome codes (``basin.EXACT_OUTCOMES``) of basin.png's cells, drawn as RGBA bytes
    in ``basin.OUTCOME_COLOURS`` (each colour one outcome's)."""
    from matplotlib.colors import to_rgba

    colours = np.array([np.round(np.array(to_rgba(basin.OUTCOME_COLOURS[o])) * 255)
                        for o in basin.EXACT_OUTCOMES])
    match = (np.asarray(image)[..., None, :] == colours).all(axis=-1)
    assert (match.sum(axis=-1) == 1).all(), "a cell of no outcome's colour"
    return match.argmax(axis=-1)


@pytest.mark.slow
def test_basin_cli_small_grid_jobs_independent(tmp_path, paper_params, cli):
    out1, out2 = tmp_path / "j1", tmp_path / "j2"
    r1 = cli("basin", *SMALL, "--jobs", 1, "--out", out1, "--quiet")
    r2 = cli("basin", *SMALL, "--jobs", 2, "--out", out2, "--quiet")
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


@pytest.mark.slow
def test_basin_figures_redraw_from_csv(tmp_path, cli):
    out = tmp_path / "b"
    assert cli("basin", *SMALL, "--jobs", 1, "--out", out, "--quiet").exit_code == 0
    frames = {name: pd.read_csv(out / name) for name in ("basin.csv", "markers.csv")}
    figures = basin.draw(frames)
    assert set(figures) == {"basin.png", "basin_iterations.png"}
    image = figures["basin.png"].axes[0].images[0].get_array()
    df = frames["basin.csv"].sort_values(["v0_m_s", "theta0_deg"])
    codes = df.outcome.map({o: i for i, o in enumerate(basin.OUTCOMES)}).to_numpy()
    np.testing.assert_array_equal(cell_codes(image), codes.reshape(40, 40))
    ax = figures["basin.png"].axes[0]
    assert "deg" in ax.get_xlabel() and "m/s" in ax.get_ylabel() and "Fig. 4" in ax.get_title()
    labels = [t.get_text() for t in figures["basin.png"].legends[0].get_texts()]
    assert any("undecided" in t for t in labels) and any("Fig. 3" in t for t in labels)
    colour_bar = figures["basin_iterations.png"].axes[1]  # the cells' scale
    assert colour_bar.get_ylim()[1] == df.iterations.max()


def test_basin_grid_limit_and_bad_grid_are_one_line_errors(tmp_path, cli):
    for args, needle in [
        (["--set", "limits.max_points=1000"], "limits.max_points"),
        (["--set", "grid.v0_m_s.num=0"], "grid.v0_m_s.num"),
        (["--set", "grid.theta0_deg.stop=-1"], "grid.theta0_deg"),
        (["--set", "classify.tolerance=0"], "classify.tolerance"),
    ]:
        result = cli("basin", *args, "--out", tmp_path / "x", "--quiet")
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
    # every 3rd v0, 4th theta0 (the cells drawn as RGBA bytes)
    assert small.axes[0].images[0].get_array().shape == (7, 8, 4)


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


@pytest.mark.slow
def test_one_value_axes_run_and_draw(tmp_path, paper_params, cli):
    """num: 1 is linspace's one value: a basin along a line of v0 at the Fig. 3 phase, along
    a line of theta0, and at one initial condition; each agrees with the classifier run
    directly on those points, and its figures hold one row / column / cell."""
    from bounce_cli.analysis.classify import classify_batch

    theta0 = math.degrees(math.asin(0.205 / 0.30))
    cases = {
        "line_v0": (["--set", f"grid.theta0_deg.start={theta0!r}", "--set", "grid.theta0_deg.num=1",
                     "--set", "grid.v0_m_s.start=4", "--set", "grid.v0_m_s.stop=6",
                     "--set", "grid.v0_m_s.num=21"], (21, 1)),
        "line_theta0": (["--set", "grid.theta0_deg.num=30", "--set", "grid.v0_m_s.start=4.8",
                         "--set", "grid.v0_m_s.num=1"], (1, 30)),
        "point": (["--set", f"grid.theta0_deg.start={theta0!r}", "--set", "grid.theta0_deg.num=1",
                   "--set", "grid.v0_m_s.start=5.7", "--set", "grid.v0_m_s.num=1"], (1, 1)),
    }
    for name, (args, shape) in cases.items():
        out = tmp_path / name
        result = cli("basin", *args, "--out", out, "--quiet", "--jobs", 1)
        assert result.exit_code == 0, result.output
        df = pd.read_csv(out / "basin.csv")
        assert len(df) == shape[0] * shape[1]
        direct = classify_batch(df.theta0_rad, df.v0_m_s, paper_params)
        assert list(df.outcome) == list(direct.names())
        figures = basin.draw({n: pd.read_csv(out / n) for n in ("basin.csv", "markers.csv")})
        for fig in figures.values():
            image = np.asarray(fig.axes[0].images[0].get_array())
            assert image.shape == (*shape, 4)  # RGBA bytes
            x0, x1, y0, y1 = fig.axes[0].images[0].get_extent()
            assert x1 > x0 and y1 > y0  # a one-value axis still has a width
    point = pd.read_csv(tmp_path / "point" / "basin.csv")
    assert list(point.outcome) == ["sticking"]  # Fig. 3's bottom panel


@pytest.mark.slow
def test_paper_statements_only_at_the_papers_parameters(tmp_path, cli):
    small = [*SMALL, "--jobs", 1]
    at_paper = cli("basin", *small, "--out", tmp_path / "p")
    assert "paper: no point reached 100" in at_paper.stderr
    assert "Fig. 3 initial conditions" in at_paper.stderr
    other = cli("basin", *small, "--set", "model.alpha=0.6", "--out", tmp_path / "o")
    assert other.exit_code == 0, other.output
    assert "paper:" not in other.stderr and "Fig. 3" not in other.stderr
    markers = pd.read_csv(tmp_path / "o" / "markers.csv")
    assert list(markers.marker) == ["fixed_point"]
    png = basin.draw({n: pd.read_csv(tmp_path / "o" / n) for n in ("basin.csv", "markers.csv")})
    labels = png["basin.png"].legends[0].get_texts()
    assert not any("Fig. 3" in t.get_text() for t in labels)


@pytest.mark.slow
def test_binary_tables_hold_what_the_csv_holds_and_redraw(tmp_path, cli, user_error,
                                                          monkeypatch):
    """output.format npz / parquet: basin.npz / basin.parquet instead of basin.csv, the same
    rows and values read back (artifacts.read_frame), and the figures redraw from them."""
    from bounce_cli.runtime import artifacts

    small = ["--set", "grid.theta0_deg.num=30", "--set", "grid.v0_m_s.num=20", "--quiet"]
    assert cli("basin", *small, "--out", tmp_path / "csv").exit_code == 0
    reference = pd.read_csv(tmp_path / "csv" / "basin.csv")
    for fmt in ("npz", "parquet"):
        out = tmp_path / fmt
        result = cli("basin", *small, "--set", f"output.format={fmt}", "--out", out)
        assert result.exit_code == 0, result.output
        assert not (out / "basin.csv").exists() and (out / f"basin.{fmt}").is_file()
        frames = artifacts.read_frames(out)
        assert set(frames) == {f"basin.{fmt}", "fractions.csv", "markers.csv"}
        table = frames[f"basin.{fmt}"]
        assert list(table.columns) == list(reference.columns)
        for column in reference.columns:
            np.testing.assert_array_equal(np.asarray(table[column]),
                                          reference[column].to_numpy(), err_msg=column)
        assert set(basin.draw(frames)) == {"basin.png", "basin_iterations.png"}
    npz_bytes = (tmp_path / "npz" / "basin.npz").stat().st_size
    assert npz_bytes < 30 * 600 + 2000  # NPZ_BYTES_PER_ROW (27) a row, plus the headers
    # without pyarrow: one line naming the key and the way out, before any computing
    import importlib.util
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None)
    result = cli("basin", *small, "--set", "output.format=parquet", "--out", tmp_path / "p2")
    user_error(result, "output.format", "pyarrow", "npz")
    assert not (tmp_path / "p2").exists()


def test_canonical_axes_found_without_sorting_or_refused():
    theta, v = np.meshgrid([0.0, 90.0, 180.0], [1.0, 2.0])
    th, vs = basin._canonical_axes(theta.ravel(), v.ravel())
    np.testing.assert_array_equal(th, [0.0, 90.0, 180.0])
    np.testing.assert_array_equal(vs, [1.0, 2.0])
    for t, w in (([5.0], [1.0]), ([5.0, 5.0], [1.0, 2.0]), ([1.0, 2.0], [3.0, 3.0])):
        found = basin._canonical_axes(np.array(t), np.array(w))  # 1 x 1, N x 1, 1 x N
        assert found is not None
    assert basin._canonical_axes(theta.ravel()[::-1], v.ravel()[::-1]) is None  # decreasing
    assert basin._canonical_axes(np.array([0.0, 1.0, 0.0]), np.array([1.0, 1.0, 2.0])) is None


def test_exact_sticking_without_a_locked_orbit_leaves_its_period_empty(tmp_path):
    # Gamma <= 1: a ball that sticks rides the racket for ever (resting), no orbit locks;
    # period_cycles was 0 in every row and the legend said "period 0 racket cycles"
    result = bounce_cli.run("basin", out=tmp_path / "r", set={
        "grid.theta0_deg.num": 6, "grid.v0_m_s.num": 5, "classify.min_hop_s": 0,
        "model.racket_amplitude": 0.15, "model.alpha": 0.9})
    fractions = pd.read_csv(tmp_path / "r" / "fractions.csv")
    assert fractions.set_index("outcome").loc["resting", "count"] > 0
    assert fractions.period_cycles.isna().all()
    redrawn = basin.draw({name: pd.read_csv(tmp_path / "r" / name)
                          for name in ("basin.csv", "markers.csv", "fractions.csv")})
    for figures in (redrawn, result.figures):
        texts = [t.get_text() for t in figures["basin.png"].legends[0].get_texts()]
        assert not any("period 0" in t for t in texts), texts


@pytest.mark.slow
def test_exact_sticking_basin_separates_locked_orbits_with_their_period(tmp_path, cli):
    """classify.min_hop_s=0: the grey of Fig. 4 becomes the locked sticking solution (period
    1 racket cycle at the paper's model), drawn and labelled with its period; redrawn from
    the CSVs alone."""
    out = tmp_path / "exact"
    result = cli("basin", *SMALL, "--set", "classify.min_hop_s=0", "--jobs", 1, "--out", out,
                 "--quiet")
    assert result.exit_code == 0, result.output
    fractions = pd.read_csv(out / "fractions.csv")
    assert list(fractions.outcome) == list(basin.EXACT_OUTCOMES)
    locked = fractions.set_index("outcome").loc["locked"]
    assert locked["count"] > 0 and locked.period_cycles == 1
    # the other outcomes have no period: empty cells, not 0
    assert fractions.drop(columns="count").set_index("outcome").drop(
        index="locked").period_cycles.isna().all()
    assert fractions.set_index("outcome").loc["sticking", "count"] == 0
    frames = {name: pd.read_csv(out / name) for name in ("basin.csv", "markers.csv",
                                                          "fractions.csv")}
    assert frames["markers.csv"].set_index("marker").loc["fig3_sticking", "outcome"] == "locked"
    figures = basin.draw(frames)
    image = cell_codes(figures["basin.png"].axes[0].images[0].get_array())
    assert (image == basin.EXACT_OUTCOMES.index("locked")).sum() == locked["count"]
    labels = [t.get_text() for t in figures["basin.png"].legends[0].get_texts()]
    assert any("locked" in t and "period 1 racket cycle" in t for t in labels)
    for fig in figures.values():  # both figures say which rule they were made with
        assert "exact sticking" in fig.axes[0].get_title()


@pytest.mark.slow
@pytest.mark.parametrize("kernel", ["numpy", "auto"])
def test_controlled_basin_cli_jobs_2_is_jobs_1(tmp_path, cli, monkeypatch, kernel):
    """``bounce basin`` with racket period control on two worker processes (numpy kernel) or
    two threads of the compiled kernel (auto, where numba is installed): the same basin.csv
    as one process, byte for byte."""
    monkeypatch.setenv("BOUNCE_KERNEL", kernel)
    control = ["--set", "model.control.gain=0.6", "--set", "model.control.rate=0.9"]
    out1, out2 = tmp_path / "j1", tmp_path / "j2"
    r1 = cli("basin", *SMALL, *control, "--jobs", 1, "--out", out1, "--quiet")
    monkeypatch.setattr(basin, "POOL_MIN_POINTS", 100)
    monkeypatch.setattr(basin, "COMPILED_MIN_POINTS", 100)
    r2 = cli("basin", *SMALL, *control, "--jobs", 2, "--out", out2, "--quiet")
    assert r1.exit_code == 0 and r2.exit_code == 0, r1.output + r2.output
    for name in ("basin.csv", "fractions.csv", "markers.csv"):
        assert (out1 / name).read_bytes() == (out2 / name).read_bytes(), name
    fractions = pd.read_csv(out1 / "fractions.csv").set_index("outcome")["count"]
    assert fractions["period1"] > 0 and fractions["sticking"] > 0


def test_figures_colour_each_cell_by_its_outcome_and_impact_count():
    """The cells are drawn as RGBA bytes: each outcome in its colour (white, grey, black as
    in the paper), and the impact counts on viridis over their range with the cells below
    the racket transparent (the axes' black shows), as the colour bar says."""
    from matplotlib import colormaps
    from matplotlib.colors import to_rgba

    th, v = np.meshgrid(np.linspace(0, 360, 6), np.linspace(0, 10, 5))
    codes = np.array(["below_racket", "sticking", "period1", "period1", "sticking"])
    outcome = codes[np.arange(5)][:, None].repeat(6, axis=1)
    iterations = np.where(outcome == "below_racket", 0, np.arange(30).reshape(5, 6) + 2)
    df = pd.DataFrame({"theta0_rad": np.deg2rad(th.ravel()), "theta0_deg": th.ravel(),
                       "v0_m_s": v.ravel(), "outcome": outcome.ravel(),
                       "iterations": iterations.ravel()})
    markers = pd.DataFrame({"marker": ["fixed_point"], "theta0_deg": [42.8], "v0_m_s": [4.5],
                            "outcome": ["period1"], "iterations": [1]})
    figures = basin.draw({"basin.csv": df, "markers.csv": markers})
    cells = figures["basin.png"].axes[0].images[0].get_array()
    for row, name in enumerate(codes):
        expected = np.round(np.array(to_rgba(basin.OUTCOME_COLOURS[name])) * 255)
        np.testing.assert_array_equal(cells[row], np.tile(expected, (6, 1)))
    shaded = figures["basin_iterations.png"].axes[0].images[0].get_array()
    assert (shaded[0, :, 3] == 0).all()  # below the racket: transparent
    counts = iterations[1:].astype(float)
    scaled = (counts - counts.min()) / (counts.max() - counts.min())
    np.testing.assert_array_equal(shaded[1:], colormaps["viridis"](scaled, bytes=True))
    colour_bar = figures["basin_iterations.png"].axes[1]
    assert colour_bar.get_ylim() == (counts.min(), counts.max())
    # one count everywhere (every flight sticks at its first impact): imshow's middle colour
    df["iterations"] = np.where(df["outcome"] == "below_racket", 0, 1)
    shaded = basin.draw({"basin.csv": df, "markers.csv": markers})[
        "basin_iterations.png"].axes[0].images[0].get_array()
    np.testing.assert_array_equal(shaded[1:], np.broadcast_to(
        colormaps["viridis"](0.5, bytes=True), shaded[1:].shape))
    # and the colour bar says that one count, no fractions (a 1 x 1 grid had -0.1 ... 0.1);
    # nothing counted (every start below the racket): the bar says 0
    for everywhere, only, expected in ((1, "period1", 1.0), (0, "below_racket", 0.0)):
        one = df.assign(iterations=everywhere, outcome=only)
        fig = basin.draw({"basin.csv": one, "markers.csv": markers})["basin_iterations.png"]
        fig.canvas.draw()
        bar = fig.axes[1]
        assert bar.get_ylim() == (expected - 0.5, expected + 0.5)
        ticks = [t for t in bar.get_yticks() if bar.get_ylim()[0] <= t <= bar.get_ylim()[1]]
        assert ticks == [expected]


def test_an_unstable_fixed_point_is_said_and_reached_by_no_start(tmp_path, cli):
    """At alpha 0.7, a_r 0.3 m the fixed point exists but is unstable (spectral radius 2.07):
    no start is period-1 (the tree before counted starts that passed within the tolerance of
    it, and the fixed point itself), markers.csv records the radius, the summary says why,
    and basin.png's title says so, also when redrawn from the tables."""
    result = cli("basin", *SMALL, "--jobs", 1, "--set", "model.alpha=0.7",
                 "--out", tmp_path / "u")
    assert result.exit_code == 0, result.output
    assert "no start is period-1: the fixed point is unstable (spectral radius 2.07" \
        in result.stderr
    fractions = pd.read_csv(tmp_path / "u" / "fractions.csv").set_index("outcome")
    assert fractions.loc["period1", "count"] == 0
    markers = pd.read_csv(tmp_path / "u" / "markers.csv")
    assert markers.outcome[0] != "period1"
    assert markers.spectral_radius[0] == pytest.approx(2.0716, abs=1e-4)
    figures = basin.draw({n: pd.read_csv(tmp_path / "u" / n)
                          for n in ("basin.csv", "markers.csv")})
    title = figures["basin.png"].axes[0].get_title()
    assert "no period-1 attractor" in title and "2.07" in title
    # at the paper's model the fixed point is stable: Fig. 4's title and period-1 starts
    stable = cli("basin", *SMALL, "--jobs", 1, "--out", tmp_path / "s")
    assert stable.exit_code == 0 and "no start is period-1" not in stable.stderr
    markers = pd.read_csv(tmp_path / "s" / "markers.csv")
    assert markers.outcome[0] == "period1" and markers.spectral_radius[0] < 1.0
    assert basin.unstable_radius(markers) is None
    assert pd.read_csv(tmp_path / "s" / "fractions.csv").set_index(
        "outcome").loc["period1", "count"] > 0
