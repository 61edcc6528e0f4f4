"""The group figures of ``bounce study``, drawn from its group tables (so that each can be
redrawn from its CSVs): Figs. 6, 7 and 8, 9, 11 over the study, and the data's stability
against the model's."""

from __future__ import annotations

import textwrap
from typing import Any, Callable, Iterable

import numpy as np
import pandas as pd
from matplotlib.ticker import MaxNLocator

from .plotting import new_figure

COLORS = ["k", "tab:blue", "tab:red", "tab:green", "tab:purple", "tab:orange"]
PAIRS = (("v_v", "$v \\to v$"), ("theta_to_v", "$\\theta \\to v$"),
         ("v_to_theta", "$v \\to \\theta$"), ("theta_theta", "$\\theta \\to \\theta$"))
#: (quantity, axis label, factor from the table's unit to the axis'): the racket's in ms and
#: mm, as the unit's own modulation_data.png
RESPONSES = (("v_m_s", "$\\Delta v_k$ (m/s)", 1.0),
             ("theta_deg", "$\\Delta \\theta_k$ (deg)", 1.0),
             ("racket_period_s", "$\\Delta$ racket period (ms)", 1e3),
             ("racket_amplitude_m", "$\\Delta$ racket amplitude (mm)", 1e3))
#: the smallest half-span a response panel shows, in its axis' unit: a response within it (a
#: sine racket's period, unchanged up to rounding, 1e-16 s) is drawn flat, not magnified
RESPONSE_FLOOR = {"v_m_s": 1e-3, "theta_deg": 0.1, "racket_period_s": 1.0,
                  "racket_amplitude_m": 1.0}


def group_figure_builders(frames: dict[str, pd.DataFrame]) -> dict[str, Callable[[], Any]]:
    """name -> a function drawing that group figure, for every group figure whose table is
    present (in the report's order)."""
    builders: dict[str, Callable[[], Any]] = {}
    if "group_regression.csv" in frames and "slope" in frames["group_regression.csv"]:
        fit = frames["group_regression.csv"].dropna(subset=["slope"])
        if len(fit):
            def regression():
                from .regression import draw as draw_regression

                fig = draw_regression({"trials.csv": frames["group_regression_trials.csv"],
                                       "fit.csv": fit})["regression.png"]
                fig.axes[0].set_title("Fig. 7 over the study: trial means of every subject, "
                                      "pooled by condition")
                return fig

            builders["group_regression.png"] = regression
    if "group_learning_trials.csv" in frames:
        builders["group_learning.png"] = lambda: learning_figure(
            frames["group_learning_trials.csv"], frames.get("group_learning.csv"))
    group = frames.get("group.csv")
    if group is not None and "radius_ols" in group and group["radius_ols"].notna().any():
        builders["group_stability.png"] = lambda: stability_figure(
            group, frames.get("group_stability.csv"))
    if "group_acf.csv" in frames:
        builders["group_acf.png"] = lambda: acf_figure(frames["group_acf.csv"])
    if "group_impulse.csv" in frames:
        builders["group_impulse.png"] = lambda: impulse_figure(frames["group_impulse.csv"])
    return builders


def draw_group(frames: dict[str, pd.DataFrame], names: Iterable[str] | None = None) -> dict:
    """Every group figure whose table is present, or those of ``names``."""
    builders = group_figure_builders(frames)
    chosen = builders if names is None else [n for n in names if n in builders]
    return {name: builders[name]() for name in chosen}


#: characters of a 10-point title line per inch of figure width (DejaVu Sans averages about
#: 5.5 points a character: 13 per inch; one fewer for a margin)
TITLE_CHARS_PER_INCH = 12


