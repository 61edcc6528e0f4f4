"""From sampled racket and ball positions to the map's variables per bounce (Fig. 2).

Definitions (section 2; on the model's own motion they return the model's variables exactly):

* racket cycle: from one upward crossing of the racket's mid-position to the next; the phase of
  impact maps the time in its cycle linearly onto [0, 2 pi) (theta = w_r t of eq. 5 on a
  sinusoidal racket, eq. 4); the cycle's period and amplitude ((peak - trough) / 2, each about
  the mid-position at its time) go with it.
  The mid-position may drift: it is a local quadratic fit, over ``mid_window_s`` either side,
  of the midpoints between consecutive racket extrema (peaks and troughs located by local
  quartic fits), so a slow drift is followed and cycle-to-cycle amplitude changes average out;
* impacts: the events' times when given; otherwise the samples where the ball's velocity jumps
  upward by more than ``min_velocity_jump_m_s`` close to the racket, located to sub-sample
  precision where the fitted flights before and after meet (both constant-g parabolas, eq. 1:
  their difference is linear in t), or, without a clean flight before, where the flight after
  meets the racket;
* v_k: the velocity at t_k of a constant-g fit (eq. 1, g from the config) to the samples of the
  following free flight, ``guard_samples`` kept away from each contact; without ball data, eq. 1
  between two impacts with the racket positions at both: v_k = (x_r(t_k+1) - x_r(t_k)) / h + g h/2;
* AC: the racket's second derivative at t_k from a local polynomial least-squares fit
  (Savitzky-Golay; evaluated at t_k, which need not be a sample) over ``acc_half_window_s``.

Each local fit's half window is widened where the sampling is too coarse to give it
degree + 3 samples.

Messy recordings: gaps (NaN) shorter than ``max_gap_s`` are bridged for detection (fits use only
measured samples); impacts whose data lie in longer gaps are dropped and reported. Contacts
closer in time than ``sticking_hop_s`` (chatter) or followed by the ball resting on the racket
(within ``contact_tolerance_m`` of it: sticking, a resting start) are flagged, not reported.

Times in s, positions in m, velocities in m/s, phases in rad.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..model.params import ModelError
from ..model.flight import restitution_of
from .peaks import peaks_by_prominence

TWO_PI = 2.0 * math.pi
#: a racket cycle whose period differs from the trial's median by more than this fraction is
#: not used (e.g. a crossing of a still, drifting racket before the movement starts)
MAX_PERIOD_DEVIATION = 0.4
#: ball-racket closing speed (m/s) allowed for when deciding whether a velocity jump happened
#: near the racket: ``contact_distance_m`` + this x the velocities' span
CLOSING_SPEED_M_S = 10.0
#: contact detection: the ball's velocities either side of a sample are differences over this
#: time (s; at least one sample): 10 ms, two samples at 200 Hz
JUMP_SPAN_S = 0.01
#: contact detection: a jump counts when above this many robust SDs of all the jumps
JUMP_NOISE_FACTOR = 4.0
#: time kept away from each contact by the flight fits and the resting test (s; at least
#: ``guard_samples``; 10 ms: 2 samples at 200 Hz)
CONTACT_GUARD_S = 0.01
#: racket positions within this fraction of the racket's range of its mid-position count as at
#: the mid-position (and a still racket as still within it): a racket resting at its
#: mid-position was "below" it, hence found to start a cycle, or not, by the last bits of the
#: least-squares mid-position (they differ between BLAS kernels). 1e-9 of a 0.6 m range is
#: 0.6 nm: 10^4 times below a motion-capture file's resolution (0.01 mm), 10^6 times above
#: the rounding of the fits (1e-16 relative, times their conditioning, < 1e-13)
ROUNDING_TOLERANCE = 1e-9


@dataclass(frozen=True)
class ExtractionSettings:
    """Tuning of the extraction (see the module docstring); SI units."""

    g: float = 9.81
    max_gap_s: float = 0.05
    acc_half_window_s: float = 0.1
    acc_degree: int = 4
    velocity_degree: int = 6
    position_half_window_s: float = 0.02
    position_degree: int = 3
    extremum_half_window_s: float = 0.08
    extremum_degree: int = 4
    mid_window_s: float = 2.5
    min_velocity_jump_m_s: float = 1.0
    contact_distance_m: float = 0.05
    contact_tolerance_m: float = 0.005
    sticking_hop_s: float = 0.05
    guard_samples: int = 2
    min_flight_samples: int = 5
    ball_offset_m: float = 0.0


# -- local polynomial fits (Savitzky-Golay at any time) -------------------------------------
#: above this condition number (infinity norm) of X'X, :func:`least_squares` solves by SVD
#: (the normal equations lose about eps x cond(X'X): 1e-10 relative at the limit)
GRAM_CONDITION_LIMIT = 1e6


def least_squares(design, y):
    """(coefficients, (X'X)^-1) of the least-squares fit of ``y`` on the columns of
    ``design``, by the normal equations.

    The local fits here are small (2-5 columns, tens of rows) and well conditioned (times
    scaled to [-1, 1], or a line in seconds), so the normal equations agree with an SVD
    solution to about 1e-12 relative at a fifth of its cost; a singular or ill-conditioned
    Gram matrix (condition number above ``GRAM_CONDITION_LIMIT``) falls back to ``lstsq``
    and ``pinv``.

    Parameters
    ----------
    design : array (n, p)
        Design matrix.
    y : array (n,)
        Observations.

    Returns
    -------
    coef : array (p,)
    gram_inverse : array (p, p)
    """
    gram = design.T @ design
    try:
        inverse = np.linalg.inv(gram)
    except np.linalg.LinAlgError:
        inverse = None
    if (inverse is None or not np.isfinite(inverse).all()
            or np.abs(gram).sum(axis=1).max() * np.abs(inverse).sum(axis=1).max()
            > GRAM_CONDITION_LIMIT):
        coef, *_ = np.linalg.lstsq(design, y, rcond=None)
        return coef, np.linalg.pinv(gram)
    return inverse @ (design.T @ y), inverse


def least_squares_line(x, y):
    """``least_squares`` of ``y`` on the columns (1, x) in closed form: the 2x2 normal
    equations [[n, sum x], [sum x, sum x^2]] inverted by hand (a tenth of the general route's
    cost, the same numbers to rounding; the same fallback beyond ``GRAM_CONDITION_LIMIT``).

    Parameters
    ----------
    x, y : array (n,)
        Abscissae and observations.

    Returns
    -------
    coef : array (2,)
        Intercept and slope.
    gram_inverse : array (2, 2)
    """
    n = float(x.size)
    sx, sxx = float(x.sum()), float(x @ x)
    sy, sxy = float(y.sum()), float(x @ y)
    det = n * sxx - sx * sx
    if det > 0.0:
        inverse = np.array([[sxx, -sx], [-sx, n]]) / det
        # ||G||_inf * ||G^-1||_inf: the two row-sum norms are equal for this G
        row_norm = max(n, sxx) + abs(sx)
        condition = row_norm * row_norm / det
        if math.isfinite(condition) and condition <= GRAM_CONDITION_LIMIT:
            return inverse @ np.array([sy, sxy]), inverse
    return least_squares(np.column_stack([np.ones_like(x), x]), y)


def local_polynomial(t, x, t0: float, half_window: float, degree: int):
    """Least-squares polynomial of ``degree`` fitted to the finite samples with
    |t - t0| <= half_window; returns its coefficients in s = (t - t0) / half_window
    (increasing powers), or None with too few samples (fewer than degree + 2).

    At a sample time of uniformly sampled data this is the Savitzky-Golay filter."""
    fit = _local_design(t, x, t0, half_window, degree)
    if fit is None:
        return None
    design, xx = fit
    return least_squares(design, xx)[0]


def _local_design(t, x, t0: float, half_window: float, degree: int):
    """(design matrix in s = (t - t0) / half_window, finite samples) of a local fit, or None
    with fewer than degree + 2 finite samples."""
    lo = np.searchsorted(t, t0 - half_window * (1.0 + 1e-9), side="left")
    hi = np.searchsorted(t, t0 + half_window * (1.0 + 1e-9), side="right")
    tt, xx = t[lo:hi], x[lo:hi]
    ok = np.isfinite(xx)
    if np.count_nonzero(ok) < degree + 2:
        return None
    s = (tt[ok] - t0) / half_window
    return np.vander(s, degree + 1, increasing=True), xx[ok]


@dataclass(frozen=True)
class LocalFit:
    """A local polynomial fit at t0 (``local_polynomial``) with what its residuals say: the
    position and velocity at t0, their variances, the residual sum of squares and dof."""

    x: float
    v: float
    var_x: float
    var_v: float
    rss: float
    dof: int
    #: the second derivative at t0 (0 for a polynomial of degree below 2)
    acc: float = 0.0


def local_fit(t, x, t0: float, half_window: float, degree: int) -> LocalFit | None:
    """``local_polynomial`` at t0 with the variances of its value and slope there
    (s^2 (X'X)^-1, s^2 = RSS / dof).

    Parameters
    ----------
    t, x : array
        Sample times (sorted, s) and positions (NaN: missing, m).
    t0, half_window : float
        Centre and half width of the window, s.
    degree : int
        Degree of the polynomial.

    Returns
    -------
    LocalFit or None
        None with too few samples.
    """
    return _local_fit_and_coefficients(t, x, t0, half_window, degree)[1]


def _local_fit_and_coefficients(t, x, t0: float, half_window: float, degree: int):
    """(coefficients of ``local_polynomial``, ``local_fit``), or (None, None) with too few
    samples: one least-squares fit serves both."""
    fit = _local_design(t, x, t0, half_window, degree)
    if fit is None:
        return None, None
    design, xx = fit
    coef, inv = least_squares(design, xx)
    resid = xx - design @ coef
    dof = len(xx) - degree - 1
    s2 = float(resid @ resid) / dof if dof > 0 else math.nan
    acc = float(2.0 * coef[2] / half_window**2) if len(coef) > 2 else 0.0
    return coef, LocalFit(float(coef[0]), float(coef[1] / half_window), s2 * float(inv[0, 0]),
                          s2 * float(inv[1, 1]) / half_window**2, float(resid @ resid), dof,
                          acc)


def local_derivatives(t, x, t0: float, half_window: float, degree: int):
    """(x, x', x'') at t0 from ``local_fit``; NaNs when it has too few samples."""
    fit = local_fit(t, x, t0, half_window, degree)
    if fit is None:
        return math.nan, math.nan, math.nan
    return fit.x, fit.v, fit.acc


def _poly_root_near(coef, half_window: float, t0: float, target: float = 0.0,
                    reach: float = 1.0):
    """Real root of the local polynomial (minus target) in [-reach, reach] (in units of the
    half window; 1: the window) nearest s = 0, as a time."""
    c = np.array(coef, dtype=float)
    c[0] -= target
    roots = np.polynomial.polynomial.polyroots(c)
    real = roots[np.abs(roots.imag) < 1e-9].real
    real = real[np.abs(real) <= reach]
    if real.size == 0:
        return math.nan
    return float(t0 + half_window * real[np.argmin(np.abs(real))])


# -- gaps -------------------------------------------------------------------------------------
def bridge_short_gaps(t, x, max_gap_s: float):
    """(x with NaN runs shorter than ``max_gap_s`` filled by a cubic spline, long-gap mask).

    A run's length is the time between the measured samples either side of it."""
    x = np.asarray(x, dtype=float)
    bad = ~np.isfinite(x)
    if not bad.any():
        return x.copy(), np.zeros(x.shape, dtype=bool)
    good = ~bad
    if np.count_nonzero(good) < 4:
        return x.copy(), bad
    from scipy.interpolate import CubicSpline  # (its import is a quarter second: gaps only)

    filled = x.copy()
    spline = CubicSpline(t[good], x[good])
    long_gap = np.zeros(x.shape, dtype=bool)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], bad.astype(int), [0]])))
    for start, stop in zip(edges[::2], edges[1::2]):
        before, after = start - 1, stop
        if before < 0 or after >= len(x) or t[after] - t[before] > max_gap_s:
            long_gap[start:stop] = True
        else:
            filled[start:stop] = spline(t[start:stop])
    return filled, long_gap


