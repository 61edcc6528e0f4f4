"""Linear stability diagram (paper Fig. 5, section 4) and the coarse-grained predictions
(section 5), cross-checked against the map itself.

The diagram is pure algebra in (alpha, AC) (eqs. 10-14), so its grid may extend to the
alpha < 0 the paper also draws. The cross-check points are real models (0 <= alpha < 1):
each is placed at a chosen AC by solving the explicit AC formula for a_r.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
from pydantic import Field, model_validator

from ..paper import values as paper
from ..runtime.config import ExperimentConfig, StrictModel
from ..memory import check_array_memory
from ..model.linear import (
    complex_boundaries_g,
    eigenvalues,
    empirical_contraction_rate,
    finite_difference_jacobian,
    flip_boundary_g,
    is_complex_regime,
    min_stable_spectral_radius,
    racket_amplitude_for_ac,
    radius_below,
    spectral_radius,
    stability,
    stable_ac_range_g,
)
from ..model.params import ModelParams
from .plotting import publication_style
from .base import Experiment, ExperimentResult, RunOptions


class GridBlock(StrictModel):
    """The (alpha, AC) grid of the diagram."""

    alpha_min: float = Field(-0.2, gt=-1.0)
    alpha_max: float = Field(1.0, gt=-1.0)
    n_alpha: int = Field(121, ge=1)
    ac_min_g: float = -3.5
    ac_max_g: float = 0.5
    n_ac: int = Field(201, ge=1)

    @model_validator(mode="after")
    def _ordered(self):
        if self.n_alpha > 1 and self.alpha_max <= self.alpha_min:
            raise ValueError("alpha_max must be greater than alpha_min")
        if self.n_ac > 1 and self.ac_max_g <= self.ac_min_g:
            raise ValueError("ac_max_g must be greater than ac_min_g")
        check_array_memory(self.n_alpha * self.n_ac, f"n_alpha x n_ac = {self.n_alpha:,} x "
                           f"{self.n_ac:,} points", "reduce them")
        return self


class PredictionsBlock(StrictModel):
    n_ac: int = Field(4001, ge=3, description="AC grid for the minimum spectral radius")
    human_ac_g: tuple[float, float] = Field(
        (-0.5, -0.3), description="range of mean AC observed by Schaal et al. (section 5)"
    )

    @model_validator(mode="after")
    def _fits_in_memory(self):
        check_array_memory(self.n_ac, f"n_ac = {self.n_ac:,} points", "reduce n_ac")
        return self


class CrosscheckPoint(StrictModel):
    alpha: float = Field(ge=0.0, lt=1.0)
    ac_g: float = Field(lt=0.0, description="target AC in units of g")
    racket_period: float = Field(gt=0.0, description="s")


class CrosscheckBlock(StrictModel):
    points: list[CrosscheckPoint] = Field(min_length=1)
    perturbation: float = Field(1e-5, gt=0.0, lt=0.01, description="relative dv at k = 0")
    max_impacts: int = Field(600, ge=5)
    floor: float = Field(1e-13, gt=0.0, description="deviation norm at which the fit stops")
    ceiling: float = Field(1e-2, gt=0.0, description="norm at which the orbit has left")


class StabilityConfig(ExperimentConfig):
    grid: GridBlock = GridBlock()
    predictions: PredictionsBlock = PredictionsBlock()
    crosscheck: CrosscheckBlock


# -- tables ---------------------------------------------------------------------------------
def boundaries_frame(alpha: np.ndarray) -> pd.DataFrame:
    low, high = complex_boundaries_g(alpha)
    return pd.DataFrame(
        {
            "alpha": alpha,
            "ac_flip_g": flip_boundary_g(alpha),
            "ac_fold_g": np.zeros_like(alpha),
            "ac_complex_low_g": low,
            "ac_complex_high_g": high,
        }
    )


def eigen_frame(alpha: np.ndarray, ac: np.ndarray) -> pd.DataFrame:
    aa, cc = (x.ravel() for x in np.meshgrid(alpha, ac, indexing="ij"))
    lp, lm = eigenvalues(aa, cc)
    radius = spectral_radius(aa, cc)
    return pd.DataFrame(
        {
            "alpha": aa,
            "ac_g": cc,
            "lambda1_re": lp.real,
            "lambda1_im": lp.imag,
            "lambda2_re": lm.real,
            "lambda2_im": lm.imag,
            "spectral_radius": radius,
            "regime": np.where(is_complex_regime(aa, cc), "complex", "real"),
            "stable": radius_below(radius),
        }
    )


def surface_frame(alpha: np.ndarray, n_ac: int) -> pd.DataFrame:
    """max |lambda| on a grid that follows the stable region (Fig. 5 right): for each alpha
    with |alpha| < 1, n_ac values of AC from the flip boundary to 0 (eq. 14), both ends
    included, so the surface's rim lies on the stability boundary."""
    alpha = alpha[np.abs(alpha) < 1.0]
    low, high = stable_ac_range_g(alpha)
    frac = np.linspace(0.0, 1.0, n_ac)
    ac = low[:, None] + (high - low)[:, None] * frac[None, :]
    aa = np.broadcast_to(alpha[:, None], ac.shape)
    return pd.DataFrame({"alpha": aa.ravel(), "fraction": np.tile(frac, len(alpha)),
                         "ac_g": ac.ravel(), "spectral_radius": spectral_radius(aa, ac).ravel()})