def learning_figure(trials: pd.DataFrame, trends: pd.DataFrame | None):
    """Fig. 6 over the study: each subject's per-trial AC and SD of ball amplitude (thin), the
    trend's fixed-effect line (thick; the title names its method), one column per condition."""
    conditions = sorted(trials["condition"].astype(str).unique())
    fig, axes = new_figure(2, len(conditions), width=4.2 * len(conditions) + 1, height=6.4,
                           sharex=True)
    quantities = (("ac_mean_g", "AC, trial mean (g)", 1.0, "g"),
                  ("apex_sd_m", "SD of ball amplitude (cm)", 100.0, "cm"))
    subjects = sorted(trials["subject"].astype(str).unique())
    style = subject_styles(subjects)
    for j, condition in enumerate(conditions):
        part = trials[trials["condition"].astype(str) == condition]
        for i, (column, label, scale, unit) in enumerate(quantities):
            ax = axes[i, j]
            for subject, rows in part.groupby(part["subject"].astype(str), sort=True):
                ax.plot(rows["trial_number"], rows[column] * scale, "-", ms=3.5, lw=0.8,
                        alpha=0.7, label=subject, **style[subject])
            if trends is not None and "intercept" in trends:
                row = trends[(trends["condition"].astype(str) == condition)
                             & (trends["quantity"] == column)]
                if len(row) and np.isfinite(row["slope_per_trial"].iloc[0]):
                    r = row.iloc[0]
                    xs = np.array([part["trial_number"].min(), part["trial_number"].max()])
                    ax.plot(xs, (r["intercept"] + r["slope_per_trial"] * xs) * scale, "k-",
                            lw=2.2, label=f"fixed effect {r['slope_per_trial'] * scale:+.3g} "
                            f"{unit}/trial [{r['ci_low'] * scale:.3g}, "
                            f"{r['ci_high'] * scale:.3g}]")
                    # the panel's own legend: its fixed effect (the subjects: below)
                    ax.legend(handles=ax.get_lines()[-1:], fontsize=7, loc="best")
            ax.set_ylabel(label)
            if column == "apex_sd_m":
                ax.set_ylim(bottom=0.0)
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        axes[0, j].set_title(f"condition {condition}")
        axes[1, j].set_xlabel("trial number")
    handles = {line.get_label(): line for ax in axes.flat for line in ax.get_lines()
               if line.get_label() in style}
    fig.legend(handles=[handles[s] for s in subjects if s in handles], loc="outside lower center",
               ncol=min(len(subjects), 10), fontsize=7, frameon=False, title="subject",
               title_fontsize=7)
    # the fit the trends were made with (a mixed model from two subjects on; with one, OLS),
    # on a line of its own: a one-condition figure is narrow
    methods = (sorted(trends["method"].dropna().astype(str).unique())
               if trends is not None and "method" in trends else [])
    # 'mixed: random intercept and slope' reads as a sentence in the title
    methods = [f"mixed model with {m.removeprefix('mixed: ')}" if m.startswith("mixed: ")
               else m for m in methods]
    # wrapped to the figure's width: one condition's figure is narrow (the line ran off it)
    method_line = textwrap.fill(f"(fixed effect: {'; '.join(methods)})",
                                width=int(fig.get_figwidth() * TITLE_CHARS_PER_INCH))
    fig.suptitle("Fig. 6 over the study: learning trends"
                 + (f"\n{method_line}" if methods else ""), fontsize=10)
    return fig


