"""`bounce regression` (Fig. 7, eq. 15): simulation, --data round trip, errors, redraw."""

import json

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from bounce_cli.experiments import regression

SMALL = ["--set", "design.subjects=2", "--set", "design.trials_per_height=2",
         "--set", "stochastic_map.duration_s=8"]
NOISELESS = ["--set", "design.subject_phase_sd_deg=0", "--set", "design.phase_sd_deg=0",
             "--set", "design.period_sd_s=0", "--set", "design.amplitude_sd_m=0",
             "--set", "stochastic_map.q_v=0", "--set", "stochastic_map.q_theta=0"]


@pytest.fixture(scope="module")
def small_run(tmp_path_factory, cli):
    out = tmp_path_factory.mktemp("reg")
    result = cli("regression", "--out", out, "--quiet", *SMALL)
    assert result.exit_code == 0, result.output
    return out


def test_simulated_trials_and_fit(small_run):
    trials = pd.read_csv(small_run / "trials.csv")
    assert len(trials) == 2 * 3 * 2
    for col in ("a_r_m", "tau_s", "theta_deg", "alpha", "g", "tau2_s2", "subject",
                "target_height_m"):
        assert col in trials.columns
    fit = pd.read_csv(small_run / "fit.csv")
    assert list(fit.columns[:9]) == ["condition", "n", "slope", "slope_ci_low", "slope_ci_high",
                                     "intercept", "intercept_ci_low", "intercept_ci_high", "r2"]
    row = fit.iloc[0]
    # fit.csv is the OLS of the fitted trials in trials.csv (scipy, an independent route)
    used = trials[~trials.lost.astype(bool)]
    ref = stats.linregress(used.tau2_s2, used.a_r_m)
    t = stats.t.ppf(0.975, len(used) - 2)
    assert row.n == len(used)
    assert row.slope == pytest.approx(ref.slope, rel=1e-10)
    assert row.intercept == pytest.approx(ref.intercept, abs=1e-12)
    assert row.r2 == pytest.approx(ref.rvalue**2, rel=1e-10)
    assert (row.slope_ci_low, row.slope_ci_high) == pytest.approx(
        (ref.slope - t * ref.stderr, ref.slope + t * ref.stderr), rel=1e-9)
    assert (row.intercept_ci_low, row.intercept_ci_high) == pytest.approx(
        (ref.intercept - t * ref.intercept_stderr, ref.intercept + t * ref.intercept_stderr),
        rel=1e-9)
    assert row.predicted_slope > 0 and 0.5 < row.r2 <= 1
    manifest = json.loads((small_run / "run.json").read_text())
    assert manifest["config"]["data"] is None and manifest["seed"] == 1996


def test_without_noise_the_fit_recovers_eq15_exactly(tmp_path, cli):
    result = cli("regression", "--out", tmp_path, "--quiet", *SMALL, *NOISELESS)
    assert result.exit_code == 0, result.output
    fit = pd.read_csv(tmp_path / "fit.csv").iloc[0]
    assert fit.slope == pytest.approx(fit.predicted_slope, rel=1e-9)
    assert abs(fit.intercept) < 1e-10 and fit.r2 == pytest.approx(1.0, abs=1e-12)
    assert fit.mean_theta_deg == pytest.approx(32.0, abs=1e-9)


def test_data_round_trip(small_run, tmp_path, cli):
    out = tmp_path / "again"
    result = cli("regression", "--data", small_run / "trials.csv", "--out", out, "--quiet")
    assert result.exit_code == 0, result.output
    pd.testing.assert_frame_equal(pd.read_csv(out / "fit.csv"),
                                  pd.read_csv(small_run / "fit.csv"), rtol=1e-10)
    manifest = json.loads((out / "run.json").read_text())
    assert manifest["config"]["data"] == str(small_run / "trials.csv")


def test_data_with_conditions_and_only_required_columns(tmp_path, cli):
    rows = []
    for cond, k in (("vision", 0.30), ("no-vision", 0.33)):
        for i, tau in enumerate([0.55, 0.57, 0.7, 0.71, 0.8, 0.82]):
            rows.append({"condition": cond, "tau_s": tau, "a_r_m": k * tau**2 + 0.001 * (-1) ** i})
    path = tmp_path / "trials.csv"
    pd.DataFrame(rows).to_csv(path, index=False)
    result = cli("regression", "--data", path, "--out", tmp_path / "o")
    assert result.exit_code == 0, result.output
    fit = pd.read_csv(tmp_path / "o" / "fit.csv").set_index("condition")
    assert sorted(fit.index) == ["no-vision", "vision"]
    assert fit.loc["vision", "slope"] == pytest.approx(0.30, abs=0.01)
    assert fit["predicted_slope"].isna().all()  # no theta_deg column: no eq. 15 slope
    assert fit.loc["vision", "implied_theta_deg"] > 0


@pytest.mark.parametrize("content, needles", [
    ("a_r_m,period\n0.1,0.5\n", ["data:", "missing column(s) tau_s"]),
    ("a_r_m,tau_s\n0.1,0.5\nx,0.6\n0.2,0.7\n", ["column a_r_m", "not a number", "row 2"]),
    ("a_r_m,tau_s\n0.1,0.5\n-0.1,0.6\n0.2,0.7\n", ["column a_r_m", "must be > 0"]),
    ("a_r_m,tau_s\n0.1,0.5\n0.2,0.6\n", ["at least 3 points"]),
    ("a_r_m,tau_s,alpha\n0.1,0.5,0.5\n0.15,0.6,0.6\n0.2,0.7,0.5\n", ["alpha", "differs"]),
    ("", ["cannot read"]),
])
def test_bad_data_is_one_line_error(tmp_path, content, needles, cli, user_error):
    path = tmp_path / "bad.csv"
    path.write_text(content)
    user_error(cli("regression", "--data", path, "--out", tmp_path / "o"), *needles)


def test_missing_data_file(tmp_path, cli, user_error):
    user_error(cli("regression", "--data", tmp_path / "none.csv", "--out", tmp_path / "o"),
                      "data:", "not found")


def test_figure_redraws_from_csvs(small_run):
    frames = {name: pd.read_csv(small_run / name) for name in ("trials.csv", "fit.csv")}
    fig = regression.draw(frames)["regression.png"]
    ax = fig.axes[0]
    assert "Fig. 7" in ax.get_title() and r"$\tau^2$" in ax.get_xlabel()
    assert len(ax.get_lines()) >= 3


def test_trials_at_one_period_warn_that_the_slope_is_undetermined(tmp_path, cli):
    """All trials at (nearly) the same racket period: tau^2 spans nothing, eq. 15's slope is
    not determined; the fit is written with its (wide) interval and a warning says why."""
    rng = np.random.default_rng(2)
    tau = 0.92 + rng.normal(0, 1e-4, 6)
    pd.DataFrame({"a_r_m": 0.30 + rng.normal(0, 0.01, 6), "tau_s": tau}).to_csv(
        tmp_path / "t.csv", index=False)
    result = cli("regression", "--data", tmp_path / "t.csv", "--out", tmp_path / "o")
    assert result.exit_code == 0, result.output
    assert "bounce: warning: condition 'all': the trials' squared racket periods span only" in (
        result.stderr)
    spread = cli("regression", "--out", tmp_path / "s", "--quiet")
    assert "warning" not in spread.stderr
