"""The package's version, on the ground floor: ``run.json`` records it and ``bounce --version``
prints it; ``pyproject.toml`` reads it from here."""

__version__ = "0.1.0"
