"""One CLI over every kind of mechanism: each command on the paper's model (its options), a 3-mass chain
(`--masses`) and a mechanism file (`examples/worm.toml`) prints what the library's front end gives on
the same mechanism; a command that does not run a kind says so by name; the deprecated `chain-*`
aliases run the new commands. Short horizons and few saves: the compilations are small.

The `chain-*` aliases' own outputs (`chain-simulate`, `chain-gait`, `chain-sweep`) equal the library
calls they wrap, made here with the same shapes (so the compilation is shared)."""

import json
import os
from pathlib import Path

import locomotion_jax as lj
import numpy as np
import pytest
import xarray as xr
from cli_helpers import invoke


pytestmark = pytest.mark.usefixtures("isolate_xla_flags")
WORM = str(Path(__file__).resolve().parents[1] / "examples" / "worm.toml")
CHAIN = ["--masses", "1,1,1", "--d", "0", "--friction", "anisotropic", "--mu-s-bwd", "0.9", "--mu-k-bwd", "0.7",
         "--a", "0.08", "--omega", "3", "--phi", "2.0944"]  # fmt: skip
KINDS = {"paper": ["--omega", "2"], "chain": CHAIN, "worm": [WORM]}
FAST = ["--z", "0.3", "--horizon", "30", "--window", "5", "--dt", "0.02"]


def mechanism(kind: str):
    """The mechanism of `KINDS[kind]`, built here in Python."""
    if kind == "paper":
        return lj.Params(omega=2.0)
    if kind == "chain":
        return lj.Chain(masses=[1.0] * 3, d=0.0, waveforms=lj.TravellingWave(0.08, 3.0, 2.0944),
                        friction=lj.AnisotropicCoulomb(0.7, 0.9, 0.5, 0.7))  # fmt: skip
    return lj.load_mechanism(WORM)


@pytest.mark.parametrize("kind", list(KINDS))
def test_measure_equals_lj_measure(kind):
    res = invoke("measure", *KINDS[kind], *FAST, "--json")
    assert res.exit_code == 0, res.output
    record = json.loads(res.stdout)
    m = lj.measure(mechanism(kind), 0.3, horizon=30.0, window=5.0, dynamics=lj.Exact(dt=0.02))
    for name, value in m.to_numpy().items():
        expected = np.asarray(value, dtype=float)
        expected = np.where(np.isfinite(expected), expected, np.nan)  # non-finite numbers are null in JSON
        got = np.asarray([np.nan if v is None else v for v in np.ravel(record[name])], dtype=float)
        np.testing.assert_array_equal(got, expected.ravel(), err_msg=name)
    assert record["kind"] == ("chain" if kind == "worm" else kind)
    assert record["status_name"] == lj.Status(int(m.status)).name


@pytest.mark.parametrize("kind", list(KINDS))
def test_simulate_equals_lj_simulate(kind):
    res = invoke("simulate", *KINDS[kind], "--t-end", "2", "--saves", "5", "--dt", "0.02", "--json")
    assert res.exit_code == 0, res.output
    record = json.loads(res.stdout)
    traj = lj.simulate(mechanism(kind), 2.0, np.linspace(0.0, 2.0, 5), dynamics=lj.Exact(dt=0.02))
    np.testing.assert_array_equal(record["X"], np.asarray(traj.X))
    np.testing.assert_array_equal(record["t"], np.asarray(traj.t))
    assert record["displacement"] == float(traj.X[-1] - traj.X[0]) and record["n_switch"] == int(traj.n_switch)
    positions = np.asarray(record["x"]) if kind != "paper" else np.stack([record["x1"], record["x2"]], -1)
    assert positions.shape == (5, 2 if kind == "paper" else 3 if kind == "chain" else 4)


@pytest.mark.slow  # the 4-mass chain's gait solver: a compilation of its own (about 2.5 min on 2 cores)
def test_gait_of_the_worm_file_equals_lj_steady_gait():
    res = invoke("gait", WORM, "--periods", "1", "--transient", "5", "--dt", "0.02", "--json")
    assert res.exit_code == 0, res.output
    record = json.loads(res.stdout)
    worm = lj.load_mechanism(WORM)
    assert isinstance(worm, lj.Chain)
    g = lj.steady_gait(worm, periods=1, transient=5, dynamics=lj.Exact(dt=0.02))
    assert record["status_name"] == lj.GaitStatus(int(g.status)).name and record["kind"] == "chain"
    assert record["mean_speed"] == float(g.mean_speed) and record["state"] == np.asarray(g.state).tolist()
    assert record["stick_fraction"] == np.asarray(g.stick_fraction).tolist()


