"""The stacked VAR fits (analysis/var_stacked.py) against the one-at-a-time fits of
analysis/var_fit.py, and the panels they are tested on."""

from __future__ import annotations

import numpy as np
import pytest

from bounce_cli.analysis.var_stacked import (
    simulate_panels,
    stacked_fit,
)
from bounce_cli.analysis.var_fit import fit_var1
from bounce_cli.model.linear import eigenvalues_2x2, spectral_radii_2x2

J_TRUE = np.array([[0.2, -0.9], [0.5, 0.45]])  # a complex pair, radius about 0.72
NOISE = np.array([[0.04, 0.01], [0.01, 0.02]])


def panel(lengths, seed, inputs=None, coef=None):
    rng = np.random.default_rng(seed)
    return simulate_panels(J_TRUE, NOISE, lengths, 1, rng, inputs, coef)[0]


def split(y, lengths):
    return np.split(y, np.cumsum(lengths)[:-1])


@pytest.mark.parametrize("method", ["ols", "lag2"])
@pytest.mark.parametrize("jackknife", [False, True])
@pytest.mark.parametrize("with_inputs", [False, True])
def test_the_stacked_fit_is_fit_var1_on_each_panel(method, jackknife, with_inputs):
    lengths = [31, 24, 40]
    rng = np.random.default_rng(5)
    inputs = rng.standard_normal((sum(lengths), 2)) if with_inputs else None
    coef = np.array([[0.3, -0.1, 0.2, 0.05], [0.1, 0.2, -0.3, 0.1]]) if with_inputs else None
    panels = np.stack([panel(lengths, s, inputs, coef) for s in range(3)])
    stacked = stacked_fit(panels, lengths, method, jackknife, inputs)
    for r in range(3):
        exog = split(inputs, lengths) if with_inputs else None
        one = fit_var1(split(panels[r], lengths), method, jackknife=jackknife, exog=exog)
        np.testing.assert_allclose(stacked.jacobian[r], one.jacobian, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(stacked.cov_vec[r], one.cov_vec, rtol=1e-8, atol=1e-14)
    assert stacked.valid.all()


@pytest.mark.parametrize("method", ["ols", "lag2"])
@pytest.mark.parametrize("jackknife", [False, True])
def test_the_stacked_fit_with_each_panels_own_inputs_is_fit_var1_on_each(method, jackknife):
    """The model sessions of a VARX prediction: every panel its own racket inputs."""
    lengths = [33, 26, 41]
    rng = np.random.default_rng(8)
    coef = np.array([[0.3, -0.1, 0.2, 0.05], [0.1, 0.2, -0.3, 0.1]])
    inputs = rng.standard_normal((4, sum(lengths), 2)) * [0.01, 0.002] + [0.6, 0.3]
    panels = np.stack([panel(lengths, 10 + s, inputs[s], coef) for s in range(4)])
    stacked = stacked_fit(panels, lengths, method, jackknife, inputs)
    for r in range(4):
        one = fit_var1(split(panels[r], lengths), method, jackknife=jackknife,
                       exog=split(inputs[r], lengths))
        np.testing.assert_allclose(stacked.jacobian[r], one.jacobian, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(stacked.cov_vec[r], one.cov_vec, rtol=1e-8, atol=1e-14)
        assert stacked.valid[r] == (one.radius_problem() == "")
    shared = stacked_fit(panels, lengths, method, jackknife, inputs[0])
    assert not np.allclose(shared.jacobian[1:], stacked.jacobian[1:], rtol=1e-6)


def test_spectral_radii_are_the_eigenvalues_moduli():
    rng = np.random.default_rng(1)
    mats = rng.normal(size=(200, 2, 2))
    expected = [max(abs(lam) for lam in eigenvalues_2x2(m)) for m in mats]
    np.testing.assert_allclose(spectral_radii_2x2(mats), expected, rtol=1e-12)
    np.testing.assert_allclose(spectral_radii_2x2(mats), np.abs(np.linalg.eigvals(mats)).max(-1),
                               rtol=1e-10)


def test_a_panel_starts_in_the_stationary_distribution():
    """The first impact of each trial has eq. 19's stationary covariance (no burn-in)."""
    from bounce_cli.analysis.stochastic import stationary_covariance

    rng = np.random.default_rng(2)
    panels = simulate_panels(J_TRUE, NOISE, [3, 3], 40000, rng)
    cov_first = np.cov(panels[:, 3].T)
    cov_last = np.cov(panels[:, 5].T)
    expected = stationary_covariance(J_TRUE, NOISE)
    np.testing.assert_allclose(cov_first, expected, rtol=0.05, atol=1e-4)
    np.testing.assert_allclose(cov_last, expected, rtol=0.05, atol=1e-4)
