"""``bounce extract``: a recording of racket and ball -> the impacts table (paper Fig. 2).

Reads a lab's recording (CSV or C3D, ``bounce_cli.data.recordings``), optionally its event log
(``--events``: the impact times and alpha of a virtual set-up), and extracts per bounce the
map's variables (``data.extraction``): phase of impact theta_k, ball velocity after impact v_k
(eq. 5's state), racket acceleration at impact AC (section 4) and the rest of
``bounce_cli.data.impacts``. Writes ``impacts.csv``, ``excluded.csv`` (contacts not reported, with
the reason), ``cycles.csv`` (the racket cycles), ``fig2.png`` with the samples it shows
(``fig2_samples.csv``) and, given the truth (``truth:``), ``accuracy.csv``.

Without ``data`` it extracts the bundled simulated session (``configs/recording.yaml``,
simulated in memory exactly as ``bounce simulate-recording`` writes it) and holds the result
against that session's truth: ``bounce reproduce`` needs no file from elsewhere.
"""

from __future__ import annotations

import math
from collections import Counter
from pathlib import Path
from dataclasses import replace
from typing import Literal, NamedTuple, Optional, Union

import numpy as np
import pandas as pd
from pydantic import Field, field_validator, model_validator

from ..runtime.config import ConfigError, ExperimentConfig, StrictModel
from ..model.impact import first_impact_phase
from ..model.params import ModelError
from ..data.plausibility import racket_half_range_m, racket_warnings
from ..data.extraction import (
    PLAUSIBLE_G_M_S2,
    ExtractionSettings,
    TrialExtraction,
    contact_duration,
    extract_trial,
    match_impacts,
    pooled_gravity,
    robust_sd,
    sample_noise_m,
)
from ..data.impacts import EVENT_COLUMNS, MEASURED_COLUMNS, REQUIRED_COLUMNS
from ..data.setup_table import SetupQuantity, setup_frame
from ..data.recordings import (
    LENGTH_UNITS,
    TIME_UNITS,
    Trial,
    read_events,
    read_recording,
    read_table,
)
from .plotting import caption_figures, centred_deg, draw_fig2, publication_style
from .base import Experiment, ExperimentResult, RunOptions


def at_least_one(names):
    """The racket's names: one, or a non-empty list (their mean is the racket)."""
    if isinstance(names, list) and not names:
        raise ValueError("name at least one")
    return names


class ColumnsBlock(StrictModel):
    """Column names of a CSV recording (null: the file has no such column)."""

    trial: Optional[str] = "trial"
    time: str = "t_s"
    racket: Union[str, list[str]] = "racket_x_m"
    ball: Optional[str] = "ball_x_m"

    _some = field_validator("racket")(classmethod(lambda cls, value: at_least_one(value)))


class EventColumnsBlock(StrictModel):
    """Column names of the events CSV (alpha is optional in the file)."""

    trial: Optional[str] = "trial"
    time: str = "t_s"
    alpha: Optional[str] = "alpha"


#: names a separator or decimal mark may be given by (a bare "," or ";" is not a YAML value
#: on the command line: ``--set csv.separator=semicolon``)
CSV_MARKS = {"comma": ",", "semicolon": ";", "tab": "\t", "\\t": "\t", "space": " ",
             "whitespace": " ", "point": ".", "period": ".", "dot": "."}


class CsvBlock(StrictModel):
    """How the CSV files are written: field separator, decimal mark, rows to skip after the
    header (a row of units), and the values a height column writes for a marker it did not
    see (``missing_heights``: e.g. [0], read as gaps like empty cells). Marks by character or
    by name (``CSV_MARKS``)."""

    separator: str = Field(",", min_length=1)
    decimal: Literal[".", ","] = "."
    skip_rows: int = Field(0, ge=0)
    missing_heights: list[float] = Field(default_factory=list)

    @field_validator("separator", "decimal", mode="before")
    @classmethod
    def _named(cls, value):
        return CSV_MARKS.get(value.strip().lower(), value) if isinstance(value, str) else value

    @model_validator(mode="after")
    def _distinct(self):
        if self.separator == self.decimal:
            raise ValueError(f"csv.separator and csv.decimal are both {self.decimal!r}")
        return self


#: what a "no bounce found" asks the user to check: a recording read in the wrong unit or axis
#: shows no bounce at all
NO_BOUNCE_HINT = ("; check units.length (positions in mm read as m, or cm as mm), units.time "
                  "(times in ms read as s), the vertical axis (markers.vertical_axis; a CSV's "
                  "columns must be heights) and that columns.ball and columns.racket name the "
                  "ball and the racket")


class UnitsBlock(StrictModel):
    """Units of a CSV recording's and the events' columns (C3D: from the file)."""

    length: Literal[tuple(LENGTH_UNITS)] = "m"  # type: ignore[valid-type]
    time: Literal[tuple(TIME_UNITS)] = "s"  # type: ignore[valid-type]


class MarkersBlock(StrictModel):
    """Which markers of a marker file (C3D, Vicon, QTM, Motive) are racket and ball, which
    axis is vertical (null: the format's, y for Motive, else z) and the positions' length unit
    (null: the file's)."""

    racket: Union[str, list[str]] = "racket"
    ball: Optional[str] = "ball"
    vertical_axis: Optional[Literal["x", "y", "z"]] = None
    units: Optional[Literal[tuple(LENGTH_UNITS)]] = None  # type: ignore[valid-type]

    _some = field_validator("racket")(classmethod(lambda cls, value: at_least_one(value)))


#: the former ``c3d`` block's keys -> the ``markers`` block's
FORMER_MARKER_KEYS = {"racket_marker": "racket", "ball_marker": "ball"}

#: the recording formats (``auto``: by the suffix and the first line)
RECORDING_FORMATS = ("auto", "csv", "c3d", "vicon", "qtm", "motive")