# -- racket cycles ----------------------------------------------------------------------------
@dataclass
class RacketCycles:
    """Upward mid-position crossings and the cycles between them."""

    crossings: np.ndarray  # start times of complete cycles
    periods: np.ndarray
    amplitudes: np.ndarray
    mids: np.ndarray  # mid-position at each cycle start
    mid_times: np.ndarray  # (time, midpoint) of consecutive extrema, for mid_position()
    mid_values: np.ndarray
    mid_window_s: float

    def mid_position(self, t):
        """The racket's (drifting) mid-position at times t: a local quadratic (a mean with
        fewer than 3 midpoints) fitted to the extrema midpoints within ``mid_window_s``,
        all times at once (the normal equations of every window stacked; ``least_squares``
        for a window whose Gram matrix it would not invert)."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        mt, w = self.mid_times, self.mid_window_s
        if t.size == 0 or mt.size == 0:
            return np.full(t.shape, np.nan)
        flat = t.ravel()
        # the midpoints within the window of each time, as a padded (m, width) table
        # (mid_times are sorted; the searchsorted range is widened and |dt| <= w decides)
        lo = np.searchsorted(mt, flat - w * (1.0 + 1e-9), side="left")
        hi = np.searchsorted(mt, flat + w * (1.0 + 1e-9), side="right")
        width = int(np.max(hi - lo, initial=0))
        if width == 0:
            return np.full(t.shape, np.nan)
        index = np.minimum(lo[:, None] + np.arange(width), mt.size - 1)
        inside = (np.arange(width) < (hi - lo)[:, None]) & (
            np.abs(mt[index] - flat[:, None]) <= w)
        count = inside.sum(axis=1)
        s = np.where(inside, (mt[index] - flat[:, None]) / w, 0.0)
        y = np.where(inside, self.mid_values[index], 0.0)
        value = np.full(flat.shape, np.nan)
        few = (count > 0) & (count < 3)
        value[few] = y[few].sum(axis=1) / count[few]
        many = np.flatnonzero(count >= 3)
        if many.size:
            powers = inside[many, :, None] * s[many, :, None] ** np.arange(5)  # (m, width, 5)
            sums = powers.sum(axis=1)
            gram = sums[:, np.arange(3)[:, None] + np.arange(3)]  # (m, 3, 3): sum s^(i+j)
            rhs = np.einsum("mwk,mw->mk", powers[:, :, :3], y[many])
            try:
                inverse = np.linalg.inv(gram)
            except np.linalg.LinAlgError:  # an exactly singular window among them
                inverse = np.stack([_inverse_or_nan(g) for g in gram])
            with np.errstate(all="ignore"):
                condition = (np.abs(gram).sum(axis=2).max(axis=1)
                             * np.abs(inverse).sum(axis=2).max(axis=1))
            good = np.isfinite(inverse).all(axis=(1, 2)) & (condition <= GRAM_CONDITION_LIMIT)
            value[many[good]] = np.einsum("mk,mk->m", inverse[good, 0, :], rhs[good])
            for i in many[~good]:  # a degenerate window: least_squares' own fallback
                sel = inside[i]
                coef, _ = least_squares(np.vander(s[i, sel], 3, increasing=True), y[i, sel])
                value[i] = coef[0]
        return value.reshape(t.shape)

    def locate(self, t):
        """(cycle index or -1, phase in [0, 2 pi)) of times t."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        if len(self.periods) == 0:  # no complete cycle: no time is inside one
            return np.full(t.shape, -1), np.full(t.shape, np.nan)
        c = np.searchsorted(self.crossings, t, side="right") - 1
        inside = (c >= 0) & (t < self.crossings[np.maximum(c, 0)] + self.periods[np.maximum(c, 0)])
        c = np.where(inside, c, -1)
        cc = np.maximum(c, 0)
        theta = np.where(inside, TWO_PI * (t - self.crossings[cc]) / self.periods[cc], np.nan)
        return c, np.minimum(theta, np.nextafter(TWO_PI, 0.0))


def _inverse_or_nan(matrix: np.ndarray) -> np.ndarray:
    """The inverse of a square matrix, NaNs where it is singular."""
    try:
        return np.linalg.inv(matrix)
    except np.linalg.LinAlgError:
        return np.full_like(matrix, np.nan)


def _refined_extrema(t, x, measured, index, kind: int, s: ExtractionSettings):
    """(time, value) of each extremum (kind +1 peak, -1 trough) by a local quartic fit."""
    out = []
    x = np.where(measured, x, np.nan)
    for i in index:
        coef = local_polynomial(t, x, t[i], s.extremum_half_window_s, s.extremum_degree)
        if coef is None:
            continue
        dcoef = np.polynomial.polynomial.polyder(coef)
        roots = np.polynomial.polynomial.polyroots(dcoef)
        real = roots[np.abs(roots.imag) < 1e-9].real
        real = real[np.abs(real) <= 0.5]
        if real.size == 0:
            continue
        r = real[np.argmin(np.abs(real))]
        value = float(np.polynomial.polynomial.polyval(r, coef))
        out.append((t[i] + r * s.extremum_half_window_s, value, kind))
    return out


def robust_sd(x) -> float:
    """The SD of a normal sample from its median absolute deviation (outliers barely count)."""
    x = np.asarray(x, dtype=float)
    return 1.4826 * float(np.median(np.abs(x - np.median(x))))


def sample_noise_m(x, order: int = 2) -> float:
    """The white measurement noise of a sampled position (m): a robust SD of its differences
    of ``order``, which is sqrt(C(2 order, order)) times the noise's SD (sqrt(6) for second
    differences). The motion itself adds a little: a racket's 0.3 m at 0.92 s adds 0.35 mm to
    second differences at 200 Hz (0.1 mm to the estimate), 4e-4 mm to fourth differences;
    NaN with fewer than 10 differences."""
    x = np.asarray(x, dtype=float)
    d = np.diff(x[np.isfinite(x)], order)
    if d.size < 10:
        return math.nan
    return robust_sd(d) / math.sqrt(math.comb(2 * order, order))


