"""Data from the lab: recordings and their file formats (``recordings``), the impacts table
(``impacts``), the extraction of impacts from recordings (``extraction``), the set-up
measured from data (``setup_table``, ``data_parameters``), a study's manifest
(``study_manifest``), the plausibility of a racket's motion (``plausibility``) and the
simulated lab session (``simulated_lab``)."""
