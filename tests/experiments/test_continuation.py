"""bounce continuation (the command) and bounce bifurcation's thresholds located by
continuation: files and columns, the located numbers against eqs. 8 and 14, the figure drawn
from the CSVs, and one-line errors for bad starts."""

import math

import numpy as np
import pandas as pd
import pytest

from bounce_cli.analysis.bifurcation import period1_thresholds
from bounce_cli.model.params import ModelParams
from bounce_cli.experiments.bifurcation import draw as draw_bifurcation
from bounce_cli.experiments.continuation import draw

SMALL = ["--set", "range.low=1.0", "--set", "range.high=1.72",
         "--set", "starts=[{at: 1.3}]", "--set", "steps.max_period=4",
         "--set", "diagram.num=12", "--set", "diagram.theta0_deg=[45]",
         "--set", "diagram.v0_m_s=[5]", "--set", "diagram.transient_impacts=100"]


def small_but(*extra):
    """SMALL, with the --set keys of ``extra`` replacing its own (a key may be given once)."""
    keys = {e.split("=", 1)[0] for e in extra[1::2]}
    return [a for k, v in zip(SMALL[::2], SMALL[1::2]) if v.split("=", 1)[0] not in keys
            for a in (k, v)]


def run_small(cli, out, *extra):
    result = cli("continuation", *small_but(*extra), *extra, "--out", out, "--quiet")
    assert result.exit_code == 0, result.output
    return {p.name: pd.read_csv(p) for p in out.glob("*.csv")}


@pytest.mark.slow
def test_cli_small_run_files_columns_and_numbers(cli, tmp_path):
    frames = run_small(cli, tmp_path)
    assert sorted(frames) == ["bifurcations.csv", "branches.csv", "diagram.csv",
                              "diagram_orbits.csv", "feigenbaum.csv", "orbits.csv"]
    orbits_of_diagram = frames["diagram_orbits.csv"]
    recorded = frames["diagram.csv"].groupby(["gamma", "initial_condition"]).size()
    # every orbit that did not stick has its recorded impacts in diagram.csv
    flew = orbits_of_diagram[orbits_of_diagram.stuck_at_impact < 0]
    assert len(recorded) == len(flew) and (recorded == 64).all()
    assert (tmp_path / "continuation.png").is_file()
    branches, bifs = frames["branches.csv"], frames["bifurcations.csv"]
    for column in ("branch", "period", "cycles", "gamma", "v_m_s", "theta_deg", "lambda1_re",
                   "lambda1_im", "lambda2_re", "lambda2_im", "spectral_radius", "stable",
                   "physical"):
        assert column in branches.columns
    assert set(branches.period) == {1, 2, 4}
    assert list(bifs.columns[:7]) == ["type", "start", "period", "cycles", "gamma", "v_m_s",
                                      "theta_deg"]
    base = ModelParams(0.5, 9.81, 0.30, 0.92)
    closed = period1_thresholds(base, "gamma")
    flip1 = bifs.query("type == 'flip' and period == 1").iloc[0]
    fold1 = bifs.query("type == 'fold' and period == 1").iloc[0]
    assert flip1.gamma == pytest.approx(closed.flip, rel=1e-10)
    assert flip1.closed_form_gamma == pytest.approx(closed.flip, rel=1e-15)
    assert fold1.gamma == pytest.approx(closed.existence, rel=1e-10)
    assert abs(fold1.theta_deg) < 1e-6  # signed phase: no wrap at the fold
    assert sorted(bifs.query("type == 'flip'").period) == [1, 2, 4]
    # stable exactly between the fold and the first flip on the period-1 branch (theta > 0)
    p1 = branches.query("period == 1 and theta_deg > 0 and physical")
    inside = p1.gamma.between(closed.existence * (1 + 1e-6), closed.flip * (1 - 1e-6))
    outside = (p1.gamma > closed.flip * (1 + 1e-6))
    assert p1[inside].stable.all() and not p1[outside].stable.any()
    # the spectral radius column is the largest eigenvalue modulus
    radius = np.hypot(branches.lambda1_re, branches.lambda1_im)
    np.testing.assert_allclose(branches.spectral_radius, radius, rtol=1e-12)
    cascade = frames["feigenbaum.csv"]
    assert list(cascade.period) == [1, 2, 4]
    assert cascade.delta.notna().sum() == 1


