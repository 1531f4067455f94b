"""The sweep engine: equality with `measure`, chunking, persistence, sharding, bad input; and
`lj.sweep(axes, mechanism=build)`, which maps a `Mechanism` (SPEC §9) as it maps a chain: the map
equals `lj.measure` on the same batch, whatever the chunking, and its attributes name the bodies'
laws and links.

Kept fast: short horizons, tiny grids, `Exact(dt=0.02)`, and chunk shapes shared
between tests so that few compilations are needed.
"""

import importlib
import json
import math
import os
import subprocess
import sys
import textwrap
from types import SimpleNamespace
from typing import Any

import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
import xarray as xr
from locomotion_jax.maps import _schedule, _sharding, _store, _sweep
from mechanism_cases import capsule


FAST: dict[str, Any] = dict(z=0.3, horizon=30.0, window=5.0, dynamics=lj.Exact(dt=0.02), progress=False)
AXES = {"omega": [2.0, 6.0, 9.5, 16.0, 23.0], "a": [0.02, 0.05]}  # 10 configurations
EXACT_FIELDS = ("reached", "regime", "status", "liftoff")
# Iteration counts: measure() itself gives 5993 vs 6009 steps for one configuration in a
# batch of 1 vs 2 (round-off decides some trial steps); the physics agrees to 1e-14.
COUNT_FIELDS = ("n_steps", "n_switch")


def assert_same(actual, expected, rtol=1e-7):
    """Dataset variables (or arrays by name) equal up to round-off.

    The batch width changes XLA's vectorisation and so the round-off; located event
    times then move by ~1e-9 (relative), which is what `rtol` allows for.
    """
    for name in _sweep.MEASURE_FIELDS:
        a, b = np.asarray(actual[name]), np.asarray(expected[name])
        if name in EXACT_FIELDS:
            np.testing.assert_array_equal(a, b, err_msg=name)
        elif name in COUNT_FIELDS:
            np.testing.assert_allclose(a, b, rtol=0.01, atol=2, err_msg=name)
        else:
            np.testing.assert_allclose(a, b, rtol=rtol, atol=1e-12, equal_nan=True, err_msg=name)


