"""Iteration of the ball bouncing map (eqs. 5, 6) and its stochastic version (eqs. 16-18).

The state is (theta_k, v_k): phase of the k-th impact (rad, unwrapped: theta = omega_r t_k)
and ball velocity just after it (m/s).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .impact import can_fly, next_impact_phase
from .params import ModelParams


def velocity_after_impact(theta_next, v, hop_phase, params: ModelParams, alpha=None, *,
                          cos_theta_next=None):
    """Velocity map, eq. 5:
    v_{k+1} = (1+alpha) a_r w cos(theta_{k+1}) - alpha v_k + (g alpha / w)(theta_{k+1} - theta_k).

    ``hop_phase`` is theta_{k+1} - theta_k (in eq. 16 the noiseless phi_{k+1} - theta_k).
    ``alpha`` overrides the model's coefficient of restitution for this impact (section 7).
    ``cos_theta_next``: ``np.cos(theta_next)`` if the caller has it already.
    """
    alpha = params.alpha if alpha is None else alpha
    w = params.omega
    cos_next = np.cos(theta_next) if cos_theta_next is None else cos_theta_next
    return (
        (1.0 + alpha) * params.racket_amplitude * w * cos_next
        - alpha * v
        + params.g * alpha / w * hop_phase
    )


@dataclass(frozen=True)
class MapStep:
    """One application of the map to an array of states."""

    theta: np.ndarray  # theta_{k+1}, rad (unwrapped continuation of the input phase)
    v: np.ndarray  # v_{k+1}, m/s
    hop_phase: np.ndarray  # phi_{k+1} - theta_k: phase elapsed in flight (NaN: no flight)


def map_step(theta, v, params: ModelParams, velocity_noise=0.0, phase_noise=0.0, *,
             released=None) -> MapStep:
    """Advance states (theta_k, v_k) by one impact.

    Deterministic map: eqs. 5 and 6. With noise terms (already scaled: q_v xi and q_theta xi'
    with independent xi, xi'), the stochastic map of eqs. 16-18: the noiseless next phase
    phi_{k+1} solves eq. 17, theta_{k+1} = phi_{k+1} + phase_noise (eq. 18), and
    v_{k+1} follows eq. 16 with cos(theta_{k+1}) and (phi_{k+1} - theta_k).
    States whose ball cannot leave the racket give NaN. ``released``: states that leave from
    a release point of exact sticking (``engine.chatter``; ``next_impact_phase``).
    """
    theta = np.asarray(theta, dtype=float)
    v = np.asarray(v, dtype=float)
    hop = next_impact_phase(theta, v, params, released=released)
    theta_next = theta + hop + phase_noise
    v_next = velocity_after_impact(theta_next, v, hop, params) + velocity_noise
    return MapStep(theta=theta_next, v=v_next, hop_phase=hop)


def iterate_map(theta0, v0, params: ModelParams, n_impacts: int):
    """Iterate the deterministic map n_impacts times from arrays of initial conditions.

    Returns (theta, v, hop_phase) with shapes (n_impacts + 1, *shape): row 0 is the
    initial condition (hop_phase NaN there). Once a state cannot fly, it stays NaN.
    """
    theta0, v0 = np.broadcast_arrays(np.asarray(theta0, float), np.asarray(v0, float))
    theta = np.full((n_impacts + 1,) + theta0.shape, np.nan)
    v = np.full_like(theta, np.nan)
    hop = np.full_like(theta, np.nan)
    theta[0], v[0] = theta0, v0
    for k in range(n_impacts):
        step = map_step(theta[k], v[k], params)
        theta[k + 1], v[k + 1], hop[k + 1] = step.theta, step.v, step.hop_phase
    return theta, v, hop


@dataclass(frozen=True)
class Orbit:
    """A single orbit of the deterministic map, stopped early when it can go no further.

    Arrays run over impacts k = 0..K (row 0: the initial condition, hop NaN there).
    stop_reason: "" (all impacts done) | "below_racket" (v_0 not above the racket's
    velocity: the ball cannot leave) | "sticking" (the last hop was shorter than
    ``min_hop_s``).
    """

    theta: np.ndarray
    v: np.ndarray
    hop_phase: np.ndarray
    stop_reason: str


def iterate_orbit(
    theta0: float, v0: float, params: ModelParams, n_impacts: int, min_hop_s: float
) -> Orbit:
    """Iterate eqs. 5, 6 from one initial condition for up to ``n_impacts`` impacts.

    Stops after the first hop lasting less than ``min_hop_s`` (section 3's sticking
    criterion), or at once when the ball cannot leave the racket (v_0 <= racket velocity).
    """
    theta, v, hop = [float(theta0)], [float(v0)], [np.nan]
    reason = ""
    if not can_fly(theta0, v0, params):
        reason = "below_racket"
    else:
        for _ in range(n_impacts):
            step = map_step(theta[-1], v[-1], params)
            theta.append(float(step.theta))
            v.append(float(step.v))
            hop.append(float(step.hop_phase))
            if hop[-1] / params.omega < min_hop_s:
                reason = "sticking"
                break
            if not can_fly(theta[-1], v[-1], params):  # only when alpha == 0
                reason = "sticking"
                break
    return Orbit(np.array(theta), np.array(v), np.array(hop), reason)
