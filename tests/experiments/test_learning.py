"""`bounce learning` (Fig. 6): eq. 19's SD of ball amplitude against AC, and a learning curve
from simulated trials whose AC drifts with known slope."""


import numpy as np
import pandas as pd
import pytest

from bounce_cli.model.linear import flip_boundary_g, racket_amplitude_for_ac, stability
from bounce_cli.model.params import ModelParams
from bounce_cli.analysis.data_stats import apex_sd_eq19, simulate_impacts
from bounce_cli.model.flight import apex_height
from bounce_cli.experiments import learning
from bounce_cli.data.impacts import impacts_frame

AC_START, AC_END, TRIALS = -0.25, -0.8, 12


def test_model_curve_spans_the_stable_range_and_sets_ac():
    curve = learning.model_curve(0.5, 9.81, 0.92, 0.04, 0.05, 41)
    low = float(flip_boundary_g(0.5))
    assert curve["ac_g"].min() > low and curve["ac_g"].max() < 0
    for row in curve.iloc[[0, 20, 40]].itertuples():
        st = stability(ModelParams(0.5, 9.81, row.racket_amplitude_m, 0.92))
        assert st.ac_g == pytest.approx(row.ac_g, abs=1e-9) and st.stable
    # the variability grows towards both stability boundaries; its minimum is inside
    i = int(curve["apex_sd_m"].idxmin())
    assert 0 < i < 40
    assert curve["apex_sd_m"].iloc[0] > 2 * curve["apex_sd_m"].iloc[i]


@pytest.mark.slow
def test_apex_sd_of_long_simulations_matches_eq19_with_the_maps_noise():
    """Eq. 19's apex SD (with the printed map's noise covariance) against 20 x 1000 bounces
    of eqs. 16-18: within 3 %."""
    from bounce_cli.analysis.stochastic import map_noise_covariance

    for ac in (-0.3, -0.7):
        a_r = float(racket_amplitude_for_ac(0.5, ac, 9.81, 0.92))
        p = ModelParams(0.5, 9.81, a_r, 0.92)
        sim = simulate_impacts(p, 0.04, 0.05, 20, 1000, seed=3)
        sd = apex_height(p, sim.theta, sim.v).std(axis=1).mean()
        predicted = apex_sd_eq19(p, 0.04, 0.05, map_noise_covariance(p, 0.04, 0.05))
        assert sd == pytest.approx(predicted, rel=0.03)


@pytest.fixture(scope="module")
def learning_run(tmp_path_factory, cli):
    """12 trials of 120 bounces; trial i bounces at AC from -0.25 g to -0.8 g (linear in i)."""
    tmp = tmp_path_factory.mktemp("learning")
    frames = []
    for i, ac in enumerate(np.linspace(AC_START, AC_END, TRIALS)):
        a_r = float(racket_amplitude_for_ac(0.5, ac, 9.81, 0.92))
        p = ModelParams(0.5, 9.81, a_r, 0.92)
        sim = simulate_impacts(p, 0.04, 0.05, 1, 120, seed=10 + i)
        frames.append(impacts_frame(sim, p, trial_names=[f"day{i + 1}"]))
    path = tmp / "impacts.csv"
    pd.concat(frames).to_csv(path, index=False)
    out = tmp / "out"
    result = cli("learning", "--data", path, "--out", out, "--quiet")
    assert result.exit_code == 0, result.output
    return path, out


@pytest.mark.slow
def test_learning_trend_recovers_the_known_drift(learning_run):
    _, out = learning_run
    trials = pd.read_csv(out / "trials.csv")
    assert list(trials["trial"]) == [f"day{i + 1}" for i in range(TRIALS)]
    assert (trials["bounces"] == 120).all()
    trend = pd.read_csv(out / "trend.csv").set_index("quantity")
    slope = (AC_END - AC_START) / (TRIALS - 1)
    ac = trend.loc["ac_mean_g"]
    # the per-trial mean AC sits near the fixed point's AC (noise moves it by ~0.01 g)
    assert ac.slope_ci_low - 0.003 <= slope <= ac.slope_ci_high + 0.003
    assert ac.trend == "decreasing"
    # SD of ball amplitude rises with more negative AC in this range (eq. 19 at fixed noise)
    assert trend.loc["apex_sd_m", "trend"] == "increasing"