DEFAULTS = ExtractionSettings()
#: standard gravity, m/s^2: unit slips scale it by powers of ten
STANDARD_GRAVITY = 9.80665


class ExtractionBlock(StrictModel):
    """The extraction's settings (``data.extraction``; g comes from the model block)."""

    max_gap_s: float = Field(DEFAULTS.max_gap_s, ge=0.0)
    acc_half_window_s: float = Field(DEFAULTS.acc_half_window_s, gt=0.0)
    acc_degree: int = Field(DEFAULTS.acc_degree, ge=2, le=8)
    velocity_degree: int = Field(DEFAULTS.velocity_degree, ge=1, le=8)
    position_half_window_s: float = Field(DEFAULTS.position_half_window_s, gt=0.0)
    position_degree: int = Field(DEFAULTS.position_degree, ge=1, le=8)
    extremum_half_window_s: float = Field(DEFAULTS.extremum_half_window_s, gt=0.0)
    extremum_degree: int = Field(DEFAULTS.extremum_degree, ge=2, le=8)
    mid_window_s: float = Field(DEFAULTS.mid_window_s, gt=0.0)
    min_velocity_jump_m_s: float = Field(DEFAULTS.min_velocity_jump_m_s, gt=0.0)
    contact_distance_m: float = Field(DEFAULTS.contact_distance_m, gt=0.0)
    contact_tolerance_m: float = Field(DEFAULTS.contact_tolerance_m, gt=0.0)
    sticking_hop_s: float = Field(DEFAULTS.sticking_hop_s, ge=0.0)
    guard_samples: int = Field(DEFAULTS.guard_samples, ge=0, le=100)
    min_flight_samples: int = Field(DEFAULTS.min_flight_samples, ge=3)
    ball_offset_m: Optional[float] = Field(None, description="ball marker above the racket "
                                           "marker at impact, m (null: measured)")
    g: Optional[float] = Field(None, gt=0.0, description="g of the flight fits, m/s^2 (null: "
                               "measured from the flights; extract: model.g when set)")

    def settings(self, g: float, ball_offset_m: float = 0.0) -> ExtractionSettings:
        """The engine's settings at gravity ``g`` and marker offset ``ball_offset_m`` (the
        block's own where it sets them)."""
        values = self.model_dump(exclude={"g", "ball_offset_m"})
        return ExtractionSettings(
            g=self.g if self.g is not None else g,
            ball_offset_m=self.ball_offset_m if self.ball_offset_m is not None else ball_offset_m,
            **values)


class FigureBlock(StrictModel):
    """Which bounces Fig. 2 shows: a trial (null: the first), from a time (null: its first
    impact), how many."""

    trial: Optional[Union[int, str]] = None
    start_s: Optional[float] = None
    bounces: int = Field(10, ge=1, le=200)


class ExtractConfig(ExperimentConfig):
    data: Optional[str] = Field(None, description="recording (CSV or .c3d); null: the "
                                "simulated session of configs/recording.yaml")
    events: Optional[str] = Field(None, description="events CSV: the impact times (and alpha)")
    events_shift_s: float = Field(0.0, description="added to every event's time, s: an event "
                                  "log on a clock of its own (setup.csv's event_lag_s measures "
                                  "its lag; a shift of minus that puts it on the recording's)")
    truth: Optional[str] = Field(None, description="truth.csv of a simulated session: "
                                 "writes accuracy.csv")
    columns: ColumnsBlock = ColumnsBlock()
    event_columns: EventColumnsBlock = EventColumnsBlock()
    csv: CsvBlock = CsvBlock()
    units: UnitsBlock = UnitsBlock()
    format: Literal[RECORDING_FORMATS] = Field(  # type: ignore[valid-type]
        "auto", description="the recording's format: auto (by the suffix and the first line) "
        "| csv | c3d | vicon | qtm | motive")
    markers: MarkersBlock = MarkersBlock()
    extraction: ExtractionBlock = ExtractionBlock()
    figure: FigureBlock = FigureBlock()

    @model_validator(mode="before")
    @classmethod
    def _former_c3d_block(cls, data):
        """Configs written before the ``markers`` block (which now serves every marker
        format) named it ``c3d`` with ``racket_marker``, ``ball_marker`` and
        ``vertical_axis``: still read, as that block (its keys win over the markers block's
        where both are given, e.g. ``--set c3d.ball_marker=b`` on the bundled config)."""
        if not isinstance(data, dict) or "c3d" not in data:
            return data
        former, markers = data["c3d"], data.get("markers") or {}
        if not isinstance(former, dict) or not isinstance(markers, dict):
            return data  # validation names the key
        renamed = {FORMER_MARKER_KEYS.get(k, k): v for k, v in former.items()}
        return {**{k: v for k, v in data.items() if k != "c3d"},
                "markers": {**markers, **renamed}}


# -- inputs -------------------------------------------------------------------------------------
def demo_session():
    """(trials, truth frame) of the bundled simulated session, simulated in memory."""
    from ..runtime.config import bundled_config_path, load_config
    from .simulate_recording import RecordingConfig, session_frames

    cfg = load_config(RecordingConfig, bundled_config_path("recording"))
    recording, _, truth = session_frames(cfg)
    return trials_from_frame(recording), truth


def trials_from_frame(frame: pd.DataFrame) -> list[Trial]:
    """Trials of a recording frame in ``simulate-recording``'s columns."""
    return [Trial(label, g["t_s"].to_numpy(float), g["racket_x_m"].to_numpy(float),
                  g["ball_x_m"].to_numpy(float))
            for label, g in frame.groupby("trial", sort=False)]


def read_truth(path: str) -> pd.DataFrame:
    truth = read_table(Path(path))
    missing = [c for c in REQUIRED_COLUMNS if c not in truth.columns]
    if missing:
        raise ConfigError(f"{path}: not an impacts table: no column {missing[0]!r}")
    return truth


