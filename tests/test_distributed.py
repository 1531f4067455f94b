"""Multi-process sweeps: processes under `jax.distributed` (127.0.0.1, one CPU device
each) share out the chunks of one Zarr store; the result equals a one-process sweep
bit for bit, a sweep whose processes were killed is resumed by another process, and a
survivor of a killed process finishes the store and exits 0.

The processes run the CLI or `tests/distributed_sweep.py`; they share a compilation
cache (so that fewer of them compile), and the coordinator listens on a port free at
run time.
"""

import json
import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import locomotion_jax as lj
import numpy as np
import pytest
import xarray as xr
from distributed_sweep import AXES, CHAIN_AXES, CHAIN_SETTINGS, SETTINGS, worm


HELPER = Path(__file__).with_name("distributed_sweep.py")
N_CHUNKS = 8  # 8 x 4 configurations in chunks of 4 (rows of the grid)
TIMEOUT = 240


@pytest.fixture(scope="module")
def reference():
    """The same sweep in this process (in memory, NetCDF-style chunks, whatever its devices)."""
    return lj.sweep(AXES, **SETTINGS)


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    # The run's compilation cache (tests/conftest.py), where there is one; else one for this
    # module (under pytest-xdist the workers' temporary directories share a parent: so does it).
    shared = os.environ.get("LJ_TEST_CACHE_DIR")
    if shared and shared != "off":
        return Path(shared)
    root = tmp_path_factory.getbasetemp()
    path = (root.parent if os.environ.get("PYTEST_XDIST_WORKER") else root) / "jax_cache_distributed"
    path.mkdir(exist_ok=True)
    return path


def _free_port(low: int = 0, high: int = 0) -> int:
    """A port nobody listens on now: any (the default), or one in `[low, high]`."""
    for port in [0] if not low else np.random.default_rng().permutation(np.arange(low, high + 1))[:200]:
        with socket.socket() as s:
            try:
                s.bind(("127.0.0.1", int(port)))
            except OSError:
                continue
            return s.getsockname()[1]
    raise RuntimeError(f"no free port in [{low}, {high}]")


def _start(
    store: Path, cache: Path, n: int = 1, die_after: dict[int, int] | None = None, chain: bool = False
) -> list[subprocess.Popen]:
    env = dict(os.environ, DISTRIBUTED_SWEEP_CACHE=str(cache))
    env["PYTHONPATH"] = os.pathsep.join([str(HELPER.parents[1]), env.get("PYTHONPATH", "")])
    port = _free_port()
    procs = []
    for p in range(n):
        cmd = [sys.executable, str(HELPER), str(store), "--process-id", str(p), "--processes", str(n)]
        cmd += ["--port", str(port)]
        if die_after and p in die_after:
            cmd += ["--die-after", str(die_after[p])]
        if chain:
            cmd += ["--chain"]
        procs.append(subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env))
    return procs


def _wait(procs: list[subprocess.Popen]) -> list[tuple[int, str, str]]:
    try:
        outputs = [p.communicate(timeout=TIMEOUT) for p in procs]
        return [(p.returncode, *o) for p, o in zip(procs, outputs)]
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()


def _report(stdout: str) -> dict:
    return json.loads(stdout.strip().splitlines()[-1])


def _assert_same(store: Path, reference: xr.Dataset) -> None:
    ds = xr.open_zarr(store, consolidated=True)  # as a user opens it
    assert set(ds.data_vars) == set(reference.data_vars)
    for name in reference.variables:
        assert ds[name].dims == reference[name].dims, name
        assert ds[name].dtype == reference[name].dtype, name
        np.testing.assert_array_equal(ds[name].values, reference[name].values, err_msg=name)


