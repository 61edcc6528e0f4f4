"""``bounce simulate-study``: a whole lab study with known truth, for ``bounce study``.

Subjects x conditions x trials, one recording file per trial, each made by
``bounce simulate-recording``'s engine (eqs. 1-4 with eq. 16's velocity noise, sampled with
measurement noise). Each subject has its own racket period (drawn around
``subjects.period_mean_s``) and learns: the racket acceleration at impact AC of its trial n is
``ac_first + n_slope * (n - 1)`` (each subject's first AC and slope drawn around the means),
the racket amplitude that gives that AC at the trial's period following from eqs. 8 and 9
(``a_r = g / w^2 sqrt(AC^2 + pi^2 ((1 - alpha)/(1 + alpha))^2)``). Trials cycle through
``period_factors`` (target heights, as Fig. 7's design), and each condition has its own
velocity noise (e.g. with and without vision).

Writes ``recordings/<subject>_<condition>_t<trial>.csv`` (what a lab measures; with
perturbations also ``events/...csv``, the impacts' times and alpha as a virtual set-up logs
them), the manifest ``study.csv`` (file[, events], subject, condition, trial),
``truth_trials.csv`` (each trial's true racket, AC, alpha, g and noise, and how often it was
restarted because the ball fell into sticking) and ``truth.csv`` (every exact impact, with
subject, condition and trial). ``damaged_files`` replaces that many recordings (the last ones)
with files that cannot be read, to see how ``bounce study`` reports failures.
"""

from __future__ import annotations


import numpy as np
import pandas as pd
from pydantic import Field, ValidationError, model_validator

from ..runtime.config import NAME_PATTERN, ConfigError, ExperimentConfig, ModelBlock, StrictModel
from ..model.linear import racket_amplitude_for_ac, stable_ac_range_g
from ..model.params import ModelError
from .base import OUT_DIR, Experiment, ExperimentResult, RunOptions
from .simulate_recording import PerturbationBlock, RacketBlock, RecordingConfig, session_frames


class SubjectsBlock(StrictModel):
    """How many subjects, and how they differ (each drawn from these means and SDs)."""

    count: int = Field(6, ge=1, le=200)
    period_mean_s: float = Field(0.6, gt=0.2, le=3.0, description="racket period, s")
    period_sd_s: float = Field(0.04, ge=0.0, description="between subjects, s")
    ac_first_mean_g: float = Field(-0.4, lt=0.0, description="AC of the first trial, g")
    ac_first_sd_g: float = Field(0.05, ge=0.0)
    ac_slope_mean_g: float = Field(-0.03, description="AC change per trial (learning), g")
    ac_slope_sd_g: float = Field(0.01, ge=0.0)


class ConditionSpec(StrictModel):
    """One condition every subject performs."""

    name: str = Field(min_length=1, pattern=NAME_PATTERN)
    velocity_noise_m_s: float = Field(0.04, ge=0.0, description="q_v of eq. 16, m/s")


