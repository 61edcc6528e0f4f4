"""The Jacobian of eqs. 5, 6 at any state (implicit differentiation) and the largest Lyapunov
exponent along orbits, each checked against an independent route: finite differences of the
map, eq. 9 at the fixed point, the area contraction of the impact law, eq. 10's spectral
radius, and the divergence of two nearby orbits of the map itself."""

import math

import numpy as np
import pytest

from bounce_cli.model.linear import jacobian, stability
from bounce_cli.model.maps import map_step
from bounce_cli.model.params import ModelParams
from bounce_cli.analysis.bifurcation import SweepSettings, iterate_sweep, sweep_parameters
from bounce_cli.analysis.lyapunov import advance_tangent, initial_tangent, map_jacobian


def random_flying_states(rng, n):
    """Random parameters and launch states whose next impact is transversal (the ball meets
    the racket at a relative speed of at least 5 % of a_r w), so the map is smooth there."""
    out = []
    while len(out) < n:
        params = ModelParams(alpha=rng.uniform(0.0, 0.95), g=rng.uniform(2.0, 20.0),
                             racket_amplitude=rng.uniform(0.02, 0.6),
                             racket_period=rng.uniform(0.3, 1.5))
        theta = rng.uniform(0.0, 2 * math.pi)
        excess = rng.uniform(0.05, 3.0) * params.g * params.racket_period
        v = float(params.racket_velocity(theta)) + excess
        hop = float(map_step(theta, v, params).hop_phase)
        v_before = v - params.g * hop / params.omega
        approach = float(params.racket_velocity(theta + hop)) - v_before
        if approach > 0.05 * params.racket_amplitude * params.omega:
            out.append((params, theta, v))
    return out


def finite_difference_jacobian_at(theta, v, params, h_v=1e-6, h_t=1e-7):
    """Central differences of the full map (eq. 6 re-solved for each perturbed state)."""
    h_v *= max(1.0, abs(v))
    th = np.array([theta, theta, theta + h_t, theta - h_t])
    vv = np.array([v + h_v, v - h_v, v, v])
    step = map_step(th, vv, params)
    return np.array([
        [(step.v[0] - step.v[1]) / (2 * h_v), (step.v[2] - step.v[3]) / (2 * h_t)],
        [(step.theta[0] - step.theta[1]) / (2 * h_v), (step.theta[2] - step.theta[3]) / (2 * h_t)],
    ])


def test_orbit_jacobian_matches_finite_differences_at_random_states():
    rng = np.random.default_rng(2026)
    worst = 0.0
    for params, theta, v in random_flying_states(rng, 200):
        hop = float(map_step(theta, v, params).hop_phase)
        analytic = map_jacobian(theta, v, hop, params)
        numeric = finite_difference_jacobian_at(theta, v, params)
        scale = np.abs(numeric).max()
        worst = max(worst, float(np.abs(analytic - numeric).max() / scale))
    assert worst < 2e-6, worst


def test_orbit_jacobian_at_the_fixed_point_is_eq9(paper_params):
    others = (ModelParams(0.3, 9.81, 0.2, 0.6), ModelParams(0.8, 5.8, 0.1, 0.55))
    for params in (paper_params, *others):
        fp = params.fixed_point()
        general = map_jacobian(fp.theta_rad, fp.v_m_s, 2 * math.pi, params)
        np.testing.assert_allclose(general, jacobian(params), rtol=1e-12, atol=1e-12)


@pytest.mark.slow
def test_jacobian_determinant_is_the_impact_law_area_contraction():
    """det J = alpha (v_k - v_r(theta_k)) / (v_r(theta_{k+1}) - v^-): the relative velocity
    leaving impact k over the relative velocity arriving at impact k+1. Along an orbit the
    product telescopes (eq. 3: leaving = alpha * arriving), so the mean of log det J, the sum
    of the two Lyapunov exponents, tends to 2 ln alpha."""
    rng = np.random.default_rng(5)
    for params, theta, v in random_flying_states(rng, 50):
        hop = float(map_step(theta, v, params).hop_phase)
        v_before = v - params.g * hop / params.omega
        expected = params.alpha * (v - float(params.racket_velocity(theta))) / (
            float(params.racket_velocity(theta + hop)) - v_before)
        assert np.linalg.det(map_jacobian(theta, v, hop, params)) == pytest.approx(
            expected, rel=1e-9, abs=1e-12)
    # along a chaotic orbit (Gamma = 1.75, alpha = 0.5)
    params = gamma_params(1.75)
    theta, v, log_det = math.radians(90.0), 5.0, []
    for _ in range(3000):
        step = map_step(theta, v, params)
        log_det.append(math.log(abs(np.linalg.det(map_jacobian(theta, v, step.hop_phase, params)))))
        theta, v = float(step.theta) % (2 * math.pi), float(step.v)
    assert np.mean(log_det) == pytest.approx(2 * math.log(0.5), abs=2e-3)


