"""Jacobian (eq. 9), eigenvalues (eq. 10) and stability boundaries (eqs. 11-14)."""

import math

import numpy as np
import pytest

from bounce_cli.model.linear import (
    complex_boundaries_g,
    eigenvalues,
    finite_difference_jacobian,
    flip_boundary_g,
    is_complex_regime,
    jacobian,
    racket_acceleration_at_impact_g,
    spectral_radius,
    stability,
)
from bounce_cli.model.params import ModelParams, NoFixedPointError


def random_params_with_fixed_point(seed, n):
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < n:
        p = ModelParams(rng.uniform(0, 0.95), rng.uniform(2, 15), rng.uniform(0.05, 0.8),
                        rng.uniform(0.3, 1.5))
        try:
            p.fixed_point()
        except NoFixedPointError:
            continue
        out.append(p)
    return out


def test_paper_eigenvalues_complex_pair_modulus_half(paper_params):
    st = stability(paper_params)
    assert st.regime == "complex" and st.stable
    assert st.spectral_radius == pytest.approx(0.5, abs=1e-12)
    lp, lm = st.eigenvalues
    assert lp == pytest.approx(np.conj(lm))
    assert abs(lp.imag) > 0.1


@pytest.mark.parametrize("p", random_params_with_fixed_point(1, 25))
def test_eq9_against_finite_differences_of_the_implicit_map(p):
    analytic = jacobian(p)
    numeric = finite_difference_jacobian(p)
    np.testing.assert_allclose(numeric, analytic, rtol=2e-6, atol=2e-6 * np.abs(analytic).max())


@pytest.mark.parametrize("p", random_params_with_fixed_point(2, 25))
def test_eq10_against_numpy_eigvals_of_eq9(p):
    ac = racket_acceleration_at_impact_g(p)
    ours = np.sort_complex(np.array(eigenvalues(p.alpha, ac)))
    theirs = np.sort_complex(np.linalg.eigvals(jacobian(p)))
    np.testing.assert_allclose(ours, theirs, atol=1e-10)
    assert np.linalg.det(jacobian(p)) == pytest.approx(p.alpha**2, abs=1e-10)


def test_complex_regime_has_modulus_alpha_eq12():
    alpha = np.linspace(0.01, 0.99, 50)[:, None]
    lo, hi = complex_boundaries_g(alpha)
    ac = lo + (hi - lo) * np.linspace(0.01, 0.99, 40)[None, :]
    assert np.all(is_complex_regime(alpha, ac))
    np.testing.assert_allclose(spectral_radius(alpha, ac), np.broadcast_to(alpha, ac.shape),
                               rtol=1e-12)


def test_complex_boundaries_are_low_then_high_on_the_whole_diagram():
    """The stability diagram's grid runs from alpha -0.2 (pure algebra, eqs. 10-14): there
    eq. 11's second boundary lies below -1, and boundaries.csv gave low above high (a model
    review). Between them the eigenvalues are complex, outside real, at every alpha."""
    alpha = np.array([-0.2, -0.1, 0.0, 0.3, 0.9])
    lo, hi = complex_boundaries_g(alpha)
    assert np.all(lo <= hi)
    inner = (lo + hi) / 2.0
    wide = alpha != 0.0  # at alpha 0 the regime is the single point AC = -1
    assert np.all(is_complex_regime(alpha[wide], inner[wide]))
    assert not np.any(is_complex_regime(alpha, lo - 0.05))
    assert not np.any(is_complex_regime(alpha, hi + 0.05))


def test_stability_boundaries_eq13_eq14():
    for alpha in np.linspace(0.0, 0.95, 20):
        flip = flip_boundary_g(alpha)
        assert spectral_radius(alpha, flip + 1e-6) < 1 < spectral_radius(alpha, flip - 1e-6)
        assert spectral_radius(alpha, -1e-6) < 1 < spectral_radius(alpha, 1e-6)


def test_alpha_half_stable_range_paper_section5():
    # "for alpha = 0.5, AC should be between 0 and -1.11 g"
    assert flip_boundary_g(0.5) == pytest.approx(-1.11, abs=5e-3)


def test_jacobian_sign_conventions(paper_params):
    """Column order (v, theta): d theta_{k+1} / d v_k = (1 + alpha) w / g > 0 (section 4)."""
    J = jacobian(paper_params)
    assert J[1, 0] == pytest.approx(1.5 * paper_params.omega / 9.81)
    assert J[1, 1] == 1.0
    assert J[0, 1] < 0
    ac = racket_acceleration_at_impact_g(paper_params)
    assert math.isclose(np.trace(J), 1 + 0.25 + 2.25 * ac)


def test_with_parameters_sets_the_racket_amplitude_by_gamma_or_by_ac():
    """The one parameter-point rule of bounce bifurcation, continuation and sweep: Gamma and
    AC each give back the value they were set to (AC through eq. 8's fixed point, an
    independent route to section 4's explicit form), at the point's own g and period."""
    from bounce_cli.model.linear import racket_acceleration_at_impact_g, with_parameters
    from bounce_cli.model.params import ModelError

    base = ModelParams(0.5, 9.81, 0.30, 0.92)
    point = with_parameters(base, {"gamma": 1.7, "g": 3.7, "racket_period": 0.6})
    assert point.racket_amplitude * point.omega**2 / point.g == pytest.approx(1.7, rel=1e-14)
    assert (point.alpha, point.g, point.racket_period) == (0.5, 3.7, 0.6)
    point = with_parameters(base, {"ac_g": -0.8, "alpha": 0.7})
    assert racket_acceleration_at_impact_g(point) == pytest.approx(-0.8, rel=1e-12)
    assert with_parameters(base, {}) == base
    with pytest.raises(ModelError, match="gamma and ac_g cannot both"):
        with_parameters(base, {"gamma": 1.7, "ac_g": -0.8})
    with pytest.raises(ModelError, match="cannot set"):
        with_parameters(base, {"tau": 0.6})
    with pytest.raises(ModelError, match="gamma must be > 0"):
        with_parameters(base, {"gamma": 0.0})
    with pytest.raises(ModelError, match="ac_g must be <= 0"):
        with_parameters(base, {"ac_g": 0.2})
