"""Optimal actuation and parameter identification."""