def test_learning_figure_and_redraw(learning_run):
    _, out = learning_run
    frames = {n: pd.read_csv(out / n) for n in ("trials.csv", "trend.csv", "model_curve.csv")}
    fig = learning.draw(frames)["learning.png"]
    labels = {ax.get_xlabel() for ax in fig.axes}
    assert "trial number" in labels and "racket acceleration at impact AC (g)" in labels
    # the model's title names every parameter its curve depends on, g among them (a boom's
    # gravity changes it; a reviewer found g missing)
    g = frames["model_curve.csv"]["g_m_s2"].iloc[0]
    assert any(f"$g$ = {g:.3g} m/s$^2$" in ax.get_title() for ax in fig.axes)
    # alpha measured from data (0.601577) is shown to the figures' 3 digits, as g and tau
    frames["model_curve.csv"]["alpha"] = 0.601577
    fig = learning.draw(frames)["learning.png"]
    shown = " ".join([ax.get_title() for ax in fig.axes]
                     + [t.get_text() for ax in fig.axes if ax.get_legend()
                        for t in ax.get_legend().get_texts()])
    assert "$\\alpha$ = 0.602" in shown and "0.601577" not in shown


@pytest.mark.slow
def test_the_model_curve_runs_at_the_datas_noise_not_the_configs(learning_run, tmp_path,
                                                                  cli):
    """The trials were simulated with q_v 0.04 m/s, q_theta 0.05 rad; the config says 0.2 and
    0.3. The model curve uses the data's noise from each trial's VAR(1) residuals (12 trials
    of 120 bounces, each with its own AC and so its own J): within 10 % of the truth (measured:
    q_v +9 %, the map's nonlinearity up to AC -0.8 g), and the
    summary says whose noise it is."""
    path, _ = learning_run
    out = tmp_path / "o"
    result = cli("learning", "--data", path, "--out", out, "--set", "noise.q_v=0.2",
                 "--set", "noise.q_theta=0.3")
    assert result.exit_code == 0, result.output
    assert "the data's noise (VAR(1) residuals of each trial" in result.output
    curve = pd.read_csv(out / "model_curve.csv")
    assert curve["q_v_m_s"].iloc[0] == pytest.approx(0.04, rel=0.10)
    assert curve["q_theta_rad"].iloc[0] == pytest.approx(0.05, rel=0.10)
    # without data the config's noise draws the curve
    result = cli("learning", "--out", tmp_path / "m", "--quiet", "--set", "noise.q_v=0.2")
    assert result.exit_code == 0, result.output
    assert pd.read_csv(tmp_path / "m" / "model_curve.csv")["q_v_m_s"].iloc[0] == 0.2


@pytest.mark.slow
def test_model_only_without_data(tmp_path, cli):
    result = cli("learning", "--out", tmp_path, "--quiet")
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["learning.png", "model_curve.csv",
                                                          "run.json", "timing.json"]


def test_learning_errors(learning_run, tmp_path, cli, user_error):
    path, _ = learning_run
    frame = pd.read_csv(path)
    no_apex = tmp_path / "no_apex.csv"
    frame.drop(columns=["ball_apex_m"]).to_csv(no_apex, index=False)
    user_error(cli("learning", "--data", no_apex, "--out", tmp_path / "a"),
                      "missing column ball_apex_m", "SD of ball amplitude")
    two = tmp_path / "two.csv"
    frame[frame.trial.isin(["day1", "day2"])].to_csv(two, index=False)
    user_error(cli("learning", "--data", two, "--out", tmp_path / "b"),
                      "2 trial(s)", "at least 3")
    short = tmp_path / "short.csv"
    frame[(frame.trial != "day3") | (frame.k < 4)].to_csv(short, index=False)
    user_error(cli("learning", "--data", short, "--out", tmp_path / "c"),
                      "trial day3", "4 impacts")
    assert not any((tmp_path / d).exists() and any((tmp_path / d).iterdir()) for d in "abc")


