"""Figures for a paper: every figure redrawn from the committed CSVs in the publication style
(mathtext for every symbol, whole-number ticks on integer axes, honest axis ranges, paper
references only at the paper's parameters), and a run's figures written as PNG, PDF or SVG
at a chosen resolution, with the run's parameters in the file's metadata, not in its title."""

from __future__ import annotations

import io
import json
import math
import re
import zlib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bounce_cli.paper import values as paper
from bounce_cli.model.linear import jacobian
from bounce_cli.model.params import ModelParams
from bounce_cli.experiments.registry import entry, reproduced

RESULTS = Path(__file__).resolve().parents[1] / "results"


def committed_frames(name: str) -> dict[str, pd.DataFrame]:
    return {p.name: pd.read_csv(p) for p in sorted((RESULTS / name).glob("*.csv"))}


@pytest.fixture(scope="module")
def figures():
    """Every reproduced experiment's figures, drawn from its committed CSVs alone."""
    drawn = {}
    for e in reproduced():
        for png, fig in e.load().draw(committed_frames(e.name)).items():
            drawn[f"{e.name}/{png}"] = fig
    return drawn


def texts(fig) -> list[str]:
    """Every text a reader sees: titles, axis and colorbar labels, legends, annotations."""
    out = [fig.get_suptitle()]
    for ax in fig.axes:
        out += [ax.get_title(loc) for loc in ("left", "center", "right")]
        out += [ax.get_xlabel(), ax.get_ylabel()]
        if hasattr(ax, "get_zlabel"):
            out.append(ax.get_zlabel())
        out += [t.get_text() for t in ax.texts]
        legend = ax.get_legend()
        if legend is not None:
            out += [t.get_text() for t in legend.get_texts()] + [legend.get_title().get_text()]
    for legend in fig.legends:
        out += [t.get_text() for t in legend.get_texts()]
    return [t for t in out if t]


#: symbols written as ASCII outside mathtext: m/s^2, theta[k], q_v, alpha, |lambda|, +-, >=, 3x3,
#: v0
ASCII_MATH = re.compile(r"\^|\[k|\b[A-Za-z]+_[A-Za-z0-9{]|\b(alpha|theta|lambda|tau|omega|Gamma)"
                        r"\b|\+-|>=|<=|\||\b\dx\d\b|->|\b[a-z]+0\b")


@pytest.mark.slow
def test_no_ascii_math_in_any_figure(figures):
    found = []
    for name, fig in figures.items():
        for text in texts(fig):
            outside = re.sub(r"\$[^$]*\$", "", text)  # what mathtext does not render
            if ASCII_MATH.search(outside):
                found.append(f"{name}: {text!r}")
    assert not found, "\n".join(found)


def test_the_checker_catches_what_it_is_for():
    for plain in ("m/s^2", "theta[k]", "q_v = 0.04", "alpha_p < alpha_0", "|lambda|",
                  "mean +- SD", "n >= 2", "the 3x3 Jacobian", "phase -> velocity",
                  "Fig. 3: v0 = 4.8 m/s"):
        assert ASCII_MATH.search(plain), plain
    for math_text in ("m/s$^2$", r"$\theta_k$", r"$q_v$ = 0.04", r"$|\lambda|$",
                      r"mean $\pm$ SD", "racket period (s)", "lag $l$ (bounces)"):
        assert not ASCII_MATH.search(re.sub(r"\$[^$]*\$", "", math_text)), math_text


#: axis labels of whole-number quantities: trial, impact index, lag
INTEGER_AXIS = re.compile(r"\btrial\b|\blag\b|impact \$k\$|bounce \$k\$|impacts until")


@pytest.mark.slow
def test_every_figure_is_laid_out(figures, figure_layout_problems):
    """No title, label, legend entry or annotation cut off at the figure's edge, and no title
    under a legend (the attractors' continuation figure had both; its own test is beside
    the command's)."""
    found = [f"{name}: {problem}" for name, fig in figures.items()
             for problem in figure_layout_problems(fig)]
    assert not found, "\n".join(found)


