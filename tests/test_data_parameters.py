"""The --data analyses at the data's own parameters: the racket (mean period and amplitude of
the impacts), alpha (``alpha_measured``, else the events' ``alpha``) and g (``setup.csv``, else
a ``g_m_s2`` column), unless the user set model.alpha / model.g (``--set`` or their own
``--config``; a bundled config's values are not the user's)."""

import json

import numpy as np
import pandas as pd
import pytest

from bounce_cli.runtime.config import bundled_config_path, keys_set_by_user, load_config
from bounce_cli.data.data_parameters import alpha_from_data, data_model
from bounce_cli.model.control import PeriodController
from bounce_cli.analysis.control_design import simulate_perturbation_trials
from bounce_cli.analysis.data_stats import simulate_impacts
from bounce_cli.model.linear import stability
from bounce_cli.model.params import ModelParams
from bounce_cli.experiments import learning, regression
from bounce_cli.experiments.base import RunOptions
from bounce_cli.data.impacts import impacts_frame, read_impacts
from bounce_cli.data.setup_table import SetupQuantity, setup_frame, setup_path

#: a lab's set-up far from every bundled config (acf's 0.42 / 5.8, the others' 0.5 / 9.81,
#: racket 0.30 m / 0.92 s)
LAB = ModelParams(alpha=0.55, g=9.5, racket_amplitude=0.11, racket_period=0.60)
ACF_FAST = ["--set", "data_analysis.trust_repetitions=20", "--set",
            "data_analysis.trust_bounces=[200]"]


def lab_table(tmp_path, params=LAB, with_setup=True, name="impacts.csv", seed=3):
    """Impacts simulated at ``params`` with the events' alpha column and, beside the table,
    a setup.csv holding the set-up's g (no g_m_s2 column: the file is the only source)."""
    sim = simulate_impacts(params, 0.02, 0.02, 4, 120, seed=seed)
    frame = impacts_frame(sim, params).drop(columns="g_m_s2")
    path = tmp_path / name
    frame.to_csv(path, index=False)
    if with_setup:
        setup_frame([SetupQuantity("g_m_s2", params.g, 0.01, 300, "flights")]).to_csv(
            setup_path(path), index=False)
    return path


def summary(result) -> str:
    return " ".join(result.stderr.split())


@pytest.mark.slow
def test_acf_data_runs_the_model_at_the_datas_alpha_and_g(tmp_path, cli):
    """The bundled acf config (alpha 0.42, g 5.8) is not the user's: with --data the model is
    the data's (events' alpha 0.55, setup.csv's g 9.5), printed and recorded in run.json."""
    path = lab_table(tmp_path)
    out = tmp_path / "out"
    result = cli("acf", "--data", path, "--out", out, *ACF_FAST)
    assert result.exit_code == 0, result.output
    text = summary(result)
    assert "model at the data's alpha 0.55 (events, median of 480 impacts)" in text
    assert "g 9.50 m/s^2 (measured, setup.csv)" in text
    stab = pd.read_csv(out / "stability_data.csv").set_index(["quantity", "source"])
    truth = stability(LAB)
    assert stab.loc[("lambda_plus_re", "model_eq10"), "estimate"] == pytest.approx(
        truth.eigenvalues[0].real, rel=1e-9)
    v_fixed = stab.loc[("v_fixed", "model_eq7"), "estimate"]
    assert v_fixed == pytest.approx(LAB.fixed_point().v_m_s, rel=2e-3)  # the data's racket
    manifest = json.loads((out / "run.json").read_text())
    assert manifest["model_at_data"]["alpha"] == {
        "value": 0.55, "source": "events", "n": 480, "detail": "median of 480 impacts"}
    assert manifest["model_at_data"]["g"]["source"] == "measured"
    assert manifest["model_at_data"]["g"]["value"] == 9.5


