"""Test configuration: float64 on, strict promotion off (the package mixes Python
floats freely), rank promotion raises (catches silent broadcasting bugs), the
CLI's own compilation cache off, one lasting compilation cache shared by the runs and their workers,
and the tests marked `slow` run only with `--slow`."""

import os


os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")
# The CLI, called in-process by the tests, would otherwise turn on the persistent
# compilation cache (a global setting) in ~/.cache for the rest of the session.
os.environ.setdefault("LOCOMOTION_JAX_CACHE", "0")

import shutil
import tempfile
import warnings
from pathlib import Path

import jax
import pytest


jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")


_OWN_CACHE: list[str] = []


LASTING_CACHE_BYTES = 2**30
"""Bound on the lasting test compilation cache: a run that finds it larger empties it first
(a full run writes about 60 MB per version of the code)."""


def _shared_compilation_cache() -> None:
    """One persistent compilation cache for the test runs, shared by pytest-xdist's workers.

    The workers run different tests that compile many of the same programs (the engines
    at the same batch shapes and settings); with the cache, a program one worker compiled
    is read back by the other instead of compiled again, and a later run reads back what an
    earlier one compiled. By default the cache lasts, in `locomotion_jax/tests` under the
    platform's per-user cache directory (`_cache.user_cache_root`: `$XDG_CACHE_HOME` or
    `~/.cache` on Linux), beside the package's own cache and apart from it, emptied by the
    run that finds it over `LASTING_CACHE_BYTES`.
    `LJ_TEST_CACHE_DIR` names another lasting directory; `LJ_TEST_CACHE_DIR=fresh` makes a
    new temporary one for the run (every program compiled, as on a clean machine) and
    deletes it at the end; `LJ_TEST_CACHE_DIR=off` turns the cache off. The controlling
    process resolves the choice and passes the directory to the workers in
    `LJ_TEST_CACHE_DIR`. Results do not depend on it: JAX's key covers the program, the
    compiler options, `XLA_FLAGS`, the devices and the JAX version, and an entry it cannot
    read (one another process is still writing) is compiled again, with a warning.
    """
    from locomotion_jax import _cache

    path = os.environ.get("LJ_TEST_CACHE_DIR")
    if path == "off":
        return
    if path == "fresh":
        path = tempfile.mkdtemp(prefix="locomotion_jax-tests-")
        os.environ["LJ_TEST_CACHE_DIR"] = path  # inherited by the workers
        _OWN_CACHE.append(path)
    else:
        if not path:
            path = str(_cache.user_cache_root() / "locomotion_jax" / "tests")
            os.environ["LJ_TEST_CACHE_DIR"] = path
        if "PYTEST_XDIST_WORKER" not in os.environ:  # the controlling process (or the only one)
            _bound(Path(path))
    _cache.enable_compilation_cache(path)


def _bound(directory: Path) -> None:
    # JAX's own bound (`jax_compilation_cache_max_size`) rescans the directory at every
    # write; emptying it when it outgrows the bound costs one scan per run. Only JAX's
    # entries (`<program>-<key>-cache`) are removed.
    files = list(directory.glob("*-cache")) if directory.is_dir() else []
    if sum(f.stat().st_size for f in files) > LASTING_CACHE_BYTES:
        for f in files:
            f.unlink(missing_ok=True)


def pytest_addoption(parser):
    parser.addoption(
        "--slow",
        action="store_true",
        default=os.environ.get("LOCOMOTION_JAX_SLOW_TESTS") == "1",
        help="also run the tests marked slow (end-to-end optimisations, notebooks, several processes)",
    )


def pytest_configure(config):
    # tests/test_fuzz.py draws this many times more examples under --slow (read at its import).
    if config.getoption("--slow"):
        os.environ.setdefault("LJ_FUZZ_SCALE", "20")


def pytest_collection_modifyitems(config, items):
    # The slow tests run whole optimisations, notebooks and multi-process sweeps whose parts
    # the default tests check one by one; they take about as long again as the rest.
    if config.getoption("--slow"):
        return
    skip = pytest.mark.skip(reason="slow: run with --slow")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)


def pytest_collection_finish(session):
    # pytest-xdist's loadgroup keeps a group on one worker by a suffix on the node id; a
    # pytest that does not read that suffix splits the groups without a word.
    if getattr(session.config.option, "loadgroup", False):
        split = [it.nodeid for it in session.items if it.get_closest_marker("xdist_group") and "@" not in it.nodeid]
        if split:
            warnings.warn(
                f"xdist_group is not honoured by pytest {pytest.__version__} with this pytest-xdist: "
                f"{len(split)} grouped tests may run on different workers (module fixtures built twice).",
                pytest.PytestConfigWarning,
            )


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_programs():
    # A worker runs dozens of modules; without this it keeps every program it compiled (up
    # to ~9 GB per worker). A program needed again is read back from the shared cache.
    yield
    jax.clear_caches()


def pytest_unconfigure(config):
    for path in _OWN_CACHE:
        shutil.rmtree(path, ignore_errors=True)


_shared_compilation_cache()

import sys


# `reference.py` (the independent scipy solver) is imported by several tests.
sys.path.insert(0, str(Path(__file__).parent))


@pytest.fixture(autouse=True)
def isolate_xla_flags(monkeypatch):
    """Every test (the CLI's above all, `cli_helpers`): the CLI sets XLA_FLAGS (--cpu-devices) for its
    own process. Start JAX's backend first, so that this test process keeps its devices, and undo
    the variable after, so that no test sees another's (nor do the compilation cache's keys)."""
    jax.devices()
    monkeypatch.setenv("XLA_FLAGS", os.environ.get("XLA_FLAGS", ""))
