"""`locomotion-jax sweep FILE --vary PATH=VALUES` maps the numbers of a mechanism file (`kind = "mechanism"`):
the map equals `lj.sweep(axes, mechanism=build)` of the same mechanism built by hand in Python, bit for bit
(grid and list mode, a fixed value, paths joined by commas); an invalid swept value is refused naming
its grid index and path, or flagged in its own row with the others unchanged; a bad path or value ends
with one `Error:` line naming the option, the path and what the file has there. A chain file
(`examples/worm.toml`) is swept the same way. Short runs (t_start 5, horizon 6, dt 0.02) and one
chunk shape (4 configurations): one compilation per mechanism and dtype serves the module."""

import json
import re
from pathlib import Path
from typing import Any

import jax
import locomotion_jax as lj
import numpy as np
import pytest
import xarray as xr
from cli_helpers import invoke
from locomotion_jax.maps import _sweep


pytestmark = pytest.mark.usefixtures("isolate_xla_flags")
EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
CAPSULE = str(EXAMPLES / "capsule.toml")
RUN: dict[str, Any] = dict(
    z=1e6, horizon=6.0, window=6.0, t_start=5.0, dynamics=lj.Exact(dt=0.02), chunk_size=4, progress=False
)
FLAGS = ["--z", "1e6", "--horizon", "6", "--window", "6", "--t-start", "5", "--dt", "0.02", "--chunk-size", "4",
         "--no-progress"]  # fmt: skip
A, M0, K, C1, OMEGA = "links.1.waveform.a", "bodies.0.mass", "links.0.k", "bodies.1.c", "links.1.waveform.omega"
G1 = "links.2.waveform.cos.1"


def capsule(**v: Any) -> lj.Mechanism:
    """examples/capsule.toml written out in Python, any of its numbers replaced by `v` (keyed by path)."""
    get = lambda path, default: np.asarray(v.get(path, default), float)
    m0, a, omega = get(M0, 1.0), get(A, 0.6), get(OMEGA, 3.0)
    omega2 = get("links.2.waveform.omega", 3.0)
    m0, c1 = np.broadcast_arrays(m0, get(C1, 0.0))
    masses = np.stack(np.broadcast_arrays(m0, 0.5), -1)
    c = np.stack(np.broadcast_arrays(0.0, c1), -1)
    cos = np.stack(np.broadcast_arrays(0.0, get(G1, 0.1)), -1)
    return lj.Mechanism(
        masses=masses, friction=[lj.AnisotropicCoulomb(0.5, 0.2, 0.4, 0.15), None], carried_by=[None, 0],
        links=[lj.Spring(0, 1, k=get(K, 10.0), rest=0.0), lj.Force(0, 1, lj.Sinusoid(a=a, omega=omega, lbar=0.0)),
               lj.ExternalForce(0, lj.Fourier(cos, [0.0, 0.0], omega2, 0.0))],
        c=c, check=False,
    )  # fmt: skip


def sweep_cli(tmp_path: Path, *args: str) -> xr.Dataset:
    out = tmp_path / "capsule.nc"
    res = invoke("sweep", CAPSULE, *args, *FLAGS, "--out", str(out))
    assert res.exit_code == 0, res.output
    return xr.load_dataset(out)


def assert_same(ds: xr.Dataset, expected: xr.Dataset) -> None:
    """Same dimensions in the same order, coordinates and every variable bit for bit."""
    assert list(ds.dims) == list(expected.dims) and set(ds.data_vars) == set(expected.data_vars)
    for name in expected.coords:
        np.testing.assert_array_equal(ds[name].values, expected[name].values)
    for name in expected.data_vars:
        assert ds[name].dims == expected[name].dims, name
        np.testing.assert_array_equal(ds[name].values, expected[name].values, err_msg=name)