def test_integer_axes_have_whole_number_ticks(figures):
    checked = 0
    for name, fig in figures.items():
        for ax in fig.axes:
            for axis, label in ((ax.xaxis, ax.get_xlabel()), (ax.yaxis, ax.get_ylabel())):
                if not INTEGER_AXIS.search(label):
                    continue
                low, high = sorted(axis.get_view_interval())
                ticks = [t for t in axis.get_majorticklocs() if low <= t <= high]
                assert ticks and np.allclose(ticks, np.round(ticks)), (name, label, ticks)
                checked += 1
    assert checked >= 15  # trajectory, learning, acf, impulse, control, the data's side


def test_impulse_phase_panels_are_fitted_to_the_responses_not_fixed_at_180(figures):
    for name in ("impulse/impulse.png", "impulse/impulse_linear.png",
                 "control/control_impulse.png"):
        phase_axes = [ax for ax in figures[name].axes if "theta_k" in ax.get_ylabel()]
        assert phase_axes, name
        for ax in phase_axes:
            low, high = ax.get_ylim()
            drawn = np.concatenate([line.get_ydata() for line in ax.get_lines()])
            # the responses (about 33 deg at section 7's model) fill the axis
            assert high - low < 1.2 * (np.nanmax(drawn) - np.nanmin(drawn)) + 5, (name, low, high)


def test_learning_variability_axis_starts_at_zero(figures):
    fig = figures["learning-data/learning.png"]
    right = [ax for ax in fig.axes if ax.get_ylabel() == "SD of ball amplitude (cm)"
             and ax.get_xlabel() == ""]  # the twin axis of the trial panel
    assert len(right) == 1
    low, high = right[0].get_ylim()
    sd = committed_frames("learning-data")["trials.csv"]["apex_sd_m"] * 100
    assert low == 0.0 and sd.max() < high < 1.5 * sd.max()


def legend_labels(fig) -> list[str]:
    return [t.get_text() for ax in fig.axes if ax.get_legend() is not None
            for t in ax.get_legend().get_texts()]


def frames_at(params: ModelParams, frames: dict[str, pd.DataFrame]) -> dict[str, pd.DataFrame]:
    """The committed control tables with the passive model's rows (the stationary state and
    the Jacobian's eigenvalues, eqs. 7-10) at ``params`` instead of section 7's."""
    frames = {k: v.copy() for k, v in frames.items()}
    fp = params.fixed_point()
    lam = np.linalg.eigvals(jacobian(params))
    impulse = frames["impulse.csv"]
    passive = impulse.model == "passive"
    impulse.loc[passive, "v_m_s"] = fp.v_m_s + impulse.loc[passive, "dv_m_s"]
    impulse.loc[passive, "theta_deg"] = fp.theta_deg + impulse.loc[passive, "dtheta_deg"]
    impulse.loc[passive, "racket_period_s"] = params.racket_period
    eigen = frames["eigen.csv"]
    row = eigen.model == "passive"
    for i, value in enumerate(lam, start=1):
        eigen.loc[row, f"lambda{i}_re"], eigen.loc[row, f"lambda{i}_im"] = value.real, value.imag
    return frames


@pytest.mark.parametrize("params", [ModelParams(0.3, 9.81, 0.40, 0.92),
                                    ModelParams(0.5, 5.8, 0.065, 0.55),
                                    ModelParams(0.7, 9.81, 0.45, 0.80)])
def test_controls_model_is_recovered_from_its_tables(params):
    from bounce_cli.experiments.control import passive_model

    recovered = passive_model(frames_at(params, committed_frames("control")))
    for name in ("alpha", "g", "racket_amplitude", "racket_period"):
        assert getattr(recovered, name) == pytest.approx(getattr(params, name), rel=1e-9)


def test_control_draws_the_subjects_numbers_only_at_section_7s_model():
    from bounce_cli.experiments.control import draw_stability

    committed = committed_frames("control")
    at_paper = legend_labels(draw_stability(committed))
    assert any("section 7" in t for t in at_paper)
    assert any("the subject" in t for t in at_paper)
    other = legend_labels(draw_stability(frames_at(ModelParams(0.45, 9.81, 0.30, 0.92),
                                                   committed)))
    assert not any("section 7" in t or "subject" in t for t in other)
    assert any("radius.target_radius" in t for t in other)


