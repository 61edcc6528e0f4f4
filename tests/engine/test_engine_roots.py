"""engine.roots.nearest_root and the inverse problems of section 6 built on it (which racket
amplitude or noise strengths would give a printed SD), each checked by a round trip through
the forward computation."""

import math

import numpy as np
import pytest

from bounce_cli.model.linear import jacobian
from bounce_cli.model.params import ModelParams
from bounce_cli.analysis.roots import nearest_root
from bounce_cli.analysis.stochastic import (
    noise_strengths_for_sds,
    paper_noise_covariance,
    racket_amplitude_for_sd,
    stationary_covariance,
    stationary_sds,
)


def test_nearest_root_picks_the_root_nearest_to_the_guess():
    # sin has roots pi, 2 pi, 3 pi in [2, 10]
    assert nearest_root(math.sin, 2.0, 10.0, near=6.0) == pytest.approx(2 * math.pi, abs=1e-12)
    assert nearest_root(math.sin, 2.0, 10.0, near=9.0) == pytest.approx(3 * math.pi, abs=1e-12)
    assert nearest_root(math.sin, 2.0, 10.0, near=0.0) == pytest.approx(math.pi, abs=1e-12)


def test_nearest_root_none_and_undefined_regions():
    assert math.isnan(nearest_root(lambda x: x * x + 1.0, -3.0, 3.0, near=0.0))
    # NaN where f is undefined: no root is looked for across it, the defined one is found
    f = lambda x: math.nan if x < 1.0 else x - 2.5  # noqa: E731
    assert nearest_root(f, 0.0, 4.0, near=0.0) == pytest.approx(2.5)


def test_stationary_sds_are_the_lyapunov_solution(acf_params):
    noise = paper_noise_covariance(0.04, 0.05)
    cov = stationary_covariance(jacobian(acf_params), noise)
    sd_v, sd_theta = stationary_sds(acf_params, noise)
    assert (sd_v, sd_theta) == (math.sqrt(cov[0, 0]), math.sqrt(cov[1, 1]))
    # the section 6 value we reproduce (the paper prints 0.068 m/s and 8.4 deg)
    assert sd_v == pytest.approx(0.0695, abs=1e-4)
    assert math.degrees(sd_theta) == pytest.approx(7.885, abs=1e-3)


@pytest.mark.parametrize("q_v, q_theta", [(0.04, 0.05), (0.0354, 0.0707), (0.01, 0.2)])
def test_noise_strengths_round_trip(acf_params, q_v, q_theta):
    sd_v, sd_theta = stationary_sds(acf_params, paper_noise_covariance(q_v, q_theta))
    back = noise_strengths_for_sds(jacobian(acf_params), sd_v, sd_theta)
    np.testing.assert_allclose(back, (q_v, q_theta), rtol=1e-10)


def test_noise_strengths_that_do_not_exist_are_nan(acf_params):
    # velocity noise alone already gives a phase SD: a much smaller one needs q_theta^2 < 0
    sd_v, sd_theta = stationary_sds(acf_params, paper_noise_covariance(0.04, 0.0))
    q_v, q_theta = noise_strengths_for_sds(jacobian(acf_params), sd_v, 0.1 * sd_theta)
    assert math.isfinite(q_v) and math.isnan(q_theta)


@pytest.mark.parametrize("a_true", [0.063, 0.07])
def test_racket_amplitude_for_sd_round_trip(acf_params, a_true):
    p = acf_params
    at = ModelParams(p.alpha, p.g, a_true, p.racket_period)
    sd_v, sd_theta = stationary_sds(at, paper_noise_covariance(0.04, 0.05))
    a_v = racket_amplitude_for_sd(p, 0.04, 0.05, 0.076, sd_v_m_s=sd_v)
    a_t = racket_amplitude_for_sd(p, 0.04, 0.05, 0.076, sd_theta_deg=math.degrees(sd_theta))
    assert a_v == pytest.approx(a_true, rel=1e-9)
    assert a_t == pytest.approx(a_true, rel=1e-9)


def test_racket_amplitude_for_an_sd_no_amplitude_gives(acf_params):
    assert math.isnan(racket_amplitude_for_sd(acf_params, 0.04, 0.05, 0.076, sd_v_m_s=1e-6))
    with pytest.raises(ValueError):
        racket_amplitude_for_sd(acf_params, 0.04, 0.05, 0.076)