def _motion_onset(t, x, t0: float, half_window: float, t_peak: float,
                  amplitude: float) -> float | None:
    """For a racket that stood still and then started moving up (a resting start), the time
    of its last still sample (within 4 robust SDs of its resting position) before ``t_peak``;
    None when it was moving at the upward crossing ``t0``. Still: it moved less than a quarter
    as far in the half window before ``t0`` as in the one after, or less than 2 % of its
    ``amplitude`` in both (a still racket dithering about its mid-position crosses it by
    noise alone, before it starts moving). A noise-free still racket's band is
    ROUNDING_TOLERANCE x ``amplitude``, not 0."""
    finite = np.isfinite(x)
    before = x[(t >= t0 - half_window) & (t < t0) & finite]
    after = x[(t > t0) & (t <= t0 + half_window) & finite]
    if before.size < 2 or after.size < 2:
        return None
    starts_here = np.ptp(before) < 0.25 * np.ptp(after)
    still_here = max(np.ptp(before), np.ptp(after)) < 0.02 * amplitude
    if not (starts_here or still_here):
        return None
    rest = float(np.median(before))
    band = max(4.0 * robust_sd(before), ROUNDING_TOLERANCE * abs(amplitude))
    ahead = (t >= t0 - half_window) & (t < t_peak) & finite
    still = np.flatnonzero(ahead & (np.abs(x - rest) <= band))
    if still.size == 0:
        return None
    onset = float(t[still[-1]])
    moving = x[(t > onset) & (t <= onset + half_window) & finite]
    return onset if moving.size >= 2 and np.ptp(moving) > 4.0 * np.ptp(before) else None


#: the largest difference between an event's time and where the ball's flights either side
#: meet that is taken as the event log's lag (s); beyond it the two are not the same contact
EVENT_LAG_MAX_S = 0.05

#: measured samples a crossing's local fit needs on each side of the crossing: fewer, and the
#: polynomial extrapolates from one side (a logger's dropout just after a crossing: crossing
#: times 5 ms off, cycles 6 ms long or short)
SAMPLES_EACH_SIDE = 2


def _upward_crossing(t, raw, measured_t, t_a: float, t_b: float, h: float, mid: float,
                     s: ExtractionSettings) -> float:
    """The time the racket crosses ``mid`` upwards between samples ``t_a`` and ``t_b`` of
    the bridged racket: the root of a local polynomial over +-h about ``t_a`` (measured
    samples ``raw``, whose times are ``measured_t``).

    Where samples are missing near the crossing (cells, or rows: a logger's dropout), so that
    the window holds fewer than SAMPLES_EACH_SIDE measured samples on a side of it (inside
    the recording: at its ends the fit is as it is), the window is widened by ``max_gap_s``
    about the gap of the measured samples around the crossing, if that gap is one
    ``max_gap_s`` bridges, and the root is taken within h of its ends; NaN where neither
    finds the crossing."""
    centre = 0.5 * (t_a + t_b)
    k = int(np.searchsorted(measured_t, centre))
    inside = measured_t.size > 0 and measured_t[0] <= t_a - h and t_a + h <= measured_t[-1]
    left = k - int(np.searchsorted(measured_t, t_a - h))
    right = int(np.searchsorted(measured_t, t_a + h, side="right")) - k
    if not inside or (left >= SAMPLES_EACH_SIDE and right >= SAMPLES_EACH_SIDE):
        coef = local_polynomial(t, raw, t_a, h, s.position_degree)
        return math.nan if coef is None else _poly_root_near(coef, h, t_a, mid)
    before, after = float(measured_t[k - 1]), float(measured_t[k])  # inside: both exist
    if after - before > s.max_gap_s:
        return math.nan  # a gap too long to bridge
    centre, wide = 0.5 * (before + after), h + s.max_gap_s
    left = k - int(np.searchsorted(measured_t, centre - wide))
    right = int(np.searchsorted(measured_t, centre + wide, side="right")) - k
    if left < SAMPLES_EACH_SIDE or right < SAMPLES_EACH_SIDE:
        return math.nan
    coef = local_polynomial(t, raw, centre, wide, s.position_degree)
    reach = (0.5 * (after - before) + h) / wide
    return math.nan if coef is None else _poly_root_near(coef, wide, centre, mid, reach=reach)


def racket_cycles(t, racket, measured, s: ExtractionSettings) -> RacketCycles:
    """The racket's cycles (see the module docstring). ``racket``: gap-bridged positions;
    ``measured``: which samples were measured (local fits use only those)."""
    finite = np.isfinite(racket)
    if np.count_nonzero(finite) < 2:
        raise ModelError("no racket positions (every sample missing)")
    work = np.interp(t, t[finite], racket[finite])  # long gaps: only for coarse detection
    lo, hi = np.percentile(work, [1.0, 99.0])
    prominence = 0.2 * (hi - lo)  # an extremum at the recording's edge has a low prominence
    at_mid = ROUNDING_TOLERANCE * (hi - lo)
    if prominence <= 0.0:
        raise ModelError("the racket does not move")
    peaks = peaks_by_prominence(work, prominence)  # scipy.signal.find_peaks' own
    troughs = peaks_by_prominence(-work, prominence)
    raw = np.where(measured, racket, np.nan)
    measured_t = t[np.isfinite(raw)]
    extrema = sorted(_refined_extrema(t, raw, measured, peaks, 1, s)
                     + _refined_extrema(t, raw, measured, troughs, -1, s))
    alternating: list[tuple[float, float, int]] = []
    for e in extrema:  # keep the more extreme of two neighbours of the same kind
        if alternating and alternating[-1][2] == e[2]:
            if e[2] * e[1] > e[2] * alternating[-1][1]:
                alternating[-1] = e
        else:
            alternating.append(e)
    et = np.array([e[0] for e in alternating])
    ex = np.array([e[1] for e in alternating])
    ek = np.array([e[2] for e in alternating])
    mid_times = 0.5 * (et[1:] + et[:-1])
    mid_values = 0.5 * (ex[1:] + ex[:-1])
    cycles = RacketCycles(np.array([]), np.array([]), np.array([]), np.array([]),
                          mid_times, mid_values, s.mid_window_s)
    # upward crossings: between each trough and the following peak (or, for a first peak,
    # the start of the recording)
    crossings = []
    half_cycle = float(np.median(np.diff(et))) if len(et) > 1 else 0.0
    rises = []  # (j, t_before, t_peak) of each rise from a trough to the next peak
    for j in range(-1, len(et)):
        if j == -1:
            if not (len(et) > 1 and ek[0] == 1):
                continue
            # no trough before the first peak: search at most a typical half cycle before it
            rises.append((j, max(t[0], et[0] - half_cycle), et[0]))
        elif j == len(et) - 1:
            if not (len(et) > 1 and ek[j] == -1):
                continue
            # no peak after the last trough (the recording ends first): the crossing may
            # still be recorded, and it closes the cycle before it
            rises.append((j, et[j], min(t[-1], et[j] + half_cycle)))
        elif ek[j] == -1 and ek[j + 1] == 1:
            rises.append((j, et[j], et[j + 1]))
    rise_mids = cycles.mid_position([0.5 * (t_before + t_peak) for _, t_before, t_peak in rises])
    for (j, t_before, t_peak), mid in zip(rises, rise_mids.tolist()):
        a, b = np.searchsorted(t, [t_before, t_peak])
        y = work[a:b] - mid
        # from at or below the mid-position to at or above it, "at" within at_mid: a racket
        # resting at its mid-position starts a cycle at its last still sample, whichever side
        # of it the last bits of ``mid`` fall
        up = np.flatnonzero((y[:-1] <= at_mid) & (y[1:] >= -at_mid))
        if up.size == 0:
            continue
        i = a + up[-1]  # the last one before the peak (a still racket before it may dither)
        h = s.position_half_window_s
        peak_x = float(ex[j + 1]) if j + 1 < len(et) else float(np.max(work[a:b + 1]))
        onset = _motion_onset(t, raw, t[i], h, t_peak, peak_x - mid)
        if onset is None:
            tc = _upward_crossing(t, raw, measured_t, t[i], t[i + 1], h, mid, s)
        else:
            # a racket that stood still until it started moving (a resting start): a fit
            # across that kink is biased (a cubic over +-20 ms: 5 ms early); fit the moving
            # side, from the last still sample, and look for the crossing up to a sample
            # before it
            coef = local_polynomial(t, raw, onset + h, h, s.position_degree)
            step = float(np.median(np.diff(t[max(i - 3, 0):i + 4])))
            tc = (math.nan if coef is None
                  else _poly_root_near(coef, h, onset + h, mid, reach=1.0 + step / h))
        if math.isfinite(tc):
            crossings.append((tc, j))
    starts, periods, extremes = [], [], []
    for (t0, _j0), (t1, _j1) in zip(crossings[:-1], crossings[1:]):
        between = (et > t0) & (et < t1)
        if np.count_nonzero(between & (ek == 1)) != 1 or np.count_nonzero(
                between & (ek == -1)) != 1:
            continue
        lo_i, hi_i = np.searchsorted(t, [t0, t1])
        if np.any(~finite[lo_i:hi_i]):
            continue  # a long gap inside the cycle
        starts.append(t0)
        periods.append(t1 - t0)
        extremes.append(np.flatnonzero(between & (ek == 1))[0])
        extremes.append(np.flatnonzero(between & (ek == -1))[0])
    # each extremum about its own mid-position; the cycle's mid-position at its start
    drift = cycles.mid_position(et[np.array(extremes, dtype=int)]).reshape(-1, 2)
    peaks_x = ex[np.array(extremes[0::2], dtype=int)]
    troughs_x = ex[np.array(extremes[1::2], dtype=int)]
    amplitudes = (0.5 * ((peaks_x - drift[:, 0]) - (troughs_x - drift[:, 1]))).tolist()
    mids = cycles.mid_position(np.array(starts)).tolist()
    if periods:  # a cycle far longer or shorter than the trial's typical one is not a cycle
        typical = float(np.median(periods))
        ok = [abs(p / typical - 1.0) <= MAX_PERIOD_DEVIATION for p in periods]
        starts, periods, amplitudes, mids = ([v for v, keep in zip(seq, ok) if keep]
                                             for seq in (starts, periods, amplitudes, mids))
    cycles.crossings = np.array(starts)
    cycles.periods = np.array(periods)
    cycles.amplitudes = np.array(amplitudes)
    cycles.mids = np.array(mids)
    return cycles


