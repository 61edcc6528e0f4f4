"""The contract of an experiment, and what the CLI hands it.

An experiment module ``bounce_cli/experiments/<name>.py`` provides ``EXPERIMENT``, an
:class:`Experiment`, and is listed once in :mod:`bounce_cli.experiments.registry`. Adding an
experiment means: one module, one bundled config ``configs/<name>.yaml``, one registry line,
its tests, and (if it is part of ``bounce reproduce``) its baseline in ``results/<name>/``.

What an experiment must provide (as scipy's ``OdeSolver`` documents what a solver provides):

``schema``
    A subclass of :class:`bounce_cli.runtime.config.ExperimentConfig` (pydantic, unknown keys
    forbidden) describing its config; the bundled YAML must validate against it.
``run(config, options) -> ExperimentResult``
    Pure with respect to files: it reads nothing but the config (and, for an experiment with a
    ``data`` key, the file the config names), writes nothing, prints nothing. It returns tidy
    DataFrames (file name -> frame, written as CSV) and figures. Numerics belong in
    ``bounce_cli.model`` and ``bounce_cli.analysis``; an experiment turns a config into tables
    and figures. User errors are raised as ``ConfigError`` or ``ModelError`` with one line
    naming the key or file.
``draw(frames) -> dict[str, Figure]``
    Every figure of the run, drawn from the DataFrames ``run`` returned (or read back from the
    CSVs): a figure can always be redrawn from its data. ``draw`` is decorated with
    :func:`bounce_cli.experiments.plotting.publication_style` (the one style of every figure).
    ``run`` builds its figures by calling ``draw`` on its own frames, then records the
    parameters it ran at as their caption (:func:`bounce_cli.experiments.plotting.caption_figures`),
    which goes into each figure file's metadata (not its title), so that two runs' figures can
    be told apart.

The paper's values come from :mod:`bounce_cli.paper.values` (never literals in an experiment), and a
summary line or CSV column states one only where the run is at the paper's parameters
(:func:`bounce_cli.paper.values.at_parameters`); numerics (solvers, scans, inverse problems) live in
:mod:`bounce_cli.model` and :mod:`bounce_cli.analysis` with their own tests.

What it gets: the validated config, and :class:`RunOptions` (worker count or Dask scheduler,
a progress sink, a warning sink, a checkpoint store), which never change the numbers it
produces. Parallel work goes through
:mod:`bounce_cli.runtime.parallel` (a list of independent tasks handed to an executor's ``map``).
"""

from __future__ import annotations

import shlex
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Protocol

from ..runtime.config import ExperimentConfig
from ..runtime.figure_files import FIGURE_DPI

if TYPE_CHECKING:  # annotations only: ``bounce --help`` does not import pandas
    import pandas as pd

    from ..data.impacts import ImpactsSource


class Progress(Protocol):
    """Progress of long work: ``start(total, description)``, ``advance(n)``."""

    def start(self, total: int, description: str) -> None: ...

    def advance(self, n: int = 1) -> None: ...


class NullProgress:
    """Progress that reports nothing (library use, tests, ``--quiet``)."""

    def start(self, total: int, description: str) -> None:
        pass

    def advance(self, n: int = 1) -> None:
        pass


class Checkpoints(Protocol):
    """Finished tasks of a long run kept across interruptions (``bounce sweep --resume``):
    ``load()`` -> {task index: result} of an earlier, interrupted run of the same config;
    ``save(index, result)`` keeps one result (a JSON-able dict) as soon as it is done."""

    def load(self) -> dict[int, Any]: ...

    def save(self, index: int, result: Any) -> None: ...


class NoCheckpoints:
    """Keeps nothing (library use, tests): every run starts from scratch."""

    def load(self) -> dict[int, Any]:
        return {}

    def save(self, index: int, result: Any) -> None:
        pass


def no_warning(message: str) -> None:
    """The default warning sink: library use and tests hear nothing."""