@pytest.mark.slow
def test_figure_redrawn_from_the_csvs(cli, tmp_path):
    frames = run_small(cli, tmp_path)
    fig = draw(frames)["continuation.png"]
    top, bottom = fig.axes[:2]
    assert "m/s" in top.get_ylabel() and "Gamma" in bottom.get_xlabel()
    labels = top.get_legend_handles_labels()[1]
    assert {"period 1", "period 2", "period 4", "flip", "fold"} <= set(labels)


@pytest.mark.slow
def test_start_found_by_iterating_gives_the_same_flips(cli, tmp_path):
    """A start given by an initial condition (the map iterated until periodic) at Gamma 1.6,
    where the attractor is the period-2 orbit: its branch flips where the period-1 orbit's
    doubled branch does, once (the branch, turned back at the orbit's birth, follows the same
    orbit from its other impact through the same flip)."""
    frames = run_small(cli, tmp_path, "--set",
                       "starts=[{at: 1.3}, {at: 1.6, theta0_deg: 45, v0_m_s: 4.8}]")
    flips = frames["bifurcations.csv"].query("type == 'flip' and period == 2")
    assert sorted(flips.start) == [0, 1]
    assert flips.gamma.iloc[0] == pytest.approx(flips.gamma.iloc[1], rel=1e-10)


@pytest.mark.parametrize("override,needle", [
    ("starts=[{at: 3.0}]", "starts[0].at"),
    ("starts=[{at: 1.02}]", "starts[0]"),
    ("starts=[{at: 1.3, theta0_deg: 45}]", "theta0_deg and v0_m_s together"),
    ("range.low=2.0", "low must be less than high"),
])
def test_bad_starts_are_one_line_errors(cli, user_error, tmp_path, override, needle):
    result = cli("continuation", *small_but("--set", override), "--set", override, "--out",
                 tmp_path / "x", "--quiet")
    user_error(result, needle)
    assert not (tmp_path / "x").exists()


def test_bifurcation_draws_its_flip_lines_at_the_continuations_thresholds():
    """The lines follow thresholds.csv's continuation column (moved on purpose here), not the
    closed form nor the brute-force estimate."""
    thresholds = pd.DataFrame({
        "threshold": ["existence", "flip"], "cycles": [1, 1], "equation": ["eq. 8", "eq. 14"],
        "closed_form_gamma": [math.pi / 3, 1.5268], "continuation_gamma": [1.1, 1.6],
        "located_gamma": [math.nan, 1.52], "located_period1_end_gamma": [math.nan, 1.51],
        "located_period2_end_gamma": [math.nan, 1.53], "relative_difference": [math.nan, 0.0]})
    values = pd.DataFrame({"gamma": [1.0, 2.0], "attractors": ["period1", "period1"],
                           "dominant_attractor": ["period1", "period1"],
                           "n_initial_conditions": [1, 1], "n_sticking": [0, 0],
                           "lyapunov_max_per_impact": [-0.7, -0.7],
                           "lyapunov_dominant_per_impact": [-0.7, -0.7],
                           "ln_spectral_radius_eq10": [-0.7, -0.7]})
    attractors = pd.DataFrame({"gamma": [1.0, 2.0], "lyapunov_per_impact": [-0.7, -0.7]})
    bif = pd.DataFrame({"gamma": [1.0, 2.0], "v_m_s": [4.5, 4.5]})
    fig = draw_bifurcation({"bifurcation.csv": bif, "attractors.csv": attractors,
                            "values.csv": values, "thresholds.csv": thresholds})
    top = fig["bifurcation.png"].axes[0]
    vertical = sorted({line.get_xdata()[0] for line in top.get_lines()
                       if len(set(line.get_xdata())) == 1 and len(line.get_xdata()) == 2})
    assert vertical == [1.1, 1.6]
