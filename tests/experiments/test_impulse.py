"""`bounce impulse`: section 7's perturbed velocity, full vs linear responses, threshold."""

import math

import numpy as np
import pandas as pd
import pytest

from typer.testing import CliRunner

from bounce_cli.cli.commands import app
from bounce_cli.runtime.config import bundled_config_path, load_config
from bounce_cli.analysis.impulse import impulse_response_full, impulse_response_linear
from bounce_cli.model.perturbation import perturbed_velocity, relaxation_impacts
from bounce_cli.model.linear import jacobian
from bounce_cli.model.maps import map_step, velocity_after_impact
from bounce_cli.experiments import impulse as exp
from bounce_cli.experiments.base import RunOptions

FAST = ["threshold.scan_step=0.02", "threshold.bisection_tolerance=1e-3"]


@pytest.fixture(scope="module")
def result():
    cfg = load_config(exp.ImpulseConfig, bundled_config_path("impulse"), FAST)
    return exp.run(cfg, RunOptions())


def test_v0_for_alpha_p_07_is_5_7(paper_params):
    assert perturbed_velocity(paper_params, 0.7) == pytest.approx(5.7, abs=0.05)
    assert perturbed_velocity(paper_params, 0.5) == pytest.approx(paper_params.fixed_point().v_m_s)


@pytest.mark.parametrize("alpha_p", [0.0, 0.3, 0.4, 0.6, 0.7, 0.95])
def test_closed_form_v0_is_eq5_with_alpha_p_at_the_fixed_point(paper_params, alpha_p):
    """(1+alpha_p) a_r w cos(theta~) - alpha_p v~ + g alpha_p 2 pi / w, with cos(theta~) from
    eq. 8 and v~ from eq. 7, reduces to (1 + 2 alpha_p - alpha_0)/(1 + alpha_0) v~."""
    fp = paper_params.fixed_point()
    general = velocity_after_impact(fp.theta_rad + 2 * math.pi, fp.v_m_s, 2 * math.pi,
                                    paper_params, alpha=alpha_p)
    assert perturbed_velocity(paper_params, alpha_p) == pytest.approx(float(general), rel=1e-12)
    # and the same map step with alpha_0 instead returns the fixed point itself
    step = map_step(fp.theta_rad, fp.v_m_s, paper_params)
    assert float(step.v) == pytest.approx(fp.v_m_s, rel=1e-10)


def test_linear_response_is_J_powers_and_odd_in_the_perturbation(paper_params):
    up = impulse_response_linear(paper_params, 0.6, 10)
    down = impulse_response_linear(paper_params, 0.4, 10)
    np.testing.assert_allclose(up.dv, -down.dv, atol=1e-12)
    np.testing.assert_allclose(up.dtheta, -down.dtheta, atol=1e-12)
    J = jacobian(paper_params)
    y3 = np.linalg.matrix_power(J, 3) @ [up.dv[0], 0.0]
    np.testing.assert_allclose([up.dv[3], up.dtheta[3]], y3, atol=1e-12)
    # eigenvalues 0.5 in absolute value at these parameters (section 7)
    np.testing.assert_allclose(np.abs(np.linalg.eigvals(J)), 0.5, rtol=1e-12)


def test_full_response_is_not_symmetric_but_agrees_for_tiny_perturbations(paper_params):
    up = impulse_response_full(paper_params, 0.6, 10)
    down = impulse_response_full(paper_params, 0.4, 10)
    assert np.max(np.abs(up.dv[1:] + down.dv[1:])) > 0.3  # far from mirror images
    for eps in (1e-4, -1e-4):
        full = impulse_response_full(paper_params, 0.5 + eps, 10)
        lin = impulse_response_linear(paper_params, 0.5 + eps, 10)
        scale = abs(full.dv[0])
        np.testing.assert_allclose(full.dv, lin.dv, atol=2e-3 * scale)


def test_relaxation_impacts_counts_from_the_last_excursion():
    dv = np.array([1.0, 0.01, 0.2, 0.0, 0.0])
    assert relaxation_impacts(dv, np.zeros(5), 0.05, 1.0) == 3
    assert relaxation_impacts(np.zeros(3), np.zeros(3), 0.05, 1.0) == 0
    assert relaxation_impacts(np.array([0.0, 1.0]), np.zeros(2), 0.05, 1.0) == -1