# -- the run's figure files -------------------------------------------------------------------
SMALL_STABILITY = ["--set", "grid.n_alpha=21", "--set", "grid.n_ac=21",
                   "--set", "predictions.n_ac=101",
                   "--set", "crosscheck.points=[{alpha: 0.5, ac_g: -0.5, racket_period: 0.92}]"]


def png_text_chunks(data: bytes) -> dict[str, str]:
    """The tEXt chunks of a PNG, read chunk by chunk (not by the library that wrote it)."""
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    chunks, at = {}, 8
    while at < len(data):
        length = int.from_bytes(data[at:at + 4], "big")
        kind, body = data[at + 4:at + 8], data[at + 8:at + 8 + length]
        if kind == b"tEXt":
            key, _, value = body.partition(b"\0")
            chunks[key.decode("latin-1")] = value.decode("latin-1")
        elif kind == b"zTXt":
            key, _, rest = body.partition(b"\0")
            chunks[key.decode("latin-1")] = zlib.decompress(rest[1:]).decode("latin-1")
        at += 12 + length
    return chunks


def png_size(data: bytes) -> tuple[int, int]:
    return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")


@pytest.mark.slow
def test_figures_are_written_in_every_format_asked_for_at_the_dpi_asked_for(tmp_path, cli):
    out = tmp_path / "r"
    result = cli("regression", "--out", out, "--quiet", "--figure-format", "png,pdf",
                 "--figure-format", "svg", "--dpi", 72)
    assert result.exit_code == 0, result.output
    png, pdf, svg = (out / f"regression.{kind}" for kind in ("png", "pdf", "svg"))
    assert pdf.read_bytes()[:5] == b"%PDF-" and b"<svg" in svg.read_bytes()[:1000]
    # regression.png is 7 x 5.2 in: 504 x 374 pixels at 72 dpi
    assert png_size(png.read_bytes()) == (504, 374)
    manifest = json.loads((out / "run.json").read_text())
    assert {"regression.png", "regression.pdf", "regression.svg"} <= set(manifest["files"])
    # the default: PNG only, at 150 dpi; the PDF and SVG of the run replaced are removed
    assert cli("regression", "--out", out, "--quiet").exit_code == 0
    assert png_size(png.read_bytes()) == (1050, 780)
    assert not pdf.exists() and not svg.exists()


@pytest.mark.slow
def test_a_rerun_writes_the_same_bytes_in_every_format(tmp_path, cli):
    runs = []
    for name in ("a", "b"):
        out = tmp_path / name
        assert cli("stability", *SMALL_STABILITY, "--out", out, "--quiet",
                   "--figure-format", "png,pdf,svg").exit_code == 0
        runs.append({kind: (out / f"stability.{kind}").read_bytes()
                     for kind in ("png", "pdf", "svg")})
    for kind in ("png", "pdf", "svg"):
        assert runs[0][kind] == runs[1][kind], kind  # no creation date, fixed SVG ids


@pytest.mark.slow
def test_run_metadata_goes_into_the_files_not_into_the_titles(tmp_path, cli):
    out = tmp_path / "r"
    result = cli("regression", "--set", "seed=7", "--out", out, "--quiet",
                 "--figure-format", "png,pdf,svg")
    assert result.exit_code == 0, result.output
    caption = "simulated trials: alpha = 0.5, g = 9.81 m/s^2; seed 7"
    chunks = png_text_chunks((out / "regression.png").read_bytes())
    assert chunks["Description"] == caption and chunks["Source"] == "bounce regression"
    assert chunks["Title"].startswith("Fig. 7")
    pdf = (out / "regression.pdf").read_bytes()
    assert b"/Subject (" + caption.encode() + b")" in pdf and b"/CreationDate" not in pdf
    assert caption.encode() in (out / "regression.svg").read_bytes()
    from bounce_cli.experiments.regression import EXPERIMENT as regression
    from bounce_cli.runtime.config import bundled_config_path, load_config
    from bounce_cli.experiments.base import RunOptions

    config = load_config(regression.schema, bundled_config_path("regression"), ["seed=7"])
    fig = regression.run(config, RunOptions()).figures["regression.png"]
    assert not any("seed" in t or "g = 9.81" in t for t in texts(fig))


