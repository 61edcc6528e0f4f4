"""Basin entropy (Daza et al. 2016) and the uncertainty exponent on grids with known answers."""

import math

import numpy as np
import pytest

from bounce_cli.analysis.basin_measures import basin_entropy, uncertainty_exponent


def test_one_outcome_has_zero_entropy():
    result = basin_entropy(np.zeros((50, 40), dtype=int), box=5)
    assert result.basin_entropy == 0.0 and result.boundary_basin_entropy == 0.0
    assert result.boxes == 10 * 8 and result.boundary_boxes == 0


def test_straight_boundary_through_box_middles():
    # columns 0..22 outcome 0, 23.. outcome 1: the boundary splits every box of column
    # block 4 (cells 20..24) into 3:2 -> S_i = -(0.6 ln 0.6 + 0.4 ln 0.4) in those boxes only
    grid = np.zeros((30, 50), dtype=int)
    grid[:, 23:] = 1
    result = basin_entropy(grid, box=5)
    s = -(0.6 * math.log(0.6) + 0.4 * math.log(0.4))
    assert result.boxes == 6 * 10 and result.boundary_boxes == 6
    assert result.boundary_basin_entropy == pytest.approx(s, rel=1e-12)
    assert result.basin_entropy == pytest.approx(s * 6 / 60, rel=1e-12)
    # the smooth boundary stays below the fractal criterion ln 2
    assert result.boundary_basin_entropy < math.log(2)


def test_random_two_colour_grid_reaches_ln2_and_boxes_ignore_the_ragged_edge():
    rng = np.random.default_rng(0)
    grid = rng.integers(0, 2, size=(503, 497))
    result = basin_entropy(grid, box=5)
    assert result.boxes == 100 * 99  # the 3 last rows and 2 last columns are left out
    # each box: 25 fair coin flips -> expected entropy slightly below ln 2
    assert 0.62 < result.basin_entropy < math.log(2)
    three = basin_entropy(rng.integers(0, 3, size=(500, 500)), box=5)
    assert three.boundary_basin_entropy > math.log(2)  # well mixed: fractal-like criterion


def test_grid_smaller_than_a_box_is_refused():
    with pytest.raises(ValueError, match="smaller than one box"):
        basin_entropy(np.zeros((3, 10)), box=5)


def test_uncertainty_exponent_of_smooth_and_rough_boundaries():
    rng = np.random.default_rng(1)
    eps = np.geomspace(1e-4, 1e-2, 5)

    def half_plane(x, y):
        return (x > 0.3 + 0.2 * y).astype(int)

    smooth = uncertainty_exponent(half_plane, (0, 1), (0, 1), eps, 20000, rng)
    assert smooth.alpha == pytest.approx(1.0, abs=0.1)
    # the uncertain fraction of a straight boundary: about 2 eps (one eps either side in x)
    # plus the y-moves' contribution 2 * 0.2 eps -> 2.4 eps
    assert smooth.uncertain_fraction[-1] == pytest.approx(2.4e-2, rel=0.15)

    def noise(x, y):  # outcome random per cell of 1e-6: every eps above it uncertain -> alpha 0
        i, j = np.floor(x * 1e6), np.floor(y * 1e6)
        return (np.mod(np.sin(i * 12.9898 + j * 78.233) * 43758.5453, 1.0) > 0.5).astype(int)

    rough = uncertainty_exponent(noise, (0, 1), (0, 1), eps, 2000, rng)
    assert abs(rough.alpha) < 0.05


def test_an_uncertainty_exponent_from_a_handful_of_uncertain_points_is_withheld():
    """300 samples of a straight boundary: 5, 6 and 8 uncertain points at the three
    eps. Fitted through them the slope is noise (the review of a sweep found -0.08 and 1.6
    where the exponent lies in [0, 1]); no eps has MIN_UNCERTAIN_POINTS, so NaN."""
    from bounce_cli.analysis.basin_measures import MIN_UNCERTAIN_POINTS

    def half_plane(x, y):
        return (x > 0.3 + 0.2 * y).astype(int)

    eps = np.array([5e-3, 1e-2, 2e-2])
    fit = uncertainty_exponent(half_plane, (0, 1), (0, 1), eps, 300, np.random.default_rng(2))
    counts = np.round(fit.uncertain_fraction * 300)
    assert (counts > 0).sum() >= 2 and (counts >= MIN_UNCERTAIN_POINTS).sum() < 2, counts
    assert np.isnan(fit.alpha) and np.isnan(fit.alpha_se)
    # with enough samples the same boundary gives its exponent, 1
    fit = uncertainty_exponent(half_plane, (0, 1), (0, 1), eps, 20000, np.random.default_rng(2))
    assert fit.alpha == pytest.approx(1.0, abs=0.1)
