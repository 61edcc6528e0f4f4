"""The CLI through typer's CliRunner: exit codes, one-line errors, no tracebacks."""

import io
import json
import math
import os

import numpy as np
import pandas as pd
import pytest

from bounce_cli import __version__


def test_version_and_help(cli):
    result = cli("--version")
    assert result.exit_code == 0 and __version__ in result.stdout
    result = cli("--help")
    assert result.exit_code == 0
    for command in ("fixed-point", "orbit"):
        assert command in result.stdout


def test_fixed_point_json_paper_values(cli):
    result = cli("fixed-point", "--json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert set(data) == {"exists", "v_m_s", "theta_rad", "theta_deg", "ac_g", "eigenvalues",
                         "spectral_radius", "regime", "stable"}
    assert data["exists"] is True
    assert round(data["v_m_s"], 3) == 4.513
    assert round(data["theta_deg"], 2) == 42.76
    assert round(data["ac_g"], 3) == -0.968
    assert data["regime"] == "complex" and data["stable"] is True
    assert data["spectral_radius"] == pytest.approx(0.5)
    (re1, im1), (re2, im2) = data["eigenvalues"]
    assert math.hypot(re1, im1) == pytest.approx(0.5) and im1 == pytest.approx(-im2)
    assert data["theta_rad"] == pytest.approx(math.radians(data["theta_deg"]))


def test_fixed_point_table_and_overrides(cli):
    result = cli("fixed-point", "--set", "model.alpha=0.6")
    assert result.exit_code == 0
    assert "v~" in result.stdout and "4.5126" in result.stdout  # v~ does not depend on alpha
    result = cli("fixed-point", "--json", "--set", "model.racket_period=0.5")
    assert json.loads(result.stdout)["v_m_s"] == pytest.approx(math.pi * 9.81 / (2 * math.pi / 0.5))


def test_fixed_point_json_without_a_fixed_point_says_so_in_json_and_exits_1(cli):
    # eq. 8: cos(theta~) = g^2 (1 - alpha) / (... a_r ...) grows as 1 / a_r: at a_r = 0.01 m
    # it is 22.02 (> 1, no fixed point); the threshold 0.2202 m is a_r * cos(theta~)
    result = cli("fixed-point", "--json", "--set", "model.racket_amplitude=0.01")
    assert result.exit_code == 1, result.output
    data = json.loads(result.stdout)
    assert data["exists"] is False and "no period-1 fixed point" in data["reason"]
    assert data["cos_theta"] == pytest.approx(22.02, abs=0.005)
    assert data["min_racket_amplitude_m"] == pytest.approx(0.01 * data["cos_theta"])
    at_threshold = cli("fixed-point", "--json", "--set",
                       f"model.racket_amplitude={data['min_racket_amplitude_m'] * 1.0001}")
    assert at_threshold.exit_code == 0 and json.loads(at_threshold.stdout)["exists"] is True
    # a bad key is still a user error, not an answer
    assert cli("fixed-point", "--json", "--set", "model.nope=1").exit_code == 2


def test_at_alpha_0_the_fixed_point_exists_where_the_racket_outruns_gravity(cli):
    """alpha 0: the ball leaves with the racket's own velocity, so it separates only where the
    racket decelerates faster than gravity (AC < -1 g). The answer hung on the last bit of a
    zero relative velocity: 'no orbit' at 1.05, 1.1, 1.3 times eq. 8's least amplitude,
    'exists' at 1.2 and 1.5 (a new-user review). Now AC decides, and the flight is then
    checked from a velocity 1e-9 above the racket's."""
    least = math.pi * 9.81 / (2 * math.pi / 0.92) ** 2
    for factor in (1.05, 1.1, 1.2, 1.3, 1.5, 1.8, 3.0):
        data = json.loads(cli("fixed-point", "--json", "--set", "model.alpha=0", "--set",
                              f"model.racket_amplitude={factor * least}").stdout)
        assert data["exists"] is True and data["ac_g"] < -1.0, (factor, data)
    data = json.loads(cli("fixed-point", "--json", "--set", "model.alpha=0", "--set",
                          f"model.racket_amplitude={1.01 * least}").stdout)
    assert data["exists"] is False and "cannot leave the racket" in data["reason"]
    assert "decelerates slower than gravity" in data["reason"]


