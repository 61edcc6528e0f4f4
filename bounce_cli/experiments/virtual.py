"""``bounce virtual``: the paper's virtual set-up (sections 6-7), run headless.

A racket stream (``--racket``: ``sine``, ``replay:<file>``) drives the model's ball
(``bounce_cli.virtual.physics``: exact flights, each impact at the first crossing of the
interpolated racket, eq. 3 with the interpolant's velocity), trial by trial, with the
protocol's perturbations of alpha (section 7: every N-th impact from given ranges, seeded).
Headless runs go as fast as the physics allows. It writes, in formats bounce already reads:

* ``recordings/<subject>_<condition>_t<n>.csv``: trial, t_s, racket_x_m, ball_x_m (what
  ``bounce extract`` takes with no ``--set``);
* ``events/<subject>_<condition>_t<n>.csv``: trial, t_s, alpha of every impact (as
  ``extract --events`` and ``bounce study`` read a virtual set-up's log);
* ``impacts.csv``: the exact impacts in the impacts table's columns (phase, period and
  amplitude from the recorded racket's cycles, as ``bounce extract`` defines them);
* ``gaps.csv``: the stream's gaps longer than ``max_gap_s`` (the ball waited);
* ``study.csv``: the manifest for ``bounce study --manifest <out>/study.csv``.
"""

from __future__ import annotations

import itertools
import math
import signal
import time
from dataclasses import fields, replace
from pathlib import Path
from collections.abc import Iterable
from typing import Literal

import numpy as np
import pandas as pd
from pydantic import Field, field_validator, model_validator

from ..data.extraction import (ExtractionSettings, racket_cycles, sample_noise_m,
                               widened_windows)
from ..data.impacts import EVENT_COLUMNS, MEASURED_COLUMNS, REQUIRED_COLUMNS, ball_apex
from ..data.plausibility import (HUMAN_RACKET_AMPLITUDE_M, racket_half_range_m,
                                 racket_warnings)
from ..data.setup_table import SETUP_FILE, SetupQuantity, setup_frame
from ..data.simulated_lab import LAB_MIN_HOP_S
from ..data.study_manifest import names_a_folder
from ..errors import ConfigError, ModelError, NoFixedPointError
from ..model.flight import restitution_of
from ..model.params import ModelParams
from ..runtime.config import (NAME_PATTERN, ControlBlock, ExperimentConfig, ModelBlock,
                              StrictModel)
from ..runtime.artifacts import RECORDED_LIVE
from ..runtime.interrupts import Interrupted
from ..virtual.display import Display, MouseSource, View, latency_summary
from ..virtual.physics import Impact, racket_velocity_noise_m_s
from ..virtual.session import Launch, Paced, Schedule, TrialRecord, run_trial
from ..virtual.sources import LslSettings, open_source
from ..virtual.subject import DEFAULT_GAIN, SubjectControl
from .base import OUT_DIR, Experiment, ExperimentResult, RunOptions
from .extract import RECORDING_FORMATS, ColumnsBlock, CsvBlock, MarkersBlock, UnitsBlock
from .plotting import caption_figures, draw_fig2, publication_style


class LaunchBlock(StrictModel):
    """How each trial's ball starts."""

    mode: Literal["fixed_point", "state", "drop"] = Field(
        "fixed_point", description="fixed_point: from the racket at the model's theta~, v~ "
        "(eqs. 7, 8); state: from the racket at theta_deg with v_m_s; drop: at rest from "
        "height_m")
    theta_deg: float = Field(40.0, description="state: the racket's phase at launch, deg "
                             "(t = theta / omega_r of the model's racket)")
    t_s: float | None = Field(None, ge=0.0, description="state: the launch's time in the "
                              "trial instead, s (a replayed recording's first impact)")
    v_m_s: float = Field(4.5, description="state: the ball's velocity at launch, m/s")
    height_m: float = Field(1.0, gt=0.0, description="drop: the ball's height at rest "
                            "above the racket's mid-position, m")


