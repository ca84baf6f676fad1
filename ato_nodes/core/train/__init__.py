"""The real train (core.train.plant) and its line (core.train.line)."""
