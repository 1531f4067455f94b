"""The `locomotion-jax` command line (typer's CliRunner; short horizons to stay fast)."""

import json
import os
import sys
import types
from pathlib import Path

import jax
import locomotion_jax as lj
import numpy as np
import pytest
import typer
import xarray as xr
from cli_helpers import invoke, runner
from locomotion_jax import _json
from locomotion_jax.cli import _main as _cli
from locomotion_jax.maps import _sweep


FAST = ["--z", "0.3", "--horizon", "30", "--window", "5", "--dt", "0.02"]
pytestmark = pytest.mark.usefixtures("isolate_xla_flags")


def _strict_json(text: str):
    """Parse one JSON object, refusing the non-standard NaN/Infinity literals."""

    def refuse(name):
        raise AssertionError(f"non-standard JSON literal {name}")

    return json.loads(text, parse_constant=refuse)


def _text_value(stdout: str, name: str) -> str:
    """The value printed on the `  name  value` line of `measure`'s text report."""
    (line,) = [ln for ln in stdout.splitlines() if ln.split()[:1] == [name]]
    return line.split()[1]


def test_measure_json_matches_measure():
    res = invoke("measure", "--omega", "2", "--a", "0.05", "--json", *FAST)
    assert res.exit_code == 0, res.output
    record = _strict_json(res.stdout)  # stdout is exactly one JSON object
    m = lj.measure(lj.Params(omega=2.0, a=0.05), 0.3, horizon=30.0, window=5.0, dynamics=lj.Exact(dt=0.02))
    assert record["tau_z"] == pytest.approx(float(m.tau_z), rel=1e-12)
    assert record["status_name"] == "OK" and record["regime_name"] == lj.Regime(int(m.regime)).name
    assert not np.isfinite(float(m.t_liftoff))  # inf (no lift-off) is encoded as null, like NaN
    assert record["t_liftoff"] is None and record["liftoff"] is False
    assert record["params"]["omega"] == 2.0 and record["contact"] == "strict" and record["kind"] == "paper"


def test_simulate_json_matches_simulate_and_plots(tmp_path):
    res = invoke("simulate", "--omega", "2", "--t-end", "5", "--saves", "6", "--dt", "0.02", "--out", str(tmp_path),
                 "--json")  # fmt: skip
    assert res.exit_code == 0, res.output
    record = _strict_json(res.stdout)
    traj = lj.simulate(lj.Params(omega=2.0), 5.0, np.linspace(0, 5, 6), dynamics=lj.Exact(dt=0.02))
    for name in ("x1", "x2", "v1", "X", "mode"):
        np.testing.assert_allclose(record[name], np.asarray(getattr(traj, name)), rtol=1e-12, atol=0)
    assert record["displacement"] == pytest.approx(float(traj.X[-1] - traj.X[0]), rel=1e-12)
    assert record["status_name"] == "OK" and record["t_liftoff"] is None and record["params"]["omega"] == 2.0
    png = tmp_path / record["plot"].split("/")[-1]
    assert png.exists() and png.read_bytes()[:4] == b"\x89PNG"


