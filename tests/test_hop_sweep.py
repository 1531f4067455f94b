"""`lj.sweep` of the paper's model under `contact="hop"` (SPEC §10, issue 27): the sharded, chunked
path of `Params` (NetCDF and Zarr, resumable, cost order, `on_invalid="flag"`) with the hopping
variables (`flight_fraction1/2`, `highest_hop1/2`, `landings_per_period`, `zeno`), equal bit for bit
to `lj.measure(Params(...), contact="hop")` of the same configurations; the CLI writes them.

Kept small: a (3, 2) grid through the lift-off band at `Exact(dt=0.02)`, chunks of 4 (padded to 8
lanes) everywhere, so that the chunks of every test share one compilation."""

from typing import Any

import locomotion_jax as lj
import numpy as np
import pytest
import xarray as xr
from cli_helpers import invoke
from locomotion_jax.maps import _dataset, _sharding, _store, _sweep


pytestmark = pytest.mark.usefixtures("isolate_xla_flags")

FAST: dict[str, Any] = dict(z=1.0, horizon=30.0, window=10.0, dynamics=lj.Exact(dt=0.02), progress=False)
AXES = {"omega": [2.0, 9.0, 12.0], "a": [0.05, 0.08]}  # no lift-off at omega = 2; hops at 9 and 12
FIXED = {"d": 0.25}
HOP_VARS = ("flight_fraction1", "flight_fraction2", "highest_hop1", "highest_hop2", "landings_per_period", "zeno")


def _as_dataset_fields(m: lj.Measurement) -> dict[str, np.ndarray]:
    """A `Measurement`'s fields named as a sweep's variables (per-mass hopping fields one per mass)."""
    out = m.to_numpy()
    for name in ("flight_fraction", "highest_hop"):
        both = out.pop(name)
        out |= {f"{name}1": both[..., 0], f"{name}2": both[..., 1]}
    return out


def _assert_bitwise(ds: xr.Dataset, want: dict[str, np.ndarray]) -> None:
    assert set(ds.data_vars) == set(_sweep.MEASURE_FIELDS) | set(HOP_VARS)
    for name in map(str, ds.data_vars):
        got = np.asarray(ds[name].values)
        assert got.dtype == want[name].dtype, name
        assert np.array_equal(got, want[name], equal_nan=True), name


@pytest.fixture(scope="module")
def measured() -> dict[str, np.ndarray]:
    """`lj.measure` of the grid's configurations under "hop", as the sweep's variables."""
    W, A = np.meshgrid(AXES["omega"], AXES["a"], indexing="ij")
    kw = {k: v for k, v in FAST.items() if k != "progress"}
    m = lj.measure(lj.Params(omega=W, a=A, **FIXED), contact="hop", **kw)  # type: ignore[arg-type]
    return _as_dataset_fields(m)


@pytest.fixture(scope="module")
def memory(measured) -> xr.Dataset:
    return lj.sweep(AXES, fixed=FIXED, contact="hop", chunk_size=4, order="natural", **FAST)


def test_hop_sweep_equals_measure_bit_for_bit(memory, measured):
    """Every variable of the in-memory sweep (two chunks, the second padded) equals `lj.measure` of
    the same configurations bit for bit; the hopping variables are there, with the grid's dimensions,
    and the grid covers both a run that never lifts off and runs that fly on past t_start."""
    ds = memory
    _assert_bitwise(ds, measured)
    for name in HOP_VARS:
        assert ds[name].dims == ("omega", "a") and "contact='hop'" in ds[name].attrs["description"]
    assert ds.attrs["contact"] == "hop" and np.all(ds.status.values == lj.Status.OK)
    for name in map(str, ds.data_vars):  # every run is OK: no NaN anywhere
        assert not np.any(np.isnan(ds[name].values.astype(float))), name
    ff1, ff2 = ds.flight_fraction1.values, ds.flight_fraction2.values
    print("flight fractions", ff1.round(4).tolist(), ff2.round(4).tolist(), "tau_z", ds.tau_z.values.round(3).tolist())
    assert np.all(ff1[0] == 0) and np.all(ff2[0] == 0) and np.all(ds.highest_hop2.values[0] == 0)  # omega = 2
    assert np.all(np.maximum(ff1, ff2)[1:, 1] > 0.05) and np.all(ds.landings_per_period.values[1:, 1] > 0)
    assert not ds.zeno.values.any() and np.all(ds.liftoff.values[1:, 1])
    # The coarse step's energy balance (measured: at most 1.5e-4 e_d at dt = 0.02, fourth order in dt).
    assert np.all(np.abs(ds.balance.values) <= 1e-3 * ds.e_d.values)


