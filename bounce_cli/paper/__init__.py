"""The paper: its printed values and parameter sets (``values``), each number with its unit
and the tolerance its rounding allows. It sits low (the model's and the analyses' rooms below
it), so that anything above may compare with it; the claims and the gallery of
``bounce reproduce`` that read the experiments are ``bounce_cli.reproduction``.
"""
