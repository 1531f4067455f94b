"""The warm start: a second process reads the compiled engine from the persistent cache.

The CLI runs in subprocesses (turning the cache on is a global JAX setting, and the
test process has the tests' own cache on, `tests/conftest.py`), with the cache in a
temporary directory.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from locomotion_jax import _cache


def _cli(args: list[str], cache: Path, tmp_path: Path, switch: str = "1") -> subprocess.CompletedProcess:
    """`locomotion-jax --cpu-devices 1 ARGS` in a new process, with the cache in `cache`."""
    env = dict(os.environ)
    env.pop("XLA_FLAGS", None)
    env[_cache.ENV_DIR] = str(cache)
    env[_cache.ENV_SWITCH] = switch  # tests/conftest.py sets "0" for the in-process CLI tests
    env["PYTHONPATH"] = os.pathsep.join([str(Path(__file__).parents[1]), env.get("PYTHONPATH", "")])
    cmd = [sys.executable, "-m", "locomotion_jax.cli._main", "--cpu-devices", "1", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=300, cwd=tmp_path, env=env)


def _entries(cache: Path) -> set[str]:
    return {p.name for p in cache.iterdir()}


def test_second_process_reads_the_cache(tmp_path):
    cache = tmp_path / "cache"
    args = ["measure", "--omega", "2", "--horizon", "30", "--json"]
    first = _cli(args, cache, tmp_path)
    assert first.returncode == 0, first.stderr
    written = _entries(cache)
    # The engine's measurement of the paper's model (`dynamics/_paper.measure_batch`, compiled
    # with `_compile.COMPILER_OPTIONS`) is cached, and so are the small computations around it
    # (min compile time 0).
    assert any(name.startswith("jit_measure_batch-") for name in written), sorted(written)
    assert len(written) > 5, sorted(written)
    second = _cli(args, cache, tmp_path)
    assert second.returncode == 0, second.stderr
    # Every compilation of the second process was a cache hit: nothing new written.
    assert _entries(cache) == written
    assert json.loads(second.stdout) == json.loads(first.stdout)


def test_no_cache_writes_nothing(tmp_path):
    # An invalid argument ends the command before any computation; the cache
    # directory is created at start-up only when the cache is on.
    bad = ["simulate", "--a", "-1", "--no-plot"]
    on, flag, variable = tmp_path / "on", tmp_path / "flag", tmp_path / "variable"
    assert _cli(bad, on, tmp_path).returncode == 2
    assert on.is_dir()
    assert _cli(["--no-cache", *bad], flag, tmp_path).returncode == 2
    assert not flag.exists()
    assert _cli(bad, variable, tmp_path, switch="0").returncode == 2
    assert not variable.exists()


def test_cache_dir(monkeypatch, tmp_path):
    monkeypatch.delenv(_cache.ENV_DIR, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    if sys.platform.startswith("linux"):
        assert _cache.cache_dir() == tmp_path / "xdg" / "locomotion_jax" / "jax"
    monkeypatch.setenv(_cache.ENV_DIR, str(tmp_path / "mine"))
    assert _cache.cache_dir() == tmp_path / "mine"


def test_unwritable_cache_dir_is_a_clear_error(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(ValueError, match="Cannot create the compilation cache directory"):
        _cache.enable_compilation_cache(blocker / "cache")


def test_lasting_test_cache_is_emptied_past_its_bound(tmp_path, monkeypatch):
    # tests/conftest.py's bound on the tests' lasting cache: JAX's entries go, all at once,
    # only once they exceed it; other files stay.
    import conftest

    monkeypatch.setattr(conftest, "LASTING_CACHE_BYTES", 300)
    for i in range(3):
        (tmp_path / f"jit_f-{i}-cache").write_bytes(b"x" * 100)
    (tmp_path / "notes.txt").write_text("not JAX's")
    conftest._bound(tmp_path)
    assert len(list(tmp_path.glob("*-cache"))) == 3
    (tmp_path / "jit_g-3-cache").write_bytes(b"x")
    conftest._bound(tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]
    conftest._bound(tmp_path / "missing")  # nothing there yet: nothing to do
