"""What every experiment module provides, and what the CLI hands it.

An experiment turns a validated config into tidy DataFrames (written as CSV) and figures drawn
from those same DataFrames, so that every figure can be redrawn from its CSVs.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Protocol

import pandas as pd

from ..config import ExperimentConfig


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


@dataclass
class RunOptions:
    """Run-time choices that are not part of the config (they never change the results)."""

    jobs: int = 1
    progress: Progress = field(default_factory=NullProgress)


@dataclass
class ExperimentResult:
    """Tables (file name -> DataFrame), figures (file name -> matplotlib Figure) and a few
    human-readable summary lines for the terminal."""

    frames: dict[str, pd.DataFrame]
    figures: dict[str, Any]
    summary: list[str] = field(default_factory=list)
    seed: int | None = None


@dataclass(frozen=True)
class Experiment:
    """An experiment: its name (bundled config ``configs/<name>.yaml``), config schema, and
    ``run(config, options) -> ExperimentResult``. Its one-line summary lives with its command
    in ``cli.py``, so that ``bounce --help`` need not import the experiments."""

    name: str
    schema: type[ExperimentConfig]
    run: Callable[[Any, RunOptions], ExperimentResult]