def paper_stable_ac_low(alpha: float) -> float:
    """The paper's lower end of the stable AC range (section 5), which it gives for
    alpha = 0.5 only; NaN at any other alpha."""
    return paper.STABLE_AC_LOW.value if alpha == paper.STABLE_AC_ALPHA else math.nan


def predictions_frame(params: ModelParams, block: PredictionsBlock) -> pd.DataFrame:
    alpha = params.alpha
    st = stability(params)
    low, high = (float(x) for x in stable_ac_range_g(alpha))
    cx_low, cx_high = (float(x) for x in complex_boundaries_g(alpha))
    best = min_stable_spectral_radius(alpha, block.n_ac)
    human = [float(spectral_radius(alpha, ac)) for ac in block.human_ac_g]
    paper_low = paper_stable_ac_low(alpha)  # the paper's value at its alpha only
    rows = [
        ("ac_model_g", st.ac_g, math.nan, "g",
         f"AC of the model block; {'stable' if st.stable else 'unstable'}, {st.regime} regime"),
        ("spectral_radius_model", st.spectral_radius,
         abs(alpha) if st.regime == "complex" else math.nan, "1",
         "largest |lambda| at the model block (eq. 12: |alpha| in the complex regime; "
         "the real regime has no closed form beside it)"),
        ("stable_ac_low_g", low, paper_low, "g",
         "eq. 14's flip boundary" + (f"; section 5: AC between 0 and {paper.STABLE_AC_LOW}"
                                      if math.isfinite(paper_low) else "")),
        ("stable_ac_high_g", high, 0.0, "g", "section 5 / eq. 14: upper bound AC = 0"),
        ("complex_ac_low_g", cx_low, -1.0, "g", "eq. 11 (bounds in increasing order)"),
        ("complex_ac_high_g", cx_high, -(((1 - alpha) / (1 + alpha)) ** 2), "g", "eq. 11"),
        ("min_spectral_radius_stable", best.spectral_radius, alpha, "1",
         f"section 4: min over stable AC of max|lambda| = alpha (on a grid of {block.n_ac})"),
        ("min_spectral_radius_ac_low_g", best.ac_low_g, -1.0, "g",
         "lowest AC where the minimum is attained (complex regime edge)"),
        ("min_spectral_radius_ac_high_g", best.ac_high_g, cx_high, "g",
         "highest AC where the minimum is attained (complex regime edge)"),
        ("human_ac_low_spectral_radius", human[0], math.nan, "1",
         f"max|lambda| at AC = {block.human_ac_g[0]:g} g (Schaal et al. range, section 5)"),
        ("human_ac_high_spectral_radius", human[1], math.nan, "1",
         f"max|lambda| at AC = {block.human_ac_g[1]:g} g (Schaal et al. range, section 5)"),
        ("energy_optimal_ac_g", 0.0, 0.0, "g",
         "section 5: least effort at zero racket acceleration (peak racket velocity)"),
        ("energy_optimal_spectral_radius", float(spectral_radius(alpha, 0.0)), math.nan, "1",
         "max|lambda| at AC = 0: exactly 1, the energy optimum sits on the stability boundary"),
    ]
    return pd.DataFrame(rows, columns=["quantity", "value", "paper_value", "unit", "note"])