def test_the_file_as_loaded_is_the_capsule_written_here():
    """The hand-written `capsule` is the file: their measurements agree exactly (the reference of the tests below)."""
    one: dict[str, Any] = dict(z=1e6, horizon=6.0, window=6.0, t_start=5.0, dynamics=lj.Exact(dt=0.02))
    mine, loaded = lj.measure(capsule(), **one), lj.measure(lj.load_mechanism(CAPSULE), **one)
    for name, value in loaded.to_numpy().items():
        np.testing.assert_array_equal(mine.to_numpy()[name], value, err_msg=name)


def test_grid_sweep_of_the_file_equals_lj_sweep_bit_for_bit(tmp_path):
    a, m0 = np.linspace(0.3, 0.9, 3), np.array([0.8, 1.2])
    ds = sweep_cli(tmp_path, "--vary", f"{A}=0.3:0.9:3", "--vary", f"{M0}=0.8,1.2", "--vary", f"{K}=12")
    expected = lj.sweep({A: a, M0: m0}, mechanism=capsule, fixed={K: 12.0}, **RUN)
    assert ds.mean_speed.dims == (A, M0) and ds.mean_speed.shape == (3, 2)
    assert_same(ds, expected)
    assert (ds.status.values == lj.Status.OK).all()
    speed = ds.mean_speed.values
    assert np.all(np.isfinite(speed)) and np.ptp(speed[:, 0]) > 1e-3 and np.ptp(speed[0, :]) > 1e-4  # both axes matter
    assert ds.attrs["swept"] == f"{A},{M0}" and ds.attrs["kind"] == "mechanism"
    # Run again: the finished file is read back (nothing computed). In cost order (a pilot run of the
    # capsules), into another file: the same map bit for bit.
    args = ["--vary", f"{A}=0.3:0.9:3", "--vary", f"{M0}=0.8,1.2", "--vary", f"{K}=12"]
    before = dict(_sweep.STATS)
    assert_same(sweep_cli(tmp_path, *args), expected)
    assert dict(_sweep.STATS) == before
    res = invoke("sweep", CAPSULE, *args, *FLAGS, "--order", "cost", "--out", str(tmp_path / "cost.nc"))
    assert res.exit_code == 0 and _sweep.STATS["pilots"] == before.get("pilots", 0) + 1, res.output
    cost = xr.load_dataset(tmp_path / "cost.nc")
    assert cost.attrs["order"] == "cost" and ds.attrs["order"] == "natural"
    assert_same(cost, expected)


def test_a_files_map_into_a_zarr_store_is_resumed(tmp_path):
    """`--out capsule.zarr`: the store equals the NetCDF map bit for bit; run again, it is read back
    (nothing computed); with another value, refused naming the specification."""
    out = tmp_path / "capsule.zarr"
    args = ["sweep", CAPSULE, "--vary", f"{A}=0.3:0.9:3", "--vary", f"{M0}=0.8,1.2", *FLAGS, "--out", str(out)]
    res = invoke(*args)
    assert res.exit_code == 0, res.output
    expected = lj.sweep({A: np.linspace(0.3, 0.9, 3), M0: np.array([0.8, 1.2])}, mechanism=capsule, **RUN)
    assert_same(xr.open_zarr(out).load(), expected)
    again = invoke(*args)
    assert again.exit_code == 0 and f"wrote {out}: {A}[3] x {M0}[2]" in again.output, again.output
    other = invoke(*[a.replace("0.3:0.9:3", "0.3:0.9:4") for a in args])
    assert other.exit_code != 0 and "holds a sweep with a different specification" in other.output


