"""bounce from Python: run an experiment in a notebook, read a recording, extract its impacts.

The same code path as the command line: :func:`run` loads and validates a config exactly as
``bounce <name>`` does (:func:`load_run_config`), runs the experiment, and, given ``out``,
writes exactly what the command writes through the same run directory (:func:`open_run_directory`,
:func:`write_result`). A user error raises a :class:`~bounce_cli.errors.BounceError` (a
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
import warnings
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .runtime.artifacts import FIGURE_DPI, RunDirectory
from .runtime.config import (
    DATA_MODEL_KEYS,
    ConfigError,
    ExperimentConfig,
    bundled_config_path,
    keys_set_by_user,
    load_config,
    validate,
)
from .model.params import FixedPoint, ModelError, ModelParams
from .model.maps import Orbit, iterate_orbit, map_step
from .model.linear import Stability, stability
from .experiments.base import Experiment, ExperimentResult, RunOptions
from .experiments.registry import EXPERIMENTS, Entry

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "run", "read_recording", "extract", "ExperimentResult",
    "ModelParams", "FixedPoint", "map_step", "iterate_orbit", "Orbit", "stability", "Stability",
    "ConfigError", "ModelError",
]


# -- the one path shared with the CLI (``cli.run_experiment``) -------------------------------
def find_entry(name: str) -> Entry:
    """The registry entry of experiment ``name`` (a command of ``bounce``).

    Parameters
    ----------
    name : str
        The command's name, e.g. ``"basin"``.

    Returns
    -------
    Entry
        Its :class:`bounce_cli.experiments.registry.Entry`.

    Raises
    ------
    ConfigError
        When no experiment has that name (the message lists them).

    Examples
    --------
    >>> find_entry("basin").figures[0][0]
    'basin.png'
    """
    for entry in EXPERIMENTS:
        if entry.name == name:
            return entry
    raise ConfigError(f"no experiment named {name!r} (one of: "
                      + ", ".join(e.name for e in EXPERIMENTS) + ")")


def load_run_config(entry: Entry, config: Path | None,
                    overrides: list[str]) -> tuple[Experiment, Path, ExperimentConfig]:
    """Load an experiment's config and validate it, as ``bounce <name> --config --set`` does.

    Parameters
    ----------
    entry : Entry
        The experiment (:func:`find_entry`).
    config : Path or None
        A YAML config; None: the bundled ``configs/<name>.yaml``.
    overrides : list of str
        ``dotted.key=value`` overrides (YAML scalars), applied in order.

    Returns
    -------
    tuple
        (the experiment, the config file read, the validated config).

    Raises
    ------
    ConfigError
        A missing or malformed file, an unknown key, a value out of range.

    Examples
    --------
    >>> _, path, cfg = load_run_config(find_entry("basin"), None, ["grid.v0_m_s.num=4"])
    >>> path.name, cfg.grid.v0_m_s.num
    ('basin.yaml', 4)
    """
    experiment = entry.load()
    path = Path(config) if config is not None else bundled_config_path(entry.config)
    return experiment, path, load_config(experiment.schema, path, overrides, EXPERIMENTS)


def warn_if_unstable(params: ModelParams, controller=None,
                     warn: Callable[[str], None] | None = None) -> None:
    """Warn when the period-1 fixed point exists but is linearly unstable (eq. 10; with racket
    period control the 3 x 3 Jacobian of ``engine.control``): the figures then describe an
    orbit nothing converges to.

    Parameters
    ----------
    params : ModelParams
        The model's parameters.
    controller : optional
        The racket period controller of ``model.control``, or None.
    warn : callable, optional
        Receives the one-line message (the CLI prints ``bounce: warning: <message>``); None:
        a Python ``UserWarning``.

    Raises
    ------
    NoFixedPointError
        When there is no fixed point at all (eq. 8).

    Examples
    --------
    >>> unstable = ModelParams(alpha=0.5, g=9.81, racket_amplitude=0.30, racket_period=0.5)
    >>> warn_if_unstable(unstable, warn=print)  # doctest: +ELLIPSIS
    the period-1 fixed point is linearly unstable at these parameters (spectral radius ...
    """
    from .model.linear import flip_boundary_g, is_stable

    say = warn if warn is not None else python_warning
    if controller is not None:
        from .model.control import controlled_jacobian, spectral_radius_3x3

        radius = float(spectral_radius_3x3(controlled_jacobian(params, controller)))
        if not is_stable(radius):
            say(f"the period-1 fixed point is linearly unstable with this racket period "
                f"control (model.control: spectral radius {radius:.3g} of the 3 x 3 Jacobian)")
        return
    st = stability(params)
    if not st.stable:
        say(f"the period-1 fixed point is linearly unstable at these parameters (spectral "
            f"radius {st.spectral_radius:.3g}, AC = {st.ac_g:.3g} g; stable for "
            f"{float(flip_boundary_g(params.alpha)):.3g} g < AC < 0, eq. 14)")


def warn_if_implausible_racket(model, warn: Callable[[str], None] | None = None) -> None:
    """A warning per racket parameter of a ``model`` block outside what a person can do
    (``bounce_cli.data.plausibility``), naming the likely unit slip (a block without a racket, such
    as a study's, has nothing to check).

    Parameters
    ----------
    model
        A config's validated ``model`` block.
    warn : callable, optional
        Receives each one-line message; None: a Python ``UserWarning``.
    """
    from .data.plausibility import racket_warnings

    if getattr(model, "racket_amplitude", None) is None or getattr(
            model, "racket_period", None) is None:
        return
    say = warn if warn is not None else python_warning
    for message in racket_warnings(model.racket_amplitude, model.racket_period,
                                   "model.racket_amplitude", "model.racket_period"):
        say(message)


def check_model(entry: Entry, cfg: ExperimentConfig,
                warn: Callable[[str], None] | None = None) -> None:
    """Before a run: warn of an implausible racket, and, for a run about the period-1 fixed
    point, of an unstable one (with a ``data`` file the model is taken at the data's racket,
    not the config's, so neither is checked). Raises ``NoFixedPointError`` when there is
    none."""
    if getattr(cfg, "data", None) is not None:
        return
    warn_if_implausible_racket(cfg.model, warn)
    if entry.needs_fixed_point:
        controller = getattr(cfg.model, "controller", lambda: None)()
        warn_if_unstable(cfg.params, controller, warn)


def run_options(entry: Entry, cfg: ExperimentConfig, config: Path | None, overrides: list[str],
                **options: Any) -> RunOptions:
    """The run's :class:`RunOptions` (``options``: jobs, warn, scheduler), with the model keys
    the user set (``--set``'s, and their own config's where it differs from the bundled one:
    ``config.keys_set_by_user``) where a ``data`` analysis takes the others from the data."""
    run = RunOptions(**options)
    if getattr(cfg, "data", None) is not None:
        defaults = None if config is None else load_config(
            type(cfg), bundled_config_path(entry.config)).model_dump(mode="json")
        given = keys_set_by_user(config, overrides, defaults)
        run.model_set_by_user = frozenset(
            key for key in DATA_MODEL_KEYS if f"model.{key}" in given)
    return run


def open_run_directory(entry: Entry, cfg: ExperimentConfig, path: Path, *, config_given: bool,
                       overrides: list[str], out: Path | None, force: bool,
                       figure_formats: tuple[str, ...] = ("png",),
                       dpi: int = FIGURE_DPI) -> RunDirectory:
    """The run directory the results go to (default ``results/<name>``), with the manifest's
    provenance; checks that ``out`` holds no other config's results unless ``force``.

    Parameters
    ----------
    entry, cfg, path
        The experiment, its validated config and the file it was read from
        (:func:`load_run_config`).
    config_given : bool
        The user named the config (else the bundled one was read).
    overrides : list of str
        The ``--set`` overrides, recorded in the manifest.
    out : Path or None
        The output folder; None: ``results/<config's stem or name>``.
    force : bool
        Replace results of a different config in ``out``.
    figure_formats : tuple of str, default ("png",)
        Each figure is written once in each format.
    dpi : int
        The PNGs' resolution.

    Returns
    -------
    RunDirectory
        Nothing is written until :func:`write_result` commits it.
    """
    data_file = getattr(cfg, "data", None)
    name = path.stem if config_given else entry.name
    return RunDirectory(
        Path(out) if out is not None else Path("results") / name,
        command=entry.name,
        resolved_config=cfg.model_dump(mode="json"),
        overrides=overrides,
        config_path=str(path) if config_given else f"bundled: configs/{path.name}",
        # a fit to a data file draws no random numbers: its seed is not part of the run
        seed=getattr(cfg, "seed", None) if data_file is None else None,
        data_file=data_file,
        force=force,
        figure_formats=figure_formats,
        dpi=dpi,
    )


def write_result(run_dir: RunDirectory, result: ExperimentResult, agrees=None) -> list[Path]:
    """Write a result's tables, figures and files into ``run_dir`` atomically.

    Parameters
    ----------
    run_dir : RunDirectory
        From :func:`open_run_directory`.
    result : ExperimentResult
        What the experiment returned.
    agrees : optional
        See ``RunDirectory.commit``.

    Returns
    -------
    list of Path
        The files written (the manifest among them).
    """
    for name, frame in result.frames.items():
        run_dir.add_csv(name, frame)
    for name, figure in result.figures.items():
        run_dir.add_figure(name, figure)
    for name, content in result.files.items():
        run_dir.add_file(name, content)
    return run_dir.commit(agrees)


def python_warning(message: str) -> None:
    """The API's warning sink: a ``UserWarning`` carrying the CLI's warning text."""
    warnings.warn(message, UserWarning, stacklevel=3)


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
    experiment, path, cfg = load_run_config(entry, None if config is None else Path(config),
                                            overrides)
    check_model(entry, cfg)
    run_dir = None
    if out is not None:  # checked before the work: a folder of another config's results
        run_dir = open_run_directory(entry, cfg, path, config_given=config is not None,
                                     overrides=overrides, out=Path(out), force=force)
    try:
        options = run_options(entry, cfg, None if config is None else Path(config), overrides,
                              jobs=int(jobs), warn=python_warning)
        if run_dir is not None:
            run_dir.record = options.record
        result = experiment.run(cfg, options)
        if run_dir is not None:
            write_result(run_dir, result)
    except BaseException:
        if run_dir is not None:
            run_dir.discard()
        raise
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
