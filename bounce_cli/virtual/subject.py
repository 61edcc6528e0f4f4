"""A simulated subject for the virtual set-up: the model's racket with period control.

The racket is the sine of eq. 4, ``x_r = a_r sin(phi)``, whose phase ``phi`` advances at
``2 pi / tau`` with a period ``tau`` that the subject sets impact by impact from the ball it
sees: the racket period as a third state, the control that section 7 infers from Fig. 11 ("the
racket period is increased or decreased at the first and second impact in response to the
perturbation") and sections 7-8 leave for future study. The controller is the one of
``bounce control`` (``bounce_cli.model.control.PeriodController``, after de Rugy et al.
2003, defaults from ``configs/control.yaml``):

    tau_{k+1} = tau_k + c (tau_bar + K 2 (v_k - v~) / g - tau_k),   v~ = pi g / w_bar (eq. 7),

with v_k the ball's velocity just after impact k (the error signal ``v_k - v~``), gain K and
rate c. ``switch`` says when the new period starts, as in the controlled map: ``"impact"``
(the flight after impact k runs at tau_{k+1}) or ``"cycle"`` (at the racket's next upward
mid-position crossing). The phase stays continuous, so the racket's position never jumps;
its velocity changes with the frequency (by ``a_r (w_{k+1} - w_k) cos(phi)``).

The subject is causal: it learns of an impact from ``run_trial``'s ``observe(impact)``, right
after the racket sample whose interval held it, and the samples already given are not taken
back. With ``switch = "impact"`` the new period therefore starts at that sample (at most one
sample interval after the impact, 1 ms at 1 kHz), not at the impact itself as in the map.
Impacts that leave the ball on the racket (``stuck``) do not change the period: the map has
no flight after them (section 3's sticking ends an orbit).

With K = 0 (or with a ball exactly at v~) the period stays tau_bar bit for bit and the samples
are those of :class:`bounce_cli.virtual.sources.SineSource`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterator, Literal

import numpy as np

from ..model.control import PeriodController, RacketClock, Reference
from ..model.params import ModelError, ModelParams
from .physics import Impact

TWO_PI = 2.0 * math.pi

#: the controller of ``bounce control`` (``configs/control.yaml``'s ``model.control``)
DEFAULT_GAIN = 0.7
DEFAULT_RATE = 1.0
DEFAULT_SWITCH: Literal["impact", "cycle"] = "impact"


@dataclass(frozen=True)
class SubjectControl:
    """The simulated subject's period controller and the world it regulates in.

    Parameters
    ----------
    gain : float
        K of the period controller (dimensionless; 1 = the period follows the change of the
        ball's flight time in full, 0 = no control: the ``sine`` racket).
    rate : float
        c, per impact (1 = immediate adaptation, 0 = the period never changes).
    switch : {"impact", "cycle"}
        When a new period starts: at the impact (at the sample that reported it) or at the
        racket's next upward mid-position crossing.
    g : float
        Gravity the subject expects, m/s^2 (the screen's g): the flight-time error
        ``2 (v_k - v~) / g`` and v~ = pi g / w_bar (eq. 7).
    alpha : float
        alpha_0 of the steady state, for the reference's theta~ (eq. 8; the period controller
        does not use it).
    """

    gain: float = DEFAULT_GAIN
    rate: float = DEFAULT_RATE
    switch: Literal["impact", "cycle"] = DEFAULT_SWITCH
    g: float = 9.81
    alpha: float = 0.5


#: ``bounce control``'s controller in the paper's section 7 world (g 9.81 m/s^2, alpha_0 0.5)
NOMINAL_SUBJECT = SubjectControl()


@dataclass(frozen=True)
class PeriodUpdate:
    """One period the subject set: after impact ``k`` at ``t_impact_s`` it asked for
    ``period_s``, which starts at ``t_start_s`` (NaN: not started yet, or replaced by the next
    impact's before the crossing it waited for)."""

    k: int
    t_impact_s: float
    period_s: float
    t_start_s: float


class SubjectSource:
    """A simulated subject's racket (``--racket subject``): eq. 4 with a period controlled
    impact by impact (section 7's Fig. 11; the controlled map of ``bounce control``).

    Parameters
    ----------
    amplitude_m : float
        a_r, m (eq. 4).
    period_s : float
        tau_bar, the nominal period and the controller's set point, s.
    rate_hz : float
        Samples per second, every ``1 / rate_hz`` s from t = 0 as ``SineSource``.
    control : SubjectControl
        The controller (default: ``bounce control``'s, K = 0.7, c = 1, switch at impact).

    Notes
    -----
    The racket of a trial is a chain of segments ``phi(t) = phi_i + w_i (t - t_i)`` (a
    :class:`bounce_cli.model.control.RacketClock`), the first ``(0, 0, 2 pi / tau_bar)``: each
    trial starts on the nominal racket. :meth:`observe` takes each impact (``run_trial`` calls
    it before asking for the next sample) and sets the next period with
    ``PeriodController.next_period`` (the v_k error of eqs. 5-7's controlled map); a period
    equal to the running one starts no segment, so with K = 0 the samples are
    ``a_r sin(w_bar t)`` exactly as ``SineSource`` computes them.
    """

    def __init__(self, amplitude_m: float, period_s: float, rate_hz: float,
                 control: SubjectControl = NOMINAL_SUBJECT):
        if control.switch not in ("impact", "cycle"):
            raise ModelError(f"subject: switch must be impact or cycle (got {control.switch!r})")
        self.amplitude_m, self.period_s, self.rate_hz = amplitude_m, period_s, rate_hz
        self.control = control
        self.controller = PeriodController(control.gain, control.rate, switch=control.switch)
        self.reference = Reference.of(ModelParams(control.alpha, control.g, amplitude_m,
                                                  period_s))
        self._reset()

    @property
    def description(self) -> str:
        c = self.control
        return (f"subject: a_r = {self.amplitude_m:g} m, tau_bar = {self.period_s:g} s, period "
                f"control K = {c.gain:g}, c = {c.rate:g} (new period at the {c.switch}), "
                f"sampled at {self.rate_hz:g} Hz")

    # -- the racket's phase ------------------------------------------------------------------
    def _reset(self) -> None:
        self._starts = [0.0]
        self._phases = [0.0]
        self._omegas = [TWO_PI / self.period_s]  # as SineSource's w, bit for bit
        self._periods = [self.period_s]  # the controller's state tau (not 2 pi / omega)
        self._pending: tuple[float, float] | None = None  # (period, crossing phase): "cycle"
        self._t_last = 0.0
        self.updates: list[PeriodUpdate] = []

    def _phase(self, t: float) -> float:
        """phi(t) on the latest segment (t not before its start)."""
        return self._phases[-1] + self._omegas[-1] * (t - self._starts[-1])

    def _phase_at(self, t: float) -> float:
        """phi(t) on the segment that ran at t (an impact may precede the latest start)."""
        i = len(self._starts) - 1
        while i > 0 and self._starts[i] > t:
            i -= 1
        return self._phases[i] + self._omegas[i] * (t - self._starts[i])

    def _start_segment(self, t: float, phase: float, period: float) -> None:
        self._starts.append(t)
        self._phases.append(phase)
        self._omegas.append(TWO_PI / period)
        self._periods.append(period)

    @property
    def clock(self) -> RacketClock:
        """The racket's phase in time in the current (or last) trial."""
        return RacketClock(np.array(self._starts), np.array(self._phases),
                           np.array(self._omegas))

    @property
    def period_now_s(self) -> float:
        """The period the racket runs with after the latest sample, s."""
        return self._periods[-1]

    # -- the protocol ------------------------------------------------------------------------
    def samples(self, trial: int, duration_s: float) -> Iterator[tuple[float, float]]:
        """Samples ``(t, a_r sin(phi(t)))`` at ``t = i / rate_hz``, i = 0 .. floor(duration_s *
        rate_hz), from the nominal racket at t = 0 (each trial anew)."""
        self._reset()
        n = int(math.floor(duration_s * self.rate_hz)) + 1
        for i in range(n):
            t = i / self.rate_hz
            if self._pending is not None and self._phase(t) >= self._pending[1]:
                self._cross(*self._pending)
            self._t_last = t
            yield t, self.amplitude_m * math.sin(self._phase(t))

    def _cross(self, period: float, crossing: float) -> None:
        """The new period starts at the upward mid-position crossing (phase ``crossing``)."""
        t_cross = self._starts[-1] + (crossing - self._phases[-1]) / self._omegas[-1]
        self._start_segment(t_cross, crossing, period)
        self._pending = None
        last = self.updates[-1]
        self.updates[-1] = PeriodUpdate(last.k, last.t_impact_s, last.period_s, t_cross)

    def observe(self, impact: Impact) -> None:
        """Set the next period from ``impact`` (``run_trial`` calls it once per impact, after
        the sample that found it).

        Parameters
        ----------
        impact : bounce_cli.virtual.physics.Impact
            Its ``v_m_s`` (velocity after impact, eq. 3) is the controller's v_k; a ``stuck``
            impact changes nothing.

        Raises
        ------
        ModelError
            The controller asks for a period that is not > 0 (no racket has one).
        """
        if impact.stuck:
            return
        tau = self.period_now_s
        theta = self._phase_at(impact.t_s)
        tau_next = float(self.controller.next_period(impact.v_m_s, theta, tau, self.reference))
        if not (math.isfinite(tau_next) and tau_next > 0.0):
            raise ModelError(f"subject: the period controller asks for a racket period of "
                             f"{tau_next!r} s after the impact at t = {impact.t_s:.4g} s")
        self._pending = None  # a crossing still awaited: the new impact's period replaces it
        if tau_next == tau:  # K = 0, or v_k = v~ exactly: the racket goes on as it is
            self.updates.append(PeriodUpdate(impact.k, impact.t_s, tau_next, math.nan))
            return
        if self.control.switch == "impact":
            t = self._t_last  # the sample that reported the impact: already given
            self._start_segment(t, self._phase(t), tau_next)
            self.updates.append(PeriodUpdate(impact.k, impact.t_s, tau_next, t))
        else:  # at the next upward mid-position crossing after the latest sample
            crossing = TWO_PI * (math.floor(self._phase(self._t_last) / TWO_PI) + 1.0)
            self._pending = (tau_next, crossing)
            self.updates.append(PeriodUpdate(impact.k, impact.t_s, tau_next, math.nan))