def test_list_sweep_with_joined_paths_equals_lj_sweep_bit_for_bit(tmp_path):
    """`--mode list`; `links.1.waveform.omega,links.2.waveform.omega` (the base frequency every waveform shares)."""
    both = f"{OMEGA},links.2.waveform.omega"
    omega, c1, g1 = np.array([2.0, 3.0, 4.0, 5.0]), np.array([0.0, 0.05, 0.1, 0.2]), np.array([0.0, 0.1, 0.2, 0.05])
    ds = sweep_cli(tmp_path, "--mode", "list", "--vary", f"{both}=2,3,4,5", "--vary", f"{C1}=0,0.05,0.1,0.2",
                   "--vary", f"{G1}=0,0.1,0.2,0.05")  # fmt: skip

    def build(**v: Any) -> lj.Mechanism:
        return capsule(**{OMEGA: v[both], "links.2.waveform.omega": v[both], C1: v[C1], G1: v[G1]})

    expected = lj.sweep({both: omega, C1: c1, G1: g1}, mechanism=build, mode="list", **RUN)
    assert ds.mean_speed.dims == ("config",) and list(ds.coords) == [both, C1, G1]
    assert_same(ds, expected)
    assert len(set(ds.mean_speed.values.tolist())) == 4


def test_an_invalid_value_is_refused_by_name_or_flagged_in_its_own_row(tmp_path):
    res = invoke("sweep", CAPSULE, "--vary", f"{M0}=-1,1,1.5,2", *FLAGS, "--out", str(tmp_path / "x.nc"))
    assert res.exit_code == 2 and "Traceback" not in res.output
    assert res.output.startswith(f"Error: Invalid configuration at grid index (0,) ({M0}=-1.0): ")
    assert "masses" in res.output and "body 0" in res.output, res.output
    assert not (tmp_path / "x.nc").exists()
    ds = sweep_cli(tmp_path, "--vary", f"{M0}=-1,1,1.5,2", "--on-invalid", "flag")
    status = ds.status.values
    assert status[0] == lj.Status.INVALID and (status[1:] == lj.Status.OK).all()
    good = lj.sweep({M0: np.array([1.0, 1.0, 1.5, 2.0])}, mechanism=capsule, **RUN)  # the invalid row replaced
    for name in ("mean_speed", "e_d", "cost_of_transport", "regime"):
        np.testing.assert_array_equal(ds[name].values[1:], good[name].values[1:], err_msg=name)
    assert np.isnan(ds.mean_speed.values[0])
    again = ["sweep", CAPSULE, "--vary", f"{M0}=1,2", *FLAGS, "--out", str(tmp_path / "capsule.nc")]
    res = invoke(*again)  # the file holds another map: refused, naming what differs; --overwrite replaces it
    assert res.exit_code == 2 and "different specification" in res.output and "axes" in res.output, res.output
    assert invoke(*again, "--overwrite").exit_code == 0
    assert xr.load_dataset(tmp_path / "capsule.nc").sizes[M0] == 2


