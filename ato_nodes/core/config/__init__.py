"""A run's configuration: the registered kinds, every parameter, the run context,
scenario files and prepare()."""
