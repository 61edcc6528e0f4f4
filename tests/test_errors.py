"""Configs and errors as a new user meets them: one line ``bounce: error: ...``, exit 2, the
key to change, the value as the user wrote it; an editable --print-config; no output folder
left behind by a failed run."""

from __future__ import annotations

import pytest
import yaml
from typer.testing import CliRunner

from bounce_cli.cli.commands import app
from bounce_cli.runtime.config import load_config, show_value
from bounce_cli.experiments.registry import EXPERIMENTS

runner = CliRunner()


def run(*args):
    return runner.invoke(app, [str(a) for a in args])


def one_error_line(result, *needles) -> str:
    """The run failed with exit 2 and exactly one line on stderr (no leading blank line, no
    traceback, no usage box), holding each needle."""
    assert result.exit_code == 2, result.output
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("bounce: error: ")
    for needle in needles:
        assert needle in lines[0], lines[0]
    return lines[0]


# -- typer's own usage errors ------------------------------------------------------------------
@pytest.mark.parametrize("args, needles", [
    (["basin", "--jobs", "0"], ["--jobs", "(see bounce basin --help)"]),
    (["orbit", "--v0", "3"], ["Missing option", "--theta0-deg", "bounce orbit --help"]),
    (["nosuchcommand"], ["No such command", "nosuchcommand"]),
    (["basin", "--nosuchoption"], ["--nosuchoption"]),
    (["basin", "--jobs", "two"], ["--jobs", "integer"]),
])
def test_usage_errors_are_one_line_like_ours(args, needles):
    one_error_line(run(*args), *needles)


def test_help_and_version_still_exit_zero():
    assert run("--help").exit_code == 0
    assert run("basin", "--help").exit_code == 0
    assert run("--version").exit_code == 0


# -- YAML booleans and duplicate keys ---------------------------------------------------------
@pytest.mark.parametrize("command, setting, key", [
    ("fixed-point", "model.alpha=no", "model.alpha"),
    ("fixed-point", "model.alpha=yes", "model.alpha"),
    ("basin", "classify.max_iterations=on", "classify.max_iterations"),
    ("basin", "grid.v0_m_s.num=true", "grid.v0_m_s.num"),
    ("impulse", "alpha_p=[0.4, off]", "alpha_p"),
])
def test_a_yaml_boolean_where_a_number_is_expected_names_the_key(tmp_path, command, setting,
                                                                  key):
    args = [command, "--set", setting]
    if command != "fixed-point":
        args += ["--out", tmp_path / "o"]
    one_error_line(run(*args), key, "boolean")
    assert not (tmp_path / "o").exists()


def test_booleans_stay_booleans_and_numbers_numbers(tmp_path):
    from bounce_cli.experiments.basin import BasinConfig
    from bounce_cli.runtime.config import bundled_config_path

    cfg = load_config(BasinConfig, bundled_config_path("basin"),
                      ["model.alpha=0", "classify.max_iterations=7"])
    assert cfg.model.alpha == 0.0 and cfg.classify.max_iterations == 7


def test_duplicate_yaml_key_names_key_and_line(tmp_path):
    path = tmp_path / "dup.yaml"
    path.write_text("model:\n  alpha: 0.5\n  g: 9.81\n  alpha: 0.6\n")
    one_error_line(run("fixed-point", "--config", path), "duplicate key 'alpha'", "line 4",
                   str(path))
    path.write_text("model:\n  alpha: 0.5\nmodel:\n  g: 9.81\n")
    one_error_line(run("fixed-point", "--config", path), "duplicate key 'model'", "line 3")


# -- values as written ------------------------------------------------------------------------
def test_values_are_shown_without_numpy_reprs():
    np = pytest.importorskip("numpy")
    assert show_value(np.float64("nan")) == "nan"
    assert show_value(np.int64(3)) == "3"
    assert show_value(-0.2) == "-0.2" and show_value("abc") == "'abc'"


