"""A synthetic lab for the data analyses: ``bounce learning-data``, ``regression-data``,
``acf-data`` and ``impulse-data``.

Each runs the whole data side in memory, as a researcher runs it on a lab's files: a lab
session is simulated (``bounce simulate-recording``: continuous motion of ball and racket, eqs.
1-4 with eq. 16's velocity noise, sampled with measurement noise), its recording is extracted
(``bounce extract``: theta_k, v_k, AC, ... per bounce), and the extracted impacts are analysed
exactly as ``bounce <analysis> --data impacts.csv`` analyses a file (Figs. 6-9, 11). The
config is the analysis's own plus a ``lab:`` block describing the session; the session's
model is the config's ``model`` block, so the analysis compares the data with the model that
made them. ``lab.conditions`` simulates one session per racket (amplitude, period), e.g. the
trials of Fig. 7 at three target heights or a learning series of racket amplitudes (Fig. 6).

Besides the analysis's files every run writes the impacts it analysed (``impacts.csv``, as
``bounce extract`` writes them) and the session's exact impacts (``truth.csv``), so a
result can be held against the truth. Nothing is read from or written to other folders: the
results depend on the config alone (``bounce reproduce --out anywhere`` works).
"""

from __future__ import annotations

from typing import Any, Callable, Optional

import numpy as np
import pandas as pd
from pydantic import Field, ValidationError, model_validator

from ..runtime.config import ConfigError, StrictModel, format_validation_error
from ..data.recordings import Events
from ..data.simulated_lab import LAB_MIN_HOP_S
from .base import Experiment, ExperimentResult, RunOptions
from .extract import ExtractionBlock, extract_all, trials_from_frame
from .simulate_recording import PerturbationBlock, RacketBlock, RecordingConfig, session_frames

#: how the analysed impacts are named in messages (for a file: its path)
LAB_LABEL = "lab (the simulated session, extracted)"


class ConditionBlock(StrictModel):
    """One racket of the session (null: the model block's)."""

    racket_amplitude: Optional[float] = Field(None, gt=0.0, description="a_r, m")
    racket_period: Optional[float] = Field(None, gt=0.0, description="tau, s")


class LabBlock(StrictModel):
    """A simulated lab session (``bounce simulate-recording``'s keys, the model from the
    config's ``model`` block) and how it is extracted (``bounce extract``'s keys)."""

    seed: int = Field(0, ge=0, description="one stream per condition and trial")
    trials: int = Field(4, ge=1, le=200, description="trials per condition")
    duration_s: float = Field(40.0, gt=1.0, le=3600.0, description="s per trial")
    sample_rate_hz: float = Field(200.0, ge=20.0, le=10_000.0)
    position_noise_m: float = Field(0.0005, ge=0.0, le=0.05, description="measurement noise, m")
    velocity_noise_m_s: float = Field(0.04, ge=0.0, description="q_v of eq. 16, m/s")
    racket: RacketBlock = RacketBlock()
    perturbations: PerturbationBlock = PerturbationBlock()
    conditions: list[ConditionBlock] = Field(
        default_factory=list, description="one session per racket; empty: the model's racket")
    min_hop_s: float = Field(LAB_MIN_HOP_S, gt=0.0,
                             description="a shorter hop is sticking: an error")
    events: bool = Field(False, description="extract at the logged impact times (with alpha "
                         "and perturbed), as with --events; else detect the impacts")
    #: extracted at the session's known set-up: the model's g and no marker offset where
    #: ``extraction.g`` / ``extraction.ball_offset_m`` are null (``bounce extract`` measures
    #: them from the flights)
    extraction: ExtractionBlock = ExtractionBlock()


