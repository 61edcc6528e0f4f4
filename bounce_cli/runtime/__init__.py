"""What a run stands on, knowing no experiment: the configs (``config``: YAML -> pydantic
models, ``--set`` overrides), run directories and their tables (``artifacts``), the
executors of parallel work (``parallel``), the finished points of a long run
(``checkpoints``) and signals (``interrupts``)."""
