"""``bounce simulate-recording``: a simulated lab session with known truth (Fig. 2's raw data).

The engine (``data.simulated_lab``) moves ball and racket in continuous time (eqs. 1-4, the impact
law eq. 3 with eq. 16's velocity noise q_v after each impact, per-cycle racket period and
amplitude, perturbations of alpha as in section 7) and samples both positions like a motion
capture system. Writes ``recording.csv`` (what a lab measures), ``events.csv`` (every impact's
time and alpha, as a virtual set-up logs them), ``truth.csv`` (the exact impacts in the columns
of ``bounce_cli.data.impacts``, with ``v_in_m_s, alpha_measured, contact_s``) and ``recording.png``
(Fig. 2's layout drawn from the truth).

A physical set-up (``contact:``, ``racket.harmonic2_m``, ``racket.disturbance_*``, the marker
offset, the model's g): see ``data.simulated_lab``; the truth then holds the equivalent
instantaneous impacts (where the flights before and after a contact meet).
"""

from __future__ import annotations


import numpy as np
import pandas as pd
from pydantic import Field, model_validator

from ..runtime.config import ControllableModelBlock, ExperimentConfig, StrictModel
from ..memory import check_array_memory
from ..data.simulated_lab import LAB_MIN_HOP_S, SessionSettings, simulate_session, truth_rows
from ..data.impacts import EVENT_COLUMNS, MEASURED_COLUMNS, REQUIRED_COLUMNS
from .plotting import caption_figures, centred_deg, draw_fig2, publication_style
from .base import Experiment, ExperimentResult, RunOptions

#: recorded positions are rounded to 0.1 micrometre (far below any lab's noise)
POSITION_DECIMALS = 7


class RacketBlock(StrictModel):
    """Cycle-to-cycle variation and drift of the racket (section 2's sine, cycle by cycle)."""

    period_sd_s: float = Field(0.0, ge=0.0, description="SD of each cycle's period, s")
    amplitude_sd_m: float = Field(0.0, ge=0.0, description="SD of each cycle's amplitude, m")
    drift_amplitude_m: float = Field(0.0, ge=0.0, description="slow drift of the mid-position, m")
    drift_period_s: float = Field(20.0, gt=0.0, description="period of that drift, s")
    harmonic2_m: float = Field(0.0, description="second harmonic b sin(2 theta) in each "
                               "cycle, m (|b| <= a_r / 4)")
    disturbance_m: float = Field(0.0, ge=0.0, description="the impact's disturbance of the "
                                 "racket: its scale A, m")
    disturbance_s: float = Field(0.1, gt=0.0, le=0.5, description="... lasting this long, s")


class ContactBlock(StrictModel):
    """A physical set-up's contact: a spring-damper lasting ``duration_s`` whose restitution
    is alpha (the model's, or alpha_p) plus ``alpha_sd`` xi_k per impact."""

    duration_s: float = Field(0.0, ge=0.0, le=0.05, description="0: instantaneous (eq. 3)")
    alpha_sd: float = Field(0.0, ge=0.0, le=0.2, description="SD of alpha per impact")


class PerturbationBlock(StrictModel):
    """alpha replaced by alpha_p at every ``every``-th impact from impact ``first`` (section 7)."""

    every: int = Field(0, ge=0, description="0: no perturbations")
    first: int = Field(4, ge=0)
    alphas: list[float] = Field(default_factory=list)

    @model_validator(mode="after")
    def _alphas(self):
        if any(not 0.0 <= a < 1.0 for a in self.alphas):
            raise ValueError("each alpha must be in [0, 1)")
        if self.every and not self.alphas:
            raise ValueError("give alphas for the perturbed impacts")
        return self