class SimulateStudyConfig(ExperimentConfig):
    model: ModelBlock = ModelBlock()
    seed: int = Field(21, ge=0)
    subjects: SubjectsBlock = SubjectsBlock()
    conditions: list[ConditionSpec] = Field(
        default_factory=lambda: [ConditionSpec(name="vision", velocity_noise_m_s=0.03),
                                 ConditionSpec(name="no-vision", velocity_noise_m_s=0.05)],
        min_length=1)
    trials: int = Field(5, ge=1, le=100, description="per subject and condition")
    period_factors: list[float] = Field(default_factory=lambda: [0.9, 1.0, 1.1], min_length=1)
    duration_s: float = Field(20.0, gt=1.0, le=600.0, description="s per trial")
    sample_rate_hz: float = Field(200.0, ge=20.0, le=10_000.0)
    position_noise_m: float = Field(0.0005, ge=0.0, le=0.05)
    racket: RacketBlock = RacketBlock()
    perturbations: PerturbationBlock = PerturbationBlock()
    damaged_files: int = Field(0, ge=0, description="recordings replaced by unreadable files")

    @model_validator(mode="after")
    def _checks(self):
        names = [c.name for c in self.conditions]
        if len(set(names)) != len(names):
            raise ValueError("conditions: each name once")
        if any(f <= 0 for f in self.period_factors):
            raise ValueError("period_factors must be positive")
        total = self.subjects.count * len(self.conditions) * self.trials
        if self.damaged_files > total:
            raise ValueError(f"damaged_files: at most the {total} recordings")
        shortest = self.subjects.period_mean_s * min(self.period_factors)
        if self.racket.period_sd_s > 0.1 * shortest:
            # each trial's recording allows 10 % of its racket period: refused here, before
            # any trial is drawn, against the shortest mean period a trial asks for
            raise ValueError(f"racket.period_sd_s must be at most 10% of the shortest trial "
                             f"period (subjects.period_mean_s x min(period_factors) = "
                             f"{shortest:g} s)")
        if total * self.duration_s * self.sample_rate_hz > 5e7:
            raise ValueError("subjects x conditions x trials x duration_s x sample_rate_hz "
                             "exceeds 5e7 samples")
        return self


#: |AC| kept inside eq. 14's stable range by this fraction of its width at each end
AC_MARGIN = 0.08


def trial_plan(config: SimulateStudyConfig) -> pd.DataFrame:
    """Every trial's true parameters (truth_trials.csv) and its seed, subjects drawn from
    their own streams (``SeedSequence(seed).spawn``) so that adding conditions or trials
    leaves each subject's racket as it was."""
    s, m = config.subjects, config.model
    low, high = (float(x) for x in stable_ac_range_g(m.alpha))
    lo, hi = low + AC_MARGIN * (high - low), high - AC_MARGIN * (high - low)
    rows = []
    for number, seq in enumerate(np.random.SeedSequence(config.seed).spawn(s.count), start=1):
        subject_seq, trial_seq = seq.spawn(2)
        rng = np.random.default_rng(subject_seq)
        period = max(s.period_mean_s + s.period_sd_s * rng.standard_normal(), 0.25)
        ac_first = s.ac_first_mean_g + s.ac_first_sd_g * rng.standard_normal()
        slope = s.ac_slope_mean_g + s.ac_slope_sd_g * rng.standard_normal()
        seeds = iter(trial_seq.spawn(len(config.conditions) * config.trials))
        for condition in config.conditions:
            for trial in range(1, config.trials + 1):
                ac = min(max(ac_first + slope * (trial - 1), lo), hi)
                tau = period * config.period_factors[(trial - 1) % len(config.period_factors)]
                rows.append({
                    "subject": f"s{number}", "condition": condition.name, "trial": trial,
                    "racket_period_s": tau,
                    "racket_amplitude_m": float(racket_amplitude_for_ac(m.alpha, ac, m.g, tau)),
                    "ac_g": ac, "alpha": m.alpha, "g_m_s2": m.g,
                    "velocity_noise_m_s": condition.velocity_noise_m_s,
                    "seed": int(next(seeds).generate_state(1)[0]),
                })
    return pd.DataFrame(rows)


#: a trial whose ball falls into sticking is started again (as a subject would), this often
MAX_RESTARTS = 5


def simulate_trial(data: dict, row) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame, int]:
    """(recording, events, exact impacts, restarts) of one trial. A trial in which the ball falls
    into sticking (the engine's ModelError) is simulated again from the next stream of its
    seed, as a subject starts a failed trial again; ``truth_trials.csv`` counts the restarts."""
    streams = np.random.SeedSequence(int(data["seed"])).spawn(MAX_RESTARTS)
    for restart in range(MAX_RESTARTS + 1):
        seed = data["seed"] if restart == 0 else int(streams[restart - 1].generate_state(1)[0])
        try:
            config = RecordingConfig.model_validate({**data, "seed": seed})
        except ValidationError as exc:  # one line: the first rule of the trial's config broken
            error = exc.errors()[0]
            where = ".".join(str(part) for part in error["loc"])
            reason = error["msg"].removeprefix("Value error, ")
            raise ConfigError(f"{row.subject} {row.condition} trial {row.trial} "
                              f"(racket period {row.racket_period_s:.4g} s): "
                              + (f"{where}: {reason}" if where else reason)) from None
        except ValueError as exc:
            raise ConfigError(f"{row.subject} {row.condition} trial {row.trial}: {exc}") from None
        try:
            recording, events, truth = session_frames(config)
            return recording, events, truth, restart
        except ModelError as exc:
            failure = exc
    raise ConfigError(f"{row.subject} {row.condition} trial {row.trial}: {failure} (in each of "
                      f"{MAX_RESTARTS + 1} attempts)")


