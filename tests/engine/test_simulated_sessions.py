"""data/simulated_runs.py: every run of every model session simulated at once is the
simulated lab's own trial, run by run (simulate_trial, the Python loop and the compiled one),
bit for bit: the same draws, the same impacts, the same retries."""

from __future__ import annotations

import numpy as np
import pytest

from bounce_cli.data import simulated_lab
from bounce_cli.data.simulated_lab import SessionSettings, impact_state, simulate_trial
from bounce_cli.data.simulated_runs import (
    MAX_SIMULATION_RETRIES,
    SIMULATION_BURN_IN,
    RacketSession,
    run_duration,
    simulate_runs,
    simulate_sessions,
)
from bounce_cli.model.params import ModelError, ModelParams


def one_run_at_a_time(params, session, lengths, seed):
    """The reference: each run by simulate_trial, retried on sticking (the route before
    simulate_sessions)."""
    runs, redrawn = [], 0
    for n, run_seed in zip(lengths, seed.spawn(len(lengths))):
        settings = SessionSettings(n_trials=1, duration_s=run_duration(params, n),
                                   period_sd_s=session.period_sd_s,
                                   amplitude_sd_m=session.amplitude_sd_m,
                                   velocity_noise_m_s=session.velocity_noise_m_s)
        for _ in range(MAX_SIMULATION_RETRIES):
            racket_seq, velocity_seq, alpha_seq = run_seed.spawn(1)[0].spawn(3)
            try:
                truth = simulate_trial(params, settings, (np.random.default_rng(racket_seq),
                                                          np.random.default_rng(velocity_seq),
                                                          np.random.default_rng(alpha_seq)))
            except ModelError:
                redrawn += 1
                continue
            rows = impact_state(truth)
            keep = slice(SIMULATION_BURN_IN, SIMULATION_BURN_IN + n)
            runs.append([rows[k][keep] for k in ("v_m_s", "theta_rad", "racket_period_s",
                                                 "racket_amplitude_m")])
            break
        else:
            raise ModelError("sticking")
    return runs, redrawn


CASES = [
    (ModelParams(0.5, 9.81, 0.3, 0.92), RacketSession(0.01, 0.003, 0.04), [40, 25, 61]),
    (ModelParams(0.42, 5.8, 0.065, 0.55), RacketSession(0.006, 0.002, 0.03), [30, 30]),
    # a racket this jittery sticks now and then: the retries are the reference's
    (ModelParams(0.55, 9.81, 0.11, 0.6), RacketSession(0.015, 0.005, 0.1), [50, 50, 50, 50]),
]


@pytest.mark.parametrize("route", ["python", "compiled"])
@pytest.mark.parametrize("case", range(len(CASES)))
def test_sessions_at_once_are_the_lab_run_by_run(case, route, monkeypatch):
    if route == "compiled":
        pytest.importorskip("numba")
    monkeypatch.setenv("BOUNCE_LAB", "python" if route == "python" else "auto")
    params, session, lengths = CASES[case]
    seeds = [np.random.SeedSequence([7, case, s]) for s in range(3)]
    together = simulate_sessions(params, session, lengths, seeds)
    redrawn_total = 0
    for seed, (runs, redrawn) in zip(seeds, together):
        expected, expected_redrawn = one_run_at_a_time(params, session, lengths,
                                                       np.random.SeedSequence(seed.entropy))
        assert redrawn == expected_redrawn
        redrawn_total += redrawn
        assert len(runs) == len(expected)
        for run, columns in zip(runs, expected):
            for got, want in zip((run.v_m_s, run.theta_rad, run.racket_period_s,
                                  run.racket_amplitude_m), columns):
                np.testing.assert_array_equal(got, want)
    if case == 2:
        assert redrawn_total > 0  # the case does exercise the retries


def test_simulate_runs_is_one_session():
    params, session, lengths = CASES[0]
    alone, redrawn = simulate_runs(params, session, lengths, np.random.SeedSequence(3))
    together = simulate_sessions(params, session, lengths, [np.random.SeedSequence(3)])
    assert redrawn == together[0][1]
    for a, b in zip(alone, together[0][0]):
        np.testing.assert_array_equal(a.v_m_s, b.v_m_s)
    assert [len(r.v_m_s) for r in alone] == lengths


def test_a_session_that_always_sticks_is_one_model_error():
    params = ModelParams(0.5, 9.81, 0.3, 0.92)
    with pytest.raises(ModelError, match="fall into sticking"):
        simulate_sessions(params, RacketSession(0.2, 0.1, 3.0), [40],
                          [np.random.SeedSequence(1)])
    assert simulated_lab.MAX_CONTACT_STEPS > 0