@pytest.mark.slow
def test_a_value_the_user_sets_wins_and_is_printed_as_set(tmp_path, cli):
    path = lab_table(tmp_path)
    out = tmp_path / "out"
    result = cli("acf", "--data", path, "--out", out, "--set", "model.alpha=0.5", *ACF_FAST)
    assert result.exit_code == 0, result.output
    assert "model at alpha 0.5 (set), g 9.50 m/s^2 (measured, setup.csv)" in (
        summary(result))
    stab = pd.read_csv(out / "stability_data.csv").set_index(["quantity", "source"])
    at = ModelParams(0.5, 9.5, *stab.loc[[("racket_amplitude", "data"), ("racket_period", "data")],
                                         "estimate"])
    assert stab.loc[("theta_fixed", "model_eq8"), "estimate"] == pytest.approx(
        at.fixed_point().theta_deg, rel=1e-9)
    # the user's own config: a key written there is set, one left out is the data's
    own = tmp_path / "mine.yaml"
    own.write_text("model:\n  g: 9.6\n")
    result = cli("acf", "--config", own, "--data", path, "--out", tmp_path / "o2", *ACF_FAST)
    assert result.exit_code == 0, result.output
    assert "alpha 0.55 (events, median of 480 impacts), g 9.60 m/s^2 (set)" in summary(result)


@pytest.mark.slow
def test_neither_in_the_data_nor_set_is_one_line_naming_both_ways(tmp_path, cli, user_error):
    path = lab_table(tmp_path, with_setup=False)
    bare = tmp_path / "bare.csv"
    pd.read_csv(path).drop(columns=["alpha"]).to_csv(bare, index=False)
    for command in ("acf", "learning", "regression"):
        result = cli(command, "--data", bare, "--out", tmp_path / command)
        user_error(result, str(bare), "alpha_measured or alpha column", "setup.csv",
                   "--set model.alpha=VALUE", "--set model.g=VALUE")
        assert not (tmp_path / command).exists()
    # setting them is enough
    result = cli("learning", "--data", bare, "--out", tmp_path / "l", "--quiet",
                 "--set", "model.alpha=0.55", "--set", "model.g=9.5")
    assert result.exit_code == 0, result.output


def test_alpha_measured_first_over_the_unperturbed_impacts():
    frame = pd.DataFrame({"alpha": [0.5, 0.5, 0.3, 0.5], "perturbed": [False, False, True, False],
                          "alpha_measured": [0.48, 0.52, 0.31, np.nan]})
    found = alpha_from_data(frame)
    assert (found.source, found.n) == ("measured", 2)
    assert found.value == pytest.approx(0.50)  # not 0.437 with the perturbed impact
    events = alpha_from_data(frame.drop(columns="alpha_measured"))
    assert (events.source, events.value, events.n) == ("events", 0.5, 3)
    assert alpha_from_data(frame.drop(columns=["alpha", "alpha_measured"])) is None


def test_g_from_a_column_when_there_is_no_setup_file(tmp_path):
    path = lab_table(tmp_path, with_setup=False)
    frame = pd.read_csv(path).assign(g_m_s2=9.4)
    frame.to_csv(path, index=False)
    impacts = read_impacts(path)
    model = load_config(learning.LearningConfig, bundled_config_path("learning")).model
    found = data_model(impacts, model, frozenset(), [path])
    assert found.g.source == "column" and found.g.value == pytest.approx(9.4, rel=1e-12)
    library = data_model(impacts, model, None, [path])  # library use: the config's values
    assert (library.alpha.source, library.g.value) == ("config", model.g)


def test_learning_and_regression_use_the_datas_alpha_and_g(tmp_path):
    """Neither reads the config's 0.5 / 9.81 when the data say 0.55 / 9.5."""
    path = lab_table(tmp_path)
    options = RunOptions(model_set_by_user=frozenset())
    cfg = load_config(learning.LearningConfig, bundled_config_path("learning"),
                      [f"data={path}", "min_bounces=10"])
    frames = learning.run(cfg, options).frames
    curve = frames["model_curve.csv"]
    assert set(curve["alpha"]) == {0.55} and set(curve["g_m_s2"]) == {9.5}
    assert options.record["model_at_data"]["g"]["source"] == "measured"
    trials = [pd.read_csv(lab_table(tmp_path, ModelParams(0.55, 9.5, 0.11 * (tau / 0.6) ** 2, tau),
                                    name=f"t{tau}.csv"))
              for tau in (0.5, 0.6, 0.7)]
    for tau, frame in zip((0.5, 0.6, 0.7), trials):
        frame["trial"] = [f"tau{tau}-{t}" for t in frame["trial"]]
    pd.concat(trials).to_csv(path, index=False)  # setup.csv beside it: the last one's, g 9.5
    cfg = load_config(regression.RegressionConfig, bundled_config_path("regression"),
                      [f"data={path}"])
    fit = regression.run(cfg, RunOptions(model_set_by_user=frozenset())).frames["fit.csv"]
    assert (fit["alpha"].iloc[0], fit["g"].iloc[0]) == (0.55, 9.5)


