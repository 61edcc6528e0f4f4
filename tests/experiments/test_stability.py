"""`bounce stability`: Fig. 5 boundaries, eigenvalues, crosscheck and section 5 predictions."""

import math

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from bounce_cli.cli.commands import app
from bounce_cli.runtime.config import bundled_config_path, load_config
from bounce_cli.model.linear import (
    ac_explicit_g,
    characteristic_c,
    empirical_contraction_rate,
    is_complex_regime,
    iterate_linear,
    jacobian,
    min_stable_spectral_radius,
    racket_acceleration_at_impact_g,
    racket_amplitude_for_ac,
    spectral_radius,
    stability,
)
from bounce_cli.model.params import ModelParams
from bounce_cli.experiments import stability as exp
from bounce_cli.experiments.base import RunOptions

SMALL = ["grid.n_alpha=13", "grid.n_ac=21", "predictions.n_ac=801"]


@pytest.fixture(scope="module")
def result():
    cfg = load_config(exp.StabilityConfig, bundled_config_path("stability"), SMALL)
    return exp.run(cfg, RunOptions())


def test_boundaries_against_closed_forms(result):
    b = result.frames["boundaries.csv"]
    assert list(b.columns) == ["alpha", "ac_flip_g", "ac_fold_g", "ac_complex_low_g",
                               "ac_complex_high_g"]
    a = b.alpha.to_numpy()
    assert a.min() == pytest.approx(-0.2) and a.max() == pytest.approx(1.0)
    np.testing.assert_allclose(b.ac_flip_g, -2 * (1 + a**2) / (1 + a) ** 2)
    # eq. 11's two values, as (low, high) at every alpha (a review found low above high for
    # alpha < 0, where the diagram's grid runs as algebra)
    other = -((1 - a) / (1 + a)) ** 2
    np.testing.assert_allclose(b.ac_complex_low_g, np.minimum(-1.0, other))
    np.testing.assert_allclose(b.ac_complex_high_g, np.maximum(-1.0, other))
    assert (b.ac_fold_g == 0).all() and (b.ac_complex_low_g <= b.ac_complex_high_g).all()
    # |lambda| = 1 on the flip and fold boundaries (eq. 14); c^2 = alpha^2 on eq. 11's
    inside = a < 1
    for col in ("ac_flip_g", "ac_fold_g"):
        np.testing.assert_allclose(spectral_radius(a[inside], b[col][inside].to_numpy()), 1.0,
                                   atol=1e-9)
    for col in ("ac_complex_low_g", "ac_complex_high_g"):
        c = characteristic_c(a, b[col].to_numpy())
        np.testing.assert_allclose(c**2, a**2, atol=1e-12)
    # eq. 11 as printed (-(..)^2 < AC < -1) holds only for alpha < 0: for alpha > 0 the
    # complex regime is -1 < AC < -((1-alpha)/(1+alpha))^2
    assert (b.ac_complex_high_g[a > 1e-9] > -1).all()
    assert (b.ac_complex_low_g[a < -1e-9] < -1).all()
    mid = (b.ac_complex_low_g + b.ac_complex_high_g) / 2
    assert is_complex_regime(a, mid.to_numpy())[np.abs(a) > 1e-9].all()


def test_eigen_grid_against_numpy_on_the_jacobian(result):
    e = result.frames["eigen.csv"]
    assert len(e) == 13 * 21
    # a Jacobian with the same (alpha, AC): trace 1 + alpha^2 + (1+alpha)^2 AC, det alpha^2
    for row in e.sample(40, random_state=0).itertuples():
        t = 1 + row.alpha**2 + (1 + row.alpha) ** 2 * row.ac_g
        J = np.array([[t - 1, -row.alpha**2 + (t - 1)], [1.0, 1.0]])  # trace t, det alpha^2
        assert np.trace(J) == pytest.approx(t) and np.linalg.det(J) == pytest.approx(row.alpha**2)
        ours = np.sort_complex([row.lambda1_re + 1j * row.lambda1_im,
                                row.lambda2_re + 1j * row.lambda2_im])
        np.testing.assert_allclose(ours, np.sort_complex(np.linalg.eigvals(J)), atol=1e-9)
        assert row.spectral_radius == pytest.approx(max(abs(ours)))
        assert row.stable == (row.spectral_radius < 1)
        assert row.regime == ("complex" if abs(row.lambda1_im) > 0 else "real")