# -- flights ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FlightFit:
    """x(t) = x0 + v0 (t - t_ref) - g (t - t_ref)^2 / 2 fitted to a free flight (eq. 1)."""

    t_ref: float
    x0: float
    v0: float
    t_first: float
    t_last: float
    n: int
    rms: float
    #: covariance of (x0, v0) from the residuals (s^2 (X'X)^-1, s^2 = RSS / (n - 2))
    cov: tuple[tuple[float, float], tuple[float, float]] = ((math.nan, math.nan),
                                                            (math.nan, math.nan))
    #: the samples fitted (for the pooled gravity fit)
    samples: tuple[np.ndarray, np.ndarray] | None = None

    def position_var(self, t) -> float:
        """Variance of the fitted position at t (g known)."""
        d = float(t) - self.t_ref
        (a, b), (_, c) = self.cov
        return a + 2.0 * b * d + c * d * d

    def position(self, t, g):
        dt = np.asarray(t, dtype=float) - self.t_ref
        return self.x0 + self.v0 * dt - 0.5 * g * dt * dt

    def velocity(self, t, g):
        return self.v0 - g * (np.asarray(t, dtype=float) - self.t_ref)


def fit_flight(t, x, t_ref: float, g: float, min_samples: int) -> FlightFit | None:
    """Least-squares constant-g parabola through (t, x) (finite samples); None if too few."""
    ok = np.isfinite(x)
    if np.count_nonzero(ok) < min_samples:
        return None
    tt, xx = t[ok], x[ok]
    dt = tt - t_ref
    coef, inv = least_squares_line(dt, xx + 0.5 * g * dt * dt)
    resid = xx - (coef[0] + coef[1] * dt - 0.5 * g * dt * dt)
    s2 = float(resid @ resid) / (tt.size - 2) if tt.size > 2 else math.nan
    inv = inv * s2
    cov = ((float(inv[0, 0]), float(inv[0, 1])), (float(inv[1, 0]), float(inv[1, 1])))
    return FlightFit(t_ref, float(coef[0]), float(coef[1]), float(tt[0]), float(tt[-1]),
                     int(tt.size), float(np.sqrt(np.mean(resid * resid))), cov, (tt, xx))


#: a fitted g outside this range is no set-up's (m/s^2): a unit slip (mm read as cm: 98)
PLAUSIBLE_G_M_S2 = (1.0, 20.0)


@dataclass(frozen=True)
class GravityFit:
    """g from the curvature of free flights: one parabola per flight (its own position and
    velocity), one g for all; ``residual_sd`` the flights' residual SD (m)."""

    g: float
    se: float
    n_flights: int
    n_samples: int
    residual_sd: float


def pooled_gravity(flights) -> GravityFit | None:
    """The least-squares g of free flights x = a_i + b_i s - g s^2 / 2 (eq. 1; s: time from
    each flight's first sample), a_i and b_i per flight: each flight's samples are projected
    off span{1, s}, and g is the regression of the projected x on the projected -s^2 / 2.

    Parameters
    ----------
    flights : iterable of (t, x) arrays
        The samples of each free flight (finite positions), s and m.

    Returns
    -------
    GravityFit or None
        None with no flight of at least 4 samples.
    """
    num = den = rss_x = 0.0
    n_flights = n_samples = 0
    parts = []
    for t, x in flights:
        t, x = np.asarray(t, dtype=float), np.asarray(x, dtype=float)
        if t.size < 4:
            continue
        s_ = (t - t[0]) / max(t[-1] - t[0], 1e-12)  # scaled for conditioning
        basis, _ = np.linalg.qr(np.column_stack([np.ones_like(s_), s_]))
        q = -0.5 * (t - t[0]) ** 2
        q = q - basis @ (basis.T @ q)
        r = x - basis @ (basis.T @ x)
        num += float(q @ r)
        den += float(q @ q)
        rss_x += float(r @ r)
        parts.append((q, r))
        n_flights += 1
        n_samples += t.size
    if n_flights == 0 or den <= 0.0:
        return None
    g = num / den
    rss = sum(float((r - g * q) @ (r - g * q)) for q, r in parts)
    dof = max(n_samples - 2 * n_flights - 1, 1)
    sigma2 = rss / dof
    return GravityFit(g, math.sqrt(sigma2 / den), n_flights, n_samples, math.sqrt(sigma2))


# -- contacts -----------------------------------------------------------------------------------
def detect_contacts(t, ball, racket, s: ExtractionSettings, bridged=None) -> np.ndarray:
    """Sample indices of contacts: the ball's velocity jumps upward (net of gravity) by more
    than a threshold within ``contact_distance_m`` (plus ``CLOSING_SPEED_M_S`` times the
    velocities' span) of the racket; a jump straddling two samples counts once (the larger).

    The velocities either side of a sample are differences over JUMP_SPAN_S (at least one
    sample): over one sample, 0.5 mm of noise at 1 kHz is a jump of 1.2 m/s (SD), and spurious
    contacts split the flights. The threshold is ``min_velocity_jump_m_s`` or
    JUMP_NOISE_FACTOR robust SDs of the jumps (which are noise but at the contacts),
    whichever is larger.

    ``bridged`` (optional) marks the samples of short gaps that ``bridge_short_gaps`` filled:
    a spline across a contact smears the jump into spurious or missing contacts, so inside a
    bridged gap (and a span either side) the jump is the one ACROSS the gap, from the measured
    samples on each side, and such a gap holds at most one contact."""
    n = t.size
    jump = np.full(t.shape, np.nan)
    # the sample nearest a contact may be up to the span away from it, while ball and racket
    # approach each other at several m/s: the distance allowed grows with the span
    span = np.zeros(t.shape)
    step = float(np.median(np.diff(t))) if n > 1 else 1.0
    m = max(1, int(round(JUMP_SPAN_S / step)))
    if n > 2 * m:
        i = np.arange(m, n - m)
        v_after = (ball[i + m] - ball[i]) / (t[i + m] - t[i])
        v_before = (ball[i] - ball[i - m]) / (t[i] - t[i - m])
        span[i] = 0.5 * (t[i + m] - t[i - m])
        jump[i] = v_after - v_before + s.g * span[i]
    finite = jump[np.isfinite(jump)]
    threshold = s.min_velocity_jump_m_s
    if finite.size:
        threshold = max(threshold, JUMP_NOISE_FACTOR * robust_sd(finite))
    near = (ball - s.ball_offset_m - racket) < s.contact_distance_m + CLOSING_SPEED_M_S * span
    if bridged is not None and np.any(bridged):
        _jumps_across_gaps(t, ball, racket, bridged, m, jump, near, s)
    with np.errstate(invalid="ignore"):
        candidate = np.flatnonzero((jump > threshold) & near)
    contacts: list[int] = []
    for i in candidate.tolist():
        if contacts and i - contacts[-1] <= 2 * m:
            if jump[i] > jump[contacts[-1]]:
                contacts[-1] = i
            continue
        contacts.append(int(i))
    return np.array(contacts, dtype=int)


def _jumps_across_gaps(t, ball, racket, bridged, m: int, jump, near,
                       s: ExtractionSettings) -> None:
    """In place: for each bridged gap, the jump across it (velocities over ``m`` measured
    samples before its first and after its last missing sample) at the gap's middle sample,
    no jump elsewhere within ``m`` samples of the gap; near the racket when a measured sample
    at either edge is."""
    n = t.size
    edges = np.flatnonzero(np.diff(np.concatenate([[0], bridged.astype(int), [0]])))
    for start, stop in zip(edges[::2], edges[1::2]):
        before, after = start - 1, stop  # the measured samples either side
        jump[max(start - m, 0):min(stop + m, n)] = np.nan
        if before - m < 0 or after + m >= n:
            continue
        v_before = (ball[before] - ball[before - m]) / (t[before] - t[before - m])
        v_after = (ball[after + m] - ball[after]) / (t[after + m] - t[after])
        elapsed = 0.5 * (t[after + m] + t[after]) - 0.5 * (t[before] + t[before - m])
        middle = (start + stop - 1) // 2
        jump[middle] = v_after - v_before + s.g * elapsed
        reach = s.contact_distance_m + CLOSING_SPEED_M_S * (t[after] - t[before])
        near[middle] = min(ball[before] - racket[before],
                           ball[after] - racket[after]) - s.ball_offset_m < reach