def test_simulate_writes_nothing_without_out(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for extra in ([], ["--json"]):
        res = invoke("simulate", "--omega", "2", "--t-end", "2", "--saves", "3", "--dt", "0.02", *extra)
        assert res.exit_code == 0, res.output
        assert "plot:" not in res.stdout
    assert _strict_json(res.stdout)["plot"] is None
    assert list(tmp_path.iterdir()) == []


def test_simulate_text_and_not_reached_encoding():
    # omega = 0.1: far too slow to travel z in the horizon -> tau_z and e_z are inf.
    res = invoke("measure", "--omega", "0.1", *FAST)
    assert res.exit_code == 0, res.output
    assert _text_value(res.stdout, "tau_z") == "inf" and _text_value(res.stdout, "e_z") == "inf"
    assert _text_value(res.stdout, "reached") == "False"
    res = invoke("measure", "--omega", "2", *FAST)  # reached: a finite tau_z in the same place
    assert float(_text_value(res.stdout, "tau_z")) > 0 and _text_value(res.stdout, "reached") == "True"
    res = invoke("measure", "--omega", "0.1", "--json", *FAST)
    record = _strict_json(res.stdout)
    assert record["tau_z"] is None and record["e_z"] is None and record["reached"] is False


def test_json_encoding_of_non_finite_numbers():
    # One encoder for every JSON output of the CLI (simulate, optimize): NaN and +-inf are null.
    values = {"nan": np.nan, "inf": np.float64(np.inf), "-inf": -np.inf, "x": np.float32(1.5), "n": np.int32(3)}
    values["nested"] = [np.array([1.0, np.inf]), {"b": np.bool_(True)}]
    assert _strict_json(_json.dumps(values)) == {
        "nan": None,
        "inf": None,
        "-inf": None,
        "x": 1.5,
        "n": 3,
        "nested": [[1.0, None], {"b": True}],
    }


def test_sweep_writes_and_reads_back(tmp_path):
    out = tmp_path / "maps" / "s.nc"
    args = [
        "sweep",
        "--omega",
        "2,6",
        "--a",
        "0.02:0.05:2",
        "--d",
        "0.5",
        "--chunk-size",
        "4",
        "--out",
        str(out),
        "--no-progress",
        "--order",
        "cost",
        *FAST,
    ]
    res = invoke(*args)
    assert res.exit_code == 0, res.output
    assert "omega[2] x a[2]" in res.stdout
    ds = xr.load_dataset(out, engine="h5netcdf")
    np.testing.assert_allclose(ds.a, [0.02, 0.05])
    assert ds.attrs["fixed_d"] == 0.5 and ds.attrs["dynamics_dt"] == 0.02 and ds.attrs["order"] == "cost"
    before = dict(_sweep.STATS)
    res = invoke(*args)  # a rerun reads the finished file back
    assert res.exit_code == 0, res.output
    assert dict(_sweep.STATS) == before


@pytest.mark.parametrize(
    "args, mentions",
    [
        (["sweep", "--omega", "1:25:0", "--out", "{tmp}/x.nc"], "--omega"),
        (["sweep", "--a", "0.01:5:3", "--out", "{tmp}/x.nc"], "'a'"),
        (["sweep", "--omega", "1:x:3", "--out", "{tmp}/x.nc"], "--omega"),
        (["sweep", "--foo", "1", "--out", "{tmp}/x.nc"], "--foo"),
        (["sweep", "--a", "0.05", "--out", "{tmp}/x.nc"], "nothing to sweep"),
        (["sweep", "--omega", "1:2:2", "--out", "{tmp}/blocker/x.nc"], "Cannot write"),
        (["sweep", "--omega", "1:2:2", "--order", "fastest", "--out", "{tmp}/x.nc"], "'fastest' is not one of"),
        (["simulate", "--mu-s", "0.3", "--no-plot"], "mu_s"),
        (["simulate", "--omega", "abc"], "--omega"),
        (["figures", "11"], "unknown figure '11'"),
        # --t-end was checked only with --out; 0 and nan ran with exit 0
        (["simulate", "--t-end", "0", "--no-plot"], "--t-end must be a finite number > 0"),
        (["simulate", "--t-end", "nan"], "--t-end must be a finite number > 0"),
        (["sweep", "--omega", "1:inf:3", "--out", "{tmp}/x.nc"], "--omega '1:inf:3': the ends of a range"),
        (["animate", "--fps", "inf"], "--fps and --dpi must be finite"),
        (["gait", "--omega", "0"], "--omega must be a finite number > 0"),
        # an unusable output path gave a traceback (an OSError, not a ValueError)
        (["animate", "--t-end", "1", "--dt", "0.05", "--out", "{tmp}/blocker/x.gif"], "--out {tmp}/blocker/x.gif"),
    ],
)
def test_argument_errors(tmp_path, args, mentions):
    (tmp_path / "blocker").write_text("a file where a directory is needed")
    before = dict(_sweep.STATS)
    res = invoke(*(a.replace("{tmp}", str(tmp_path)) for a in args))
    assert res.exit_code == 2, res.output
    assert mentions.replace("{tmp}", str(tmp_path)) in res.output
    assert "Traceback" not in res.output
    assert res.exception is None or isinstance(res.exception, SystemExit)
    assert dict(_sweep.STATS) == before


def test_os_errors_name_the_option(capsys):
    """Every command's OSError is one line naming the path option it concerns, exit code 2."""
    app = typer.Typer()

    @app.command()
    @_cli._friendly
    def write(out: Path = typer.Option(...)) -> None:
        raise PermissionError(13, "Permission denied", str(out / "inside.txt"))

    @app.command()
    def other() -> None:
        pass

    res = runner.invoke(app, ["write", "--out", "/somewhere/out"])
    assert res.exit_code == 2
    assert res.output.strip() == (
        "Error: --out /somewhere/out: cannot use it (Permission denied: /somewhere/out/inside.txt)."
    )


def test_main_prints_error_and_exits_2(capsys):
    with pytest.raises(SystemExit) as exc:
        _cli.main(["simulate", "--a", "-1", "--no-plot"])
    assert exc.value.code == 2
    assert "Error: Invalid parameter 'a'" in capsys.readouterr().err


def test_global_options_set_jax_config(monkeypatch):
    # Every command run before in this process set the CPU device count (the default, one per core).
    monkeypatch.setenv("XLA_FLAGS", "")
    try:
        res = invoke("--no-x64", "--cpu-devices", "3", "figures", "bad")
        assert res.exit_code == 2
        assert jax.config.read("jax_enable_x64") is False
        assert "--xla_force_host_platform_device_count=3" in os.environ["XLA_FLAGS"]
    finally:
        jax.config.update("jax_enable_x64", True)
    assert invoke("--cpu-devices", "-1", "figures").exit_code == 2


def test_figure_names():
    assert _cli.figure_names(None) == list(_cli.FIGURES)
    assert _cli.figure_names(["fig6", "4B", "figure12", "fig08", "04b"]) == ["6", "4b", "12", "8", "4b"]


def test_optimize_registered_when_module_exists(monkeypatch):
    fake = types.ModuleType("locomotion_jax.cli._optimise")

    def register(app: typer.Typer) -> None:
        @app.command()
        def optimize() -> None:
            typer.echo("optimising")

    setattr(fake, "register", register)
    monkeypatch.setitem(sys.modules, "locomotion_jax.cli._optimise", fake)
    app = typer.Typer()

    @app.command()
    def other() -> None:
        pass

    _cli._register_optional(app, ("locomotion_jax.cli._optimise", "locomotion_jax._no_such_plugin"))
    res = runner.invoke(app, ["optimize"])
    assert res.exit_code == 0 and "optimising" in res.output


def test_installed_plugins_are_registered():
    commands = {c.name or getattr(c.callback, "__name__", None) for c in _cli.app.registered_commands}
    assert {"simulate", "sweep", "figures"} <= commands
    for module, command in (("_optimise", "optimize"), ("_animate", "animate"), ("_commands", "measure")):
        if (Path(_cli.__file__).parent / f"{module}.py").exists():
            assert command in commands
    hidden = {c.name for c in _cli.app.registered_commands if c.hidden}
    assert hidden == {"chain", "chain-simulate", "chain-gait", "chain-sweep", "chain-optimize"}


def test_chain_json_matches_measure():
    """`chain`: per-mass lists parsed, the anisotropic law built, the result that of `measure`."""
    args = ["--masses", "1,1,1", "--d", "0", "--a", "0.08", "--omega", "3", "--phi", "2.0944", "--friction",
            "anisotropic", "--mu-s-bwd", "0.9", "--mu-k-bwd", "0.7", "--z", "1", "--horizon", "60",
            "--t-start", "30", "--dt", "0.02"]  # fmt: skip
    res = invoke("chain", *args, "--json")
    assert res.exit_code == 0, res.output
    record = _strict_json(res.stdout)
    mech = lj.Chain(masses=[1.0] * 3, d=0.0, waveforms=lj.TravellingWave(0.08, 3.0, 2.0944),
                    friction=lj.AnisotropicCoulomb(0.7, 0.9, 0.5, 0.7))  # fmt: skip
    m = lj.measure(mech, 1.0, horizon=60.0, t_start=30.0, dynamics=lj.Exact(dt=0.02))
    assert record["mean_speed"] == pytest.approx(float(m.mean_speed), rel=1e-12) and record["n_masses"] == 3
    assert record["stick_fraction"] == pytest.approx(np.asarray(m.stick_fraction).tolist(), rel=1e-12)
    assert record["status_name"] == "OK"
    text = invoke("chain", *args)
    assert text.exit_code == 0 and "stick_fraction" in text.stdout and "anisotropic friction" in text.stdout
    bad = invoke("chain", "--masses", "1,1,1", "--k", "50,-1")
    assert bad.exit_code == 2 and "'k'" in bad.output and "spring 1" in bad.output
    bad = invoke("chain", "--masses", "1,1", "--mu-s-bwd", "0.9")
    assert bad.exit_code == 2 and "--friction anisotropic" in bad.output