@pytest.mark.slow
def test_data_statistics_leave_out_the_relaxation_after_perturbations(tmp_path, cli):
    """The per-trial SDs describe the stationary state: the perturbed impacts AND the
    relaxation after each are left out (settle_after_perturbation, as acf --data). On the
    passive lab's perturbation session (every 10th impact, |alpha_p - 0.5| >= 0.1), keeping
    the relaxations inflates the SD of v by a factor 2-4."""
    from pathlib import Path

    data = Path(__file__).resolve().parents[2] / "results" / "impulse-data" / "impacts.csv"
    sds = {}
    for settle in (0, 4):
        out = tmp_path / f"s{settle}"
        result = cli("learning", "--data", data, "--set", f"settle_after_perturbation={settle}",
                     "--set", "model.g=9.81", "--out", out, "--quiet")
        assert result.exit_code == 0, result.output
        sds[settle] = pd.read_csv(out / "trials.csv")["v_sd_m_s"].to_numpy()
    assert np.all(sds[4] < 0.6 * sds[0])


def test_a_trial_left_with_too_few_settled_impacts_is_left_out_with_a_warning(tmp_path, cli):
    """min_bounces was checked on the whole trial, before the perturbed impacts and the
    relaxation after each were removed: a trial perturbed every fifth impact kept none (or
    four) and still gave a row, its statistics over nothing, and the trend was fitted to it.
    Four of the passive lab's eight trials are perturbed every fifth impact here: with
    settle_after_perturbation 4 they keep no impact, and are left out with a warning."""
    from pathlib import Path

    frame = pd.read_csv(Path(__file__).resolve().parents[2] / "results" / "impulse-data"
                        / "impacts.csv")
    dense = frame["trial"] > frame["trial"].min() + 3  # the later four trials
    frame.loc[dense, "perturbed"] = frame.loc[dense, "k"] % 5 == 0
    data = tmp_path / "impacts.csv"
    frame.to_csv(data, index=False)
    out = tmp_path / "out"
    result = cli("learning", "--data", data, "--set", "model.g=9.81", "--out", out, "--quiet")
    assert result.exit_code == 0, result.output
    trials = pd.read_csv(out / "trials.csv")
    assert len(trials) == 4 and (trials["bounces"] >= 10).all()
    assert trials["trial_number"].tolist() == [1, 2, 3, 4]
    assert "fewer than min_bounces" in result.output
    assert "settle_after_perturbation" in result.output


def test_the_printed_reading_s_curve_is_drawn_only_where_it_can_be_seen():
    """learning.png's legend named a dotted eq. 19 curve (the noise of eqs. 16-18 as printed)
    that lay under the solid one at the data's small phase noise. It is drawn where the two
    differ by more than 1 % somewhere; else the solid curve's label says they agree."""
    curve = learning.model_curve(0.5, 9.81, 0.92, 0.04, 0.05, 41)
    close = learning.model_curve(0.5, 9.81, 0.92, 0.0408, 0.00232, 41)
    for frame, dotted in ((curve, True), (close, False)):
        fig = learning.draw({"model_curve.csv": frame})["learning.png"]
        ax = fig.axes[0]
        styles = [line.get_linestyle() for line in ax.get_lines()]
        assert (":" in styles) is dotted
        labels = ax.get_legend_handles_labels()[1]
        assert any("the same within 1 %" in label for label in labels) is not dotted


def test_trials_put_in_the_order_of_their_numbers_are_said(tmp_path, cli):
    """A file listing trials 3, 1, 4, 2 is read in the order 1, 2, 3, 4 (learning's trend runs
    over it): a warning says so, with both orders."""
    from pathlib import Path

    frame = pd.read_csv(Path(__file__).resolve().parents[2] / "results" / "impulse-data"
                        / "impacts.csv")
    first = sorted(frame["trial"].unique())[:4]
    frame = pd.concat([frame[frame.trial == first[i]] for i in (2, 0, 3, 1)])
    data = tmp_path / "impacts.csv"
    frame.to_csv(data, index=False)
    result = cli("learning", "--data", data, "--set", "model.g=9.81", "--out",
                 tmp_path / "out", "--quiet")
    assert result.exit_code == 0, result.output
    said = " ".join(result.output.split())
    ordered = ", ".join(str(t) for t in first)
    listed = ", ".join(str(first[i]) for i in (2, 0, 3, 1))
    assert f"trials in the order of their numbers ({ordered}), not as the file lists them " \
           f"({listed})" in said
    trials = pd.read_csv(tmp_path / "out" / "trials.csv")
    assert trials["trial"].tolist() == first
