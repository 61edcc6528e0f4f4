"""The paper: its printed values and parameter sets (``values``), its claims held against
the results (``claims``) and the gallery that ``bounce reproduce`` writes (``reproduce``).

``values`` sits low (the model's and the analyses' rooms below it, anything above may compare
with it); ``claims`` and ``reproduce`` read the experiments and sit above them.
"""
