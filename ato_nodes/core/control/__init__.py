"""Controllers, the limiter between a law and the train, the ATO's nominal train, and
seed 001's model and its identification."""