def test_keys_set_by_user():
    assert keys_set_by_user(None, ["data=x.csv"]) == {"data"}
    assert keys_set_by_user(None, ["model={g: 9.7}", "model.alpha=0.5"]) == {
        "model.g", "model.alpha"}


def test_a_config_file_sets_only_the_keys_that_differ_from_the_bundled_one(tmp_path):
    """A leaf of the user's file equal to the bundled config's value is no choice (a printed
    config holds every one); one that differs is; a --set always is."""
    bundled = load_config(learning.LearningConfig, bundled_config_path("learning"))
    own = tmp_path / "own.yaml"
    own.write_text(f"model:\n  alpha: {bundled.model.alpha}\n  g: 9.6\n")
    defaults = bundled.model_dump(mode="json")
    assert bundled.model.g != 9.6
    assert keys_set_by_user(own, [], defaults) == {"model.g"}
    assert keys_set_by_user(own, [f"model.alpha={bundled.model.alpha}"], defaults) >= {
        "model.alpha", "model.g"}
    assert keys_set_by_user(own, []) >= {"model.alpha", "model.g"}  # no defaults: every leaf


@pytest.mark.slow
def test_a_printed_config_loaded_back_leaves_the_data_its_alpha_and_g(tmp_path, cli):
    """--print-config writes every key of the resolved config, model.alpha and model.g among
    them; loaded back with --config they counted as set by the user, so the data's alpha 0.55
    and g 9.5 were replaced by the bundled 0.42 / 5.8 without a word. Now a printed default is
    no choice, and a value edited in the printout is."""
    path = lab_table(tmp_path)
    printed = cli("acf", "--print-config")
    assert printed.exit_code == 0, printed.output
    config = tmp_path / "printed.yaml"
    config.write_text(printed.stdout)
    assert "alpha:" in printed.stdout and "g:" in printed.stdout
    result = cli("acf", "--config", config, "--data", path, "--out", tmp_path / "o", *ACF_FAST)
    assert result.exit_code == 0, result.output
    assert "model at the data's alpha 0.55 (events, median of 480 impacts), g 9.50 m/s^2 " \
           "(measured, setup.csv)" in summary(result)
    assert json.loads((tmp_path / "o" / "run.json").read_text())["model_at_data"]["g"][
        "source"] == "measured"
    edited = tmp_path / "edited.yaml"
    edited.write_text(printed.stdout.replace("alpha: 0.42", "alpha: 0.5", 1))
    assert edited.read_text() != printed.stdout
    result = cli("acf", "--config", edited, "--data", path, "--out", tmp_path / "e", *ACF_FAST)
    assert result.exit_code == 0, result.output
    assert "model at alpha 0.5 (set), g 9.50 m/s^2 (measured, setup.csv)" in (
        summary(result))


