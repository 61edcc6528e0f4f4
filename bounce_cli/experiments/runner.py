"""The one front door of a run: :func:`execute` loads and checks a config, opens the run
directory, runs the experiment, writes its files atomically and cleans up on any exit.

Every way of running an experiment goes through it: ``bounce <name>`` (the CLI's
``run_experiment``), ``bounce reproduce`` (each bundled config in turn), the notebook's
:func:`bounce_cli.api.run`, and ``bounce study`` (each unit's extraction and analyses, with
the unit's impacts table held in memory). What differs between them is only what they pass:
the CLI prints warnings and shows a progress bar, the notebook hears Python warnings and
writes only when given ``out``, the study writes nothing and draws no figure.

The pieces it is made of (:func:`load_run_config`, :func:`check_model`, :func:`run_options`,
:func:`open_run_directory`, :func:`write_result`) are public for a caller that needs one
step alone (``bounce <name> --print-config`` loads a config and prints it).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import ConfigError
from ..runtime.artifacts import RunDirectory
from ..runtime.figure_files import FIGURE_DPI
from ..runtime.interrupts import Interrupted
from ..runtime.config import (
    DATA_MODEL_KEYS,
    ExperimentConfig,
    bundled_config_path,
    keys_set_by_user,
    load_config,
)
from ..model.impact import check_period1_orbit
from ..model.params import ModelParams
from ..model.linear import stability
from .base import Experiment, ExperimentResult, Progress, RunOptions, no_warning
from .registry import EXPERIMENTS, Entry

if TYPE_CHECKING:
    from ..data.impacts import ImpactsSource


def python_warning(message: str) -> None:
    """The library's warning sink: a ``UserWarning`` carrying the CLI's warning text."""
    warnings.warn(message, UserWarning, stacklevel=3)


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
    period control the 3 x 3 Jacobian of ``model.control``): the figures then describe an
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
    from ..model.linear import flip_boundary_g, is_stable

    say = warn if warn is not None else python_warning
    if controller is not None:
        from ..model.control import controlled_jacobian, spectral_radius_3x3

        radius = float(spectral_radius_3x3(controlled_jacobian(params, controller)))
        if not is_stable(radius):
            say(f"the period-1 fixed point is linearly unstable with this racket period "
                f"control (model.control: spectral radius {radius:.3g} of the 3 x 3 Jacobian)")
        return
    st = stability(params)
    if not st.stable:
        say(f"the period-1 fixed point is linearly unstable at these parameters (spectral "
            f"radius {st.spectral_radius:.3g}, AC = {st.ac_g:.3g} g; stable for "
            f"{float(flip_boundary_g(params.alpha)):.4g} g < AC < 0, eq. 14)")


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
    from ..data.plausibility import racket_warnings

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


#: the blocks whose ``parameter`` replaces a model key over the whole run (bifurcation's
#: sweep, continuation's range), and the model key each swept parameter replaces (gamma is set
#: through a_r at the model's tau and g)
SWEPT_BLOCKS = ("sweep", "range")
SWEPT_MODEL_KEY = {"gamma": "racket_amplitude", "racket_amplitude": "racket_amplitude",
                   "racket_period": "racket_period", "alpha": "alpha"}


def warn_if_swept_over(entry: Entry, cfg: ExperimentConfig, config: Path | None,
                       overrides: list[str], warn: Callable[[str], None] | None = None) -> None:
    """Warn where the user set a model key that the run's swept parameter replaces at every
    value (``--set model.racket_amplitude=0.02`` with a sweep of Gamma: the CSVs are those
    of the bundled a_r, a reviewer found), so that a setting never goes without effect in
    silence. What the user set is ``user_keys``', as for a ``--data`` analysis."""
    swept = [(block, parameter, SWEPT_MODEL_KEY[parameter]) for block in SWEPT_BLOCKS
             if (parameter := str(getattr(getattr(cfg, block, None), "parameter", None)))
             in SWEPT_MODEL_KEY and hasattr(getattr(cfg, "model", None),
                                            SWEPT_MODEL_KEY[parameter])]
    if not swept:
        return
    given = user_keys(entry, cfg, config, overrides)
    for block, parameter, key in swept:
        if f"model.{key}" in given:
            message = (f"model.{key} has no effect: {block}.parameter {parameter} sets it at "
                       f"every value of the run"
                       + (" (Gamma through a_r, at the model's racket_period and g)"
                          if parameter == "gamma" else ""))
            (warn if warn is not None else python_warning)(message)