@dataclass
class TrialExtraction:
    """One trial's impacts (the impacts table's columns, without ``trial``), the excluded
    contacts (time, reason), the racket cycles, and the ball-marker offset measured at the
    contacts located from two flights (median, m; NaN when none)."""

    impacts: dict[str, np.ndarray]
    excluded: list[tuple[float, str]]
    cycles: RacketCycles
    measured_offset_m: float = math.nan
    #: the free flights' samples (t, x), for the pooled gravity fit (``pooled_gravity``)
    flights: list = field(default_factory=list)
    #: per reported impact: the ball marker above the racket marker at t_k (m), and the
    #: standard errors of v_k (m/s) and theta_k (rad) propagated from the fits' residuals
    offsets_m: np.ndarray = field(default_factory=lambda: np.array([]))
    se_v_m_s: np.ndarray = field(default_factory=lambda: np.array([]))
    se_theta_rad: np.ndarray = field(default_factory=lambda: np.array([]))
    #: the racket's local position fits at the impacts: residual sum of squares, dof
    racket_rss: float = 0.0
    racket_dof: int = 0
    #: per reported impact: the contact's area and its weight (contact_s^2 = area / weight;
    #: ``contact_duration`` pools them)
    contact_area: np.ndarray = field(default_factory=lambda: np.array([]))
    contact_weight: np.ndarray = field(default_factory=lambda: np.array([]))
    #: per reported impact given by an event: its time less the ball's own contact time,
    #: where the flights either side meet (s; NaN: no flight before it)
    event_lags_s: np.ndarray = field(default_factory=lambda: np.array([]))
    #: per event inside the recording, reported or not: its time less the nearest contact
    #: detected in the ball's samples (s, to about a sample; NaN: none near)
    event_lags_coarse_s: np.ndarray = field(default_factory=lambda: np.array([]))


def _segment_fits(t, ball, long_gap, racket, lo: int, hi: int, t_after: float,
                  t_before: float, s: ExtractionSettings):
    """Fits of the samples [lo, hi) between two contacts (``ball``: measured samples, NaN
    elsewhere; ``long_gap``: samples in gaps too long to bridge): (fit after the first contact
    or None, fit before the second or None, resting seconds, long gap of the ball's data
    inside, long gap of the racket's data inside)."""
    seg = np.arange(max(lo, 0), min(hi, len(t)))
    if seg.size == 0:
        return None, None, 0.0, False, False
    xb = ball[seg]
    gap = xb - s.ball_offset_m - racket[seg]
    with np.errstate(invalid="ignore"):
        resting = gap < s.contact_tolerance_m
    # a stretch without rows longer than max_gap_s is a gap as a run of empty cells is (the
    # virtual set-up stops its world while the racket's stream is silent: a flight fitted
    # across that hole measured g 8 % low): the sample after it ends the fits before it
    in_gap = long_gap[seg].copy()
    in_gap[1:] |= np.diff(t[seg]) > s.max_gap_s
    has_gap = bool(np.any(in_gap))  # the ball's data has a hole: the next hop is unknown
    # where the racket is not measured (a gap too long to bridge) no contact is seen, so the
    # ball's way down and up again was fitted as one flight (g measured 30 % low): it ends
    # the fits too
    racket_gap = ~np.isfinite(racket[seg])
    in_gap |= racket_gap
    rest_s = 0.0
    if resting.any():
        r = seg[resting]
        rest_s = float(t[r[-1]] - t[r[0]]) if r.size > 1 else 0.0
    # after-fit: up to the first resting sample or long gap
    stop = seg.size
    bad = np.flatnonzero(resting | in_gap)
    if bad.size:
        stop = bad[0] - s.guard_samples
    after = None
    if stop > 0 and not (resting.any() and rest_s > 0.0):
        after = fit_flight(t[seg[:stop]], xb[:stop], t_after, s.g, s.min_flight_samples)
    # before-fit: after the last resting sample or long gap
    start = 0 if bad.size == 0 else bad[-1] + 1 + s.guard_samples
    before = None
    if start < seg.size:
        before = fit_flight(t[seg[start:]], xb[start:], t_before, s.g, s.min_flight_samples)
    return after, before, rest_s, has_gap, bool(np.any(racket_gap))


def guard_samples(s: ExtractionSettings, dt: float) -> int:
    """Samples kept away from each contact by the flight fits and the resting test:
    ``guard_samples``, and at least CONTACT_GUARD_S (right after a contact the ball is still
    within ``contact_tolerance_m`` of the racket for a few ms: at 1 kHz, with noise, it
    looked like resting and the flight was lost)."""
    return max(s.guard_samples, int(math.ceil(CONTACT_GUARD_S / dt - 1e-9)))


def widened_windows(s: ExtractionSettings, dt: float) -> ExtractionSettings:
    """The settings with each local-fit half window widened, where the sampling is coarse, to
    hold at least degree + 3 samples."""
    def wide(half: float, degree: int) -> float:
        return max(half, 0.5 * (degree + 3) * dt)

    return replace(
        s,
        acc_half_window_s=wide(s.acc_half_window_s, s.acc_degree),
        position_half_window_s=wide(s.position_half_window_s, s.position_degree),
        extremum_half_window_s=wide(s.extremum_half_window_s, s.extremum_degree),
    )


@dataclass
class _Racket:
    """A trial's racket: its positions at the measured samples (NaN elsewhere), the same with
    the short gaps bridged (for detection), the samples in gaps too long to bridge, and its
    cycles."""

    fit: np.ndarray
    bridged: np.ndarray
    long_gap: np.ndarray
    cycles: RacketCycles
    #: local fits of ``fit`` done so far, by (t0, half window, degree): the passes over a
    #: trial at another g or marker offset meet the same times (events, cycle crossings)
    _fits: dict = field(default_factory=dict, repr=False)

    def local(self, t, t0: float, half_window: float, degree: int):
        """(coefficients, :class:`LocalFit`) of the racket's local polynomial at t0
        (``local_fit``; (None, None) with too few samples), each fitted once."""
        key = (float(t0), half_window, degree)
        if key not in self._fits:
            self._fits[key] = _local_fit_and_coefficients(t, self.fit, t0, half_window, degree)
        return self._fits[key]

    def position(self, t, t0: float, s: ExtractionSettings) -> float:
        """The racket's position at t0 from its local position fit (NaN: too few samples)."""
        fit = self.local(t, t0, s.position_half_window_s, s.position_degree)[1]
        return math.nan if fit is None else fit.x


@dataclass
class _Ball:
    """A trial's ball marker: positions at the measured samples (NaN elsewhere), the same with
    the short gaps bridged, the samples in gaps too long to bridge, which samples were
    measured."""

    fit: np.ndarray
    bridged: np.ndarray
    long_gap: np.ndarray
    measured: np.ndarray


@dataclass
class _Contacts:
    """A trial's contacts before they are located: crude times and sample indices, whether the
    time is an event's logged one (exact), the index k of each in the log, alpha per event."""

    t: np.ndarray
    index: np.ndarray
    exact: np.ndarray
    k: np.ndarray
    alpha: np.ndarray
    #: per event: its time less the nearest contact detected in the ball's samples (s; to
    #: about a sample; NaN: none within EVENT_LAG_MAX_S, or no ball data)
    coarse_lag: np.ndarray


@dataclass
class _Impacts:
    """Per contact, what the steps of :func:`extract_trial` find (NaN: not found): the located
    time t_k, the velocities after and before, the contact's duration, area and weight, the
    marker offset, the variance of t_k, the SE of v_k, whether the flights met, the apex
    height, why it is not reported ("" when it is), whether the flight after runs into a long
    gap; and the trial's marker offsets and free flights."""

    t_k: np.ndarray
    v_k: np.ndarray
    v_in: np.ndarray
    contact: np.ndarray
    area: np.ndarray
    weight: np.ndarray
    offset_k: np.ndarray
    event_lag: np.ndarray
    var_t: np.ndarray
    se_v: np.ndarray
    met: np.ndarray
    apex_x: np.ndarray
    reason: list[str]
    next_unknown: np.ndarray
    #: the flight after the impact crosses a long gap of the racket's data, where a contact
    #: cannot be seen (the ball's data are there)
    racket_gap: np.ndarray
    offsets: list[float] = field(default_factory=list)
    flights: list = field(default_factory=list)

    @classmethod
    def at(cls, contacts: _Contacts) -> _Impacts:
        n = len(contacts.t)
        return cls(
            t_k=contacts.t.copy(), v_k=np.full(n, np.nan),
            v_in=np.full(n, np.nan),  # ball velocity just before the impact (the flight before)
            contact=np.full(n, np.nan),
            area=np.full(n, np.nan),  # of the ball above its two flights, around it (m s)
            weight=np.full(n, np.nan),  # |closing velocity| K(alpha): area / weight = contact^2
            offset_k=np.full(n, np.nan),
            event_lag=np.full(n, np.nan),  # an event's time less where the flights meet
            var_t=np.zeros(n),  # variance of t_k from the flight fits (0: an event's time)
            se_v=np.full(n, np.nan),
            met=contacts.exact.copy(),  # timed where the flights meet (or logged)
            apex_x=np.full(n, np.nan),  # ball height at the apex of the following flight
            reason=[""] * n, next_unknown=np.zeros(n, dtype=bool),
            racket_gap=np.zeros(n, dtype=bool))


