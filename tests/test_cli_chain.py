"""`locomotion-jax simulate`, `gait` and `sweep` of a chain, through the deprecated `chain-*` aliases (short runs).

Each command's output equals the library call it wraps, made here with the same shapes (so the
compilation is shared)."""

import json
import os

import locomotion_jax as lj
import numpy as np
import pytest
import xarray as xr
from cli_helpers import invoke


pytestmark = pytest.mark.usefixtures("isolate_xla_flags")
MECH = ["--masses", "1,1,1", "--d", "0", "--friction", "anisotropic", "--mu-s-bwd", "0.9", "--mu-k-bwd", "0.7"]
WAVE = ["--a", "0.08", "--omega", "3", "--phi", "2.0944"]


def worm(a=0.08, omega=3.0, phi=2.0944) -> lj.Chain:
    return lj.Chain(masses=[1.0] * 3, d=0.0, waveforms=lj.TravellingWave(a, omega, phi),
                    friction=lj.AnisotropicCoulomb(0.7, 0.9, 0.5, 0.7))  # fmt: skip


def test_chain_simulate_json_and_plot(tmp_path):
    res = invoke("chain-simulate", *MECH, *WAVE, "--t-end", "4", "--saves", "9", "--dt", "0.02", "--out",
                 str(tmp_path), "--json")  # fmt: skip
    assert res.exit_code == 0, res.output
    record = json.loads(res.stdout)
    traj = lj.simulate(worm(), 4.0, np.linspace(0, 4, 9), dynamics=lj.Exact(dt=0.02))
    np.testing.assert_allclose(record["x"], np.asarray(traj.x), rtol=1e-12)
    np.testing.assert_allclose(record["X"], np.asarray(traj.X), rtol=1e-12)
    assert np.asarray(record["stuck"]).shape == (9, 3) and np.asarray(record["l0"]).shape == (9, 2)
    assert record["status_name"] == "OK" and record["t_liftoff"] is None and record["n_masses"] == 3
    assert record["plot"] is not None and os.path.exists(record["plot"])
    text = invoke("chain-simulate", *MECH, *WAVE, "--t-end", "4", "--saves", "9", "--dt", "0.02")
    assert text.exit_code == 0 and "mean_velocity" in text.stdout
    bad = invoke("chain-simulate", *MECH, "--t-end", "-1")
    assert bad.exit_code == 2 and "Error: --t-end must be" in bad.output


@pytest.mark.slow  # a compilation of the chain's gait solver of its own (steady_gait is tested in test_chain_gait.py)
def test_chain_gait_json_equals_steady_gait():
    res = invoke("chain-gait", *MECH, *WAVE, "--transient", "10", "--dt", "0.02", "--start", "relaxed", "--json")
    assert res.exit_code == 0, res.output
    record = json.loads(res.stdout)
    g = lj.steady_gait(worm(), transient=10, dynamics=lj.Exact(dt=0.02), start="relaxed")
    assert record["status_name"] == "CONVERGED"
    assert record["mean_speed"] == pytest.approx(float(g.mean_speed), rel=1e-12)
    assert record["cost_of_transport"] == pytest.approx(float(g.cost_of_transport), rel=1e-12)
    assert record["stick_fraction"] == pytest.approx(np.asarray(g.stick_fraction).tolist(), rel=1e-12)
    assert len(record["multipliers"]) == 5 and len(record["multipliers"][0]) == 2


def test_chain_gait_bad_input():
    bad = invoke("chain-gait", *MECH, "--periods", "0")
    assert bad.exit_code == 2 and "Error: --periods" in bad.output


@pytest.mark.parametrize(
    "args, mentions",
    [
        # --omega inf reported CONVERGED with period 0; 0 has no period either
        (["chain-gait", "--masses", "1,1,1", "--omega", "inf", "--json"], "--omega must be a finite number > 0"),
        (["chain-gait", "--masses", "1,1,1", "--omega", "0", "--json"], "--omega must be a finite number > 0"),
        (["chain", "--masses", "1,1,1", "--phi", "nan"], "'phi' of TravellingWave: got phi=nan"),
        (["chain", "--masses", "1,1,1", "--mu-k", "inf"], "'mu_k' of mass 0: got mu_k=inf"),
        # an unusable output path: FileExistsError from deep inside, once the map was computed
        (["chain-sweep", "--masses", "1,1,1", "--omega", "1,2", "--out", "{tmp}/blocker/c.nc"], "Cannot write"),
        (["chain-sweep", "--masses", "1,1,1", "--omega", "1:inf:2", "--out", "{tmp}/c.nc"], "--omega"),
    ],
)
def test_chain_commands_refuse_bad_input(tmp_path, args, mentions):
    (tmp_path / "blocker").write_text("a file where a directory is needed")
    res = invoke(*(a.replace("{tmp}", str(tmp_path)) for a in args))
    assert res.exit_code == 2, res.output
    assert mentions in res.output and "Traceback" not in res.output
    assert res.exception is None or isinstance(res.exception, SystemExit)
    assert not (tmp_path / "c.nc").exists()


def test_chain_sweep_writes_the_map(tmp_path):
    out = tmp_path / "worm.nc"
    meas = ["--z", "0.5", "--horizon", "20", "--t-start", "10", "--dt", "0.02", "--no-progress"]
    res = invoke("chain-sweep", *MECH, "--a", "0.08", "--omega", "2,3", "--phi", "-1,2.0944", *meas, "--out", str(out))
    assert res.exit_code == 0, res.output
    assert "omega[2] x phi[2]" in res.stdout and "fastest" in res.stdout
    ds = xr.open_dataset(out)
    assert ds.mean_speed.dims == ("omega", "phi") and ds.stick_fraction.dims == ("omega", "phi", "mass")
    # The same map by `measure` on the batch of the four chains (grid order).
    batch = lj.Chain.stack([worm(0.08, w, p) for w in (2.0, 3.0) for p in (-1.0, 2.0944)])
    m = lj.measure(batch, 0.5, horizon=20.0, t_start=10.0, dynamics=lj.Exact(dt=0.02))
    np.testing.assert_allclose(ds.mean_speed.values.ravel(), np.asarray(m.mean_speed), rtol=1e-12)
    bad = invoke("chain-sweep", *MECH, "--out", str(tmp_path / "x.nc"))
    assert bad.exit_code == 2 and "Error: nothing to sweep" in bad.output
    bad = invoke("chain-sweep", *MECH, "--phi", "0,1", "--out", str(tmp_path / "x.zarr"))
    assert bad.exit_code == 2 and "NetCDF" in bad.output
