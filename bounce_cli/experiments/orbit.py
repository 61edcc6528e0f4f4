"""The engine commands' tables: ``bounce fixed-point``'s report and ``bounce orbit``'s rows.

An orbit is iterated three ways (the command line chooses by the config and ``--min-hop-s``):
the passive map of eqs. 5, 6 (:func:`passive_orbit`), the map with the racket period as a
third state (:func:`controlled_orbit`, ``model.control``), and the exact hybrid orbit with
complete chatters, riding and release (:func:`exact_orbit`, ``--min-hop-s 0``). Each gives an
:class:`OrbitTable`: the frame ``--csv`` writes, its title, and the notes the user should
read beside it. The command line only renders them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..model.linear import stability
from ..model.impact import check_period1_orbit
from ..model.params import ModelParams, wrap_phase


def fixed_point_report(params: ModelParams) -> dict:
    """``bounce fixed-point``'s numbers: the period-1 fixed point (eqs. 7, 8), the racket
    acceleration at impact AC (section 4), the eigenvalues and spectral radius (eq. 10).

    Parameters
    ----------
    params : ModelParams
        The model's parameters.

    Returns
    -------
    dict
        ``v_m_s``, ``theta_rad``, ``theta_deg``, ``ac_g``, ``eigenvalues`` (pairs of real and
        imaginary part), ``spectral_radius``, ``regime``, ``stable``: JSON-able.

    Raises
    ------
    NoFixedPointError
        Where eq. 8 has no solution or its point is no orbit of the map
        (``check_period1_orbit``).
    """
    check_period1_orbit(params)
    fp = params.fixed_point()
    st = stability(params)
    return {
        "v_m_s": fp.v_m_s,
        "theta_rad": fp.theta_rad,
        "theta_deg": fp.theta_deg,
        "ac_g": st.ac_g,
        "eigenvalues": [[lam.real, lam.imag] for lam in st.eigenvalues],
        "spectral_radius": st.spectral_radius,
        "regime": st.regime,
        "stable": st.stable,
    }


def no_fixed_point_report(params: ModelParams, error: Exception) -> dict:
    """``fixed-point --json`` where eq. 8 has no solution: why, and the racket amplitude from
    which it has one at the other parameters."""
    return {"exists": False, "reason": str(error), "cos_theta": params.cos_theta_fixed(),
            "min_racket_amplitude_m": params.min_racket_amplitude()}


@dataclass
class OrbitTable:
    """An orbit as ``bounce orbit`` shows it: one row per event (``frame``, what ``--csv``
    writes), a ``title``, the ``notes`` printed below it, and the columns shown to 3
    significant digits (``small``) in the terminal's table."""

    frame: pd.DataFrame
    title: str
    notes: list[str] = field(default_factory=list)
    small: tuple[str, ...] = ()


def passive_orbit(theta0: float, v0: float, params: ModelParams, n_impacts: int,
                  min_hop_s: float) -> OrbitTable:
    """The map of eqs. 5, 6 iterated from (theta0 rad, v0 m/s) for ``n_impacts`` impacts,
    stopped at the first hop shorter than ``min_hop_s`` (sticking, section 3).

    Parameters
    ----------
    theta0, v0 : float
        The phase (rad) and velocity (m/s) with which the ball leaves the racket.
    params : ModelParams
        The model's parameters (any: the map needs no fixed point).
    n_impacts : int
        Impacts to iterate.
    min_hop_s : float
        The shortest hop, s, that is not sticking (> 0).

    Returns
    -------
    OrbitTable
        Columns ``k``, ``t_s``, ``theta_rad``, ``theta_deg`` (wrapped), ``v_m_s``,
        ``flight_s`` (the hop ending at each impact; NaN at the start), ``event``.
    """
    from ..model.maps import iterate_orbit

    orbit = iterate_orbit(theta0, v0, params, n_impacts, min_hop_s)
    w = params.omega
    frame = pd.DataFrame([
        {
            "k": k,
            "t_s": orbit.theta[k] / w,
            "theta_rad": orbit.theta[k],
            "theta_deg": math.degrees(float(wrap_phase(orbit.theta[k]))),
            "v_m_s": orbit.v[k],
            "flight_s": orbit.hop_phase[k] / w,
            "event": "start" if k == 0 else "impact",
        }
        for k in range(len(orbit.theta))
    ])
    return OrbitTable(frame, f"Orbit from theta0 = {math.degrees(theta0):g} deg, v0 = {v0:g} m/s",
                      passive_notes(orbit, params, min_hop_s))


