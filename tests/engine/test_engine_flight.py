"""Continuous-time simulation (eqs. 1-4) with sticking: engine/flight.py."""

import math

import numpy as np
import pytest

from bounce_cli.model.flight import FlightSettings, leave_phase, simulate
from bounce_cli.model.maps import iterate_orbit
from bounce_cli.model.params import ModelError, ModelParams, phase_difference

THETA0 = math.asin(0.205 / 0.30)  # x_b(0) = 0.205 m on the racket (section 3)
PERIOD1_V0, STICKING_V0 = 4.8, 5.7  # Fig. 3 top and bottom


@pytest.fixture(scope="module")
def params(paper_params):
    return paper_params


@pytest.fixture(scope="module")
def runs(params):
    """Both Fig. 3 cases with both integrators over 10 s."""
    return {
        (v0, integ): simulate(THETA0, v0, params, 10.0, FlightSettings(integrator=integ))
        for v0 in (PERIOD1_V0, STICKING_V0)
        for integ in ("exact", "rk4")
    }


def flight_before(traj, t):
    """The flight segment that ends at time t."""
    (seg,) = [s for s in traj.segments if s.kind == "flight" and s.t_end == t]
    return seg


@pytest.mark.parametrize("integ", ["exact", "rk4"])
@pytest.mark.parametrize("v0", [PERIOD1_V0, STICKING_V0])
def test_ball_never_below_racket(runs, params, v0, integ):
    traj = runs[(v0, integ)]
    t = np.linspace(traj.t0, traj.t_end, 200_001)
    x, _, stuck = traj.sample(t)
    height = x - params.racket_position(params.omega * t)
    assert height.min() > -1e-9
    assert np.all(np.abs(height[stuck]) < 1e-12)
    # and it really flies: far above the racket at some time
    assert height.max() > 0.3


@pytest.mark.parametrize("integ", ["exact", "rk4"])
@pytest.mark.parametrize("v0", [PERIOD1_V0, STICKING_V0])
def test_each_impact_obeys_eq3(runs, params, v0, integ):
    traj = runs[(v0, integ)]
    assert len(traj.impacts) >= 10
    w, alpha = params.omega, params.alpha
    for im in traj.impacts:
        seg = flight_before(traj, im.t_s)
        dt = im.t_s - seg.t_start
        # ball meets the racket (eqs. 1 and 4 equal) ...
        x_ball = seg.x_start + seg.v_start * dt - params.g * dt * dt / 2
        assert x_ball == pytest.approx(float(params.racket_position(w * im.t_s)), abs=1e-9)
        # ... arrives with the velocity of eq. 2, moving down relative to the racket ...
        v_r = params.racket_amplitude * w * math.cos(w * im.t_s)
        assert im.v_before_m_s == pytest.approx(seg.v_start - params.g * dt, abs=1e-12)
        assert im.v_before_m_s < v_r
        # ... and leaves by eq. 3 with an unchanged racket velocity
        assert im.v_after_m_s - v_r == pytest.approx(-alpha * (im.v_before_m_s - v_r), abs=1e-12)


def test_exact_and_rk4_impact_times_agree_within_a_step(runs):
    exact, rk4 = runs[(PERIOD1_V0, "exact")], runs[(PERIOD1_V0, "rk4")]
    assert len(exact.impacts) == len(rk4.impacts) == 10
    diff = max(abs(a.t_s - b.t_s) for a, b in zip(exact.impacts, rk4.impacts))
    assert diff < 1e-3  # the RK4 step
    # the sticking case: same impacts and the same stuck phases as well
    exact, rk4 = runs[(STICKING_V0, "exact")], runs[(STICKING_V0, "rk4")]
    assert len(exact.impacts) == len(rk4.impacts)
    assert np.allclose(exact.stuck_phases, rk4.stuck_phases, atol=1e-3)


def test_period1_case_converges_to_fixed_point(params):
    fp = params.fixed_point()
    traj = simulate(THETA0, PERIOD1_V0, params, 30.0)
    assert not traj.stuck_phases
    last = traj.impacts[-1]
    assert abs(last.v_after_m_s - fp.v_m_s) < 1e-3
    assert abs(phase_difference(last.theta_rad, fp.theta_rad)) < 1e-3
    # one impact per racket period at the attractor
    hops = [im.hop_s for im in traj.impacts[-5:]]
    assert hops == pytest.approx([params.racket_period] * 5, abs=1e-3)
    # and it was not there from the start
    assert abs(traj.impacts[0].v_after_m_s - fp.v_m_s) > 0.1


