"""`bounce trajectory`: files, columns, agreement with `bounce orbit`, figure from CSVs."""

import io
import math

import numpy as np
import pandas as pd
import pytest

from bounce_cli.runtime.config import bundled_config_path, load_config
from bounce_cli.experiments import trajectory
from bounce_cli.experiments.base import RunOptions


@pytest.fixture(scope="module")
def out(tmp_path_factory, cli):
    out = tmp_path_factory.mktemp("trajectory")
    result = cli("trajectory", "--set", "duration_s=4", "--out", out, "--quiet")
    assert result.exit_code == 0, result.output
    return out


def test_bundled_config_has_the_fig3_cases():
    cfg = load_config(trajectory.TrajectoryConfig, bundled_config_path("trajectory"))
    assert cfg.integrator == "exact" and cfg.rk4_step_s == 1e-3 and cfg.duration_s >= 10
    assert [c.v0_m_s for c in cfg.cases] == [4.8, 5.7]
    for case in cfg.cases:  # x_b(0) = 0.205 m on the racket
        assert 0.30 * math.sin(case.theta0) == pytest.approx(0.205, abs=1e-12)


def test_files_and_columns(out):
    track = pd.read_csv(out / "trajectory.csv")
    impacts = pd.read_csv(out / "impacts.csv")
    assert list(track.columns) == ["case", "t_s", "ball_x_m", "ball_v_m_s", "racket_x_m",
                                   "racket_v_m_s", "state"]
    assert list(impacts.columns) == ["case", "k", "t_s", "theta_deg", "v_m_s", "racket_acc_g"]
    assert set(track["state"]) == {"flight", "stuck"}
    assert set(track["case"]) == set(impacts["case"]) == {"period-1", "sticking"}
    assert (track["ball_x_m"] - track["racket_x_m"]).min() > -1e-9
    for _, tr in track.groupby("case"):
        assert tr["t_s"].is_monotonic_increasing
        assert tr["t_s"].iloc[-1] - tr["t_s"].iloc[0] == pytest.approx(4.0)
        assert tr["t_s"].diff().max() <= 0.005 + 1e-12
    stuck = track[track["state"] == "stuck"]
    assert set(stuck["case"]) == {"sticking"}
    assert np.allclose(stuck["ball_x_m"], stuck["racket_x_m"])
    assert impacts["theta_deg"].between(0, 360).all()
    assert (out / "trajectory.png").stat().st_size > 10_000


@pytest.mark.parametrize("case", ["period-1", "sticking"])
def test_impacts_agree_with_bounce_orbit(out, case, cli):
    impacts = pd.read_csv(out / "impacts.csv")
    imp = impacts[impacts["case"] == case].reset_index(drop=True)
    theta0_deg = math.degrees(math.asin(0.205 / 0.30))
    result = cli("orbit", "--theta0-deg", repr(theta0_deg), "--v0", imp["v_m_s"][0],
                 "-n", len(imp) - 1, "--csv")
    assert result.exit_code == 0, result.output
    orbit = pd.read_csv(io.StringIO(result.stdout))
    n = min(len(orbit), len(imp))
    assert n >= 4
    for col in ("t_s", "theta_deg", "v_m_s"):
        np.testing.assert_allclose(imp[col][:n], orbit[col][:n], atol=1e-8)
    if case == "sticking":
        assert "sticking" in result.stderr and len(orbit) < len(imp)


def test_figure_redrawn_from_csvs_alone(out, paper_params):
    cfg = load_config(trajectory.TrajectoryConfig, bundled_config_path("trajectory"),
                      ["duration_s=4"])
    result = trajectory.run(cfg, RunOptions())
    frames = {name: pd.read_csv(out / name) for name in result.frames}
    redrawn = trajectory.draw(frames)["trajectory.png"]
    original = result.figures["trajectory.png"]
    assert len(redrawn.axes) == len(original.axes) == 6
    for ax_a, ax_b in zip(original.axes, redrawn.axes):
        assert ax_a.get_ylabel() == ax_b.get_ylabel() and ax_a.get_ylabel()
        assert len(ax_a.lines) == len(ax_b.lines) > 0
        for la, lb in zip(ax_a.lines, ax_b.lines):
            np.testing.assert_allclose(la.get_ydata(), lb.get_ydata(), atol=1e-12)
        assert len(ax_a.patches) == len(ax_b.patches)
    assert len(original.axes[3].patches) >= 2  # stuck phases shaded in the sticking case
    fp = paper_params.fixed_point()
    assert original.axes[1].lines[1].get_ydata()[0] == pytest.approx(fp.v_m_s)
    assert original.axes[2].lines[1].get_ydata()[0] == pytest.approx(fp.theta_deg)


@pytest.mark.slow
def test_rk4_integrator_from_the_command_line(tmp_path, out, cli):
    result = cli("trajectory", "--set", "duration_s=4", "--set", "integrator=rk4",
                 "--out", tmp_path, "--quiet")
    assert result.exit_code == 0, result.output
    a = pd.read_csv(out / "impacts.csv")
    b = pd.read_csv(tmp_path / "impacts.csv")
    assert len(a) == len(b)
    assert np.abs(a["t_s"] - b["t_s"]).max() < 1e-3