@dataclass
class RunOptions:
    """Run-time choices that are not part of the config (apart from ``model_set_by_user``,
    they never change the results).

    ``warn(message)`` tells the user something before or during the run (the CLI prints
    ``bounce: warning: <message>``); an experiment never prints itself. ``scheduler``: a
    Dask scheduler address to run the tasks on instead of ``jobs`` local workers;
    ``checkpoints``: where an experiment that supports resuming keeps finished tasks.
    ``model_set_by_user``: the model keys (``alpha``, ``g``) the user set on the command
    line or in their own config; a ``--data`` analysis takes the others from the data
    (``bounce_cli.data.data_parameters``; None, library use: every config value counts as set).
    ``record``: what the run adds to ``run.json`` beside the config (the CLI writes it), e.g.
    ``model_at_data``, the values a ``--data`` analysis used and where they came from.
    ``inform(message)``: what a live experiment tells its operator while it runs (the URL of
    the virtual set-up's page; the CLI prints ``bounce: <message>``). ``impacts``: a
    ``--data`` analysis's impacts table held in memory, ``(label, frame)``, read instead of
    the config's ``data`` file (the study's units). ``figures``: draw the figures (False:
    the tables alone, for a caller that draws its own or none). ``figure_formats`` and
    ``dpi``: the formats and resolution of the figures an experiment renders itself (the
    study's, embedded in its report; the others' are written by the run directory)."""

    jobs: int = 1
    progress: Progress = field(default_factory=NullProgress)
    warn: Callable[[str], None] = no_warning
    inform: Callable[[str], None] = no_warning
    scheduler: str | None = None
    checkpoints: Checkpoints = field(default_factory=NoCheckpoints)
    model_set_by_user: frozenset[str] | None = None
    record: dict[str, Any] = field(default_factory=dict)
    impacts: ImpactsSource | None = None
    figures: bool = True
    figure_formats: tuple[str, ...] = ("png",)
    dpi: float = FIGURE_DPI


#: where a summary line names the run directory, which ``run`` does not know (it writes
#: nothing), as in ``f"bounce study --manifest {OUT_DIR}/study.csv --out {OUT_DIR}-study"``;
#: a run that is written shows the directory there (:meth:`ExperimentResult.name_out_dir`)
OUT_DIR = "<out>"


@dataclass
class ExperimentResult:
    """Tables (file name -> DataFrame), figures (file name -> matplotlib Figure, or a
    :class:`~bounce_cli.runtime.figure_files.DeferredFigure` drawn where it is written), a
    few human-readable summary lines for the terminal, other files (name -> bytes: a
    report), and the exit status once everything is written (1: some of the work failed, as
    a study's ``failures.csv`` says). File names may hold folders
    (``s1/vision/acf/acf.csv``)."""

    frames: dict[str, pd.DataFrame]
    figures: dict[str, Any]
    summary: list[str] = field(default_factory=list)
    files: dict[str, bytes] = field(default_factory=dict)
    exit_code: int = 0

    def draw_figures(self) -> None:
        """Every deferred figure drawn: ``figures`` then holds matplotlib Figures only (what
        a caller that writes no run directory gets, e.g. ``bounce_cli.run``)."""
        from ..runtime.figure_files import drawn

        self.figures = {name: drawn(figure) for name, figure in self.figures.items()}

    def name_out_dir(self, out_dir: Path) -> None:
        """The summary's :data:`OUT_DIR` replaced by ``out_dir`` as a shell takes it (quoted
        where it holds a space or other special characters), so that a command it suggests
        can be pasted as printed."""
        shown = shlex.quote(str(out_dir))
        self.summary = [line.replace(OUT_DIR, shown) for line in self.summary]


@dataclass(frozen=True)
class Experiment:
    """An experiment module's entry point: see the module docstring for the contract.

    ``name`` is its command and bundled config (``configs/<name>.yaml``); its one-line summary,
    figure captions and capabilities (``--data``) are in
    :mod:`bounce_cli.experiments.registry`, so that ``bounce --help`` need not import the
    experiments."""

    name: str
    schema: type[ExperimentConfig]
    run: Callable[[Any, RunOptions], ExperimentResult]
    draw: Callable[[dict[str, pd.DataFrame]], dict[str, Any]]
