"""``bounce attractors``: the tables, the figures, section 3's classes of the same result."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import bounce_cli

SMALL = {"grid.theta0_deg.num": 60, "grid.v0_m_s.num": 60, "recurrence.transient": 500,
         "recurrence.window": 128, "recurrence.max_period": 32, "recurrence.sample": 200,
         "measures.samples": 300, "continuation.num": 3, "continuation.start": 1.45,
         "continuation.stop": 1.6, "continuation.grid.theta0_deg.num": 30,
         "continuation.grid.v0_m_s.num": 30}


@pytest.mark.slow
def test_section_3_s_classes_are_the_attractors_seen_coarser(tmp_path):
    quick = {**SMALL, "grid.theta0_deg.num": 40, "grid.v0_m_s.num": 40, "continuation.num": 0,
             "measures.samples": 100}
    result = bounce_cli.run("attractors", set=quick)
    basin = result.frames["basin.csv"]
    today = bounce_cli.run("basin", set={"grid.theta0_deg.num": 40, "grid.v0_m_s.num": 40}
                           ).frames["basin.csv"]
    assert np.array_equal(basin["paper_class"].to_numpy(), today["outcome"].to_numpy())
    table = result.frames["attractors.csv"]
    assert list(table["name"]) == ["period-1"] and table["basin_fraction"].iloc[0] == \
        pytest.approx(float(np.mean(today["outcome"] == "period1")))
    assert "continuation.csv" not in result.frames and "attractors.png" in result.figures


@pytest.mark.slow
def test_attractors_writes_every_table_and_section_3_s_classes_agree(tmp_path):
    out = tmp_path / "a"
    result = bounce_cli.run("attractors", set=SMALL, out=out)
    for name in ("attractors.csv", "attractor_points.csv", "fractions.csv", "basin.csv",
                 "measures.csv", "uncertainty.csv", "continuation.csv", "attractors.png",
                 "attractors_continuation.png"):
        assert (out / name).is_file(), name
    fractions = pd.read_csv(out / "fractions.csv")
    assert fractions["fraction"].sum() == pytest.approx(1.0)
    basin = pd.read_csv(out / "basin.csv")
    today = bounce_cli.run("basin", set={"grid.theta0_deg.num": 60, "grid.v0_m_s.num": 60}
                           ).frames["basin.csv"]
    assert np.array_equal(basin["paper_class"].to_numpy(), today["outcome"].to_numpy())
    measures = pd.read_csv(out / "measures.csv").set_index("quantity")["value"]
    assert measures["undecided_fraction"] == 0.0
    assert 0.0 < measures["basin_entropy"] < measures["boundary_basin_entropy"] < 1.1
    continued = pd.read_csv(out / "continuation.csv")
    for _, at in continued.groupby("gamma"):
        assert at["fraction"].sum() == pytest.approx(1.0)
    # past eq. 14's flip (Gamma 1.5268) the period-1 orbit's basin has gone to period 2
    late = continued[continued["gamma"] == continued["gamma"].max()]
    assert "period-1" not in set(late["name"]) and "period-2" in set(late["name"])
    # every start accounted for in the summary, nothing undecided
    assert result.summary[0].startswith("1 attractor in 3,600 starts: period-1 ")
    assert "undecided" not in result.summary[0]
    # each figure's caption names its own grid: the continuation's is not the main one
    from bounce_cli.runtime.figure_files import drawn, figure_caption

    assert "60 x 60 starts" in figure_caption(drawn(result.figures["attractors.png"]))
    continued = figure_caption(drawn(result.figures["attractors_continuation.png"]))
    assert continued.endswith("gamma from 1.45 to 1.6 (3 values, a_r = gamma g / w_r^2); "
                              "30 x 30 starts at each value")


def test_summary_accounts_for_every_start():
    from bounce_cli.analysis.attractors import BELOW_RACKET, STICKING, UNDECIDED
    from bounce_cli.experiments.attractors import summary_lines

    class Found:
        def __init__(self, index, name):
            self.index, self.name = index, name

    shares = {0: (30, 0.3), 1: (10, 0.1), STICKING: (50, 0.5), BELOW_RACKET: (6, 0.06),
              UNDECIDED: (4, 0.04)}
    lines = summary_lines([Found(0, "period-1"), Found(1, "period-2")], shares, 100, 7)
    assert lines[0] == ("2 attractors in 100 starts: period-1 30.0%, period-2 10.0%; "
                        "sticking 50.0%, below racket 6.0%, undecided 4.0%")
    assert lines[1].startswith("second discovery: 7 starts")
    none = summary_lines([], {STICKING: (100, 1.0), UNDECIDED: (0, 0.0)}, 100, 0)
    assert none[0] == "no attractor in 100 starts: sticking 100.0%"
    one = summary_lines([Found(0, "period-1")], {0: (100, 1.0)}, 100, 0)
    assert one[0] == "1 attractor in 100 starts: period-1 100.0%"


def test_a_grid_above_max_points_is_one_line(cli, user_error, tmp_path):
    user_error(cli("attractors", "--set", "grid.theta0_deg.num=3000", "--set",
                   "grid.v0_m_s.num=3000", "--out", tmp_path / "x"),
               "--set: grid.theta0_deg.num x grid.v0_m_s.num = 3000 x 3000")
    assert not (tmp_path / "x").exists()
    # the continuation's grid at all its values too (it ran for hours before)
    user_error(cli("attractors", "--set", "continuation.grid.v0_m_s.num=3000",
                   "--out", tmp_path / "x"), "17 x 90 x 3000 = 4,590,000 starts")
    assert not (tmp_path / "x").exists()


def test_the_continuation_does_not_depend_on_its_workers():
    # its values run as tasks on --jobs workers; the branches are matched in the values'
    # order afterwards: one table whatever the workers
    from bounce_cli.experiments import runner
    from bounce_cli.experiments.attractors import continue_fractions
    from bounce_cli.experiments.base import RunOptions

    tiny = {**SMALL, "recurrence.sample": 40, "continuation.num": 4,
            "continuation.start": 1.45, "continuation.stop": 1.65,
            "continuation.grid.theta0_deg.num": 12, "continuation.grid.v0_m_s.num": 12}
    _, _, config = runner.load_run_config(runner.find_entry("attractors"), None,
                                          [f"{k}={v}" for k, v in tiny.items()])
    one = continue_fractions(config, RunOptions(jobs=1))
    two = continue_fractions(config, RunOptions(jobs=2))
    pd.testing.assert_frame_equal(one, two)
    # across eq. 14's flip (Gamma 1.5268) the period-1 branch hands over to period 2
    assert {"period-1", "period-2"} <= set(one["name"])
    assert one.groupby("gamma")["fraction"].sum().to_numpy() == pytest.approx(1.0)


def test_the_continuation_figure_s_caption_names_its_own_grid_and_parameter():
    # it named the main grid's size and the main a_r, which the continuation over gamma
    # changes at every value (the run's wiring: the slow test above)
    from bounce_cli.experiments import runner
    from bounce_cli.experiments.attractors import continuation_caption

    def caption(*sets):
        _, _, config = runner.load_run_config(runner.find_entry("attractors"), None,
                                              list(sets))
        return continuation_caption(config)

    assert caption("continuation.start=1.45", "continuation.stop=1.6", "continuation.num=3",
                   "continuation.grid.theta0_deg.num=30", "continuation.grid.v0_m_s.num=20") \
        == ("alpha = 0.5, g = 9.81 m/s^2, tau = 0.92 s; gamma from 1.45 to 1.6 "
            "(3 values, a_r = gamma g / w_r^2); 30 x 20 starts at each value")
    assert caption("continuation.parameter=racket_period", "continuation.num=1",
                   "continuation.start=0.9", "model.alpha=0.7") == (
        "alpha = 0.7, g = 9.81 m/s^2, a_r = 0.3 m; racket_period = 0.9; "
        "90 x 90 starts at each value")
    assert "tau = 0.92 s; racket_amplitude from" in caption(
        "continuation.parameter=racket_amplitude", "continuation.start=0.2",
        "continuation.stop=0.4")


@pytest.mark.parametrize("parameter", ["gamma", "racket_amplitude", "racket_period",
                                       "alpha"])
def test_the_continuation_figure_is_laid_out_for_every_parameter(parameter,
                                                                 figure_layout_problems):
    # its one-line title was wider than the axes beside the legend: cut at the left edge and
    # under the legend (a reviewer, at the bundled parameters)
    from bounce_cli.experiments.attractors import _draw_continuation

    from bounce_cli.analysis.bifurcation import parameter_column

    values = np.linspace(0.4, 0.6, 3)
    table = pd.DataFrame({parameter_column(parameter): np.repeat(values, 3),
                          "label": [0, 1, -1] * 3,
                          "name": ["period-1", "period-2", "sticking"] * 3,
                          "branch": [0, 1, -1] * 3, "fraction": [0.5, 0.3, 0.2] * 3})
    fig = _draw_continuation(table, None)
    assert figure_layout_problems(fig) == []


def test_orbits_above_the_cells_are_found():
    # alpha 0.9: a chaotic attractor up to about 40 m/s; with the cells up to 12 m/s 83 % of
    # the starts were undecided without a word, and measures.csv reported basin entropies of
    # the undecided; with the range widened the attractor is found
    from bounce_cli.analysis.attractors import AttractorFinder, RecurrenceSettings
    from bounce_cli.model.params import ModelParams

    params = ModelParams(alpha=0.9, g=9.81, racket_amplitude=0.3, racket_period=0.92)
    theta, v = np.meshgrid(np.linspace(0.0, 2.0 * np.pi, 5), np.linspace(1.0, 9.0, 4))
    small = dict(transient=200, window=64, max_period=16, recurrence=30,
                 recurrence_impacts=3000, max_impacts=100)
    narrow = AttractorFinder(params, RecurrenceSettings(v_range=(0.0, 12.0), **small))
    narrow.discover(theta, v)
    assert narrow.beyond_cells() is not None and narrow.beyond_cells() > 15.0
    wide = AttractorFinder(params, RecurrenceSettings(v_range=(0.0, 80.0), transient=200,
                                                      window=64, max_period=16))
    wide.discover(theta, v)
    assert wide.beyond_cells() is None
    assert "chaotic" in {a.kind for a in wide.attractors}


@pytest.mark.slow
def test_the_command_warns_of_orbits_above_the_cells_and_flags_undecided_measures():
    with pytest.warns(UserWarning, match=r"above recurrence.v_range_m_s \[0, 12\]"):
        result = bounce_cli.run("attractors", set={
            **SMALL, "model.alpha": 0.9, "grid.theta0_deg.num": 6, "grid.v0_m_s.num": 6,
            "recurrence.sample": 12, "recurrence.recurrence_impacts": 2000,
            "measures.box": 2, "measures.samples": 10, "continuation.num": 0})
    measures = result.frames["measures.csv"].set_index("quantity")
    if measures.loc["undecided_fraction", "value"] > 0.05:
        assert "undecided, which these measures count as one outcome" in \
            measures.loc["basin_entropy", "note"]


def test_the_warning_of_orbits_above_the_cells_comes_before_the_long_labelling(monkeypatch):
    """Where the sample's orbits already leave the cells, the user is told before the grid
    is labelled (which then takes minutes), once."""
    from bounce_cli.analysis.attractors import AttractorFinder
    from bounce_cli.experiments import attractors as experiment
    from bounce_cli.experiments.base import RunOptions

    said: list[str] = []
    label = AttractorFinder.label
    monkeypatch.setattr(AttractorFinder, "label",
                        lambda self, *a, **k: said.append("labelling") or label(self, *a, **k))
    config = experiment.AttractorsConfig.model_validate({
        "model": {"alpha": 0.9}, "grid": {"theta0_deg": {"start": 0, "stop": 360, "num": 6},
                                          "v0_m_s": {"start": 0, "stop": 10, "num": 6}},
        "recurrence": {"sample": 12, "recurrence_impacts": 2000, "transient": 200,
                       "window": 64, "max_period": 16},
        "measures": {"box": 2, "samples": 10}, "continuation": {"num": 0}})
    result = experiment.run(config, RunOptions(warn=said.append))
    assert "above recurrence.v_range_m_s" in said[0] and said[1] == "labelling"
    assert sum("above recurrence" in s for s in said) == 1
    # the summary's second discovery counts the grid's starts, not the measures' own
    second = int(result.summary[1].split(":")[1].split()[0].replace(",", ""))
    assert 0 < second <= 36


def test_the_long_passes_report_progress_to_their_totals():
    """The labelling and the following of the undecided starts each start a progress bar
    and advance it to its total (alpha 0.9: minutes of work otherwise silent)."""
    from bounce_cli.experiments import attractors as experiment
    from bounce_cli.experiments.base import RunOptions

    class Recorder:
        def __init__(self):
            self.phases: list[list] = []

        def start(self, total, description):
            self.phases.append([description, total, 0])

        def advance(self, n=1):
            self.phases[-1][2] += n

    config = experiment.AttractorsConfig.model_validate({
        "model": {"alpha": 0.9}, "grid": {"theta0_deg": {"start": 0, "stop": 360, "num": 8},
                                          "v0_m_s": {"start": 0, "stop": 10, "num": 8}},
        "recurrence": {"sample": 12, "recurrence_impacts": 2000, "transient": 200,
                       "window": 64, "max_period": 16, "max_impacts": 20},
        "measures": {"box": 2, "samples": 10}, "continuation": {"num": 0}})
    progress = Recorder()
    experiment.run(config, RunOptions(progress=progress))
    names = [p[0] for p in progress.phases]
    assert names[:2] == ["attractors: labelling the starts",
                         "attractors: following the undecided starts further"]
    for description, total, advanced in progress.phases:
        assert advanced == total > 0, description


def test_a_box_larger_than_the_grid_is_said_in_the_measures():
    result = bounce_cli.run("attractors", set={
        "grid.theta0_deg.num": 6, "grid.v0_m_s.num": 5, "recurrence.sample": 10,
        "measures.box": 8, "measures.samples": 10, "continuation.num": 0})
    measures = result.frames["measures.csv"].set_index("quantity")
    for quantity in ("basin_entropy", "boundary_basin_entropy"):
        assert np.isnan(measures.loc[quantity, "value"])
        assert "smaller than one box of measures.box = 8" in measures.loc[quantity, "note"]


def test_an_attractor_has_one_colour_in_both_figures():
    """attractors.png and attractors_continuation.png coloured attractors by their order in
    each table: period-1 blue in both by chance, but orange was period-3 (6 cycles) in one and
    period-2 (4 cycles) in the other. A name met in attractors.png now keeps its colour in
    the continuation, and no other attractor takes it; the title names what is varied."""
    from matplotlib.colors import to_hex

    from bounce_cli.experiments import attractors

    names = ["sticking", "below_racket", "period-1 (2 cycles)", "period-3 (6 cycles)"]
    theta, v = np.meshgrid([0.0, 120.0, 240.0, 360.0], [0.0, 5.0])
    basin_frame = pd.DataFrame({"theta0_deg": theta.ravel(), "v0_m_s": v.ravel(),
                                "attractor": names * 2})
    fractions = pd.DataFrame({"name": names, "fraction": [0.25] * 4})
    points = pd.DataFrame({"name": names[2:], "theta_deg": [40.0, 10.0], "v_m_s": [9.0, 9.5]})
    continuation = pd.DataFrame({
        "gamma": [1.4, 1.4, 1.6, 1.6, 1.6],
        "label": [-3, 0, -3, 0, 1], "branch": [-3, 0, -3, 1, 0],
        "name": ["sticking", "period-1 (2 cycles)", "sticking", "period-2 (4 cycles)",
                 "period-1 (2 cycles)"],
        "fraction": [0.9, 0.1, 0.8, 0.1, 0.1]})
    figures = attractors.draw({"basin.csv": basin_frame, "fractions.csv": fractions,
                               "attractor_points.csv": points,
                               "continuation.csv": continuation})

    def legend_colours(figure) -> dict[str, str]:
        legend = figure.legends[0]
        return {text.get_text().split(":")[0]: to_hex(handle.get_facecolor())
                for text, handle in zip(legend.get_texts(), legend.legend_handles)}

    main = legend_colours(figures["attractors.png"])
    continued = legend_colours(figures["attractors_continuation.png"])
    assert continued["period-1 (2 cycles)"] == main["period-1 (2 cycles)"]
    assert continued["period-2 (4 cycles)"] not in main.values()
    assert "Gamma" in figures["attractors_continuation.png"].axes[0].get_title()


def test_each_cell_of_the_basin_image_is_centred_on_its_start():
    """attractors.png drew its grid from the first start to the last one (the cells' edges on
    the starts), half a cell off basin.png, where each cell is centred on its start."""
    from bounce_cli.experiments import attractors

    theta, v = np.meshgrid([0.0, 120.0, 240.0], [1.0, 3.0, 5.0, 7.0])
    names = np.where(theta.ravel() < 100, "sticking", "period-1 (1 cycles)")
    frame = pd.DataFrame({"theta0_deg": theta.ravel(), "v0_m_s": v.ravel(),
                          "attractor": names})
    fractions = pd.DataFrame({"name": ["sticking", "period-1 (1 cycles)"],
                              "fraction": [1 / 3, 2 / 3]})
    points = pd.DataFrame({"name": ["period-1 (1 cycles)"], "theta_deg": [40.0],
                           "v_m_s": [4.0]})
    figure = attractors.draw({"basin.csv": frame, "fractions.csv": fractions,
                              "attractor_points.csv": points})["attractors.png"]
    assert figure.axes[0].images[0].get_extent() == pytest.approx((-60.0, 300.0, 0.0, 8.0))


def test_the_continuation_table_names_its_parameter_with_its_unit():
    """continuation.csv over the racket's amplitude had a column `racket_amplitude`, where
    every other table (bifurcation, continuation) writes `racket_amplitude_m` (a model
    review); the figure reads it back."""
    result = bounce_cli.run("attractors", set={
        **SMALL, "grid.theta0_deg.num": 20, "grid.v0_m_s.num": 20,
        "continuation.parameter": "racket_amplitude", "continuation.start": 0.28,
        "continuation.stop": 0.3, "continuation.num": 2,
        "continuation.grid.theta0_deg.num": 12, "continuation.grid.v0_m_s.num": 12})
    table = result.frames["continuation.csv"]
    assert list(table.columns[:2]) == ["racket_amplitude_m", "label"]
    assert sorted(set(table["racket_amplitude_m"])) == pytest.approx([0.28, 0.3])
    assert "attractors_continuation.png" in result.figures
