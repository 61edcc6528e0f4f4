"""Model parameters of the ball bouncing map and the period-1 fixed point (eqs. 4, 7, 8).

Units are SI throughout: ``g`` in m/s^2, ``racket_amplitude`` (a_r) in m, ``racket_period``
(tau = 2 pi / omega_r) in s. Phases are in radians, ``theta = omega_r t`` (section 2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import ModelError, NoFixedPointError

#: the largest power of ten a term of eq. 8 (omega_r, omega_r^2 a_r, v~, a_r omega_r^2 / g) may
#: reach, either way: beyond it the map's products (squares of velocities, the Jacobian of
#: eq. 9) overflow or underflow to inf, 0 or NaN; physical values are within 1e+-6
MAX_TERM_EXPONENT = 100

#: section 3's sticking threshold: a hop (time between two impacts) shorter than this, s, is
#: sticking (grey in Fig. 4); the default of every ``min_hop_s`` on the map's side
MIN_HOP_S = 1e-3


# -- eq. 8 and the quantities built on it: each defined here once -----------------------------
def eq8_cos_theta(alpha, g, racket_amplitude, omega):
    """The right-hand side of eq. 8: cos(theta~) of the period-1 fixed point.

    ``cos theta~ = pi (1 - alpha)/(1 + alpha) g / (omega_r^2 a_r)`` (eq. 8); the orbit exists
    where it is <= 1. With ``racket_amplitude = 1`` it is :func:`eq8_amplitude` at theta = 0.

    Parameters
    ----------
    alpha : float or array_like
        Coefficient of restitution.
    g : float or array_like
        Gravitational acceleration, m/s^2.
    racket_amplitude : float or array_like
        a_r, m.
    omega : float or array_like
        omega_r = 2 pi / tau, rad/s.

    Returns
    -------
    float or numpy.ndarray
        cos(theta~), the inputs' broadcast shape.

    Examples
    --------
    At the parameters of Figs. 3 and 9 (alpha 0.5, a_r 0.30 m, tau 0.92 s), theta~ = 42.76 deg:

    >>> round(eq8_cos_theta(0.5, 9.81, 0.30, 2 * math.pi / 0.92), 4)
    0.7342
    """
    return math.pi * (1.0 - alpha) / (1.0 + alpha) * g / (omega**2 * racket_amplitude)


def eq8_amplitude(alpha, g, omega, theta_rad):
    """Eq. 8 solved for the racket amplitude: the a_r (m) whose period-1 orbit hits at phase
    ``theta_rad``, ``a_r = pi (1 - alpha)/(1 + alpha) g / (omega_r^2 cos theta)``.

    Eq. 15 is this with omega_r = 2 pi / tau, a line in tau^2 (``analysis.regression``);
    at theta = 0 it is the smallest amplitude with a fixed point.

    Parameters
    ----------
    alpha, g, omega : float or array_like
        As in :func:`eq8_cos_theta`.
    theta_rad : float or array_like
        The impact phase, rad.

    Returns
    -------
    float or numpy.ndarray
        a_r, m (negative or infinite where cos theta <= 0).
    """
    cos = math.cos(theta_rad) if isinstance(theta_rad, (float, int)) else np.cos(theta_rad)
    return eq8_cos_theta(alpha, g, 1.0, omega) / cos


def eq8_alpha(g, racket_amplitude, omega, theta_rad: float) -> float:
    """Eq. 8 solved for the coefficient of restitution: ``(1 - alpha)/(1 + alpha) = r`` with
    ``r = cos(theta) omega_r^2 a_r / (pi g)``, so ``alpha = (1 - r)/(1 + r)``.

    Parameters
    ----------
    g, racket_amplitude, omega : float
        As in :func:`eq8_cos_theta`.
    theta_rad : float
        The observed impact phase, rad.

    Returns
    -------
    float
        alpha; NaN where the phase is outside (-90, 90) deg (r <= 0).
    """
    r = math.cos(theta_rad) * omega**2 * racket_amplitude / (math.pi * g)
    return (1.0 - r) / (1.0 + r) if r > 0 else math.nan


def gamma(racket_amplitude, omega, g):
    """Gamma = a_r omega_r^2 / g: the racket's peak acceleration in units of g.

    The parameter the bifurcation diagram and the continuation sweep; the ball resting on
    the racket is released where sin(theta) = 1 / Gamma (``model.chatter``).

    Parameters
    ----------
    racket_amplitude, omega, g : float or array_like
        a_r (m), omega_r (rad/s), g (m/s^2).

    Returns
    -------
    float or numpy.ndarray
    """
    return racket_amplitude * omega**2 / g


def racket_acceleration_g(racket_amplitude, omega, g, phase):
    """The racket's acceleration at ``phase`` in units of g: ``-a_r omega_r^2 sin(theta) / g``
    (eq. 4 differentiated twice); at the fixed point's phase it is section 4's AC, negative on
    the stable branch (``model.linear.racket_acceleration_at_impact_g``).

    Parameters
    ----------
    racket_amplitude, omega, g : float or array_like
        a_r (m), omega_r (rad/s), g (m/s^2).
    phase : float or array_like
        theta = omega_r t, rad (a Python float takes ``math.sin``, an array ``numpy.sin``).

    Returns
    -------
    float or numpy.ndarray
    """
    sin = math.sin(phase) if isinstance(phase, float) else np.sin(phase)
    return -racket_amplitude * omega**2 * sin / g


@dataclass(frozen=True)
class FixedPoint:
    """The period-1 fixed point (v~, theta~) of eqs. 7 and 8.

    ``theta_rad`` is the stable branch ``+arccos(...)`` in (0, pi/2], where the racket
    decelerates at impact.
    """

    v_m_s: float
    theta_rad: float

    @property
    def theta_deg(self) -> float:
        return math.degrees(self.theta_rad)


@dataclass(frozen=True)
class ModelParams:
    """Parameters of the sinusoidally driven racket (eq. 4) and the impact law (eq. 3).

    alpha: coefficient of restitution, 0 <= alpha < 1.
    g: gravitational acceleration in m/s^2, > 0.
    racket_amplitude: a_r in m, > 0.
    racket_period: tau in s, > 0; omega_r = 2 pi / tau.
    """

    alpha: float
    g: float
    racket_amplitude: float
    racket_period: float

    def __post_init__(self) -> None:
        checks = (
            ("alpha", 0.0 <= self.alpha < 1.0, "must satisfy 0 <= alpha < 1"),
            ("g", self.g > 0.0, "must be > 0"),
            ("racket_amplitude", self.racket_amplitude > 0.0, "must be > 0"),
            ("racket_period", self.racket_period > 0.0, "must be > 0"),
        )
        for name, ok, reason in checks:
            value = getattr(self, name)
            if not (ok and math.isfinite(value)):
                raise ModelError(f"{name} {reason} (got {value!r})")
        self._check_terms()

    def _check_terms(self) -> None:
        """Eq. 8's terms, as powers of ten (no overflow on the way): each within
        +-:data:`MAX_TERM_EXPONENT`, else one ModelError naming the parameters."""
        log_omega = math.log10(2.0 * math.pi) - math.log10(self.racket_period)
        log_acceleration = 2.0 * log_omega + math.log10(self.racket_amplitude)
        terms = (
            ("omega_r = 2 pi / racket_period", " rad/s", log_omega),
            ("omega_r^2 a_r", " m/s^2", log_acceleration),
            ("v~ = pi g / omega_r (eq. 7)", " m/s",
             math.log10(math.pi) + math.log10(self.g) - log_omega),
            ("a_r omega_r^2 / g", "", log_acceleration - math.log10(self.g)),
        )
        for term, unit, exponent in terms:
            if abs(exponent) > MAX_TERM_EXPONENT:
                raise ModelError(
                    f"model parameters out of range: g = {self.g:.3g} m/s^2, racket_amplitude = "
                    f"{self.racket_amplitude:.3g} m, racket_period = {self.racket_period:.3g} s "
                    f"make {term} about 1e{exponent:+.0f}{unit}, beyond the 1e+-"
                    f"{MAX_TERM_EXPONENT} within which eq. 8 is evaluated without overflow; "
                    "give model.g, model.racket_amplitude and model.racket_period in SI units "
                    "(m/s^2, m, s)")

    # -- racket motion (eq. 4) ---------------------------------------------------------
    @property
    def omega(self) -> float:
        """Racket angular frequency omega_r = 2 pi / tau in rad/s."""
        return 2.0 * math.pi / self.racket_period

    def racket_position(self, phase):
        """x_r = a_r sin(theta), eq. 4, with theta = omega_r t."""
        return self.racket_amplitude * np.sin(phase)

    def racket_velocity(self, phase):
        """v_r = a_r omega_r cos(theta)."""
        return self.racket_amplitude * self.omega * np.cos(phase)

    def racket_acceleration(self, phase):
        """Racket acceleration -a_r omega_r^2 sin(theta) in m/s^2."""
        return -self.racket_amplitude * self.omega**2 * np.sin(phase)

    # -- fixed point (eqs. 7, 8) -----------------------------------------------------------
    def cos_theta_fixed(self) -> float:
        """Right-hand side of eq. 8 at these parameters (:func:`eq8_cos_theta`)."""
        return eq8_cos_theta(self.alpha, self.g, self.racket_amplitude, self.omega)

    def min_racket_amplitude(self) -> float:
        """Smallest a_r for which eq. 8 has a solution (cos theta~ = 1), in m
        (:func:`eq8_amplitude` at theta = 0)."""
        return eq8_amplitude(self.alpha, self.g, self.omega, 0.0)

    @property
    def gamma(self) -> float:
        """Gamma = a_r w^2 / g (:func:`gamma`)."""
        return gamma(self.racket_amplitude, self.omega, self.g)

    def racket_acceleration_g(self, phase):
        """The racket's acceleration at ``phase`` in units of g (:func:`racket_acceleration_g`)."""
        return racket_acceleration_g(self.racket_amplitude, self.omega, self.g, phase)

    def fixed_point(self) -> FixedPoint:
        """Period-1 fixed point: v~ = pi g / omega_r (eq. 7), theta~ = arccos(eq. 8).

        Raises NoFixedPointError when |cos theta~| > 1.
        """
        cos_theta = self.cos_theta_fixed()
        if cos_theta > 1.0:
            raise NoFixedPointError(
                f"no period-1 fixed point: eq. 8 gives cos(theta~) = {cos_theta:.4g} > 1; "
                f"the racket amplitude (model.racket_amplitude) must be >= "
                f"{self.min_racket_amplitude():.4g} m "
                f"at alpha={self.alpha:g}, g={self.g:g}, racket_period={self.racket_period:g}"
            )
        return FixedPoint(v_m_s=math.pi * self.g / self.omega, theta_rad=math.acos(cos_theta))

    def with_alpha(self, alpha: float) -> "ModelParams":
        return ModelParams(alpha, self.g, self.racket_amplitude, self.racket_period)