def test_surface_follows_the_stable_region(result):
    s = result.frames["surface.csv"]
    assert (s.alpha.abs() < 1).all()
    rim = s[s.fraction.isin([0.0, 1.0])]
    np.testing.assert_allclose(rim.spectral_radius, 1.0, atol=1e-9)  # flip and fold boundaries
    inner = s[(s.fraction > 0) & (s.fraction < 1)]
    assert (inner.spectral_radius < 1).all()
    np.testing.assert_allclose(inner.spectral_radius, spectral_radius(inner.alpha, inner.ac_g))


def test_eigen_grid_matches_eq9_at_real_models():
    for alpha, ac, period in [(0.3, -0.7, 0.8), (0.5, -1.05, 0.6), (0.9, -0.2, 1.1)]:
        a_r = float(racket_amplitude_for_ac(alpha, ac, 9.81, period))
        p = ModelParams(alpha, 9.81, a_r, period)
        assert racket_acceleration_at_impact_g(p) == pytest.approx(ac, abs=1e-12)
        assert ac_explicit_g(alpha, 9.81, p.racket_amplitude, period) == pytest.approx(ac)
        frame = exp.eigen_frame(np.array([alpha]), np.array([ac]))
        radius = np.abs(np.linalg.eigvals(jacobian(p))).max()
        assert frame.spectral_radius[0] == pytest.approx(radius)


def test_crosscheck_agrees_where_stable_and_grows_where_not(result):
    c = result.frames["crosscheck.csv"]
    assert c.stable.any() and (~c.stable).any()
    assert set(c.regime[c.stable]) == {"real", "complex"}
    np.testing.assert_allclose(c.ac_g, c.ac_target_g, atol=1e-9)
    assert c.rel_diff_fd.abs().max() < 1e-6
    stable = c[c.stable]
    assert stable.rel_diff_empirical.abs().max() < 0.01
    assert (stable.left_neighbourhood_at == -1).all() and (stable.radius_empirical < 1).all()
    unstable = c[~c.stable]
    assert (unstable.radius_empirical > 1).all() and (unstable.left_neighbourhood_at > 0).all()
    assert unstable.rel_diff_empirical.abs().max() < 0.02


def test_empirical_rate_does_not_depend_on_period_at_fixed_alpha_and_ac():
    rates = []
    for period in (0.5, 0.92):
        p = ModelParams(0.5, 9.81, float(racket_amplitude_for_ac(0.5, -1.05, 9.81, period)), period)
        rates.append(empirical_contraction_rate(p).rate)
    assert rates[0] == pytest.approx(rates[1], rel=1e-3)
    assert rates[0] == pytest.approx(stability(p).spectral_radius, rel=1e-3)


def test_section5_predictions_alpha_half(result):
    p = result.frames["predictions.csv"].set_index("quantity")
    assert p.value["stable_ac_low_g"] == pytest.approx(-1.11, abs=5e-3)  # "0 to -1.11 g"
    assert p.value["stable_ac_high_g"] == 0.0
    assert p.value["min_spectral_radius_stable"] == pytest.approx(0.5, abs=1e-9)
    # attained on the complex regime: -1 < AC < -1/9
    assert p.value["min_spectral_radius_ac_low_g"] == pytest.approx(-1.0, abs=5e-3)
    assert p.value["min_spectral_radius_ac_high_g"] == pytest.approx(-1 / 9, abs=5e-3)
    assert p.value["ac_model_g"] == pytest.approx(-0.968, abs=1e-3)
    assert p.value["energy_optimal_ac_g"] == 0.0
    assert p.value["energy_optimal_spectral_radius"] == pytest.approx(1.0)