def recording_name(row) -> str:
    return f"recordings/{row.subject}_{row.condition}_t{row.trial}.csv"


def events_name(row) -> str:
    """The events file of a recording (with perturbations: which impacts were perturbed is
    known from a virtual set-up's log, not from the ball)."""
    return f"events/{row.subject}_{row.condition}_t{row.trial}.csv"


def run(config: SimulateStudyConfig, options: RunOptions) -> ExperimentResult:
    plan = trial_plan(config)
    options.progress.start(len(plan), "simulate-study: recordings")
    frames: dict[str, pd.DataFrame] = {}
    truths = []
    damaged = set(range(len(plan) - config.damaged_files, len(plan)))
    restarts = [0] * len(plan)
    for i, row in enumerate(plan.itertuples()):
        data = {
            "model": {"alpha": row.alpha, "g": row.g_m_s2,
                      "racket_amplitude": row.racket_amplitude_m,
                      "racket_period": row.racket_period_s},
            "seed": row.seed, "trials": 1, "duration_s": config.duration_s,
            "sample_rate_hz": config.sample_rate_hz,
            "position_noise_m": config.position_noise_m,
            "velocity_noise_m_s": row.velocity_noise_m_s,
            "racket": config.racket.model_dump(),
            "perturbations": config.perturbations.model_dump(),
        }
        recording, events, truth, restarts[i] = simulate_trial(data, row)
        name = recording_name(row)
        if i in damaged:
            # what a crashed export leaves: a header and half a line
            recording = pd.DataFrame({"trial": ["1"], "t_s": ["0.0,0.1"]})
        frames[name] = recording
        if config.perturbations.every:
            frames[events_name(row)] = events
        truths.append(truth.assign(subject=row.subject, condition=row.condition,
                                   trial=row.trial))
        options.progress.advance()
    manifest = pd.DataFrame({
        "file": [recording_name(r) for r in plan.itertuples()],
        **({"events": [events_name(r) for r in plan.itertuples()]}
           if config.perturbations.every else {}),
        "subject": plan["subject"], "condition": plan["condition"], "trial": plan["trial"],
    })
    truth = pd.concat(truths, ignore_index=True)
    truth = truth[["subject", "condition", *[c for c in truth.columns
                                             if c not in ("subject", "condition")]]]
    plan = plan.assign(restarts=restarts)
    frames.update({"study.csv": manifest,
                   "truth_trials.csv": plan.drop(columns="seed"), "truth.csv": truth})
    summary = [f"{config.subjects.count} subjects x {len(config.conditions)} conditions x "
               f"{config.trials} trials of {config.duration_s:g} s at "
               f"{config.sample_rate_hz:g} Hz: {len(plan)} recordings, {len(truth)} impacts"
               + (f", {config.damaged_files} damaged" if config.damaged_files else "")
               + (f"; {sum(restarts)} trial(s) restarted after the ball fell into sticking"
                  if sum(restarts) else "")
               + f"; run `bounce study --manifest {OUT_DIR}/study.csv --out {OUT_DIR}-study`"
               ]
    return ExperimentResult(frames=frames, figures={}, summary=summary)


def draw(frames: dict[str, pd.DataFrame]) -> dict:
    """No figures: the study's report draws them."""
    return {}


EXPERIMENT = Experiment(name="simulate-study", schema=SimulateStudyConfig, run=run, draw=draw)
