"""Where the virtual set-up's racket samples come from: one interface, a source per kind.

A source gives, for trial n (1, 2, ...), its racket samples ``(t, x)`` in s and m, time from the
trial's start, in increasing time. ``sine``: the model's racket (eq. 4) sampled at the
protocol's rate, the deterministic check of the physics; ``subject``: that racket with its
period controlled impact by impact (a simulated subject, ``virtual.subject``);
``replay:<file>``: the racket column of any recording ``bounce extract`` reads (CSV, C3D,
Vicon, QTM, Motive; the recording's trials in turn, cycled when the protocol has more), played
at its own clock; ``lsl:<name>``: a Lab Streaming Layer stream of that name (how Vicon,
Qualisys, OptiTrack and most lab sensors publish in real time; ``pylsl``, the ``virtual``
extra), one channel of it, at the sender's timestamps.
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator, Protocol

import numpy as np

from ..errors import ConfigError
from .subject import NOMINAL_SUBJECT, SubjectControl, SubjectSource

#: the sources ``--racket`` takes
SOURCE_KINDS = ("sine", "subject", "replay:<file>", "lsl:<stream name>", "mouse")


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


#: a racket sample closer to the one before than this fraction of the stream's sample interval
#: carries a timestamp taken when it was sent, not when it was measured (a burst of samples
#: stamped microseconds apart, as ``push_sample`` without a timestamp gives): its position
#: belongs to a later time, and the racket's cubic through it moves at hundreds of m/s, the
#: ball then flying kilometres. Such samples are left out, and counted in a warning.
MIN_SPACING_FRACTION = 0.25

#: the sample interval a stream is judged by: the median of this many latest spacings
SPACING_WINDOW = 15


class SpacingGuard:
    """Leaves out samples much closer to the one before than the stream's sample interval
    (``MIN_SPACING_FRACTION``): the nominal interval where the stream declares one, else the
    median of the latest accepted spacings (no sample is judged before three spacings are
    seen)."""

    def __init__(self, interval_s: float | None = None) -> None:
        self.interval_s = interval_s if interval_s and math.isfinite(interval_s) else None
        self.spacings: deque[float] = deque(maxlen=SPACING_WINDOW)
        self.last = -math.inf
        self.dropped = 0

    def accept(self, t: float) -> bool:
        """Whether the sample at time t is kept (t after the last kept sample)."""
        spacing = t - self.last
        reference = self.interval_s
        if reference is None and len(self.spacings) >= 3:
            reference = float(np.median(self.spacings))
        if reference is not None and spacing < MIN_SPACING_FRACTION * reference:
            self.dropped += 1
            return False
        if math.isfinite(spacing):
            self.spacings.append(spacing)
        self.last = t
        return True

    def report(self, warn: Callable[[str], None], where: str) -> None:
        if self.dropped:
            warn(f"{where}: {self.dropped} racket sample(s) stamped less than "
                 f"{MIN_SPACING_FRACTION:g} of a sample interval after the one before were "
                 "left out (timestamps of when samples were sent, not measured? an LSL "
                 "outlet should pass each sample's own time to push_sample)")


@dataclass(frozen=True)
class ReplaySource:
    """The racket of a recording's trials (SI units, as ``bounce extract`` reads it); samples
    with a missing racket position are left out (the physics bridges or pauses over them)."""

    path: Path
    trials: tuple  # of (t, racket) arrays
    warn: Callable[[str], None] = lambda message: None

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
        spacing = np.diff(t)
        guard = SpacingGuard(float(np.median(spacing)) if spacing.size else None)
        for ti, xi in zip(t[t <= duration_s], racket[t <= duration_s]):
            if guard.accept(float(ti)):
                yield float(ti), float(xi)
        guard.report(self.warn, f"replay:{self.path}: trial {trial}")


@dataclass(frozen=True)
class LslSettings:
    """Which channel of the stream is the racket's height, in which unit, and how long to
    wait: for the stream to be found, and for samples before a trial is given up."""

    channel: int = 0
    metres_per_unit: float = 1.0
    resolve_timeout_s: float = 5.0
    give_up_s: float = 5.0


#: samples asked for per pull, and how long one pull waits (s)
LSL_CHUNK = 1024
LSL_PULL_S = 0.05


def _quiet_liblsl() -> None:
    """liblsl logs INFO lines on stderr; unless the user points ``LSLAPICFG`` at a config of
    their own, give it one that logs errors only (liblsl reads it when it starts)."""
    import os
    import tempfile

    if "LSLAPICFG" in os.environ:
        return
    path = Path(tempfile.gettempdir()) / "bounce-liblsl-errors-only.cfg"
    try:
        if not path.is_file():
            path.write_text("[log]\nlevel = -2\n", encoding="ascii")
    except OSError:
        return
    os.environ["LSLAPICFG"] = str(path)


class LslSource:
    """A Lab Streaming Layer stream: each trial takes the samples from the first one on (time
    from its timestamp), until ``duration_s`` of stream time; the next trial starts ``rest_s``
    of stream time after. Timestamps are the sender's (no clock post-processing), so a stall
    shows as a jump, which the physics takes as a gap; a stream silent for ``give_up_s`` (wall
    clock) ends the trial where it is, with a warning. Samples not later than the one before,
    or not finite, are dropped and counted."""

    live = True  # the stream's own clock paces it

    def __init__(self, name: str, settings: LslSettings, rest_s: float,
                 warn: Callable[[str], None]):
        _quiet_liblsl()
        try:
            import pylsl
        except ImportError:
            raise ConfigError("racket: lsl: needs pylsl (python -m pip install "
                              "'bounce-cli[virtual]')") from None
        found = pylsl.resolve_byprop("name", name, timeout=settings.resolve_timeout_s)
        if not found:
            raise ConfigError(f"racket: lsl:{name}: no stream of that name found within "
                              f"{settings.resolve_timeout_s:g} s")
        info = found[0]
        if not 0 <= settings.channel < info.channel_count():
            raise ConfigError(f"racket: lsl:{name}: channel {settings.channel} does not exist "
                              f"(the stream has {info.channel_count()})")
        self.name, self.settings, self.rest_s, self.warn = name, settings, rest_s, warn
        self.rate_hz = info.nominal_srate()
        self.inlet = pylsl.StreamInlet(info, max_buflen=360, processing_flags=0)
        self.inlet.open_stream(timeout=settings.resolve_timeout_s)
        self._next_start: float | None = None  # stream time the next trial starts at
        self._held: deque[tuple[float, float]] = deque()  # pulled, not yet taken

    @property
    def description(self) -> str:
        return (f"lsl: stream {self.name!r}, channel {self.settings.channel}, "
                f"{self.settings.metres_per_unit:g} m per unit, nominal {self.rate_hz:g} Hz")

    def skip_to_now(self) -> None:
        """Drop what the stream sent before now: a trial shown live (after a countdown or a
        rest on the screen) starts at the next sample, not at the backlog."""
        self._held.clear()
        while self.inlet.pull_chunk(timeout=0.0, max_samples=LSL_CHUNK)[1]:
            pass
        self._next_start = None

    def _pulled(self) -> Iterator[tuple[float, float] | None]:
        """Samples (stream time, metres) as they arrive; None when a pull found nothing."""
        channel, scale = self.settings.channel, self.settings.metres_per_unit
        while True:
            if self._held:  # a chunk is held whole: a trial that ends inside it loses nothing
                yield self._held.popleft()
                continue
            chunk, stamps = self.inlet.pull_chunk(timeout=LSL_PULL_S, max_samples=LSL_CHUNK)
            if not stamps:
                yield None
                continue
            self._held.extend((float(stamp), float(values[channel]) * scale)
                              for values, stamp in zip(chunk, stamps))

    def samples(self, trial: int, duration_s: float) -> Iterator[tuple[float, float]]:
        t_first: float | None = None
        last, dropped, silent_since = -math.inf, 0, time.monotonic()
        guard = SpacingGuard(1.0 / self.rate_hz if self.rate_hz > 0 else None)
        for sample in self._pulled():
            if sample is None:
                if time.monotonic() - silent_since > self.settings.give_up_s:
                    self.warn(f"lsl:{self.name}: no samples for {self.settings.give_up_s:g} s: "
                              f"trial {trial} ends there")
                    break
                continue
            silent_since = time.monotonic()
            stamp, x = sample
            if self._next_start is not None and stamp < self._next_start:
                continue  # the rest between trials
            if t_first is None:
                t_first = stamp
            if stamp - t_first > duration_s:
                self._held.appendleft(sample)  # the next trial's (or its rest's)
                break
            if stamp <= last or not math.isfinite(x):
                dropped += 1
                continue
            if not guard.accept(stamp):
                continue
            last = stamp
            yield stamp - t_first, x
        if t_first is not None:
            self._next_start = t_first + duration_s + self.rest_s
        if dropped:
            self.warn(f"lsl:{self.name}: trial {trial}: {dropped} sample(s) out of order or "
                      "not finite were dropped")
        guard.report(self.warn, f"lsl:{self.name}: trial {trial}")


def open_source(spec: str, amplitude_m: float, period_s: float, rate_hz: float,
                read_racket: Callable[[Path], list[tuple[np.ndarray, np.ndarray]]],
                lsl: LslSettings = LslSettings(), rest_s: float = 0.0,
                warn: Callable[[str], None] = lambda message: None,
                subject: SubjectControl = NOMINAL_SUBJECT) -> RacketSource:
    """The source a ``--racket`` text names (see ``SOURCE_KINDS``); a one-line error otherwise.
    ``read_racket(path)``: the (t, racket) arrays of a recording's trials, in SI units (the
    experiment reads it as ``bounce extract`` does); ``lsl``, ``rest_s``: an LSL stream's
    settings and the rest between its trials; ``subject``: the period control of the
    ``subject`` source (``virtual.subject``)."""
    if spec == "sine":
        return SineSource(amplitude_m, period_s, rate_hz)
    if spec == "subject":
        return SubjectSource(amplitude_m, period_s, rate_hz, subject)
    if spec.startswith("replay:"):
        text = spec[len("replay:"):]
        path = Path(text)
        if not text.strip():
            raise ConfigError("racket: replay: names no recording (replay:<file>)")
        if path.is_dir():
            raise ConfigError(f"racket: replay:{path}: a folder, not a recording")
        if not path.is_file():
            raise ConfigError(f"racket: replay:{path}: no such file")
        return ReplaySource(path, tuple(read_racket(path)), warn)
    if spec.startswith("lsl:") and spec[len("lsl:"):]:
        return LslSource(spec[len("lsl:"):], lsl, rest_s, warn)
    raise ConfigError(f"racket: unknown source {spec!r} (one of {', '.join(SOURCE_KINDS)})")
