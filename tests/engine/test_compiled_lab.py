"""The simulated lab's compiled contact loop (``data.compiled_lab``) against its Python loop:
the same seeds give the same impacts, bit for bit, and the same errors."""

from __future__ import annotations

import numpy as np
import pytest

from bounce_cli.data import simulated_lab
from bounce_cli.data.simulated_lab import SessionSettings, simulate_session, simulate_trial
from bounce_cli.errors import ModelError
from bounce_cli.model.params import ModelParams

pytest.importorskip("numba")

PARAMS = ModelParams(alpha=0.55, g=9.81, racket_amplitude=0.11, racket_period=0.6)


def _both(monkeypatch, make):
    """make() under the Python loop, then under the compiled one."""
    out = []
    for route in ("python", "auto"):
        monkeypatch.setenv("BOUNCE_LAB", route)
        out.append(make())
    return out


def _assert_same_truth(a, b):
    for name in ("flight_starts", "flight_x", "flight_v", "impact_t", "impact_v",
                 "impact_alpha", "impact_perturbed", "impact_v_in", "impact_contact_s"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and x.shape == y.shape, name
        np.testing.assert_array_equal(x, y, err_msg=name)
    for name, column in simulated_lab.truth_rows(a).items():
        np.testing.assert_array_equal(column, simulated_lab.truth_rows(b)[name], err_msg=name)


def test_compiled_route_is_taken():
    assert simulated_lab.compiled_lab_available()
    assert simulated_lab.common_path(SessionSettings())
    assert not simulated_lab.common_path(SessionSettings(drift_amplitude_m=0.01))


@pytest.mark.parametrize("seed", range(8))
def test_trials_bit_identical(monkeypatch, seed):
    """Cycle-wise racket and velocity noise (the VARX calibration's sessions): every flight,
    impact and truth column equal, and the velocity stream left where the Python loop leaves
    it."""
    settings = SessionSettings(n_trials=1, duration_s=60.0, period_sd_s=0.01,
                               amplitude_sd_m=0.003, velocity_noise_m_s=0.04)

    def make():
        streams = [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(3)]
        truth = simulate_trial(PARAMS, settings, streams)
        return truth, streams[1].standard_normal(3)

    (a, after_a), (b, after_b) = _both(monkeypatch, make)
    assert len(a.impact_t) > 50
    _assert_same_truth(a, b)
    np.testing.assert_array_equal(after_a, after_b)


def test_sessions_bit_identical(monkeypatch):
    """simulate_session's trials with measurement noise (bounce simulate-recording's route)."""
    settings = SessionSettings(n_trials=3, duration_s=20.0, position_noise_m=0.0005,
                               period_sd_s=0.005, amplitude_sd_m=0.002,
                               velocity_noise_m_s=0.03, seed=11)
    a, b = _both(monkeypatch, lambda: simulate_session(PARAMS, settings))
    for (ta, sa), (tb, sb) in zip(a, b):
        _assert_same_truth(ta, tb)
        for x, y in zip(sa, sb):
            np.testing.assert_array_equal(x, y)


def test_sticking_raises_the_same_error(monkeypatch):
    """A noise that makes the ball stick: the same ModelError from both routes."""
    settings = SessionSettings(n_trials=1, duration_s=60.0, velocity_noise_m_s=1.5)
    messages = []
    for route in ("python", "auto"):
        monkeypatch.setenv("BOUNCE_LAB", route)
        streams = [np.random.default_rng(s) for s in np.random.SeedSequence(4).spawn(3)]
        with pytest.raises(ModelError) as error:
            simulate_trial(PARAMS, settings, streams)
        messages.append(str(error.value))
    assert messages[0] == messages[1]
    assert "sticking" in messages[0]


def test_simulate_runs_bit_identical(monkeypatch):
    """The data side's model sessions (``data.simulated_runs.simulate_runs``), redraws included."""
    from bounce_cli.data.simulated_runs import RacketSession, simulate_runs

    session = RacketSession(0.01, 0.003, 0.04)
    a, b = _both(monkeypatch, lambda: [simulate_runs(PARAMS, session, [80, 120],
                                                     np.random.SeedSequence([5, i]))
                                       for i in range(3)])
    for (runs_a, redrawn_a), (runs_b, redrawn_b) in zip(a, b):
        assert redrawn_a == redrawn_b
        for x, y in zip(runs_a, runs_b):
            for name in ("v_m_s", "theta_rad", "racket_period_s", "racket_amplitude_m"):
                np.testing.assert_array_equal(getattr(x, name), getattr(y, name))