def test_continue_of_a_chain_equals_lj_continuation(tmp_path):
    """`continue` of a chain: the points and events of `lj.continuation`, the state and the stick
    fractions as lists per point, the chain's description in the record."""
    args = ["continue", *CHAIN, "--parameter", "omega", "--stop", "3.3", "--periods", "1", "--max-points", "3",
            "--dt", "0.02", "--json", "--out", str(tmp_path / "branch.json")]  # fmt: skip
    res = invoke(*args)
    assert res.exit_code == 0, res.output
    record = json.loads(res.stdout)
    assert record == json.loads((tmp_path / "branch.json").read_text())
    b = lj.continuation(mechanism("chain"), "omega", 3.3, periods=1, max_points=3, max_step=0.04, step=0.01,
                        dynamics=lj.Exact(dt=0.02))  # fmt: skip
    n = int(b.n_points)
    assert record["kind"] == "chain" and record["n_points"] == n >= 2 and record["lam_start"] == 3.0
    assert record["k"] == int(b.k) == 1 and record["mechanism_k"] == 50.0  # the gait period; the springs'
    assert record["status"] == int(b.status)
    points = record["points"]
    assert points["lam"] == np.asarray(b.lam)[:n].tolist()
    assert points["mean_speed"] == np.asarray(b.mean_speed)[:n].tolist()
    assert points["state"] == np.asarray(b.state)[:n].tolist() and len(points["stick_fraction"][0]) == 3
    assert "u" not in points and all("state" in e and "u" not in e for e in record["events"])
    text = invoke(*args[:-3])
    assert text.exit_code == 0 and f"{n} points" in text.stdout


def test_animate_draws_a_chain_at_its_simulated_positions(tmp_path):
    """`animate` of a chain writes one GIF frame per saved state of `lj.simulate`, and counts each
    mass's stuck frames; `lj.animate` of the chain draws mass i centred on x_i, a spring between
    neighbours, an anchor under a stuck mass; a batch needs its index."""
    from PIL import Image

    out = tmp_path / "chain.gif"
    res = invoke("animate", *CHAIN, "--t-from", "4", "--t-end", "8", "--frames", "7", "--dt", "0.02", "--out", str(out))
    assert res.exit_code == 0, res.output
    chain = mechanism("chain")
    assert isinstance(chain, lj.Chain)
    traj = lj.simulate(chain, 8.0, np.linspace(4.0, 8.0, 7), dynamics=lj.Exact(dt=0.02))
    stuck = np.asarray(traj.stuck).sum(axis=0)
    counts = ", ".join(f"body {i} stuck in {stuck[i]}" for i in range(3))
    assert f"(7 frames, t = 4..8); {counts} frames" in res.stdout and getattr(Image.open(out), "n_frames") == 7
    anim = lj.animate(traj, chain, trace=False)
    fig = anim._fig  # pyright: ignore[reportAttributeAccessIssue]
    assert len([line for line in fig.axes[0].lines if str(line.get_gid()).startswith("spring")]) == 2
    x, held = np.asarray(traj.x), np.asarray(traj.stuck)
    for k in range(7):
        anim._func(k)  # pyright: ignore[reportAttributeAccessIssue]
        for i in range(3):
            (r,) = [a for a in fig.axes[0].patches if a.get_gid() == f"body{i}"]
            assert abs(r.get_x() + r.get_width() / 2 - float(x[k, i])) < 1e-12
            (anchor,) = [a for a in fig.axes[0].lines if a.get_gid() == f"anchor{i}"]
            assert len(anchor.get_xdata()) == int(held[k, i])
    batch = lj.Chain.stack([chain, chain])
    both = lj.simulate(batch, 8.0, np.linspace(4.0, 8.0, 7), dynamics=lj.Exact(dt=0.02))
    with pytest.raises(ValueError, match="must pick one of the batch shape"):
        lj.animate(both, batch)
    one = lj.animate(both, batch, index=(1,), t_range=(5.0, 8.0), trace=False)
    assert one._fig is not None  # pyright: ignore[reportAttributeAccessIssue]


def test_sweep_of_a_chain_equals_lj_measure_of_the_batch(tmp_path):
    out = tmp_path / "w.nc"
    res = invoke("sweep", *CHAIN[:-6], "--a", "0.08", "--phi", "-1,2.0944", *FAST, "--no-progress", "--out", str(out))
    assert res.exit_code == 0, res.output
    assert "phi[2]" in res.stdout
    import xarray as xr

    ds = xr.open_dataset(out)
    law = lj.AnisotropicCoulomb(0.7, 0.9, 0.5, 0.7)
    chains = [lj.Chain(masses=[1.0] * 3, d=0.0, waveforms=lj.TravellingWave(0.08, 2.0, p), friction=law)
              for p in (-1.0, 2.0944)]  # fmt: skip
    batch = lj.Chain.stack(chains)
    m = lj.measure(batch, 0.3, horizon=30.0, window=5.0, dynamics=lj.Exact(dt=0.02))
    np.testing.assert_array_equal(ds.mean_speed.values, np.asarray(m.mean_speed))


