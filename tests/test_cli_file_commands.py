"""Every command that runs a mechanism takes a mechanism file: `measure`, `simulate`, `gait`, `optimize`, `sweep`
and `animate` give what the library gives on the loaded file, refuse mechanism options beside
it, and end a broken file with one line `Error: FILE, line N: [table] field: ...`, exit code 2.

The long computations (optimisers, sweeps) are replaced by stand-ins that record what they receive: what
is tested is that the file's mechanism reaches the library unchanged; the library is tested elsewhere.
"""

import json
from pathlib import Path

import equinox as eqx
import locomotion_jax as lj
import numpy as np
import pytest
from cli_helpers import invoke
from test_cli_files import assert_record_equals


pytestmark = pytest.mark.usefixtures("isolate_xla_flags")
EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
WORM, PAPER = str(EXAMPLES / "worm.toml"), str(EXAMPLES / "paper.toml")


class Captured(ValueError):
    """Raised by a stand-in once it has recorded its arguments (the command then exits 2)."""


def capture(monkeypatch, module, name: str) -> dict:
    seen: dict = {}

    def stand_in(*args, **kwargs):
        seen.update(args=args, kwargs=kwargs)
        raise Captured("captured")

    monkeypatch.setattr(module, name, stand_in)
    return seen


def test_measure_file_equals_the_library():
    res = invoke("measure", WORM, "--z", "1", "--horizon", "40", "--window", "10", "--dt", "0.02", "--json")
    assert res.exit_code == 0, res.output
    record = json.loads(res.stdout)
    m = lj.measure(lj.load_mechanism(WORM), z=1.0, horizon=40.0, window=10.0, dynamics=lj.Exact(dt=0.02))
    assert_record_equals(record, m)
    assert record["kind"] == "chain" and record["mechanism"] == WORM


def test_gait_file_equals_the_library():
    res = invoke("gait", PAPER, "--periods", "1", "--transient", "5", "--dt", "0.02", "--json")
    assert res.exit_code == 0, res.output
    record = json.loads(res.stdout)
    g = lj.steady_gait(lj.load_mechanism(PAPER), periods=1, transient=5, dynamics=lj.Exact(dt=0.02))
    assert record["mean_speed"] == float(g.mean_speed) and record["status"] == int(g.status)
    assert record["params"] == {n: float(v) for n, v in lj.Params().as_dict().items()}
    assert record["mechanism"] == PAPER


def test_optimize_chain_file_passes_the_files_chain(monkeypatch):
    seen = capture(monkeypatch, lj, "optimise")
    res = invoke("optimize", WORM, "--v-min", "0.1")
    assert res.exit_code == 2 and "captured" in res.output, res.output
    chain, v_min, a_max = seen["args"]
    assert bool(eqx.tree_equal(chain, lj.load_mechanism(WORM)))
    assert (v_min, a_max) == (0.1, 0.1)  # --a-max: the file's travelling wave's amplitude
    assert seen["kwargs"]["harmonics"] == 3 and seen["kwargs"]["direction"] == 1


def test_optimize_paper_file_passes_the_files_params(monkeypatch):
    from locomotion_jax.optimisation import _pareto

    seen = capture(monkeypatch, _pareto, "sinusoid_sweep")
    res = invoke("optimize", PAPER, "--v-min", "0.02")
    assert res.exit_code == 2 and "captured" in res.output, res.output
    params, a_max = seen["args"]
    assert params.as_dict() == lj.Params().as_dict() and a_max == 0.05


def test_optimize_needs_a_max_without_a_file():
    res = invoke("optimize", "--v-min", "0.02")
    assert res.exit_code == 2 and "--a-max is required" in res.output, res.output


def test_sweep_file_fixes_the_files_values(monkeypatch, tmp_path):
    seen = capture(monkeypatch, lj, "sweep")
    text = Path(PAPER).read_text().replace("a = 0.05", "a = 0.07")
    path = tmp_path / "paper.toml"
    path.write_text(text)
    res = invoke("sweep", str(path), "--omega", "1,2", "--out", str(tmp_path / "m.nc"))
    assert res.exit_code == 2 and "captured" in res.output, res.output
    (axes,) = seen["args"]
    assert list(axes) == ["omega"] and seen["kwargs"]["fixed"]["a"] == 0.07 and "omega" not in seen["kwargs"]["fixed"]