def gamma_params(gamma, alpha=0.5):
    """alpha, g 9.81, tau 0.92 and a_r set by Gamma = a_r w^2 / g."""
    return ModelParams(alpha, 9.81, gamma * 9.81 / (2 * math.pi / 0.92) ** 2, 0.92)


def sweep_exponents(base, gammas, theta0_deg, v0, transient=1000, measured=2000):
    """Exponents of the orbits from (theta0_deg[i], v0[i]) at Gamma gammas[i], in one batch."""
    settings = SweepSettings(transient_impacts=transient, measured_impacts=measured)
    arrays = sweep_parameters(base, "gamma", gammas)
    orbits = iterate_sweep(np.radians(theta0_deg), v0, arrays, settings)
    return orbits.lyapunov


def test_exponent_at_the_stable_period1_orbit_is_ln_of_eq10_radius(paper_params):
    """Fig. 4 parameters (alpha 0.5, g 9.81, a_r 0.30, tau 0.92): complex eigenvalues of
    modulus alpha, so the exponent is ln 0.5, from any start that reaches the period-1
    attractor."""
    assert stability(paper_params).spectral_radius == pytest.approx(0.5, abs=1e-12)
    gamma = paper_params.racket_amplitude * paper_params.omega**2 / paper_params.g
    exponents = sweep_exponents(paper_params, [gamma] * 4, [45.0, 43.1, 90.0, 135.0],
                                [5.0, 4.8, 3.0, 3.0])
    # measured over 2000 impacts: the norm of J^n u oscillates within a bounded factor, so
    # the mean log growth is within O(1/2000) of ln 0.5
    np.testing.assert_allclose(exponents, math.log(0.5), atol=2e-3)


@pytest.mark.slow
def test_exponent_matches_eq10_in_the_real_regime_too(paper_params):
    """Real eigenvalues, near the fold (Gamma 1.05: -0.111 < AC < 0) and near the flip (1.45,
    1.5: AC below -1): the exponent is ln max |lambda| of eq. 10, not ln alpha. Started 5 %
    above the fixed point's velocity."""
    gammas = [1.05, 1.45, 1.5]
    expected, theta0, v0 = [], [], []
    for gamma in gammas:
        st, fp = stability(gamma_params(gamma)), gamma_params(gamma).fixed_point()
        assert st.stable and st.regime == "real"
        expected.append(math.log(st.spectral_radius))
        theta0.append(fp.theta_deg)
        v0.append(1.05 * fp.v_m_s)
    exponents = sweep_exponents(paper_params, gammas, theta0, v0, transient=3000, measured=3000)
    np.testing.assert_allclose(exponents, expected, atol=3e-3)


def test_tangent_product_equals_eq9_power_at_the_fixed_point(paper_params):
    """Started on the fixed point the tangent dynamics is J^n u with J of eq. 9: the summed
    log growth equals log ||D J^n D^-1 u|| exactly (to rounding)."""
    fp = paper_params.fixed_point()
    J = jacobian(paper_params)
    D = np.diag([paper_params.omega / paper_params.g, 1.0])
    u = initial_tangent(1)
    total = 0.0
    for _ in range(200):
        jac = map_jacobian([fp.theta_rad], [fp.v_m_s], [2 * math.pi], paper_params)
        u, growth = advance_tangent(u, jac, paper_params)
        total += float(growth[0])
    product = D @ np.linalg.matrix_power(J, 200) @ np.linalg.inv(D) @ initial_tangent(1)[0]
    assert total == pytest.approx(math.log(np.linalg.norm(product)), rel=1e-9)


