"""The virtual ball on a sampled racket against the ball bouncing map (eqs. 5-6) and against
constructed racket samples whose crossings are known."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bounce_cli.model.flight import leave_phase
from bounce_cli.model.maps import iterate_map
from bounce_cli.paper.values import FIG3_MODEL
from bounce_cli.virtual.physics import VirtualBall
from bounce_cli.virtual.sources import SineSource

P = FIG3_MODEL  # Figs. 3-4: alpha 0.5, a_r 0.30 m, tau 0.92 s


def sine_ball(theta0, v0, rate_hz, duration_s, params=P):
    ball = VirtualBall(g=params.g, alpha_of=lambda k: (params.alpha, False))
    ball.launch_from_racket(theta0 / params.omega, v0)
    source = SineSource(params.racket_amplitude, params.racket_period, rate_hz)
    heights = [(t, x, ball.push(t, x)[1]) for t, x in source.samples(1, duration_s)]
    return ball, np.array(heights)


def map_errors(ball, theta0, v0, params=P):
    n = len(ball.impacts)
    theta, v, _ = iterate_map(np.array([theta0]), np.array([v0]), params, n)
    t = np.array([i.t_s for i in ball.impacts])
    vv = np.array([i.v_m_s for i in ball.impacts])
    return np.max(np.abs(t - theta[1:, 0] / params.omega)), np.max(np.abs(vv - v[1:, 0]))


@pytest.mark.parametrize("theta0, v0", [(0.6, 4.2), (0.746, 4.5126), (0.2, 4.8)])
def test_sine_source_at_1khz_is_the_map_at_every_impact(theta0, v0):
    ball, _ = sine_ball(theta0, v0, 1000.0, 25.0)
    assert len(ball.impacts) >= 25
    dt, dv = map_errors(ball, theta0, v0)
    assert dt < 1e-6 and dv < 1e-6


def test_interpolation_error_falls_as_h_cubed():
    """O(h^3) in the racket's velocity: 10x the rate, about 1000x smaller (at least 300x)."""
    errors = [map_errors(sine_ball(0.6, 4.2, rate, 15.0)[0], 0.6, 4.2)[1]
              for rate in (100.0, 1000.0)]
    assert errors[0] < 1e-3  # 100 Hz: below a millimetre per second
    assert errors[0] / errors[1] > 300.0


def test_first_of_three_crossings_and_a_graze_inside_one_interval():
    """Racket samples of r(t) = ball(t) - c (t - t1)(t - t2)(t - t3): the gap is that cubic,
    positive at every sample, its first root t1 inside the last interval (where the cubic
    through the latest four samples is r itself)."""
    g, h = 9.81, 0.01

    def run(roots):
        c = -1000.0

        def racket(t):
            return 1.0 - 0.5 * g * t * t - c * np.prod([t - r for r in roots])

        ball = VirtualBall(g=g, alpha_of=lambda k: (0.5, False))
        ball.drop(0.0, 1.0)
        impacts = []
        for t in h * np.arange(6):
            impacts += ball.push(t, float(racket(t)))[0]
        return impacts

    three = run((0.0425, 0.045, 0.0475))
    assert len(three) == 1 and three[0].t_s == pytest.approx(0.0425, abs=1e-12)
    graze = run((0.044, 0.046, 0.5))  # both samples of the interval above the racket
    assert len(graze) == 1 and graze[0].t_s == pytest.approx(0.044, abs=1e-12)


def test_sticking_ball_rides_the_racket_and_leaves_where_it_outruns_g():
    """Fig. 3's sticking start (5.7 m/s): once stuck the ball is on the racket, and it leaves
    where a_r w^2 sin(w t) = g (section 3)."""
    theta0 = math.asin(0.205 / 0.30)
    ball, samples = sine_ball(theta0, 5.7, 1000.0, 20.0)
    stuck = [i for i in ball.impacts if i.stuck]
    assert stuck, "the 5.7 m/s start falls into sticking (Fig. 3)"
    first = stuck[0]
    after = ball.impacts[first.k + 1]
    # the next flight leaves at the leave phase after the stuck impact
    t_leave = leave_phase(P.omega * first.t_s, P) / P.omega
    hop = after.t_s - t_leave
    assert hop > 0.0
    t, racket, height = samples.T
    riding = (t > first.t_s + 2e-3) & (t < t_leave - 2e-3)
    assert np.allclose(height[riding], racket[riding], atol=1e-9)


def test_a_stream_gap_pauses_the_ball_and_it_never_goes_through_the_racket():
    ball = VirtualBall(g=P.g, alpha_of=lambda k: (P.alpha, False), max_gap_s=0.05)
    fixed = P.fixed_point()
    ball.launch_from_racket(fixed.theta_rad / P.omega, fixed.v_m_s)
    source = SineSource(P.racket_amplitude, P.racket_period, 500.0)
    rows = []
    for t, x in source.samples(1, 20.0):
        if 5.0 < t < 5.3 or 11.0 < t < 11.02:  # a 0.3 s stall and a bridged 20 ms hole
            continue
        rows.append((t, x, ball.push(t, x)[1]))
    t, racket, height = np.array(rows).T
    assert len(ball.gaps) == 1 and ball.gaps[0].t_end_s - ball.gaps[0].t_start_s > 0.29
    assert np.all(height >= racket - 1e-9)
    assert len(ball.impacts) > 15


def test_samples_out_of_order_are_refused():
    from bounce_cli.model.params import ModelError

    ball = VirtualBall(g=9.81, alpha_of=lambda k: (0.5, False))
    ball.push(0.0, 0.0)
    with pytest.raises(ModelError, match="increasing time"):
        ball.push(0.0, 0.1)


def test_the_cubic_s_velocity_noise_gain_is_measured_on_white_noise():
    """CUBIC_VELOCITY_NOISE_GAIN (1.945, the RMS of the cubic's derivative weights over the
    last interval) against the racket's velocity through the physics' own interpolant on
    samples of pure white noise, at uniform times in the interval: within 2 %."""
    from bounce_cli.virtual.physics import (CUBIC_VELOCITY_NOISE_GAIN, RacketInterval,
                                            racket_velocity_noise_m_s)

    rng = np.random.default_rng(4)
    h, sigma = 0.005, 2e-4
    times = np.arange(4) * h
    velocities = [RacketInterval(times, rng.normal(0.0, sigma, 4)).velocity(
        times[2] + rng.uniform(0.0, h)) for _ in range(40_000)]
    measured = float(np.sqrt(np.mean(np.square(velocities))))
    assert measured == pytest.approx(racket_velocity_noise_m_s(sigma, h), rel=0.02)
    assert racket_velocity_noise_m_s(sigma, h) == pytest.approx(
        CUBIC_VELOCITY_NOISE_GAIN * sigma / h)
