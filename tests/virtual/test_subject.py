"""``--racket subject``: a simulated subject whose racket period follows ``bounce control``'s
period controller (sections 7-8), in closed loop with the virtual ball."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import bounce_cli
from bounce_cli.experiments.control import ControlConfig
from bounce_cli.experiments.virtual import VirtualConfig
from bounce_cli.model.control import PeriodController, iterate_controlled
from bounce_cli.model.params import ModelParams
from bounce_cli.virtual.session import Launch, Schedule, run_trial
from bounce_cli.virtual.sources import SOURCE_KINDS, SineSource, open_source
from bounce_cli.virtual.subject import SubjectControl, SubjectSource

PROTOCOL = Path(__file__).resolve().parents[2] / "configs" / "virtual" / "perturbation.yaml"

#: section 7's world: alpha_0 0.5, a_r 0.30 m, tau 0.92 s
PARAMS = ModelParams(alpha=0.5, g=9.81, racket_amplitude=0.30, racket_period=0.92)
#: the protocol: every fifth impact from the 4th on, alpha from 0.3-0.4 or 0.6-0.7
SCHEDULE = Schedule(0.5, 5, 4, ((0.3, 0.4), (0.6, 0.7)))
PHYSICS = {"min_hop_s": 0.01, "min_relative_velocity_m_s": 1e-3, "max_gap_s": 0.05}
#: the tests run without a page
HEADLESS = {"display.headless": True}
SHORT = {**HEADLESS, "trials": 2, "trial_s": 15.0, "seed": 0}


def launch_at_fixed_point() -> Launch:
    fp = PARAMS.fixed_point()
    return Launch(fp.theta_rad / PARAMS.omega, fp.v_m_s, None)


def closed_loop(source, duration_s=12.0, seed=1, trial=1):
    """One trial of the protocol with the source in the loop, and the samples it gave."""
    given = []

    class Recorded:  # what the ball is given, sample by sample; observe goes to the source
        description = source.description

        def samples(self, n, d):
            for sample in source.samples(n, d):
                given.append(sample)
                yield sample

        def __getattr__(self, name):
            return getattr(source, name)

    record = run_trial(Recorded(), trial, duration_s, PARAMS.g, SCHEDULE,
                       launch_at_fixed_point(), np.random.default_rng(seed), **PHYSICS)
    return record, given


# -- the source on its own --------------------------------------------------------------------
def test_the_defaults_are_bounce_control_s_controller():
    control = ControlConfig().model.control
    subject = SubjectControl()
    assert (subject.gain, subject.rate, subject.switch) == (control.gain, control.rate,
                                                            control.switch)
    block = VirtualConfig().subject_control
    assert (block.gain, block.rate, block.switch) == (control.gain, control.rate, control.switch)
    assert "subject" in SOURCE_KINDS
    source = open_source("subject", 0.3, 0.92, 500.0, read_racket=lambda path: [])
    assert isinstance(source, SubjectSource) and source.control == SubjectControl()
    assert "K = 0.7" in source.description


@pytest.mark.parametrize("control", [SubjectControl(gain=0.0),
                                     SubjectControl(gain=0.0, rate=0.4),
                                     SubjectControl(gain=0.0, switch="cycle")],
                         ids=["K0", "K0-c0.4", "K0-cycle"])
@pytest.mark.slow
def test_gain_zero_is_the_sine_source_sample_for_sample(control):
    """In closed loop on the perturbation protocol, every impact observed: the period stays
    tau_bar bit for bit, so the samples are SineSource's, and so are the impacts."""
    subject = SubjectSource(0.3, 0.92, 1000.0, control)
    record, given = closed_loop(subject)
    sine = list(SineSource(0.3, 0.92, 1000.0).samples(1, 12.0))
    assert given == sine  # exact: the same floats
    assert len(subject.updates) == len([i for i in record.impacts if not i.stuck]) > 5
    assert all(u.period_s == 0.92 for u in subject.updates)
    sine_record = run_trial(SineSource(0.3, 0.92, 1000.0), 1, 12.0, PARAMS.g, SCHEDULE,
                            launch_at_fixed_point(), np.random.default_rng(1), **PHYSICS)
    def key(impacts):
        return [(i.k, i.t_s, i.v_m_s, i.alpha, i.stuck) for i in impacts]

    assert key(record.impacts) == key(sine_record.impacts)


