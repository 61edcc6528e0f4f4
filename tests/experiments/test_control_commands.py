"""`model.control` in the commands that iterate the map (orbit, basin, impulse): K = 0 gives the
passive results exactly; a passive config's resolved config (run.json) is unchanged; commands
that do not support control refuse it in one line."""

import io

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from bounce_cli.cli.commands import app
from bounce_cli.runtime.config import ModelOnlyConfig, bundled_config_path, load_config
from bounce_cli.experiments import basin, impulse
from bounce_cli.experiments.base import RunOptions

runner = CliRunner()
SMALL_BASIN = ["grid.theta0_deg.num=60", "grid.v0_m_s.num=60"]
FAST_IMPULSE = ["threshold.scan_step=0.02", "threshold.bisection_tolerance=1e-3"]


def test_passive_configs_dump_as_before():
    """No `control` key appears in a passive config's dump (run.json, --print-config)."""
    assert list(ModelOnlyConfig().model_dump()["model"]) == [
        "alpha", "g", "racket_amplitude", "racket_period"]
    for schema, name in ((basin.BasinConfig, "basin"), (impulse.ImpulseConfig, "impulse")):
        cfg = load_config(schema, bundled_config_path(name))
        assert "control" not in cfg.model_dump(mode="json")["model"]
        controlled = load_config(schema, bundled_config_path(name), ["model.control.gain=0.5"])
        assert controlled.model_dump(mode="json")["model"]["control"] == {
            "kind": "period", "gain": 0.5, "rate": 1.0}


def orbit_csv(*extra):
    result = runner.invoke(app, ["orbit", "--theta0-deg", "40", "--v0", "5.3", "-n", "12",
                                 "--csv", *extra])
    assert result.exit_code == 0, result.output
    return pd.read_csv(io.StringIO(result.stdout))


def test_orbit_with_zero_gain_is_the_passive_orbit_plus_the_period():
    passive = orbit_csv()
    zero = orbit_csv("--set", "model.control.gain=0", "--set", "model.control.rate=0.5")
    assert list(zero.columns) == list(passive.columns) + ["racket_period_s"]
    for column in ("theta_rad", "v_m_s", "theta_deg"):
        assert np.array_equal(zero[column].to_numpy(), passive[column].to_numpy())
    np.testing.assert_allclose(zero.t_s, passive.t_s, rtol=1e-14)
    assert (zero.racket_period_s == 0.92).all()
    controlled = orbit_csv("--set", "model.control.gain=0.7")
    assert controlled.racket_period_s.iloc[1] == pytest.approx(
        0.92 + 0.7 * 2 * (5.3 - np.pi * 9.81 / (2 * np.pi / 0.92)) / 9.81)
    # times add up the flights at their own periods
    np.testing.assert_allclose(np.diff(controlled.t_s), controlled.flight_s.iloc[1:], rtol=1e-12)


def run_basin(*overrides):
    cfg = load_config(basin.BasinConfig, bundled_config_path("basin"),
                      SMALL_BASIN + list(overrides))
    return basin.run(cfg, RunOptions())


def test_basin_with_zero_gain_is_the_passive_basin():
    passive, zero = run_basin(), run_basin("model.control.gain=0", "model.control.rate=0.2")
    for name in ("basin.csv", "fractions.csv", "markers.csv"):
        # markers.csv's spectral_radius is the passive map's (eq. 10), NaN with a controller
        pd.testing.assert_frame_equal(passive.frames[name].drop(columns="spectral_radius",
                                                                errors="ignore"),
                                      zero.frames[name].drop(columns="spectral_radius",
                                                             errors="ignore"))
    assert zero.frames["markers.csv"]["spectral_radius"].isna().all()
    controlled = run_basin("model.control.gain=0.7")
    frac = controlled.frames["fractions.csv"].set_index("outcome").fraction
    assert frac["period1"] > 2 * passive.frames["fractions.csv"].set_index(
        "outcome").fraction["period1"]


def run_impulse(*overrides):
    cfg = load_config(impulse.ImpulseConfig, bundled_config_path("impulse"),
                      FAST_IMPULSE + list(overrides))
    return impulse.run(cfg, RunOptions())


@pytest.mark.slow
def test_impulse_with_zero_gain_is_the_passive_impulse():
    passive = run_impulse()
    zero = run_impulse("model.control.gain=0", "model.control.rate=0.4")
    for name, frame in passive.frames.items():
        pd.testing.assert_frame_equal(frame, zero.frames[name])


def test_impulse_with_control_stays_in_the_basin_and_relaxes_faster():
    controlled = run_impulse("model.control.gain=0.7")
    threshold = controlled.frames["threshold.csv"].set_index("direction")
    assert np.isnan(threshold.loc["increase", "alpha_p_threshold"])  # never left up to 0.99
    relax = controlled.frames["relaxation.csv"]
    full = relax[relax.model == "full"].set_index("alpha_p").relaxation_impacts
    assert (full > 0).all() and (full <= 4).all()
    linear = relax[relax.model == "linear"]
    assert (linear.outcome == "period1").all()


@pytest.mark.parametrize("command", ["stability", "regression"])
def test_commands_without_control_refuse_it(command, tmp_path):
    result = runner.invoke(app, [command, "--set", "model.control.gain=0.5",
                                 "--out", str(tmp_path / "o")])
    assert result.exit_code == 2
    lines = [x for x in result.stderr.splitlines() if x.strip()]
    assert lines == ["bounce: error: --set: model.control: unknown key"]


@pytest.mark.slow
def test_unstable_controller_warns_in_one_line(tmp_path):
    result = runner.invoke(app, ["impulse", "--set", "model.control.gain=1.3", "-q",
                                 *sum((["--set", s] for s in FAST_IMPULSE), []),
                                 "--out", str(tmp_path / "o")])
    assert result.exit_code == 0, result.output
    warnings = [x for x in result.stderr.splitlines() if x.startswith("bounce: warning:")]
    assert len(warnings) == 1 and "model.control" in warnings[0]


@pytest.mark.slow
def test_fit_to_passive_data_says_no_control_is_detected(tmp_path):
    """The passive lab's perturbations (results/impulse-data): K's interval holds 0, and the
    summary says that c and the fitted radius then describe nothing about the ball."""
    from pathlib import Path

    from typer.testing import CliRunner

    from bounce_cli.cli.commands import app

    data = Path(__file__).resolve().parents[2] / "results" / "impulse-data" / "impacts.csv"
    result = CliRunner().invoke(app, ["control", "--data", str(data), "--out",
                                      str(tmp_path / "c"), "--set", "model.g=9.81"])
    assert result.exit_code == 0, result.output
    text = " ".join(result.stderr.split())
    assert "K's interval includes 0, no period control is detected" in text


def test_the_controlled_runs_figures_name_the_controller_in_their_caption():
    """A figure of the controlled map says so in its caption (the file's metadata), as the
    passive map's does not."""
    from bounce_cli.runtime.figure_files import drawn, figure_caption

    controlled = drawn(run_basin("model.control.gain=0.7").figures["basin.png"])
    assert "racket period control K = 0.7, c = 1" in figure_caption(controlled)
    assert "racket period control" not in figure_caption(drawn(run_basin().figures["basin.png"]))
    for fig in run_impulse("model.control.gain=0.7").figures.values():
        assert "racket period control K = 0.7" in figure_caption(drawn(fig))
