"""``bounce trajectory`` with ``model.control``: the continuous motion of ball and racket with
racket period control (``engine.control.simulate_controlled_motion``) gives the controlled
map's impacts, keeps the racket's position continuous, and gain 0 is the passive run byte for
byte."""

import math

import numpy as np
import pytest

from bounce_cli.runtime.config import ConfigError, bundled_config_path, load_config
from bounce_cli.model.params import ModelParams
from bounce_cli.model.control import (
    PeriodController,
    iterate_controlled_orbit,
    simulate_controlled_motion,
)
from bounce_cli.model.flight import FlightSettings
from bounce_cli.experiments import trajectory
from bounce_cli.experiments.base import RunOptions


def run(overrides):
    config = load_config(trajectory.TrajectoryConfig, bundled_config_path("trajectory"),
                         overrides)
    return trajectory.run(config, RunOptions())


def test_gain_zero_is_the_passive_run_byte_for_byte():
    passive, zero = run([]), run(["model.control.gain=0"])
    for name, frame in passive.frames.items():
        assert frame.to_csv(index=False) == zero.frames[name].to_csv(index=False), name


@pytest.mark.parametrize("v0", [4.8, 5.7])
def test_continuous_motion_gives_the_controlled_maps_impacts(v0):
    params = ModelParams(0.5, 9.81, 0.3, 0.92)
    controller = PeriodController(0.7, 0.8)
    theta0 = math.asin(0.205 / 0.30)
    traj, clock, periods = simulate_controlled_motion(theta0, v0, params, controller, 10.0,
                                                      FlightSettings())
    n = len(traj.impacts)
    assert n >= 9 and not traj.stuck_phases  # control keeps even the Fig. 3 sticking start
    orbit = iterate_controlled_orbit(theta0, v0, params, controller, n, 1e-3)
    assert np.allclose([im.v_after_m_s for im in traj.impacts], orbit.v[1:], atol=1e-9)
    assert np.allclose([im.theta_rad for im in traj.impacts], orbit.theta[1:], atol=1e-9)
    assert np.allclose(periods, orbit.tau[1:], atol=1e-12)
    assert np.allclose([im.t_s for im in traj.impacts], orbit.t_s[1:], atol=1e-9)
    # the racket's position is continuous at each impact, its velocity jumps with the period
    t = np.array([im.t_s for im in traj.impacts])
    before, w_before = clock.phase(t - 1e-9)
    after, w_after = clock.phase(t + 1e-9)
    assert np.allclose(np.sin(before), np.sin(after), atol=1e-7)
    assert np.abs(w_after - w_before).max() > 0.1


def test_trajectory_with_control_writes_the_period_and_refuses_rk4():
    result = run(["model.control.gain=0.7", "model.control.rate=0.8"])
    impacts = result.frames["impacts.csv"]
    assert "racket_period_s" in impacts.columns
    assert impacts["racket_period_s"].iloc[0] == pytest.approx(0.92)
    assert impacts["racket_period_s"].nunique() > 3
    with pytest.raises(ConfigError, match="integrator"):
        run(["model.control.gain=0.7", "integrator=rk4"])


@pytest.mark.parametrize("gain", [0.0, 0.05])
def test_controlled_motion_sticks_and_leaves_where_the_racket_outruns_gravity(gain):
    """The stuck/leave branch of the one event loop with the controlled racket: Fig. 3's
    sticking start (v0 = 5.7 m/s) sticks under a weak controller too; while stuck the ball is
    the racket, and it leaves where the racket's acceleration reaches -g at the period the
    racket has then (a w^2 sin(phase) = g); with gain 0 the motion is the passive one."""
    from bounce_cli.model.flight import simulate

    params = ModelParams(0.5, 9.81, 0.3, 0.92)
    theta0 = math.asin(0.205 / 0.30)
    traj, clock, periods = simulate_controlled_motion(
        theta0, 5.7, params, PeriodController(gain, 1.0), 6.0, FlightSettings())
    stuck = [s for s in traj.segments if s.kind == "stuck"]
    assert stuck, "the run never stuck"
    for seg in stuck[:-1] if stuck[-1].t_end == traj.t_end else stuck:
        phase, omega = clock.phase(seg.t_end)
        assert params.racket_amplitude * omega**2 * math.sin(phase) == pytest.approx(
            params.g, rel=1e-9)
        # the ball leaves with the racket's velocity (the next flight starts from it)
        after = next(s for s in traj.segments if s.t_start == seg.t_end and s.kind == "flight")
        assert after.v_start == pytest.approx(params.racket_amplitude * omega
                                              * math.cos(phase), abs=1e-12)
        # riding: at its start the ball is where the racket is
        ph0, w0 = clock.phase(seg.t_start)
        assert seg.x_start == pytest.approx(params.racket_amplitude * math.sin(ph0), abs=1e-12)
    assert len(periods) == len(traj.impacts)
    if gain == 0.0:
        passive = simulate(theta0, 5.7, params, 6.0, FlightSettings())
        assert np.allclose([s.t_end for s in stuck], [s.t_end for s in passive.segments
                                                      if s.kind == "stuck"], atol=1e-9)
        assert np.allclose([im.t_s for im in traj.impacts],
                           [im.t_s for im in passive.impacts], atol=1e-9)
        assert np.all(periods == params.racket_period)
    else:
        assert np.ptp(periods) > 0  # the controller moved the period