def controlled_orbit(theta0: float, v0: float, params: ModelParams, controller,
                     n_impacts: int, min_hop_s: float) -> OrbitTable:
    """:func:`passive_orbit` with racket period control (``model.control``,
    ``model.control.iterate_controlled_orbit``): the passive columns plus
    ``racket_period_s`` (the period of the flight ending at each impact)."""
    from ..model.control import iterate_controlled_orbit

    orbit = iterate_controlled_orbit(theta0, v0, params, controller, n_impacts, min_hop_s)
    frame = pd.DataFrame({"k": np.arange(len(orbit.theta)), "t_s": orbit.t_s,
                          "theta_rad": orbit.theta,
                          "theta_deg": np.degrees(wrap_phase(orbit.theta)), "v_m_s": orbit.v,
                          "flight_s": orbit.flight_s,
                          "event": ["start", *["impact"] * (len(orbit.theta) - 1)],
                          "racket_period_s": orbit.tau})
    notes = []
    if orbit.stop_reason == "below_racket":
        notes.append(f"note: stopped: the initial velocity {v0:g} m/s is not above the "
                     f"racket's velocity at that phase (below the racket)")
    elif orbit.stop_reason == "sticking":
        notes.append(f"note: stopped at impact {len(orbit.theta) - 1}: the hop lasted "
                     f"{orbit.flight_s[-1]:.3g} s < {min_hop_s:g} s, or the ball could not "
                     f"leave the racket (sticking)")
    return OrbitTable(frame, f"Orbit with racket period control from theta0 = "
                             f"{math.degrees(theta0):g} deg, v0 = {v0:g} m/s", notes)


def exact_orbit(theta0: float, v0: float, params: ModelParams, n_impacts: int) -> OrbitTable:
    """The hybrid orbit of ``model.chatter`` (``bounce orbit --min-hop-s 0``): impacts,
    accumulation points of complete chatters, releases, one row per event; ``k`` counts the
    resolved impacts (a stick or release row carries the k of the impact before it)."""
    from ..model.chatter import IMPACT, iterate_exact_orbit, locked_period

    orbit = iterate_exact_orbit(theta0, v0, params, n_impacts)
    w = params.omega
    frame = pd.DataFrame({
        "k": np.cumsum(np.asarray(orbit.event, dtype=object) == IMPACT),
        "t_s": orbit.theta / w, "theta_rad": orbit.theta,
        "theta_deg": np.degrees(wrap_phase(orbit.theta)), "v_m_s": orbit.v,
        "flight_s": orbit.flight / w, "event": orbit.event,
        "chatter_impacts": orbit.chatter_impacts, "tail_error_s": orbit.tail_error_s,
    })
    return OrbitTable(frame, f"Exact orbit from theta0 = {math.degrees(theta0):g} deg, "
                             f"v0 = {v0:g} m/s",
                      exact_notes(orbit, params, locked_period(orbit)),
                      small=("flight_s", "tail_error_s"))


def below_racket_note(orbit, params: ModelParams) -> str:
    """The note of an orbit whose ball cannot leave the racket at its initial condition."""
    v_r = float(params.racket_velocity(orbit.theta[0]))
    return (f"note: stopped: the initial velocity {orbit.v[0]:g} m/s is not above the racket's "
            f"{v_r:.4f} m/s at that phase (below the racket)")


def exact_notes(orbit, params: ModelParams, cycles: int) -> list[str]:
    """:func:`passive_notes` for the hybrid orbit: below the racket, resting, or locked (with
    its period in racket cycles, the release phase and the Lyapunov exponent -inf)."""
    notes = []
    if orbit.stop_reason == "below_racket":
        notes.append(below_racket_note(orbit, params))
    elif orbit.stop_reason == "resting":
        notes.append(
            f"note: resting: the ball stuck at t = {orbit.theta[-1] / params.omega:.6g} s and "
            f"is never released (Gamma = a_r w^2 / g = "
            f"{params.gamma:.4g} <= 1)")
    elif cycles > 0:
        release = orbit.theta[orbit.rows("release")[-1]]
        notes.append(
            f"note: locked orbit: period {cycles} racket cycle{'s' if cycles > 1 else ''} "
            f"(stick, ride, release at {math.degrees(float(wrap_phase(release))):.4f} deg = "
            f"asin(1/Gamma)); Lyapunov exponent -inf (superstable)")
    return notes


def passive_notes(orbit, params: ModelParams, min_hop_s: float) -> list[str]:
    """What the user should know about an orbit: no period-1 fixed point at these parameters,
    and why it stopped early."""
    notes = []
    cos_theta = params.cos_theta_fixed()
    if cos_theta > 1.0:
        notes.append(
            f"note: no period-1 fixed point at these parameters (eq. 8 gives cos(theta~) = "
            f"{cos_theta:.4g} > 1): the orbit cannot settle on one"
        )
    if orbit.stop_reason == "below_racket":
        notes.append(below_racket_note(orbit, params))
    elif orbit.stop_reason == "sticking":
        k = len(orbit.theta) - 1
        notes.append(
            f"note: stopped at impact {k}: the hop lasted {orbit.hop_phase[k] / params.omega:.3g} s"
            f" < {min_hop_s:g} s (sticking)"
        )
    return notes