class PerturbationsBlock(StrictModel):
    """Section 7: alpha drawn from one of ``ranges`` (equal chances) at impacts ``first``,
    ``first + every``, ... (every 0: none)."""

    every: int = Field(0, ge=0, le=1000)
    first: int = Field(4, ge=0)
    ranges: list[tuple[float, float]] = Field(
        default_factory=lambda: [(0.3, 0.4), (0.6, 0.7)])

    @model_validator(mode="after")
    def _ranges(self):
        if self.every and not self.ranges:
            raise ValueError("give ranges for the perturbed impacts")
        for lo, hi in self.ranges:
            if not 0.0 <= lo <= hi < 1.0:
                raise ValueError(f"each range must satisfy 0 <= low <= high < 1 (got "
                                 f"[{lo}, {hi}])")
        return self


#: metres per unit of an LSL stream's racket channel
LSL_UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}


class LslBlock(StrictModel):
    """``racket: lsl:<stream name>``: the channel holding the racket's height and its unit."""

    channel: int = Field(0, ge=0, description="index of the racket height's channel")
    units: Literal["m", "cm", "mm"] = Field("m", description="that channel's unit")
    resolve_timeout_s: float = Field(5.0, gt=0.0, le=600.0, description="wait this long "
                                     "for the stream to be found, s")
    give_up_s: float = Field(5.0, gt=0.0, le=3600.0, description="a stream silent this "
                             "long ends the trial (wall clock), s")

    def settings(self) -> LslSettings:
        return LslSettings(self.channel, LSL_UNITS[self.units], self.resolve_timeout_s,
                           self.give_up_s)


class DisplayBlock(StrictModel):
    """The screen: a page on this machine that draws the ball and the racket."""

    headless: bool = Field(False, description="no page: the physics and the files only "
                           "(--headless)")
    realtime: bool = Field(False, description="pace sine, replay and subject sources to the "
                           "wall clock even when headless (--realtime; with a page they are)")
    port: int = Field(8765, ge=0, le=65535, description="the page's port on 127.0.0.1 (0: "
                      "any free one; --port)")
    delay_s: float = Field(0.0, ge=0.0, le=5.0, description="the protocol's display delay: "
                           "each frame shown this long after its racket sample, s")
    countdown_s: float = Field(3.0, ge=0.0, le=60.0, description="the countdown on the "
                               "screen before each trial, s")
    view_m: tuple[float, float] | None = Field(None, description="heights from the page's "
                                               "bottom to its top, m (default: from the "
                                               "racket's trough to above the ball's apex)")
    target_m: float | None = Field(None, description="a target height drawn as a line, m")

    @model_validator(mode="after")
    def _view(self):
        if self.view_m is not None and not self.view_m[0] < self.view_m[1]:
            raise ValueError(f"view_m must be [low, high] with low < high (got "
                             f"{list(self.view_m)})")
        return self


class SubjectControlBlock(ControlBlock):
    """``racket: subject``: the simulated subject's racket period control, ``bounce control``'s
    ``model.control`` (``virtual.subject``); every key has its default there."""

    gain: float = Field(DEFAULT_GAIN, description="K: 1 = the period follows the ball's "
                        "flight time in full, 0 = the sine racket")


class ReplayBlock(StrictModel):
    """How ``--racket replay:<file>`` reads its recording: ``bounce extract``'s keys of the
    same names (the racket column or marker, units, the CSV's format, the file's format)."""

    columns: ColumnsBlock = ColumnsBlock()
    csv: CsvBlock = CsvBlock()
    units: UnitsBlock = UnitsBlock()
    markers: MarkersBlock = MarkersBlock()
    format: Literal[RECORDING_FORMATS] = "auto"  # type: ignore[valid-type]


