"""A racket that varies cycle to cycle (engine/racket_inputs.py, engine/var_fit.py's VARX): the
implicit-function derivatives of eqs. 5-6 against finite differences of the simulated lab's own
contact search, eq. 9 as their state part, and a VARX that recovers J where the VAR(1) drifts."""

import math

import numpy as np
import pytest

from bounce_cli.model.linear import jacobian, stability
from bounce_cli.model.params import ModelParams
from bounce_cli.analysis.racket_inputs import racket_input_jacobian
from bounce_cli.data.simulated_runs import cycle_map_step
from bounce_cli.analysis.var_fit import fit_var1

LAB = ModelParams(alpha=0.55, g=9.81, racket_amplitude=0.11, racket_period=0.60)
ACF = ModelParams(alpha=0.42, g=5.8, racket_amplitude=0.065, racket_period=0.55)
PAPER = ModelParams(alpha=0.5, g=9.81, racket_amplitude=0.30, racket_period=0.92)


@pytest.mark.parametrize("params", [LAB, ACF, PAPER])
def test_the_state_part_is_eq9(params):
    np.testing.assert_allclose(racket_input_jacobian(params).state, jacobian(params),
                               rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("params", [LAB, ACF, PAPER])
def test_racket_derivatives_match_finite_differences_of_the_lab_simulator(params):
    """Central differences of one flight on engine.recording's cycle-wise racket (safe-step
    contact search, eq. 3 at the contact; not eqs. 5-6) in each cycle's period and amplitude,
    against the implicit-function derivatives. A transposed B, the two cycles swapped or the
    phase taken in (-pi, pi] instead of from the upward crossing would fail."""
    fp = params.fixed_point()
    theta, v = fp.theta_rad % (2 * math.pi), fp.v_m_s
    tau, a = params.racket_period, params.racket_amplitude
    np.testing.assert_allclose(cycle_map_step(params, v, theta, (tau, a), (tau, a)),
                               (v, theta), rtol=1e-9)
    steps = (1e-6, 1e-7)
    fd = np.zeros((2, 4))
    for column, (which, index) in enumerate(((1, 0), (1, 1), (0, 0), (0, 1))):
        out = []
        for sign in (1.0, -1.0):
            cycles = [[tau, a], [tau, a]]  # impact k's cycle, the next one
            cycles[which][index] += sign * steps[index]
            out.append(cycle_map_step(params, v, theta, tuple(cycles[0]), tuple(cycles[1])))
        fd[:, column] = (np.array(out[0]) - np.array(out[1])) / (2 * steps[index])
    np.testing.assert_allclose(racket_input_jacobian(params).as_varx(), fd, rtol=1e-5,
                               atol=1e-6)


def varx_series(jac, b, noise_cov, input_sd, n_trials, n, rng, burn=100):
    """y_{k+1} = J y_k + b [u_{k+1}; u_k] + eps_k with white inputs u (SDs input_sd):
    (T, n, 2) states and (T, n, 2) inputs."""
    chol = np.linalg.cholesky(noise_cov)
    total = burn + n
    u = rng.standard_normal((n_trials, total + 1, 2)) * input_sd
    y = np.zeros((n_trials, total, 2))
    for k in range(total - 1):
        y[:, k + 1] = (y[:, k] @ jac.T + np.concatenate([u[:, k + 1], u[:, k]], axis=1) @ b.T
                       + rng.standard_normal((n_trials, 2)) @ chol.T)
    return y[:, burn:], u[:, burn:total]


@pytest.mark.parametrize("method", ["ols", "lag2"])
def test_varx_recovers_j_and_b_where_the_var_drifts(method):
    """Linear data with the lab's J and the model's B, racket SDs 10 ms and 3 mm per cycle,
    10 trials x 300: the OLS VAR(1) spectral radius is off by more than 4 SE (u_k moves y_k
    and y_{k+1} alike; the lag-2 instrument y_{k-1} is free of u_k, so on linear data lag-2
    stays consistent without the inputs), the VARX's J and B are within 3.5 SE of the truth
    and its radius within its interval, for both estimators."""
    rng = np.random.default_rng(3)
    truth = jacobian(LAB)
    b = racket_input_jacobian(LAB).as_varx()
    y, u = varx_series(truth, b, np.diag([0.03**2, 0.01**2]), np.array([0.01, 0.003]), 10,
                       300, rng)
    radius = stability(LAB).spectral_radius
    if method == "ols":
        r_var = fit_var1(list(y), method).eigen_summary()["spectral_radius"]
        assert abs(r_var[0] - radius) > 4 * r_var[1]
    varx = fit_var1(list(y), method, exog=list(u))
    assert np.all(np.abs(varx.jacobian - truth) < 3.5 * varx.jacobian_se)
    assert np.all(np.abs(varx.exog_coef - b) < 3.5 * varx.exog_se + 1e-12)
    value, _, low, high = varx.eigen_summary()["spectral_radius"]
    assert low <= radius <= high


def test_varx_inputs_never_pair_two_trials():
    """The inputs are cut at trial boundaries like the states: two trials fitted apart equal
    the fit of their pairs, and shifting one trial's inputs by a constant changes nothing (its
    own mean is removed)."""
    rng = np.random.default_rng(4)
    b = racket_input_jacobian(LAB).as_varx()
    y, u = varx_series(jacobian(LAB), b, np.diag([0.03**2, 0.01**2]),
                       np.array([0.01, 0.003]), 2, 200, rng)
    one = fit_var1(list(y), "ols", jackknife=False, exog=list(u))
    shifted = fit_var1(list(y), "ols", jackknife=False, exog=[u[0], u[1] + [0.05, 0.01]])
    np.testing.assert_allclose(one.exog_coef, shifted.exog_coef, rtol=1e-9)
    glued = fit_var1([np.concatenate(y)], "ols", jackknife=False,
                     exog=[np.concatenate([u[0], u[1] + [0.05, 0.01]])])
    assert not np.allclose(glued.exog_coef, one.exog_coef, rtol=1e-3)