@pytest.mark.slow
def test_the_pdf_embeds_its_fonts_as_truetype_not_type3(tmp_path, cli):
    out = tmp_path / "s"
    assert cli("stability", *SMALL_STABILITY, "--out", out, "--quiet",
               "--figure-format", "pdf").exit_code == 0
    pdf = (out / "stability.pdf").read_bytes()
    assert b"/CIDFontType2" in pdf and b"/Type3" not in pdf  # TrueType outlines (fonttype 42)


@pytest.mark.parametrize("args, needles", [
    (["--figure-format", "jpg"], ["--figure-format", "'jpg' is not a figure format", "png"]),
    (["--figure-format", "png,"], ["--figure-format", "'' is not a figure format"]),
    (["--dpi", "10"], ["--dpi", "30"]),
])
def test_a_bad_figure_option_is_one_line_and_writes_nothing(args, needles, tmp_path, cli,
                                                            user_error):
    out = tmp_path / "never"
    user_error(cli("regression", "--out", out, *args), *needles)
    assert not out.exists()


def test_every_experiment_command_offers_the_figure_options(cli):
    for e in reproduced():
        text = cli(e.name, "--help").stdout
        assert "--figure-format" in text and "--dpi" in text, e.name


@pytest.mark.slow
def test_a_figure_redrawn_from_csv_writes_as_pdf(tmp_path):
    from bounce_cli.runtime.figure_files import save_figure

    fig = entry("impulse").load().draw(committed_frames("impulse"))["impulse.png"]
    buffer = io.BytesIO()
    save_figure(fig, buffer, "pdf", dpi=150, source="test")  # type: ignore[arg-type]
    assert buffer.getvalue()[:5] == b"%PDF-"
    assert math.isfinite(paper.FIG3_MODEL.alpha)


@pytest.mark.parametrize("folder, env", [
    ("d\u00e4t\u00e4".encode(), {"LC_ALL": "C", "PYTHONUTF8": "0"}),  # UTF-8 bytes, ASCII locale
    (b"d\xe4t", {"LC_ALL": "C"}),  # a Latin-1 file name: not UTF-8 at all
])
@pytest.mark.slow
def test_a_non_ascii_path_in_the_c_locale_goes_into_the_png_metadata(tmp_path, cli, folder,
                                                                     env):
    """``LC_ALL=C`` and a data path the command line cannot decode: the figure is written with
    the path in its metadata (the bytes as UTF-8, else U+FFFD), not a UnicodeEncodeError."""
    import os
    import subprocess
    import sys

    from PIL import Image

    sim = tmp_path / "sim"
    assert cli("simulate-recording", "--quiet", "--out", sim, "--set", "trials=1",
               "--set", "duration_s=6").exit_code == 0
    data = os.fsencode(tmp_path) + b"/" + folder
    os.mkdir(data)
    with open(data + b"/rec.csv", "wb") as handle:
        handle.write((sim / "recording.csv").read_bytes())
    out = data + b"/\xc3\xb6ut"
    done = subprocess.run([sys.executable, "-m", "bounce_cli", "extract", "--quiet", "--data",
                           data + b"/rec.csv", "--out", out], capture_output=True, timeout=300,
                          env={**os.environ, **env})
    assert done.returncode == 0, done.stderr.decode(errors="replace")[-3000:]
    caption = Image.open(out + b"/fig2.png").text["Description"]
    shown = "d\u00e4t\u00e4" if folder == "d\u00e4t\u00e4".encode() else "d\ufffdt"
    assert f"{shown}/rec.csv" in caption, caption