@pytest.mark.parametrize("cell, shown", [("n/a", "(got 'n/a')"), ("NA", "(got 'NA')"),
                                         ("", "(got an empty cell)"),
                                         ("abc", "(got 'abc')")])
def test_a_bad_data_cell_is_reported_as_the_file_holds_it(tmp_path, cell, shown):
    path = tmp_path / "trials.csv"
    path.write_text(f"a_r_m,tau_s\n0.1,0.5\n0.2,{cell}\n")
    line = one_error_line(run("regression", "--data", path, "--out", tmp_path / "o"),
                          "column tau_s", "data row 2", shown)
    assert "np." not in line


def test_a_data_range_error_shows_a_plain_number(tmp_path):
    path = tmp_path / "trials.csv"
    path.write_text("a_r_m,tau_s\n0.1,0.5\n-0.25,0.5\n")
    line = one_error_line(run("regression", "--data", path, "--out", tmp_path / "o"),
                          "column a_r_m", "(data row 2: -0.25)")
    assert "np." not in line


@pytest.mark.parametrize("setting, key", [
    ("design.amplitude_sd_m=0.05", "design.amplitude_sd_m"),
    ("design.phase_sd_deg=40", "design.phase_sd_deg"),
])
def test_a_regression_design_error_names_a_design_key(tmp_path, setting, key):
    line = one_error_line(run("regression", "--set", setting, "--out", tmp_path / "o",
                              "--quiet"), key)
    assert "model.racket_amplitude" not in line  # the simulated trials draw their own
    assert not (tmp_path / "o").exists()


def test_grid_size_error_has_no_leading_blank_line(tmp_path):
    one_error_line(run("basin", "--set", "limits.max_points=10", "--out", tmp_path / "o"),
                   "limits.max_points")


# -- --print-config ---------------------------------------------------------------------------
@pytest.mark.parametrize("entry", EXPERIMENTS, ids=lambda e: e.name)
def test_printed_config_loads_back_to_the_same_config(tmp_path, entry):
    result = run(entry.name, "--print-config")
    assert result.exit_code == 0, result.output
    path = tmp_path / "printed.yaml"
    path.write_text(result.stdout)
    schema = entry.load().schema
    from bounce_cli.runtime.config import bundled_config_path

    assert load_config(schema, path) == load_config(schema, bundled_config_path(entry.config))


def test_printed_trajectory_config_has_only_the_phase_key_given_and_stays_editable(tmp_path):
    printed = run("trajectory", "--print-config").stdout
    data = yaml.safe_load(printed)
    for case in data["cases"]:
        assert "theta0_rad" in case and "theta0_deg" not in case
    # the user edits the printed phase into degrees
    for case in data["cases"]:
        case["theta0_deg"] = 43.1
        del case["theta0_rad"]
    path = tmp_path / "mine.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    again = run("trajectory", "--config", path, "--print-config")
    assert again.exit_code == 0, again.output
    assert "theta0_deg: 43.1" in again.stdout and "theta0_rad" not in again.stdout


# -- no output folder left by a failed run ----------------------------------------------------
def test_a_failed_run_leaves_no_folder_it_created_but_keeps_existing_ones(tmp_path):
    out = tmp_path / "a" / "b" / "c"
    one_error_line(run("regression", "--set", "design.amplitude_sd_m=0.05", "--out", out,
                       "--quiet"))
    assert not (tmp_path / "a").exists()
    (tmp_path / "a").mkdir()
    one_error_line(run("regression", "--set", "design.amplitude_sd_m=0.05", "--out", out,
                       "--quiet"))
    assert (tmp_path / "a").is_dir() and not (tmp_path / "a" / "b").exists()


