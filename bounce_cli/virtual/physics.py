"""The virtual ball: the model's ball (eqs. 1-3) against a racket known only by its samples.

The racket between two samples ``t[n-1] < t <= t[n]`` is the cubic through the four latest
samples ``n-3 .. n`` (fewer at a trial's start): causal, so that an impact inside an interval is
known as soon as the sample that ends it arrives. Its error is O(h^4) in position and O(h^3)
in velocity for a smooth racket sampled every h: on the Fig. 4 racket (a_r = 0.3 m,
tau = 0.92 s) sampled at 1 kHz about 3e-11 m and 2e-7 m/s, at 100 Hz 1000 times that (tested
in ``tests/virtual/test_physics.py``).

Between impacts the ball flies its parabola exactly (eq. 1). An impact is the first time at
which the gap (ball minus racket, a cubic in time on each interval) falls to zero while the
ball approaches the racket: the interval is cut at the gap's critical points into monotone
pieces and the first piece whose gap goes from above zero to below it holds the root
(``brentq``), so a graze inside one interval is never missed and a later root is never taken
for the first. The velocity after impact is eq. 3 (eq. 2 of the racket's velocity, here the
cubic's derivative): ``v+ = v_r - alpha (v- - v_r)``.

Sticking (section 3): an impact after a hop shorter than ``min_hop_s``, or leaving the racket
slower than ``min_relative_velocity_m_s``, puts the ball on the racket; it rides there until the
racket's acceleration (the cubic's second derivative) falls below -g, and leaves with the
racket's velocity.

A sample that puts the racket above the ball (after a stream's gap, or a racket moved faster
than the samples resolve) is an impact at that sample's interval start: the ball never passes
through the racket. Longer gaps than ``max_gap_s`` are not bridged by the cubic: the ball's
clock stops until samples arrive again (``Gap`` records, the trial keeps running).

Times in s, positions in m (the racket's and the ball's heights), velocities in m/s.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy.optimize import brentq

from ..model.flight import impact_velocity
from ..model.params import ModelError

#: gap (m) within which the ball counts as on the racket: far below any racket's resolution,
#: far above the rounding of a cubic's value (so no decision hinges on a last bit)
AT_RACKET_M = 1e-12

#: samples in the racket's interpolant
STENCIL = 4

#: the RMS over an interval of the cubic's derivative weights on its 4 samples (nodes -3..0 in
#: sample steps, the impact anywhere in the last interval): white position noise sigma in the
#: samples every h gives the racket's velocity at an impact a noise of this times sigma / h
CUBIC_VELOCITY_NOISE_GAIN = 1.945


def racket_velocity_noise_m_s(position_noise_m: float, sample_interval_s: float) -> float:
    """The SD of the racket's velocity at an impact (m/s) that white noise of SD
    ``position_noise_m`` in its samples every ``sample_interval_s`` gives through the cubic
    (``CUBIC_VELOCITY_NOISE_GAIN``); eq. 3 passes (1 + alpha) times it to the ball."""
    return CUBIC_VELOCITY_NOISE_GAIN * position_noise_m / sample_interval_s


@dataclass(frozen=True)
class Impact:
    """One impact: its index in the trial, time, the ball's velocity before and after (eq. 3),
    the racket's position, velocity and acceleration there, alpha applied, and whether alpha
    was perturbed."""

    k: int
    t_s: float
    v_in_m_s: float
    v_m_s: float
    racket_x_m: float
    racket_v_m_s: float
    racket_acc_m_s2: float
    alpha: float
    perturbed: bool
    hop_s: float  # since the previous impact (NaN for a trial's first)
    stuck: bool  # the ball stayed on the racket after it


@dataclass(frozen=True)
class Gap:
    """A stretch without racket samples longer than ``max_gap_s``: the ball's clock stopped."""

    t_start_s: float
    t_end_s: float


@dataclass(frozen=True)
class _Flight:
    """A free flight (eq. 1) from height x0 with velocity v0 at time t0."""

    t0: float
    x0: float
    v0: float


#: the inverse Vandermonde matrices of evenly spaced stencils (s = -2, -1, 0, 1 and shorter):
#: a racket sampled at a steady rate needs no linear solve per sample
_EVEN_INVERSE = {n: np.linalg.inv(np.vander(np.arange(2 - n, 2.0), n, increasing=True))
                 for n in range(2, STENCIL + 1)}


def _horner(coef, s: float) -> float:
    value = 0.0
    for c in reversed(coef):
        value = value * s + c
    return value