class VirtualConfig(ExperimentConfig):
    model: ModelBlock = ModelBlock()
    racket: str = Field("sine", description="the racket's source: sine | replay:<file> | "
                        "lsl:<stream name> | mouse | subject")
    replay: ReplayBlock = ReplayBlock()
    lsl: LslBlock = LslBlock()
    subject_control: SubjectControlBlock = SubjectControlBlock()
    display: DisplayBlock = DisplayBlock()
    visual_gain: float = Field(1.0, gt=0.0, le=100.0, description="the virtual racket moves "
                               "this many times the source's racket (the ball meets, and the "
                               "recordings hold, the virtual racket)")
    sample_rate_hz: float = Field(1000.0, ge=20.0, le=100_000.0,
                                  description="sine: racket samples per second")
    subject: str = Field("s1", pattern=NAME_PATTERN)
    condition: str = Field("virtual", pattern=NAME_PATTERN)
    seed: int = Field(0, ge=0)
    trials: int = Field(2, ge=1, le=1000)
    trial_s: float = Field(40.0, gt=1.0, le=3600.0)
    rest_s: float = Field(0.0, ge=0.0, description="rest between trials, s (headless: "
                          "recorded, not waited)")
    launch: LaunchBlock = LaunchBlock()
    perturbations: PerturbationsBlock = PerturbationsBlock()
    min_hop_s: float = Field(LAB_MIN_HOP_S, gt=0.0, description="a shorter hop: the ball "
                             "sticks to the racket (section 3)")
    min_relative_velocity_m_s: float = Field(1e-3, ge=0.0, description="leaving the racket "
                                             "slower than this: the ball sticks")
    max_gap_s: float = Field(0.05, gt=0.0, description="longer stretches without racket "
                             "samples stop the ball's clock (logged in gaps.csv)")

    @field_validator("subject", "condition")
    @classmethod
    def _names_a_folder(cls, value: str) -> str:
        if not names_a_folder(value):  # '.', '..': bounce study would refuse the manifest
            raise ValueError(f"{value!r} names a folder's own or parent folder, not a subject "
                             "or condition (use letters, digits, '.', '_', '-')")
        return value

    @model_validator(mode="after")
    def _size(self):
        if (self.racket in ("sine", "subject")
                and self.trials * self.trial_s * self.sample_rate_hz > 2e7):
            raise ValueError("trials x trial_s x sample_rate_hz exceeds 2e7 racket samples")
        return self


def _read_racket(path: Path, how: ReplayBlock, warn):
    """The racket of each trial of a recording, read as ``replay`` says; a reading error
    names the keys as this command takes them (``replay.columns.racket``)."""
    from ..data.recordings import keys_in_block, read_recording

    try:
        trials = read_recording(path, how.columns, how.units, how.markers, how.csv,
                                how.format, warn=warn)
    except ConfigError as exc:
        raise keys_in_block(exc, "replay") from None
    return [(np.asarray(tr.t, float), np.asarray(tr.racket, float)) for tr in trials]


def virtual_racket_params(config: VirtualConfig) -> ModelParams:
    """The model of the ball and the racket it meets: the config's, with the racket's
    amplitude times ``visual_gain`` (the virtual racket; the sine and subject sources move
    ``model.racket_amplitude``)."""
    params = config.params
    return replace(params, racket_amplitude=config.visual_gain * params.racket_amplitude)


def launch_of(config: VirtualConfig) -> Launch:
    """Where each trial's ball starts: ``fixed_point`` is eqs. 7, 8 of the racket the ball
    meets (``virtual_racket_params``), so that a sine session with a visual gain starts on
    its period-1 orbit."""
    params = virtual_racket_params(config)
    if config.launch.mode == "drop":
        return Launch(None, None, config.launch.height_m)
    if config.launch.mode == "state":
        t_s = config.launch.t_s
        return Launch(np.radians(config.launch.theta_deg) / params.omega if t_s is None
                      else t_s, config.launch.v_m_s, None)
    fixed = params.fixed_point()
    return Launch(fixed.theta_rad / params.omega, fixed.v_m_s, None)


