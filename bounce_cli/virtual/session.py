"""A virtual set-up's trial: the protocol's schedule of alpha, the ball on the racket stream,
and what is recorded (section 7's perturbation study: alpha_0 with every N-th impact's alpha
drawn from one of the given ranges, which one at random).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Iterator

import numpy as np

from .physics import Gap, Impact, VirtualBall
from .sources import RacketSource


@dataclass(frozen=True)
class Schedule:
    """alpha of each impact: ``alpha`` except at impacts ``first, first + every, ...`` (every
    > 0), where it is drawn uniformly from one of ``ranges`` (each chosen with equal
    probability) from the trial's own random stream."""

    alpha: float
    every: int
    first: int
    ranges: tuple[tuple[float, float], ...]

    def alpha_at(self, k: int, rng: np.random.Generator) -> tuple[float, bool]:
        """(alpha, perturbed) of impact k; called once per impact in impact order, so that
        the draws (and so the trial) do not depend on how fast the samples come."""
        if self.every and k >= self.first and (k - self.first) % self.every == 0:
            lo, hi = self.ranges[int(rng.integers(len(self.ranges)))]
            return float(rng.uniform(lo, hi)), True
        return self.alpha, False


@dataclass(frozen=True)
class Launch:
    """How each trial's ball starts: from the racket at time ``t_s`` with ``v_m_s`` (None:
    the racket's velocity), or dropped at rest from ``height_m`` at t = 0."""

    t_s: float | None
    v_m_s: float | None
    height_m: float | None


@dataclass(frozen=True)
class TrialRecord:
    """What one trial recorded: the samples (t, racket, ball), the impacts, the stream's
    gaps."""

    t: np.ndarray
    racket: np.ndarray
    ball: np.ndarray
    impacts: tuple[Impact, ...]
    gaps: tuple[Gap, ...]


def run_trial(source: RacketSource, trial: int, duration_s: float, g: float,
              schedule: Schedule, launch: Launch, rng: np.random.Generator, *,
              min_hop_s: float, min_relative_velocity_m_s: float, max_gap_s: float,
              racket_gain: float = 1.0,
              on_sample: Callable[[float, float, float, list[Impact]], None] | None = None,
              ) -> TrialRecord:
    """One trial, headless: every racket sample of the source pushed to the ball in order (as
    fast as the source gives them: at once for ``sine`` and ``replay``, live for a stream).
    The ball asks for each impact's alpha once, in impact order. A source with an
    ``observe(impact)`` method (a simulated subject) is shown each impact as soon as the sample
    that found it is pushed, before it gives the next sample. ``racket_gain``: the virtual
    racket moves that many times the source's (a visual gain; the ball meets, and the record
    holds, the virtual racket). ``on_sample(t, racket, ball, new_impacts)`` is called after
    each sample (the screen)."""
    ball = VirtualBall(g=g, alpha_of=lambda k: schedule.alpha_at(k, rng), min_hop_s=min_hop_s,
                       min_relative_velocity_m_s=min_relative_velocity_m_s,
                       max_gap_s=max_gap_s)
    if launch.height_m is not None:
        ball.drop(0.0, launch.height_m)
    else:
        ball.launch_from_racket(0.0 if launch.t_s is None else launch.t_s, launch.v_m_s)
    observe = getattr(source, "observe", None)  # a closed-loop source sees each impact
    ts, xs, bs = [], [], []
    for t, x in source.samples(trial, duration_s):
        x = racket_gain * x
        new, b = ball.push(t, x)
        if on_sample is not None:
            on_sample(t, x, b, new)
        if observe is not None:
            for impact in new:
                observe(impact)
        ts.append(t)
        xs.append(x)
        bs.append(b)
    return TrialRecord(np.asarray(ts), np.asarray(xs), np.asarray(bs), tuple(ball.impacts),
                       tuple(ball.gaps))



class Paced:
    """A source without a clock of its own (sine, replay, a simulated subject) given out in
    real time: sample (t, x) of a trial not before t s after the trial's first sample was
    asked for. Everything else (``description``, a closed loop's ``observe``) is the
    source's."""

    live = True

    def __init__(self, source: RacketSource):
        self.source = source

    def __getattr__(self, name: str):
        return getattr(self.source, name)

    def samples(self, trial: int, duration_s: float) -> Iterator[tuple[float, float]]:
        t0 = time.perf_counter()
        for t, x in self.source.samples(trial, duration_s):
            wait = t0 + t - time.perf_counter()
            if wait > 0.0:
                time.sleep(wait)
            yield t, x