# -- the tables ---------------------------------------------------------------------------------
class SessionExtraction(NamedTuple):
    """Every trial extracted: the tables, the set-up measured from them (``setup.csv``), the
    settings the extraction ran at (g, marker offset: measured or set) and warnings."""

    impacts: pd.DataFrame
    excluded: pd.DataFrame
    cycles: pd.DataFrame
    setup: list[SetupQuantity]
    settings: ExtractionSettings
    warnings: list[str]


def _extract_trials(trials: list[Trial], events, settings: ExtractionSettings, source: str,
                    caches: list[dict] | None = None):
    """[(trial, its events, TrialExtraction)] at ``settings``; a trial without a bounce is a
    one-line error naming the file and the trial. ``caches``: one dict per trial, kept across
    the passes of ``extract_all`` (the racket's cycles are found once per trial)."""
    out = []
    caches = caches if caches is not None else [{} for _ in trials]
    for trial, cache in zip(trials, caches):
        ev = events.get(str(trial.label)) if events is not None else None
        if events is not None and (ev is None or ev.t.size == 0):
            raise ConfigError(f"{source}: trial {trial.label}: no events for this trial")
        if trial.ball is None and ev is None:
            raise ConfigError(f"{source}: no ball column (columns.ball is null) and no "
                              "--events: nothing gives the impacts")
        try:
            result = extract_trial(trial.t, trial.racket, trial.ball,
                                   None if ev is None else ev.t,
                                   None if ev is None else ev.alpha, settings, cache)
        except ModelError as exc:
            hint = NO_BOUNCE_HINT if str(exc).startswith("no bounce found") else ""
            slip = racket_scale_hint(trial) if hint else ""
            if slip:  # a unit slip first: its "noise" is the motion at the wrong scale
                hint = slip + hint
            elif hint and trial.ball is not None:
                hint = noise_hint(trial, settings.contact_tolerance_m) + hint
            if hint and ev is not None:
                hint += ("; and that the events' times are on the recording's clock (events "
                         "a few samples late or early cut the flights at the wrong place)")
            raise ConfigError(f"{source}: trial {trial.label}: {exc}{hint}") from None
        out.append((trial, ev, result))
    return out


def separation_noise_m(racket: np.ndarray, ball: np.ndarray) -> float:
    """The measurement noise of the ball's height above the racket (m): ``sample_noise_m`` of
    ball minus racket; NaN with too few samples."""
    return sample_noise_m(np.asarray(ball, float) - np.asarray(racket, float))


#: the half-width (s) of the window in which a bounce's lowest point is the least height of
#: the ball above the racket: shorter than any hop, longer than a contact
LOWEST_POINT_HALF_WINDOW_S = 0.05


def lowest_points_m(t: np.ndarray, racket: np.ndarray, ball: np.ndarray) -> np.ndarray:
    """The ball's height above the racket's marker (m) at its lowest points: the samples that
    are the least within +-``LOWEST_POINT_HALF_WINDOW_S`` (the contacts, and a resting ball)."""
    d = np.asarray(ball, float) - np.asarray(racket, float)
    dt = float(np.median(np.diff(t))) if len(t) > 1 else math.nan
    if not dt > 0.0:
        return np.empty(0)
    from scipy.ndimage import minimum_filter1d

    half = max(int(round(LOWEST_POINT_HALF_WINDOW_S / dt)), 1)
    if d.size < 2 * half + 1:
        return np.empty(0)
    least = minimum_filter1d(np.where(np.isfinite(d), d, np.inf), 2 * half + 1,
                             mode="constant", cval=np.inf)
    return d[np.isfinite(d) & (d == least)]


def seeded_offset(trials: list[Trial], settings) -> float:
    """The marker offset a first pass starts from: the median of the ball's lowest points
    above the racket's marker (``lowest_points_m``, all trials) where it lies below
    -``contact_tolerance_m`` (the ball's marker under the racket's at every bounce: a racket
    marker 30 mm above the face stopped the extraction), else ``settings``' own. The offset
    is then measured at the impacts as always."""
    per_trial = [lowest_points_m(tr.t, tr.racket, tr.ball) for tr in trials
                 if tr.ball is not None]
    lows = np.concatenate(per_trial) if per_trial else np.empty(0)
    if lows.size < 3:
        return settings.ball_offset_m
    below = float(np.median(lows))
    return below if below < -settings.contact_tolerance_m else settings.ball_offset_m


def racket_scale_hint(trial: Trial) -> str:
    """Where no bounce was found and the racket moves more than a person can (half its range
    beyond ``plausibility``'s: positions in mm read as m), that unit slip; empty otherwise."""
    found = racket_warnings(racket_half_range_m(trial.racket), math.nan,
                            "the racket's half range", "")
    return f"; {found[0]}" if found else ""


def noise_hint(trial: Trial, tolerance_m: float) -> str:
    """Where no bounce was found because the markers' noise reaches the distance within which
    the ball counts as resting (``contact_tolerance_m``): the measured noise and the setting
    (the ball at 3 mm of noise "rested" on the racket all trial, and the error blamed units);
    empty where the noise is below a third of it."""
    assert trial.ball is not None
    noise = separation_noise_m(trial.racket, trial.ball)
    if not noise > tolerance_m / 3.0:
        return ""
    return (f"; the ball's height above the racket is noisy (SD about {1000 * noise:.1f} mm, "
            f"from its second differences) against extraction.contact_tolerance_m = "
            f"{1000 * tolerance_m:g} mm, within which the ball counts as resting: raise it to "
            f"about 3 times the noise (--set extraction.contact_tolerance_m="
            f"{math.ceil(3000 * noise) / 1000:g})")