def impacts_frame(record: TrialRecord, trial: int, g: float, duration_s: float) -> pd.DataFrame:
    """The trial's exact impacts in the impacts table's columns; phase, period and amplitude
    from the recorded racket's cycles (``bounce extract``'s definitions)."""
    imp = pd.DataFrame([vars(i) for i in record.impacts],
                       columns=[f.name for f in fields(Impact)])
    t, v = imp["t_s"].to_numpy(float), imp["v_m_s"].to_numpy(float)
    columns = [*REQUIRED_COLUMNS, *EVENT_COLUMNS, *MEASURED_COLUMNS, "stuck"]
    # the local fits' windows widened to the racket's sampling, as ``bounce extract`` does
    # (a 60 Hz mouse or a slow stream: with the default windows no cycle, so no impact, had
    # a phase)
    spacing = np.diff(np.asarray(record.t, dtype=float))
    settings = ExtractionSettings(g=g)
    if spacing.size:
        settings = widened_windows(settings, float(np.median(spacing)))
    try:
        cycles = racket_cycles(record.t, record.racket, np.isfinite(record.racket), settings)
    except ModelError:  # a racket that never moved: no cycle, so no impact has a phase
        return pd.DataFrame(columns=columns)
    cycle, theta = cycles.locate(t)
    frame = pd.DataFrame({
        "trial": trial, "k": imp["k"], "t_s": t, "theta_rad": theta,
        "theta_deg": np.degrees(theta), "v_m_s": v,
        "racket_acc_g": imp["racket_acc_m_s2"].to_numpy(float) / g,
        "racket_period_s": _at(cycles.periods, cycle),
        "racket_amplitude_m": _at(cycles.amplitudes, cycle),
        "hop_s": np.append(np.diff(t), np.nan)[: len(t)],
        "ball_apex_m": ball_apex(t, v, imp["racket_x_m"].to_numpy(float),
                                 np.append(t[1:], duration_s), g, cycles.mid_position),
        "alpha": imp["alpha"], "perturbed": imp["perturbed"].astype(bool),
        "v_in_m_s": imp["v_in_m_s"],
        "alpha_measured": restitution_of(imp["v_in_m_s"].to_numpy(float), v,
                                         imp["racket_v_m_s"].to_numpy(float)),
        "contact_s": 0.0, "stuck": imp["stuck"].astype(bool),
    })
    # as bounce extract does: an impact outside a complete racket cycle has no phase, and the
    # table leaves it out (its k stays a gap); the events keep every impact
    frame = frame[np.isfinite(theta)].reset_index(drop=True)
    return frame[columns]


def _at(values: np.ndarray, cycle: np.ndarray) -> np.ndarray:
    """``values[cycle]``, NaN where cycle is -1 (outside a complete cycle)."""
    out = np.full(cycle.shape, np.nan)
    out[cycle >= 0] = values[cycle[cycle >= 0]]
    return out


def subject_control_of(config: VirtualConfig) -> SubjectControl:
    """``racket: subject``'s controller: ``subject_control`` in the model's g and alpha."""
    c = config.subject_control
    return SubjectControl(c.gain, c.rate, c.switch, config.model.g, config.model.alpha)


def trial_name(config: VirtualConfig, trial: int, folder: str) -> str:
    return f"{folder}/{config.subject}_{config.condition}_t{trial}.csv"


def view_of(config: VirtualConfig) -> View:
    """The heights the page shows: ``display.view_m``, or from below the (gained) racket's
    trough to above the fixed point's apex (eqs. 7, 8)."""
    if config.display.view_m is not None:
        low, high = config.display.view_m
        return View(low, high, config.display.target_m)
    params = virtual_racket_params(config)
    racket = params.racket_amplitude
    try:
        fixed = params.fixed_point()
        top = racket * math.sin(fixed.theta_rad) + fixed.v_m_s ** 2 / (2.0 * params.g)
    except NoFixedPointError:
        top = racket + 1.0
    top = max(top, racket, config.display.target_m or -math.inf)
    span = top + racket
    return View(-racket - 0.12 * span, top + 0.15 * span, config.display.target_m)


#: latency.csv: per drawn frame, the delay from racket sample to drawn frame
LATENCY_COLUMNS = ["trial", "sample", "t_s", "connection", "delay_ms", "round_trip_ms"]