def two_orbit_exponent(params, theta, v, transient, measured, separation=1e-9):
    """Benettin's method on the map itself (no Jacobian): a companion orbit at distance
    ``separation`` (scaled coordinates v w/g, theta) is iterated, the log growth of the
    distance accumulated and the companion pulled back to ``separation`` after every impact."""
    scale = params.omega / params.g
    dv, dt = 0.6 * separation / scale, 0.8 * separation
    total = 0.0
    for k in range(transient + measured):
        step = map_step(np.array([theta, theta + dt]), np.array([v, v + dv]), params)
        th, vv = step.theta, step.v
        ev, et = (vv[1] - vv[0]) * scale, th[1] - th[0]
        d = math.hypot(ev, et)
        if k >= transient:
            total += math.log(d / separation)
        dv, dt = ev / d * separation / scale, et / d * separation
        theta, v = float(th[0]) % (2 * math.pi), float(vv[0])
        # the companion follows the reference phase modulo 2 pi
    return total / measured


@pytest.mark.slow
def test_chaotic_exponent_agrees_with_two_nearby_orbits():
    """At Gamma = 1.75 (alpha 0.5) the attractor is chaotic: positive exponent, and the
    Jacobian route agrees with the divergence of two orbits of the map."""
    params = gamma_params(1.75)
    transient, measured = 500, 3000
    settings = SweepSettings(transient_impacts=transient, measured_impacts=measured)
    orbits = iterate_sweep([math.radians(90.0)], [5.0],
                           sweep_parameters(params, "alpha", [0.5]), settings)
    assert orbits.stuck_at[0] == -1
    jacobian_route = float(orbits.lyapunov[0])
    benettin = two_orbit_exponent(params, math.radians(90.0), 5.0, transient, measured)
    assert jacobian_route > 0.2
    assert jacobian_route == pytest.approx(benettin, abs=1e-4)  # measured: 0.375312 both


def test_batch_means_standard_error_by_hand_and_for_independent_growth():
    """SD of the batch means / sqrt(B): by hand on four batches; for independent log growths
    of SD sigma it is sigma / sqrt(N) on average (the textbook error of a mean), whatever the
    batch lengths (N not a multiple of B)."""
    from bounce_cli.analysis.bifurcation import lyapunov_standard_error

    sums = np.array([[1.0, 2.0, 3.0, 6.0]])  # 4 batches of 2 impacts: means 0.5 1 1.5 3
    expected = np.std([0.5, 1.0, 1.5, 3.0], ddof=1) / 2.0
    assert lyapunov_standard_error(sums, 8)[0] == pytest.approx(expected, rel=1e-14)
    # 13 impacts in 4 batches: impact i in batch i * 4 // 13, so of 4, 3, 3 and 3 impacts
    sums = np.array([[4.0, 6.0, 9.0, 3.0]])
    expected = np.std([4.0 / 4, 6.0 / 3, 9.0 / 3, 3.0 / 3], ddof=1) / 2.0
    assert lyapunov_standard_error(sums, 13)[0] == pytest.approx(expected, rel=1e-14)
    assert np.isnan(lyapunov_standard_error(np.ones((3, 1)), 5)).all()  # one batch: no error

    rng = np.random.default_rng(7)
    n_states, measured, batches, sigma = 4000, 1003, 10, 0.8
    growth = rng.normal(0.3, sigma, (n_states, measured))
    which = np.arange(measured) * batches // measured  # iterate_sweep's assignment
    sums = np.stack([growth[:, which == j].sum(axis=1) for j in range(batches)], axis=1)
    se = lyapunov_standard_error(sums, measured)
    # E[SE^2] = sigma^2 / N (the batch means have variance sigma^2 B / N)
    assert np.mean(se**2) == pytest.approx(sigma**2 / measured, rel=0.05)