def _racket_of(t, racket, s: ExtractionSettings) -> _Racket:
    """The racket's samples, bridged, and its cycles (ModelError without a complete one)."""
    racket_raw = np.asarray(racket, dtype=float)
    bridged, long_gap = bridge_short_gaps(t, racket_raw, s.max_gap_s)
    measured = np.isfinite(racket_raw)
    cycles = racket_cycles(t, bridged, measured, s)
    if cycles.crossings.size == 0:
        raise ModelError("no complete racket cycle found")
    return _Racket(np.where(measured, racket_raw, np.nan), bridged, long_gap, cycles)


def _ball_of(t, ball, s: ExtractionSettings) -> _Ball:
    """The ball marker's samples and the same bridged."""
    ball_raw = np.asarray(ball, dtype=float)
    bridged, long_gap = bridge_short_gaps(t, ball_raw, s.max_gap_s)
    measured = np.isfinite(ball_raw)
    return _Ball(np.where(measured, ball_raw, np.nan), bridged, long_gap, measured)


def _contacts_of(t, racket: _Racket, ball: _Ball | None, event_t, event_alpha,
                 s: ExtractionSettings, excluded: list[tuple[float, str]]) -> _Contacts:
    """The contacts: the events inside the recording's time (the others go to ``excluded``),
    or, without events, the contacts detected in the ball's samples."""
    if event_t is not None:
        ct = np.asarray(event_t, dtype=float)
        inside = (ct > t[0]) & (ct < t[-1])
        excluded += [(float(x), "event outside the recording's time") for x in ct[~inside]]
        k_index = np.flatnonzero(inside)  # k: the event's index in the log
        ct = ct[inside]
        if event_alpha is not None:
            event_alpha = np.asarray(event_alpha, dtype=float)[inside]
        ci = np.clip(np.searchsorted(t, ct), 1, len(t) - 2)
        exact = np.ones(ct.shape, dtype=bool)
        coarse_lag = np.full(ct.shape, np.nan)
        if ball is not None:  # the events against the contacts the ball's own samples show
            found = t[detect_contacts(t, ball.bridged, racket.bridged, s,
                                      ~ball.measured & ~ball.long_gap)]
            nearest = match_impacts(found, ct, EVENT_LAG_MAX_S)
            coarse_lag = np.where(nearest >= 0, ct - found[np.maximum(nearest, 0)], np.nan)
    else:
        if ball is None:
            raise ModelError("neither ball positions nor events: no impacts to find")
        ci = detect_contacts(t, ball.bridged, racket.bridged, s, ~ball.measured & ~ball.long_gap)
        ct = t[ci]
        exact = np.zeros(ct.shape, dtype=bool)
        k_index = np.arange(len(ct))
        coarse_lag = np.full(ct.shape, np.nan)
    alpha = (np.asarray(event_alpha, dtype=float) if event_alpha is not None
             else np.full(len(ct), np.nan))
    return _Contacts(ct, ci, exact, k_index, alpha, coarse_lag)


def _flights_around(t, racket: _Racket, ball: _Ball, contacts: _Contacts,
                    s: ExtractionSettings):
    """The flight fits between consecutive contacts (and before the first, after the last):
    per contact the fit after it and the fit before it (None where there is none); ``imp``'s
    sticking reasons, long gaps and free flights are filled on the way."""
    ct, ci = contacts.t, contacts.index
    n = len(ct)
    imp = _Impacts.at(contacts)
    bounds = np.concatenate([[-s.guard_samples - 1], ci, [len(t) + s.guard_samples]])
    afters: list[FlightFit | None] = [None] * n
    befores: list[FlightFit | None] = [None] * n
    for j in range(n + 1):
        lo = bounds[j] + s.guard_samples + (0 if j == 0 else 1)
        hi = bounds[j + 1] - s.guard_samples
        t_after = ct[j - 1] if j > 0 else t[0]
        t_before = ct[j] if j < n else t[-1]
        after, before, rest_s, has_gap, racket_gap = _segment_fits(
            t, ball.fit, ball.long_gap, racket.bridged, lo, hi, t_after, t_before, s)
        if rest_s == 0.0:  # a free flight: its curvature is g
            flight = after if after is not None else before
            if flight is not None and flight.samples is not None:
                imp.flights.append(flight.samples)
        if j > 0:
            afters[j - 1] = after
            if rest_s > 0.0:
                imp.reason[j - 1] = f"sticking: the ball rested on the racket for {rest_s:.3g} s"
            if has_gap:
                imp.next_unknown[j - 1] = True
            imp.racket_gap[j - 1] = racket_gap
        if j < n:
            befores[j] = before
    return imp, afters, befores


def _impacts_from_flights(t, racket: _Racket, ball: _Ball, contacts: _Contacts,
                          s: ExtractionSettings) -> _Impacts:
    """Each contact located where its two flights meet (or where the flight after meets the
    racket), with v_k, the velocity before, the contact's area, the SEs and the apex."""
    imp, afters, befores = _flights_around(t, racket, ball, contacts, s)
    ct, ci, exact = contacts.t, contacts.index, contacts.exact
    n, g = len(ct), s.g
    # a contact in a bridged gap is timed from the flights either side: anywhere in it
    gap_width = np.array([_run_width(t, ~ball.measured, i) for i in ci]) if n else ci
    for j in range(n):
        after, before = afters[j], befores[j]
        if imp.reason[j]:
            continue
        if after is None:
            near_gap = np.any(ball.long_gap[max(ci[j] - 3, 0):ci[j] + 4])
            imp.reason[j] = ("gap: no ball data after the impact"
                             if near_gap or imp.next_unknown[j]
                             else "no free flight after the impact")
            continue
        # where the two flights meet, as ct[j] less this (both parabolas have the same g: their
        # difference is linear in t); NaN without a flight before or with parallel ones
        meet = ((after.x0 - before.x0) / (after.v0 - before.v0)
                if before is not None and abs(after.v0 - before.v0) > 0.0 else math.nan)
        if exact[j] and abs(meet) <= EVENT_LAG_MAX_S:
            # the event's time against the ball's own contact (the event log's clock against
            # the recording's)
            imp.event_lag[j] = meet
        if not exact[j]:
            if math.isfinite(meet):
                tj = ct[j] - meet
                if abs(tj - ct[j]) <= 3.0 * _spacing(t, ci[j]) + gap_width[j]:
                    imp.t_k[j] = tj
                    imp.met[j] = True
                    imp.offsets.append(float(after.position(tj, g))
                                       - racket.position(t, tj, s))
                else:
                    imp.t_k[j] = _meet_racket(t, racket, after, ct[j], s)
            else:
                imp.t_k[j] = _meet_racket(t, racket, after, ct[j], s)
        if not math.isfinite(imp.t_k[j]):
            # keep the detected sample's time: the impact is listed (excluded.csv) at it,
            # the hops and the count of impacts lost in gaps stay defined, and k skips it
            imp.t_k[j] = ct[j]
            imp.reason[j] = "contact not located"
            continue
        _velocities_at(t, racket, ball, imp, j, after, before, exact[j],
                       ct[j + 1] if j + 1 < n else t[-1], _spacing(t, ci[j]), s)
    return imp


def _velocities_at(t, racket: _Racket, ball: _Ball, imp: _Impacts, j: int, after: FlightFit,
                   before: FlightFit | None, exact: bool, t_next: float, spacing: float,
                   s: ExtractionSettings) -> None:
    """Impact ``j`` at its located time: v_k and its SE, the velocity before and the
    contact's area, the marker offset, the apex of the flight after."""
    g, t_k = s.g, imp.t_k[j]
    imp.v_k[j] = float(after.velocity(t_k, g))
    if before is not None:
        imp.v_in[j] = float(before.velocity(t_k, g))
        imp.area[j] = _contact_area(t, ball.fit, before, after, g)
        closing = float(imp.v_in[j] - imp.v_k[j])
        if not exact and closing > 0.0:
            imp.var_t[j] = (before.position_var(t_k) + after.position_var(t_k)) / closing**2
    imp.se_v[j] = math.sqrt(after.cov[1][1] + g * g * imp.var_t[j])
    racket_here = racket.local(t, t_k, s.position_half_window_s, s.position_degree)[1]
    if racket_here is not None and imp.met[j]:
        imp.offset_k[j] = float(after.position(t_k, g)) - racket_here.x
    x_k = float(after.position(t_k, g)) - s.ball_offset_m
    rise = max(imp.v_k[j], 0.0) / g
    if t_k + rise <= min(t_next, after.t_last + 0.5 * spacing):
        imp.apex_x[j] = x_k + 0.5 * max(imp.v_k[j], 0.0) * rise