def run(config: VirtualConfig, options: RunOptions) -> ExperimentResult:
    params = config.params
    display = None
    if config.racket == "mouse" and config.display.headless:
        raise ConfigError("racket: mouse is the pointer on the page: run without --headless")
    source = None
    if config.racket != "mouse":  # a source that cannot be opened stops the run before a page
        source = open_source(config.racket, params.racket_amplitude, params.racket_period,
                             config.sample_rate_hz,
                             lambda path: _read_racket(path, config.replay, options.warn),
                             config.lsl.settings(), config.rest_s, options.warn,
                             subject_control_of(config))
    if not config.display.headless:
        display = Display(view_of(config), mouse=config.racket == "mouse",
                          port=config.display.port, delay_s=config.display.delay_s)
    try:
        if display is not None:
            url = display.start()
            options.inform(f"the set-up's page is at {url} (open it on the subject's screen; "
                           "click or press F for full screen)")
        if source is None:
            assert display is not None  # mouse without a page was refused above
            source = MouseSource(display)
        if (display is not None or config.display.realtime) and not getattr(
                source, "live", False):
            source = Paced(source)
        return _session(config, options, source, display)
    finally:
        if display is not None:
            display.stop()


#: a source's trial may end this much before ``trial_s`` (its last sample interval) without
#: a warning that it was shorter
SHORT_TRIAL_SLACK_S = 0.05
#: the same for a live source (a page, a stream), whose first sample may come a few frames
#: into the trial: shorter by more, its trial ended early (a stream that died)
LIVE_SHORT_TRIAL_SLACK_S = 0.5