def recording_configs(lab: LabBlock, model) -> list[RecordingConfig]:
    """One ``simulate-recording`` config per condition, each with its own seed (spawned)."""
    conditions = lab.conditions or [ConditionBlock()]
    seeds = np.random.SeedSequence(lab.seed).spawn(len(conditions))
    out = []
    for i, (condition, seq) in enumerate(zip(conditions, seeds)):
        racket = {k: v for k, v in condition.model_dump().items() if v is not None}
        data: dict[str, Any] = {
            "model": {"alpha": model.alpha, "g": model.g,
                      "racket_amplitude": model.racket_amplitude,
                      "racket_period": model.racket_period, **racket},
            "seed": int(seq.generate_state(1)[0]),
            **lab.model_dump(include={"trials", "duration_s", "sample_rate_hz",
                                      "position_noise_m", "velocity_noise_m_s", "racket",
                                      "perturbations", "min_hop_s"}),
        }
        try:
            out.append(RecordingConfig.model_validate(data))
        except ValidationError as exc:
            where = f"lab.conditions[{i}]" if lab.conditions else "lab"
            raise ConfigError(format_validation_error(exc, where)) from None
    return out


def lab_session(lab: LabBlock, model) -> tuple[pd.DataFrame, pd.DataFrame, list[str]]:
    """(extracted impacts, exact impacts, summary lines) of the simulated session. Trials are
    labelled 1, 2, ... or, with conditions, ``c<condition>-<trial>``."""
    impacts, truths = [], []
    configs = recording_configs(lab, model)
    settings = lab.extraction.settings(model.g)
    for i, cfg in enumerate(configs, start=1):
        recording, events, truth = session_frames(cfg)
        if lab.conditions:
            for frame in (recording, events, truth):
                frame["trial"] = [f"c{i}-{t}" for t in frame["trial"]]
        trials = trials_from_frame(recording)
        logged = None
        if lab.events:
            logged = {str(label): Events(g["t_s"].to_numpy(float), g["alpha"].to_numpy(float))
                      for label, g in events.groupby("trial", sort=False)}
        extracted = extract_all(trials, logged, settings, LAB_LABEL).impacts
        impacts.append(extracted)
        truths.append(truth)
    impacts_frame, truth_frame = (pd.concat(impacts, ignore_index=True),
                                  pd.concat(truths, ignore_index=True))
    how = "at the logged impact times" if lab.events else "impacts detected from the ball"
    lines = [f"lab: {len(configs)} condition(s) x {lab.trials} trial(s) x {lab.duration_s:g} s "
             f"at {lab.sample_rate_hz:g} Hz, {1000 * lab.position_noise_m:g} mm noise: "
             f"{len(truth_frame)} impacts simulated, {len(impacts_frame)} extracted ({how})"]
    return impacts_frame, truth_frame, lines


def lab_experiment(name: str, base: Experiment,
                   analyse: Callable[[Any, RunOptions, Any], ExperimentResult]) -> Experiment:
    """The experiment ``name``: ``base``'s config with a ``lab:`` block; its run simulates and
    extracts the session and hands the impacts to ``analyse(config, options, source)`` (the
    base's data path, as ``--data`` would)."""

    class LabConfig(base.schema):  # type: ignore[name-defined]
        lab: LabBlock = LabBlock()

        @model_validator(mode="after")
        def _lab_not_data(self):
            if getattr(self, "data", None) is not None:
                raise ValueError(f"data: bounce {name} analyses its simulated session (lab:); "
                                 f"to analyse a file run bounce {base.name} --data FILE")
            return self

    LabConfig.__name__ = LabConfig.__qualname__ = f"{base.schema.__name__}WithLab"

    def run(config, options: RunOptions) -> ExperimentResult:
        impacts, truth, lines = lab_session(config.lab, config.model)
        result = analyse(config, options, (LAB_LABEL, impacts))
        result.frames["impacts.csv"] = impacts
        result.frames["truth.csv"] = truth
        result.summary = lines + result.summary
        return result

    return Experiment(name=name, schema=LabConfig, run=run, draw=base.draw)


def _experiments() -> dict[str, Experiment]:
    from . import acf, impulse, learning, regression

    return {
        "learning-data": lab_experiment("learning-data", learning.EXPERIMENT, learning.run),
        "regression-data": lab_experiment("regression-data", regression.EXPERIMENT,
                                          regression.run),
        "acf-data": lab_experiment("acf-data", acf.EXPERIMENT, acf.run_data),
        "impulse-data": lab_experiment("impulse-data", impulse.EXPERIMENT, impulse.run_data),
    }


EXPERIMENTS = _experiments()
LEARNING, REGRESSION, ACF, IMPULSE = (EXPERIMENTS[n] for n in (
    "learning-data", "regression-data", "acf-data", "impulse-data"))
