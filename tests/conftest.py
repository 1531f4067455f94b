"""Test configuration: float64 on, strict promotion off (the package mixes Python
floats freely), rank promotion raises (catches silent broadcasting bugs)."""

import os


os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")

import jax


jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")

import sys
from pathlib import Path


# `reference.py` (the independent scipy solver) is imported by several tests.
sys.path.insert(0, str(Path(__file__).parent))