def _impacts_from_racket(t, racket: _Racket, contacts: _Contacts,
                         s: ExtractionSettings) -> _Impacts:
    """Without ball data: v_k from eq. 1 between two impacts with the racket positions at
    both, and the apex it gives; the last impact has no flight time."""
    imp = _Impacts.at(contacts)
    n, g = len(imp.t_k), s.g
    for j in range(n - 1):
        h = imp.t_k[j + 1] - imp.t_k[j]
        x0 = racket.position(t, imp.t_k[j], s)
        x1 = racket.position(t, imp.t_k[j + 1], s)
        imp.v_k[j] = (x1 - x0) / h + 0.5 * g * h  # eq. 1 at both impacts
        rise = max(imp.v_k[j], 0.0) / g
        imp.apex_x[j] = x0 + 0.5 * max(imp.v_k[j], 0.0) * rise
    if n:
        imp.reason[n - 1] = "last impact of the trial: no flight time (no ball data)"
    return imp


def _lost_in_gap(lost: int) -> str:
    """excluded.csv's words for the impacts a long gap hid, estimated from the time between
    the impacts on either side in typical hops: "about 2 impact(s) lost in it", or, where
    that time is about one hop, that none was."""
    return (f"about {lost} impact(s) lost in it" if lost else
            "probably no impact lost in it (the time across it is about one typical hop)")


def _hops_and_gaps(t, racket: _Racket, ball: _Ball | None, contacts: _Contacts,
                   imp: _Impacts, from_events: bool, s: ExtractionSettings,
                   excluded: list[tuple[float, str]]):
    """The hops (NaN into a long gap), the impacts lost in long gaps of the ball data (counted
    into k, reported in ``excluded``), chatter, and racket gaps in a flight without ball data:
    (hop, k)."""
    t_k, reason, next_unknown = imp.t_k, imp.reason, imp.next_unknown
    n = len(t_k)
    k_index = contacts.k
    hop = np.append(np.diff(t_k), np.nan)
    hop[next_unknown] = np.nan
    racket_gap = imp.racket_gap
    if ball is not None and not from_events and (next_unknown | racket_gap).any():
        # impacts inside a long gap of the ball data are lost: estimate how many from the
        # typical hop, report them, and keep k counting them; the same for a bounce hidden
        # where the racket's data are missing (no contact seen there: the hop spans two)
        spans = np.diff(t_k)
        known = spans[~next_unknown[:-1] & ~racket_gap[:-1] & np.isfinite(spans)]
        typical = float(np.median(known)) if known.size else math.nan
        lost = np.zeros(n, dtype=int)
        for j in np.flatnonzero((next_unknown | racket_gap)[:-1]).tolist():
            lost[j] = max(int(round(spans[j] / typical)) - 1, 0) if math.isfinite(typical) else 0
            lo, hi = np.searchsorted(t, [t_k[j], t_k[j + 1]])
            if not next_unknown[j]:  # the racket's data missing, the ball's there
                if lost[j]:
                    hop[j] = math.nan
                    gone = np.flatnonzero(~np.isfinite(racket.bridged[lo:hi])) + lo
                    excluded.append((float(np.mean(t[gone])),
                                     f"gap: {t[gone[-1]] - t[gone[0]]:.3g} s without racket "
                                     f"data; {_lost_in_gap(lost[j])}"))
                continue
            missing = np.flatnonzero(~np.isfinite(ball.bridged[lo:hi])) + lo
            if missing.size:  # empty cells
                at, span = float(np.mean(t[missing])), t[missing[-1]] - t[missing[0]]
            else:  # rows missing: the longest stretch between samples
                i = lo + int(np.argmax(np.diff(t[lo:hi + 1]))) if hi > lo else lo
                after = t[min(i + 1, len(t) - 1)]
                at, span = 0.5 * (t[i] + after), after - t[i]
            excluded.append((float(at), f"gap: {span:.3g} s without ball data; "
                             f"{_lost_in_gap(lost[j])}"))
        k_index = k_index + np.concatenate([[0], np.cumsum(lost)[:-1]])
    for j in range(n):
        if not reason[j] and math.isfinite(hop[j]) and hop[j] < s.sticking_hop_s:
            reason[j] = f"chatter: hop {hop[j]:.3g} s < sticking_hop_s"
        if ball is None and not reason[j]:
            lo, hi = np.searchsorted(t, [t_k[j], t_k[j + 1] if j + 1 < n else t[-1]])
            if np.any(racket.long_gap[max(lo - 1, 0):hi + 1]):
                reason[j] = "gap: racket data missing in the flight"
    return hop, k_index


def _racket_at_impacts(t, racket: _Racket, imp: _Impacts, s: ExtractionSettings):
    """Each impact's racket cycle and phase, AC (the racket's second derivative, eq. 4's
    a_r w^2 / g), and eq. 3's alpha from the racket's velocity there (local fit), with the
    contact's duration; the racket fits' residual sum of squares and dof:
    (cycle, theta, AC, alpha measured, rss, dof)."""
    t_k, reason, g = imp.t_k, imp.reason, s.g
    n = len(t_k)
    cycles = racket.cycles
    cycle, theta = cycles.locate(t_k)
    acc = np.full(n, np.nan)
    period = float(np.median(cycles.periods)) if cycles.periods.size else 0.0
    for j in range(n):
        if reason[j]:
            continue
        if cycle[j] < 0:
            # a cycle with a long racket gap is not a cycle: say so when that is why (a gap of
            # missing cells, or of missing rows: samples further apart than max_gap_s)
            lo, hi = np.searchsorted(t, [t_k[j] - period, t_k[j] + period])
            gap = (np.any(racket.long_gap[lo:hi])
                   or np.any(np.diff(t[max(lo - 1, 0):hi + 1]) > s.max_gap_s))
            reason[j] = ("gap: racket data missing in the impact's racket cycle" if gap
                         else "outside a complete racket cycle")
            continue
        here = racket.local(t, t_k[j], s.acc_half_window_s, s.acc_degree)[1]
        acc[j] = math.nan if here is None else here.acc / g
        if not math.isfinite(acc[j]) or not math.isfinite(imp.v_k[j]):
            reason[j] = "gap: too few racket samples around the impact"
    # eq. 3 at t_k with the racket's velocity there (local fit), and the racket's residuals
    alpha_measured = np.full(n, np.nan)
    racket_rss, racket_dof = 0.0, 0
    for j in range(n):
        if reason[j]:
            continue
        here = racket.local(t, t_k[j], s.acc_half_window_s, s.acc_degree)[1]
        if here is None:
            continue
        if math.isfinite(here.rss) and here.dof > 0:
            racket_rss, racket_dof = racket_rss + here.rss, racket_dof + here.dof
        # the racket's velocity from a fit of velocity_degree over the same window: a quartic's
        # slope is biased by the racket's fifth derivative a_r w^5 (alpha +1.7e-3 at tau 0.5 s)
        moving = racket.local(t, t_k[j], s.acc_half_window_s, s.velocity_degree)[1]
        v_racket = here.v if moving is None else moving.v
        if math.isfinite(imp.v_in[j]) and imp.v_in[j] < v_racket:  # approaching the racket
            alpha_measured[j] = restitution_of(imp.v_in[j], imp.v_k[j], v_racket)
            shape = (contact_shape_factor(alpha_measured[j])
                     if 0.0 < alpha_measured[j] < 1.0 else math.nan)
            # K(alpha) <= 0 below alpha ~ 0.296: there the area does not measure the duration
            if shape > 0.0 and math.isfinite(imp.area[j]):
                imp.weight[j] = (v_racket - imp.v_in[j]) * shape
                imp.contact[j] = math.sqrt(max(imp.area[j], 0.0) / imp.weight[j])
    return cycle, theta, acc, alpha_measured, racket_rss, racket_dof


def extract_trial(t, racket, ball=None, event_t=None, event_alpha=None,
                  s: ExtractionSettings = ExtractionSettings(),
                  cache: dict | None = None) -> TrialExtraction:
    """Impacts of one trial (see the module docstring). ``ball`` may be None when events give
    the impact times; ``event_alpha`` (optional) the coefficient of restitution per event.
    ``cache`` (a dict kept for the trial's samples, empty at first): the racket's cycles and
    the bridged samples, found once and reused by later passes over the same samples at
    another g or marker offset (neither enters them).

    In steps: the racket's cycles, the contacts (events or detected), the flights around each
    contact (or, without ball data, eq. 1 between impacts), hops and gaps, the racket at each
    impact; then the reported impacts and the excluded ones."""
    t = np.asarray(t, dtype=float)
    dt = float(np.median(np.diff(t)))
    s = replace(widened_windows(s, dt), guard_samples=guard_samples(s, dt))
    g = s.g
    key = replace(s, g=0.0, ball_offset_m=0.0)  # what the racket's cycles depend on
    if cache is not None and cache.get("key") == key:
        racket_, ball_ = cache["racket"], cache["ball"]
    else:
        racket_ = _racket_of(t, racket, s)
        ball_ = None if ball is None else _ball_of(t, ball, s)
        if cache is not None:
            cache.update(key=key, racket=racket_, ball=ball_)
    excluded: list[tuple[float, str]] = []
    contacts = _contacts_of(t, racket_, ball_, event_t, event_alpha, s, excluded)
    imp = (_impacts_from_flights(t, racket_, ball_, contacts, s) if ball_ is not None
           else _impacts_from_racket(t, racket_, contacts, s))
    hop, k_index = _hops_and_gaps(t, racket_, ball_, contacts, imp, event_t is not None, s,
                                  excluded)
    cycle, theta, acc, alpha_measured, racket_rss, racket_dof = _racket_at_impacts(
        t, racket_, imp, s)
    t_k, n, cycles = imp.t_k, len(imp.t_k), racket_.cycles
    keep = np.array([not r for r in imp.reason], dtype=bool)
    for j in np.flatnonzero(~keep).tolist():
        excluded.append((float(t_k[j]), imp.reason[j]))
    excluded.sort()
    if not keep.any():
        raise ModelError("no bounce found" + (f" ({excluded[0][1]}, ...)" if excluded else ""))
    apex_t = t_k + np.maximum(imp.v_k, 0.0) / g
    mid_apex = np.full(n, np.nan)
    mid_apex[keep] = cycles.mid_position(apex_t[keep])
    cc = np.maximum(cycle, 0)
    impacts = {
        "k": k_index[keep],
        "t_s": t_k[keep],
        "theta_rad": theta[keep],
        "theta_deg": np.degrees(theta[keep]),
        "v_m_s": imp.v_k[keep],
        "racket_acc_g": acc[keep],
        "racket_period_s": cycles.periods[cc][keep],
        "racket_amplitude_m": cycles.amplitudes[cc][keep],
        "hop_s": hop[keep],
        "ball_apex_m": (imp.apex_x - mid_apex)[keep],
    }
    if event_t is not None:
        impacts["alpha"] = contacts.alpha[keep]
    if ball_ is not None:
        impacts["v_in_m_s"] = imp.v_in[keep]
        impacts["alpha_measured"] = alpha_measured[keep]
        impacts["contact_s"] = imp.contact[keep]
    offset = float(np.median(imp.offsets)) if imp.offsets else math.nan
    se_theta = _phase_se(t, racket_, t_k, imp.var_t, s)
    return TrialExtraction(impacts, excluded, cycles, offset, imp.flights, imp.offset_k[keep],
                           imp.se_v[keep], se_theta[keep], racket_rss, racket_dof,
                           imp.area[keep], imp.weight[keep], imp.event_lag[keep],
                           contacts.coarse_lag)