def test_tick_labels_are_plain_text_and_the_power_of_ten_stays_mathtext():
    """Tick labels are written as plain text (mathtext's parser was a quarter of a study's
    figure time) with the same true minus sign; the offset (x10^k) stays a superscript. The
    unwrapping must match how this matplotlib wraps a label, or it would do nothing."""
    from matplotlib.ticker import ScalarFormatter

    from bounce_cli.experiments.plotting import new_figure, publication_style

    @publication_style
    def draw(frames):
        fig, axes = new_figure()
        axes[0, 0].plot([0.0, 1.0], [-3e-7, 2e-7])
        return {"f.png": fig}

    fig = draw({})["f.png"]
    fig.draw_without_rendering()
    ax = fig.axes[0]
    y_labels = [t.get_text() for t in ax.get_yticklabels() if t.get_text()]
    x_labels = [t.get_text() for t in ax.get_xticklabels() if t.get_text()]
    assert y_labels and x_labels
    assert not any("$" in label for label in y_labels + x_labels), y_labels + x_labels
    assert any(label.startswith("\N{MINUS SIGN}") for label in y_labels), y_labels
    offset = ax.yaxis.get_offset_text().get_text()
    assert offset.startswith("$") and r"\times" in offset, offset
    assert "10^{\N{MINUS SIGN}7}" in offset, offset
    # the label a plain ScalarFormatter writes under use_mathtext is what gets unwrapped
    from matplotlib import rc_context
    with rc_context({"axes.formatter.use_mathtext": True}):
        formatter = ScalarFormatter()
    formatter.create_dummy_axis()
    formatter.axis.set_view_interval(-0.6, 0.6)
    formatter.set_locs([-0.5, 0.0, 0.5])
    from bounce_cli.experiments.plotting import _MATHTEXT_TICK
    assert _MATHTEXT_TICK.fullmatch(formatter(-0.5)), formatter(-0.5)


@pytest.mark.slow
def test_no_figure_parses_its_tick_labels_as_mathtext(figures):
    found = []
    checked = 0
    for name, fig in figures.items():
        fig.draw_without_rendering()
        for ax in fig.axes:
            for axis in (ax.xaxis, ax.yaxis):
                if axis.get_scale() != "linear":
                    continue
                labels = [t.get_text() for t in axis.get_ticklabels() if t.get_text()]
                found += [f"{name}: {label!r}" for label in labels if "mathdefault" in label]
                checked += len(labels)
    assert not found, "\n".join(found[:10])
    assert checked > 500


@pytest.mark.parametrize("name", ["basin", pytest.param("stability", marks=pytest.mark.slow),
                                  "bifurcation"])
def test_a_png_laid_out_before_saving_is_what_savefig_writes(name):
    """``save_figure`` runs the layout engine itself before ``savefig`` (which then draws the
    figure once instead of twice): the PNG is, byte for byte, what ``savefig`` alone writes
    with its own first draw; the figure keeps its engine, canvas and resolution and still
    saves as PDF."""
    from matplotlib import rc_context

    from bounce_cli.runtime import figure_files
    from bounce_cli.runtime.figure_files import SAVE_STYLE, figure_metadata, save_figure

    def drawn():
        return next(iter(entry(name).load().draw(committed_frames(name)).values()))

    ours, theirs = io.BytesIO(), io.BytesIO()
    fig = drawn()
    engine, canvas, dpi = fig.get_layout_engine(), fig.canvas, fig.dpi
    draws = []  # the artists drawn once: savefig's own draw without output is skipped too
    original_draw = type(fig).draw
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(type(fig), "draw",
                      lambda self, renderer: draws.append(1) or original_draw(self, renderer))
        save_figure(fig, ours, "png", dpi=150, source="test")  # type: ignore[arg-type]
    assert len(draws) == 1
    assert fig.get_layout_engine() is engine and fig.canvas is canvas and fig.dpi == dpi
    reference = drawn()
    with rc_context(SAVE_STYLE):  # type: ignore[arg-type]
        reference.savefig(theirs, format="png", dpi=150,
                          metadata=figure_metadata(reference, "png", "test"))
    assert ours.getvalue() == theirs.getvalue()
    with figure_files.laid_out(fig, "pdf", 150):  # a vector format: left to savefig
        assert fig.get_layout_engine() is engine
    pdf = io.BytesIO()
    save_figure(fig, pdf, "pdf", dpi=150, source="test")  # type: ignore[arg-type]
    assert pdf.getvalue()[:5] == b"%PDF-"


