"""The impacts table (``impacts.csv``): one row per bounce, the interface between the data
side's extraction (``bounce extract``, recordings -> impacts) and every data analysis
(``--data impacts.csv``). A lab may also write this table itself.

Columns (units in the names; phases are the racket's phase of impact, section 2, eq. 6 with
``theta_k = omega_r t_k`` per racket cycle):

======================  ==========================================================================
``trial``               trial label (statistics never cross a trial boundary)
``k``                   impact index within the trial (0, 1, ...)
``t_s``                 time of the impact, s
``theta_rad``           phase of impact, wrapped to [0, 2 pi)
``theta_deg``           the same in degrees, [0, 360)
``v_m_s``               ball velocity just after the impact, m/s (the map's v_k)
``racket_acc_g``        racket acceleration at impact in units of g (AC, section 4)
``racket_period_s``     period of the racket cycle in which the impact falls, s
``racket_amplitude_m``  amplitude of that racket cycle, m
``hop_s``               time to the next impact, s (empty for a trial's last impact)
``ball_apex_m``         highest ball position of the following flight, relative to the racket's
                        mid-position, m
``alpha``               coefficient of restitution of this impact (optional: from events)
``perturbed``           True where alpha was changed at this impact (optional: from events)
``v_in_m_s``            ball velocity just before the impact, m/s (optional: ``bounce extract``
                        with the ball tracked; at a finite contact, of the equivalent
                        instantaneous impact: where the flights before and after meet)
``alpha_measured``      coefficient of restitution by eq. 3 from v_in, v_k and the racket's
                        velocity at t_k (optional: as ``v_in_m_s``)
``contact_s``           time the ball is off its free flights around the impact, s (0: an
                        instant; optional: as ``v_in_m_s``)
``g_m_s2``              gravity of the set-up, m/s^2 (optional; ``setup.csv`` beside the table
                        is read first)
======================  ==========================================================================

The ``--data`` analyses take the model's alpha and g from ``alpha_measured`` (else ``alpha``)
and ``setup.csv`` (else ``g_m_s2``) unless the user sets them (``bounce_cli.data.data_parameters``).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Union

import numpy as np
import pandas as pd

from ..runtime.config import ConfigError, show_value

#: the columns every impacts table has, in this order
REQUIRED_COLUMNS: tuple[str, ...] = (
    "trial",
    "k",
    "t_s",
    "theta_rad",
    "theta_deg",
    "v_m_s",
    "racket_acc_g",
    "racket_period_s",
    "racket_amplitude_m",
    "hop_s",
    "ball_apex_m",
)
#: columns present when the recording came with events (a virtual set-up's log)
EVENT_COLUMNS: tuple[str, ...] = ("alpha", "perturbed")
#: columns present when the ball was tracked: what the impact itself shows (eq. 3)
MEASURED_COLUMNS: tuple[str, ...] = ("v_in_m_s", "alpha_measured", "contact_s")

#: what every analysis needs: the trial, the impact index, and the map's state (v, theta);
#: theta may come as theta_rad or theta_deg
CORE_COLUMNS: tuple[str, ...] = ("trial", "k", "v_m_s")


def ball_apex(t, v, racket_x, next_t, g: float, mid_at):
    """``ball_apex_m``: the highest ball position of the flight after each impact (eq. 1:
    ``x_r(t_k) + v_k^2 / 2g``), relative to the racket's mid-position ``mid_at(time)`` at the
    apex; NaN where the apex would come after ``next_t`` (the next impact, or the trial's end)."""
    rise = np.maximum(v, 0.0) / g
    apex_t = t + rise
    apex = racket_x + np.maximum(v, 0.0) ** 2 / (2.0 * g) - mid_at(apex_t)
    return np.where(apex_t <= next_t, apex, np.nan)
#: what each optional column is for (named in the error when an analysis needs it)
COLUMN_PURPOSE: dict[str, str] = {
    "racket_acc_g": "the racket acceleration at impact AC",
    "racket_period_s": "the racket period (the model at the data's parameters)",
    "racket_amplitude_m": "the racket amplitude (the model at the data's parameters)",
    "ball_apex_m": "the SD of ball amplitude (Fig. 6)",
    "alpha": "the coefficient of restitution of each impact (perturbations, Figs. 9 and 11)",
    "perturbed": "which impacts were perturbed (Figs. 9 and 11)",
    "hop_s": "the time to the next impact",
    "t_s": "the time of each impact",
}


@dataclass(frozen=True)
class Impacts:
    """A checked impacts table: ``frame`` sorted by (trial, k) with ``theta_rad`` present, and
    the file it came from (for messages)."""

    frame: pd.DataFrame
    path: Path
    #: every trial of the table in its order, those left out for too few impacts included
    #: (``read_impacts``'s ``drop_short``): a trial's number in the series is its place here
    series: tuple = ()
    #: the phases were read from ``theta_deg`` (the table had no ``theta_rad``)
    phase_in_degrees: bool = False
    #: the trials as the file lists them (first appearance), where ``series`` put them in the
    #: order of their numbers instead (``session_order``); empty where the two agree
    listed: tuple = ()

    @property
    def trials(self) -> list:
        return list(dict.fromkeys(self.frame["trial"]))

    def trial_number(self, trial) -> int:
        """The trial's place in the session's series (1 first), counting trials left out."""
        return (list(self.series) if self.series else self.trials).index(trial) + 1

    def by_trial(self):
        """(trial, rows) in the file's order of trials."""
        for trial in self.trials:
            yield trial, self.frame[self.frame["trial"] == trial]

    def segments(self, min_length: int = 2):
        """(trial, rows) of each run of consecutive k (an impact missing from the table, e.g.
        dropped by the extraction in a gap, ends a run: no pair spans it), in order; runs
        shorter than ``min_length`` are left out."""
        for trial, rows in self.by_trial():
            k = rows["k"].to_numpy()
            breaks = np.flatnonzero(np.diff(k) != 1) + 1
            for part in np.split(np.arange(len(rows)), breaks):
                if len(part) >= min_length:
                    yield trial, rows.iloc[part]


#: how a ``perturbed`` cell may be written
PERTURBED_VALUES = {"true": True, "false": False, "1": True, "0": False, "1.0": True,
                    "0.0": False, "yes": True, "no": False, "y": True, "n": False}


def read_data_csv(path: Path) -> pd.DataFrame:
    """A ``--data`` CSV as a DataFrame with stripped column names; an unreadable file is one
    line naming ``data`` and the file (so is a device or a file above the recordings' size
    limit, ``recordings.text_exports.check_recording_file``)."""
    from .recordings.text_exports import check_recording_file, comment_lines, uncommented

    check_recording_file(Path(path))
    try:
        with open(path, "rb") as handle:
            # "# ..." lines before the header, by line number (an int would not count the
            # blank lines among them)
            notes = list(range(comment_lines(handle.read(65536))))
        # only an empty cell is missing: a cell such as 'n/a' stays text, so that an error
        # can show what the file holds
        # trial labels as written: "01" and "1" are two trials, not the number 1 twice
        header = pd.read_csv(path, nrows=0, skiprows=notes)
        labels = {c: str for c, name in zip(header.columns, uncommented(header.columns))
                  if name.strip() == "trial"}
        frame = pd.read_csv(path, keep_default_na=False, na_values=[""], dtype=labels,
                            skiprows=notes)
    except FileNotFoundError:
        raise ConfigError(f"data: {path}: file not found") from None
    except (OSError, pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise _fail(path, f"cannot read as CSV: {first}") from None
    frame.columns = [c.strip() for c in uncommented(frame.columns)]
    return frame


def cell_text(value: Any) -> str:
    """A cell as the file holds it: ``'n/a'``, ``-0.9``, or 'an empty cell'."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "an empty cell"
    return show_value(value)


def _fail(path: Path, message: str) -> ConfigError:
    return ConfigError(f"data: {path}: {message}")


#: where an impacts table comes from: a CSV file, several (trials of one session), or (label,
#: table) already in memory (a simulated lab session, ``experiments.lab``)
ImpactsSource = Union[str, Path, list, tuple[str, pd.DataFrame]]


def file_labels(paths: list[Path]) -> list[str]:
    """A short distinct label per file: its stem (``day1``), else its folder and stem
    (``lab1/impacts``), else its position (``1``, ``2``, ...)."""
    for label in (lambda p: p.stem, lambda p: f"{p.parent.name}/{p.stem}"):
        labels = [label(p) for p in paths]
        if len(set(labels)) == len(labels):
            return labels
    return [str(i) for i in range(1, len(paths) + 1)]


def read_session(paths: list) -> pd.DataFrame:
    """Several impacts tables as the trials of one session, in the order given. Trial labels
    stay as written unless two files share one: then every trial is labelled
    ``<file>:<trial>`` (``file_labels``), so that trials of different files never merge."""
    paths = [Path(p) for p in paths]
    frames = [read_data_csv(p) for p in paths]
    for p, f in zip(paths, frames):
        if "trial" not in f.columns:
            raise _fail(p, "missing column(s) trial: not an impacts table (required: trial, k, "
                           "v_m_s, theta_rad or theta_deg)")
    seen: dict[str, Path] = {}
    collide = False
    for p, f in zip(paths, frames):
        for trial in dict.fromkeys(f["trial"].astype(str)):
            collide |= trial in seen
            seen.setdefault(trial, p)
    if collide:
        for label, f in zip(file_labels(paths), frames):
            f["trial"] = label + ":" + f["trial"].astype(str)
    return pd.concat(frames, ignore_index=True)


_WHOLE_NUMBER = re.compile(r"\s*[+-]?[0-9]+\s*")


def session_order(labels: list[str]) -> list[str]:
    """Trial labels in their session's order: by their value where every label is a whole
    number (``1, 2, ..., 10``: a file sorted as text, or glued from several files, is put
    back in order, as a study's manifest orders numbered recordings), else in the order they
    first appear (``T1``, ``cond3``, a date: their numbers need not be the order in time).
    Equal numbers (``01`` and ``1``) keep their order of appearance."""
    if not labels or not all(_WHOLE_NUMBER.fullmatch(label) for label in labels):
        return labels
    return sorted(labels, key=int)


def read_impacts(source: ImpactsSource, needs: tuple[str, ...] = (), command: str = "",
                 min_bounces: int = 2, optional: tuple[str, ...] = (),
                 min_bounces_key: str = "",
                 drop_short: Callable[[str], None] | None = None) -> Impacts:
    """Read and check an impacts table (ours or a lab's own). Every problem is one line naming
    the file and the column, row or trial (ConfigError). ``needs``: the optional columns the
    analysis ``command`` requires; ``min_bounces``: fewest impacts a trial may have (the
    config key that sets it: ``min_bounces_key``, named in the message); a shorter trial is
    an error, or, with ``drop_short`` (a study's unit: one short recording must not cost the
    unit its analysis), left out with a warning passed to ``drop_short`` while other trials
    remain.
    ``source`` may also be ``(label, frame)``: a table in memory, checked the same way (the
    label stands for the file name in messages), or a list of files: the trials of one
    session (``read_session``). ``optional``: columns the analysis uses
    when present, checked like ``needs`` then."""
    if isinstance(source, tuple):
        label, frame = source
        path = Path(label)
        frame = frame.copy()
    elif isinstance(source, list):  # several files: one session (``read_session``)
        frame = read_session(source)
        path = Path(" + ".join(str(p) for p in source))
    else:
        path = Path(source)
        frame = read_data_csv(path)
    who = f"bounce {command} needs" if command else "needed"
    checked = (*needs, *(c for c in optional if c in frame.columns))
    missing = [c for c in CORE_COLUMNS if c not in frame.columns]
    if "theta_rad" not in frame.columns and "theta_deg" not in frame.columns:
        missing.append("theta_rad (or theta_deg)")
    if missing:
        # a recording (positions over time) is what a lab has first: say how to get impacts
        recording = "t_s" in frame.columns and "k" not in frame.columns
        hint = ("; a recording of positions? bounce extract --data it first (or run bounce "
                "study on a manifest of recordings)" if recording else "")
        raise _fail(path, f"missing column(s) {', '.join(missing)}: not an impacts table "
                          f"(required: trial, k, v_m_s, theta_rad or theta_deg){hint}")
    for column in needs:
        if column not in frame.columns:
            purpose = COLUMN_PURPOSE.get(column, column)
            raise _fail(path, f"missing column {column}: {who} {purpose}")
    if frame.empty:
        raise _fail(path, "no rows")
    if frame["trial"].isna().any():
        row = int(np.flatnonzero(frame["trial"].isna().to_numpy())[0])
        raise _fail(path, f"column trial: empty in data row {row + 1}")
    numeric = ["k", "v_m_s", "theta_rad" if "theta_rad" in frame.columns else "theta_deg",
               *[c for c in checked if c not in ("perturbed",)]]
    allow_nan = {"hop_s", "ball_apex_m"}  # a trial's last impact has no following flight
    for column in dict.fromkeys(numeric):
        values = pd.to_numeric(frame[column], errors="coerce")
        bad = ~np.isfinite(values.astype(float))
        if column in allow_nan:
            bad &= frame[column].notna()
        if bad.any():
            row = int(np.flatnonzero(bad.to_numpy())[0])
            raise _fail(path, f"column {column}: not a number in data row {row + 1} (trial "
                              f"{frame['trial'].iloc[row]}, "
                              f"got {cell_text(frame[column].iloc[row])})")
        frame[column] = values.astype(float)
    phase_in_degrees = "theta_rad" not in frame.columns
    if phase_in_degrees:
        frame["theta_rad"] = np.radians(frame["theta_deg"])
    elif "theta_deg" in frame.columns and not np.allclose(
            np.exp(1j * frame["theta_rad"].to_numpy(float)),
            np.exp(1j * np.radians(pd.to_numeric(frame["theta_deg"], errors="coerce")
                                   .to_numpy(float))), atol=1e-6, equal_nan=False):
        raise _fail(path, "columns theta_rad and theta_deg disagree (the same phase in two "
                          "units; keep one)")
    elif (np.abs(frame["theta_rad"]) > 2.0 * math.pi + 1e-9).any():
        row = int(np.flatnonzero((np.abs(frame["theta_rad"]) > 2.0 * math.pi + 1e-9)
                                 .to_numpy())[0])
        raise _fail(path, f"column theta_rad: {cell_text(frame['theta_rad'].iloc[row])} in data "
                          f"row {row + 1} is beyond 2 pi: degrees? (name the column theta_deg)")
    if (frame["k"] != np.round(frame["k"])).any():
        raise _fail(path, "column k: impact indices must be whole numbers")
    frame["k"] = frame["k"].astype(int)
    checks = {"racket_period_s": ("> 0", lambda x: x > 0),
              "racket_amplitude_m": ("> 0", lambda x: x > 0),
              "alpha": ("in [0, 1)", lambda x: (x >= 0) & (x < 1))}
    for column, (rule, ok) in checks.items():
        if column in checked and not ok(frame[column]).all():
            row = int(np.flatnonzero(~ok(frame[column]).to_numpy())[0])
            raise _fail(path, f"column {column}: must be {rule} (data row {row + 1}, trial "
                              f"{frame['trial'].iloc[row]}: "
                              f"{cell_text(frame[column].iloc[row])})")
    if "perturbed" in frame.columns:  # checked wherever present: acf and learning use it too
        text = frame["perturbed"].astype(str).str.strip().str.lower()
        unknown = ~text.isin(list(PERTURBED_VALUES))
        if unknown.any():
            row = int(np.flatnonzero(unknown.to_numpy())[0])
            raise _fail(path, f"column perturbed: expected True/False (or yes/no, 1/0) in "
                              f"data row {row + 1} "
                              f"(got {cell_text(frame['perturbed'].iloc[row])})")
        frame["perturbed"] = text.map(PERTURBED_VALUES).astype(bool)
    frame["trial"] = frame["trial"].astype(str)
    listed = list(dict.fromkeys(frame["trial"]))
    order = session_order(listed)
    frame["_order"] = frame["trial"].map({t: i for i, t in enumerate(order)})
    frame = frame.sort_values(["_order", "k"], kind="stable").drop(columns="_order")
    frame = frame.reset_index(drop=True)
    duplicate = frame.duplicated(["trial", "k"])
    if duplicate.any():
        row = frame[duplicate].iloc[0]
        raise _fail(path, f"trial {row['trial']}: impact k = {row['k']} appears twice")
    counts = frame.groupby("trial", sort=False).size()
    short = counts[counts < min_bounces]
    needed = (f"fewer than the {min_bounces} {('bounce ' + command) if command else 'the analysis'}"
              " needs per trial")
    lower = f"lower {min_bounces_key}" if min_bounces_key else "lower the requirement"
    if len(short) and (drop_short is None or len(short) == len(counts)):
        raise _fail(path, f"trial {short.index[0]}: {int(short.iloc[0])} impacts, {needed} "
                          f"(drop the trial or {lower})")
    series = tuple(counts.index)
    if len(short):
        assert drop_short is not None
        for trial, count in short.items():
            drop_short(f"trial {trial}: {int(count)} impacts, {needed}: left out ({lower} to "
                       "keep it)")
        frame = frame[~frame["trial"].isin(short.index)].reset_index(drop=True)
    return Impacts(frame, path, series, phase_in_degrees,
                   tuple(listed) if order != listed else ())


def impacts_frame(sim, params, trial_names=None) -> pd.DataFrame:
    """An impacts table (the columns above) from the engine's synthetic lab
    (``analysis.data_stats.simulate_impacts``): racket period and amplitude are the model's,
    AC = -a_r w^2 sin(theta) / g, ball apex x_r(theta) + v^2 / 2g, the set-up's g (``g_m_s2``,
    what the data analyses run the model at). Lost trials are left out."""
    from ..model.flight import apex_height

    rows = []
    n_trials, n = sim.v.shape
    for i in range(n_trials):
        if sim.lost[i]:
            continue
        name = trial_names[i] if trial_names is not None else i + 1
        theta = sim.theta[i]
        rows.append(pd.DataFrame({
            "trial": name, "k": np.arange(n), "t_s": sim.t[i],
            "theta_rad": theta, "theta_deg": np.degrees(theta), "v_m_s": sim.v[i],
            "racket_acc_g": params.racket_acceleration_g(np.asarray(theta)),
            "racket_period_s": params.racket_period,
            "racket_amplitude_m": params.racket_amplitude,
            "hop_s": sim.hop[i], "ball_apex_m": apex_height(params, theta, sim.v[i]),
            "alpha": sim.alpha[i], "perturbed": sim.perturbed[i], "g_m_s2": params.g,
        }))
    return pd.concat(rows, ignore_index=True)