def wrap_phase(theta):
    """Phase wrapped to [0, 2 pi)."""
    return np.mod(theta, 2.0 * np.pi)


def phase_difference(theta, reference):
    """theta - reference wrapped to [-pi, pi): compares a wrapped or unwrapped phase with a
    reference without the 2 pi ambiguity."""
    return np.mod(np.asarray(theta) - reference + np.pi, 2.0 * np.pi) - np.pi


def circular_mean(theta_rad) -> float:
    """The mean of phases: the angle of the mean unit vector exp(i theta), in [0, 2 pi).

    Unlike the arithmetic mean it does not depend on where the phases were wrapped (impacts
    at 359 deg and 1 deg average to 0 deg, not 180 deg); deviations from it are taken with
    :func:`phase_difference`. A mean a rounding error below 0 is 0, not 2 pi (``np.mod``
    of -1e-17 is 2 pi exactly).

    Parameters
    ----------
    theta_rad : array_like
        Phases, rad (wrapped or not).

    Returns
    -------
    float
        The mean phase, rad, in [0, 2 pi); NaN for no phases.

    Examples
    --------
    >>> round(math.degrees(circular_mean(np.radians([359.0, 1.0, 3.0]))), 9)  # not 121
    1.0
    """
    theta = np.asarray(theta_rad, float)
    if theta.size == 0:
        return math.nan
    mean = float(np.mod(np.angle(np.mean(np.exp(1j * theta))), 2 * math.pi))
    return 0.0 if mean == 2 * math.pi else mean  # a mean just below 0 rounds up to 2 pi
