"""A run's results outside the core: strict JSON (every results file is written with it)
and a journey's per-station results from a run's parameters and series."""