#: a stretch between two samples longer than this many times the trial's typical sample
#: interval, and than MISSING_ROWS_MIN_S, is rows missing (a logger's dropout): the local fits
#: near it have samples of one side only
MISSING_ROWS_FACTOR = 3.0
MISSING_ROWS_MIN_S = 0.01


def missing_rows_warnings(trials: list[Trial], source: str, max_gap_s: float) -> list[str]:
    """A warning where the recording's rows skip time (samples missing without a row, which
    no cell shows as a gap): how many such stretches, the longest and where. Impacts and
    racket crossings near them are fitted from fewer samples (35 ms of rows missing at an
    impact: v_k 20 mm/s and theta_k 0.8 deg off at 200 Hz); those longer than ``max_gap_s``
    are gaps."""
    found: list[tuple[float, object, float]] = []  # (length, trial, time it starts)
    for trial in trials:
        steps = np.diff(trial.t)
        if steps.size < 2:
            continue
        limit = max(MISSING_ROWS_FACTOR * float(np.median(steps)), MISSING_ROWS_MIN_S)
        for i in np.flatnonzero(steps > limit):
            found.append((float(steps[i]), trial.label, float(trial.t[i])))
    if not found:
        return []
    length, label, at = max(found, key=lambda item: item[0])
    return [f"{source}: {len(found)} stretch(es) without samples (rows missing? the longest "
            f"{1000 * length:.0f} ms, in trial {label} after t = {at:g} s): impacts and racket "
            "cycles near them are fitted from fewer samples; stretches longer than "
            f"max_gap_s ({1000 * max_gap_s:g} ms) are gaps"]


#: a flight longer than this many times the one its launch gives (the model's flight from
#: the impact at the cycle's racket) holds a bounce that was not found
MISSED_BOUNCE_RATIO = 1.5


def missed_bounce_warnings(impacts: pd.DataFrame, g: float, source: str) -> list[str]:
    """A warning where flights last far longer than their launch allows: the model's flight
    from (theta_k, v_k) to the first meeting with the racket of the impact's cycle (eq. 6,
    ``model.impact.first_impact_phase``; a ballistic 2 v_k / g alone misjudged the low hops
    of chatter, whose racket falls away under them), and a flight 1.5 times that or more held
    a bounce the extraction did not find (a review's 8 mm of marker noise lost 5 of 16
    bounces without a word, and k, which counts the bounces found, paired the impacts around
    them as consecutive)."""
    needed = {"theta_rad", "v_m_s", "hop_s", "racket_period_s", "racket_amplitude_m"}
    if not len(impacts) or not needed <= set(impacts.columns):
        return []
    v, hop = impacts["v_m_s"].to_numpy(float), impacts["hop_s"].to_numpy(float)
    omega = 2.0 * math.pi / impacts["racket_period_s"].to_numpy(float)
    with np.errstate(invalid="ignore", divide="ignore"):
        flight = first_impact_phase(impacts["theta_rad"].to_numpy(float), v,
                                    impacts["racket_amplitude_m"].to_numpy(float), omega,
                                    g) / omega
        ratio = hop / flight
    long = np.flatnonzero(np.isfinite(ratio) & (ratio > MISSED_BOUNCE_RATIO))
    if not long.size:
        return []
    worst = int(long[np.argmax(ratio[long])])
    trial, t_s = impacts["trial"].iloc[worst], float(impacts["t_s"].iloc[worst])
    return [f"{source}: {long.size} flight(s) last {MISSED_BOUNCE_RATIO:g} times or more what "
            f"their launch gives (the model's flight from theta_k and v_k at the cycle's "
            f"racket; the longest {hop[worst]:.2f} s where {flight[worst]:.2f} s, trial "
            f"{trial} at t = {t_s:.2f} s): a bounce in such a flight was not found (noisy "
            "markers? see setup.csv's noise), and k, which counts the bounces found, pairs "
            "the impacts around it as consecutive"]


#: sample intervals that vary (robust SD) by more than this fraction of the clock's step are a
#: jittering clock (a PC's time stamps, not the capture system's frames)
JITTER_FRACTION = 0.05


def clock_step(steps: np.ndarray) -> float:
    """The step of the clock behind sample intervals ``steps`` (> 0) that may skip samples:
    the median of the intervals no longer than 1.5 times their 10th percentile, so that rows
    missing (intervals of 2, 3, ... steps, even as many as of one step) do not move it, then
    the total time over the total number of whole steps the intervals make."""
    shortest = float(np.percentile(steps, 10))
    first = float(np.median(steps[steps <= 1.5 * shortest]))
    # refined over every interval, each as its whole number of steps: jitter cut at the
    # 1.5x line biased the first guess low (a 5 ms clock with 1 ms of jitter read 4.94 ms)
    whole = np.maximum(np.round(steps / first), 1.0)
    return float(np.sum(steps) / np.sum(whole))


def jitter_warnings(trials: list[Trial], source: str) -> list[str]:
    """A warning where the sample times jitter: the intervals between samples stray from
    whole multiples of the clock's step (``clock_step``; a robust SD of the distances) by more
    than JITTER_FRACTION of the step. Rows missing give whole multiples and do not count. The
    ball's contacts are found from positions at those times: a review's 1 ms of jitter at
    200 Hz found contacts where there were none (one v_k 0.2 m/s off, impacts lost) without
    a word."""
    worst: tuple[float, float, object] | None = None  # (fraction, clock step, trial)
    for trial in trials:
        steps = np.diff(trial.t)
        steps = steps[np.isfinite(steps) & (steps > 0)]
        if steps.size < 10:
            continue
        step = clock_step(steps)
        spread = robust_sd(steps - step * np.maximum(np.round(steps / step), 1.0))
        if spread > JITTER_FRACTION * step and (worst is None or spread / step > worst[0]):
            worst = (spread / step, step, trial.label)
    if worst is None:
        return []
    fraction, step, label = worst
    return [f"{source}: the sample times jitter (the intervals between samples stray by about "
            f"{1000 * fraction * step:.2g} ms from multiples of {1000 * step:.3g} ms, in trial "
            f"{label}): contacts are found from the positions at those times, and a jittering "
            "clock can make contacts where there were none; export the capture system's own "
            "clock (frame number / frame rate) where it has one"]


