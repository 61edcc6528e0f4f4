"""The virtual set-up (sections 6-7): a racket stream in, a model ball out.

* :mod:`.physics`: the ball of the model (eqs. 1-3) on a sampled racket, exact between
  samples and driven by the samples' arrival, not by a display's frame rate;
* :mod:`.sources`: where racket samples come from (``sine``, ``replay:<file>``);
* :mod:`.session`: a protocol's trials (perturbations of alpha every N-th impact, seeded),
  run headless, into tables ``bounce extract`` and ``bounce study`` read.
"""