@pytest.mark.parametrize("alpha, amplitude_factor, needle", [
    (0.0, 1.01, "cannot leave the racket"),  # alpha 0: the ball leaves at the racket's speed
    (0.01, 1.0001, "meets the racket again after 0.0249 of a racket cycle"),
])
def test_eq8_s_point_where_the_ball_falls_back_at_once_is_no_fixed_point(
        cli, user_error, alpha, amplitude_factor, needle):
    """Eq. 8 solved, but the racket decelerates slower than gravity (AC > -1 g) and a nearly
    dead impact gives the ball too little lead: the next impact comes at once, not a racket
    cycle later. A review got "exists, stable" for it; eq. 8's point is no orbit of the map."""
    amplitude = amplitude_factor * math.pi * (1 - alpha) / (1 + alpha) * 9.81 / (
        2 * math.pi / 0.92) ** 2
    args = ["--set", f"model.alpha={alpha}", "--set", f"model.racket_amplitude={amplitude}"]
    result = cli("fixed-point", "--json", *args)
    assert result.exit_code == 1, result.output
    data = json.loads(result.stdout)
    assert data["exists"] is False and needle in data["reason"], data
    user_error(cli("fixed-point", *args), needle)
    # a lively ball (alpha 0.05) at the same small lead flies its racket cycle
    alive = cli("fixed-point", "--json", "--set", "model.alpha=0.05", "--set",
                f"model.racket_amplitude={amplitude * 1.1}")
    assert json.loads(alive.stdout)["exists"] is True


@pytest.mark.parametrize(
    "args, needles",
    [
        (["--set", "model.alpha=1.5"], ["model.alpha", "less than 1"]),
        (["--set", "model.racket_amplitude=0.01"], ["no period-1 fixed point", "racket_amplitude"]),
        (["--set", "model.nope=1"], ["model.nope", "unknown key"]),
        (["--set", "model.g=-3"], ["model.g", "greater than 0"]),
        (["--set", "nope=1"], ["nope"]),
        (["--set", "model.alpha"], ["expected dotted.key=value"]),
    ],
)
def test_fixed_point_user_errors(args, needles, cli, user_error):
    user_error(cli("fixed-point", *args), *needles)


def test_config_file_errors(tmp_path, cli, user_error):
    wrong_type = tmp_path / "wrong.yaml"
    wrong_type.write_text("model:\n  racket_period: fast\n")
    user_error(cli("fixed-point", "--config", wrong_type), "model.racket_period", "number")
    malformed = tmp_path / "bad.yaml"
    malformed.write_text("model: {alpha: 0.5\n")
    user_error(cli("fixed-point", "--config", malformed), "malformed YAML")
    user_error(cli("fixed-point", "--config", tmp_path / "none.yaml"), "not found")


def test_fixed_point_reads_the_model_block_of_any_config(tmp_path, cli):
    cfg = tmp_path / "other.yaml"
    cfg.write_text("model:\n  alpha: 0.42\n  g: 5.8\n  racket_amplitude: 0.065\n"
                   "  racket_period: 0.55\nnoise: {q_v: 0.04}\n")
    result = cli("fixed-point", "--json", "--config", cfg)
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["v_m_s"] == pytest.approx(math.pi * 5.8 * 0.55 / (2 * math.pi))


def read_orbit_csv(result):
    return pd.read_csv(io.StringIO(result.stdout))