def _session(config: VirtualConfig, options: RunOptions, source, display) -> ExperimentResult:
    """The trials in turn (with a page: the wait for it, each trial's countdown, the rests);
    Ctrl-C ends the session at the trial it interrupts and keeps the finished ones."""
    params = config.params
    schedule = Schedule(params.alpha, config.perturbations.every, config.perturbations.first,
                        tuple((lo, hi) for lo, hi in config.perturbations.ranges))
    launch = launch_of(config)
    streams = np.random.SeedSequence(config.seed).spawn(config.trials)
    frames: dict[str, pd.DataFrame] = {}
    impacts, gaps = [], []
    finished = 0
    kept: list[int] = []  # the trials recorded (a live trial without samples is left out)
    every_impact: list[Impact] = []  # impacts.csv leaves out those without a phase
    stopped = ""
    interrupted_by = 0
    short: list[tuple[int, float]] = []  # (trial, s) the source ended before trial_s
    without_impact: list[int] = []
    left_out: list[int] = []  # live trials without a racket: run.json names them
    racket_said = False  # a racket no person's: said after the first trial that shows it
    live = display is not None or getattr(source, "live", False)  # in real time: say so
    options.progress.start(config.trials, "virtual")
    try:
        if display is not None:
            display.show_status(phase="waiting", trials=config.trials,
                                message="waiting for the set-up to start")
            if not display.wait_for_page(0.0):
                options.inform("waiting for the page to connect (Ctrl-C to stop)")
            display.wait_for_page()
        for n in range(1, config.trials + 1):
            on_sample = None
            if display is not None:
                on_sample = _screen(display, config, n)
                getattr(source, "skip_to_now", lambda: None)()  # a stream's backlog
            record = run_trial(source, n, config.trial_s, params.g, schedule, launch,
                               np.random.default_rng(streams[n - 1]),
                               min_hop_s=config.min_hop_s,
                               min_relative_velocity_m_s=config.min_relative_velocity_m_s,
                               max_gap_s=config.max_gap_s, racket_gain=config.visual_gain,
                               on_sample=on_sample)
            if record.t.size < 4:
                if not live:
                    raise ConfigError(f"racket: {source.description}: trial {n} has fewer "
                                      "than 4 samples")
                # a live trial without a racket (the page closed, the stream silent): the
                # session goes on without it
                options.warn(f"trial {n}: fewer than 4 racket samples came ({source.description}"
                             "): it is left out")
                left_out.append(n)
                finished = n
                options.progress.advance(1)
                continue
            span = float(record.t[-1] - record.t[0])
            if span < config.trial_s - (LIVE_SHORT_TRIAL_SLACK_S if live else SHORT_TRIAL_SLACK_S):
                short.append((n, span))
            if not record.impacts:
                without_impact.append(n)
            frames[trial_name(config, n, "recordings")] = pd.DataFrame({
                "trial": n, "t_s": record.t, "racket_x_m": record.racket,
                "ball_x_m": record.ball})
            if not racket_said:  # said once, as soon as a trial shows it
                implausible = racket_range_warning(record.racket, source.description, n,
                                                   racket_keys(config.racket))
                if implausible:
                    options.warn(implausible)
                    racket_said = True
            table = impacts_frame(record, n, params.g, float(record.t[-1]))
            frames[trial_name(config, n, "events")] = pd.DataFrame(
                {"trial": n, "t_s": [i.t_s for i in record.impacts],
                 "alpha": [i.alpha for i in record.impacts]}, columns=["trial", "t_s", "alpha"])
            impacts.append(table)
            kept.append(n)
            every_impact += list(record.impacts)
            gaps += [{"trial": n, "t_start_s": gap.t_start_s, "t_end_s": gap.t_end_s}
                     for gap in record.gaps]
            finished = n
            options.progress.advance(1)
            if live:
                bounced = bounces(record.impacts)
                options.inform(f"trial {n} of {config.trials} done: {bounced} bounces"
                               + (f", {len(record.gaps)} stream gap(s)" if record.gaps else ""))
            if display is not None:
                display.show_status(best=max(display.status.best, display.status.score))
                if n < config.trials and config.rest_s > 0.0:
                    display.show_status(phase="rest", remaining_s=config.rest_s)
                    time.sleep(config.rest_s)
        if display is not None:
            display.show_status(phase="done", message="done: thank you")
    except (KeyboardInterrupt, Interrupted) as stop:
        # Ctrl-C, kill or a closed terminal (SIGHUP: an SSH session dropped): a subject's
        # finished trials are kept whichever ended the session; run.json and the exit status
        # (128 + signal) say it was interrupted
        if not impacts:
            raise
        signum = stop.signum if isinstance(stop, Interrupted) else signal.SIGINT
        how = "Ctrl-C" if signum == signal.SIGINT else signal.Signals(signum).name
        stopped = (f"; stopped by {how} in trial {finished + 1}: {len(kept)} finished "
                   "trial(s) kept, the interrupted one left out")
        interrupted_by = signum
        options.record["status"] = "interrupted"
        options.record["interrupted"] = stopped[2:]
    if not impacts:
        raise ConfigError(f"racket: {source.description}: no trial had racket samples (was the "
                          "page open, the stream sending?)")
    if left_out:  # the session completed, without these: said where a script reads it
        options.record["trials_left_out"] = left_out
        options.record["trials_left_out_reason"] = "fewer than 4 racket samples came"
    short = [(n, d) for n, d in short if n in kept]  # an interrupted trial is not kept
    if short:  # run.json says which trials were shorter than the protocol's, and by what
        options.record["trials_shorter"] = [{"trial": n, "recorded_s": round(d, 3)}
                                            for n, d in short]
    if short and not live:  # a replayed recording's trials (a live source warned itself)
        options.warn(f"trial_s = {config.trial_s:g} s, but {len(short)} trial(s) ended with "
                     f"their racket ({source.description}): "
                     + ", ".join(f"trial {n} after {d:.1f} s" for n, d in short[:5])
                     + (", ..." if len(short) > 5 else ""))
    if without_impact:
        options.warn(f"no impact in trial(s) {', '.join(map(str, without_impact[:10]))}"
                     f"{', ...' if len(without_impact) > 10 else ''} within trial_s = "
                     f"{config.trial_s:g} s (the ball's first flight is longer, or it was "
                     "launched after the trial's end): lengthen trial_s or launch earlier")
    trials = kept
    warning = racket_noise_warning(
        [frames[trial_name(config, n, "recordings")] for n in kept], params.alpha)
    if warning:
        options.warn(warning)
    impacts_table = pd.concat(impacts, ignore_index=True)
    # a copy first (one step under the GIL): the page's server thread may still append a
    # row while the table is built from the list (CI once: 467 values for 468 rows)
    latency = pd.DataFrame(list(display.latency) if display is not None else [],
                           columns=LATENCY_COLUMNS)
    # the frames of the kept trials only: an interrupted trial is left out of every table
    latency = latency[latency["trial"].isin(list(kept))].reset_index(drop=True)
    frames.update({
        "impacts.csv": impacts_table,
        "gaps.csv": pd.DataFrame(gaps, columns=["trial", "t_start_s", "t_end_s"]),
        "latency.csv": latency,
        # beside impacts.csv, as bounce extract writes it: --data analyses take g from here
        SETUP_FILE: setup_frame([SetupQuantity(
            "g_m_s2", params.g, 0.0, len(impacts_table),
            "the virtual ball's gravity (model.g): exact")]),
        "study.csv": pd.DataFrame({
            "file": [trial_name(config, n, "recordings") for n in trials],
            "events": [trial_name(config, n, "events") for n in trials],
            "subject": config.subject, "condition": config.condition, "trial": list(trials)}),
    })
    options.record["racket_source"] = source.description
    if config.racket == "mouse" or config.racket.startswith("lsl"):  # a person's racket
        options.record[RECORDED_LIVE] = True  # a rerun into --out needs --force
    figures = draw(frames)
    lengths = trial_lengths(list(kept), short, config.trial_s,
                            "the racket's samples stopped" if live
                            else "the racket's recording ended")
    caption_figures(figures, params, f"{lengths}, {source.description}, seed {config.seed}")
    stuck = sum(bool(i.stuck) for i in every_impact)
    summary = [
        f"{lengths} ({source.description}"
        + (f"; visual gain {config.visual_gain:g}: the ball meets that racket x "
           f"{config.visual_gain:g}" if config.visual_gain != 1.0 else "") + "): "
        f"{len(every_impact)} impacts ({sum(bool(i.perturbed) for i in every_impact)} perturbed"
        + (f", {stuck} left the ball on the racket" if stuck else "")
        + (f"; impacts.csv holds {len(impacts_table)}, as an impact outside a complete racket "
           "cycle has no phase" if len(impacts_table) < len(every_impact) else "")
        + f"), {len(gaps)} "
        f"stream gap(s){stopped}; run `bounce study --manifest {OUT_DIR}/study.csv "
        f"--out {OUT_DIR}-study`"]
    if display is not None:
        summary.append(latency_summary(latency.to_dict("records")) + " (latency.csv)")
    return ExperimentResult(frames=frames, figures=figures, summary=summary,
                            exit_code=128 + interrupted_by if interrupted_by else 0)


