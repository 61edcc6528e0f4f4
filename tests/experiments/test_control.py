"""`bounce control`: the period-control experiment end to end (config, tables, figures, --data).

The numbers are checked against independent routes: K = 0 gives the passive results of the
other commands (the committed `bounce impulse` threshold, identical passive/controlled frames);
the fastest controller against a fine grid; the fit against the simulated truth.
"""

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from bounce_cli.cli.commands import app
from bounce_cli.runtime.config import bundled_config_path, load_config
from bounce_cli.model.params import ModelParams
from bounce_cli.model.control import PeriodController, controlled_jacobian
from bounce_cli.analysis.control_design import period_control_radius, simulate_perturbation_trials
from bounce_cli.experiments import control as exp
from bounce_cli.experiments.base import RunOptions
from bounce_cli.experiments.registry import entry

RESULTS = Path(__file__).resolve().parents[2] / "results"
FAST = ["basin.theta0_deg.num=40", "basin.v0_m_s.num=40", "radius.gain.num=41",
        "radius.rate.num=41", "radius.zoom_num=61", "threshold.scan_step=0.02",
        "threshold.bisection_tolerance=1e-3"]
runner = CliRunner()


def load(overrides=()):
    return load_config(exp.ControlConfig, bundled_config_path("control"), FAST + list(overrides))


@pytest.fixture(scope="module")
def result():
    return exp.run(load(), RunOptions())


def test_bundled_config_is_section7s_model():
    cfg = load_config(exp.ControlConfig, bundled_config_path("control"))
    m = cfg.model
    assert (m.alpha, m.g, m.racket_amplitude, m.racket_period) == (0.5, 9.81, 0.30, 0.92)
    assert cfg.model.control.kind == "period"
    assert cfg.impulse.alpha_p == [0.4, 0.6, 0.35, 0.65]


@pytest.mark.slow
def test_frames_and_figures(result):
    assert sorted(result.figures) == sorted(png for png, _ in entry("control").figures)
    assert sorted(result.frames) == sorted([
        "radius_map.csv", "radius_gain.csv", "radius_zoom.csv", "eigen.csv", "regions.csv",
        "impulse.csv", "relaxation.csv", "relaxation_gain.csv", "threshold.csv", "basin.csv",
        "basin_fractions.csv", "fit.csv", "fit_responses.csv", "acf.csv"])
    fractions = result.frames["basin_fractions.csv"]
    for _model, part in fractions.groupby("model"):
        assert part.fraction.sum() == pytest.approx(1.0)


@pytest.mark.slow
def test_eigen_rows(result, paper_params):
    eigen = result.frames["eigen.csv"].set_index("model")
    assert eigen.loc["passive", "spectral_radius"] == pytest.approx(0.5, abs=1e-12)  # eq. 12
    configured = eigen.loc["controlled"]
    M = controlled_jacobian(paper_params, PeriodController(0.7, 1.0))
    assert configured.spectral_radius == pytest.approx(np.abs(np.linalg.eigvals(M)).max())
    # the fastest controllers beat every point of the fine grids around them
    line = eigen.loc["fastest at c = 1"]
    K = np.linspace(0.6, 0.9, 30001)
    assert line.spectral_radius <= period_control_radius(paper_params, K, 1.0).min() + 1e-9
    best = eigen.loc["fastest"]
    zoom = result.frames["radius_zoom.csv"]
    assert best.spectral_radius <= zoom.spectral_radius.min() + 1e-12
    assert best.spectral_radius < line.spectral_radius < 0.5
    # at the fastest point the three eigenvalues coincide (a triple root)
    moduli = [np.hypot(best[f"lambda{i}_re"], best[f"lambda{i}_im"]) for i in (1, 2, 3)]
    assert max(moduli) - min(moduli) < 1e-3


def test_stable_region_leaves_out_the_neutral_edge(result, paper_params):
    """At K = 1 an eigenvalue lies on the unit circle (for every c up to about 1.8 here;
    at c = 0 for every K):
    those grid points are on the boundary whatever their last bits say (1 - 1 ulp, 1 + 1 ulp)."""
    grid = result.frames["radius_map.csv"]
    at_one = grid[np.isclose(grid.gain_K, 1.0)]
    assert (at_one.spectral_radius > 1 - 1e-12).all()
    assert (np.abs(at_one.spectral_radius - 1) < 1e-12).sum() >= len(at_one) // 2
    stable = result.frames["regions.csv"].set_index("region").loc["stable"]
    assert stable.gain_max_K < 1.0
    # the area counts exactly the points clearly below 1
    K = np.unique(grid.gain_K)
    c = np.unique(grid.rate_c)
    cell = (K[1] - K[0]) * (c[1] - c[0])
    clearly = int((grid.spectral_radius < 1 - 1e-9).sum())
    assert stable.area_K_c == pytest.approx(clearly * cell, rel=1e-12)
    # rounding on either side of the boundary does not change the answer
    Kg, cg = np.meshgrid([0.5, 1.0], [0.5, 1.0])
    for ulp in (-1, 0, 1):
        radius = np.array([[0.5, 1.0 + ulp * 2.2e-16]] * 2)
        assert exp._region("stable", 1.0, "map", Kg, cg, radius)["gain_max_K"] == 0.5