def test_orbit_period1_settles_on_fixed_point(cli):
    result = cli("orbit", "--theta0-deg", 43.1, "--v0", 4.8, "-n", 40, "--csv")
    assert result.exit_code == 0, result.output
    df = read_orbit_csv(result)
    assert list(df.columns) == ["k", "t_s", "theta_rad", "theta_deg", "v_m_s", "flight_s",
                                "event"]
    assert df.event.tolist() == ["start"] + ["impact"] * 40
    assert len(df) == 41 and df.k.tolist() == list(range(41))
    assert df.iloc[0].v_m_s == 4.8 and df.iloc[0].theta_deg == pytest.approx(43.1)
    assert math.isnan(df.iloc[0].flight_s)
    last = df.iloc[-1]
    assert last.v_m_s == pytest.approx(4.5126, abs=1e-4)
    assert last.theta_deg == pytest.approx(42.763, abs=1e-3)
    assert last.flight_s == pytest.approx(0.92, abs=1e-4)
    assert (df.theta_deg.between(0, 360)).all()
    assert (df.theta_rad.diff().dropna() > 0).all()  # unwrapped
    assert df.t_s.iloc[-1] == pytest.approx(df.theta_rad.iloc[-1] / (2 * math.pi / 0.92))
    assert result.stderr.strip() == ""


def test_orbit_sticking_stops_early_with_a_note(cli):
    result = cli("orbit", "--theta0-deg", 43.1, "--v0", 5.7, "-n", 40, "--csv")
    assert result.exit_code == 0
    df = read_orbit_csv(result)
    assert len(df) < 41
    assert df.flight_s.iloc[-1] < 1e-3
    assert "sticking" in result.stderr
    # a longer shortest hop stops earlier
    coarse = read_orbit_csv(cli("orbit", "--theta0-deg", 43.1, "--v0", 5.7, "-n", 40, "--csv",
                                "--min-hop-s", 0.05))
    assert len(coarse) < len(df)


def test_orbit_below_racket(cli):
    result = cli("orbit", "--theta0-deg", 0, "--v0", 0.5, "--csv")
    assert result.exit_code == 0
    assert len(read_orbit_csv(result)) == 1
    assert "below the racket" in result.stderr


def test_orbit_table_output(cli):
    result = cli("orbit", "--theta0-deg", 43.1, "--v0", 4.8, "-n", 3)
    assert result.exit_code == 0
    assert "theta_deg" in result.stdout and "4.80000" in result.stdout


def test_python_dash_m_entry_point():
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-m", "bounce_cli", "--version"], capture_output=True,
                         text=True, cwd=os.path.dirname(os.path.dirname(__file__)))
    assert out.returncode == 0 and __version__ in out.stdout


@pytest.mark.slow
def test_unstable_fixed_point_warns_in_one_line(tmp_path, cli):
    # period 0.8 s: AC = -1.57 g, beyond the flip boundary -1.11 g (eq. 14)
    result = cli("basin", "--set", "model.racket_period=0.8", "--set", "grid.theta0_deg.num=6",
                 "--jobs", 1,
                 "--set", "grid.v0_m_s.num=6", "--out", tmp_path / "b", "--quiet")
    assert result.exit_code == 0
    warnings = [line for line in result.stderr.splitlines() if "warning" in line]
    assert len(warnings) == 1 and "unstable" in warnings[0] and "2.16" in warnings[0]
    stable = cli("basin", "--set", "grid.theta0_deg.num=6", "--set", "grid.v0_m_s.num=6",
                 "--jobs", 1,
                 "--out", tmp_path / "s", "--quiet")
    assert "warning" not in stable.stderr


def test_rk4_step_is_bounded(cli, user_error):
    user_error(cli("trajectory", "--set", "rk4_step_s=0.02", "--print-config"),
                      "rk4_step_s")


def test_orbit_iterates_where_there_is_no_fixed_point(cli, user_error):
    # a_r = 0.01 m: eq. 8 gives cos(theta~) = 22 (no period-1 orbit); the ball dies onto the
    # racket, each hop shorter than the last, until one is shorter than 1 ms
    result = cli("orbit", "--theta0-deg", 43.1, "--v0", 4.8, "-n", 40, "--csv",
                 "--set", "model.racket_amplitude=0.01")
    assert result.exit_code == 0, result.output
    df = read_orbit_csv(result)
    assert 3 < len(df) < 41
    assert (df.flight_s.diff().dropna() < 0).all()
    notes = result.stderr.splitlines()
    assert len(notes) == 2
    assert notes[0].startswith("note: no period-1 fixed point") and "22.02" in notes[0]
    assert "sticking" in notes[1]
    # the same rows as the engine's map from the same start
    from bounce_cli.model.maps import iterate_orbit
    from bounce_cli.model.params import ModelParams

    orbit = iterate_orbit(math.radians(43.1), 4.8, ModelParams(0.5, 9.81, 0.01, 0.92), 40, 1e-3)
    assert df.v_m_s.to_numpy() == pytest.approx(orbit.v, rel=1e-12)
    # fixed-point still refuses these parameters
    user_error(cli("fixed-point", "--set", "model.racket_amplitude=0.01"),
                      "no period-1 fixed point")