def unit_slip_hint(g: float) -> str:
    """What a fitted g far from any set-up's suggests (lengths scaled by a power of ten)."""
    ratio = g / STANDARD_GRAVITY
    if not (math.isfinite(ratio) and ratio > 0.0):  # a ball that does not fall: no scale slip
        return ("check units.length, the ball's column and the vertical axis (columns.ball, "
                "markers.vertical_axis): its flights do not fall")
    for factor, slip in ((10.0, "millimetres read as centimetres, or centimetres as "
                                "decimetres"), (100.0, "centimetres read as metres"),
                         (1000.0, "millimetres read as metres"),
                         (0.1, "centimetres read as millimetres"),
                         (0.01, "metres read as centimetres"),
                         (0.001, "metres read as millimetres")):
        if abs(math.log10(ratio / factor)) < 0.25:
            return (f"lengths {factor:g} times too {'large' if factor > 1 else 'small'}: "
                    f"{slip}? (units.length; a C3D file's POINT:UNITS)")
    return "check units.length and the vertical axis (columns.ball, markers.vertical_axis)"


def extract_all(trials: list[Trial], events, settings: ExtractionSettings, source: str,
                measure_g: bool = False, measure_offset: bool = False) -> SessionExtraction:
    """Every trial extracted, and the set-up measured from them (``setup_quantities``).

    With ``measure_g`` (the user set no g) the flights are fitted at the g their pooled
    curvature shows (``pooled_gravity``, all trials), with ``measure_offset`` at the median
    marker offset measured at the impacts: a first pass at ``settings`` measures both, a
    second extracts at them. A measured g outside any set-up's (PLAUSIBLE_G_M_S2) is a unit
    slip: an error when it would be used, else a warning; a set g that the flights
    contradict by more than 3 SE is a warning. Where the ball's marker goes below the
    racket's at its lowest points (a racket marker above the face), the first pass starts
    from that depth (``seeded_offset``): at offset 0 the ball reads as resting at every
    bounce."""
    caches: list[dict] = [{} for _ in trials]  # one pass finds each trial's racket cycles
    if measure_offset:
        settings = replace(settings, ball_offset_m=seeded_offset(trials, settings))
    first = _extract_trials(trials, events, settings, source, caches)
    gravity = pooled_gravity([f for _, _, r in first for f in r.flights])
    warnings: list[str] = [*missing_rows_warnings(trials, source, settings.max_gap_s),
                           *jitter_warnings(trials, source)]
    g = settings.g
    if gravity is not None:
        lo, hi = PLAUSIBLE_G_M_S2
        if not lo <= gravity.g <= hi:
            text = (f"{source}: the ball's free flights imply g = {gravity.g:.3g} m/s^2, outside "
                    f"any set-up's {lo:g}-{hi:g} m/s^2: {unit_slip_hint(gravity.g)}")
            if measure_g:
                raise ConfigError(text)
            warnings.append(text)
        elif measure_g:
            g = gravity.g
        elif abs(gravity.g - settings.g) > 3.0 * gravity.se:
            warnings.append(f"g = {settings.g:g} m/s^2 was set, but the ball's free flights "
                            f"show {gravity.g:.4g} +- {gravity.se:.2g} m/s^2 "
                            f"({abs(gravity.g - settings.g) / gravity.se:.0f} SE off): the "
                            "flights are fitted at the set g (unset it to use the measured)")
    # the marker offset is measured at the impacts of flights fitted at the right g
    results = first if g == settings.g else _extract_trials(
        trials, events, replace(settings, g=g), source, caches)
    offsets = np.concatenate([r.offsets_m for _, _, r in results])
    offsets = offsets[np.isfinite(offsets)]
    used = replace(settings, g=g)
    if measure_offset and offsets.size and float(np.median(offsets)) != settings.ball_offset_m:
        used = replace(used, ball_offset_m=float(np.median(offsets)))
        results = _extract_trials(trials, events, used, source, caches)
    impacts, excluded, cycles = [], [], []
    for trial, ev, result in results:
        frame = pd.DataFrame({"trial": trial.label, **result.impacts})
        columns = list(REQUIRED_COLUMNS)
        if ev is not None and ev.alpha is not None:
            alpha = frame["alpha"]
            baseline = Counter(np.round(ev.alpha, 12)).most_common(1)[0][0]
            frame["perturbed"] = ~np.isclose(alpha, baseline)
            columns += EVENT_COLUMNS
        if trial.ball is not None:
            columns += MEASURED_COLUMNS
        impacts.append(frame[columns])
        excluded += [(trial.label, t, why) for t, why in result.excluded]
        c = result.cycles
        cycles.append(pd.DataFrame({
            "trial": trial.label, "cycle": np.arange(len(c.crossings)),
            "t_start_s": c.crossings, "racket_period_s": c.periods,
            "racket_amplitude_m": c.amplitudes, "mid_position_m": c.mids}))
    excluded_frame = pd.DataFrame(excluded, columns=["trial", "t_s", "reason"])
    impacts_frame = pd.concat(impacts, ignore_index=True)
    setup = setup_quantities(impacts_frame, [r for _, _, r in results], gravity, used,
                             measure_g, measure_offset)
    warnings += event_clock_warnings(setup, impacts_frame, source, [r for _, _, r in results],
                                     float(np.median([np.median(np.diff(trial.t))
                                                      for trial in trials])))
    warnings += missed_bounce_warnings(impacts_frame, used.g, source)
    return SessionExtraction(impacts_frame, excluded_frame, pd.concat(cycles, ignore_index=True),
                             setup, used, warnings)