def test_tables(result):
    imp = result.frames["impulse.csv"]
    assert list(imp.columns) == ["alpha_p", "model", "k", "v_m_s", "theta_deg", "dv_m_s",
                                 "dtheta_deg", "outcome"]
    assert len(imp) == 4 * 2 * 11
    full = imp[imp.model == "full"].groupby("alpha_p").outcome.first()
    assert full[0.4] == full[0.6] == full[0.35] == "period1" and full[0.65] != "period1"
    rel = result.frames["relaxation.csv"].set_index(["alpha_p", "model"])
    # linear: equal relaxation for opposite signs; full: the increase relaxes more slowly
    assert rel.asymmetry_impacts[(0.6, "linear")] == 0
    assert rel.relaxation_impacts[(0.6, "full")] > rel.relaxation_impacts[(0.4, "full")]
    assert rel.relaxation_impacts[(0.65, "full")] == -1
    thr = result.frames["threshold.csv"].set_index("direction")
    up = thr.loc["increase"]
    assert 0.60 < up.alpha_p_threshold < 0.66  # paper: about 0.65
    assert up.alpha_p_outside - up.alpha_p_inside <= 1e-3
    assert up.v0_threshold_m_s == pytest.approx(
        (1 + 2 * up.alpha_p_threshold - 0.5) / 1.5 * math.pi * 9.81 * 0.92 / (2 * math.pi))


@pytest.mark.slow
def test_figures_redraw_from_csv(result, tmp_path):
    for name, frame in result.frames.items():
        frame.to_csv(tmp_path / name, index=False)
    figs = exp.draw({n: pd.read_csv(tmp_path / n) for n in result.frames})
    assert set(figs) == {"impulse.png", "impulse_linear.png"}
    assert "Fig. 9" in figs["impulse.png"]._suptitle.get_text()
    assert "Fig. 10" in figs["impulse_linear.png"]._suptitle.get_text()
    for fig in figs.values():
        fig.savefig(tmp_path / "x.png")


@pytest.mark.slow
def test_cli(tmp_path):
    runner = CliRunner()
    args = ["impulse", "--out", str(tmp_path / "o"), "--quiet"]
    for s in FAST:
        args += ["--set", s]
    r = runner.invoke(app, args)
    assert r.exit_code == 0, r.output
    assert {"impulse.csv", "relaxation.csv", "threshold.csv", "impulse.png",
            "impulse_linear.png", "run.json"} <= {p.name for p in (tmp_path / "o").iterdir()}
    bad = runner.invoke(app, ["impulse", "--out", str(tmp_path / "b"),
                              "--set", "relaxation.tolerance_v_m_s=0"])
    assert bad.exit_code == 2 and "relaxation.tolerance_v_m_s" in bad.stderr


@pytest.mark.slow
def test_paper_values_only_at_the_papers_parameters(tmp_path, cli):
    fast = [a for s in FAST for a in ("--set", s)]
    at_paper = cli("impulse", "--out", tmp_path / "p", *fast)
    assert "paper: about 0.65" in at_paper.stderr and "(paper: 5.7 m/s)" in at_paper.stderr
    assert pd.read_csv(tmp_path / "p" / "threshold.csv").paper_alpha_p.iloc[0] == 0.65
    other = cli("impulse", "--out", tmp_path / "o", *fast, "--set", "model.alpha=0.4")
    assert other.exit_code == 0, other.output
    assert "paper:" not in other.stderr and "not the paper's" in other.stderr
    assert pd.read_csv(tmp_path / "o" / "threshold.csv").paper_alpha_p.isna().all()


@pytest.mark.slow
def test_summary_says_in_words_when_the_response_never_leaves_the_basin(tmp_path, cli):
    """With strong period control the upward scan never leaves the basin: the summary says so
    (no 'nan'), and no paper value is quoted for a controlled run."""
    result = cli("impulse", "--set", "model.control.gain=0.7", "--set", "model.control.rate=0.8",
                 "--set", "threshold.scan_step=0.05", "--out", tmp_path / "c")
    assert result.exit_code == 0, result.output
    assert "stays in the period-1 basin for every alpha_p above alpha_0 scanned (to 0.99)" in (
        " ".join(result.stderr.split()))
    assert "nan" not in result.stderr and "paper: about" not in result.stderr


@pytest.mark.parametrize("alpha, side, model", [
    (0.7, "above", ["model.g=3.71", "model.racket_amplitude=0.055", "model.racket_period=0.8"]),
    (0.3, "below", ["model.racket_amplitude=0.4"])])
def test_alpha_p_all_on_one_side_of_alpha_0_is_warned_of(alpha, side, model, tmp_path, cli):
    """The bundled alpha_p (0.35-0.65) are all below alpha_0 = 0.7: the figure's column of
    alpha_p above it stayed empty without a word (a reviewer, at a stable model of a boom's
    gravity, took it for a plotting failure)."""
    fast = [a for s in FAST for a in ("--set", s)]
    model_set = [a for s in model for a in ("--set", s)]
    result = cli("impulse", "--out", tmp_path / "o", *fast, "--set", f"model.alpha={alpha}",
                 *model_set)
    assert "unstable" not in result.stderr
    assert result.exit_code == 0, result.output
    said = " ".join(result.stderr.split())
    assert f"bounce: warning: alpha_p: none {side} alpha_0 = {alpha:g}" in said
    both = cli("impulse", "--out", tmp_path / "b", *fast)
    assert "alpha_p: none" not in both.stderr