def test_orbit_at_an_unstable_fixed_point_has_no_note_about_it(cli):
    # alpha 0.5, period 0.8 s: the fixed point exists (unstable): the orbit runs all impacts
    result = cli("orbit", "--theta0-deg", 60, "--v0", 4.0, "-n", 30, "--csv",
                 "--set", "model.racket_period=0.8")
    assert result.exit_code == 0, result.output
    assert "no period-1 fixed point" not in result.stderr


@pytest.mark.parametrize("name", ["trajectory", "basin", "stability", "regression", "acf",
                                  "impulse"])
def test_print_config_prints_the_resolved_config_and_runs_nothing(name, tmp_path, monkeypatch,
                                                                  cli):
    """--print-config: the resolved config as YAML (the bundled file with defaults filled in
    and --set applied), a file that loads back to the same config; nothing is written."""
    import yaml

    from bounce_cli.runtime.config import bundled_config_path, load_config
    from bounce_cli.experiments.registry import entry

    monkeypatch.chdir(tmp_path)
    schema = entry(name).load().schema
    result = cli(name, "--print-config", "--set", "model.g=9.8")
    assert result.exit_code == 0, result.output
    printed = yaml.safe_load(result.stdout)
    expected = load_config(schema, bundled_config_path(name), ["model.g=9.8"])
    assert schema.model_validate(printed) == expected  # loads back to the same config
    assert printed["model"]["g"] == 9.8
    (tmp_path / "printed.yaml").write_text(result.stdout)
    again = cli(name, "--print-config", "--config", tmp_path / "printed.yaml")
    assert again.exit_code == 0 and again.stdout == result.stdout
    assert list(tmp_path.iterdir()) == [tmp_path / "printed.yaml"]  # no results folder


@pytest.mark.parametrize("command", ["stability", "reproduce"])
@pytest.mark.parametrize("empty", ["", "  "])
def test_an_empty_out_is_refused_not_the_current_folder(command, empty, tmp_path, monkeypatch,
                                                        cli, user_error):
    """``--out "$DIR"`` with DIR unset: Path("") is ".", so the run would write into the
    current folder; refused (``--out .`` says that on purpose)."""
    monkeypatch.chdir(tmp_path)
    result = cli(command, "--quiet", "--out", empty)
    user_error(result, "--out", "an empty path")
    assert list(tmp_path.iterdir()) == []


def test_a_rule_between_keys_broken_by_set_blames_set_not_the_file(cli, user_error, tmp_path):
    """A model validator's error has no key of its own: when its message names a key given
    with --set, the line says --set (the bundled file is fine), without "(top level)"."""
    result = cli("sweep", "--quiet", "--out", tmp_path / "o", "--set", "basin.v0_m_s.num=2")
    user_error(result, "--set: basin.v0_m_s.num must be at least measures.entropy_box")
    assert "sweep.yaml" not in result.output and "top level" not in result.output


@pytest.mark.slow
def test_the_summary_is_not_wrapped_when_not_on_a_terminal(cli, tmp_path):
    """A log file (stderr redirected) keeps one line per result, however long."""
    out = tmp_path / ("a-long-folder-name-" * 4)
    result = cli("stability", "--out", out)
    assert result.exit_code == 0, result.output
    wrote = [line for line in result.output.splitlines() if line.startswith("wrote ")]
    assert len(wrote) == 1 and len(wrote[0]) > 120 and wrote[0].endswith("run.json")


