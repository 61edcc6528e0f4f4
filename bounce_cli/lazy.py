"""Lazy exports (PEP 562) for the package's faces: a name is imported on first use. Standard
library only, on the ground floor, so that every package's ``__init__`` may use it."""

from __future__ import annotations

import importlib
import sys
from typing import Any


def lazy_exports(package: str, exports: dict[str, str]):
    """A package's PEP 562 ``__getattr__`` and ``__dir__`` for ``exports`` (name -> its
    submodule, relative to ``package``): each name is imported on first use and then kept
    in the package's namespace.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    exports : dict
        Exported name -> the submodule defining it (``"api"`` for ``package.api``).

    Returns
    -------
    tuple
        (``__getattr__``, ``__dir__``) to assign at the package's top level.
    """
    namespace = sys.modules[package].__dict__

    def __getattr__(name: str) -> Any:
        try:
            module = exports[name]
        except KeyError:
            raise AttributeError(f"module {package!r} has no attribute {name!r}") from None
        value = getattr(importlib.import_module(f".{module}", package), name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted([*namespace, *exports])

    return __getattr__, __dir__