def test_the_learning_figure_names_its_fit_in_a_sentence(figure_layout_problems):
    """Fig. 6 over the study names the fit its trend lines come from: 'mixed: random intercept
    and slope; a random-effects variance estimated at 0' (group_learning.csv's method) reads
    'mixed model with random intercept and slope; ...', with no nested parentheses (a review
    read the old title, '(fixed effect: mixed: ... (a random-effects variance at its
    boundary, 0))', as garbled)."""
    from bounce_cli.experiments.study_figures import learning_figure

    trials = pd.DataFrame({"subject": ["s1"] * 3 + ["s2"] * 3, "condition": "a",
                           "trial_number": [1, 2, 3] * 2,
                           "ac_mean_g": [-0.4, -0.5, -0.6, -0.45, -0.5, -0.62],
                           "apex_sd_m": [0.05, 0.04, 0.03, 0.06, 0.05, 0.04]})
    method = "mixed: random intercept and slope; a random-effects variance estimated at 0"
    trends = pd.DataFrame({"condition": "a", "quantity": ["ac_mean_g", "apex_sd_m"],
                           "intercept": [-0.3, 0.06], "slope_per_trial": [-0.1, -0.01],
                           "ci_low": [-0.2, -0.02], "ci_high": [0.0, 0.0],
                           "method": method})
    fig = learning_figure(trials, trends)
    title = " ".join(fig._suptitle.get_text().split())
    assert ("(fixed effect: mixed model with random intercept and slope; a random-effects "
            "variance estimated at 0)") in title
    assert "((" not in title and "))" not in title
    # one condition: a narrow figure, whose title line ran off both sides (a data review)
    assert figure_layout_problems(fig) == []


def test_fig2_draws_rounding_level_impacts_flat_without_an_offset_label():
    """The virtual set-up's sine racket gives impacts that vary by 5e-8 m/s: Fig. 2's panels
    blew that up under offset labels ('x1e-6 + 4.276349e1'). They span at least +-0.01 m/s
    and +-0.5 deg now; a lab's impacts (0.3 m/s apart) keep their own range. The virtual
    figure's title named trial 1 twice."""
    from bounce_cli.experiments.plotting import draw_fig2
    from bounce_cli.experiments.virtual import draw as draw_virtual

    t = np.arange(0.0, 10.0, 0.01)
    samples = pd.DataFrame({"trial": 1, "t_s": t, "racket_x_m": 0.3 * np.sin(t),
                            "ball_x_m": 0.3 * np.sin(t) + 1.0})
    hops = np.arange(1.0, 10.0, 0.9)
    flat = pd.DataFrame({"trial": 1, "t_s": hops, "hop_s": 0.9,
                         "v_m_s": 4.5126 + 5e-8 * np.cos(hops),
                         "theta_deg": 42.76349 + 4e-6 * np.sin(hops)})
    fig = draw_fig2(samples, flat, "x")
    fig.canvas.draw()
    for ax, span in ((fig.axes[1], 0.01), (fig.axes[2], 0.5)):
        low, high = ax.get_ylim()
        assert high - low >= 2 * span - 1e-12
        assert ax.yaxis.get_offset_text().get_text() == ""
    lab = flat.assign(v_m_s=4.5 + 0.3 * np.cos(hops))
    assert np.ptp(draw_fig2(samples, lab, "x").axes[1].get_ylim()) < 1.0
    frames = {"recordings/s1_virtual_t1.csv": samples, "impacts.csv": flat}
    title = draw_virtual(frames)["virtual.png"].get_suptitle()
    assert title.count("trial 1") == 1, title
    assert "virtual set-up: the first 10 bounces" in title  # 10 impacts in the samples
    short = {**frames, "impacts.csv": flat.head(8)}
    title = draw_virtual(short)["virtual.png"].get_suptitle()
    assert "virtual set-up: the trial's 8 bounces" in title and "first 10" not in title


