"""Indices from a run's series and the catalogue of their names, requirements and fitnesses."""
