"""What is computed from the model: basin classification (section 3) and basin measures, the
stochastic map and its VAR(1) theory (section 6), the VAR fits to data, impulse responses
(section 7), eq. 15's regression, Lyapunov exponents, bifurcation diagrams, continuation,
parameter sweeps and the data statistics. Numpy/scipy only: no files, no printing::

    from bounce_cli.analysis import ClassifySettings, classify_grid
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..lazy import lazy_exports

if TYPE_CHECKING:  # for type checkers: the names as if imported eagerly
    from .classify import OUTCOMES, Classification, ClassifySettings, classify_batch, classify_grid
    from .impulse import find_threshold, impulse_response_full, impulse_response_linear
    from .regression import eq15_slope, ols_line
    from .stochastic import simulate_stochastic_map, var1_theory

#: exported name -> its submodule, imported on first use (PEP 562)
_EXPORTS = {
    **dict.fromkeys(("OUTCOMES", "Classification", "ClassifySettings", "classify_batch",
                     "classify_grid"), "classify"),
    **dict.fromkeys(("simulate_stochastic_map", "var1_theory"), "stochastic"),
    **dict.fromkeys(("find_threshold", "impulse_response_full", "impulse_response_linear"),
                    "impulse"),
    **dict.fromkeys(("eq15_slope", "ols_line"), "regression"),
}

__all__ = [
    # basin classification (section 3, Fig. 4)
    "classify_batch", "classify_grid", "ClassifySettings", "Classification", "OUTCOMES",
    # stochastic map and eq. 19 (section 6)
    "simulate_stochastic_map", "var1_theory",
    # impulse responses (section 7)
    "impulse_response_full", "impulse_response_linear", "find_threshold",
    # eq. 15 (section 5)
    "eq15_slope", "ols_line",
]

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