def test_passive_threshold_is_bounce_impulse_committed_one(result):
    """Same scan and bisection with K = 0 as `bounce impulse` (committed baseline; a coarser
    scan here, so to the bisection tolerance)."""
    ours = result.frames["threshold.csv"].set_index(["model", "direction"])
    committed = pd.read_csv(RESULTS / "impulse" / "threshold.csv").set_index("direction")
    for direction in ("increase", "decrease"):
        assert ours.loc[("passive", direction), "alpha_p_threshold"] == pytest.approx(
            committed.loc[direction, "alpha_p_threshold"], abs=1e-3)
    # period control widens the domain: the experiment's 0.65 stays inside (section 7)
    up = ours.loc[("controlled", "increase")]
    assert np.isnan(up.alpha_p_threshold) or up.alpha_p_threshold > 0.65


def test_controlled_relaxes_faster_and_modulates_the_period(result):
    relax = result.frames["relaxation.csv"].set_index(["model", "alpha_p"])
    for alpha_p in (0.4, 0.6):
        fast = relax.loc[("controlled", alpha_p), "relaxation_impacts"]
        slow = relax.loc[("passive", alpha_p), "relaxation_impacts"]
        assert 0 <= fast < slow
    imp = result.frames["impulse.csv"]
    passive = imp[imp.model == "passive"]
    assert (passive.dtau_ms.dropna() == 0.0).all()  # the passive model cannot produce Fig. 11
    up = imp[(imp.model == "controlled") & (imp.alpha_p == 0.6)].set_index("k")
    assert up.loc[1, "dtau_ms"] > 0  # a faster ball: a longer racket period at once


def test_relaxation_along_gain_matches_single_responses(result, paper_params):
    """The vectorised scan along K equals single controlled responses (and K = 0 the
    passive relaxation of relaxation.csv)."""
    import math

    from bounce_cli.analysis.control_design import controlled_impulse_response

    scan = result.frames["relaxation_gain.csv"]
    relax = result.frames["relaxation.csv"].set_index(["model", "alpha_p"])
    for gain in (0.0, 0.5, 0.7):
        for alpha_p in (0.4, 0.65):
            row = scan[np.isclose(scan.gain_K, gain) & (scan.alpha_p == alpha_p)].iloc[0]
            single = controlled_impulse_response(paper_params, PeriodController(row.gain_K, 1.0),
                                                 alpha_p, 100)
            assert row.relaxation_impacts == single.relaxation_impacts(0.05, math.radians(1))
            if gain == 0.0:
                assert row.relaxation_impacts == relax.loc[("passive", alpha_p),
                                                           "relaxation_impacts"]


@pytest.mark.slow
def test_zero_gain_controlled_equals_passive_end_to_end():
    res = exp.run(load(["model.control.gain=0", "model.control.rate=0.4"]), RunOptions())
    for name, key in (("impulse.csv", ["alpha_p", "k"]), ("basin.csv", ["theta0_deg", "v0_m_s"]),
                      ("threshold.csv", ["direction"]), ("relaxation.csv", ["alpha_p"])):
        frame = res.frames[name]
        a = frame[frame.model == "passive"].drop(columns="model").sort_values(key)
        b = frame[frame.model == "controlled"].drop(columns="model").sort_values(key)
        pd.testing.assert_frame_equal(a.reset_index(drop=True), b.reset_index(drop=True))


def test_simulated_fit_contains_the_truth(result):
    fit = result.frames["fit.csv"].set_index("quantity")
    assert fit.source.iloc[0] == "simulated"
    for q in ("gain_K", "rate_c"):
        assert fit.loc[q, "ci_low"] <= fit.loc[q, "truth"] <= fit.loc[q, "ci_high"]


def impacts_csv(tmp_path, gain=0.6, rate=0.7, **drop):
    params = ModelParams(0.5, 9.81, 0.3, 0.92)
    data = pd.DataFrame(simulate_perturbation_trials(
        params, PeriodController(gain, rate), n_trials=16, impacts_per_trial=60,
        velocity_noise_sd=0.05, phase_noise_sd=0.02, period_noise_sd=0.005, seed=9))
    data["theta_deg"] = np.degrees(data.theta_rad)
    data["racket_amplitude_m"] = 0.3
    data["g_m_s2"] = 9.81  # the set-up's gravity (the model runs at the data's)
    data = data.drop(columns=list(drop))
    path = tmp_path / "impacts.csv"
    data.to_csv(path, index=False)
    return path


