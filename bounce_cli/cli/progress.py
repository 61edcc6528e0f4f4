"""Progress of long work on the terminal: a live bar (rich) where stderr is one, plain
lines at most every ten seconds where it is a log file or a batch job's output."""

from __future__ import annotations

import sys
import time
from typing import Any

from .shell import stderr


class RichProgress:
    """Progress bar on stderr (rich); shown only while work is under way."""

    def __init__(self) -> None:
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TextColumn,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )

        self._progress = Progress(
            TextColumn("{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            TimeRemainingColumn(),
            console=stderr,
            transient=True,
        )
        self._task: Any = None  # rich's TaskID once started

    def start(self, total: int, description: str) -> None:
        if self._task is None:
            self._progress.start()
            self._task = self._progress.add_task(description, total=total)
        else:
            self._progress.reset(self._task, total=total, description=description)

    def advance(self, n: int = 1) -> None:
        if self._task is not None:
            self._progress.advance(self._task, n)

    def stop(self) -> None:
        self._progress.stop()


class PlainProgress:
    """Progress for a log file or a batch job (stderr not a terminal): a plain line
    ``description: 45% (72,000 of 160,000), 12 s elapsed, about 15 s left`` at most every
    ``interval`` seconds (default INTERVAL_S); nothing for work shorter than that."""

    INTERVAL_S = 10.0

    def __init__(self, interval: float | None = None, clock=time.monotonic) -> None:
        self.interval = self.INTERVAL_S if interval is None else interval
        self._clock = clock
        self._total = 0
        self._done = 0
        self._description = ""
        self._started = self._last = clock()

    def start(self, total: int, description: str) -> None:
        self._total, self._done, self._description = total, 0, description
        self._started = self._last = self._clock()

    def advance(self, n: int = 1) -> None:
        self._done += n
        now = self._clock()
        if now - self._last < self.interval or not self._total:
            return
        self._last = now
        elapsed = now - self._started
        fraction = self._done / self._total
        left = elapsed * (1 - fraction) / fraction if fraction > 0 else float("nan")
        print(
            f"{self._description}: {fraction:.0%} ({self._done:,} of {self._total:,}), "
            f"{elapsed:.0f} s elapsed, about {left:.0f} s left",
            file=sys.stderr,
            flush=True,
        )

    def stop(self) -> None:
        pass


def make_progress():
    """The live bar on a terminal, plain lines otherwise."""
    return RichProgress() if stderr.is_terminal else PlainProgress()
