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


@pytest.mark.parametrize("kwargs, names", [
    (dict(g=1e308, racket_period=1e-300), ("racket_period = 1e-300 s", "g = 1e+308")),
    (dict(racket_period=1e300), ("racket_period = 1e+300",)),
    (dict(racket_amplitude=1e308), ("racket_amplitude = 1e+308",)),
    (dict(g=5e-324), ("g = 4.94e-324",)),
])
def test_parameters_whose_eq8_terms_overflow_are_refused_naming_them(kwargs, names):
    """Eq. 8's terms (omega_r, omega_r^2 a_r, v~, the acceleration ratio) beyond 1e+-100:
    one ModelError naming the parameters, not an OverflowError or a NaN radius later."""
    base = dict(alpha=0.5, g=9.81, racket_amplitude=0.3, racket_period=0.92)
    base.update(kwargs)
    with pytest.raises(ModelError) as info:
        ModelParams(**base)
    message = str(info.value)
    assert "\n" not in message and "SI units" in message
    for name in names:
        assert name in message, message


def test_far_but_representable_parameters_are_still_accepted():
    """The map is scale-free in a_r omega_r^2 / g: a lab on the Moon or a racket of 1 um are
    values, not errors."""
    ModelParams(0.5, 1.62, 0.05, 0.92).fixed_point()
    ModelParams(0.5, 9.81e-6, 1e-6, 0.92).fixed_point()
