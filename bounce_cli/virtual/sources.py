"""Where the virtual set-up's racket samples come from: one interface, a source per kind.

A source gives, for trial n (1, 2, ...), its racket samples ``(t, x)`` in s and m, time from the
trial's start, in increasing time. ``sine``: the model's racket (eq. 4) sampled at the
protocol's rate, the deterministic check of the physics; ``replay:<file>``: the racket column
of any recording ``bounce extract`` reads (CSV, C3D, Vicon, QTM, Motive; the recording's
trials in turn, cycled when the protocol has more), played at its own clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator, Protocol

import numpy as np

from ..errors import ConfigError

#: the sources ``--racket`` takes
SOURCE_KINDS = ("sine", "replay:<file>")


class RacketSource(Protocol):
    """Racket samples per trial, and a one-line description for ``run.json``."""

    @property
    def description(self) -> str: ...

    def samples(self, trial: int, duration_s: float) -> Iterator[tuple[float, float]]: ...


@dataclass(frozen=True)
class SineSource:
    """x_r(t) = a_r sin(omega_r t) (eq. 4), sampled every 1 / rate_hz s from t = 0."""

    amplitude_m: float
    period_s: float
    rate_hz: float

    @property
    def description(self) -> str:
        return (f"sine: a_r = {self.amplitude_m:g} m, tau = {self.period_s:g} s, sampled at "
                f"{self.rate_hz:g} Hz")

    def samples(self, trial: int, duration_s: float) -> Iterator[tuple[float, float]]:
        w = 2.0 * math.pi / self.period_s
        n = int(math.floor(duration_s * self.rate_hz)) + 1
        for i in range(n):
            t = i / self.rate_hz
            yield t, self.amplitude_m * math.sin(w * t)


@dataclass(frozen=True)
class ReplaySource:
    """The racket of a recording's trials (SI units, as ``bounce extract`` reads it); samples
    with a missing racket position are left out (the physics bridges or pauses over them)."""

    path: Path
    trials: tuple  # of (t, racket) arrays

    @property
    def description(self) -> str:
        return f"replay: {self.path} ({len(self.trials)} trial(s))"

    def samples(self, trial: int, duration_s: float) -> Iterator[tuple[float, float]]:
        t, racket = self.trials[(trial - 1) % len(self.trials)]
        keep = np.isfinite(t) & np.isfinite(racket)
        t, racket = t[keep], racket[keep]
        if t.size == 0:
            return
        t = t - t[0]
        for ti, xi in zip(t[t <= duration_s], racket[t <= duration_s]):
            yield float(ti), float(xi)


def open_source(spec: str, amplitude_m: float, period_s: float, rate_hz: float,
                read_racket: Callable[[Path], list[tuple[np.ndarray, np.ndarray]]]
                ) -> RacketSource:
    """The source a ``--racket`` text names (see ``SOURCE_KINDS``); a one-line error otherwise.
    ``read_racket(path)``: the (t, racket) arrays of a recording's trials, in SI units (the
    experiment reads it as ``bounce extract`` does)."""
    if spec == "sine":
        return SineSource(amplitude_m, period_s, rate_hz)
    if spec.startswith("replay:"):
        path = Path(spec[len("replay:"):])
        if not path.is_file():
            raise ConfigError(f"racket: replay:{path}: no such file")
        return ReplaySource(path, tuple(read_racket(path)))
    raise ConfigError(f"racket: unknown source {spec!r} (one of {', '.join(SOURCE_KINDS)})")