class RacketInterval:
    """The racket on ``[t_a, t_b]`` (the two latest samples) as a polynomial in
    ``s = (t - t_a) / h`` through the latest samples (``coef``: increasing powers)."""

    def __init__(self, times, positions):
        self.t_a, self.t_b = float(times[-2]), float(times[-1])
        self.h = self.t_b - self.t_a
        n = len(times)
        s = [(ti - self.t_a) / self.h for ti in times]
        if all(abs(si - (i + 2 - n)) < 1e-9 for i, si in enumerate(s)):
            self.coef = list(_EVEN_INVERSE[n] @ np.asarray(positions, dtype=float))
        else:  # jittered or gapped sampling: the exact interpolant through these samples
            self.coef = list(np.linalg.solve(np.vander(np.asarray(s), n, increasing=True),
                                             np.asarray(positions, dtype=float)))

    def derivative(self, order: int) -> list[float]:
        """The coefficients (in s) of the racket's derivative of that order in t."""
        coef = list(self.coef)
        for _ in range(order):
            coef = [i * c / self.h for i, c in enumerate(coef)][1:] or [0.0]
        return coef

    def s_of(self, t: float) -> float:
        return (t - self.t_a) / self.h

    def position(self, t: float) -> float:
        return _horner(self.coef, self.s_of(t))

    def velocity(self, t: float) -> float:
        return _horner(self.derivative(1), self.s_of(t))

    def acceleration(self, t: float) -> float:
        return _horner(self.derivative(2), self.s_of(t))


