"""What a person bouncing a ball with a racket can do: the one place of the ranges against
which racket amplitudes and periods are checked (a warning, never an error: the model is
defined beyond them), and the unit slip a value outside them most likely is.

The paper's subjects moved the racket by 0.065-0.30 m at periods of 0.53-0.92 s (sections 5-7);
the ranges below are wide around that: a racket moved by 2 mm to 1 m, once every 0.1 to 3 s.
A racket amplitude of 300 "m" is 300 mm typed for metres (``fixed-point`` then answers AC =
-1426 g), an ``a_r_m`` column of 150-300 is millimetres (eq. 15's slope comes out 305 m/s^2
against 0.30).
"""

from __future__ import annotations

import math

import numpy as np

from ..model.params import racket_acceleration_g

#: racket amplitude a_r a person can move a racket by, m
HUMAN_RACKET_AMPLITUDE_M: tuple[float, float] = (0.002, 1.0)
#: racket period tau a person can move a racket at, s
HUMAN_RACKET_PERIOD_S: tuple[float, float] = (0.1, 3.0)

#: (factor, unit) of the slips looked for: the value divided by the factor is in range
_LENGTH_SLIPS = ((1000.0, "millimetres"), (100.0, "centimetres"))
_TIME_SLIPS = ((1000.0, "milliseconds"),)


def _slip(value: float, span: tuple[float, float], slips, unit: str, symbol: str) -> str:
    found = [f"{name} ({value / factor:.4g} {symbol})" for factor, name in slips
             if span[0] <= value / factor <= span[1]]
    return (" or ".join(found) + f" typed for {unit}?") if found else "check the units"


def racket_half_range_m(racket) -> float:
    """Half the range of a racket's finite samples (m): its amplitude as a trace shows it, for
    ``racket_warnings``; NaN with fewer than 2 samples."""
    x = np.asarray(racket, dtype=float)
    x = x[np.isfinite(x)]
    return 0.5 * float(np.ptp(x)) if x.size >= 2 else math.nan


def racket_warnings(amplitude_m, period_s, amplitude_where: str,
                    period_where: str) -> list[str]:
    """One warning per quantity outside what a person can do, naming the likely unit slip.

    Parameters
    ----------
    amplitude_m, period_s : float or array of float
        Racket amplitudes (m) and periods (s), e.g. each trial's means; NaN is ignored.
    amplitude_where, period_where : str
        What holds them, for the message (``model.racket_amplitude``, ``data: impacts.csv:
        column racket_amplitude_m``).

    Returns
    -------
    list of str
        The warnings (empty when every value is in range).
    """
    out = []
    checks = ((amplitude_where, "amplitude", amplitude_m, HUMAN_RACKET_AMPLITUDE_M,
               _LENGTH_SLIPS, "metres", "m"),
              (period_where, "period", period_s, HUMAN_RACKET_PERIOD_S, _TIME_SLIPS,
               "seconds", "s"))
    for where, name, values, span, slips, unit, symbol in checks:
        x = np.atleast_1d(np.asarray(values, dtype=float))
        x = x[np.isfinite(x) & (x > 0)]
        bad = x[(x < span[0]) | (x > span[1])]
        if not len(bad):
            continue
        worst = float(bad[np.argmax(np.abs(np.log(bad / math.sqrt(span[0] * span[1]))))])
        count = f"{len(bad)} of {len(x)} values outside, e.g. " if len(x) > 1 else ""
        out.append(f"{where}: racket {name} {count}{worst:g} {symbol} is outside what a person "
                   f"can do ({span[0]:g}-{span[1]:g} {symbol}): "
                   + _slip(worst, span, slips, unit, symbol))
    return out


#: fewest impacts from which phases that all lie within +-2 pi degrees are taken for radians
#: written in degrees (a person's phase of impact varies by about 9 deg: section 6)
RADIANS_AS_DEGREES_MIN_IMPACTS = 10


def phase_unit_warning(theta_deg, where: str, racket=None) -> str | None:
    """A warning where every phase of impact (degrees) lies within +-2 pi: radians written
    under a column of degrees (0.5-0.8 "deg" for the 30-45 deg a person hits at), else None.
    Where the table also gives the racket (``racket``: AC in g, amplitude m, period s, and g
    m/s^2), the unit whose phases give the table's AC (-a_r w^2 sin theta / g, section 4)
    decides: a stable racket hit at 3 deg (AC -0.06 g) is degrees, and was warned of.

    Parameters
    ----------
    theta_deg : array of float
        The phases of impact as read, degrees; NaN is ignored.
    where : str
        What holds them, for the message (``data: impacts.csv: column theta_deg``).
    racket : tuple of (array, array, array, float), optional
        racket_acc_g, racket_amplitude_m, racket_period_s per impact, and g.
    """
    x = np.asarray(theta_deg, dtype=float)
    finite = np.isfinite(x)
    if finite.sum() < RADIANS_AS_DEGREES_MIN_IMPACTS or np.abs(x[finite]).max() > 2.0 * math.pi:
        return None
    if racket is not None:
        ac, amplitude, period, g = (np.asarray(r, dtype=float) for r in racket)
        omega = 2.0 * math.pi / period
        as_degrees = np.abs(ac - racket_acceleration_g(amplitude, omega, g, np.radians(x)))
        as_radians = np.abs(ac - racket_acceleration_g(amplitude, omega, g, x))
        ok = np.isfinite(as_degrees) & np.isfinite(as_radians)
        if ok.any() and np.median(as_degrees[ok]) <= np.median(as_radians[ok]):
            return None
    x = x[finite]
    return (f"{where}: every phase of impact lies within +-2 pi (the largest |value| is "
            f"{np.abs(x).max():.3g} over {len(x)} impacts), where a person's vary by about 9 "
            "deg: radians written as degrees? (name such a column theta_rad)")
