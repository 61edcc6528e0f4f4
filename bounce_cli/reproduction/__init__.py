"""The reproduction of the paper: its claims held against the results (``claims``), the
gallery that ``bounce reproduce`` writes and its reproduction tolerance (``reproduce``), and
what reproduces of the tables of chaotic orbits on another machine (``chaotic_tables``).
They read the experiments and sit above them; the paper's printed values
(``bounce_cli.paper.values``) sit low, below everything that compares with them.
"""