@pytest.fixture(scope="module")
def two_devices(tmp_path_factory):
    """The reference sweep in a subprocess with 2 forced host devices, started early so
    that it runs while the other tests do (XLA_FLAGS must be set before JAX starts)."""
    path = tmp_path_factory.mktemp("two") / "two.nc"
    env = {**os.environ, "XLA_FLAGS": "--xla_force_host_platform_device_count=2", "JAX_PLATFORMS": "cpu"}
    proc = subprocess.Popen(
        [
            sys.executable,
            "-c",
            HELPER,
            json.dumps(AXES),
            str(path),
            os.path.dirname(__file__),
            json.dumps(CAPSULE_AXES),
            json.dumps(CAPSULE_RUN),
        ],  # fmt: skip
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    yield proc, path
    if proc.poll() is None:
        proc.kill()
        proc.communicate()


@pytest.fixture(scope="module")
def reference(two_devices):
    """The 10-configuration sweep in memory (chunks of 4: the last one is padded)."""
    before = _sweep.STATS["chunks_computed"]
    ds = lj.sweep(AXES, fixed={"d": 0.5}, chunk_size=4, **FAST)
    assert _sweep.STATS["chunks_computed"] - before == 3
    return ds


def test_sweep_matches_measure(reference):
    ds = reference
    assert ds.sizes == {"omega": 5, "a": 2}
    np.testing.assert_array_equal(ds.omega, AXES["omega"])
    for name in _sweep.MEASURE_FIELDS:
        assert ds[name].dims == ("omega", "a")
    assert ds.attrs["version"] == lj.__version__
    assert ds.attrs["dynamics"] == "exact" and ds.attrs["dynamics_dt"] == 0.02
    assert ds.attrs["fixed_d"] == 0.5 and ds.attrs["fixed_mu_s"] == lj.DEFAULTS["mu_s"]
    assert (ds.attrs["dtype"], ds.attrs["contact"], ds.attrs["start"]) == ("float64", "strict", "paper")
    assert ds.attrs["z"] == 0.3 and ds.attrs["horizon"] == 30.0 and ds.attrs["window"] == 5.0
    assert ds.tau_z.dtype == np.float64
    # The grid covers stick-slip, slip and lift-off, so all paths are compared.
    assert {int(s) for s in np.unique(ds.status)} >= {lj.Status.OK, lj.Status.LIFTOFF}
    kw = {k: v for k, v in FAST.items() if k not in ("progress", "z")}
    # Each configuration on its own (a batch of one, which XLA compiles differently).
    for i, omega in enumerate(AXES["omega"]):
        for j, a in enumerate(AXES["a"]):
            m = lj.measure(lj.Params(omega=omega, a=a, d=0.5), FAST["z"], **kw).to_numpy()
            assert_same(ds.isel(omega=i, a=j), m)


def test_resume_after_interruption_and_read_back(tmp_path, monkeypatch, reference):
    path = tmp_path / "map.nc"
    traces = _sharding.TRACES["run_chunk"]
    real_save = _store.ChunkStore.save
    calls = []

    def interrupted_save(self, index, arrays):
        calls.append(index)
        if len(calls) == 2:
            raise KeyboardInterrupt("simulated interruption after the first chunk")
        real_save(self, index, arrays)

    # Sub-batches of one configuration per device: covers the optional lax.map path.
    monkeypatch.setattr(_sharding, "MICRO_BATCH", 1)
    monkeypatch.setattr(_store.ChunkStore, "save", interrupted_save)
    with pytest.raises(KeyboardInterrupt):
        lj.sweep(AXES, chunk_size=2, path=path, **FAST)
    monkeypatch.setattr(_store.ChunkStore, "save", real_save)
    parts = tmp_path / "map.nc.parts"
    assert sorted(p.name for p in parts.iterdir()) == ["chunk_000000.npz", "manifest.json"]
    assert not path.exists()
    assert json.loads((parts / "manifest.json").read_text())["spec"]["axes"]["omega"]["n"] == 5

    before = dict(_sweep.STATS)
    resumed = lj.sweep(AXES, chunk_size=2, path=path, **FAST)
    assert _sweep.STATS["chunks_computed"] - before.get("chunks_computed", 0) == 4  # chunks 1..4 only
    assert _sweep.STATS["chunks_loaded"] - before.get("chunks_loaded", 0) == 1
    # Five chunks of the same padded shape, interrupted and resumed: one trace.
    assert _sharding.TRACES["run_chunk"] - traces == 1
    assert path.exists() and not parts.exists()
    uninterrupted = lj.sweep(AXES, chunk_size=2, **FAST)
    xr.testing.assert_identical(resumed, uninterrupted)
    assert_same(resumed, reference)

    # A finished sweep is read back, not recomputed (and a different chunk size is irrelevant).
    before = dict(_sweep.STATS)
    again = lj.sweep(AXES, chunk_size=64, path=path, **FAST)
    assert dict(_sweep.STATS) == before
    xr.testing.assert_identical(again, resumed)

    # A different specification at the same path is refused before computing.
    with pytest.raises(ValueError, match="different specification(?s:.*)horizon"):
        lj.sweep(AXES, chunk_size=2, path=path, **{**FAST, "horizon": 31.0})
    with pytest.raises(ValueError, match="different specification(?s:.*)axes"):
        lj.sweep({**AXES, "a": [0.02, 0.06]}, chunk_size=2, path=path, **FAST)
    assert dict(_sweep.STATS) == before


def test_overwrite_replaces_foreign_file(tmp_path, monkeypatch):
    monkeypatch.setattr(_sharding, "MICRO_BATCH", 1)  # shares the compilation of the test above
    path = tmp_path / "x.nc"
    path.write_text("not a sweep")
    with pytest.raises(ValueError, match="not a locomotion_jax sweep"):
        lj.sweep({"omega": [2.0, 6.0]}, chunk_size=2, path=path, **FAST)
    ds = lj.sweep({"omega": [2.0, 6.0]}, chunk_size=2, path=path, overwrite=True, **FAST)
    xr.testing.assert_identical(xr.load_dataset(path, engine="h5netcdf"), ds)


def test_list_mode_flags_invalid_configurations(reference):
    # mu_s < mu_k is outside the model: flagged per configuration, others unaffected.
    axes = {"omega": [2.0, 2.0, 6.0, 6.0], "mu_s": [0.7, 0.4, 0.7, 0.4]}
    ds = lj.sweep(axes, mode="list", fixed={"a": 0.05}, chunk_size=4, on_invalid="flag", **FAST)
    assert ds.sizes == {"config": 4} and ds.mu_s.dims == ("config",)
    np.testing.assert_array_equal(ds.status, [0, lj.Status.INVALID, 0, lj.Status.INVALID])
    assert_same(ds.isel(config=[0, 2]), reference.sel(a=0.05, omega=[2.0, 6.0]).rename(omega="config"))
    with pytest.raises(ValueError, match=r"2 of 4 .*mu_s\[1\]=0.4.*Invalid parameter 'mu_s'"):
        lj.sweep(axes, mode="list", chunk_size=4, **FAST)


def test_omega_over_wn1_axis(reference):
    ds = lj.sweep({"omega_over_wn1": [0.2, 0.6], "a": AXES["a"]}, chunk_size=4, **FAST)
    np.testing.assert_allclose(ds.omega.isel(a=0), [2.0, 6.0])  # wn1 = 10 at the defaults
    assert_same(ds, reference.sel(omega=[2.0, 6.0]).rename(omega="omega_over_wn1"))


def test_cost_order_gives_identical_results_and_compiles_once(monkeypatch):
    # mu_s = 0.4 < mu_k is invalid: flagged per configuration (and predicted to cost nothing).
    axes = {"omega": AXES["omega"], "mu_s": [0.7, 0.4]}
    # Chunks of 9 (two chunks, a shape of this test's own): without `_sharding.padded_size`
    # the ninth lane is a SIMD remainder, computed 1 ulp differently from the others.
    kw: dict[str, Any] = dict(fixed={"a": 0.05}, chunk_size=9, on_invalid="flag", **FAST)
    real, perms = _sweep._cost_permutation, []

    def spy(*args):
        perms.append(real(*args))
        return perms[-1]

    monkeypatch.setattr(_sweep, "_cost_permutation", spy)
    traces = _sharding.TRACES["run_chunk"]
    cost = lj.sweep(axes, order="cost", **kw)
    natural = lj.sweep(axes, order="natural", **kw)
    # Two chunks in either order: one trace at most (the pilot is a separate, `simulate`, function;
    # none where another test of this process compiled the chunk's bucket).
    assert _sharding.TRACES["run_chunk"] - traces <= 1
    (perm,) = perms
    assert sorted(perm[:5]) == [1, 3, 5, 7, 9]  # the invalid ones first: the order differs from the grid's
    assert (cost.attrs.pop("order"), natural.attrs.pop("order")) == ("cost", "natural")
    xr.testing.assert_identical(cost, natural)  # bit for bit, configuration by configuration
    np.testing.assert_array_equal(cost.status.sel(mu_s=0.4), lj.Status.INVALID)
    assert (cost.status.sel(mu_s=0.7) != lj.Status.INVALID).all()


def test_sweeps_of_other_horizons_caps_and_sizes_share_a_program():
    # The step cap is data and a chunk is padded to its bucket (`_sharding.padded_size`): sweeps of
    # 3 and 10 configurations (chunks of 16) at two horizons, and with `Exact(max_steps=...)`, trace one
    # chunk program at most (none where another test of this process compiled the bucket).
    traces = _sharding.TRACES["run_chunk"]
    kw: dict[str, Any] = {**FAST, "z": 100.0, "horizon": 12.0, "fixed": {"a": 0.05}}  # a horizon of this test's own
    omegas = np.linspace(2.0, 23.0, 10)
    small = lj.sweep({"omega": omegas[:3]}, **kw)
    large = lj.sweep({"omega": omegas}, **kw)
    longer = lj.sweep({"omega": omegas}, **{**kw, "horizon": 14.0})
    cap = lj.Exact(dt=0.02, max_steps=4000)
    capped = lj.sweep({"omega": omegas}, **{**kw, "dynamics": cap})
    assert _sharding.TRACES["run_chunk"] - traces <= 1
    assert small.attrs["max_steps"] < longer.attrs["max_steps"]
    for name in _sweep.MEASURE_FIELDS:  # a configuration's result does not depend on its sweep
        np.testing.assert_array_equal(small[name], large[name][:3], err_msg=name)
    assert not np.array_equal(large.mean_speed, longer.mean_speed)  # the horizon reached the engine
    # The cap reached the engine: each configuration stops at it, as in its own `measure`.
    assert capped.attrs["max_steps"] == 4000 and (capped.n_steps <= 4000).all()
    over = (large.n_steps > 4000).values
    assert over.sum() >= 5 and (capped.status.values[over] == lj.Status.MAX_STEPS).all()
    np.testing.assert_array_equal(capped.n_steps.values[~over], large.n_steps.values[~over])  # those not capped
    alone = lj.measure(lj.Params(omega=omegas[-1], a=0.05), 100.0, horizon=12.0, window=5.0, dynamics=cap)
    assert (int(alone.status), int(alone.n_steps)) == (int(capped.status[-1]), int(capped.n_steps[-1]))


def test_cost_order_resumes_with_its_stored_permutation(tmp_path, monkeypatch):
    path = tmp_path / "cost.nc"
    real_save = _store.ChunkStore.save

    def interrupted_save(self, index, arrays):
        if index != 0:
            raise KeyboardInterrupt("simulated interruption after the first chunk")
        real_save(self, index, arrays)

    monkeypatch.setattr(_store.ChunkStore, "save", interrupted_save)
    with pytest.raises(KeyboardInterrupt):
        lj.sweep(AXES, chunk_size=3, path=path, order="cost", **FAST)
    monkeypatch.setattr(_store.ChunkStore, "save", real_save)
    parts = tmp_path / "cost.nc.parts"
    assert sorted(p.name for p in parts.iterdir()) == ["chunk_000000.npz", "manifest.json", "order.npy"]
    assert json.loads((parts / "manifest.json").read_text())["order"] == "cost"
    perm = np.load(parts / "order.npy")
    assert sorted(perm) == list(range(10)) and list(perm) != list(range(10))

    # A damaged permutation is refused before computing (the stored chunks could not be placed).
    np.save(parts / "order.npy", perm[::-1])
    before = dict(_sweep.STATS)
    with pytest.raises(ValueError, match="order.npy is missing or damaged"):
        lj.sweep(AXES, chunk_size=3, path=path, order="cost", **FAST)
    np.save(parts / "order.npy", perm)

    # Resumed in the stored order, whatever is asked: no new pilot, the remaining three chunks.
    resumed = lj.sweep(AXES, chunk_size=3, path=path, order="natural", **FAST)
    assert _sweep.STATS["pilots"] == before.get("pilots", 0)
    assert _sweep.STATS["chunks_computed"] - before.get("chunks_computed", 0) == 3
    assert _sweep.STATS["chunks_loaded"] - before.get("chunks_loaded", 0) == 1
    assert resumed.attrs.pop("order") == "cost" and not parts.exists()
    natural = lj.sweep(AXES, chunk_size=3, order="natural", **FAST)
    assert natural.attrs.pop("order") == "natural"
    xr.testing.assert_identical(resumed, natural)


def test_auto_order_sorts_only_where_it_can_pay():
    ex, big = lj.Exact(dt=0.02), _sweep.AUTO_MIN_CONFIGS
    assert _sweep.resolve_order("auto", ex, 600.0, 25.0, big, 8) == "cost"
    assert _sweep.resolve_order("auto", ex, 600.0, 25.0, big - 1, 8) == "natural"  # the pilot would not pay
    assert _sweep.resolve_order("auto", ex, 25.0, 25.0, big, 8) == "natural"  # every run lasts t_start + window
    assert _sweep.resolve_order("auto", ex, 600.0, 25.0, big, 1) == "natural"  # one loop: the slowest sets the time
    assert _sweep.resolve_order("auto", lj.Smoothed(eps=1e-3), 600.0, 25.0, big, 8) == "natural"
    assert _sweep.resolve_order("cost", ex, 25.0, 25.0, 1, 1) == "cost"
    with pytest.raises(ValueError, match="order must be one of 'auto', 'natural', 'cost', got 'fastest'"):
        _sweep.resolve_order("fastest", ex, 600.0, 25.0, big, 8)
    assert _sweep._loops_per_device(n_chunks=3, shard=128, micro_batch=64) == 6
    assert _sweep._loops_per_device(n_chunks=3, shard=128, micro_batch=None) == 3


def test_pilot_runs_in_equal_chunks(monkeypatch):
    shapes = []

    def fake_simulate(params, t_end, save_at, **kwargs):  # speed omega, 10 omega switches per time unit
        om = np.asarray(params.omega)
        shapes.append(om.shape)
        X = np.stack([0 * om, om * (save_at[1] - save_at[0])], -1)
        status = np.where(np.isfinite(om), lj.Status.OK, lj.Status.INVALID)
        return SimpleNamespace(X=X, status=status, n_switch=np.nan_to_num(10 * om * t_end), t_liftoff=np.inf * om)

    monkeypatch.setattr(importlib.import_module("locomotion_jax.run._simulate"), "simulate", fake_simulate)
    omega = np.asarray([1.0, 2.0, np.nan, 4.0, 5.0, 6.0, 7.0])
    out = _schedule.pilot({"omega": omega, "a": np.full(7, 0.05)}, chunk_size=3)
    assert shapes == [(3,)] * 3  # the last chunk padded: one compilation
    np.testing.assert_allclose(out["speed"], np.nan_to_num(omega), rtol=1e-15)
    np.testing.assert_allclose(out["switch_rate"], 10 * np.nan_to_num(omega), rtol=1e-15)
    np.testing.assert_array_equal(out["valid"], np.isfinite(omega))
    assert out["t_liftoff"][0] == np.inf


HELPER = textwrap.dedent(
    """
    import json, sys
    import jax
    jax.config.update("jax_enable_x64", True)
    import locomotion_jax as lj
    from locomotion_jax.maps import _sharding
    axes, path, tests = json.loads(sys.argv[1]), sys.argv[2], sys.argv[3]
    lj.sweep(axes, chunk_size=4, path=path, z=0.3, horizon=30.0, window=5.0,
             dynamics=lj.Exact(dt=0.02), progress=False)
    traces = _sharding.TRACES["run_chunk"]
    sys.path.insert(0, tests)
    from mechanism_cases import capsule
    lj.sweep(json.loads(sys.argv[4]), mechanism=lambda omega, F0: capsule(a=F0, w=omega), chunk_size=3,
             path=path + ".capsule.nc", progress=False, **json.loads(sys.argv[5]))
    print(json.dumps({"devices": jax.device_count(), "traces": traces,
                      "capsule_traces": _sharding.TRACES["run_chunk"] - traces}))
    """
)

CAPSULE_AXES = {"omega": [2.0, 3.0, 5.5], "F0": [0.5, 1.5]}
CAPSULE_RUN: dict[str, Any] = dict(z=1.0, horizon=30.0, window=4 * math.pi, t_start=20.0)
"""A map of the capsule robot (`mechanism_cases.capsule`) run on two forced devices and on one."""


def test_two_forced_host_devices_equal_one(two_devices, reference):
    proc, path = two_devices
    stdout, stderr = proc.communicate(timeout=300)
    assert proc.returncode == 0, stderr
    info = json.loads(stdout.strip().splitlines()[-1])
    assert info == {"devices": 2, "traces": 1, "capsule_traces": 1}
    two = xr.load_dataset(path, engine="h5netcdf")
    assert two.attrs["n_devices"] == 2 and reference.attrs["n_devices"] == jax.device_count() == 1
    assert_same(two, reference)
    # A builder's map: the same values on two devices as on one (chunks of 3 split 2 + 2, one padding lane).
    two = xr.load_dataset(str(path) + ".capsule.nc", engine="h5netcdf")
    one = lj.sweep(CAPSULE_AXES, mechanism=lambda omega, F0: capsule(a=F0, w=omega), chunk_size=3, progress=False,
                   **CAPSULE_RUN)  # fmt: skip
    assert two.attrs.pop("n_devices") == 2 and one.attrs.pop("n_devices") == 1
    assert (np.asarray(one.status) == lj.Status.OK).all() and np.ptp(np.asarray(one.tau_z)) > 1
    xr.testing.assert_allclose(two, one, rtol=1e-12, atol=1e-14)
    np.testing.assert_array_equal(two.n_steps, one.n_steps)


@pytest.mark.parametrize(
    "axes, kwargs, message",
    [
        ({"omega": []}, {}, "Axis 'omega' is empty"),
        ({"omgea": [1.0]}, {}, "Unknown parameter 'omgea'"),
        ({"a": [0.05, 4.0]}, {}, r"a\[1\]=4.0: Invalid parameter 'a'.*0 <= a < lbar"),
        ({"omega": [1.0, 2.0], "a": [0.1]}, {"mode": "list"}, "equal length"),
        ({"omega": [1.0]}, {"fixed": {"omega": 2.0}}, "both as an axis and as a fixed"),
        ({"omega": [1.0]}, {"z": 0.0}, "z must be"),
        ({"omega": [1.0]}, {"chunk_size": 0}, "chunk_size"),
        ({"omega": [1.0]}, {"dtype": "int32"}, "floating dtype"),
        ({"omega": np.ones((2, 2))}, {}, "1-D"),
    ],
)
def test_bad_input_fails_before_computing(axes, kwargs, message):
    before, traces = dict(_sweep.STATS), dict(_sharding.TRACES)
    with pytest.raises(ValueError, match=message):
        lj.sweep(axes, **{**FAST, **kwargs})
    assert dict(_sweep.STATS) == before and dict(_sharding.TRACES) == traces


def test_unwritable_path_fails_before_computing(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    before = dict(_sweep.STATS)
    with pytest.raises(ValueError, match="Cannot write the sweep output"):
        lj.sweep({"omega": [1.0]}, path=blocker / "sub" / "out.nc", **FAST)
    with pytest.raises(ValueError, match="is a directory"):
        lj.sweep({"omega": [1.0]}, path=tmp_path, **FAST)
    assert dict(_sweep.STATS) == before


def capsules(omega, F0):
    wave = lj.Sinusoid(a=jnp.asarray(F0), omega=jnp.asarray(omega), lbar=0.0)
    return lj.Mechanism(masses=[1.0, 0.5], friction=[lj.AnisotropicCoulomb(0.5, 0.2, 0.4, 0.15), None],
                        carried_by=[None, 0], links=[lj.Spring(0, 1, k=10.0), lj.Force(0, 1, wave)])  # fmt: skip


def test_sweep_maps_a_mechanism_as_measure_does():
    omega, F0 = np.array([2.0, 3.0, 5.5]), np.array([0.5, 1.5])
    settings: dict[str, Any] = dict(z=1e6, horizon=4 * math.pi, window=4 * math.pi, t_start=20.0)
    ds = lj.sweep({"omega": omega, "F0": F0}, mechanism=capsules, chunk_size=4, progress=False, **settings)
    W, F = (q.ravel() for q in np.meshgrid(omega, F0, indexing="ij"))
    m = lj.measure(capsules(W, F), **settings)
    assert ds["mean_speed"].shape == (3, 2) and (np.asarray(ds["status"]) == lj.Status.OK).all()
    np.testing.assert_allclose(np.asarray(ds["mean_speed"]).ravel(), np.asarray(m.mean_speed), rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(np.asarray(ds["e_d"]).ravel(), np.asarray(m.e_d), rtol=1e-12)
    assert ds.attrs["kind"] == "mechanism" and ds.attrs["friction"] == "AnisotropicCoulomb, none"
    assert ds.attrs["links"] == "Spring(0, 1), Force(0, 1)" and float(np.asarray(ds["mean_speed"]).min()) < -0.01


def test_sweep_flags_an_invalid_mechanism_and_runs_the_others():
    """A map over the internal spring's stiffness with one k <= 0 (built with `check=False`):
    `on_invalid="flag"` marks that capsule INVALID (NaN figures) and the others equal `lj.measure` of
    each alone; `on_invalid="raise"` names the configuration, the link and the valid range."""

    def build(k, omega):
        wave = lj.Sinusoid(a=1.5, omega=jnp.asarray(omega), lbar=0.0)
        return lj.Mechanism(masses=[1.0, 0.5], friction=[lj.AnisotropicCoulomb(0.5, 0.2, 0.4, 0.15), None],
                            carried_by=[None, 0], links=[lj.Spring(0, 1, k=jnp.asarray(k)), lj.Force(0, 1, wave)],
                            check=False)  # fmt: skip

    k, omega = np.array([10.0, -2.0, 4.0]), np.array([3.0])
    settings: dict[str, Any] = dict(z=1e6, horizon=4 * math.pi, window=4 * math.pi, t_start=20.0)
    ds = lj.sweep({"k": k, "omega": omega}, mechanism=build, chunk_size=2, on_invalid="flag", progress=False,
                  **settings)  # fmt: skip
    status = np.asarray(ds["status"])[:, 0]
    assert status.tolist() == [lj.Status.OK, lj.Status.INVALID, lj.Status.OK]
    assert np.isnan(float(ds["mean_speed"][1, 0])) and np.isnan(float(ds["e_d"][1, 0]))
    for i in (0, 2):
        alone = lj.measure(build(k[i : i + 1], omega), **settings)
        assert float(ds["mean_speed"][i, 0]) == float(alone.mean_speed[0])
        assert float(ds["e_d"][i, 0]) == float(alone.e_d[0])
    with pytest.raises(ValueError, match=r"grid index \(1, 0\) \(k=.*'k' of links\[0\] Spring\(0, 1\).*k > 0"):
        lj.sweep({"k": k, "omega": omega}, mechanism=build, progress=False, **settings)


def test_a_mechanism_map_into_netcdf_resumes_and_refuses_another_builder(tmp_path, monkeypatch):
    """A builder's map into a NetCDF file, interrupted after its first chunk: its parts directory holds
    that chunk, a rerun computes only the others (one chunk program for both runs) and equals the map
    in memory, a finished map is read back, and another builder or setting is refused, naming it."""
    omega, F0 = np.array([2.0, 3.0, 5.5]), np.array([0.5, 1.5])
    settings: dict[str, Any] = dict(z=1e6, horizon=4 * math.pi, window=4 * math.pi, t_start=20.0, progress=False)
    path, traces, calls = tmp_path / "capsule.nc", _sharding.TRACES["run_chunk"], []
    real_save = _store.ChunkStore.save

    def interrupted_save(self, index, arrays):
        calls.append(index)
        if len(calls) == 2:
            raise KeyboardInterrupt("simulated interruption after the first chunk")
        real_save(self, index, arrays)

    run = lambda **kw: lj.sweep({"omega": omega, "F0": F0}, mechanism=kw.pop("build", capsules), chunk_size=2,
                                **{**settings, **kw})  # fmt: skip
    monkeypatch.setattr(_store.ChunkStore, "save", interrupted_save)
    with pytest.raises(KeyboardInterrupt):
        run(path=path)
    monkeypatch.setattr(_store.ChunkStore, "save", real_save)
    parts = tmp_path / "capsule.nc.parts"
    assert sorted(p.name for p in parts.iterdir()) == ["chunk_000000.npz", "manifest.json"] and not path.exists()
    before = dict(_sweep.STATS)
    resumed = run(path=path)
    assert _sweep.STATS["chunks_computed"] - before.get("chunks_computed", 0) == 2  # chunks 1 and 2 only
    assert _sweep.STATS["chunks_loaded"] - before.get("chunks_loaded", 0) == 1
    assert _sharding.TRACES["run_chunk"] - traces <= 1  # none where another test compiled the bucket
    assert path.exists() and not parts.exists()
    memory = run()
    xr.testing.assert_identical(resumed, memory)
    assert resumed.stick_fraction.dims == ("omega", "F0", "mass") and resumed.attrs["order"] == "natural"
    before = dict(_sweep.STATS)
    xr.testing.assert_identical(run(path=path), memory)  # read back, not computed
    with pytest.raises(ValueError, match=r"different specification:\n  mechanism\.sha256: stored "):
        run(path=path, build=lambda omega, F0: capsules(omega, 1.01 * np.asarray(F0)))
    with pytest.raises(ValueError, match="different specification(?s:.*)horizon"):
        run(path=path, horizon=13.0)
    assert dict(_sweep.STATS) == before
    assert run(path=path, build=lambda omega, F0: capsules(omega, 1.01 * np.asarray(F0)), overwrite=True).attrs[
        "order"] == "natural"  # fmt: skip


def test_a_mechanism_map_in_cost_order_equals_grid_order_and_its_pilot_predicts_the_cost():
    """`order="cost"` on a builder's map: one pilot run (`_schedule.mechanism_cost_order`), the same
    map bit for bit as in grid order, and the pilot's order of the capsules follows their measured
    integrator iterations (rank correlation > 0.8): it predicts what it sorts by."""
    omega, F0 = np.array([1.5, 2.5, 4.0, 6.0, 9.0]), np.array([0.3, 1.0, 2.0])
    kw: dict[str, Any] = dict(z=0.5, horizon=60.0, window=5.0, chunk_size=8, progress=False)  # each one's t_start
    pilots = _sweep.STATS["pilots"]
    cost = lj.sweep({"omega": omega, "F0": F0}, mechanism=capsules, order="cost", **kw)
    natural = lj.sweep({"omega": omega, "F0": F0}, mechanism=capsules, order="natural", **kw)
    assert _sweep.STATS["pilots"] - pilots == 1
    assert (cost.attrs.pop("order"), natural.attrs.pop("order")) == ("cost", "natural")
    xr.testing.assert_identical(cost, natural)
    W, F = (q.ravel() for q in np.meshgrid(omega, F0, indexing="ij"))
    perm = _schedule.mechanism_cost_order(lambda i: capsules(W[i], F[i]), W.size, 8, t_start=None, z=0.5,
                                          horizon=60.0, window=5.0, dt=0.01)  # fmt: skip
    steps = np.asarray(natural.n_steps, float).ravel()
    assert np.ptp(steps) > 0.5 * steps.max() and list(perm) != list(range(W.size))
    rank = np.empty(W.size)
    rank[perm] = np.arange(W.size)
    assert np.corrcoef(rank, np.argsort(np.argsort(steps, kind="stable")))[0, 1] > 0.8
