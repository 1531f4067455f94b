"""The Zarr store of a sweep, in one process: same values as in memory, resumable,
refuses another sweep, locks that die with their process, chunks as grid blocks.

(Several processes: tests/test_distributed.py.) Same small settings as
tests/test_sweep.py, so that the compilations are shared.
"""

import os
from typing import Any

import locomotion_jax as lj
import numpy as np
import pytest
import xarray as xr
from distributed_sweep import CHAIN_AXES, CHAIN_SETTINGS, worm
from locomotion_jax.maps import _sweep, _zarr_store
from locomotion_jax.maps._zarr_store import block_shape, Blocks, NOT_COMPUTED, ZarrStore
from typer.testing import CliRunner


FAST: dict[str, Any] = dict(z=0.3, horizon=30.0, window=5.0, dynamics=lj.Exact(dt=0.02), progress=False)
AXES = {"omega": [2.0, 6.0, 9.5, 16.0, 23.0], "a": [0.02, 0.05]}  # 10 configurations


@pytest.fixture(scope="module")
def memory():
    return lj.sweep(AXES, chunk_size=4, **FAST)


def assert_identical_values(ds: xr.Dataset, ref: xr.Dataset) -> None:
    assert set(ds.data_vars) == set(ref.data_vars)
    for name in ref.variables:
        assert ds[name].dims == ref[name].dims and ds[name].dtype == ref[name].dtype, name
        np.testing.assert_array_equal(ds[name].values, ref[name].values, err_msg=name)


def test_store_equals_memory_and_resumes(tmp_path, memory):
    path = tmp_path / "map.zarr"
    before = _sweep.STATS.copy()
    ds = lj.sweep(AXES, chunk_size=4, path=path, **FAST)
    # Chunks are blocks of (2, 2): 3 of them, the last one a single row.
    assert _sweep.STATS["chunks_computed"] - before["chunks_computed"] == 3
    assert ds.attrs["sweep_block"] == [2, 2]
    assert_identical_values(ds, memory)  # other chunks than in memory, same bits
    assert ds.attrs["sweep_spec"] == memory.attrs["sweep_spec"]
    opened = xr.open_zarr(path)  # lazily, with consolidated metadata
    assert opened.tau_z.encoding["chunks"] == (2, 2)
    assert_identical_values(opened, memory)

    # Chunk 1 interrupted mid-write: its region half overwritten, not marked done.
    store = ZarrStore.open(path, json_spec(memory))
    store.group["tau_z"][2:4, :] = np.nan
    store.group["status"][2:4, :] = NOT_COMPUTED
    (path / _zarr_store.META / "done" / "chunk_000001").unlink()
    partial = xr.open_zarr(path)
    assert np.isnan(partial.tau_z.values[2:4]).all() and (partial.status.values[2:4] == NOT_COMPUTED).all()
    before = _sweep.STATS.copy()
    resumed = lj.sweep(AXES, chunk_size=4, path=path, **FAST)
    assert _sweep.STATS["chunks_computed"] - before["chunks_computed"] == 1
    assert _sweep.STATS["chunks_loaded"] - before["chunks_loaded"] == 2
    assert_identical_values(resumed, memory)
    # Finished: opened, nothing computed (a resumed store keeps its chunking).
    before = _sweep.STATS.copy()
    lj.sweep(AXES, chunk_size=2, path=path, **FAST)
    assert _sweep.STATS["chunks_computed"] == before["chunks_computed"]


def json_spec(ds: xr.Dataset) -> dict:
    import json

    return json.loads(ds.attrs["sweep_spec"])


def test_store_refuses_another_sweep(tmp_path, memory):
    path = tmp_path / "map.zarr"
    lj.sweep(AXES, chunk_size=4, path=path, **FAST)
    other = {"omega": [2.0, 6.0, 9.5, 16.0, 23.0], "a": [0.02, 0.06]}
    refused = r"different specification:\n  axes\.a\.last: stored 0\.05, requested 0\.06\n(?s:.*)overwrite=True"
    with pytest.raises(ValueError, match=refused):
        lj.sweep(other, chunk_size=4, path=path, **FAST)
    with pytest.raises(ValueError, match=r"different specification:\n  z: stored 0\.3, requested 0\.4"):
        lj.sweep(AXES, chunk_size=4, path=path, **dict(FAST, z=0.4))
    with pytest.raises(ValueError, match="order='cost' is for NetCDF output"):
        lj.sweep(AXES, path=path, order="cost", **FAST)
    # Something else at the path is never written into.
    (tmp_path / "notes.zarr").mkdir()
    (tmp_path / "notes.zarr" / "mine.txt").write_text("keep")
    with pytest.raises(ValueError, match="is not a locomotion_jax sweep store"):
        lj.sweep(AXES, path=tmp_path / "notes.zarr", **FAST)
    assert (tmp_path / "notes.zarr" / "mine.txt").read_text() == "keep"
    # overwrite=True replaces the store.
    ds = lj.sweep(other, chunk_size=4, path=path, overwrite=True, **FAST)
    np.testing.assert_array_equal(ds.a, other["a"])