def trial_lengths(kept: list[int], short: list[tuple[int, float]], trial_s: float,
                  why: str) -> str:
    """"3 trial(s) x 40 s", or, where kept trials ended before ``trial_s`` (``short``:
    (trial, seconds)), how long they were and ``why``: "2 trial(s) of 20.0 s (trial_s
    40 s; the racket's recording ended)"."""
    cut = dict(short)
    if not cut:
        return f"{len(kept)} trial(s) x {trial_s:g} s"
    lengths = [cut.get(n, trial_s) for n in kept]
    low, high = f"{min(lengths):.1f}", f"{max(lengths):.1f}"
    ended = why if len(cut) == len(kept) else f"{len(cut)} of them: {why}"
    return (f"{len(kept)} trial(s) of {low if low == high else f'{low}-{high}'} s "
            f"(trial_s {trial_s:g} s; {ended})")


def racket_keys(racket: str) -> tuple[str, str] | None:
    """The keys naming a racket source's channel and its unit (lsl, replay), else None."""
    if racket.startswith("lsl"):
        return "lsl.channel", "lsl.units"
    if racket.startswith("replay"):
        return "replay.columns.racket", "replay.units.length"
    return None


def racket_range_warning(racket: np.ndarray, description: str, trial: int,
                         keys: tuple[str, str] | None = None) -> str:
    """A warning where a trial's racket is no person's: it did not move (half its range below
    ``HUMAN_RACKET_AMPLITUDE_M``'s least: a stream's wrong channel, a racket at rest), or half
    its range is beyond what a person can move it by (``racket_warnings``: positions in mm
    read as m); ``keys`` (channel, unit: ``racket_keys``) are named; empty otherwise."""
    half = racket_half_range_m(racket)
    if not math.isfinite(half):
        return ""
    if half < HUMAN_RACKET_AMPLITUDE_M[0]:
        which = f"the wrong channel ({keys[0]}), or " if keys else ""
        return (f"racket ({description}): the racket moved by only {2000 * half:.2g} mm in "
                f"trial {trial}: {which}a racket standing still?")
    found = racket_warnings(half, math.nan, f"racket ({description}), trial {trial}: half "
                            "its range", "")
    return (found[0] + (f" (set {keys[1]})" if keys else "")) if found else ""