def test_an_output_folder_of_another_run_is_refused_before_any_warning(tmp_path):
    """--out holding another command's run is one error line, and no warning about the model
    comes before it (a reviewer read the warning as the reason the run failed)."""
    out = tmp_path / "out"
    result = run("stability", "--quiet", "--out", out)
    assert result.exit_code == 0, result.output
    unstable = ("--set", "model.alpha=0.7", "--set", "model.racket_amplitude=0.3",
                "--set", "grid.theta0_deg.num=5", "--set", "grid.v0_m_s.num=5")
    one_error_line(run("basin", "--quiet", *unstable, "--out", out), "different config",
                   "--force")
    forced = run("basin", "--quiet", *unstable, "--out", out, "--force")  # warned, then run
    assert forced.exit_code == 0, forced.output
    assert "bounce: warning: the period-1 fixed point is linearly unstable" in forced.stderr
    fresh = tmp_path / "a" / "b"  # no fixed point: the folder it opened is gone again
    one_error_line(run("basin", "--quiet", "--set", "model.racket_amplitude=0.01", "--out",
                       fresh), "no period-1 fixed point")
    assert not (tmp_path / "a").exists()


# -- what a new user mistypes or mixes up ------------------------------------------------------
@pytest.mark.parametrize("command, setting, suggestion", [
    ("fixed-point", "model.alpah=0.4", "(did you mean model.alpha?)"),
    ("basin", "grid.v0_m_s.nun=3", "(did you mean grid.v0_m_s.num?)"),
    ("basin", "gird.v0_m_s.num=3", "(did you mean grid?)"),
    ("trajectory", "cases.0.v0_ms=3", None),  # cases is a list: no mapping to set a key in
])
def test_an_unknown_key_suggests_the_closest_known_one(command, setting, suggestion):
    line = one_error_line(run(command, "--set", setting), setting.partition("=")[0].split(".")[0])
    if suggestion is not None:
        assert line.endswith(f"unknown key {suggestion}"), line


def test_an_unknown_key_far_from_every_known_one_gets_no_suggestion():
    line = one_error_line(run("fixed-point", "--set", "model.zzzzzz=1"), "model.zzzzzz")
    assert line.endswith("unknown key") and "did you mean" not in line


def test_an_unknown_key_in_a_list_item_is_compared_with_the_items_keys(tmp_path):
    from bounce_cli.runtime.config import ConfigError
    from bounce_cli.experiments.trajectory import EXPERIMENT as trajectory

    config = tmp_path / "t.yaml"
    config.write_text("cases:\n  - name: a\n    theta0_deg: 10\n    v0_ms: 4.8\n")
    with pytest.raises(ConfigError, match=r"cases\.0\.v0_ms: unknown key \(did you mean "
                                          r"cases\.0\.v0_m_s\?\)"):
        load_config(trajectory.schema, config)


@pytest.mark.parametrize("command, other", [("acf", "basin"), ("basin", "acf"),
                                            ("learning-data", "acf-data")])
def test_another_commands_config_names_the_command_it_belongs_to(command, other):
    from bounce_cli.runtime.config import bundled_config_path
    from bounce_cli.experiments.registry import entry

    path = bundled_config_path(entry(other).config)
    line = one_error_line(run(command, "--config", path, "--out", "unused"),
                          f"a config of bounce {other}, not of bounce {command}",
                          f"run bounce {other} --config {path}")
    assert "more problem" not in line


def test_a_config_with_a_block_no_command_has_is_reported_as_an_unknown_key(tmp_path):
    config = tmp_path / "c.yaml"
    config.write_text("model:\n  alpha: 0.5\nnoise_typo: 1\n")
    one_error_line(run("acf", "--config", config), "noise_typo: unknown key")


@pytest.mark.parametrize("command", ["fixed-point", "orbit"])
def test_a_top_level_typo_in_a_model_only_config_is_refused(tmp_path, command):
    # issue 36: `modle:` was ignored and the default alpha printed
    config = tmp_path / "c.yaml"
    config.write_text("modle: {alpha: 0.8}\n")
    args = [] if command == "fixed-point" else ["--theta0-deg", 43.1, "--v0", 4.8]
    one_error_line(run(command, "--config", config, *args),
                   "modle: unknown key (did you mean model?)")


