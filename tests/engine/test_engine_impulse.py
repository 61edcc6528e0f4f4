"""engine.impulse: where a one-impact perturbation of alpha sends the full map (section 7),
and the threshold beyond which it leaves the period-1 basin, checked against the scalar
reference classifier (the paper's brentq method), an independent route."""

import math

import pytest

from bounce_cli.analysis.classify import ClassifySettings
from bounce_cli.analysis.impulse import find_threshold, perturbed_outcome
from bounce_cli.model.perturbation import perturbed_velocity
from bounce_cli.model.reference import classify_point_brentq

SCAN = dict(scan_step=0.01, bisection_tolerance=1e-4, alpha_p_max=0.99)


@pytest.mark.slow
def test_perturbed_outcome_criteria(paper_params):
    # alpha_p = alpha_0 is no perturbation: the fixed point itself, period-1 after 1 impact
    assert perturbed_outcome(paper_params, paper_params.alpha) == ("period1", 1)
    # alpha_p = 0.7: v_0 = 5.7 m/s, the Fig. 3 sticking case (section 7)
    assert perturbed_outcome(paper_params, 0.7)[0] == "sticking"
    # the criteria come from the settings: one impact is too few to settle from 0.6
    assert perturbed_outcome(paper_params, 0.6, ClassifySettings(max_iterations=1)) == (
        "undecided", 1)


@pytest.mark.parametrize("direction, expected", [(+1, 0.6337), (-1, 0.2409)])
def test_threshold_bracket_checked_by_the_reference_classifier(paper_params, direction,
                                                               expected):
    t = find_threshold(paper_params, direction, **SCAN)
    assert t.alpha_p_threshold == pytest.approx(expected, abs=1e-4)
    assert abs(t.alpha_p_outside - t.alpha_p_inside) <= SCAN["bisection_tolerance"]
    assert t.alpha_p_threshold == pytest.approx(0.5 * (t.alpha_p_inside + t.alpha_p_outside))
    # the bisection halves the scan step until the tolerance: 0.01 / 2^7 < 1e-4 <= 0.01 / 2^6
    assert t.bisection_steps == 7
    assert t.v0_threshold_m_s == perturbed_velocity(paper_params, t.alpha_p_threshold)
    fp = paper_params.fixed_point()
    inside = classify_point_brentq(fp.theta_rad, perturbed_velocity(paper_params,
                                                                     t.alpha_p_inside),
                                   paper_params)
    outside = classify_point_brentq(fp.theta_rad, perturbed_velocity(paper_params,
                                                                      t.alpha_p_outside),
                                    paper_params)
    assert inside[0] == "period1"
    assert outside[0] == t.outcome_outside == "sticking"


def test_scan_that_never_leaves_the_basin(paper_params):
    t = find_threshold(paper_params, +1, scan_step=0.01, bisection_tolerance=1e-4,
                       alpha_p_max=0.6)
    assert t.alpha_p_inside == pytest.approx(0.6)
    assert math.isnan(t.alpha_p_threshold) and math.isnan(t.alpha_p_outside)
    assert t.outcome_outside == "" and t.bisection_steps == 0


def test_islands_beyond_the_threshold_are_counted(paper_params):
    # the scan upwards finds period-1 again at 0.96-0.99 (the basin is not an interval)
    t = find_threshold(paper_params, +1, **SCAN)
    assert t.period1_beyond_in_scan == 4
    for a in (0.96, 0.99):
        assert perturbed_outcome(paper_params, a)[0] == "period1"
