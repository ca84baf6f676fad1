"""Target profiles and seed 002's driving strategies."""