def test_orbit_exact_sticking_is_a_locked_orbit_with_events(cli):
    """--min-hop-s 0 (Fig. 3 bottom): impacts, then stick (accumulation point, with the
    number of resolved impacts of its chatter) and release at asin(1/Gamma) every racket
    cycle; the note calls it locked with Lyapunov exponent -inf."""
    result = cli("orbit", "--theta0-deg", 43.1, "--v0", 5.7, "--impacts", 200,
                 "--min-hop-s", 0, "--csv")
    assert result.exit_code == 0, result.output
    df = read_orbit_csv(result)
    assert list(df.columns) == ["k", "t_s", "theta_rad", "theta_deg", "v_m_s", "flight_s",
                                "event", "chatter_impacts", "tail_error_s"]
    assert df.event.iloc[0] == "start" and df.k.iloc[-1] == 200
    assert set(df.event) == {"start", "impact", "stick", "release"}
    sticks, releases = df[df.event == "stick"], df[df.event == "release"]
    assert len(sticks) >= 10 and len(releases) >= 10
    gamma = 0.30 * (2 * math.pi / 0.92) ** 2 / 9.81
    assert releases.theta_deg.to_numpy() == pytest.approx(math.degrees(math.asin(1 / gamma)))
    assert np.diff(releases.t_s.to_numpy()) == pytest.approx(0.92)
    assert (sticks.chatter_impacts > 5).all() and (sticks.tail_error_s < 1e-12).all()
    # stick and release rows carry the racket's velocity
    racket_v = 0.30 * 2 * math.pi / 0.92 * np.cos(np.radians(releases.theta_deg))
    assert releases.v_m_s.to_numpy() == pytest.approx(racket_v)
    assert "locked orbit: period 1 racket cycle" in result.stderr
    assert "-inf" in result.stderr


def test_exact_sticking_with_racket_control_is_a_one_line_error(cli, user_error, tmp_path):
    """Exact sticking is implemented for the passive racket only: orbit, basin and trajectory
    say so instead of silently ignoring min_hop_s 0."""
    control = ("--set", "model.control.gain=0.7")
    user_error(cli("orbit", "--theta0-deg", 43.1, "--v0", 5.7, "--min-hop-s", 0, *control),
               "exact sticking", "model.control")
    user_error(cli("basin", "--set", "classify.min_hop_s=0", *control, "--out",
                   tmp_path / "b", "--quiet"), "classify.min_hop_s", "model.control")
    user_error(cli("trajectory", "--set", "sticking.min_hop_s=0", *control, "--out",
                   tmp_path / "t", "--quiet"), "sticking.min_hop_s", "model.control")
    assert not (tmp_path / "b").exists() and not (tmp_path / "t").exists()


@pytest.mark.parametrize("command", [["fixed-point"], ["orbit", "--theta0-deg", "30", "--v0", "3"]])
@pytest.mark.parametrize("settings", [["model.g=1e308", "model.racket_period=1e-300"],
                                      ["model.racket_period=1e-170"],
                                      ["model.racket_period=1e300"]])
def test_extreme_parameters_are_one_line_naming_them(cli, user_error, command, settings):
    args = [a for s in settings for a in ("--set", s)]
    user_error(cli(*command, *args), "racket_period", "SI units")


@pytest.mark.parametrize("args", [["fixed-point"], ["fixed-point", "--json"],
                                  ["orbit", "--theta0-deg", "30", "--v0", "3", "--csv"],
                                  ["basin", "--print-config"]])
@pytest.mark.slow
def test_stdout_to_a_full_device_is_one_line(args):
    """``bounce fixed-point > /dev/full``: one line and exit 2, not a traceback."""
    import subprocess
    import sys

    with open("/dev/full", "w") as full:
        done = subprocess.run([sys.executable, "-m", "bounce_cli", *args], stdout=full,
                              stderr=subprocess.PIPE, text=True, timeout=120)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1, done.stderr[-3000:]
    assert lines[0] == "bounce: error: cannot write to standard output: No space left on " \
        "device", lines[0]