#: the events' lag behind the ball's contacts (s) beyond half the contact's duration that is
#: warned of: 1 ms is 0.4 deg of phase at a 0.92 s racket period (at 1 kHz and 0.5 mm noise
#: the median lag of 20 impacts is measured to about 0.01 ms)
EVENT_LAG_TOLERANCE_S = 0.001


def event_clock_warnings(setup: list[SetupQuantity], impacts: pd.DataFrame, source: str,
                         results: list[TrialExtraction], sample_s: float) -> list[str]:
    """A warning where the events' times lag or lead the ball's contacts in the recording by
    more than half the contact's duration (a log of the contacts' onsets or releases: the
    flights meet about mid-contact) plus EVENT_LAG_TOLERANCE_S: the event log's clock is not
    the recording's, and every phase is off by the lag (an impact's phase is the racket's
    phase at the event's time).

    The lag is ``event_lag_s`` (where the flights meet; beyond 3 SE), or, where events far
    off have cut the flights in the wrong place and few impacts measure it, the median over
    every event of its time less the nearest contact detected in the ball's samples
    (``results``' ``event_lags_coarse_s``, to about a sample: beyond 1.5 ``sample_s`` more)."""
    q = {item.quantity: item for item in setup}
    contact = q["contact_s"].estimate if "contact_s" in q else 0.0
    allowed = 0.5 * (contact if math.isfinite(contact) else 0.0) + EVENT_LAG_TOLERANCE_S
    lag = None
    if "event_lag_s" in q:
        fine = q["event_lag_s"]
        se = fine.se if math.isfinite(fine.se) else 0.0
        if abs(fine.estimate) > allowed + 3.0 * se:
            lag, n, how = fine.estimate, fine.n, "where its flights meet"
    coarse = np.concatenate([np.array([]), *(r.event_lags_coarse_s for r in results)])
    coarse = coarse[np.isfinite(coarse)]
    if lag is None and coarse.size >= 3 and (
            abs(float(np.median(coarse))) > allowed + 1.5 * sample_s):
        lag, n = float(np.median(coarse)), int(coarse.size)
        how = f"contacts detected in its samples, to about a sample: {1000 * sample_s:.2g} ms"
    if lag is None:
        return []
    period = float(impacts["racket_period_s"].median()) if len(impacts) else math.nan
    phase = (f", so every phase is off by about {360.0 * abs(lag) / period:.2g} deg"
             if math.isfinite(period) and period > 0 else "")
    return [f"{source}: the events are {1000 * abs(lag):.3g} ms "
            f"{'later' if lag > 0 else 'earlier'} than the ball's contacts in the recording "
            f"(median of {n}, {how}; contact {1000 * contact:.2g} ms){phase}: is the event "
            f"log on the recording's clock? (--set events_shift_s={-lag:.4g} shifts them back, "
            "or extract without --events)"]


def _median_quantity(name: str, per_trial: list[np.ndarray], note: str
                     ) -> SetupQuantity | None:
    """The median of per-impact values (NaN: not measured) over the trials, with its SE
    (1.2533 SD / sqrt(n), a normal sample's); None where no impact measured it."""
    values = np.concatenate(per_trial) if per_trial else np.array([])
    values = values[np.isfinite(values)]
    if not values.size:
        return None
    sd = float(np.std(values, ddof=1)) if values.size > 1 else math.nan
    return SetupQuantity(name, float(np.median(values)), 1.2533 * sd / math.sqrt(values.size),
                         int(values.size), note)


def _mean_se(x) -> tuple[float, float, int]:
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return math.nan, math.nan, 0
    sd = float(np.std(x, ddof=1)) if x.size > 1 else math.nan
    return float(np.mean(x)), sd / math.sqrt(x.size), int(x.size)


def setup_quantities(impacts: pd.DataFrame, results, gravity, used: ExtractionSettings,
                     measured_g: bool, measured_offset: bool) -> list[SetupQuantity]:
    """The set-up measured from the extraction (``bounce_cli.data.setup_table``'s quantities; a
    quantity the data cannot show is left out).

    Parameters
    ----------
    impacts : pandas.DataFrame
        The impacts table (``alpha_measured``, ``contact_s`` where the ball was tracked).
    results : list of TrialExtraction
        Each trial's extraction (flights, offsets, standard errors, racket residuals).
    gravity : GravityFit or None
        The pooled fit of the flights' curvature.
    used : ExtractionSettings
        What the extraction ran at (g, marker offset).
    measured_g, measured_offset : bool
        Whether those were the measured values (else set by the user).

    Returns
    -------
    list of SetupQuantity
    """
    out: list[SetupQuantity] = []
    if gravity is not None:
        how = ("used for the flight fits" if measured_g
               else f"the flights were fitted at the set g = {used.g:g}")
        out.append(SetupQuantity("g_m_s2", gravity.g, gravity.se, gravity.n_flights,
                                 f"pooled curvature of {gravity.n_flights} free flights "
                                 f"({gravity.n_samples} samples); {how}"))
    if "alpha_measured" in impacts.columns:
        alpha = impacts["alpha_measured"].to_numpy(float)
        mean, se, n = _mean_se(alpha)
        if n:
            out.append(SetupQuantity("alpha", mean, se, n, "eq. 3 per impact: ball velocity "
                                     "before and after the (equivalent) impact, racket "
                                     "velocity there"))
        if n > 1:
            sd = float(np.nanstd(alpha, ddof=1))
            out.append(SetupQuantity("alpha_sd", sd, sd / math.sqrt(2.0 * (n - 1)), n,
                                     "SD of alpha across impacts (with their measurement "
                                     "error)"))
        duration, se, n = contact_duration(
            np.concatenate([r.contact_area for r in results]),
            np.concatenate([r.contact_weight for r in results]))
        if n:
            out.append(SetupQuantity("contact_s", duration, se, n, "from the area of the "
                                     "ball above its two flights around each impact, pooled "
                                     "(a linear spring-damper contact's shape)"))
    offset = _median_quantity(
        "ball_offset_m", [r.offsets_m for r in results], "median at the equivalent impacts; "
        + ("used by the extraction" if measured_offset
           else f"the extraction used the set {used.ball_offset_m:g} m"))
    lag = _median_quantity(
        "event_lag_s", [r.event_lags_s for r in results], "median of the events' times less "
        "the ball's contacts (where its flights either side meet): 0 on one clock; a log of "
        "the contacts' onsets is early by about half the contact's duration")
    out += [q for q in (offset, lag) if q is not None]
    if gravity is not None:
        out.append(SetupQuantity("position_noise_m", gravity.residual_sd, math.nan,
                                 gravity.n_samples, "residual SD of the ball's flight fits"))
    rss = sum(r.racket_rss for r in results)
    dof = sum(r.racket_dof for r in results)
    if dof > 0:
        out.append(SetupQuantity("racket_noise_m", math.sqrt(rss / dof), math.nan, dof,
                                 "residual SD of the racket's local fits at the impacts"))
    for name, key, what in (("measurement_sd_v_m_s", "se_v_m_s", "v_k"),
                            ("measurement_sd_theta_rad", "se_theta_rad", "theta_k")):
        values = np.concatenate([getattr(r, key) for r in results])
        values = values[np.isfinite(values)]
        if values.size:
            out.append(SetupQuantity(name, float(np.median(values)), math.nan,
                                     int(values.size), f"median standard error of {what}, "
                                     "propagated from the fits' residuals"))
    return out


