"""The module paths of bounce before its rooms (issue 23), kept importable with a warning.

Until 0.2 the package was flat: ``bounce_cli.engine.params``, ``bounce_cli.config``,
``bounce_cli.recordings``, ... Each such path still imports, and gives the module at its new
home, after a :class:`DeprecationWarning` naming that home. This module is the one place
that knows the old paths: :data:`MOVED_MODULES` (old module -> new module) and
:data:`ENGINE_EXPORTS` (the names that ``bounce_cli.engine`` re-exported -> their new
module), served by one meta-path finder (:class:`OldPathFinder`, installed when
``bounce_cli`` is imported) and, for the two old modules whose name is now a package's
(``bounce_cli.paper``, ``bounce_cli.cli``), by :func:`forward_attributes`. Standard library
only: it is imported at every start.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import types
import warnings
from typing import Any, Callable, Sequence

#: old module path -> its new home
MOVED_MODULES: dict[str, str] = {
    **{f"bounce_cli.engine.{name}": f"bounce_cli.model.{name}" for name in (
        "params", "impact", "maps", "flight", "chatter", "linear", "compiled", "reference")},
    **{f"bounce_cli.engine.{name}": f"bounce_cli.analysis.{name}" for name in (
        "classify", "basin_measures", "stochastic", "var_fit", "racket_inputs", "impulse",
        "regression", "lyapunov", "bifurcation", "continuation", "sweep", "group_stats",
        "data_stats", "roots")},
    "bounce_cli.engine.extraction": "bounce_cli.data.extraction",
    "bounce_cli.engine.recording": "bounce_cli.data.simulated_lab",
    **{f"bounce_cli.{name}": f"bounce_cli.data.{name}" for name in (
        "impacts", "setup_table", "data_parameters", "study_manifest", "plausibility",
        "recordings")},
    **{f"bounce_cli.recordings.{name}": f"bounce_cli.data.recordings.{name}" for name in (
        "markers", "text_exports", "c3d_files")},
    **{f"bounce_cli.{name}": f"bounce_cli.experiments.{name}" for name in (
        "plotting", "report", "registry")},
    **{f"bounce_cli.{name}": f"bounce_cli.runtime.{name}" for name in (
        "artifacts", "parallel", "checkpoints", "interrupts", "config")},
    "bounce_cli.claims": "bounce_cli.paper.claims",
    "bounce_cli.reproduce": "bounce_cli.paper.reproduce",
}

#: old modules whose name is now a package: their attributes are the new module's
MOVED_INTO_PACKAGE: dict[str, str] = {
    "bounce_cli.paper": "bounce_cli.paper.values",
    "bounce_cli.cli": "bounce_cli.cli.commands",
}

#: the package ``bounce_cli.engine`` (gone): the names it re-exported -> their new module
ENGINE_EXPORTS: dict[str, str] = {
    **dict.fromkeys(("OUTCOMES", "Classification", "ClassifySettings", "classify_batch",
                     "classify_grid"), "bounce_cli.analysis.classify"),
    **dict.fromkeys(("FlightSettings", "Trajectory", "simulate"), "bounce_cli.model.flight"),
    "next_impact_phase": "bounce_cli.model.impact",
    **dict.fromkeys(("find_threshold", "impulse_response_full", "impulse_response_linear"),
                    "bounce_cli.analysis.impulse"),
    **dict.fromkeys(("Stability", "flip_boundary_g", "jacobian", "stability"),
                    "bounce_cli.model.linear"),
    **dict.fromkeys(("Orbit", "iterate_map", "iterate_orbit", "map_step"),
                    "bounce_cli.model.maps"),
    **dict.fromkeys(("FixedPoint", "ModelError", "ModelParams", "NoFixedPointError",
                     "wrap_phase"), "bounce_cli.model.params"),
    **dict.fromkeys(("eq15_slope", "ols_line"), "bounce_cli.analysis.regression"),
    **dict.fromkeys(("simulate_stochastic_map", "var1_theory"),
                    "bounce_cli.analysis.stochastic"),
}

#: old packages and modules that have no one new module: served as an empty package of these
#: names (name -> its module), or of every name of the new modules listed (the first that
#: has it): ``engine.control`` is now the controlled map (``model.control``) and its design
#: (``analysis.control_design``)
OLD_PACKAGES: dict[str, dict[str, str] | tuple[str, ...]] = {
    "bounce_cli.engine": ENGINE_EXPORTS,
    "bounce_cli.engine.control": ("bounce_cli.model.control",
                                  "bounce_cli.analysis.control_design"),
}


def warn_moved(old: str, new: str, stacklevel: int = 3) -> None:
    """Warn that ``old`` (a module or a name in one) is now ``new``.

    Parameters
    ----------
    old, new : str
        The dotted paths, old and new.
    stacklevel : int
        Passed on to :func:`warnings.warn` (the importer's frame).
    """
    warnings.warn(f"{old} has moved to {new}; import it from there (the old path will be "
                  "removed)", DeprecationWarning, stacklevel=stacklevel)


def forward_attributes(package: str,
                       exports: dict[str, str] | tuple[str, ...] | str) -> Callable[[str], Any]:
    """A PEP 562 ``__getattr__`` for the old module ``package``: each name is served, after
    a :class:`DeprecationWarning`, from its new module.

    Parameters
    ----------
    package : str
        The old module's path (now a package, or an empty package made here).
    exports : dict, tuple or str
        Name -> its new module; or the new modules holding the names (the first that has
        the name serves it); or one new module holding every name.

    Returns
    -------
    callable
        The ``__getattr__`` to assign.
    """

    def __getattr__(name: str) -> Any:
        if isinstance(exports, tuple):
            home = next((m for m in exports if not name.startswith("__")
                         and hasattr(importlib.import_module(m), name)), None)
        else:
            home = exports if isinstance(exports, str) else exports.get(name)
        if home is None or name.startswith("__"):
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(home), name)  # AttributeError as it is
        warn_moved(f"{package}.{name}", f"{home}.{name}")
        return value

    return __getattr__


class OldPathLoader(importlib.abc.Loader):
    """Loads an old path: the new module itself (one module object under both names), or,
    for an old package with no single new home, an empty package forwarding its names."""

    def __init__(self, old: str) -> None:
        self.old = old
        self.real_spec: Any = None

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> types.ModuleType:
        if self.old in OLD_PACKAGES:
            module = types.ModuleType(self.old, f"The old package {self.old}: see "
                                                f"bounce_cli.old_paths.")
            module.__path__ = []  # a package: its submodules are found by OldPathFinder
            module.__getattr__ = forward_attributes(  # type: ignore[method-assign]
                self.old, OLD_PACKAGES[self.old])
            warn_moved(self.old, "bounce_cli.model and bounce_cli.analysis", stacklevel=2)
            return module
        new = MOVED_MODULES[self.old]
        module = importlib.import_module(new)
        self.real_spec = module.__spec__
        warn_moved(self.old, new, stacklevel=2)
        return module

    def exec_module(self, module: types.ModuleType) -> None:
        if self.real_spec is not None:  # the import system set the old spec on the module
            module.__spec__ = self.real_spec


class OldPathFinder(importlib.abc.MetaPathFinder):
    """Finds the old module paths of :data:`MOVED_MODULES` and :data:`OLD_PACKAGES`."""

    def find_spec(self, fullname: str, path: Sequence[str] | None = None,
                  target: types.ModuleType | None = None) -> importlib.machinery.ModuleSpec | None:
        if fullname not in MOVED_MODULES and fullname not in OLD_PACKAGES:
            return None
        return importlib.machinery.ModuleSpec(fullname, OldPathLoader(fullname),
                                              is_package=fullname in OLD_PACKAGES)


def install() -> None:
    """Put :class:`OldPathFinder` first on :data:`sys.meta_path` (once), so that an old path
    gives the one module object at the new home, not a second copy of its file."""
    if not any(isinstance(finder, OldPathFinder) for finder in sys.meta_path):
        sys.meta_path.insert(0, OldPathFinder())
