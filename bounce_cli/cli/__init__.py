"""The command line: the typer app (``commands``) and the console script's entry point."""

from ..old_paths import MOVED_INTO_PACKAGE, forward_attributes

# the module ``bounce_cli.cli`` before it was a package: its names, with a warning
__getattr__ = forward_attributes(__name__, MOVED_INTO_PACKAGE[__name__])