def test_hop_sweep_resumes_netcdf_and_cost_order_is_identical(tmp_path, monkeypatch, memory):
    """Interrupted after its first chunk and run again, a NetCDF hop sweep computes only the missing
    chunk and equals the in-memory sweep; `order="cost"` (its pilot runs "hop" too) gives the same
    dataset bit for bit; a finished file is read back without computing; all chunks one trace."""
    path = tmp_path / "hop.nc"
    traces = _sharding.TRACES["run_chunk"]
    real_save, calls = _store.ChunkStore.save, []

    def interrupted_save(self, index, arrays):
        calls.append(index)
        if len(calls) == 2:
            raise KeyboardInterrupt("simulated interruption after the first chunk")
        real_save(self, index, arrays)

    monkeypatch.setattr(_store.ChunkStore, "save", interrupted_save)
    with pytest.raises(KeyboardInterrupt):
        lj.sweep(AXES, fixed=FIXED, contact="hop", chunk_size=4, order="natural", path=path, **FAST)
    monkeypatch.setattr(_store.ChunkStore, "save", real_save)
    assert not path.exists()
    before = dict(_sweep.STATS)
    resumed = lj.sweep(AXES, fixed=FIXED, contact="hop", chunk_size=4, order="natural", path=path, **FAST)
    assert _sweep.STATS["chunks_computed"] - before.get("chunks_computed", 0) == 1
    assert _sweep.STATS["chunks_loaded"] - before.get("chunks_loaded", 0) == 1
    xr.testing.assert_identical(resumed, memory)
    read = xr.load_dataset(path, engine="h5netcdf")
    for name in HOP_VARS:
        assert np.array_equal(read[name].values, memory[name].values), name
    before = dict(_sweep.STATS)
    lj.sweep(AXES, fixed=FIXED, contact="hop", chunk_size=4, order="natural", path=path, **FAST)
    assert dict(_sweep.STATS) == before

    cost = lj.sweep(AXES, fixed=FIXED, contact="hop", chunk_size=4, order="cost", **FAST)
    assert cost.attrs.pop("order") == "cost"
    natural = memory.copy()
    natural.attrs.pop("order")
    xr.testing.assert_identical(cost, natural)
    assert _sharding.TRACES["run_chunk"] - traces == 0  # the chunk shape `memory` compiled: no new trace


def test_hop_sweep_zarr_equals_memory_and_reads_back(tmp_path, memory):
    """The same sweep into a Zarr store (blocks of 2 x 2): every variable, hopping ones included,
    equals the in-memory sweep bit for bit; a rerun finds every chunk done."""
    path = tmp_path / "hop.zarr"
    ds = lj.sweep(AXES, fixed=FIXED, contact="hop", chunk_size=4, path=path, **FAST)
    assert set(ds.data_vars) == set(memory.data_vars)
    for name in memory.data_vars:
        assert np.array_equal(ds[name].values, memory[name].values, equal_nan=True), name
    before = dict(_sweep.STATS)
    again = lj.sweep(AXES, fixed=FIXED, contact="hop", chunk_size=4, path=path, **FAST)
    assert _sweep.STATS["chunks_computed"] == before.get("chunks_computed", 0)
    assert np.array_equal(again.flight_fraction2.values, memory.flight_fraction2.values)