def user_keys(entry: Entry, cfg: ExperimentConfig, config: Path | None,
              overrides: list[str]) -> frozenset[str]:
    """The dotted keys the user gave (``keys_set_by_user``: ``--set``'s, and their own
    config's where it differs from the bundled one)."""
    defaults = None if config is None else load_config(
        type(cfg), bundled_config_path(entry.config)).model_dump(mode="json")
    return keys_set_by_user(config, overrides, defaults)


def run_options(entry: Entry, cfg: ExperimentConfig, config: Path | None, overrides: list[str],
                **options: Any) -> RunOptions:
    """The run's :class:`RunOptions` (``options``: jobs, warn, scheduler), with the model keys
    the user set (``--set``'s, and their own config's where it differs from the bundled one:
    ``config.keys_set_by_user``) where a ``data`` analysis takes the others from the data."""
    run = RunOptions(**options)
    if getattr(cfg, "data", None) is not None:
        given = user_keys(entry, cfg, config, overrides)
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


@dataclass
class Execution:
    """What :func:`execute` did: the experiment's result, its validated config, and where it
    wrote (``out_dir`` None and ``written`` empty for a run that writes nothing);
    ``comparison``: each file against what the folder held before (``RunDirectory.commit``:
    ``bounce reproduce``'s identical / within tolerance / changed)."""

    result: ExperimentResult
    config: ExperimentConfig
    out_dir: Path | None = None
    written: list[Path] = field(default_factory=list)
    comparison: dict[str, str] = field(default_factory=dict)


def execute(entry: Entry | str, config: Path | str | ExperimentConfig | None = None,
            overrides: Sequence[str] = (), *, write: bool = True, out: Path | str | None = None,
            force: bool = False, jobs: int = 1, scheduler: str | None = None,
            resume: bool = False, figure_formats: tuple[str, ...] = ("png",),
            dpi: int = FIGURE_DPI, progress: Progress | None = None,
            warn: Callable[[str], None] = no_warning, inform: Callable[[str], None] = no_warning,
            agrees=None, impacts: ImpactsSource | None = None,
            figures: bool = True) -> Execution:
    """Run one experiment from its config to its written files: the one way every front end
    runs an experiment (the CLI, ``bounce reproduce``, :func:`bounce_cli.api.run`, the
    study's units).

    Parameters
    ----------
    entry : Entry or str
        The experiment (its registry entry or its command's name).
    config : Path or str or ExperimentConfig, optional
        A YAML config file; None: the bundled ``configs/<name>.yaml``; or a config already
        validated (the study builds its units' configs), which ``overrides`` must not touch
        and which is not written.
    overrides : sequence of str
        ``dotted.key=value`` overrides of a config file (the CLI's ``--set``).
    write : bool, default True
        Write the results into the run directory ``out`` (default ``results/<name>``, the
        config's stem when a config file is named); False: return them only.
    out : Path or str, optional
        The output folder.
    force : bool, default False
        Replace the results of a different config in ``out``.
    jobs : int, default 1
        Local worker processes of an experiment with parallel tasks.
    scheduler : str, optional
        A Dask scheduler's address to run the tasks on instead.
    resume : bool, default False
        Keep the finished tasks of an interrupted run in ``out`` (a resumable experiment's
        ``<out>/points/``).
    figure_formats : tuple of str, default ("png",)
        Each figure is written once in each format.
    dpi : int
        The PNGs' resolution.
    progress : Progress, optional
        Where long work reports; stopped (``progress.stop()``, where it has one) when the run
        ends, however it ends.
    warn, inform : callable
        Receive what the run tells its user (``bounce: warning: ...``) and its operator.
    agrees : optional
        When a table counts as unchanged (``RunDirectory.commit``; ``bounce reproduce``).
    impacts : ImpactsSource, optional
        A ``--data`` analysis's impacts held in memory, ``(label, frame)``, read instead of
        the config's ``data`` file.
    figures : bool, default True
        Draw the experiment's figures (False: the tables alone).

    Returns
    -------
    Execution
        The result, the config, and what was written where.

    Raises
    ------
    BounceError
        A user error (a bad config or data file, no fixed point, an output folder holding
        another config's results); nothing is written, and an output folder the run made is
        removed. An interrupt or any other error leaves the same way (a resumable run's
        finished points stay for ``--resume``).
    """
    if isinstance(entry, str):
        entry = find_entry(entry)
    overrides = list(overrides)
    if isinstance(config, ExperimentConfig):
        if overrides or write:
            raise ValueError("execute: a validated config is neither overridden nor written")
        experiment, cfg, path = entry.load(), config, None
    else:
        config = None if config is None else Path(config)
        experiment, path, cfg = load_run_config(entry, config, overrides)
    run_dir = None
    checkpoints = None
    try:
        if write:  # --out checked first: its error is not preceded by a warning
            assert path is not None
            run_dir = open_run_directory(entry, cfg, path, config_given=config is not None,
                                         overrides=overrides,
                                         out=None if out is None else Path(out), force=force,
                                         figure_formats=figure_formats, dpi=dpi)
        if impacts is None:  # with impacts the model is the data's, not the config's
            check_model(entry, cfg, warn)
            if not isinstance(config, ExperimentConfig):
                warn_if_swept_over(entry, cfg, config, overrides, warn)
        if path is None:
            options = RunOptions(jobs=jobs, warn=warn, inform=inform, scheduler=scheduler)
        else:
            assert not isinstance(config, ExperimentConfig)
            options = run_options(entry, cfg, config, overrides, jobs=jobs, warn=warn,
                                  inform=inform, scheduler=scheduler)
        options.impacts, options.figures = impacts, figures
        options.figure_formats, options.dpi = tuple(figure_formats), dpi
        if progress is not None:
            options.progress = progress
        if run_dir is not None:
            run_dir.record = options.record
            if entry.resumable:
                from ..runtime.checkpoints import PointFolder

                identity: dict = {"command": entry.name}
                if not entry.task_keys:  # else each task knows what it was made from
                    identity["config"] = run_dir.resolved_config
                checkpoints = PointFolder(run_dir.out_dir, identity, resume=resume,
                                          force=force)
                options.checkpoints = checkpoints
        try:
            result = experiment.run(cfg, options)
        finally:
            stop = getattr(progress, "stop", None)
            if stop is not None:
                stop()
        if not figures:  # the tables alone, whether or not the experiment reads the flag
            result.figures = {}
        if run_dir is None:  # the caller gets the figures themselves
            result.draw_figures()
            return Execution(result, cfg)
        written = write_result(run_dir, result, agrees)
        result.name_out_dir(run_dir.out_dir)
        if checkpoints is not None:
            checkpoints.remove()
    except BaseException as exc:
        if checkpoints is not None:
            checkpoints.discard_if_empty()
            finished = checkpoints.finished()
            if finished and isinstance(exc, Interrupted):
                exc.note = (f"{finished} finished task{'s' if finished != 1 else ''} kept in "
                            f"{checkpoints.folder}/: --resume continues")
        if run_dir is not None:
            run_dir.discard()
        raise
    return Execution(result, cfg, run_dir.out_dir, written, run_dir.comparison)