@pytest.mark.parametrize("text, needle", [
    ("classify: {tolerence: 0.001}\n", "classify.tolerence: unknown key (did you mean "
                                         "classify.tolerance?)"),
    ("model: {alpha: 0.5}\nnoise: {q_vv: 0.04}\n", "noise.q_vv: unknown key (did you mean "
                                                       "noise.q_v?)"),
])
def test_a_typo_in_another_block_of_a_config_fixed_point_reads_is_refused(tmp_path, text,
                                                                          needle):
    # fixed-point reads the model block of any command's config: the other blocks must still
    # be some command's, at every level
    config = tmp_path / "c.yaml"
    config.write_text(text)
    one_error_line(run("fixed-point", "--config", config), needle)


@pytest.mark.slow
def test_fixed_point_still_reads_any_commands_bundled_config():
    from bounce_cli.runtime.config import bundled_config_path

    for e in EXPERIMENTS:
        if e.name == "study":  # its model block leaves alpha and g to each unit's data
            continue
        result = run("fixed-point", "--json", "--config", bundled_config_path(e.config))
        assert result.exit_code == 0, (e.name, result.output)


def test_an_unknown_analysis_in_study_settings_suggests_the_closest(tmp_path):
    config = tmp_path / "s.yaml"
    config.write_text("settings: {acff: {max_lag: 6}}\n")
    one_error_line(run("study", "--config", config, "--print-config"),
                   "'acff' is not an analysis", "(did you mean acf?)")


def test_help_shows_no_type_after_a_flag_but_the_type_of_an_option_with_a_value():
    text = run("basin", "--help").stdout
    assert "<bool>" not in text
    assert "<path>" in text and "<int range>" in text
    assert "<bool>" not in run("fixed-point", "--help").stdout


@pytest.mark.parametrize("command", [e.name for e in EXPERIMENTS])
def test_jobs_is_offered_only_where_it_spreads_work(command):
    from bounce_cli.experiments.registry import entry

    offered = "--jobs" in run(command, "--help").stdout
    assert offered == (command in ("basin", "control", "sweep", "study", "attractors")) == \
        entry(command).parallel


@pytest.mark.parametrize("command, settings, needles", [
    ("basin", ["grid.theta0_deg.num=1000000000"], ["grid.theta0_deg", "8 GB"]),
    ("basin", ["grid.theta0_deg.num=40000", "grid.v0_m_s.num=40000"],
     ["limits.max_points", "304.0 GB"]),
    ("sweep", ["basin.v0_m_s.num=1000000000"], ["basin.v0_m_s", "8 GB"]),
    ("stability", ["grid.n_ac=1000000000"], ["n_alpha x n_ac", "968 GB"]),
    ("stability", ["predictions.n_ac=1000000000"], ["predictions", "8 GB"]),
    ("learning", ["ac_points=1000000000"], ["ac_points", "8 GB"]),
    ("bifurcation", ["flip.probes=1000000000"], ["flip", "probes", "8 GB"]),
    ("continuation", ["diagram.recorded_impacts=1000000000"], ["recorded_impacts", "11.5 TB"]),
    ("simulate-recording", ["rest_s=1000000000"], ["rest_s", "1.6 TB"]),
    ("control", ["radius.gain.num=100000", "radius.rate.num=100000"], ["radius", "80 GB"]),
    ("control", ["basin.theta0_deg.num=100000", "basin.v0_m_s.num=100000"], ["basin", "80 GB"]),
    ("control", ["fit.simulate.impacts_per_trial=1000000000"], ["fit.simulate", "480 GB"]),
    ("control", ["correlations.bounces=1000000000"], ["correlations", "960 GB"]),
    ("acf", ["max_lag=1000000000"], ["max_lag", "32 GB"]),
    ("acf", ["trials.duration_s=1000000000"], ["stochastic map", "87.3 GB", "duration_s"]),
    ("acf", ["long_runs.bounces=1000000000"], ["stochastic map", "1.6 TB"]),
    ("regression", ["stochastic_map.duration_s=1000000000"], ["stochastic map", "28.8 GB"]),
])
def test_a_size_that_would_not_fit_in_memory_is_refused_before_allocating(
        tmp_path, command, settings, needles):
    """A config value that sizes an array (a grid's points, a run's bounces, lags, samples):
    one line with the memory it would need, exit 2, nothing written; before, each was a
    MemoryError traceback (or an allocation of many GB)."""
    out = tmp_path / "out"
    result = run(command, "--quiet", "--out", out, *[a for s in settings for a in ("--set", s)])
    one_error_line(result, "would need" if "max_points" not in needles[0] else "memory",
                   *needles)
    assert not out.exists()