def test_two_processes_equal_one(tmp_path, cache, reference):
    """The README's Slurm launch, `srun locomotion-jax --distributed sweep ...`, with the
    variables srun sets for two tasks on one node (jax.distributed reads them)."""
    store = tmp_path / "map.zarr"
    args = ["--distributed", "--cpu-devices", "1", "sweep", "--omega", "1:24:8", "--a", "0.02:0.1:4"]
    args += ["--horizon", "30", "--window", "25", "--chunk-size", "4", "--out", str(store), "--no-progress"]
    # jax.distributed's coordinator port under Slurm: 61440 + SLURM_JOB_ID % 4096.
    job = _free_port(61440, 65535) - 61440
    slurm = dict(SLURM_JOB_ID=str(job), SLURM_STEP_NODELIST="localhost", SLURM_NTASKS="2")
    procs = []
    for p in range(2):
        env = dict(os.environ, **slurm, SLURM_PROCID=str(p), SLURM_LOCALID=str(p), LOCOMOTION_JAX_CACHE_DIR=str(cache))
        env["LOCOMOTION_JAX_CACHE"] = "1"
        env["PYTHONPATH"] = os.pathsep.join([str(HELPER.parents[1]), env.get("PYTHONPATH", "")])
        cmd = [sys.executable, "-m", "locomotion_jax.cli._main", *args]
        procs.append(subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env))
    results = _wait(procs)
    for rc, out, err in results:
        assert rc == 0, err[-3000:]
        assert f"wrote {store}: omega[8] x a[4]" in out
    # Every chunk was taken once (a claim records its holder), by both processes:
    # process 1 starts with chunk 1, and a chunk free later goes to whichever is free.
    holders = [f.read_text().split()[2] for f in sorted((store / ".locomotion_jax" / "claims").iterdir())]
    assert len(holders) == N_CHUNKS and {str(p.pid) for p in procs} == set(holders), holders
    assert len(list((store / ".locomotion_jax" / "done").iterdir())) == N_CHUNKS
    _assert_same(store, reference)


def test_killed_processes_resume(tmp_path, cache, reference):
    store = tmp_path / "map.zarr"
    # Process 0 dies writing its third chunk, process 1 writing its second: each
    # leaves half a chunk written, its lock file, and no completion mark. (When
    # one dies, jax.distributed may abort the other first.)
    results = _wait(_start(store, cache, n=2, die_after={0: 2, 1: 1}))
    assert all(rc != 0 for rc, _, _ in results)
    assert -signal.SIGKILL in [rc for rc, _, _ in results]
    meta = store / ".locomotion_jax"
    done = {p.name for p in (meta / "done").iterdir()}
    stale = {p.name.removesuffix(".lock") for p in (meta / "claims").iterdir()} - done
    assert 1 <= len(done) < N_CHUNKS and stale, (done, stale)
    # A new process, outside the killed run, finishes exactly what is left.
    [(rc, out, err)] = _wait(_start(store, cache, n=1))
    assert rc == 0, err[-3000:]
    report = _report(out)
    assert report["chunks_loaded"] == len(done)
    assert report["chunks_computed"] == N_CHUNKS - len(done)
    _assert_same(store, reference)


def test_survivor_takes_over_and_exits_cleanly(tmp_path, cache, reference):
    """Process 1 dies writing its first chunk (chunk 1); process 0 takes it over, completes the
    store and exits 0, saying which chunk it took over (JAX used to abort it at its shutdown
    barrier, exit 134, after the store was complete)."""
    store = tmp_path / "map.zarr"
    (rc0, out0, err0), (rc1, _, _) = _wait(_start(store, cache, n=2, die_after={1: 0}))
    assert rc1 == -signal.SIGKILL
    assert rc0 == 0, err0[-3000:]
    assert "process 0 of 2: the store is complete. Chunks taken over from processes that stopped: 1 (held by" in err0
    assert _report(out0)["chunks_computed"] == N_CHUNKS
    assert len(list((store / ".locomotion_jax" / "done").iterdir())) == N_CHUNKS
    _assert_same(store, reference)


def test_two_processes_fill_a_chains_store_as_one_process_maps_it(tmp_path, cache):
    """Issue 25's every feature on every mechanism: a map of a 3-mass chain on anisotropic bristles
    (`sweep(axes, mechanism=worm, path="....zarr")`) filled by two processes under
    `jax.distributed` equals the same map in one process, in memory, bit for bit, each chunk
    computed once, by either process."""
    reference = lj.sweep(CHAIN_AXES, mechanism=worm, **CHAIN_SETTINGS)
    store = tmp_path / "worm.zarr"
    results = _wait(_start(store, cache, n=2, chain=True))
    for rc, _, err in results:
        assert rc == 0, err[-3000:]
    reports = [_report(out) for _, out, _ in results]
    assert sum(r["chunks_computed"] for r in reports) == 4 and all(r["processes"] == 2 for r in reports)
    assert len(list((store / ".locomotion_jax" / "done").iterdir())) == 4
    _assert_same(store, reference)
