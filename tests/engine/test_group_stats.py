"""Group statistics of a study: the mixed-model trend, the paired difference, eq. 15's
prediction for mixed trials, averages across units; each against an independent route."""

import math

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from bounce_cli.analysis.group_stats import (
    across_units,
    eq15_prediction,
    mixed_trend,
    paired_difference,
)
from bounce_cli.analysis.regression import eq15_slope


def learning_frame(rng, subjects=10, trials=8, slope=-0.04, slope_sd=0.01, noise=0.02):
    rows = []
    for s in range(subjects):
        a = -0.3 + 0.05 * rng.standard_normal()
        b = slope + slope_sd * rng.standard_normal()
        for n in range(1, trials + 1):
            rows.append({"subject": f"s{s}", "trial_number": n,
                         "ac": a + b * (n - 1) + noise * rng.standard_normal()})
    return pd.DataFrame(rows)


@pytest.mark.slow
def test_mixed_trend_interval_covers_the_population_slope_at_its_level():
    """Random intercepts and slopes per subject: the fixed-effect interval covers the mean
    slope in about 95 % of studies (100 studies: 85-100 %, binomial 99.9 % band)."""
    rng = np.random.default_rng(3)
    covered = 0
    for _ in range(100):
        trend = mixed_trend(learning_frame(rng), "ac")
        covered += trend.ci_low <= -0.04 <= trend.ci_high
        assert trend.mixed and trend.groups == 10 and trend.observations == 80
    assert 85 <= covered <= 100


@pytest.mark.slow
# 200 small studies meet every way a mixed model fails: statsmodels' "invalid value in sqrt"
# of a covariance with a negative diagonal leaked to a study's stderr (a review saw it)
@pytest.mark.filterwarnings("error::RuntimeWarning")
def test_mixed_trend_interval_is_honest_with_three_subjects():
    """A lab's smallest study, 3 subjects x 8 trials: the normal (Wald z) interval covered
    the mean slope in 85 % of 200 simulated studies; the t interval on subjects - 1 degrees
    of freedom covers it in at least 90 % (the binomial band of 95 % over 200 studies)."""
    rng = np.random.default_rng(11)
    covered = 0
    for _ in range(200):
        trend = mixed_trend(learning_frame(rng, subjects=3), "ac")
        covered += trend.ci_low <= -0.04 <= trend.ci_high
    assert covered >= 180


def test_mixed_trend_interval_is_t_on_the_containment_degrees_of_freedom():
    """The random-slope model's slope: t on subjects - 1 degrees of freedom, for the
    interval and the p-value alike (a normal quantile here is 1.96 where t(3) is 3.18)."""
    trend = mixed_trend(learning_frame(np.random.default_rng(2), subjects=4), "ac")
    assert trend.method.startswith("mixed: random intercept and slope") and trend.df == 3
    t = stats.t.ppf(0.975, 3)
    assert (trend.ci_low, trend.ci_high) == pytest.approx(
        (trend.slope - t * trend.se, trend.slope + t * trend.se), rel=1e-12)
    assert trend.p_value == pytest.approx(2 * stats.t.sf(abs(trend.slope / trend.se), 3),
                                          rel=1e-9)


def test_mixed_trend_is_not_the_pooled_ols_when_subjects_differ():
    """Pseudo-replication: pooling 80 trials as independent gives a far too narrow interval
    when subjects' slopes differ; the mixed model's is wider (close to the two-stage one)."""
    rng = np.random.default_rng(5)
    frame = learning_frame(rng, slope_sd=0.03, noise=0.005)
    trend = mixed_trend(frame, "ac")
    pooled = stats.linregress(frame["trial_number"], frame["ac"])
    own = frame.groupby("subject").apply(
        lambda g: stats.linregress(g["trial_number"], g["ac"]).slope, include_groups=False)
    assert trend.se > 1.3 * pooled.stderr
    assert trend.se == pytest.approx(own.std(ddof=1) / math.sqrt(len(own)), rel=0.3)
    assert trend.ci_low <= -0.04 <= trend.ci_high


def test_two_subjects_without_spread_fall_back_honestly():
    """Exactly linear subjects with the same slope: nothing random to estimate; the slope
    is still right and the method says what was fitted."""
    frame = pd.DataFrame({"subject": ["a"] * 4 + ["b"] * 4,
                          "trial_number": [1, 2, 3, 4] * 2,
                          "ac": [-0.3, -0.33, -0.36, -0.39, -0.4, -0.43, -0.46, -0.49]})
    trend = mixed_trend(frame, "ac")
    assert trend.slope == pytest.approx(-0.03, abs=1e-6)
    assert trend.method


def test_one_subject_is_ordinary_least_squares():
    frame = pd.DataFrame({"subject": "a", "trial_number": [1, 2, 3, 4, 5],
                          "ac": [-0.30, -0.34, -0.35, -0.40, -0.41]})
    trend = mixed_trend(frame, "ac")
    ref = stats.linregress(frame["trial_number"], frame["ac"])
    assert trend.method.startswith("ols") and not trend.mixed
    assert trend.slope == pytest.approx(ref.slope) and trend.se == pytest.approx(ref.stderr)


def test_paired_difference_is_scipys_paired_t_test():
    rng = np.random.default_rng(1)
    a, b = rng.normal(0.3, 0.1, 9), rng.normal(0.5, 0.1, 9)
    d = paired_difference(a, b)
    ref = stats.ttest_rel(a, b)
    ci = ref.confidence_interval(0.95)
    assert d.mean == pytest.approx(np.mean(a - b))
    assert d.p_value == pytest.approx(ref.pvalue)
    assert (d.ci_low, d.ci_high) == pytest.approx((ci.low, ci.high))
    assert d.n == 9


def test_paired_difference_drops_incomplete_pairs_and_says_too_few():
    d = paired_difference([0.3, np.nan, 0.4], [0.5, 0.5, np.nan])
    assert d.n == 1 and d.mean == pytest.approx(-0.2) and math.isnan(d.ci_low)


def test_eq15_prediction_is_eq15_when_trials_agree_and_weights_long_periods():
    tau = np.array([0.5, 0.6, 0.7])
    theta = np.full(3, 0.6)
    assert eq15_prediction(tau, theta, [0.5] * 3, [9.81] * 3) == pytest.approx(
        float(eq15_slope(0.6, 0.5, 9.81)))
    # two alphas: the line through the origin of the predicted amplitudes
    alpha = np.array([0.4, 0.6, 0.6])
    predicted = eq15_slope(theta, alpha, 9.81) * tau**2
    ref = np.linalg.lstsq((tau**2)[:, None], predicted, rcond=None)[0][0]
    assert eq15_prediction(tau, theta, alpha, [9.81] * 3) == pytest.approx(ref)


def test_across_units_mean_and_sd_per_point():
    frame = pd.DataFrame({"unit": ["a", "a", "b", "b"], "lag": [0, 1, 0, 1],
                          "value": [1.0, 0.2, 1.0, 0.4]})
    out = across_units(frame, ["lag"], "value").set_index("lag")
    assert out.loc[1, "mean"] == pytest.approx(0.3)
    assert out.loc[1, "sd"] == pytest.approx(np.std([0.2, 0.4], ddof=1))
    assert out.loc[0, "units"] == 2