@pytest.mark.parametrize(
    "args, message",
    [
        ([f"{M0}=abc"], f"--vary {M0}=abc: cannot read 'abc'; expected a value, 'start:stop:count' or 'v1,v2,...'."),
        ([f"{M0}=1:2"], f"--vary {M0}=1:2: cannot read '1:2'"),
        ([f"{M0}=1:2:0"], f"--vary {M0}=1:2:0 '1:2:0': empty range"),
        ([M0], f"--vary '{M0}': expected PATH=VALUES"),
        (["links.9.k=1,2"], "--vary links.9.k: links is a list of 3 (its indices are 0 to 2); '9' is not one of"),
        (
            ["links.1.kk=1,2"],
            r"--vary links.1.kk: .*capsule.toml, line 24: \[\[links\]\] #2 kk: unknown field; the "
            "fields of this table are type, a, b, waveform.",
        ),
        (
            ["bodies.0.friction.mu_s=1,2"],
            r"--vary bodies.0.friction.mu_s: .*capsule.toml, line 11: \[\[bodies\]\] #1 "
            "friction.mu_s: unknown field; the fields of this table are type, mu_s_fwd",
        ),
        (
            ["links.1.waveform=1,2"],
            "--vary links.1.waveform: this is a table (its fields are type, a, omega, lbar), "
            "not a number; name one number.",
        ),
        (["links.1.type=1,2"], "--vary links.1.type: this is 'Force', not a number"),
        (["links.1.a=1,2"], "--vary links.1.a: 'a' says which body the file uses, not a number to sweep."),
        (["bodies.1.carried_by=1,2"], "--vary bodies.1.carried_by: 'carried_by' says which body"),
        (["schema=1,2"], "--vary schema: 'schema' says which schema"),
        (
            [f"{G1[:-2]}.5=1,2"],
            "--vary links.2.waveform.cos.5: links.2.waveform.cos is a list of 2 (its indices are "
            "0 to 1); '5' is not one of its indices.",
        ),
        ([f"{M0}.1=1,2"], f"--vary {M0}.1: {M0} is the number 1.0; it has no field '1'."),
        (
            ["body.0.mass=1,2"],
            "--vary body.0.mass: the file's top level has no field 'body'; its fields are schema, "
            "kind, description, bodies, links.",
        ),
        (
            [f"{OMEGA}=1,2"],
            rf"--vary {OMEGA}: .*capsule.toml, line 30: links\[2\] ExternalForce\(0\): its waveform's "
            r"omega=3.0 differs .* links.1.waveform.omega,links.2.waveform.omega=1:6:32.",
        ),
        ([f"{M0}=1,2", f"{A},{M0}=1,2"], f"--vary {M0}: given twice"),
        ([f"{M0}=2"], "nothing to sweep: give at least one range or list, e.g. --vary links.1.k=5:20:4."),
    ],  # fmt: skip
)
def test_a_bad_vary_names_the_option_and_the_path(tmp_path, args, message):
    vary = [x for a in args for x in ("--vary", a)]
    res = invoke("sweep", CAPSULE, *vary, "--out", str(tmp_path / "x.nc"))
    assert res.exit_code == 2 and "Traceback" not in res.output and res.output.count("\n") == 1, res.output
    assert re.match("Error: " + (message if "\\" in message or ".*" in message else re.escape(message)), res.output), (
        res.output
    )
    assert not (tmp_path / "x.nc").exists()


@pytest.mark.parametrize(
    "args, message",
    [
        (["--vary", f"{M0}=1,2"], "--vary names the numbers of a mechanism file (a chain, or bodies and links); the"),
        (["--masses", "1,1", "--vary", "chain.k=1,2"], "--vary names the numbers of a mechanism file"),
        ([str(EXAMPLES / "paper.toml"), "--vary", "params.k=1,2"], "--vary names the numbers of a mechanism file"),
        ([CAPSULE], "nothing to sweep: name the numbers of"),
        ([CAPSULE, "--omega", "1,2"], "--omega: " + CAPSULE + " describes the mechanism (bodies and links); name"),
    ],
)
def test_vary_belongs_to_mechanism_files_and_they_need_it(tmp_path, args, message):
    res = invoke("sweep", *args, "--out", str(tmp_path / "x.nc"))
    assert res.exit_code == 2 and "Traceback" not in res.output, res.output
    assert res.output.startswith("Error: " + message), res.output


def test_float32_sweep_equals_lj_sweep_in_float32_and_float64_within_its_precision(tmp_path):
    a = np.linspace(0.3, 1.2, 4)  # as the CLI reads 0.3:1.2:4
    expected64 = lj.sweep({A: a}, mechanism=capsule, **RUN)
    out = tmp_path / "f32.nc"
    try:
        res = invoke("--no-x64", "sweep", CAPSULE, "--vary", f"{A}=0.3:1.2:4", *FLAGS, "--out", str(out))
        assert res.exit_code == 0, res.output
        expected32 = lj.sweep({A: a}, mechanism=capsule, **RUN)  # still in 32-bit mode
    finally:
        jax.config.update("jax_enable_x64", True)
    ds = xr.load_dataset(out)
    assert ds.attrs["dtype"] == "float32" and ds.mean_speed.dtype == np.float32
    assert_same(ds, expected32)
    assert (ds.status.values == lj.Status.OK).all()
    np.testing.assert_allclose(ds.mean_speed.values, expected64.mean_speed.values, rtol=1e-3)