#: the noise (m/s) in the ball's velocity after impact that the racket's sampled noise may add
#: unannounced: the paper's subjects' map noise q_v is 0.03 m/s (section 7)
RACKET_NOISE_WARN_M_S = 0.02


def racket_noise_warning(recordings: list[pd.DataFrame], alpha: float) -> str:
    """A warning where the racket's samples are noisy enough that the ball's velocity after
    each impact shakes by more than ``RACKET_NOISE_WARN_M_S``: eq. 3 gives the ball (1 +
    alpha) times the racket's velocity, taken from the cubic through the 4 latest samples,
    which amplifies their noise (``racket_velocity_noise_m_s``). The noise is measured from
    the racket's fourth differences (``sample_noise_m``, median over the trials: second
    differences hold a 0.3 m racket's own motion at 200 Hz); empty where it is small."""
    noise, interval = [], []
    for frame in recordings:
        t, x = frame["t_s"].to_numpy(float), frame["racket_x_m"].to_numpy(float)
        if t.size > 12:
            noise.append(sample_noise_m(x, order=4))  # (a sine's own motion: 4e-4 mm)
            interval.append(float(np.median(np.diff(t))))
    if not noise or not np.isfinite(np.median(noise)):
        return ""
    sigma, h = float(np.median(noise)), float(np.median(interval))
    ball = (1.0 + alpha) * racket_velocity_noise_m_s(sigma, h)
    if not ball > RACKET_NOISE_WARN_M_S:
        return ""
    return (f"the racket's samples carry about {1000 * sigma:.2g} mm of noise (from their "
            f"fourth differences, at {1 / h:.0f} Hz); the ball leaves each impact with the "
            "velocity of a cubic through the 4 latest samples, which makes that about "
            f"{ball:.2g} m/s of noise in the ball's velocity after each impact (the paper's "
            "subjects' map noise is 0.03 m/s) and dominates impacts.csv's racket_acc_g: "
            "filter the racket's positions at their source (the motion-capture software's "
            "smoothing) before they stream")


def bounces(impacts: Iterable[Impact]) -> int:
    """The bounces among ``impacts`` as the subject's score counts them and the analyses see
    them: impacts that left the ball off the racket, after a flight no shorter than the
    extraction's ``sticking_hop_s`` (a chatter's micro-hops, 10-50 ms, are one contact to
    ``bounce extract``; they counted one point each)."""
    shortest = ExtractionSettings().sticking_hop_s
    return sum(not i.stuck and not i.hop_s < shortest for i in impacts)


def _screen(display: Display, config: VirtualConfig, trial: int):
    """Trial ``trial`` on the page: its countdown, then every racket sample's frame (the
    score: the trial's ``bounces``)."""
    if config.display.countdown_s > 0.0:
        display.show_status(phase="countdown", trial=trial, score=0,
                            remaining_s=config.display.countdown_s)
        time.sleep(config.display.countdown_s)
    display.show_status(phase="trial", trial=trial, score=0, duration_s=config.trial_s)
    samples = itertools.count()

    def on_sample(t: float, racket: float, ball: float, new: list[Impact]) -> None:
        if new:
            display.status.score += bounces(new)
        display.publish(trial, next(samples), t, racket, ball, time.perf_counter(),
                        impact=bool(new))

    return on_sample


@publication_style
def draw(frames: dict[str, pd.DataFrame]) -> dict:
    """Fig. 2's layout for the first trial's first 10 bounces, or all of them where it has
    fewer (perturbed ones in red)."""
    first = sorted(name for name in frames if name.startswith("recordings/"))
    if not first:
        return {}
    fig = draw_fig2(frames[first[0]], frames["impacts.csv"],
                    "virtual set-up: {shown}")
    return {"virtual.png": fig}


EXPERIMENT = Experiment(name="virtual", schema=VirtualConfig, run=run, draw=draw)
