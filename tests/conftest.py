"""Test configuration: float64 on, strict promotion off (the package mixes Python
floats freely), rank promotion raises (catches silent broadcasting bugs), the
CLI's compilation cache off."""

import os


os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")
# The CLI, called in-process by the tests, would otherwise turn on the persistent
# compilation cache (a global setting) in ~/.cache for the rest of the session.
os.environ.setdefault("LOCOMOTION_JAX_CACHE", "0")

import jax


jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")

import sys
from pathlib import Path


# `reference.py` (the independent scipy solver) is imported by several tests.
sys.path.insert(0, str(Path(__file__).parent))
