"""Model parameters and the period-1 fixed point (eqs. 7, 8)."""

import math

import numpy as np
import pytest

from bounce_cli.model.linear import racket_acceleration_at_impact_g
from bounce_cli.model.params import (
    ModelError,
    ModelParams,
    NoFixedPointError,
    phase_difference,
    wrap_phase,
)


def test_fixed_point_matches_paper_section3(paper_params):
    fp = paper_params.fixed_point()
    # paper (Fig. 9 caption): v~ = 4.5 m/s, theta~ = 42 deg; issue: 4.513 m/s, 42.76 deg
    assert fp.v_m_s == pytest.approx(4.513, abs=5e-4)
    assert fp.theta_deg == pytest.approx(42.76, abs=5e-3)
    assert racket_acceleration_at_impact_g(paper_params) == pytest.approx(-0.968, abs=5e-4)


def test_fixed_point_formulae_independently(paper_params):
    w = 2 * math.pi / 0.92
    assert paper_params.omega == pytest.approx(w)
    assert paper_params.fixed_point().v_m_s == pytest.approx(math.pi * 9.81 / w, rel=1e-14)
    cos_t = math.pi * (0.5 / 1.5) * 9.81 / (w * w * 0.30)
    assert math.cos(paper_params.fixed_point().theta_rad) == pytest.approx(cos_t, rel=1e-14)


def test_fixed_point_on_stable_branch_with_negative_racket_acceleration(paper_params):
    theta = paper_params.fixed_point().theta_rad
    assert 0 < theta <= math.pi / 2
    assert paper_params.racket_acceleration(theta) < 0


def test_ac_explicit_form_section4():
    rng = np.random.default_rng(3)
    for _ in range(50):
        p = ModelParams(rng.uniform(0, 0.95), rng.uniform(1, 20), rng.uniform(0.05, 1),
                        rng.uniform(0.2, 2))
        try:
            p.fixed_point()
        except NoFixedPointError:
            continue
        explicit = -math.sqrt((p.racket_amplitude * p.omega**2 / p.g) ** 2
                              - math.pi**2 * ((1 - p.alpha) / (1 + p.alpha)) ** 2)
        assert racket_acceleration_at_impact_g(p) == pytest.approx(explicit, rel=1e-9)


@pytest.mark.parametrize(
    "kwargs, key",
    [
        (dict(alpha=1.0), "alpha"),
        (dict(alpha=-0.1), "alpha"),
        (dict(g=0.0), "g"),
        (dict(racket_amplitude=-1.0), "racket_amplitude"),
        (dict(racket_period=0.0), "racket_period"),
        (dict(g=float("nan")), "g"),
    ],
)
def test_invalid_parameters_rejected(kwargs, key):
    base = dict(alpha=0.5, g=9.81, racket_amplitude=0.3, racket_period=0.92)
    base.update(kwargs)
    with pytest.raises(ModelError, match=key):
        ModelParams(**base)


def test_no_fixed_point_is_an_error_naming_the_minimum_amplitude():
    p = ModelParams(0.5, 9.81, 0.01, 0.92)
    with pytest.raises(NoFixedPointError, match=r"model.racket_amplitude\) must be >= 0.22"):
        p.fixed_point()
    # just above the minimum amplitude there is one, at theta~ ~ 0
    q = ModelParams(0.5, 9.81, p.min_racket_amplitude() * (1 + 1e-9), 0.92)
    assert q.fixed_point().theta_rad == pytest.approx(0.0, abs=1e-3)


def test_wrapping_helpers():
    assert wrap_phase(-0.1) == pytest.approx(2 * math.pi - 0.1)
    # an unwrapped phase 10 cycles later compares equal to the reference
    assert phase_difference(0.7 + 20 * math.pi, 0.7) == pytest.approx(0.0, abs=1e-12)
    # across the 0/2pi seam the difference is small, not ~2 pi
    assert phase_difference(0.01, 2 * math.pi - 0.01) == pytest.approx(0.02, abs=1e-12)
