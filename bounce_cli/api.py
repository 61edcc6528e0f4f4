"""bounce from Python: run an experiment in a notebook, read a recording, extract its impacts.

The same code path as the command line: :func:`run` goes through the one front door of
every run, :func:`bounce_cli.experiments.runner.execute`, which loads and validates a config
exactly as ``bounce <name>`` does, runs the experiment, and, given ``out``, writes exactly
what the command writes. A user error raises a :class:`~bounce_cli.errors.BounceError` (a
:class:`~bounce_cli.errors.ConfigError`, :class:`~bounce_cli.errors.ModelError`, ...) with the
one line the command would print; nothing exits the interpreter.

The model's entry points (the map of eqs. 5, 6; the fixed point of eqs. 7, 8; the linear
stability of eqs. 9-14) are re-exported here and from :mod:`bounce_cli`::

    >>> import bounce_cli
    >>> p = bounce_cli.ModelParams(alpha=0.5, g=9.81, racket_amplitude=0.30, racket_period=0.92)
    >>> round(p.fixed_point().v_m_s, 4)  # eq. 7: v~ = pi g / omega_r = g tau / 2
    4.5126
    >>> round(p.fixed_point().theta_deg, 2), bounce_cli.stability(p).stable  # eqs. 8, 10
    (42.76, True)
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .runtime.config import ConfigError, validate
from .model.params import FixedPoint, ModelError, ModelParams
from .model.maps import Orbit, iterate_orbit, map_step
from .model.linear import Stability, stability
from .experiments.base import ExperimentResult
from .experiments.registry import EXPERIMENTS
from .experiments.runner import execute, find_entry, python_warning

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "run", "read_recording", "extract", "ExperimentResult",
    "ModelParams", "FixedPoint", "map_step", "iterate_orbit", "Orbit", "stability", "Stability",
    "ConfigError", "ModelError",
]


def override_texts(set: Mapping[str, Any] | Sequence[str] | None) -> list[str]:
    """``--set`` texts from a mapping (``{"grid.v0_m_s.num": 40}``: each value written as a YAML
    scalar or flow list) or from ``"key=value"`` strings as given on the command line."""
    if set is None:
        return []
    if isinstance(set, Mapping):
        return [f"{key}={json.dumps(value)}" for key, value in set.items()]
    if isinstance(set, str):
        raise ConfigError(f"set: a mapping or a list of key=value texts, not the text {set!r}")
    return [str(text) for text in set]


# -- the notebook API ------------------------------------------------------------------------
def run(name: str, config: str | Path | None = None,
        set: Mapping[str, Any] | Sequence[str] | None = None,  # noqa: A002 - the CLI's --set
        data: str | Path | None = None, jobs: int = 1, out: str | Path | None = None,
        force: bool = False) -> ExperimentResult:
    """Run experiment ``name`` as ``bounce <name>`` does, and return its tables and figures.

    Parameters
    ----------
    name : str
        The experiment's command (``"basin"``, ``"acf"``, ``"extract"``, ...).
    config : str or Path, optional
        A YAML config; None: the bundled ``configs/<name>.yaml`` (the paper's figure).
    set : mapping or list of str, optional
        Overrides of config values, ``{"grid.v0_m_s.num": 40}`` or ``["grid.v0_m_s.num=40"]``
        (the CLI's ``--set``).
    data : str or Path, optional
        The data file of an experiment that takes ``--data`` (sets the config key ``data``).
    jobs : int, default 1
        Worker processes for grid work (the numbers do not depend on it).
    out : str or Path, optional
        Write the results there, exactly the files ``bounce <name> --out OUT`` writes
        (manifest included). None: nothing is written.
    force : bool, default False
        With ``out``: replace results of a different config there (``--force``).

    Returns
    -------
    ExperimentResult
        ``frames`` (CSV file name -> DataFrame), ``figures`` (PNG file name -> matplotlib
        Figure), ``summary`` (the lines the CLI prints), ``files`` and ``exit_code``.

    Raises
    ------
    ConfigError
        An unknown experiment, a bad config or override, a bad data file.
    OutputDirError
        ``out`` holds another config's results (and not ``force``), or cannot be written.
    ModelError
        Parameters without a period-1 fixed point where the experiment needs one.

    Warns
    -----
    UserWarning
        What the CLI prints as ``bounce: warning: ...`` (an unstable fixed point, ...).

    Examples
    --------
    >>> import bounce_cli
    >>> result = bounce_cli.run("basin", set={"grid.theta0_deg.num": 8, "grid.v0_m_s.num": 6})
    >>> result.frames["basin.csv"].shape[0]
    48
    >>> sorted(result.figures)
    ['basin.png', 'basin_iterations.png']
    """
    entry = find_entry(name)
    overrides = override_texts(set)
    if data is not None:
        if entry.data_help is None:
            raise ConfigError(f"data: bounce {name} takes no data file")
        overrides.append(f"data={json.dumps(str(data))}")
    if int(jobs) < 1:
        raise ConfigError(f"jobs: {jobs} (at least 1)")
    result = execute(entry, config, overrides, write=out is not None, out=out, force=force,
                     jobs=int(jobs), warn=python_warning).result
    # figures the run directory drew where it wrote them (DeferredFigure): drawn here too
    result.draw_figures()
    return result


#: the columns of a recording frame (as ``bounce simulate-recording`` writes recording.csv)
RECORDING_COLUMNS = ("trial", "t_s", "racket_x_m", "ball_x_m")


def _extract_config(data: dict[str, Any], source: str):
    from .experiments.extract import ExtractConfig

    return validate(ExtractConfig, {k: v for k, v in data.items() if v is not None}, source,
                    commands=EXPERIMENTS)


def read_recording(path: str | Path, columns: Mapping[str, Any] | None = None,
                   units: Mapping[str, Any] | None = None,
                   markers: Mapping[str, Any] | None = None,
                   csv: Mapping[str, Any] | None = None, format: str = "auto") -> pd.DataFrame:
    """Read a lab's recording of racket and ball (CSV, C3D, a Vicon, QTM or Motive export)
    into one frame.

    Parameters
    ----------
    path : str or Path
        The recording.
    columns, units, markers, csv : mapping, optional
        The blocks of the same names in ``bounce extract``'s config (``configs/extract.yaml``):
        which columns hold time, trial, racket and ball; their units; a marker file's racket
        and ball markers and vertical axis; the CSV dialect. None: that block's defaults.
    format : str, default "auto"
        ``auto`` (by the suffix and the first line), ``csv``, ``c3d``, ``vicon``, ``qtm`` or
        ``motive``, as ``bounce extract``'s ``format``.

    Returns
    -------
    pandas.DataFrame
        Columns ``trial``, ``t_s``, ``racket_x_m``, ``ball_x_m`` (SI units; ball NaN without a
        ball column), one row per sample, trials in the file's order.

    Raises
    ------
    ConfigError
        A missing file or column, a non-number, a trial too short to extract from, a file
        that is not of its format.

    Examples
    --------
    >>> import bounce_cli, tempfile, pathlib
    >>> session = bounce_cli.run("simulate-recording",
    ...                          set={"trials": 1, "duration_s": 5.0})
    >>> folder = pathlib.Path(tempfile.mkdtemp())
    >>> session.frames["recording.csv"].to_csv(folder / "recording.csv", index=False)
    >>> recording = bounce_cli.read_recording(folder / "recording.csv")
    >>> list(recording.columns), len(recording)  # 5 s at 200 Hz, both ends included
    (['trial', 't_s', 'racket_x_m', 'ball_x_m'], 1001)
    """
    import numpy as np
    import pandas as pd

    from .data.recordings import read_recording as read_trials

    cfg = _extract_config({"columns": columns, "units": units, "markers": markers, "csv": csv,
                           "format": format}, "read_recording")
    trials = read_trials(Path(path), cfg.columns, cfg.units, cfg.markers, cfg.csv, cfg.format,
                         python_warning)
    return pd.concat([pd.DataFrame({
        "trial": [trial.label] * len(trial.t), "t_s": trial.t, "racket_x_m": trial.racket,
        "ball_x_m": trial.ball if trial.ball is not None else np.full(len(trial.t), np.nan)})
        for trial in trials], ignore_index=True)


def extract(recording: pd.DataFrame | str | Path, extraction: Mapping[str, Any] | None = None,
            g: float | None = None) -> pd.DataFrame:
    """The impacts table of a recording: per bounce the map's variables (paper Fig. 2).

    The extraction of ``bounce extract`` (its ``impacts.csv``): phase of impact theta_k, ball
    velocity after impact v_k (eq. 5's state), racket acceleration at impact AC (section 4),
    racket period and amplitude of the cycle, hop and apex of the ball.

    Parameters
    ----------
    recording : DataFrame or str or Path
        A frame in :func:`read_recording`'s columns, or a CSV file in them (others: read it
        with :func:`read_recording` first).
    extraction : mapping, optional
        The ``extraction`` block of ``configs/extract.yaml`` (windows, thresholds).
    g : float, optional
        Gravitational acceleration, m/s^2 (the flights between impacts are parabolas in it);
        None: measured from the flights' curvature, as ``bounce extract`` does when no g is
        set (``extraction.g`` in ``extraction`` sets it too).

    Returns
    -------
    pandas.DataFrame
        The impacts table (``bounce_cli.data.impacts``' columns: trial, k, t_s, theta_deg, v_m_s,
        racket_acc_g, ...).

    Raises
    ------
    ConfigError
        A bad setting, a missing column, a trial without a bounce.

    Examples
    --------
    >>> import bounce_cli
    >>> import pandas as pd
    >>> session = bounce_cli.run("simulate-recording", set={"trials": 1, "duration_s": 10.0})
    >>> impacts = bounce_cli.extract(session.frames["recording.csv"])
    >>> truth = session.frames["truth.csv"]  # the simulated impacts
    >>> both = pd.merge_asof(impacts, truth, on="t_s", direction="nearest", tolerance=0.005,
    ...                      suffixes=("", "_true"))
    >>> len(both) >= 9, bool((both["v_m_s"] - both["v_m_s_true"]).abs().max() < 0.01)  # m/s
    (True, True)
    """
    import pandas as pd

    import numpy as np

    from .experiments.extract import extract_all, set_gravity
    from .data.recordings import Trial

    cfg = _extract_config({"model": None if g is None else {"g": g}, "extraction": extraction},
                          "extract")
    if isinstance(recording, pd.DataFrame):
        frame, source = recording, "the recording frame"
    else:
        frame, source = read_recording(recording), str(recording)
    missing = [c for c in RECORDING_COLUMNS if c not in frame.columns]
    if missing:
        raise ConfigError(f"{source}: no column {missing[0]!r} (expected "
                          + ", ".join(RECORDING_COLUMNS) + ")")
    trials = []
    for label, samples in frame.groupby("trial", sort=False):
        ball = samples["ball_x_m"].to_numpy(float)
        trials.append(Trial(label, samples["t_s"].to_numpy(float),
                            samples["racket_x_m"].to_numpy(float),
                            None if np.isnan(ball).all() else ball))
    if not trials:
        raise ConfigError(f"{source}: no samples")
    g_set = set_gravity(cfg)
    settings = cfg.extraction.settings(cfg.model.g if g_set is None else g_set)
    session = extract_all(trials, None, settings, source, measure_g=g_set is None,
                          measure_offset=cfg.extraction.ball_offset_m is None)
    for message in session.warnings:
        python_warning(message)
    return session.impacts