def test_hop_sweep_flags_an_invalid_configuration_only(memory):
    """`on_invalid="flag"`: a list with mu_s < mu_k in one configuration flags it `INVALID` (its
    measurements NaN, never with status OK), and the others equal their grid entries bit for bit."""
    axes = {"omega": [9.0, 12.0, 9.0], "a": [0.08, 0.05, 0.08], "mu_s": [0.7, 0.7, 0.4]}
    ds = lj.sweep(axes, mode="list", fixed=FIXED, contact="hop", chunk_size=4, on_invalid="flag", **FAST)
    assert ds.status.values.tolist() == [lj.Status.OK, lj.Status.OK, lj.Status.INVALID]
    assert np.isnan(ds.flight_fraction1.values[2]) and np.isnan(ds.e_d.values[2]) and not ds.reached.values[2]
    for name in memory.data_vars:
        got, want = ds[name].values[:2], np.asarray([memory[name].values[1, 1], memory[name].values[2, 0]])
        assert np.array_equal(got, want, equal_nan=True), name
        if np.issubdtype(got.dtype, np.floating):
            assert not np.isnan(got).any(), name
    with pytest.raises(ValueError, match=r"mu_s\[2\]=0.4"):
        lj.sweep(axes, mode="list", fixed=FIXED, contact="hop", chunk_size=4, **FAST)


def test_hop_sweep_refusals_and_strict_dataset_unchanged():
    """Smoothed dynamics refuse "hop" before computing (naming the dynamics that run it); a strict
    sweep's dataset has exactly `MEASURE_FIELDS`, no hopping variable."""
    before, traces = dict(_sweep.STATS), dict(_sharding.TRACES)
    with pytest.raises(NotImplementedError, match="contact='hop' runs with Exact dynamics only"):
        lj.sweep(AXES, contact="hop", dynamics=lj.Smoothed(), progress=False)
    assert dict(_sweep.STATS) == before and dict(_sharding.TRACES) == traces
    assert _dataset.dataset_fields("strict") == _dataset.dataset_fields("paper") == _sweep.MEASURE_FIELDS
    assert not set(HOP_VARS) & set(_sweep.MEASURE_FIELDS)
    strict = lj.sweep({"omega": [2.0, 9.0]}, mode="list", fixed={"a": 0.05, **FIXED}, chunk_size=4, **FAST)
    assert set(strict.data_vars) == set(_sweep.MEASURE_FIELDS)


def test_cli_sweep_contact_hop_writes_the_hopping_variables(tmp_path, memory):
    """`locomotion-jax sweep --contact hop --omega ... --a ...` passes the contact reading to `lj.sweep`
    and writes the hopping variables, equal to the library's sweep of the same grid."""
    out = tmp_path / "hop.nc"
    res = invoke(
        "sweep", "--contact", "hop", "--omega", "2,9,12", "--a", "0.05,0.08", "--d", "0.25", "--z", "1",
        "--horizon", "30", "--window", "10", "--dt", "0.02", "--chunk-size", "4", "--order", "natural",
        "--out", str(out), "--no-progress",
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "omega[3] x a[2]" in res.stdout and "status: OK 6" in res.stdout
    ds = xr.load_dataset(out, engine="h5netcdf")
    assert ds.attrs["contact"] == "hop"
    for name in memory.data_vars:
        assert np.array_equal(ds[name].values, memory[name].values, equal_nan=True), name


def test_hop_sweep_float32_equals_measure():
    """`dtype=float32`: the hopping variables come out in float32 and equal `lj.measure(...,
    dtype=float32)` of the same configurations bit for bit (a list of two that fly)."""
    axes = {"omega": [9.0, 12.0], "a": [0.08, 0.08]}
    ds = lj.sweep(axes, mode="list", fixed=FIXED, contact="hop", chunk_size=4, dtype=np.float32, **FAST)
    kw = {k: v for k, v in FAST.items() if k != "progress"}
    p = lj.Params(omega=np.asarray(axes["omega"]), a=np.asarray(axes["a"]), d=0.25)
    m = lj.measure(p, contact="hop", dtype=np.float32, **kw)  # type: ignore[arg-type]
    want = _as_dataset_fields(m)
    assert ds.flight_fraction1.dtype == np.float32 and ds.highest_hop2.dtype == np.float32
    assert np.all(ds.status.values == lj.Status.OK) and np.all(ds.flight_fraction2.values > 0.05)
    for name in map(str, ds.data_vars):
        assert np.array_equal(ds[name].values, want[name], equal_nan=True), name