def load_model_block(config: Path | None, overrides: Sequence[str] | None, *,
                     need_fixed_point: bool = True,
                     warn: Callable[[str], None] | None = None):
    """The validated ``model`` block of a config (any experiment's; its other blocks are
    checked for misspelt names and otherwise ignored), with its ``control`` (racket period
    control): what the engine commands ``bounce fixed-point`` and ``bounce orbit`` run at.

    Parameters
    ----------
    config : Path or None
        A YAML config; None: the bundled ``configs/model.yaml``.
    overrides : sequence of str, optional
        ``--set`` overrides; only ``model.*`` keys.
    need_fixed_point : bool, default True
        Parameters without a period-1 fixed point (eq. 8) are a user error (the map itself,
        ``bounce orbit``, is defined at any valid parameters).
    warn : callable, optional
        Receives a warning per implausible racket parameter; None: a Python ``UserWarning``.

    Returns
    -------
    ModelBlock
        ``to_params()`` gives the :class:`~bounce_cli.model.params.ModelParams`,
        ``controller()`` the racket period controller or None.

    Raises
    ------
    ConfigError
        A bad file or key, an override of another block; ``NoFixedPointError`` as above.
    """
    from ..runtime.config import (
        ModelOnlyConfig,
        apply_overrides,
        parse_override,
        read_yaml,
        refuse_unknown_blocks,
        validate,
    )

    path = config if config is not None else bundled_config_path("model")
    overrides = list(overrides or [])
    for text in overrides:
        keys, _ = parse_override(text)
        if keys[0] != "model":
            raise ConfigError(f"--set {'.'.join(keys)}: this command only uses the model block")
    data = apply_overrides(read_yaml(path), overrides)
    others = {key: value for key, value in data.items() if key != "model"}
    if others:  # read no further, but a misspelt block must not pass unseen (issue 36)
        refuse_unknown_blocks(others, str(path), [e.load().schema for e in EXPERIMENTS])
    cfg = validate(ModelOnlyConfig, {"model": data.get("model") or {}}, str(path), overrides)
    warn_if_implausible_racket(cfg.model, warn)
    if need_fixed_point:
        check_period1_orbit(cfg.params)
    return cfg.model