def crosscheck_frame(block: CrosscheckBlock, g: float, progress) -> pd.DataFrame:
    rows = []
    progress.start(len(block.points), "crosscheck")
    for pt in block.points:
        a_r = float(racket_amplitude_for_ac(pt.alpha, pt.ac_g, g, pt.racket_period))
        params = ModelParams(pt.alpha, g, a_r, pt.racket_period)
        st = stability(params)
        fd = finite_difference_jacobian(params)
        radius_fd = float(np.abs(np.linalg.eigvals(fd)).max())
        fit = empirical_contraction_rate(
            params, perturbation=block.perturbation, max_impacts=block.max_impacts,
            floor=block.floor, ceiling=block.ceiling,
        )
        rows.append(
            {
                "alpha": pt.alpha,
                "racket_amplitude_m": a_r,
                "racket_period_s": pt.racket_period,
                "ac_target_g": pt.ac_g,
                "ac_g": st.ac_g,
                "regime": st.regime,
                "stable": st.stable,
                "radius_eq10": st.spectral_radius,
                "radius_fd_jacobian": radius_fd,
                "radius_empirical": fit.rate,
                "rel_diff_fd": radius_fd / st.spectral_radius - 1.0,
                "rel_diff_empirical": fit.rate / st.spectral_radius - 1.0,
                "impacts_fitted": fit.n_fitted,
                "left_neighbourhood_at": fit.left_at if fit.left_at is not None else -1,
            }
        )
        progress.advance(1)
    return pd.DataFrame(rows)


def run(config: StabilityConfig, options: RunOptions) -> ExperimentResult:
    grid = config.grid
    alpha = np.linspace(grid.alpha_min, grid.alpha_max, grid.n_alpha)
    ac = np.linspace(grid.ac_min_g, grid.ac_max_g, grid.n_ac)
    frames = {
        "boundaries.csv": boundaries_frame(alpha),
        "eigen.csv": eigen_frame(alpha, ac),
        "surface.csv": surface_frame(alpha, grid.n_ac),
        "predictions.csv": predictions_frame(config.params, config.predictions),
        "crosscheck.csv": crosscheck_frame(config.crosscheck, config.model.g, options.progress),
    }
    pred = frames["predictions.csv"].set_index("quantity")["value"]
    cross = frames["crosscheck.csv"]
    stable = cross[cross.stable]
    unstable = cross[~cross.stable]
    quoted = paper_stable_ac_low(config.model.alpha)
    summary = [
        f"alpha = {config.model.alpha:g}: stable AC from {pred['stable_ac_low_g']:.4f} g to "
        f"{pred['stable_ac_high_g']:g} g"
        + (f" (paper: {quoted:g} to 0)" if np.isfinite(quoted) else "")
        + f"; min spectral radius {pred['min_spectral_radius_stable']:.6f} (section 4: alpha)",
        f"crosscheck, {len(stable)} stable points: max |rel diff| finite-difference "
        f"{stable.rel_diff_fd.abs().max():.2e}, empirical "
        f"{stable.rel_diff_empirical.abs().max():.2e}",
    ]
    if len(unstable):
        summary.append(
            f"crosscheck, {len(unstable)} unstable points: empirical growth per impact "
            f"within {unstable.rel_diff_empirical.abs().max():.2e} of the spectral radius"
        )
    return ExperimentResult(frames=frames, figures=draw(frames), summary=summary)


# -- figure ---------------------------------------------------------------------------------
REGION_COLOURS = {0: "#d9d9d9", 1: "#9ecae1", 2: "#fdd49e"}  # unstable, real, complex


def _cell_edges(values: np.ndarray, pad: float) -> tuple[float, float]:
    """Outer edges of cells centred on equally spaced ``values``; one value: +- ``pad``."""
    if values.size == 1:
        return float(values[0]) - pad, float(values[0]) + pad
    half = float(values[-1] - values[0]) / (values.size - 1) / 2
    return float(values[0]) - half, float(values[-1]) + half


def _limits(values: np.ndarray, pad: float) -> tuple[float, float]:
    """Axis limits spanning ``values``; a single value (an axis of ``n: 1``) +- ``pad``."""
    low, high = float(values.min()), float(values.max())
    return (low, high) if high > low else (low - pad, high + pad)