class RecordingConfig(ExperimentConfig):
    model: ControllableModelBlock = ControllableModelBlock()
    seed: int = Field(13, ge=0)
    trials: int = Field(2, ge=1, le=1000)
    duration_s: float = Field(20.0, gt=1.0, le=3600.0)
    sample_rate_hz: float = Field(200.0, ge=20.0, le=100_000.0)
    position_noise_m: float = Field(0.0005, ge=0.0, le=0.05)
    velocity_noise_m_s: float = Field(0.04, ge=0.0, description="q_v of eq. 16, m/s")
    racket: RacketBlock = RacketBlock()
    perturbations: PerturbationBlock = PerturbationBlock()
    rest_s: float = Field(0.0, ge=0.0, description="ball resting on the still racket first, s")
    ball_marker_offset_m: float = Field(0.0, description="ball marker above the ball's "
                                        "lowest point (its radius: a marker at the centre)")
    contact: ContactBlock = ContactBlock()
    min_hop_s: float = Field(LAB_MIN_HOP_S, gt=0.0,
                             description="a shorter hop is sticking: an error")

    @model_validator(mode="after")
    def _limits(self):
        check_array_memory((self.rest_s + self.duration_s) * self.sample_rate_hz,
                           f"(rest_s + duration_s) x sample_rate_hz = ({self.rest_s:g} + "
                           f"{self.duration_s:g}) s x {self.sample_rate_hz:g} Hz samples a "
                           "trial", "reduce rest_s")
        if self.racket.period_sd_s > 0.1 * self.model.racket_period:
            raise ValueError("racket.period_sd_s must be at most 10% of model.racket_period")
        if abs(self.racket.harmonic2_m) > 0.25 * self.model.racket_amplitude:
            raise ValueError("racket.harmonic2_m must be at most a quarter of "
                             "model.racket_amplitude (one peak per cycle)")
        if self.racket.amplitude_sd_m > 0.1 * self.model.racket_amplitude:
            raise ValueError("racket.amplitude_sd_m must be at most 10% of "
                             "model.racket_amplitude")
        control = self.model.control
        if control is not None and control.switch != "cycle":
            raise ValueError("model.control.switch: simulate-recording moves the racket cycle "
                             "by cycle: the controller sets the NEXT cycle's period (give "
                             "switch: cycle)")
        if self.trials * self.duration_s * self.sample_rate_hz > 2e7:
            raise ValueError("trials x duration_s x sample_rate_hz exceeds 2e7 samples")
        return self

    def session(self) -> SessionSettings:
        return SessionSettings(
            n_trials=self.trials, duration_s=self.duration_s,
            sample_rate_hz=self.sample_rate_hz, position_noise_m=self.position_noise_m,
            period_sd_s=self.racket.period_sd_s, amplitude_sd_m=self.racket.amplitude_sd_m,
            velocity_noise_m_s=self.velocity_noise_m_s,
            drift_amplitude_m=self.racket.drift_amplitude_m,
            drift_period_s=self.racket.drift_period_s, rest_s=self.rest_s,
            ball_marker_offset_m=self.ball_marker_offset_m,
            perturb_every=self.perturbations.every, perturb_first=self.perturbations.first,
            perturb_alphas=tuple(self.perturbations.alphas), min_hop_s=self.min_hop_s,
            seed=self.seed, controller=self.model.active_controller(),
            contact_s=self.contact.duration_s, alpha_sd=self.contact.alpha_sd,
            harmonic2_m=self.racket.harmonic2_m, disturbance_m=self.racket.disturbance_m,
            disturbance_s=self.racket.disturbance_s)


def session_frames(config: RecordingConfig, options: RunOptions | None = None):
    """(recording, events, truth) DataFrames of the configured session."""
    params = config.params
    params.fixed_point()  # the ball is launched at the fixed point: a clear error if none
    recordings, events, truths = [], [], []
    trials = simulate_session(params, config.session())
    for i, (truth, (t, racket, ball)) in enumerate(trials, start=1):
        recordings.append(pd.DataFrame({
            "trial": i, "t_s": t,
            "racket_x_m": np.round(racket, POSITION_DECIMALS),
            "ball_x_m": np.round(ball, POSITION_DECIMALS),
        }))
        rows = truth_rows(truth)
        events.append(pd.DataFrame({"trial": i, "t_s": rows["t_s"], "alpha": rows["alpha"]}))
        truths.append(pd.DataFrame({"trial": i, **rows})[
            list(REQUIRED_COLUMNS + EVENT_COLUMNS + MEASURED_COLUMNS)])
        if options is not None:
            options.progress.advance(1)
    return (pd.concat(recordings, ignore_index=True), pd.concat(events, ignore_index=True),
            pd.concat(truths, ignore_index=True))


def run(config: RecordingConfig, options: RunOptions) -> ExperimentResult:
    options.progress.start(config.trials, "simulate-recording")
    recording, events, truth = session_frames(config, options)
    frames = {"recording.csv": recording, "events.csv": events, "truth.csv": truth}
    summary = [
        f"{config.trials} trials x {config.duration_s:g} s at {config.sample_rate_hz:g} Hz: "
        f"{len(truth)} impacts ({int(truth['perturbed'].sum())} perturbed); mean v = "
        f"{truth['v_m_s'].mean():.4f} m/s, mean theta = "
        f"{centred_deg(truth['theta_deg']).mean():.2f} deg"
    ]
    figures = draw(frames)
    caption_figures(figures, config.params, f"{config.trials} trials x {config.duration_s:g} s, "
                    f"{config.sample_rate_hz:g} Hz, seed {config.seed}")
    return ExperimentResult(frames=frames, figures=figures, summary=summary)


@publication_style
def draw(frames: dict[str, pd.DataFrame]) -> dict:
    """Fig. 2's layout for the first trial's first 10 bounces, from the exact impacts
    (perturbed ones marked)."""
    fig = draw_fig2(frames["recording.csv"], frames["truth.csv"],
                    "simulated session (truth.csv), {shown}")
    return {"recording.png": fig}


EXPERIMENT = Experiment(name="simulate-recording", schema=RecordingConfig, run=run, draw=draw)