@pytest.mark.parametrize("order", [("--phi", "--omega"), ("--omega", "--phi")])
def test_chain_sweep_keeps_the_order_given(monkeypatch, tmp_path, order):
    seen = capture(monkeypatch, lj, "sweep")
    values = {"--phi": "0,0.5", "--omega": "2,3"}
    args = [a for o in order for a in (o, values[o])]
    res = invoke("chain-sweep", WORM, *args, "--out", str(tmp_path / "w.nc"))
    assert res.exit_code == 2 and "captured" in res.output, res.output
    (axes,) = seen["args"]
    assert list(axes) == [o[2:] for o in order]
    assert seen["kwargs"]["fixed"] == {"a": 0.1}  # from the file's travelling wave
    chain = seen["kwargs"]["mechanism"](a=0.1, omega=2.0, phi=0.785)
    assert bool(eqx.tree_equal(chain, lj.load_mechanism(WORM)))
    res = invoke("chain-sweep", "--masses", "1,1,1", *args, "--out", str(tmp_path / "w.nc"))
    assert list(seen["args"][0]) == [o[2:] for o in order]


@pytest.mark.parametrize(
    "command",
    [
        ["simulate"],
        ["gait"],
        ["optimize", "--v-min", "0.1"],
        ["sweep", "--omega", "1,2", "--out", "m.nc"],
        ["animate"],
        ["measure"],
    ],  # fmt: skip
    ids=lambda c: c[0],
)
def test_broken_file_is_one_line_naming_line_and_field(tmp_path, command):
    path = tmp_path / "robot.toml"
    path.write_text('kind = "chain"\n[chain]\nmasses = [1.0, "x"]\n')
    res = invoke(command[0], str(path), *command[1:])
    assert res.exit_code == 2 and "Traceback" not in res.output
    assert res.output.strip().count("\n") == 0, res.output
    assert res.output.startswith(f"Error: {path}, line 3: [chain] masses: expected"), res.output


@pytest.mark.parametrize(
    "args, option",
    [
        (["simulate", PAPER, "--a", "0.1"], "--a"),
        (["gait", PAPER, "--d", "0.1"], "--d"),
        (["optimize", WORM, "--v-min", "0.1", "--k", "3"], "--k"),
        (["animate", PAPER, "--mhat", "0.4"], "--mhat"),
        (["sweep", WORM, "--masses", "1,1", "--phi", "0,1", "--out", "m.nc"], "--masses"),
        (["measure", WORM, "--phi", "1"], "--phi"),
    ],  # fmt: skip
    ids=lambda a: a[0] if isinstance(a, list) else a,
)
def test_mechanism_options_beside_a_file_are_refused(args, option):
    res = invoke(*args)
    assert res.exit_code == 2 and res.output.startswith(f"Error: {option}: the mechanism comes from"), res.output


def test_animate_draws_a_chain_file_and_sweep_sends_the_other_kind_to_its_command(tmp_path):
    out = tmp_path / "worm.gif"
    res = invoke("animate", WORM, "--t-from", "3", "--t-end", "6", "--frames", "4", "--dt", "0.05", "--out", str(out))
    assert res.exit_code == 0 and "(4 frames, t = 3..6); body 0 stuck in" in res.output and out.exists(), res.output
    res = invoke("sweep", PAPER, "--phi", "0,1", "--out", "m.nc")
    assert res.exit_code == 2 and f"Error: --phi: the mechanism comes from {PAPER}" in res.output


def test_chain_commands_default_to_flat_springs(monkeypatch, tmp_path):
    # d = 0 by default, as every worm of the README (Chain's own default stays the paper's 0.5).
    seen = capture(monkeypatch, lj, "sweep")
    invoke("chain-sweep", "--masses", "1,1,1", "--phi", "0,1", "--out", str(tmp_path / "w.nc"))
    chain = seen["kwargs"]["mechanism"](a=0.05, omega=2.0, phi=0.0)
    np.testing.assert_array_equal(np.asarray(chain.d), 0.0)