def _contact_area(t, ball, before: FlightFit, after: FlightFit, g: float) -> float:
    """The area (m s) of the ball's positions above the higher of its two flights,
    extrapolated, between the fits' samples: sum of the deviations times the sampling
    interval (over a uniformly random sampling phase its mean is the integral)."""
    lo = np.searchsorted(t, before.t_last, side="right")
    hi = np.searchsorted(t, after.t_first, side="left")
    if hi <= lo:
        return math.nan
    tt, xx = t[lo:hi], ball[lo:hi]
    if not np.all(np.isfinite(xx)):
        return math.nan  # a gap in the contact: its area is unknown
    step = (after.t_first - before.t_last) / (hi - lo + 1)
    envelope = np.maximum(before.position(tt, g), after.position(tt, g))
    return float(np.sum(xx - envelope) * step)


def contact_duration(areas, weights) -> tuple[float, float, int]:
    """The session's contact duration from its impacts' areas and weights
    (``contact_shape_factor``): T^2 = sum(area) / sum(weight), a noisy area weighing by its
    impact's closing speed; SE by the delta method from the areas' scatter.

    Parameters
    ----------
    areas, weights : array
        Per impact (NaN: not measured).

    Returns
    -------
    tuple
        (T in s, its SE, the number of impacts).
    """
    a, w = np.asarray(areas, dtype=float), np.asarray(weights, dtype=float)
    ok = np.isfinite(a) & np.isfinite(w) & (w > 0.0)
    a, w = a[ok], w[ok]
    if a.size == 0:
        return math.nan, math.nan, 0
    t2 = float(np.sum(a) / np.sum(w))
    duration = math.sqrt(max(t2, 0.0))
    if a.size < 2 or duration == 0.0:
        return duration, math.nan, int(a.size)
    resid = a - t2 * w
    se_t2 = math.sqrt(float(np.sum(resid * resid)) * a.size / (a.size - 1)) / float(np.sum(w))
    return duration, se_t2 / (2.0 * duration), int(a.size)


@functools.lru_cache(maxsize=1)
def _gauss_legendre_64() -> tuple[np.ndarray, np.ndarray]:
    """The 64-point Gauss-Legendre nodes and weights, computed once (read-only)."""
    nodes, weights = np.polynomial.legendre.leggauss(64)
    nodes.flags.writeable = weights.flags.writeable = False
    return nodes, weights


def contact_shape_factor(alpha: float) -> float:
    """K(alpha) of a linear spring-damper contact (restitution alpha): the area between the
    ball's path in the contact and its two free flights extrapolated (the V they make, meeting
    at the equivalent impact) is K |u| T^2 for closing velocity u and contact duration T.
    On u = -1, T = 1: y(s) = -exp(-zeta omega_n s) sin(pi s) / pi against max(-s, alpha (s - 1)).

    Parameters
    ----------
    alpha : float
        Restitution, in (0, 1).

    Returns
    -------
    float
        K, dimensionless: positive above alpha ~ 0.296, where it crosses zero (a heavily
        damped contact's path lies inside the V as much as outside it), negative below; the
        contact's duration is measured only where K > 0.
    """
    log = math.log(alpha)
    zeta = -log / math.sqrt(math.pi**2 + log * log)
    decay = zeta * math.pi / math.sqrt(1.0 - zeta * zeta)
    nodes, weights = _gauss_legendre_64()
    s_eq = alpha / (1.0 + alpha)  # the flights meet: -s = alpha (s - 1)

    def part(a: float, b: float, v_line) -> float:
        s_ = 0.5 * (b - a) * nodes + 0.5 * (a + b)
        path = -np.exp(-decay * s_) * np.sin(math.pi * s_) / math.pi
        return float(0.5 * (b - a) * np.sum(weights * (path - v_line(s_))))

    return part(0.0, s_eq, lambda s_: -s_) + part(s_eq, 1.0, lambda s_: alpha * (s_ - 1.0))


def _phase_se(t, racket: _Racket, t_k, var_t, s: ExtractionSettings):
    """Standard error of each theta_k = 2 pi (t_k - c0) / (c1 - c0): t_k's variance
    ``var_t`` and each crossing's (the racket fit's position variance there over its slope
    squared), independent."""
    out = np.full(len(t_k), np.nan)
    cycles = racket.cycles
    c, _ = cycles.locate(t_k)

    def var_at(tc: float) -> float:
        fit = racket.local(t, tc, s.position_half_window_s, s.position_degree)[1]
        return fit.var_x / fit.v**2 if fit is not None and fit.v != 0.0 else math.nan

    for j in np.flatnonzero(c >= 0).tolist():
        c0 = float(cycles.crossings[c[j]])
        period = float(cycles.periods[c[j]])
        u = (t_k[j] - c0) / period
        var = var_t[j] + (1.0 - u) ** 2 * var_at(c0) + u * u * var_at(c0 + period)
        out[j] = TWO_PI / period * math.sqrt(var)
    return out


def _run_width(t, mask, i: int) -> float:
    """Time between the samples either side of the run of ``mask`` holding sample i (0 when
    ``mask[i]`` is False)."""
    if not mask[i]:
        return 0.0
    lo, hi = i, i
    while lo > 0 and mask[lo - 1]:
        lo -= 1
    while hi < len(mask) - 1 and mask[hi + 1]:
        hi += 1
    return float(t[min(hi + 1, len(t) - 1)] - t[max(lo - 1, 0)])


def _spacing(t, i: int) -> float:
    i = int(min(max(i, 1), len(t) - 1))
    return float(t[i] - t[i - 1])


def _meet_racket(t, racket: _Racket, after: FlightFit, t_crude: float,
                 s: ExtractionSettings) -> float:
    """Where the fitted flight after a contact meets the racket (local cubic) near t_crude."""
    h = s.position_half_window_s
    coef = racket.local(t, t_crude, h, s.position_degree)[0]
    if coef is None:
        return math.nan
    # the flight in s = (t - t_crude) / h, minus the racket polynomial
    d = t_crude - after.t_ref
    flight = np.array([after.x0 + after.v0 * d - 0.5 * s.g * d * d - s.ball_offset_m,
                       (after.v0 - s.g * d) * h, -0.5 * s.g * h * h])
    diff = np.zeros(max(len(coef), 3))
    diff[:3] += flight
    diff[:len(coef)] -= coef
    return _poly_root_near(diff, h, t_crude)


def match_impacts(truth_t, found_t, tolerance_s: float | None = None) -> np.ndarray:
    """For each found impact time, the index of the nearest true impact within
    ``tolerance_s`` (default: a quarter of the true impacts' median spacing), else -1."""
    truth_t = np.asarray(truth_t, dtype=float)
    found_t = np.asarray(found_t, dtype=float)
    if truth_t.size == 0:
        return np.full(found_t.shape, -1)
    if tolerance_s is None:
        tolerance_s = 0.25 * float(np.median(np.diff(truth_t))) if truth_t.size > 1 else 0.1
    j = np.clip(np.searchsorted(truth_t, found_t), 1, max(truth_t.size - 1, 1))
    j = np.minimum(j, truth_t.size - 1)
    left = np.maximum(j - 1, 0)
    nearest = np.where(np.abs(truth_t[left] - found_t) <= np.abs(truth_t[j] - found_t), left, j)
    return np.where(np.abs(truth_t[nearest] - found_t) <= tolerance_s, nearest, -1)