def test_one_unit_s_radii_sit_beside_its_tick():
    """With one unit, autoscaling put its OLS and lag-2 points at the axis' two ends, far
    from the unit's tick; a unit's place is one wide now."""
    from bounce_cli.experiments.study_figures import stability_figure

    row = {"subject": "s1", "condition": "virtual", "model_spectral_radius": 0.5}
    for method, value in (("ols", 0.45), ("lag2", 0.5)):
        row.update({f"radius_{method}": value, f"radius_{method}_ci_low": value - 0.01,
                    f"radius_{method}_ci_high": value + 0.01})
    fig = stability_figure(pd.DataFrame([row]), None)
    ax = fig.axes[0]
    assert ax.get_xlim() == pytest.approx((-0.6, 0.6))


def test_the_group_impulse_figure_shows_the_racket_in_ms_and_mm():
    """group_impulse.png drew the racket's modulation in s and m (0.115 s, a fixed +-0.001 m
    axis) where each unit's modulation_data.png uses ms and mm."""
    from bounce_cli.experiments.study_figures import impulse_figure

    rows = [{"condition": "virtual", "quantity": q, "direction": d, "k": k,
             "mean": (0.1155 if q == "racket_period_s" else 2e-5) * (0.5 ** k), "sd": 0.0}
            for q in ("racket_period_s", "racket_amplitude_m")
            for d in ("decrease", "increase") for k in range(5)]
    fig = impulse_figure(pd.DataFrame(rows))
    period, amplitude = fig.axes[0], fig.axes[2]
    assert period.get_ylabel().endswith("(ms)") and amplitude.get_ylabel().endswith("(mm)")
    assert period.get_ylim()[1] > 100.0  # 115.5 ms
    assert amplitude.get_ylim() == pytest.approx((-0.99, 1.01), abs=0.02)  # +-1 mm floor


@pytest.mark.parametrize("case", ["codes", "counts", "one_count", "negative", "wide"])
def test_cell_colours_are_the_colormap_s_bytes(case):
    """``plotting.cell_colours`` colours integer cells through a table: the same bytes as
    the colormap of the whole grid (basin.png's codes through a BoundaryNorm, including
    pandas' -1; basin_iterations.png's counts through a Normalize, masked cells after)."""
    from matplotlib import colormaps
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import BoundaryNorm, ListedColormap, Normalize

    from bounce_cli.experiments.plotting import cell_colours

    rng = np.random.default_rng(4)
    if case in ("codes", "negative"):
        cmap = ListedColormap(["white", "0.6", "black", "red", "tab:blue", "tab:green"])
        norm = BoundaryNorm(np.arange(7) - 0.5, cmap.N)
        values = rng.integers(-1 if case == "negative" else 0, 6, (300, 200)).astype(np.int8)
        expected = cmap(norm(values), bytes=True)
        got = cell_colours(values, lambda v: cmap(norm(v), bytes=True))
    else:
        high = {"counts": 200, "one_count": 7, "wide": 100_000}[case]
        values = (np.full((300, 200), 7) if case == "one_count"
                  else rng.integers(0, high, (300, 200))).astype(np.int64)
        mask = rng.random(values.shape) < 0.2
        low, top = float(values[~mask].min()), float(values[~mask].max())
        one = low == top
        scale = ScalarMappable(Normalize(low - 0.5 * one, top + 0.5 * one),
                               colormaps["viridis"])
        expected = scale.to_rgba(np.ma.masked_array(values.astype(float), mask=mask),
                                 bytes=True)
        got = cell_colours(values, lambda v: scale.to_rgba(v.astype(float), bytes=True))
        got[mask] = scale.to_rgba(np.ma.masked_array([0.0], mask=[True]), bytes=True)[0]
    assert got.dtype == expected.dtype
    np.testing.assert_array_equal(got, expected)