#: accuracy.csv: quantity, its unit and how an error is measured
ACCURACY_QUANTITIES = (
    ("theta_deg", "deg"), ("v_m_s", "m/s"), ("racket_acc_g", "g"), ("racket_period_s", "s"),
    ("racket_amplitude_m", "m"), ("hop_s", "s"), ("ball_apex_m", "m"), ("t_s", "s"),
    ("v_in_m_s", "m/s"), ("alpha_measured", "1"), ("contact_s", "s"),
)


def accuracy_frame(impacts: pd.DataFrame, truth: pd.DataFrame) -> pd.DataFrame:
    """RMS and largest error of each extracted quantity against the truth, impacts matched by
    trial and time; plus how many of the truth's impacts were found."""
    quantities = [(q, unit) for q, unit in ACCURACY_QUANTITIES
                  if q in impacts.columns and q in truth.columns]
    errors: dict[str, list[float]] = {q: [] for q, _ in quantities}
    found = 0
    for label, tr in truth.groupby("trial", sort=False):
        ex = impacts[impacts["trial"].astype(str) == str(label)]
        idx = match_impacts(tr["t_s"].to_numpy(float), ex["t_s"].to_numpy(float))
        ok = idx >= 0
        found += int(ok.sum())
        for q, _ in quantities:
            d = ex[q].to_numpy(float)[ok] - tr[q].to_numpy(float)[idx[ok]]
            if q == "theta_deg":
                d = (d + 180.0) % 360.0 - 180.0
            errors[q].append(d[np.isfinite(d)])
    rows = []
    for q, unit in quantities:
        d = np.concatenate(errors[q]) if errors[q] else np.array([])
        rows.append({"quantity": q, "unit": unit, "n": d.size,
                     "rms_error": float(np.sqrt(np.mean(d * d))) if d.size else math.nan,
                     "max_abs_error": float(np.max(np.abs(d))) if d.size else math.nan})
    rows.append({"quantity": "impacts_found", "unit": "count", "n": len(truth),
                 "rms_error": math.nan, "max_abs_error": float(len(truth) - found)})
    return pd.DataFrame(rows)


def figure_samples(trials: list[Trial], impacts: pd.DataFrame, fig) -> pd.DataFrame:
    """The samples Fig. 2 shows: the chosen trial, from its chosen bounce over ``bounces``."""
    labels = [str(t.label) for t in trials]
    label = labels[0] if fig.trial is None else str(fig.trial)
    if label not in labels:
        raise ConfigError(f"figure.trial: {fig.trial!r} is not a trial of the recording "
                          f"({', '.join(labels[:10])})")
    trial = trials[labels.index(label)]
    imp = impacts[impacts["trial"].astype(str) == label]
    if fig.start_s is not None:
        imp = imp[imp["t_s"] >= fig.start_s]
    if imp.empty:
        raise ConfigError(f"figure.start_s: no impact of trial {label} after {fig.start_s} s")
    t_first = float(imp["t_s"].iloc[0])
    after = imp["t_s"].iloc[fig.bounces] if len(imp) > fig.bounces else trial.t[-1]
    t_lo = max(t_first - 0.25 * float(np.nanmedian(imp["hop_s"])) if imp["hop_s"].notna().any()
               else t_first, trial.t[0])
    sel = (trial.t >= t_lo) & (trial.t < float(after))
    return pd.DataFrame({"trial": trial.label, "t_s": trial.t[sel],
                         "racket_x_m": trial.racket[sel],
                         "ball_x_m": (trial.ball[sel] if trial.ball is not None
                                      else np.full(int(sel.sum()), np.nan))})


def set_gravity(config: ExtractConfig) -> float | None:
    """The g the user set for the flight fits: ``extraction.g``, else ``model.g`` when the
    config sets it; None: measured from the flights."""
    if config.extraction.g is not None:
        return config.extraction.g
    return config.model.g if "g" in config.model.model_fields_set else None


