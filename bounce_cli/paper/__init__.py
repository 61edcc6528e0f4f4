"""The paper: its printed values and parameter sets (``values``), its claims held against
the results (``claims``) and the gallery that ``bounce reproduce`` writes (``reproduce``).

``values`` sits low (the model's and the analyses' rooms below it, anything above may compare
with it); ``claims`` and ``reproduce`` read the experiments and sit above them.
"""

from ..old_paths import MOVED_INTO_PACKAGE, forward_attributes

# the module ``bounce_cli.paper`` before it was a package: its names, with a warning
__getattr__ = forward_attributes(__name__, MOVED_INTO_PACKAGE[__name__])