def subject_styles(subjects: list[str]) -> dict[str, dict[str, Any]]:
    """A colour and marker per subject, no two subjects alike: tab10's colours (tab20's
    beyond ten subjects), then a new marker each time the colours run out."""
    from matplotlib import colormaps

    cmap = colormaps["tab10" if len(subjects) <= 10 else "tab20"]
    colours = [cmap(i) for i in range(cmap.N)]  # its 10 (20) listed colours
    markers = "o^sDvP*X<>"
    return {subject: {"color": colours[k % len(colours)],
                      "marker": markers[(k // len(colours)) % len(markers)]}
            for k, subject in enumerate(subjects)}


def stability_figure(group: pd.DataFrame, table: pd.DataFrame | None):
    """Each unit's VAR(1) spectral radius from its data (OLS and the noise-robust lag-2
    estimate, interval bars) beside the model's eq. 10 radius at the unit's parameters
    (crosses), units side by side, grouped by condition."""
    conditions = (group["condition"].astype(str) if "condition" in group
                  else pd.Series("all", index=group.index))
    order = group.assign(_c=conditions).sort_values(["_c", "subject"], kind="stable")
    fig, axes = new_figure(1, 1, width=max(6.0, 0.45 * len(order) + 2.5), height=4.8)
    ax = axes[0, 0]
    x = np.arange(len(order))
    highest = 1.0
    for offset, method, color, label in ((-0.12, "ols", "k", "data, OLS VAR(1)"),
                                         (0.12, "lag2", "tab:blue", "data, lag-2 (noise-robust)")):
        y = order[f"radius_{method}"].to_numpy(float)
        ci_low = order[f"radius_{method}_ci_low"].to_numpy(float)
        ci_high = order[f"radius_{method}_ci_high"].to_numpy(float)
        bounded = np.isfinite(ci_low) & np.isfinite(ci_high)
        if bounded.any():
            ax.errorbar((x + offset)[bounded], y[bounded],
                        yerr=np.vstack([y - ci_low, ci_high - y])[:, bounded], fmt="o",
                        color=color, ms=4, capsize=2, label=f"{label} with interval")
        alone = np.isfinite(y) & ~bounded
        if alone.any():  # an estimate without an interval (too few pairs: group.csv's note)
            ax.plot((x + offset)[alone], y[alone], "o", mfc="white", mec=color, ms=4.5,
                    label=f"{label}, no interval (see radius_{method}_note)")
        highest = max(highest, np.nanmax(np.r_[y, ci_high[bounded], 0.0]))
    ax.plot(x, order["model_spectral_radius"], "x", color="tab:red", ms=8, mew=2,
            label="model, eq. 10 at the unit's parameters")
    labels = [f"{s}\n{c}" for s, c in zip(order["subject"].astype(str), order["_c"])]
    ax.set_xticks(x, labels, fontsize=7)
    # a unit's place is one wide, its estimators beside its tick (one unit: autoscaling put
    # them at the axis' two ends)
    ax.set_xlim(-0.6, len(order) - 0.4)
    ax.axhline(1.0, color="0.7", lw=0.8, ls=":")
    ax.set_ylim(0.0, max(1.2, 1.08 * highest))
    ax.set_ylabel("spectral radius")
    ax.set_xlabel("unit (subject, condition)")
    title = "Stability per unit: the data against the model"
    if table is not None and len(table):
        ols = table[table["estimate"] == "ols"]
        # a line per condition: on one line, two conditions ran off the figure's edge
        title += "".join(f"\n{r.condition}: {_difference_words(r)}" for r in ols.itertuples())
    ax.set_title(title, fontsize=9)
    # below the axes: inside, it covered a unit's estimate
    entries = sorted(zip(*ax.get_legend_handles_labels()),  # OLS, lag-2, then the model
                     key=lambda e: (e[1].startswith("model"), "lag-2" in e[1],
                                    "no interval" in e[1]))
    # two columns of these labels need about 8 inches: narrower, one (two ran off both sides)
    fig.legend(*zip(*entries), loc="outside lower center", ncol=2 if fig.get_figwidth() >= 8.0
               else 1, fontsize=7, frameon=False)
    return fig


def _difference_words(row) -> str:
    """A condition's line of the stability title: the data's radius less the model's, mean
    over units with its interval, or why there is none (``verdict``: too few units)."""
    if not np.isfinite(row.difference_mean):
        return f"data - model (OLS): {row.verdict}"
    if not (np.isfinite(row.ci_low) and np.isfinite(row.ci_high)):
        return (f"data - model (OLS) {row.difference_mean:+.3f} ({row.units} unit"
                f"{'s' if row.units != 1 else ''}, no interval)")
    return (f"data - model (OLS) {row.difference_mean:+.3f} "
            f"[{row.ci_low:.3f}, {row.ci_high:.3f}]")


def acf_figure(table: pd.DataFrame):
    """Fig. 8 per condition: each correlation function's mean over units (SD across units as
    bars) and the theory's (eq. 19) mean over units (circles)."""
    fig, axes = new_figure(2, 2, width=9.0, height=6.8, sharex=True)
    conditions = sorted(table["condition"].astype(str).unique())
    for (pair, label), ax in zip(PAIRS, axes.flat):
        for i, condition in enumerate(conditions):
            part = table[(table["condition"].astype(str) == condition) & (table["pair"] == pair)]
            part = part.sort_values("lag")
            color = COLORS[i % len(COLORS)]
            ax.errorbar(part["lag"] + 0.08 * i, part["mean"], yerr=part["sd"], fmt="-",
                        color=color, lw=1.2, capsize=2, label=f"{condition}: data (SD across "
                        "subjects)")
            ax.plot(part["lag"] + 0.08 * i, part["theory_mean"], "o", mfc="none", mec=color,
                    ms=5, label=f"{condition}: eq. 19")
        ax.axhline(0, color="0.8", lw=0.8)
        ax.set_title(label)
        ax.set_ylabel("correlation")
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    for ax in axes[1]:
        ax.set_xlabel("lag (bounces)")
    axes[0, 0].legend(fontsize=6)
    fig.suptitle("Fig. 8 averaged over subjects, per condition", fontsize=10)
    return fig


def impulse_figure(table: pd.DataFrame):
    """Figs. 9 and 11 per condition: mean response after a perturbation of alpha (SD across
    subjects as bars), for decreases (left) and increases (right)."""
    quantities = [(q, label, scale) for q, label, scale in RESPONSES
                  if q in set(table["quantity"])]
    fig, axes = new_figure(len(quantities), 2, width=9.0, height=2.3 * len(quantities) + 0.6,
                           sharex=True)
    conditions = sorted(table["condition"].astype(str).unique())
    for i, (quantity, label, scale) in enumerate(quantities):
        for j, direction in enumerate(("decrease", "increase")):
            ax = axes[i, j]
            for c, condition in enumerate(conditions):
                part = table[(table["condition"].astype(str) == condition)
                             & (table["quantity"] == quantity) & (table["direction"] == direction)]
                part = part.sort_values("k")
                ax.errorbar(part["k"] + 0.08 * c, scale * part["mean"], yerr=scale * part["sd"],
                            fmt="-o", ms=3, color=COLORS[c % len(COLORS)], capsize=2,
                            label=condition)
            ax.axhline(0, color="0.8", lw=0.8)
            low, high = ax.get_ylim()
            floor = RESPONSE_FLOOR[quantity]
            if high - low < 2.0 * floor:
                middle = 0.5 * (low + high)
                ax.set_ylim(middle - floor, middle + floor)
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
            if j == 0:
                ax.set_ylabel(label)
            if i == 0:
                ax.set_title(f"alpha {direction}d at impact 0")
    for ax in axes[-1]:
        ax.set_xlabel("impact after the perturbation, k")
    axes[0, 0].legend(fontsize=7)
    fig.suptitle("Figs. 9 and 11 averaged over subjects (deviation from each trial's baseline)",
                 fontsize=10)
    return fig
