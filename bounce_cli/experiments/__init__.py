"""One module per paper experiment: config -> tidy DataFrames (+ figures drawn from them).

The contract of an experiment is in :mod:`bounce_cli.experiments.base`, the list of them in
:mod:`bounce_cli.experiments.registry` (light: ``bounce --help`` reads it without numpy), the
one way to run one in :mod:`bounce_cli.experiments.runner`.
"""
