"""The paper's printed values, in one place: its parameter sets and the numbers it reports.

"The dialogue between data and model: passive stability and relaxation behavior in a ball
bouncing task" (sections, equations and figures numbered as there). Experiments compare
their results with these values only when they run at the paper's parameters
(:func:`at_parameters`), and ``bounce verify`` (:mod:`bounce_cli.reproduction.claims`) holds
the reproduced results against them. Nothing here is computed from the model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from decimal import Decimal

from ..analysis.classify import ClassifySettings
from ..model.params import ModelParams


@dataclass(frozen=True)
class Printed:
    """A number as the paper prints it: ``text`` (its digits), unit and where it is printed.
    ``value`` is the number; ``tolerance`` what its rounding allows (half a unit in the last
    printed digit) unless the paper's wording ("about") allows more (``tolerance_override``)."""

    text: str
    unit: str
    where: str
    tolerance_override: float | None = None

    @property
    def value(self) -> float:
        return float(self.text)

    @property
    def resolution(self) -> float:
        """One unit in the last printed digit (0.1 for "4.5", 1 for "42")."""
        exponent = Decimal(self.text).as_tuple().exponent
        assert isinstance(exponent, int)
        return 10.0**exponent

    @property
    def tolerance(self) -> float:
        if self.tolerance_override is not None:
            return self.tolerance_override
        return self.resolution / 2

    def __str__(self) -> str:
        return f"{self.text} {self.unit}".strip()

    def tolerance_text(self) -> str:
        """The tolerance and why: the printed resolution, or the paper's wording."""
        unit = f" {self.unit}" if self.unit else ""
        why = ("the paper says 'about'" if self.tolerance_override is not None
               else f"printed to {number_text(self.resolution)}{unit}")
        return f"+-{number_text(self.tolerance)}{unit} ({why})"


def number_text(x: float) -> str:
    """A number as short as it reads: 0.05, 1e-9 (not 1e-09)."""
    return f"{x:g}".replace("e-0", "e-").replace("e+0", "e+")


# -- parameter sets --------------------------------------------------------------------------
#: Figs. 3, 4 (section 3), the section 5 example, and the perturbation model of Figs. 9, 10
#: (section 7): alpha 0.5, g 9.81 m/s^2, a_r 0.30 m, omega_r = 2 pi / 0.92 rad/s
FIG3_MODEL = ModelParams(alpha=0.5, g=9.81, racket_amplitude=0.30, racket_period=0.92)
#: Fig. 8 (section 6): the physical set-up (alpha 0.42, g 5.8 m/s^2 on a boom) with the
#: racket amplitude and period the paper used for the theory
FIG8_MODEL = ModelParams(alpha=0.42, g=5.8, racket_amplitude=0.065, racket_period=0.55)
#: section 3's stopping conditions (100 impacts, 1e-3 m/s and rad, 1e-3 s): the engine's
#: defaults are the paper's values
SECTION3_CLASSIFY = ClassifySettings()

# -- section 3, Fig. 3 -----------------------------------------------------------------------
#: x_b(0): the ball's initial height, on the racket (m)
FIG3_BALL_HEIGHT_M = 0.205
#: v_b(0) of the two panels: the period-1 attractor (top) and the sticking solution (bottom)
FIG3_V0_M_S = {"fig3_period1": 4.8, "fig3_sticking": 5.7}

# -- section 5 --------------------------------------------------------------------------------
#: the stable AC range for alpha = 0.5 ("between 0 and -1.11 g", eq. 14)
STABLE_AC_LOW = Printed("-1.11", "g", "section 5")
STABLE_AC_ALPHA = 0.5
#: R^2 of the Fig. 7 regression, vision and no-vision conditions (human data)
FIG7_R2 = {"vision": Printed("0.98", "", "section 5"),
           "no vision": Printed("0.90", "", "section 5")}

# -- section 6, Fig. 8 ------------------------------------------------------------------------
#: both eigenvalues 0.5 in absolute value (at the Fig. 3 parameters)
EIGENVALUE_MODULUS = Printed("0.5", "", "section 6")
SD_V_THEORY = Printed("0.068", "m/s", "section 6")
SD_THETA_THEORY = Printed("8.4", "deg", "section 6")
SD_V_OBSERVED = Printed("0.07", "m/s", "section 6")
SD_THETA_OBSERVED = Printed("9.2", "deg", "section 6")
#: noise strengths of eqs. 16, 18
Q_V_M_S, Q_THETA_RAD = 0.04, 0.05
#: the racket the subjects actually moved (section 6): mean amplitude and period
OBSERVED_AMPLITUDE_M, OBSERVED_PERIOD_S = 0.076, 0.53
#: three recorded trials of 40 s
TRIALS, TRIAL_DURATION_S = 3, 40.0

# -- section 7, Figs. 9, 10 -------------------------------------------------------------------
#: Fig. 9 caption: stationary velocity and phase
FIG9_V_FIXED = Printed("4.5", "m/s", "Fig. 9 caption")
FIG9_THETA_FIXED = Printed("42", "deg", "Fig. 9 caption")
#: alpha_p of the simulation (0.4, 0.6) and the experiment's averages (0.35, 0.65)
ALPHA_P_SIMULATED, ALPHA_P_EXPERIMENT = (0.4, 0.6), (0.35, 0.65)
#: "perturbations with alpha_p >~ 0.65 take the system out of the domain of attraction"
ALPHA_P_THRESHOLD = Printed("0.65", "", "section 7", tolerance_override=0.025)
#: "alpha_p = 0.7 corresponds to an initial velocity v_0 of 5.7 m/s"
ALPHA_P_FIG3 = 0.7
V0_AT_ALPHA_P_FIG3 = Printed("5.7", "m/s", "section 7")


def at_parameters(params: ModelParams, paper: ModelParams) -> bool:
    """True when ``params`` are the paper's parameter set ``paper`` (to the printed digits):
    only then do our numbers and the paper's describe the same system."""
    return all(math.isclose(getattr(params, name), getattr(paper, name), rel_tol=1e-12)
               for name in ("alpha", "g", "racket_amplitude", "racket_period"))


def parameters_text(params: ModelParams) -> str:
    """The model parameters as a figure caption shows them."""
    return (f"alpha = {params.alpha:g}, g = {params.g:g} m/s^2, "
            f"a_r = {params.racket_amplitude:g} m, tau = {params.racket_period:g} s")