@dataclass
class VirtualBall:
    """The ball of one trial. Feed racket samples in time order with :meth:`push`; each
    returns the impacts that sample resolved. ``alpha_of(k)`` gives (alpha, perturbed) of the
    k-th impact (the protocol's schedule)."""

    g: float
    alpha_of: Callable[[int], tuple[float, bool]]
    min_hop_s: float = 0.01
    min_relative_velocity_m_s: float = 1e-3
    max_gap_s: float = 0.05
    impacts: list[Impact] = field(default_factory=list)
    gaps: list[Gap] = field(default_factory=list)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.g) and self.g > 0.0):
            raise ModelError(f"g must be a finite number > 0 (got {self.g!r})")
        self._samples: deque[tuple[float, float]] = deque(maxlen=STENCIL)
        self._flight: _Flight | None = None
        self._stuck = False
        self._pending_launch: tuple[float, float | None] | None = None
        self._last_impact_t = math.nan

    # -- starting ------------------------------------------------------------------------
    def launch_from_racket(self, t: float, v: float | None) -> None:
        """The ball leaves the racket at time t with velocity v (None: the racket's), in the
        first sample interval that holds t (t before the first sample: at its start)."""
        self._pending_launch = (t, v)

    def drop(self, t: float, height_m: float) -> None:
        """The ball is released at rest at time t, ``height_m`` high."""
        self._flight = _Flight(t, height_m, 0.0)

    # -- the ball's height at a sample time (what the display and the recording show) ----
    def ball_position(self, t: float, racket: RacketInterval | None) -> float:
        f = self._flight
        if f is not None:
            d = t - f.t0
            return f.x0 + f.v0 * d - 0.5 * self.g * d * d
        if self._stuck and racket is not None:
            return racket.position(t)
        if self._samples:
            return self._samples[-1][1]
        return math.nan

    # -- one sample ----------------------------------------------------------------------
    def push(self, t: float, x: float) -> tuple[list[Impact], float]:
        """Take the racket sample (t, x): the impacts it resolved, and the ball's height at t."""
        if not (math.isfinite(t) and math.isfinite(x)):
            raise ModelError(f"a racket sample must be finite (got t = {t!r}, x = {x!r})")
        if self._samples and t <= self._samples[-1][0]:
            raise ModelError(f"racket samples must come in increasing time (got {t!r} after "
                             f"{self._samples[-1][0]!r})")
        new: list[Impact] = []
        if self._samples and t - self._samples[-1][0] > self.max_gap_s:
            self._stop_clock(t)
        self._samples.append((t, x))
        if len(self._samples) < 2:
            return new, self.ball_position(t, None)
        times, positions = zip(*self._samples)
        racket = RacketInterval(times, positions)
        self._advance(racket, new)
        return new, self.ball_position(t, racket)

    def _stop_clock(self, t: float) -> None:
        """A stream's gap: the ball waits (its flight and last impact shifted by the gap, so it
        goes on from where it was) and the interpolant starts afresh from the next samples."""
        t_last = self._samples[-1][0]
        shift = t - t_last
        self.gaps.append(Gap(t_last, t))
        if self._flight is not None:
            self._flight = _Flight(self._flight.t0 + shift, self._flight.x0, self._flight.v0)
        self._last_impact_t += shift
        self._samples.clear()

    def _advance(self, racket: RacketInterval, new: list[Impact]) -> None:
        t_lo = racket.t_a
        if self._pending_launch is not None:
            t_launch, v = self._pending_launch
            if t_launch > racket.t_b:
                return
            t_launch = max(t_launch, racket.t_a)
            self._pending_launch = None
            self._flight = _Flight(t_launch, racket.position(t_launch),
                                   racket.velocity(t_launch) if v is None else v)
            t_lo = t_launch
        while t_lo < racket.t_b:
            if self._stuck:
                t_leave = self._leave_time(racket, t_lo)
                if t_leave is None:
                    return
                self._stuck = False
                self._flight = _Flight(t_leave, racket.position(t_leave),
                                       racket.velocity(t_leave))
                t_lo = t_leave
                continue
            if self._flight is None:
                return
            t_hit = self._first_contact(racket, self._flight, t_lo)
            if t_hit is None:
                return
            new.append(self._impact(racket, self._flight, t_hit))
            t_lo = t_hit

    def _gap_coefficients(self, racket: RacketInterval, f: _Flight) -> list[float]:
        """The gap ball - racket as a cubic in s on the interval (increasing powers)."""
        h, d0 = racket.h, racket.t_a - f.t0
        gap = [f.x0 + f.v0 * d0 - 0.5 * self.g * d0 * d0, h * (f.v0 - self.g * d0),
               -0.5 * self.g * h * h, 0.0]
        for i, c in enumerate(racket.coef):
            gap[i] -= c
        return gap

    def _first_contact(self, racket: RacketInterval, f: _Flight, t_lo: float) -> float | None:
        """The first time in [t_lo, t_b] at which the ball reaches the racket, or None."""
        P = np.polynomial.polynomial
        gap = self._gap_coefficients(racket, f)
        s_lo = racket.s_of(t_lo)
        if gap[0] - abs(gap[1]) - abs(gap[2]) - abs(gap[3]) > AT_RACKET_M:
            return None  # the ball is above the racket over the whole interval
        roots: list[complex] = (list(np.atleast_1d(P.polyroots(P.polyder(gap))))
                                if any(gap[2:]) else [])
        cuts = [s_lo, *sorted(float(r.real) for r in roots
                              if abs(r.imag) <= 1e-12 * max(1.0, abs(r.real))
                              and s_lo < r.real < 1.0), 1.0]
        values = [float(P.polyval(s, gap)) for s in cuts]
        if values[0] < -AT_RACKET_M and t_lo != f.t0:
            return t_lo  # the racket came up past the ball between two samples
        # monotone pieces: the first whose end is below the racket holds the crossing
        for i in range(1, len(cuts)):
            if values[i] < -AT_RACKET_M:
                if values[i - 1] <= 0.0:
                    return racket.t_a + cuts[i - 1] * racket.h
                s = brentq(lambda s: float(P.polyval(s, gap)), cuts[i - 1], cuts[i],
                           xtol=1e-15, rtol=4 * np.finfo(float).eps)
                return racket.t_a + s * racket.h
        return None

    def _impact(self, racket: RacketInterval, f: _Flight, t_hit: float) -> Impact:
        k = len(self.impacts)
        alpha, perturbed = self.alpha_of(k)
        v_in = f.v0 - self.g * (t_hit - f.t0)
        x_r, v_r, a_r = racket.position(t_hit), racket.velocity(t_hit), racket.acceleration(t_hit)
        v_out = impact_velocity(v_in, v_r, alpha)
        hop = t_hit - self._last_impact_t if math.isfinite(self._last_impact_t) else math.nan
        stuck = ((math.isfinite(hop) and hop < self.min_hop_s)
                 or v_out - v_r <= self.min_relative_velocity_m_s)
        impact = Impact(k, t_hit, v_in, v_out, x_r, v_r, a_r, alpha,
                        perturbed, hop, stuck)
        self.impacts.append(impact)
        self._last_impact_t = t_hit
        if stuck:
            self._stuck, self._flight = True, None
        else:
            self._flight = _Flight(t_hit, x_r, v_out)
        return impact

    def _leave_time(self, racket: RacketInterval, t_lo: float) -> float | None:
        """First time in [t_lo, t_b] at which the racket's acceleration is at most -g (it
        outruns gravity, section 3): the ball riding on it leaves there; None if not here."""
        P = np.polynomial.polynomial
        excess = (racket.derivative(2) + [0.0])[:2]
        excess[0] += self.g  # the ball leaves where racket acceleration + g <= 0
        s_lo = racket.s_of(t_lo)
        if float(P.polyval(s_lo, excess)) <= 0.0:
            return t_lo
        if float(P.polyval(1.0, excess)) > 0.0:
            return None
        s = brentq(lambda s: float(P.polyval(s, excess)), s_lo, 1.0, xtol=1e-15)
        return racket.t_a + s * racket.h