def test_the_racket_stays_continuous_and_follows_the_controlled_map():
    """Each impact's period is PeriodController.next_period of its v_k; the phase is continuous
    at every change (the position never jumps); and impacts, phases and periods after a
    perturbed impact are those of the controlled map (eqs. 5, 6 with w_{k+1}) from the same
    state, to within the subject's one-sample reaction (1 ms at 1 kHz)."""
    subject = SubjectSource(0.3, 0.92, 1000.0)
    record, given = closed_loop(subject)
    impacts = record.impacts
    assert not any(i.stuck for i in impacts)
    # the controller's equation, period by period
    controller = PeriodController(0.7, 1.0)
    tau = 0.92
    for impact, update in zip(impacts, subject.updates):
        assert update.k == impact.k
        tau = float(controller.next_period(impact.v_m_s, 0.0, tau, subject.reference))
        assert update.period_s == tau
    changes = [u for u in subject.updates if math.isfinite(u.t_start_s)]
    assert len(changes) >= 5 and max(abs(u.period_s - 0.92) for u in changes) > 0.05
    # a new period starts at the sample after the impact, no later
    assert all(0.0 <= u.t_start_s - u.t_impact_s <= 1e-3 + 1e-12 for u in changes)
    # the phase is continuous at every change
    clock = subject.clock
    for i in range(1, len(clock.t_start)):
        before = clock.phase_start[i - 1] + clock.omega[i - 1] * (clock.t_start[i]
                                                                   - clock.t_start[i - 1])
        assert clock.phase_start[i] == pytest.approx(before, abs=1e-12)
    # ... so the samples never jump: a step is at most a_r w_max / rate
    x = np.array([s[1] for s in given])
    w_max = float(np.max(clock.omega))
    assert np.max(np.abs(np.diff(x))) <= 0.3 * w_max / 1000.0 * (1 + 1e-9)
    # the controlled map from the state after the first perturbed impact (k = 4)
    k0 = 4
    assert impacts[k0].perturbed and not impacts[k0 + 1].perturbed
    theta0 = float(clock.phase(impacts[k0].t_s)[0])
    theta, v, tau_map, _ = iterate_controlled(theta0, impacts[k0].v_m_s, 0.92, PARAMS,
                                              controller, 4)
    after = impacts[k0:k0 + 5]
    assert np.allclose(v, [i.v_m_s for i in after], atol=2e-3)
    assert np.allclose(theta, [float(clock.phase(i.t_s)[0]) for i in after], atol=1e-3)
    assert np.allclose(tau_map[1:], [u.period_s for u in subject.updates[k0:k0 + 4]],
                       atol=3e-4)


def test_the_cycle_switch_starts_the_period_at_the_next_upward_crossing():
    subject = SubjectSource(0.3, 0.92, 1000.0, SubjectControl(switch="cycle"))
    record, given = closed_loop(subject, duration_s=8.0)
    clock = subject.clock
    assert len(clock.t_start) > 3
    # every segment after the first starts at a multiple of 2 pi: the racket at mid-position,
    # going up
    assert np.allclose(np.mod(clock.phase_start[1:] + 1.0, 2 * math.pi) - 1.0, 0.0,
                       atol=1e-12)
    started = [u for u in subject.updates if math.isfinite(u.t_start_s)]
    assert all(u.t_start_s > u.t_impact_s for u in started)
    x = np.array([s[1] for s in given])
    assert np.max(np.abs(np.diff(x))) <= 0.3 * float(np.max(clock.omega)) / 1000.0 * (1 + 1e-9)


# -- bounce virtual --racket subject ------------------------------------------------------------
def period_modulation(impacts: pd.DataFrame) -> pd.DataFrame:
    """Fig. 11's quantity from impacts.csv: the racket period (of the cycle holding the
    impact) at each perturbed impact minus the trial's mean over unperturbed impacts, with
    the perturbation's direction."""
    rows = []
    for trial, part in impacts.groupby("trial"):
        base = part.loc[~part["perturbed"], "racket_period_s"].mean()
        hit = part[part["perturbed"]]
        rows += [{"trial": trial, "alpha": a, "dtau_s": tau - base}
                 for a, tau in zip(hit["alpha"], hit["racket_period_s"])]
    frame = pd.DataFrame(rows).dropna()
    return frame.assign(direction=np.where(frame["alpha"] > 0.5, "increase", "decrease"))