@pytest.mark.parametrize("alpha", [0.0, 0.2, 0.7, 0.95])
def test_minimum_radius_is_alpha_section4(alpha):
    best = min_stable_spectral_radius(alpha, 2001)
    assert best.spectral_radius == pytest.approx(alpha, abs=1e-9)
    # and never below alpha anywhere on the stable range (the inequality of section 4)
    ac = np.linspace(-2 * (1 + alpha**2) / (1 + alpha) ** 2, 0, 5001)[1:-1]
    assert spectral_radius(alpha, ac).min() >= alpha - 1e-12


def test_iterate_linear_powers():
    J = np.array([[0.5, 1.0], [0.0, 0.25]])
    y = iterate_linear(J, [1.0, 2.0], 3)
    np.testing.assert_allclose(y[3], np.linalg.matrix_power(J, 3) @ [1.0, 2.0])


def test_figure_redraws_from_csv(result, tmp_path):
    for name, frame in result.frames.items():
        frame.to_csv(tmp_path / name, index=False)
    back = {name: pd.read_csv(tmp_path / name) for name in result.frames}
    figs = exp.draw(back)
    assert set(figs) == {"stability.png"}
    figs["stability.png"].savefig(tmp_path / "s.png")
    ax = figs["stability.png"].axes[0]
    assert "Fig. 5" in ax.get_title() and "AC" in ax.get_ylabel()


@pytest.mark.slow
def test_cli_writes_files_and_rejects_bad_grid(tmp_path):
    runner = CliRunner()
    args = ["stability", "--out", str(tmp_path / "o"), "--quiet"]
    for s in SMALL:
        args += ["--set", s]
    r = runner.invoke(app, args + ["--set", "crosscheck.max_impacts=300"])
    assert r.exit_code == 0, r.output
    names = {p.name for p in (tmp_path / "o").iterdir()}
    assert {"boundaries.csv", "eigen.csv", "surface.csv", "predictions.csv", "crosscheck.csv",
            "stability.png", "run.json"} <= names
    bad = runner.invoke(app, ["stability", "--out", str(tmp_path / "b"),
                              "--set", "grid.alpha_max=-0.5"])
    assert bad.exit_code == 2 and "alpha_max" in bad.stderr
    bad = runner.invoke(app, ["stability", "--out", str(tmp_path / "b"),
                              "--set", "grid.alpha_min=-1"])
    assert bad.exit_code == 2 and "grid.alpha_min" in bad.stderr


@pytest.mark.slow
def test_paper_range_only_at_the_alpha_it_is_given_for(tmp_path, cli):
    small = [a for s in SMALL for a in ("--set", s)]
    for alpha, quoted in ((0.5, -1.11), (0.8, None)):
        out = tmp_path / str(alpha)
        result = cli("stability", "--out", out, *small, "--set", f"model.alpha={alpha}",
                     "--set", "crosscheck.max_impacts=300")
        assert result.exit_code == 0, result.output
        pred = pd.read_csv(out / "predictions.csv").set_index("quantity")
        if quoted is None:
            assert math.isnan(pred.loc["stable_ac_low_g", "paper_value"])
            assert "(paper:" not in result.stderr
        else:
            assert pred.loc["stable_ac_low_g", "paper_value"] == quoted
            assert "(paper: -1.11 to 0)" in result.stderr


@pytest.mark.slow
def test_one_value_grid_axes_draw(tmp_path, cli):
    """n_alpha: 1 is one column of the diagram: its regions as a band, its boundaries as
    points on that line (the 3D surface as a curve)."""
    small = [a for s in SMALL if not s.startswith("grid.n_alpha=") for a in ("--set", s)]
    out = tmp_path / "one"
    result = cli("stability", "--out", out, *small, "--set", "grid.n_alpha=1",
                 "--set", "grid.alpha_min=0.5", "--set", "crosscheck.max_impacts=300", "--quiet")
    assert result.exit_code == 0, result.output
    frames = {n: pd.read_csv(out / n) for n in ("eigen.csv", "boundaries.csv", "surface.csv")}
    assert frames["eigen.csv"].alpha.unique().tolist() == [0.5]
    fig = exp.draw(frames)["stability.png"]
    image = fig.axes[0].images[0]
    assert np.asarray(image.get_array()).shape[1] == 1
    x0, x1, _, _ = image.get_extent()
    assert x0 < 0.5 < x1