def test_sticking_phases_end_where_racket_acceleration_is_minus_g(runs, params):
    traj = runs[(STICKING_V0, "exact")]
    w, g = params.omega, params.g
    phases = traj.stuck_phases
    assert len(phases) >= 5
    ended = [(a, b) for a, b in phases if b < traj.t_end]
    assert ended
    for start, end in ended:
        assert end > start
        # leaving: racket acceleration -a w^2 sin(w t) = -g while the racket decelerates more
        assert float(params.racket_acceleration(w * end)) / g == pytest.approx(-1.0, abs=1e-9)
        assert math.cos(w * end) > 0.0
        # while stuck the racket never pulled away faster than gravity
        t = np.linspace(start, end, 200)[:-1]
        assert np.all(params.racket_acceleration(w * t) > -g)
        # the ball starts its flight with the racket's velocity
        (nxt,) = [s for s in traj.segments if s.t_start == end and s.kind == "flight"]
        assert nxt.v_start == pytest.approx(float(params.racket_velocity(w * end)), abs=1e-12)
    # sticking starts at an impact whose hop was short
    starts = {a for a, _ in phases}
    short = [im for im in traj.impacts if im.t_s in starts]
    assert len(short) == len(phases)
    assert all(im.hop_s < 1e-3 or im.v_after_m_s - im.racket_v_m_s <= 1e-3 for im in short)
    # after the transient the sticking solution repeats with the racket period
    durations = np.diff(np.array(ended[1:])[:, 0])
    assert durations == pytest.approx(params.racket_period, abs=1e-6)


@pytest.mark.parametrize("v0", [PERIOD1_V0, STICKING_V0])
def test_impacts_equal_the_maps_orbit(runs, params, v0):
    traj = runs[(v0, "exact")]
    orbit = iterate_orbit(THETA0, v0, params, len(traj.impacts), 1e-3)
    n = len(orbit.theta) - 1
    if v0 == STICKING_V0:
        assert orbit.stop_reason == "sticking" and n >= 5
        assert traj.stuck_phases[0][0] == pytest.approx(orbit.theta[-1] / params.omega, abs=1e-9)
    sim_theta = np.array([im.theta_rad for im in traj.impacts[:n]])
    sim_v = np.array([im.v_after_m_s for im in traj.impacts[:n]])
    np.testing.assert_allclose(sim_theta, orbit.theta[1:], rtol=0, atol=1e-9)
    np.testing.assert_allclose(sim_v, orbit.v[1:], rtol=0, atol=1e-9)


def test_leave_phase(params):
    r = params.g / (params.racket_amplitude * params.omega**2)
    crossing = math.asin(r)
    assert leave_phase(0.0, params) == pytest.approx(crossing)
    assert leave_phase(crossing + 2 * math.pi, params) == pytest.approx(crossing + 2 * math.pi)
    assert leave_phase(math.pi / 2, params) == math.pi / 2  # already beyond g: leaves at once
    assert leave_phase(3.0, params) == pytest.approx(crossing + 2 * math.pi)  # sin < r, falling
    assert leave_phase(1.0, ModelParams(0.5, 9.81, 0.05, 0.92)) == math.inf


def test_weak_racket_keeps_the_ball_stuck():
    weak = ModelParams(alpha=0.5, g=9.81, racket_amplitude=0.05, racket_period=0.92)
    assert weak.racket_amplitude * weak.omega**2 < weak.g
    traj = simulate(0.3, 0.0, weak, 3.0)  # slower than the racket: cannot leave
    assert [s.kind for s in traj.segments] == ["stuck"] and not traj.impacts
    assert traj.segments[0].t_end == traj.t_end
    traj = simulate(0.3, 3.0, weak, 5.0)  # thrown up: bounces, then stays on the racket
    assert traj.impacts and traj.segments[-1].kind == "stuck"
    assert traj.segments[-1].t_end == traj.t_end


def test_inelastic_ball_sticks_at_first_impact(params):
    traj = simulate(THETA0, PERIOD1_V0, params.with_alpha(0.0), 3.0)
    first = traj.impacts[0]
    assert first.v_after_m_s == pytest.approx(first.racket_v_m_s)
    assert traj.stuck_phases[0][0] == first.t_s


@pytest.mark.parametrize(
    "kwargs", [{"integrator": "euler"}, {"rk4_step_s": 0.0}, {"min_hop_s": -1.0}]
)
def test_bad_settings(kwargs):
    with pytest.raises(ModelError):
        FlightSettings(**kwargs)


def test_rk4_hop_shorter_than_a_substep_counts_as_sticking(params):
    """Leaving the racket at its lowest point (racket accelerating upwards at a_r w^2) 1 mm/s
    faster than it, the ball lands after ~8e-5 s: shorter than a 5 ms step's sub-step
    (3.1e-4 s), so rk4 cannot resolve the hop and the ball rides on the racket from the
    launch; the exact integrator records the short hop, then sticks. Both leave at the
    same analytic phase and continue identically."""
    theta0 = 1.5 * math.pi
    v0 = float(params.racket_velocity(theta0)) + 1e-3
    exact = simulate(theta0, v0, params, 1.0, FlightSettings())
    rk4 = simulate(theta0, v0, params, 1.0, FlightSettings(integrator="rk4", rk4_step_s=5e-3))
    first = rk4.segments[0]
    assert first.kind == "stuck" and first.t_start == pytest.approx(theta0 / params.omega)
    assert exact.segments[0].kind == "flight" and exact.impacts[0].hop_s < 1e-3
    assert exact.segments[1].kind == "stuck"
    assert first.t_end == pytest.approx(exact.segments[1].t_end, abs=1e-12)
    assert len(rk4.impacts) == len(exact.impacts) - 1
    for a, b in zip(rk4.impacts, exact.impacts[1:]):
        assert a.t_s == pytest.approx(b.t_s, abs=1e-9)
