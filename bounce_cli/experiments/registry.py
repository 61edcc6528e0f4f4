"""The one list of experiments: the CLI makes a command of each, ``bounce reproduce`` runs
those marked ``reproduce``, and the tests read it. Light on purpose (no numpy, no experiment
import) so that ``bounce --help`` stays fast; :meth:`Entry.load` imports the module.

Adding an experiment: see :mod:`bounce_cli.experiments.base` for the contract, then add one
:class:`Entry` here.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .base import Experiment


@dataclass(frozen=True)
class Entry:
    """One experiment: command name, one-line summary, its figures as (file, caption), and
    what it can do. Its module is ``bounce_cli.experiments.<module>`` and its bundled config
    ``configs/<config>.yaml`` (both default to the name, with ``-`` as ``_`` for the module).

    ``data_help``: the command takes ``--data FILE``, which sets the config key ``data``
    (the text is the option's help); ``events_help`` likewise for ``--events FILE`` (config
    key ``events``). ``needs_fixed_point``: the run is about the period-1
    fixed point, so the CLI warns when it is unstable. ``reproduce``: part of
    ``bounce reproduce`` and of the committed ``results/``. ``resumable``: the command takes
    ``--resume`` (the run keeps finished tasks in ``RunOptions.checkpoints``); ``parallel``:
    it takes ``--jobs N`` (its tasks run on N local workers); ``cluster``:
    it takes ``--scheduler ADDRESS`` (its tasks can run on a Dask cluster). ``attribute``:
    the module's attribute holding the :class:`Experiment` (one module may define several).
    ``manifest_help``: the command takes ``--manifest FILE`` (config key ``manifest``);
    ``racket_help``: the command takes ``--racket SOURCE`` (config key ``racket``);
    ``live``: the command shows a page and takes ``--headless``, ``--realtime`` and
    ``--port N`` (config keys ``display.headless``, ``display.realtime``, ``display.port``);
    ``task_keys``: its resumed tasks carry keys of what they were made from and are rerun
    when those change, so ``--resume`` accepts a changed config (the experiment decides
    which tasks to keep)."""

    name: str
    summary: str
    figures: tuple[tuple[str, str], ...]
    data_help: str | None = None
    events_help: str | None = None
    needs_fixed_point: bool = True
    reproduce: bool = True
    resumable: bool = False
    parallel: bool = False
    cluster: bool = False
    module: str = ""
    config: str = ""
    attribute: str = "EXPERIMENT"
    manifest_help: str | None = None
    task_keys: bool = False
    racket_help: str | None = None
    live: bool = False

    def __post_init__(self) -> None:
        if not self.module:
            object.__setattr__(self, "module", self.name.replace("-", "_"))
        if not self.config:
            object.__setattr__(self, "config", self.name)

    def load(self) -> Experiment:
        module = importlib.import_module(f"bounce_cli.experiments.{self.module}")
        experiment: Experiment = getattr(module, self.attribute)
        return experiment


#: every experiment, in the paper's order of figures
EXPERIMENTS: tuple[Entry, ...] = (
    Entry(
        "trajectory",
        "Continuous-time ball and racket trajectories with sticking (paper Figs. 2, 3).",
        (("trajectory.png", "Figs. 2-3 (section 3): ball and racket trajectories of the two "
          "coexisting attractors, period-1 (v0 = 4.8 m/s) and sticking (v0 = 5.7 m/s), with "
          "the discrete v_k and theta_k per bounce."),),
    ),
    Entry(
        "basin",
        "Basin of attraction of the period-1 attractor over (theta0, v0) (paper Fig. 4).",
        (("basin.png", "Fig. 4 (section 3): domain of attraction of the period-1 attractor; "
          "white period-1, grey sticking, black below the racket."),
         ("basin_iterations.png", "Section 3: number of impacts until each initial condition "
          "was classified.")),
        parallel=True,
    ),
    Entry(
        "stability",
        "Linear stability diagram and coarse-grained predictions (paper Fig. 5, sections 4-5).",
        (("stability.png", "Fig. 5 (section 4): stability diagram in (alpha, AC) and the "
          "largest |lambda| where stable."),),
    ),
    Entry(
        "learning",
        "Learning study: AC and ball-amplitude variability over trials vs eq. 19 (paper Fig. 6).",
        (("learning.png", "Fig. 6 (section 5): SD of ball amplitude predicted by eq. 19 as a "
          "function of the racket acceleration at impact AC at fixed noise, stable range of "
          "eq. 14 shaded (with --data: the data's trials beside it)."),),
        data_help="Impacts table (impacts.csv, with racket_acc_g and ball_apex_m): per-trial "
        "AC and variability and their trends (sets the config key `data`).",
        needs_fixed_point=False,
    ),
    Entry(
        "regression",
        "Racket amplitude vs squared period, OLS against eq. 15 (paper Fig. 7).",
        (("regression.png", "Fig. 7 (section 5, eq. 15): trial means of racket amplitude "
          "regressed on the squared racket period (simulated trials)."),),
        data_help="Trials CSV (a_r_m, tau_s; optional theta_deg, alpha, g, condition), or an "
        "impacts table (impacts.csv) averaged per trial, to fit instead of simulating (sets "
        "the config key `data`).",
    ),
    Entry(
        "acf",
        "Correlation functions of the stochastic map vs the VAR(1) theory (paper Fig. 8).",
        (("acf.png", "Fig. 8 (section 6): auto- and cross-correlation functions of the "
          "stochastic map: theory (circles) and samples (crosses)."),),
        data_help="Impacts table (impacts.csv): the data's correlation functions and the "
        "VAR(1) stability measured from it, beside eq. 19 and eqs. 9-10 at the data's "
        "parameters (sets the config key `data`).",
    ),
    Entry(
        "impulse",
        "Impulse responses after a perturbation of alpha, full vs linear (paper Figs. 9, 10).",
        (("impulse.png", "Fig. 9 (section 7): relaxation of velocity and phase after a "
          "perturbation of the coefficient of restitution (model curves)."),
         ("impulse_linear.png", "Fig. 10 (section 7): full map vs its linearisation with the "
          "same Jacobian.")),
        data_help="Impacts table with `alpha` and `perturbed` columns: the data's responses "
        "aligned on the perturbed impacts beside the model's (Figs. 9, 11; sets the config "
        "key `data`).",
    ),
    Entry(
        "simulate-recording",
        "A simulated lab session with known truth: recording, events, exact impacts (Fig. 2).",
        (("recording.png", "Fig. 2's raw data, simulated (section 2, eqs. 1-4 and 16): ball and "
          "racket of trial 1 with the exact v_k and theta_k; perturbed impacts in red."),),
        module="simulate_recording", config="recording",
    ),
    Entry(
        "extract",
        "Recording (CSV, C3D, Vicon, QTM or Motive export) -> impacts table: theta_k, v_k, "
        "AC per bounce (paper Fig. 2).",
        (("fig2.png", "Fig. 2 (section 2): continuous ball and racket trajectories and the "
          "extracted v_k and theta_k per bounce, sample means dashed."),),
        data_help="Recording to extract: CSV (columns: trial, t_s, racket_x_m, ball_x_m), "
        ".c3d, or a Vicon Nexus CSV, Qualisys TSV or OptiTrack Motive CSV export (detected, or "
        "--set format=vicon|qtm|motive; the markers block names the racket and ball) (sets "
        "the config key `data`; default: the bundled simulated session).",
        events_help="Events CSV (trial, t_s[, alpha]): the impact times of a virtual set-up "
        "(sets the config key `events`).",
        needs_fixed_point=False,
    ),
    Entry(
        "learning-data",
        "Fig. 6 on a synthetic lab: a learning series simulated, extracted and analysed.",
        (("learning.png", "Fig. 6 (section 5) on a simulated lab session: a learning series of "
          "racket amplitudes (AC from -0.25 to -0.75 g), recorded, extracted and analysed as "
          "`bounce learning --data`; per-trial AC and SD of ball amplitude beside eq. 19."),),
        needs_fixed_point=False, module="lab", attribute="LEARNING",
    ),
    Entry(
        "regression-data",
        "Fig. 7 on a synthetic lab: trials at three rackets simulated, extracted, analysed.",
        (("regression.png", "Fig. 7 (section 5, eq. 15) on a simulated lab session: trials at "
          "three racket periods with eq. 15's amplitudes, recorded, extracted, averaged per "
          "trial and regressed as `bounce regression --data impacts.csv`."),),
        module="lab", attribute="REGRESSION",
    ),
    Entry(
        "acf-data",
        "Fig. 8 on a synthetic lab: steady bouncing simulated, extracted and analysed.",
        (("acf_data.png", "Fig. 8 (section 6) on a simulated lab session at Fig. 8's "
          "parameters: the extracted data's correlation functions (grey) beside eq. 19."),
         ("stability_data.png", "Stability measured from the simulated session: VAR(1) "
          "eigenvalues (OLS and lag-2) beside eq. 10, and the bounces each estimate needs.")),
        module="lab", attribute="ACF",
    ),
    Entry(
        "impulse-data",
        "Figs. 9, 11 on a synthetic lab: perturbations simulated, extracted, aligned.",
        (("impulse_data.png", "Fig. 9 (section 7) on a simulated lab session: responses to "
          "alpha perturbations aligned on the perturbed impacts (black) beside the model's "
          "(grey)."),
         ("modulation_data.png", "Fig. 11 on the simulated session: racket period and "
          "amplitude per impact after a perturbation (the passive racket: flat).")),
        module="lab", attribute="IMPULSE",
    ),
    Entry(
        "bifurcation",
        "Bifurcation diagram and Lyapunov exponents over one swept parameter (eqs. 5-14).",
        (("bifurcation.png", "Beyond the paper (eqs. 5, 6, 8, 14): velocity after impact "
          "against Gamma = a_r w^2 / g at alpha 0.5, with the period-1 orbit's existence "
          "(eq. 8) and flip (eq. 14) thresholds, and the largest Lyapunov exponent below."),),
        needs_fixed_point=False,
    ),
    Entry(
        "continuation",
        "Periodic orbits continued in one parameter; flips, folds and grazings located.",
        (("continuation.png", "Beyond the paper (eqs. 5, 6, 8, 14): periodic orbits followed by "
          "pseudo-arclength continuation over Gamma at alpha 0.5 (the period-doubling cascade "
          "to period 32, the orbit hopping two racket cycles) over the brute-force bifurcation "
          "diagram, flips, folds and grazings marked; the largest multiplier below."),),
        needs_fixed_point=False,
    ),
    Entry(
        "control",
        "Racket period as a third state (active period control, sections 7-8's future work).",
        (("control_stability.png", "Sections 7-8 (future work): spectral radius of the map "
          "with racket period control over gain K and rate c (and around its minimum); along K "
          "at c = 1 the radius and the full map's impacts to relax after section 7's "
          "perturbations."),
         ("control_impulse.png", "Fig. 9 with period control: passive (grey) and controlled "
          "(black) impulse responses, and the racket period per impact (the model's Fig. 11)."),
         ("control_basin.png", "Fig. 4 without and with racket period control."),
         ("control_acf.png", "Fig. 8's correlation functions without and with racket period "
          "control (VAR(1) theory and the controlled stochastic map)."),
         ("control_fit.png", "Fit of K and c to mean perturbation responses (simulated trials "
          "of a known controller, or --data).")),
        data_help="impacts.csv with perturbation events (trial, k, theta_rad, v_m_s, "
        "racket_period_s, racket_amplitude_m, perturbed; optional alpha): fit K and c to it, "
        "every result at the data's racket, alpha and g (sets `data`).",
        parallel=True,
    ),
    Entry(
        "attractors",
        "Every basin point named: attractors by recurrence, fractions, entropy, continuation.",
        (("attractors.png", "Beyond the paper (section 3's Fig. 4, every start named): the "
          "basins of the attractors found by recurrence on the exact map, the attractors as "
          "markers, each one's share of the starts."),
         ("attractors_continuation.png", "Beyond the paper: the attractors' basin fractions "
          "continued over Gamma (stacked), eq. 8's existence and eq. 14's flip of the period-1 "
          "orbit marked.")),
        needs_fixed_point=False, reproduce=False, parallel=True,
    ),
    Entry(
        "sweep",
        "Basin atlas over a grid of parameters: fractions, basin entropy, stability (Fig. 4 x 5).",
        (("sweep.png", "Beyond the paper (section 3's basin over section 4's plane): at each "
          "(alpha, AC) the basin's outcome fractions, the fixed point's spectral radius (eq. "
          "10), the basin entropy and boundary basin entropy; dashed: spectral radius 1."),),
        needs_fixed_point=False, resumable=True, parallel=True, cluster=True,
    ),
    Entry(
        "simulate-study",
        "A simulated lab study with known truth: subjects x conditions x trials of recordings.",
        (),
        needs_fixed_point=False, reproduce=False, module="simulate_study",
    ),
    Entry(
        "study",
        "A lab's whole study: every recording extracted and analysed, group statistics, report.",
        (("group_regression.png", "Fig. 7 over the study: trial means of racket amplitude "
          "against squared period, pooled by condition, with eq. 15's prediction."),
         ("group_learning.png", "Fig. 6 over the study: per-trial AC and SD of ball amplitude "
          "of every subject, and the mixed model's fixed-effect trend."),
         ("group_stability.png", "The data's VAR(1) spectral radius per unit against the "
          "model's (eq. 10 at the unit's parameters)."),
         ("group_acf.png", "Fig. 8 per condition, averaged over subjects."),
         ("group_impulse.png", "Figs. 9 and 11 per condition, averaged over subjects.")),
        manifest_help="The study's manifest CSV: one row per recording (file, subject[, "
        "condition, trial, events, extract.<key>]); sets the config key `manifest`.",
        needs_fixed_point=False, reproduce=False, resumable=True, parallel=True, cluster=True,
        task_keys=True,
    ),
    Entry(
        "virtual",
        "The paper's virtual set-up: a racket stream drives the model's ball (sections 6-7).",
        (("virtual.png", "The virtual set-up (sections 6-7): ball and racket of trial 1, the "
          "exact impacts' v_k and theta_k; perturbed impacts in red."),),
        racket_help="The racket's source: sine (the model's racket, eq. 4), replay:<file> "
        "(the racket of a recording bounce extract reads), lsl:<stream name> (a live Lab "
        "Streaming Layer stream), mouse (the pointer's height on the page) or subject (a "
        "simulated subject controlling the racket's period); sets the config key `racket`.",
        needs_fixed_point=False, reproduce=False, live=True,
    ),
)

BY_NAME: dict[str, Entry] = {entry.name: entry for entry in EXPERIMENTS}


def entry(name: str) -> Entry:
    return BY_NAME[name]


def reproduced() -> tuple[Entry, ...]:
    """The experiments ``bounce reproduce`` runs, in order."""
    return tuple(e for e in EXPERIMENTS if e.reproduce)