def test_hop_with_a_carried_body_equals_strict_on_the_ground(tmp_path):
    """`--contact hop` with a carried body: the capsule's forces are horizontal, so it never lifts off
    and its `measure` (JSON) and `sweep` (a map) under "hop" equal those under "strict" (SPEC §10:
    without lift-off the third reading equals the strict one), and no flight is recorded."""
    args = ["--z", "1e6", "--horizon", "6", "--window", "6", "--t-start", "5", "--dt", "0.02", "--json"]
    got = {c: invoke("measure", CAPSULE, *args, "--contact", c) for c in ("hop", "strict")}
    assert all(r.exit_code == 0 for r in got.values()), got["hop"].output
    hop, strict = (json.loads(got[c].stdout) for c in ("hop", "strict"))
    for key in ("mean_speed", "e_d", "work", "cost_of_transport", "n_steps"):
        assert hop[key] == strict[key], key
    assert hop["landings_per_period"] == 0 and max(hop["flight_fraction"]) == 0
    maps = {}
    for c in ("hop", "strict"):
        res = invoke(
            "sweep", CAPSULE, "--vary", f"{M0}=1,2", "--contact", c, *FLAGS, "--out", str(tmp_path / f"{c}.nc")
        )
        assert res.exit_code == 0, res.output
        maps[c] = xr.load_dataset(tmp_path / f"{c}.nc")
    for name in maps["strict"].data_vars:
        np.testing.assert_array_equal(maps["hop"][name].values, maps["strict"][name].values, err_msg=name)


def worm(**v: Any) -> lj.Chain:
    """examples/worm.toml written out in Python, its spring stiffness, wave phase and backward static
    coefficient replaced by `v` (keyed by path)."""
    k = np.asarray(v.get("chain.k", 50.0), float)[..., None]  # per spring: one value for all three
    mu_s_bwd = np.asarray(v.get("friction.mu_s_bwd", 0.9), float)[..., None]  # per mass
    phi = np.asarray(v.get("waveform.phi", 0.785), float)
    law = lj.AnisotropicCoulomb(0.5, mu_s_bwd, 0.3, 0.7)
    return lj.Chain(masses=[1.0] * 4, k=k, d=0.0, lbar=3.0, c=0.01, waveforms=lj.TravellingWave(0.1, 2.0, phi),
                    friction=law, actuator=lj.RestLength(), check=False)  # fmt: skip


def test_vary_sweeps_a_chain_file_as_lj_sweep_does_bit_for_bit(tmp_path):
    k, phi = np.array([20.0, 50.0, 80.0]), np.array([0.0, 0.785])
    out = tmp_path / "worm.nc"
    args = ["--vary", "chain.k=20,50,80", "--vary", "waveform.phi=0,0.785", "--vary", "friction.mu_s_bwd=0.8"]
    res = invoke("sweep", str(EXAMPLES / "worm.toml"), *args, *FLAGS, "--out", str(out))
    assert res.exit_code == 0, res.output
    ds = xr.load_dataset(out)
    expected = lj.sweep({"chain.k": k, "waveform.phi": phi}, mechanism=worm, fixed={"friction.mu_s_bwd": 0.8}, **RUN)
    assert ds.mean_speed.dims == ("chain.k", "waveform.phi")
    assert_same(ds, expected)
    speed = ds.mean_speed.values
    assert (ds.status.values == lj.Status.OK).all() and np.ptp(speed[:, 0]) > 1e-3 and np.ptp(speed[0]) > 1e-3
    res = invoke("sweep", str(EXAMPLES / "worm.toml"), "--a", "0.1", *args, "--out", str(tmp_path / "x.nc"))
    assert res.exit_code == 2 and res.output.startswith("Error: --a: ") and "is swept with --vary" in res.output