@publication_style
def draw(frames: dict[str, pd.DataFrame]) -> dict:
    from matplotlib.colors import BoundaryNorm, ListedColormap

    from .plotting import new_figure

    eig = frames["eigen.csv"]
    bnd = frames["boundaries.csv"].sort_values("alpha")
    alpha = np.sort(eig.alpha.unique())
    ac = np.sort(eig.ac_g.unique())
    table = eig.set_index(["alpha", "ac_g"]).sort_index()
    shape = (len(alpha), len(ac))
    stable = table["stable"].to_numpy(bool).reshape(shape)
    complex_ = (table["regime"] == "complex").to_numpy().reshape(shape)
    region = np.where(stable, np.where(complex_, 2, 1), 0)

    fig, axes = new_figure(1, 2, width=13.0, height=5.6)
    ax = axes[0, 0]
    cmap = ListedColormap([REGION_COLOURS[i] for i in range(3)])
    # cells centred on the (equally spaced) grid values; an axis of one value gets a band
    ax.imshow(region.T, origin="lower", aspect="auto", interpolation="nearest", cmap=cmap,
              norm=BoundaryNorm([-0.5, 0.5, 1.5, 2.5], 3),
              extent=(*_cell_edges(alpha, 0.05), *_cell_edges(ac, 0.1)))
    a = bnd.alpha.to_numpy()
    # a diagram at one alpha draws the boundaries as points on that vertical line
    style = {"marker": "_", "ms": 30} if len(a) == 1 else {}
    ax.plot(a, bnd.ac_flip_g, color="k", lw=2, label="stability boundary, eq. 14 (flip)", **style)
    ax.plot(a, bnd.ac_fold_g, color="k", lw=2, ls="--", label="stability boundary AC = 0, eq. 14",
            **style)
    ax.axvline(1.0, color="k", lw=2, ls=":", label=r"$|\alpha| = 1$, eq. 13")
    ax.plot(a, bnd.ac_complex_low_g, color="0.45", lw=1.5, label="real/complex, eq. 11",
            **style)
    ax.plot(a, bnd.ac_complex_high_g, color="0.45", lw=1.5, **style)
    ax.set_xlim(*_limits(alpha, 0.05))
    ax.set_ylim(*_limits(ac, 0.1))
    # region labels along the middle of the physical alphas shown (0 <= alpha < 1), and the
    # upper real band's label a tenth of the way in, where that band is wider
    lo_a, hi_a = max(float(alpha.min()), 0.0), min(float(alpha.max()), 1.0)
    if hi_a <= lo_a:
        lo_a, hi_a = float(alpha.min()), float(alpha.max())
    a0 = 0.5 * (lo_a + hi_a)
    b = {c: float(np.interp(a0, a, bnd[c])) for c in bnd.columns}
    hi = min(b["ac_complex_high_g"], 0.0)
    lo = max(b["ac_complex_low_g"], b["ac_flip_g"])
    a1 = lo_a + 0.1 * (hi_a - lo_a)
    hi1 = min(float(np.interp(a1, a, bnd.ac_complex_high_g)), 0.0)
    ax.text(a1, hi1 / 2, "real (stable)", ha="center", va="center", fontsize=9)
    labels = [
        ((lo + hi) / 2, "complex (stable)\n" r"$|\lambda| = \alpha$"),
        ((b["ac_flip_g"] + ac.min()) / 2, "unstable"),
        ((0.0 + ac.max()) / 2, "unstable"),
    ]
    for y, text in labels:
        if ac.min() < y < ac.max():
            ax.text(a0, y, text, ha="center", va="center", fontsize=9)
    if b["ac_complex_low_g"] > b["ac_flip_g"]:
        ax.annotate("real (stable)", xy=(a0, (b["ac_complex_low_g"] + b["ac_flip_g"]) / 2),
                    xytext=(a0 - 0.45 * (hi_a - lo_a), b["ac_flip_g"] - 0.35), fontsize=9,
                    arrowprops={"arrowstyle": "->", "lw": 0.8})
    ax.set_xlabel(r"coefficient of restitution $\alpha$")
    ax.set_ylabel("racket acceleration at impact AC (g)")
    ax.set_title("Stability diagram (paper Fig. 5, left)")
    ax.legend(loc="lower left", fontsize=7, framealpha=0.9)

    axes[0, 1].remove()
    ax3 = fig.add_subplot(1, 2, 2, projection="3d")
    surf_df = frames["surface.csv"].sort_values(["alpha", "fraction"])
    n_frac = surf_df.fraction.nunique()
    A, C, Z = (surf_df[c].to_numpy().reshape(-1, n_frac) for c in ("alpha", "ac_g",
                                                                    "spectral_radius"))
    if min(A.shape) > 1:
        surf = ax3.plot_surface(A, C, Z, cmap="viridis", vmin=0.0, vmax=1.0, rstride=1,
                                cstride=1, linewidth=0, antialiased=False)
    else:  # one alpha (or one AC): the surface is a curve (or a point)
        surf = ax3.scatter(A.ravel(), C.ravel(), Z.ravel(), c=Z.ravel(), cmap="viridis",
                           vmin=0.0, vmax=1.0)
    ax3.set_xlabel(r"$\alpha$")
    ax3.set_ylabel("AC (g)")
    ax3.set_zlabel(r"max $|\lambda|$")
    ax3.set_zlim(0.0, 1.0)
    ax3.view_init(elev=28, azim=-130)
    ax3.set_title(r"Largest $|\lambda|$ where stable (paper Fig. 5, right)")
    fig.colorbar(surf, ax=ax3, shrink=0.6, pad=0.1, label=r"$\max(|\lambda_+|, |\lambda_-|)$")
    return {"stability.png": fig}


EXPERIMENT = Experiment(name="stability", schema=StabilityConfig, run=run, draw=draw)