@pytest.mark.slow
def test_control_data_computes_everything_at_the_datas_racket(tmp_path, cli):
    """control --data at a lab's racket (0.11 m, 0.60 s) and alpha 0.55: at the config's
    racket (0.30 m, 0.92 s) alpha 0.55 is unstable (spectral radius 1.04), which made the
    old code refuse with an eq. 19 error; every table is now at the data's model."""
    data = pd.DataFrame(simulate_perturbation_trials(
        LAB, PeriodController(0.6, 0.7), n_trials=16, impacts_per_trial=60,
        velocity_noise_sd=0.05, phase_noise_sd=0.02, period_noise_sd=0.005, seed=9))
    data["racket_amplitude_m"] = LAB.racket_amplitude
    path = tmp_path / "impacts.csv"
    data.to_csv(path, index=False)
    setup_frame([SetupQuantity("g_m_s2", LAB.g, 0.01, 300)]).to_csv(setup_path(path),
                                                                    index=False)
    fast = ["basin.theta0_deg.num=30", "basin.v0_m_s.num=30", "radius.gain.num=21",
            "radius.rate.num=21", "radius.zoom_num=11", "threshold.scan_step=0.05",
            "threshold.bisection_tolerance=1e-2", "correlations.runs=4",
            "correlations.bounces=100"]
    out = tmp_path / "out"
    result = cli("control", "--data", path, "--out", out,
                 *sum((["--set", s] for s in fast), []))
    assert result.exit_code == 0, result.output
    assert "every result at the data's racket a_r = 0.11 m" in summary(result)
    fit = pd.read_csv(out / "fit.csv").set_index("quantity")
    tau = fit.loc["model_racket_period", "estimate"]
    at_data = ModelParams(0.55, LAB.g, LAB.racket_amplitude, tau)
    eigen = pd.read_csv(out / "eigen.csv").set_index("model")
    truth = stability(at_data)
    assert eigen.loc["passive", "lambda1_re"] == pytest.approx(truth.eigenvalues[0].real,
                                                               abs=1e-9)
    impulse = pd.read_csv(out / "impulse.csv")
    v_stationary = (impulse.v_m_s - impulse.dv_m_s).to_numpy()
    assert v_stationary == pytest.approx(at_data.fixed_point().v_m_s, rel=1e-9)
    assert v_stationary == pytest.approx(LAB.g * tau / 2, rel=1e-9)  # eq. 7, not 4.5 m/s


# -- several --data files, repeated --set and --out ----------------------------------------------
@pytest.mark.slow
def test_several_data_files_are_the_trials_of_one_session(tmp_path, cli):
    """Two files whose trials are both labelled 1-4: eight trials, labelled by file (before,
    the last --data alone was read: "4 trial(s)")."""
    (tmp_path / "day1").mkdir()
    (tmp_path / "day2").mkdir()
    first = lab_table(tmp_path / "day1", name="monday.csv", seed=3)
    second = lab_table(tmp_path / "day2", name="tuesday.csv", seed=4)
    out = tmp_path / "out"
    result = cli("learning", "--data", first, "--data", second, "--out", out, "--quiet",
                 "--set", "min_bounces=10")
    assert result.exit_code == 0, result.output
    trials = pd.read_csv(out / "trials.csv", dtype={"trial": str})
    assert list(trials["trial"]) == [f"{day}:{t}" for day in ("monday", "tuesday")
                                     for t in range(1, 5)]
    manifest = json.loads((out / "run.json").read_text())
    assert [d["path"] for d in manifest["data_file"]] == [str(first.resolve()),
                                                          str(second.resolve())]
    assert manifest["config"]["data"] == [str(first), str(second)]
    # g from both set-up files (weighted by their flights), alpha from both tables
    assert manifest["model_at_data"]["g"]["detail"] == "2 setup.csv files"
    assert manifest["model_at_data"]["alpha"]["n"] == 960


def test_distinct_trial_labels_stay_as_written(tmp_path):
    first = lab_table(tmp_path, name="a.csv")
    frame = pd.read_csv(first)
    second = tmp_path / "b.csv"
    frame.assign(trial=frame["trial"] + 10).to_csv(second, index=False)
    impacts = read_impacts([first, second])
    assert impacts.trials == ["1", "2", "3", "4", "11", "12", "13", "14"]


def test_a_repeated_set_key_or_out_is_an_error(tmp_path, cli, user_error):
    user_error(cli("fixed-point", "--set", "model.alpha=0.5", "--set", "model.alpha=0.6"),
               "--set model.alpha: given twice (0.5, then 0.6)")
    user_error(cli("trajectory", "--set", "model={alpha: 0.5}", "--set", "model.alpha=0.4",
                   "--out", tmp_path / "t"), "--set model.alpha: overlaps --set model")
    user_error(cli("trajectory", "--out", tmp_path / "a", "--out", tmp_path / "b"),
               "--out given 2 times")
    user_error(cli("extract", "--data", "x.csv", "--data", "y.csv", "--out", tmp_path / "e"),
               "--data given 2 times", "bounce extract reads one file per run")
    assert not any(tmp_path.iterdir())
    # different keys stay fine
    result = cli("fixed-point", "--set", "model.alpha=0.5", "--set", "model.g=9.8", "--json")
    assert result.exit_code == 0, result.output