def run(config: ExtractConfig, options: RunOptions) -> ExperimentResult:
    """``bounce extract``; ``options.figures`` False draws no figure (the study draws its own
    from the frames, and only those it writes)."""
    g_set = set_gravity(config)
    # without a set g a first pass runs at model.g's default (and stays there without ball
    # data, whose flights alone show g)
    settings = config.extraction.settings(config.model.g if g_set is None else g_set)
    summary = []
    if config.data is None:
        for key in ("events", "truth"):
            if getattr(config, key) is not None:
                raise ConfigError(f"{key}: needs data (the recording it belongs to)")
        trials, truth = demo_session()
        source = "the simulated session of configs/recording.yaml"
        summary.append(f"no data given: extracted {source} (bounce simulate-recording's "
                       "recording.csv) and compared it with its truth")
    else:
        trials = read_recording(Path(config.data), config.columns, config.units,
                                config.markers, config.csv, config.format, options.warn)
        source = config.data
        truth = read_truth(config.truth) if config.truth is not None else None
    events = None
    if config.events is not None:
        events = read_events(Path(config.events), config.event_columns, config.units, trials,
                             config.csv, shift_s=config.events_shift_s)
    if g_set is None and events is not None and any(t.ball is None for t in trials):
        options.warn(f"no ball data (columns.ball is null): v_k and AC come from the events' "
                     f"flight times at g = {settings.g:g} m/s^2, model.g's default, which no "
                     "flight measured; set model.g (or extraction.g) to the set-up's g")
    options.progress.start(len(trials), "extract")
    session = extract_all(trials, events, settings, source, measure_g=g_set is None,
                          measure_offset=config.extraction.ball_offset_m is None)
    impacts, excluded, cycles = session.impacts, session.excluded, session.cycles
    for message in session.warnings:
        options.warn(message)
    options.progress.advance(len(trials))
    frames = {"impacts.csv": impacts, "excluded.csv": excluded, "cycles.csv": cycles,
              "setup.csv": setup_frame(session.setup),
              "fig2_samples.csv": figure_samples(trials, impacts, config.figure)}
    if truth is not None:
        frames["accuracy.csv"] = accuracy_frame(impacts, truth)
        matched = frames["accuracy.csv"].set_index("quantity").loc["theta_deg", "n"]
        if len(truth) and len(impacts) and matched == 0:
            raise ConfigError(
                f"truth {config.truth}: none of its {len(truth)} impacts matches one of the "
                f"{len(impacts)} extracted (by trial and time: is it this recording's truth, "
                "on the same time base?)")
    reasons = Counter(r.split(":")[0] for r in excluded["reason"])
    summary.append(
        f"{len(trials)} trial(s): {len(impacts)} impacts, mean v = {impacts['v_m_s'].mean():.4f}"
        f" m/s, mean theta = {centred_deg(impacts['theta_deg']).mean():.2f} deg, mean AC = "
        f"{impacts['racket_acc_g'].mean():.3f} g; not reported: {len(excluded)}"
        + (" (" + ", ".join(f"{n} {r}" for r, n in reasons.items()) + ")" if reasons else ""))
    summary.append(setup_summary(session.setup))
    if "accuracy.csv" in frames:
        acc = frames["accuracy.csv"].set_index("quantity")
        summary.append("RMS error against the truth: " + ", ".join(
            f"{q} {acc.loc[q, 'rms_error']:.3g} {acc.loc[q, 'unit']}"
            for q in ("theta_deg", "v_m_s", "racket_acc_g")))
    if not options.figures:
        return ExperimentResult(frames=frames, figures={}, summary=summary)
    drawn = draw(frames)
    caption_figures(drawn, None, f"data: {config.data}" if config.data is not None
                    else "the bundled simulated session (no --data)")
    return ExperimentResult(frames=frames, figures=drawn, summary=summary)


def setup_summary(setup: list[SetupQuantity]) -> str:
    """One line of the measured set-up (``setup.csv``)."""
    q = {item.quantity: item for item in setup}
    parts = []
    if "g_m_s2" in q:
        g = q["g_m_s2"]
        parts.append(f"g {g.estimate:.3f} +- {g.se:.2g} m/s^2 ({g.n} flights)")
    if "alpha" in q:
        sd = f", SD {q['alpha_sd'].estimate:.3f}" if "alpha_sd" in q else ""
        parts.append(f"alpha {q['alpha'].estimate:.3f}{sd} ({q['alpha'].n} impacts)")
    if "contact_s" in q:
        parts.append(f"contact {1000 * q['contact_s'].estimate:.1f} ms")
    if "ball_offset_m" in q:
        parts.append(f"ball marker {1000 * q['ball_offset_m'].estimate:.1f} mm above the "
                     "racket marker at impact")
    noise = [f"{label} {1000 * q[name].estimate:.2f} mm" for name, label in
             (("position_noise_m", "ball"), ("racket_noise_m", "racket")) if name in q]
    if noise:
        parts.append("noise: " + ", ".join(noise))
    if "measurement_sd_v_m_s" in q or "measurement_sd_theta_rad" in q:
        sds = []
        if "measurement_sd_v_m_s" in q:
            sds.append(f"v {1000 * q['measurement_sd_v_m_s'].estimate:.2f} mm/s")
        if "measurement_sd_theta_rad" in q:
            sds.append(f"theta {math.degrees(q['measurement_sd_theta_rad'].estimate):.3f} deg")
        parts.append("measurement SD " + ", ".join(sds))
    if "event_lag_s" in q:
        parts.append(f"events {1000 * q['event_lag_s'].estimate:+.2f} ms from the ball's "
                     "contacts")
    return "set-up measured (setup.csv): " + ("; ".join(parts) if parts else "nothing")


@publication_style
def draw(frames: dict[str, pd.DataFrame]) -> dict:
    samples, impacts = frames["fig2_samples.csv"], frames["impacts.csv"]
    return {"fig2.png": draw_fig2(samples, impacts, "extracted ball velocity after impact "
                                  "and phase of impact", bounces=len(impacts))}


EXPERIMENT = Experiment(name="extract", schema=ExtractConfig, run=run, draw=draw)