@pytest.mark.parametrize(
    "args, needles",
    [
        (["--set", "integrator=euler"], ["integrator"]),
        (["--set", "duration_s=0"], ["duration_s", "greater than 0"]),
        (["--set", "sticking.min_hop_s=-1"], ["sticking.min_hop_s"]),
        (["--set", "cases=[]"], ["cases"]),
    ],
)
def test_user_errors(args, needles, cli):
    result = cli("trajectory", *args, "--print-config")
    assert result.exit_code == 2, result.output
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("bounce: error: ")
    for needle in needles:
        assert needle in lines[0]


def test_case_needs_exactly_one_phase(tmp_path, cli):
    text = bundled_config_path("trajectory").read_text().replace(
        "theta0_rad: 0.752318481155386", "theta0_rad: 0.75\n    theta0_deg: 43", 1)
    path = tmp_path / "both.yaml"
    path.write_text(text)
    result = cli("trajectory", "--config", path, "--print-config")
    assert result.exit_code == 2
    assert "cases.0" in result.stderr and "exactly one of" in result.stderr


@pytest.mark.slow
def test_exact_sticking_trajectory_marks_the_accumulation_points(tmp_path, cli, user_error,
                                                                 paper_params):
    """sticking.min_hop_s=0: the continuous motion of Fig. 3's sticking case without a cut;
    its accumulation points are the exact orbit's sticks (engine.chatter), the ball rides
    from each to the release at asin(1/Gamma), and the figure marks them. rk4 cannot do this:
    a one-line error."""
    from bounce_cli.model.chatter import STICK, iterate_exact_orbit
    from bounce_cli.model.flight import FlightSettings, simulate

    out = tmp_path / "exact"
    result = cli("trajectory", "--set", "sticking.min_hop_s=0", "--set", "duration_s=5",
                 "--out", out, "--quiet")
    assert result.exit_code == 0, result.output
    acc = pd.read_csv(out / "accumulations.csv")
    track = pd.read_csv(out / "trajectory.csv")
    sticking = acc[acc["case"] == "sticking"]
    assert len(sticking) >= 3 and (acc["case"] == "period-1").sum() == 0
    theta0 = 0.752318481155386
    t_end = theta0 / paper_params.omega + 5.0
    orbit = iterate_exact_orbit(theta0, 5.7, paper_params, 500,
                                until_theta=paper_params.omega * t_end)
    expected = orbit.theta[orbit.rows(STICK)] / paper_params.omega
    np.testing.assert_allclose(sticking.t_s, expected[expected <= t_end], rtol=0, atol=1e-12)
    stuck = track[(track["case"] == "sticking") & (track.state == "stuck")]
    np.testing.assert_allclose(stuck.ball_x_m, stuck.racket_x_m, atol=1e-12)
    gamma = paper_params.racket_amplitude * paper_params.omega**2 / paper_params.g
    # every stuck phase ends at the release phase asin(1/Gamma) (the last one at the run's end)
    motion = simulate(theta0, 5.7, paper_params, 5.0, FlightSettings(min_hop_s=0.0))
    assert motion.accumulations == tuple(sticking.t_s)
    ends = [b for _, b in motion.stuck_phases[:-1]]
    np.testing.assert_allclose(np.mod(paper_params.omega * np.array(ends), 2 * np.pi),
                               math.asin(1 / gamma), atol=1e-9)
    with open(out / "trajectory.png", "rb") as fh:
        assert fh.read(4) == b"\x89PNG"
    bad = cli("trajectory", "--set", "sticking.min_hop_s=0", "--set", "integrator=rk4",
              "--out", tmp_path / "rk4", "--quiet")
    user_error(bad, "exact sticking", "integrator")


def test_each_case_says_how_it_ends_whatever_its_name(tmp_path, cli):
    """The bundled cases are named after what they do at Fig. 3's model; at a reviewer's
    model (alpha 0.7, g 3.71 m/s^2, a_r 0.055 m, tau 0.8 s) 'period-1' ended stuck and
    'sticking' never stuck, and nothing said so. Each case's summary line and panel title
    say how it ends."""
    at_paper = cli("trajectory", "--out", tmp_path / "p")
    assert at_paper.exit_code == 0, at_paper.output
    said = " ".join(at_paper.stderr.split())
    assert "ends near the period-1 fixed point" in said.split("sticking:")[0]
    assert "sticking:" in said and "ends stuck on the racket" in said.split("sticking:")[1]
    other = cli("trajectory", "--out", tmp_path / "o", "--set", "model.alpha=0.7",
                "--set", "model.g=3.71", "--set", "model.racket_amplitude=0.055",
                "--set", "model.racket_period=0.8")
    assert other.exit_code == 0, other.output
    assert "ends near the period-1 fixed point" not in other.stderr.split("sticking:")[0]
    frames = {name: pd.read_csv(tmp_path / "o" / name) for name in
              ("trajectory.csv", "impacts.csv", "fixed_point.csv")}
    fig = trajectory.draw(frames)["trajectory.png"]
    titles = [ax.get_title() for ax in fig.axes if ax.get_title()]
    assert len(titles) == 2 and all("; ends " in t for t in titles)
