"""Impulse response after a one-impact change of the coefficient of restitution (section 7).

At the period-1 fixed point (v~, theta~) of a model with alpha_0, one impact happens with
alpha_p instead: the ball leaves the racket at theta~ with v_0 (the velocity map, eq. 5, with
alpha_p), and from then on the map with alpha_0 runs, either in full (eqs. 5, 6) or linearised
about the fixed point, y_{k+1} = J y_k with the Jacobian of eq. 9 and y = (v - v~, theta - theta~).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .classify import OUTCOMES, ClassifySettings, classify_batch, classify_states
from ..model.control import ControlledMap
from ..model.linear import iterate_linear, jacobian
from ..model.maps import iterate_map
from ..model.params import ModelParams, phase_difference
from ..model.perturbation import perturbed_velocity


@dataclass(frozen=True)
class ImpulseResponse:
    """Impacts k = 0..n after the perturbed impact (k = 0): velocity after impact (m/s),
    wrapped phase (rad, in [0, 2 pi)) and deviations from the fixed point (dtheta wrapped to
    [-pi, pi))."""

    v: np.ndarray
    theta: np.ndarray
    dv: np.ndarray
    dtheta: np.ndarray


def _response(params: ModelParams, v: np.ndarray, dtheta: np.ndarray) -> ImpulseResponse:
    fp = params.fixed_point()
    return ImpulseResponse(
        v=v, theta=np.mod(fp.theta_rad + dtheta, 2.0 * math.pi), dv=v - fp.v_m_s, dtheta=dtheta
    )


def impulse_response_full(params: ModelParams, alpha_p: float, n_impacts: int) -> ImpulseResponse:
    """The full map (eqs. 5, 6) from (theta~, v_0). NaN once the ball cannot leave the racket."""
    fp = params.fixed_point()
    theta, v, _ = iterate_map(fp.theta_rad, perturbed_velocity(params, alpha_p), params, n_impacts)
    return _response(params, v, phase_difference(theta, fp.theta_rad))


def impulse_response_linear(
    params: ModelParams, alpha_p: float, n_impacts: int
) -> ImpulseResponse:
    """The linearised map y_{k+1} = J y_k (J of eq. 9) from y_0 = (v_0 - v~, 0)."""
    fp = params.fixed_point()
    y = iterate_linear(jacobian(params), [perturbed_velocity(params, alpha_p) - fp.v_m_s, 0.0],
                       n_impacts)
    return _response(params, fp.v_m_s + y[:, 0], y[:, 1])


# -- where the perturbed response goes (section 3's criteria) ----------------------------------
def perturbed_outcome(params: ModelParams, alpha_p: float,
                      settings: ClassifySettings = ClassifySettings(), *,
                      controller=None) -> tuple[str, int]:
    """Where the full map from (theta~, v_0(alpha_p)) ends with section 3's criteria (the
    basin's classifier, ``classify_batch``): ``period1`` | ``sticking`` | ``below_racket`` |
    ``undecided``, and the number of impacts until it was decided. With a racket period
    ``controller`` (``model.control``), the controlled map's outcome (the same classifier
    over the step protocol, the numpy kernel: one point does not repay loading numba)."""
    theta0, v0 = params.fixed_point().theta_rad, perturbed_velocity(params, alpha_p)
    if controller is not None:
        result = classify_states(ControlledMap.of(params, controller, require_fixed_point=True),
                                 theta0, v0, settings, kernel="numpy")
    else:
        result = classify_batch(theta0, v0, params, settings)
    return OUTCOMES[int(result.outcome)], int(result.iterations)


@dataclass(frozen=True)
class Threshold:
    """The alpha_p beyond which the perturbed response leaves the period-1 basin, found in
    one direction from alpha_0 (NaN fields and ``outcome_outside`` "" when the scan never
    leaves). ``alpha_p_inside`` / ``alpha_p_outside``: the final bracket (period-1 / not);
    ``alpha_p_threshold`` its midpoint and ``v0_threshold_m_s`` the v_0 there;
    ``period1_beyond_in_scan``: scan points beyond the first leaving one that are period-1
    again (the basin is not an interval in v_0)."""

    alpha_p_inside: float
    alpha_p_outside: float
    alpha_p_threshold: float
    v0_threshold_m_s: float
    outcome_outside: str
    bisection_steps: int
    period1_beyond_in_scan: int


def find_threshold(
    params: ModelParams, direction: int, settings: ClassifySettings = ClassifySettings(), *,
    scan_step: float, bisection_tolerance: float, alpha_p_max: float, controller=None,
) -> Threshold:
    """Scan alpha_p away from alpha_0 = params.alpha (``direction`` +1: up to ``alpha_p_max``,
    -1: down to 0) in steps of ``scan_step`` until the full response leaves the period-1
    basin (``perturbed_outcome``), then bisect between the last value inside and the first
    outside until the bracket is at most ``bisection_tolerance`` wide.

    The scan decides which boundary is found: a period-1 island narrower than a scan step
    beyond it is not seen, and one the scan does see beyond the first exit is counted in
    ``period1_beyond_in_scan``.
    """
    alpha_0 = params.alpha
    end = alpha_p_max if direction > 0 else 0.0

    def outcome(a: float) -> str:
        return perturbed_outcome(params, a, settings, controller=controller)[0]

    # steps that fit between alpha_0 and the end, the end included: 0.1 / 0.01 is
    # 9.999999999999998 in floating point, so a plain int() would drop the last step
    scan = np.arange(1, math.floor(abs(end - alpha_0) / scan_step * (1 + 1e-12)) + 1)
    values = alpha_0 + direction * scan_step * scan
    outcomes = [outcome(a) for a in values]
    leaving = [i for i, o in enumerate(outcomes) if o != "period1"]
    if not leaving:
        return Threshold(values[-1] if len(values) else alpha_0, math.nan, math.nan, math.nan,
                         "", 0, 0)
    first = leaving[0]
    inside = alpha_0 if first == 0 else float(values[first - 1])
    outside, outside_outcome = float(values[first]), outcomes[first]
    steps = 0
    while abs(outside - inside) > bisection_tolerance:
        mid = 0.5 * (inside + outside)
        o = outcome(mid)
        if o == "period1":
            inside = mid
        else:
            outside, outside_outcome = mid, o
        steps += 1
    threshold = 0.5 * (inside + outside)
    return Threshold(inside, outside, threshold, perturbed_velocity(params, threshold),
                     outside_outcome, steps, sum(o == "period1" for o in outcomes[first:]))