@pytest.mark.slow
def test_exponent_standard_error_matches_the_scatter_of_exponents_on_one_chaotic_attractor():
    """Independent route: 40 orbits on the chaotic attractor at Gamma = 1.75 give 40
    finite-time exponents whose scatter is what each orbit's batch-means error says; a
    period-1 orbit (Gamma = 1.3) has an error at rounding level, and an orbit whose transient
    ends while it is measured has an error that covers it."""
    params = gamma_params(1.75)
    settings = SweepSettings(transient_impacts=300, measured_impacts=800)
    rng = np.random.default_rng(3)
    n = 40
    orbits = iterate_sweep(rng.uniform(0.5, 1.5, n), rng.uniform(4.5, 5.5, n),
                           sweep_parameters(params, "alpha", [0.5] * n), settings)
    chaotic = (orbits.stuck_at < 0) & (orbits.lyapunov > 0.1)
    assert chaotic.sum() >= 20
    scatter = np.std(orbits.lyapunov[chaotic], ddof=1)
    typical_se = math.sqrt(np.mean(orbits.lyapunov_se[chaotic] ** 2))
    assert 0.5 < scatter / typical_se < 2.0, (scatter, typical_se)  # measured: 0.92

    # near the period-1 orbit at Gamma = 1.3 (eq. 8: theta~ = 36.34 deg, v~ = 4.5126 m/s): a
    # complex pair of multipliers turns the tangent vector, so batches differ a little
    period1 = iterate_sweep([math.radians(36.0)], [4.5], sweep_parameters(
        gamma_params(1.3), "alpha", [0.5]), settings)
    assert period1.lyapunov[0] == pytest.approx(math.log(0.5), abs=0.01)  # eq. 12: |lambda|
    assert period1.lyapunov_se[0] < 0.01 * abs(period1.lyapunov[0])  # measured: 0.0028


def test_the_sweeps_standard_error_is_that_of_its_own_log_growths():
    """Independent route to iterate_sweep's batches: the orbit followed impact by impact
    (map_step, map_jacobian, advance_tangent), its measured log growths cut into 10 equal
    batches by numpy, give the same exponent and standard error. On the period-1 orbit at
    Gamma 1.3, whose complex multipliers turn the tangent vector (batches differ), and which
    no last bit can send elsewhere."""
    params = gamma_params(1.3)
    transient, measured = 150, 400
    orbits = iterate_sweep([math.radians(36.0)], [4.5], sweep_parameters(params, "alpha", [0.5]),
                           SweepSettings(transient_impacts=transient, measured_impacts=measured))
    theta, v, tangent, growths = math.radians(36.0), 4.5, initial_tangent(1), []
    for k in range(1, transient + measured + 1):
        step = map_step(np.array([theta]), np.array([v]), params)
        jac = map_jacobian(np.array([theta]), np.array([v]), step.hop_phase, params)
        tangent, growth = advance_tangent(tangent, jac, params)
        if k > transient:
            growths.append(float(growth[0]))
        theta, v = float(np.mod(step.theta[0], 2 * math.pi)), float(step.v[0])
    means = [batch.mean() for batch in np.array_split(np.array(growths), 10)]
    assert orbits.stuck_at[0] == -1
    assert orbits.lyapunov[0] == pytest.approx(np.mean(growths), rel=1e-9)
    assert orbits.lyapunov_se[0] == pytest.approx(np.std(means, ddof=1) / math.sqrt(10),
                                                  rel=1e-6)
    assert orbits.lyapunov_se[0] > 1e-4  # the batches do differ


def test_peak_stretch_is_the_largest_divergence_of_two_nearby_orbits():
    """Independent route to iterate_sweep's peak_stretch: two orbits of the map itself
    started 1e-12 apart along the initial tangent (scaled coordinates), followed without
    renormalising over 40 impacts of the chaotic attractor at Gamma 1.75 (still linear:
    1e-12 e^18.3 is 9e-5); the largest ln of their separation over the start's is the
    stretch (measured: 18.33)."""
    from bounce_cli.model.params import phase_difference

    params = gamma_params(1.75)
    impacts, delta = 40, 1e-12
    settings = SweepSettings(transient_impacts=0, measured_impacts=impacts, recorded_impacts=2,
                             max_period=1)
    theta0, v0 = math.radians(90.0), 5.0
    orbits = iterate_sweep([theta0], [v0], sweep_parameters(params, "alpha", [0.5]), settings)
    scale = params.omega / params.g  # m/s -> dimensionless velocity (as the tangent)
    u = initial_tangent(1)[0]
    theta = np.array([theta0, theta0 + delta * u[1]])
    v = np.array([v0, v0 + delta * u[0] / scale])
    largest = 0.0
    for _ in range(impacts):
        step = map_step(theta, v, params)
        theta, v = step.theta, step.v
        apart = math.hypot((v[1] - v[0]) * scale, float(phase_difference(theta[1], theta[0])))
        largest = max(largest, math.log(apart / delta))
    assert orbits.stuck_at[0] == -1 and 8.0 < largest < 25.0
    assert orbits.peak_stretch[0] == pytest.approx(largest, abs=0.05)
