"""Steady gaits: periodic orbits, their stability, continuation and basins."""