@pytest.mark.parametrize(
    "args, message",
    [
        (["measure", "--phi", "1"], "--phi: these options describe a chain: give --masses."),
        (["measure", "--masses", "1,1", "--mhat", "0.3"], "--mhat: these options describe the paper's model"),
        (["measure", "--k", "50,60"], "--k must be a number (the paper's model takes one value)"),
        (["sweep", "--masses", "1,1,1", "--k", "1:2:3", "--out", "x.nc"], "--k must be a number or a comma"),
    ],  # fmt: skip
)
def test_an_option_of_the_other_kind_is_named(args, message):
    res = invoke(*args)
    assert res.exit_code == 2 and "Traceback" not in res.output
    assert res.output.startswith(f"Error: {message}"), res.output


@pytest.mark.parametrize(
    "old, new, args",
    [
        ("chain", "measure", [*CHAIN, *FAST, "--json"]),
        ("chain-simulate", "simulate", [*CHAIN, "--t-end", "1", "--saves", "3", "--dt", "0.02", "--json"]),
        ("chain-gait", "gait", [*CHAIN, "--periods", "0"]),
        ("chain-sweep", "sweep", [*CHAIN, "--out", "x.nc"]),
        ("chain-optimize", "optimize", [*CHAIN[:-6], "--v-min", "0", "--a-max", "0.05"]),
    ],
)
def test_every_alias_notes_its_deprecation_and_runs_the_new_command(old, new, args):
    res, expected = invoke(old, *args), invoke(new, *args)
    assert res.exit_code == expected.exit_code
    assert res.stderr.splitlines()[0] == f"Note: `{old}` is deprecated and will be removed; use `locomotion-jax {new}`."
    assert res.stdout == expected.stdout and res.stderr.splitlines()[1:] == expected.stderr.splitlines()


def test_optimize_of_a_chain_passes_the_options_chain(monkeypatch):
    """`optimize --masses ...` hands `lj.optimise` the chain of the options (the optimiser is tested in
    tests/test_optimise.py) with the screen's options."""
    import equinox as eqx

    seen: dict = {}

    def stand_in(*args, **kwargs):
        seen.update(args=args, kwargs=kwargs)
        raise ValueError("captured")

    monkeypatch.setattr(lj, "optimise", stand_in)
    res = invoke("optimize", *CHAIN[:-6], "--v-min", "0.1", "--a-max", "0.05", "--phases", "3", "--transient", "7")
    assert res.exit_code == 2 and "captured" in res.output, res.output
    chain, v_min, a_max = seen["args"]
    expected = lj.Chain(masses=[1.0] * 3, d=0.0, friction=lj.AnisotropicCoulomb(0.7, 0.9, 0.5, 0.7))
    assert bool(eqx.tree_equal(chain, expected)) and (v_min, a_max) == (0.1, 0.05)
    settings = seen["kwargs"]["settings"]
    assert (settings.phases, settings.transient, seen["kwargs"]["harmonics"]) == (3, 7, 3)
    assert seen["kwargs"]["method"] == "exact" and settings.smoothed == lj.OptimiseSettings()
    res = invoke("optimize", *CHAIN[:-6], "--v-min", "0.1", "--a-max", "0.05", "--method", "smoothed", "--outer", "2",
                 "--eps", "1e-2,5e-3")  # fmt: skip
    assert res.exit_code == 2 and "captured" in res.output, res.output
    smoothed = seen["kwargs"]["settings"].smoothed
    assert seen["kwargs"]["method"] == "smoothed" and (smoothed.outer, smoothed.eps_schedule) == (2, (1e-2, 5e-3))
    res = invoke("optimize", *CHAIN[:-6], "--v-min", "0.1")
    assert res.exit_code == 2 and "--a-max is required" in res.output


# The deprecated chain-* aliases, output against the library.

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


@pytest.mark.slow  # a compilation of the chain's gait solver of its own (steady_gait is tested in test_gait.py)
def test_chain_gait_json_equals_steady_gait():
    res = invoke("chain-gait", *MECH, *WAVE, "--transient", "10", "--dt", "0.02", "--start", "relaxed", "--json")
    assert res.exit_code == 0, res.output
    record = json.loads(res.stdout)
    g = lj.steady_gait(worm(), transient=10, dynamics=lj.Exact(dt=0.02), start="relaxed")
    assert record["status_name"] == "CONVERGED" and record["k"] == int(g.k) and record["mechanism_k"] == 50.0
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
    store = invoke("chain-sweep", *MECH, "--a", "0.08", "--omega", "2,3", "--phi", "-1,2.0944", *meas, "--out",
                   str(tmp_path / "worm.zarr"))  # fmt: skip
    assert store.exit_code == 0, store.output
    np.testing.assert_array_equal(xr.open_zarr(tmp_path / "worm.zarr").mean_speed.values, ds.mean_speed.values)
    bad = invoke("chain-sweep", *MECH, "--phi", "0,1", "--out", str(tmp_path / "x.txt"))
    assert bad.exit_code == 2 and "NetCDF file (.nc)" in bad.output and "Zarr store (.zarr)" in bad.output