def test_claims_die_with_their_holder(tmp_path, memory):
    path = tmp_path / "map.zarr"
    lj.sweep(AXES, chunk_size=4, path=path, **FAST)
    store = ZarrStore.open(path, json_spec(memory))
    held = store.claim(0)
    assert held is not None
    if _zarr_store.fcntl is not None:
        assert store.claim(0) is None  # held (flock: another open file, same process or not)
    held.release()
    again = store.claim(0)
    assert again is not None
    again.release()
    # A lock file left by a process that is gone (its flock went with it) blocks nothing.
    stale = path / _zarr_store.META / "claims" / "chunk_000002.lock"
    stale.write_text("node17 pid 4242 since 2026-01-01T00:00:00\n")
    claim = store.claim(2)
    assert claim is not None
    claim.release()


@pytest.mark.parametrize(
    "shape, chunk, block",
    [
        ((2048, 2048), 4096, (2, 2048)),
        ((256, 256), 4096, (16, 256)),
        ((10, 3000), 4096, (1, 3000)),
        ((5000,), 4096, (4096,)),
        ((4, 3, 5), 7, (1, 1, 5)),
        ((4, 3, 5), 1, (1, 1, 1)),
        ((4, 3, 5), 100, (4, 3, 5)),
    ],
)
def test_blocks_tile_the_grid(shape, chunk, block):
    assert block_shape(shape, chunk) == block
    blocks = Blocks(shape, block)
    if np.prod(shape) <= 100:
        configs = np.concatenate([blocks.configs(i) for i in range(blocks.n_chunks)])
        np.testing.assert_array_equal(np.sort(configs), np.arange(np.prod(shape)))  # every configuration once
        for i in range(blocks.n_chunks):  # a block's configurations are its region, in C order
            grid = np.arange(np.prod(shape)).reshape(shape)
            np.testing.assert_array_equal(blocks.configs(i), grid[blocks.region(i)].ravel())


def test_store_list_mode_with_ratio(tmp_path):
    axes = {"omega_over_wn1": [0.2, 1.0, 2.3], "a": [0.02, 0.05, 0.08]}
    kw: dict[str, Any] = dict(mode="list", chunk_size=2, **FAST)
    ds = lj.sweep(axes, path=tmp_path / "list.zarr", **kw)
    assert_identical_values(xr.open_zarr(tmp_path / "list.zarr"), lj.sweep(axes, **kw))
    assert set(ds.coords) == {"omega_over_wn1", "a"} and ds.tau_z.dims == ("config",)
    assert "omega" in ds.data_vars


def test_cli_writes_a_store(tmp_path, monkeypatch):
    from locomotion_jax.cli import _main as _cli

    monkeypatch.chdir(tmp_path)
    args = ["sweep", "--omega", "2,6,9.5,16,23", "--a", "0.02,0.05", "--z", "0.3", "--horizon", "30"]
    args += ["--window", "5", "--dt", "0.02", "--chunk-size", "4", "--out", "maps/m.zarr", "--no-progress"]
    result = CliRunner().invoke(_cli.app, args)
    assert result.exit_code == 0, result.output
    assert "wrote maps/m.zarr: omega[5] x a[2]" in result.output
    assert (tmp_path / "maps" / "m.zarr" / "zarr.json").is_file()
    assert len(os.listdir(tmp_path / "maps" / "m.zarr" / _zarr_store.META / "done")) == 3


def test_a_chain_map_into_a_store_equals_memory_resumes_and_refuses_another_builder(tmp_path):
    """`sweep(axes, mechanism=build, path="....zarr")`: the same bits as in memory (every variable,
    `stick_fraction` with its `mass` dimension), chunk by chunk; an interrupted chunk is computed
    again and the others read; a store made by another builder (the same axes, other mechanisms:
    its digest differs) or with other settings is refused, naming what differs."""
    memory = lj.sweep(CHAIN_AXES, mechanism=worm, **CHAIN_SETTINGS)
    path = tmp_path / "worm.zarr"
    before = _sweep.STATS.copy()
    ds = lj.sweep(CHAIN_AXES, mechanism=worm, path=path, **CHAIN_SETTINGS)
    assert _sweep.STATS["chunks_computed"] - before["chunks_computed"] == 4  # blocks of (1, 2)
    assert ds.stick_fraction.dims == ("omega", "a", "mass") and ds.attrs["kind"] == "chain"
    assert_identical_values(ds, memory)
    (path / _zarr_store.META / "done" / "chunk_000001").unlink()
    before = _sweep.STATS.copy()
    resumed = lj.sweep(CHAIN_AXES, mechanism=worm, path=path, **CHAIN_SETTINGS)
    assert _sweep.STATS["chunks_computed"] - before["chunks_computed"] == 1
    assert _sweep.STATS["chunks_loaded"] - before["chunks_loaded"] == 3
    assert_identical_values(resumed, memory)
    with pytest.raises(ValueError, match=r"different specification:\n  mechanism\.sha256: stored "):
        lj.sweep(CHAIN_AXES, mechanism=lambda omega, a: worm(omega, 1.01 * np.asarray(a)), path=path, **CHAIN_SETTINGS)
    with pytest.raises(ValueError, match=r"different specification:\n  horizon: stored 20\.0, requested 25\.0"):
        lj.sweep(CHAIN_AXES, mechanism=worm, path=path, **dict(CHAIN_SETTINGS, horizon=25.0))
    with pytest.raises(ValueError, match=r"must be a NetCDF file \(\.nc\)(?s:.*)or a Zarr store \(\.zarr\)"):
        lj.sweep(CHAIN_AXES, mechanism=worm, path=tmp_path, **CHAIN_SETTINGS)  # an existing path that is not a store