@pytest.mark.parametrize("value", ["1e9", "inf", "0.2"])
def test_a_racket_period_sd_beyond_a_trial_period_is_one_line_in_simulate_study(tmp_path,
                                                                                value):
    """simulate-study's racket.period_sd_s (cycle-to-cycle SD) above 10 % of the shortest
    trial period a subject draws: refused before any trial is simulated, one line, no folder
    (it was a pydantic traceback-like block from one trial's config)."""
    out = tmp_path / "sim"
    result = run("simulate-study", "--out", out, "--set", "subjects.count=1", "--set",
                 "trials=1", "--set", "duration_s=5", "--set", f"racket.period_sd_s={value}")
    one_error_line(result, "racket.period_sd_s")
    assert not out.exists()


def test_a_trial_config_rule_broken_by_one_subject_is_one_line(tmp_path, monkeypatch):
    """A rule of one trial's recording config that the study's own checks do not cover (here
    a subject drawn with a short racket period, below the study's mean) is one line naming the
    trial and the key, never pydantic's block of lines."""
    from bounce_cli.experiments import simulate_study

    plan = simulate_study.trial_plan

    def short_periods(config):
        table = plan(config)
        table["racket_period_s"] = table["racket_period_s"] * 0.5
        return table

    monkeypatch.setattr(simulate_study, "trial_plan", short_periods)
    out = tmp_path / "sim"
    result = run("simulate-study", "--out", out, "--set", "subjects.count=1", "--set",
                 "trials=1", "--set", "duration_s=5", "--set", "racket.period_sd_s=0.05")
    one_error_line(result, "s1 ", "trial 1", "racket.period_sd_s")
    assert not out.exists()


@pytest.mark.parametrize("g", [-3.0, 0.0, float("nan"), float("inf")])
def test_a_fitted_g_that_is_no_fall_gets_a_hint_not_a_math_error(g):
    """The fuzzer's find (a ball sample of 1e40): a fitted g <= 0 or not finite has no power
    of ten to blame; the hint says to check the ball's column instead of raising."""
    from bounce_cli.experiments.extract import unit_slip_hint

    assert "columns.ball" in unit_slip_hint(g)


@pytest.mark.parametrize("theta, v, needle", [
    ("43", "1e200", "--v0: 1e+200 m/s is beyond what the map can follow"),
    ("1e308", "5", "--theta0-deg: 1e+308 deg is beyond what the map can follow"),
])
def test_an_orbit_launched_beyond_reach_is_one_line(theta, v, needle):
    """--v0 1e200 printed numpy's overflow warnings and a NaN row (a new-user review)."""
    one_error_line(run("orbit", "--theta0-deg", theta, "--v0", v), needle)


@pytest.mark.parametrize("args, key", [
    (["virtual", "--racket", "sine", "--headless", "--set", "subject=a b"], "subject"),
    (["simulate-study", "--set", "conditions=[{name: a/b}]"], "conditions.0.name"),
])
def test_a_name_that_cannot_name_files_is_said_in_words_not_as_a_regex(args, key, cli,
                                                                       user_error, tmp_path):
    """'String should match pattern '^[A-Za-z0-9._\\-]+$'' told a user the rule in a regex."""
    result = cli(*args, "--out", tmp_path / "o")
    user_error(result, f"{key}: letters, digits, '.', '_' and '-' only: it names files")
    assert "pattern" not in result.output
