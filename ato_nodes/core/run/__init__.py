"""A run: the loop's stages, simulate() and its compiled twin, the scorer of a run."""