@pytest.mark.slow
def test_cli_fits_a_labs_impacts_table(tmp_path):
    path = impacts_csv(tmp_path)
    out = tmp_path / "out"
    result = runner.invoke(app, ["control", "--data", str(path), "--out", str(out), "-q",
                                 *sum((["--set", s] for s in FAST), [])])
    assert result.exit_code == 0, result.output
    fit = pd.read_csv(out / "fit.csv").set_index("quantity")
    assert fit.source.iloc[0] == "data"
    assert fit.loc["gain_K", "ci_low"] <= 0.6 <= fit.loc["gain_K", "ci_high"]
    assert fit.loc["rate_c", "ci_low"] <= 0.7 <= fit.loc["rate_c", "ci_high"]
    assert fit.loc["model_racket_period", "estimate"] == pytest.approx(0.92, abs=0.01)


@pytest.mark.slow
def test_data_without_alpha_uses_the_sign_of_the_velocity(tmp_path):
    path = impacts_csv(tmp_path, alpha=True)
    frames = exp.fit_frames(load([f"data={path}"]))
    fit = frames["fit.csv"].set_index("quantity")
    assert fit.loc["gain_K", "ci_low"] <= 0.6 <= fit.loc["gain_K", "ci_high"]
    assert fit.loc["rate_c", "ci_low"] <= 0.7 <= fit.loc["rate_c", "ci_high"]


@pytest.mark.parametrize("change,needle", [
    (dict(drop="racket_period_s"), "missing column racket_period_s"),
    (dict(unperturbed=True), "no perturbed impact"),
    (dict(bad_value=True), "column v_m_s: not a number in data row 3"),
])
def test_cli_bad_data_is_one_line(tmp_path, change, needle):
    path = impacts_csv(tmp_path)
    frame = pd.read_csv(path)
    if "drop" in change:
        frame = frame.drop(columns=change["drop"])
    if change.get("unperturbed"):
        frame["perturbed"] = False
    if change.get("bad_value"):
        frame["v_m_s"] = frame["v_m_s"].astype(object)
        frame.loc[2, "v_m_s"] = "fast"
    frame.to_csv(path, index=False)
    out = tmp_path / "out"
    result = runner.invoke(app, ["control", "--data", str(path), "--out", str(out), "-q"])
    assert result.exit_code == 2, result.output
    lines = [x for x in result.stderr.splitlines() if x.strip()]
    assert len(lines) == 1 and lines[0].startswith("bounce: error: data:"), result.stderr
    assert needle in lines[0]
    assert not out.exists() or not any(out.iterdir())  # nothing half-written


@pytest.mark.parametrize("setting,needle", [
    ("model.control.rate=3", "model.control.rate"),
    ("model.control.kind=mirror", "model.control.kind"),
    ("model.control.speed=1", "model.control.speed: unknown key"),
])
def test_cli_bad_controller_is_one_line(tmp_path, setting, needle):
    result = runner.invoke(app, ["control", "--set", setting, "--out", str(tmp_path / "o")])
    assert result.exit_code == 2
    assert needle in result.stderr and "Traceback" not in result.output


@pytest.mark.slow
def test_correlations_theory_matches_the_controlled_stochastic_map(result):
    """eq. 19 with the 3 x 3 Jacobian vs runs of the controlled map of eqs. 16-18 (same noise
    covariance): within 3 standard errors plus 0.01 (the map is not linear)."""
    acf = result.frames["acf.csv"]
    gap = np.abs(acf.controlled_theory - acf.controlled_sample_mean)
    assert (gap <= 3 * acf.controlled_sample_se + 0.01).all()
    lag1 = acf[(acf.lag == 1) & (acf.pair == "v_v")].iloc[0]
    assert lag1.passive_theory < -0.5 < 0 < lag1.controlled_theory  # control changes the sign


def test_zero_gain_correlations_are_the_passive_ones():
    cfg = load(["model.control.gain=0", "correlations.runs=2", "correlations.bounces=40"])
    frame = exp.correlations_frame(cfg.params, cfg)
    np.testing.assert_allclose(frame.controlled_theory, frame.passive_theory, rtol=1e-10,
                               atol=1e-12)


@pytest.mark.slow
def test_the_controlled_basin_runs_on_the_worker_pool(monkeypatch):
    """``bounce control --jobs 2``: the passive and controlled basins on two worker processes
    (the basin command's classifier), the same tables as in one process."""
    from bounce_cli.runtime import parallel
    from bounce_cli.experiments import basin

    started = []

    class CountedPool(parallel.LocalPool):
        def __enter__(self):
            started.append(self.workers)
            return super().__enter__()

    monkeypatch.setenv("BOUNCE_KERNEL", "numpy")
    monkeypatch.setattr(parallel, "LocalPool", CountedPool)
    cfg = load()
    one = exp.basin_frames(cfg.params, cfg, RunOptions(jobs=1))
    monkeypatch.setattr(basin, "POOL_MIN_POINTS", 100)
    two = exp.basin_frames(cfg.params, cfg, RunOptions(jobs=2))
    assert started == [2, 2]  # one pool per model (passive, controlled)
    for name in ("basin.csv", "basin_fractions.csv"):
        pd.testing.assert_frame_equal(one[name], two[name])
    assert "--jobs" in runner.invoke(app, ["control", "--help"]).output