@pytest.mark.slow
def test_the_subject_modulates_its_period_and_keeps_the_ball_in_period_one():
    """Section 7's protocol: with the passive sine the perturbations leave the period-1 basin
    (chatter, sticking) and the racket period is flat; the controlled subject lengthens the
    racket period after a faster ball (alpha up), shortens it after a slower one, and the
    ball stays period-1: no stuck impact, one impact per racket cycle."""
    sine = bounce_cli.run("virtual", config=PROTOCOL, set={**SHORT, "racket": "sine"})
    subject = bounce_cli.run("virtual", config=PROTOCOL, set={**SHORT, "racket": "subject"})
    a, b = sine.frames["impacts.csv"], subject.frames["impacts.csv"]
    flat = period_modulation(a)
    assert np.all(np.abs(flat["dtau_s"]) < 1e-9)
    # the passive racket loses the ball: chatter (hops far shorter than a cycle), sticking
    assert a["stuck"].sum() >= 1 and (a["hop_s"] < 0.6).sum() >= 10
    moved = period_modulation(b)
    assert len(moved) >= 4 and set(moved["direction"]) == {"increase", "decrease"}
    assert moved.loc[moved["direction"] == "increase", "dtau_s"].min() > 0.02
    assert moved.loc[moved["direction"] == "decrease", "dtau_s"].max() < -0.02
    assert b["stuck"].sum() == 0
    hops = b["hop_s"].dropna()
    assert hops.min() > 0.6 and hops.max() < 1.3  # one bounce per racket cycle
    assert len(b) <= 2 * (15.0 / 0.92 + 1)
    assert "period control K = 0.7" in subject.summary[0]


def test_subject_control_keys_reach_the_source():
    """``subject_control.gain: 0`` runs the sine racket exactly; the keys are validated."""
    sine = bounce_cli.run("virtual", set={**HEADLESS, "trials": 1, "trial_s": 6.0})
    flat = bounce_cli.run("virtual", set={**HEADLESS, "trials": 1, "trial_s": 6.0,
                                          "racket": "subject", "subject_control.gain": 0.0,
                                          "subject_control.rate": 0.5})
    name = "recordings/s1_virtual_t1.csv"
    pd.testing.assert_frame_equal(sine.frames[name], flat.frames[name])
    with pytest.raises(bounce_cli.ConfigError, match="subject_control"):
        bounce_cli.run("virtual", set={**HEADLESS, "racket": "subject",
                                       "subject_control.rate": 5.0})
    # one key alone: the others keep bounce control's defaults
    cycle = bounce_cli.run("virtual", config=PROTOCOL,
                           set={**HEADLESS, "trials": 1, "trial_s": 3.0, "racket": "subject",
                                "subject_control.switch": "cycle"})
    assert "K = 0.7, c = 1 (new period at the cycle)" in cycle.summary[0]


@pytest.mark.slow
def test_study_sees_the_subject_s_period_modulation(tmp_path, cli):
    """``bounce study`` on a controlled virtual session: Fig. 11's racket period modulation
    (group_impulse.csv, quantity racket_period_s) is nonzero, with the sign of section 7
    (longer after alpha up, shorter after alpha down); the amplitude's stays flat."""
    out = tmp_path / "v"
    assert cli("virtual", "--headless", "--config", PROTOCOL, "--racket", "subject", "--set",
               "trials=4", "--quiet", "--out", out).exit_code == 0
    result = cli("study", "--manifest", out / "study.csv", "--quiet", "--out",
                 tmp_path / "study")
    assert result.exit_code in (0, 1)  # 1: an analysis the data cannot support, in failures.csv
    impulse = pd.read_csv(tmp_path / "study" / "group_impulse.csv")
    period = impulse[impulse["quantity"] == "racket_period_s"].set_index(["direction", "k"])
    assert period["mean"].abs().max() > 0.02
    assert period.loc[("increase", 0), "mean"] > 0.02
    assert period.loc[("decrease", 0), "mean"] < -0.02
    amplitude = impulse[impulse["quantity"] == "racket_amplitude_m"]
    assert amplitude["mean"].abs().max() < 1e-3  # the subject controls the period only
