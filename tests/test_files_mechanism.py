"""Mechanism files of `kind = "mechanism"` (SPEC §9, issue 26): `examples/capsule.toml` is the issue's capsule
and measures as the Python-built one (library and CLI, bit for bit); round trips of every link, waveform and
friction law; broken files of the new tables give one error naming the file, line, table and field."""

import json
import os
import re
import textwrap
from pathlib import Path
from typing import Any

import jax
import locomotion_jax as lj
import numpy as np
import pytest
from locomotion_jax.cli import _main as _cli
from locomotion_jax.cli._vary import builder
from locomotion_jax.model._files import tomllib
from typer.testing import CliRunner


EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
SHORT = ["--z", "1", "--horizon", "40", "--window", "10", "--t-start", "20", "--dt", "0.02"]
SETTINGS: dict[str, Any] = dict(z=1.0, horizon=40.0, window=10.0, t_start=20.0, dynamics=lj.Exact(dt=0.02))


def capsule() -> lj.Mechanism:
    """The issue's capsule, as examples/capsule.toml describes it."""
    return lj.Mechanism(
        masses=[1.0, 0.5], friction=[lj.AnisotropicCoulomb(0.5, 0.2, 0.4, 0.15), None], carried_by=[None, 0],
        links=[lj.Spring(0, 1, k=10.0, rest=0.0), lj.Force(0, 1, lj.Sinusoid(a=0.6, omega=3.0, lbar=0.0)),
               lj.ExternalForce(0, lj.Fourier([0.0, 0.1], [0.0, 0.0], 3.0, 0.0))],
        c=0.0, x0=[0.0, 0.0], v0=[0.0, 0.0],
    )  # fmt: skip


def assert_same(a, b) -> None:
    la, ta = jax.tree_util.tree_flatten(a)
    lb, tb = jax.tree_util.tree_flatten(b)
    assert ta == tb
    for x, y in zip(la, lb):
        assert np.shape(x) == np.shape(y) and np.asarray(x).dtype == np.asarray(y).dtype
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


@pytest.fixture(autouse=True)
def _isolate_xla_flags(monkeypatch):
    jax.devices()
    monkeypatch.setenv("XLA_FLAGS", os.environ.get("XLA_FLAGS", ""))


def test_capsule_example_is_the_issues_capsule_and_the_cli_measures_it_bit_for_bit():
    loaded = lj.load_mechanism(EXAMPLES / "capsule.toml")
    assert_same(loaded, capsule())
    m = lj.measure(capsule(), **SETTINGS)
    assert int(m.status) == int(lj.Status.OK) and np.isfinite(float(m.mean_speed))
    res = CliRunner().invoke(_cli.app, ["measure", str(EXAMPLES / "capsule.toml"), *SHORT, "--json"])
    assert res.exit_code == 0, res.output
    record = json.loads(res.stdout)
    for name, value in m.to_numpy().items():
        expected = np.asarray(value)
        got = np.asarray(record[name], dtype=float)
        finite = np.isfinite(expected)
        np.testing.assert_array_equal(got[finite], expected[finite], err_msg=name)  # identical, not close
        assert np.isnan(got[~finite]).all(), name
    assert record["kind"] == "mechanism" and record["status_name"] == "OK" and len(record["stick_fraction"]) == 2
    text = CliRunner().invoke(_cli.app, ["measure", str(EXAMPLES / "capsule.toml"), *SHORT])
    assert text.exit_code == 0 and "mechanism of 2 bodies (1 carried), 3 links" in text.stdout


ROUND_TRIPS = {
    "capsule": capsule(),
    "oscillator": lj.Mechanism(masses=[1.0], friction=lj.Coulomb(1.0, 1.0), links=[lj.Spring(0, lj.WALL, k=1.0)],
                               x0=[12.0], v0=[6.0]),
    "every_element": lj.Mechanism(
        masses=[1.0, 0.4, 0.3, 0.8, 0.2],
        friction=[lj.Stribeck(0.6, 0.4, 0.1), None, None, lj.Coulomb(0.5, 0.3), None],
        carried_by=[None, 0, 1, None, None], c=[0.05, 0.0, 0.0, 0.02, 0.01],
        links=[lj.Spring(lj.WALL, 0, k=3.0, rest=lj.Fourier([0.05, 0.02], [0.3, -0.1], 2.0, 1.0)),
               lj.Spring(0, 1, k=8.0, rest=0.1), lj.Damper(3, lj.WALL, c=0.3), lj.Damper(0, 4, c=0.1),
               lj.Force(2, 0, lj.Spline(np.array([0.0, 0.2, -0.1, 0.05]), 2.0, 0.1)),
               lj.ExternalForce(3, lj.Sinusoid(0.4, 2.0, -0.05)), lj.Force(lj.WALL, 4, 0.02),
               lj.ExternalForce(1, -0.3)],
        x0=[0.5, 0.6, 0.7, 2.4, 3.0], v0=[0.0, 0.3, -0.2, 0.0, 0.0]),
    # The hopping reading's inputs: a capsule thrown up, bouncing (y0, w0, restitution, zeno_speed).
    "thrown_capsule": lj.Mechanism(masses=[1.0, 0.5], friction=[lj.Coulomb(0.5, 0.4), None], carried_by=[None, 0],
                                   links=[lj.Spring(0, 1, k=10.0)], y0=[0.3, 0.0], w0=[0.45, 0.0],
                                   restitution=[0.6, 0.0], zeno_speed=2e-3),
    # Tilted springs: to a wall with an actuated rest length, and between two bodies without a `d`.
    "tilted": lj.Mechanism(masses=[1.0, 0.7], friction=lj.Coulomb(0.6, 0.4), x0=[1.0, 3.5],
                           links=[lj.TiltedSpring(lj.WALL, 0, k=20.0, d=-0.4, rest=lj.Sinusoid(0.05, 3.0, 1.1)),
                                  lj.TiltedSpring(0, 1, k=30.0, rest=2.4)]),
}  # fmt: skip


@pytest.mark.parametrize("name", ROUND_TRIPS)
def test_mechanism_round_trip(tmp_path, name):
    mech = ROUND_TRIPS[name]
    path = lj.save_mechanism(mech, tmp_path / "m.toml", description=name)
    assert_same(lj.load_mechanism(path), mech)


def test_hopping_inputs_are_read_and_swept(tmp_path):
    """A file's `y0`, `w0`, `restitution` (per body) and `zeno_speed` are the mechanism's; a file without
    them writes none (the capsule's text keeps its fields); `bodies.0.y0` is swept like any number."""
    text = lj.save_mechanism(ROUND_TRIPS["thrown_capsule"], tmp_path / "t.toml").read_text()
    assert "y0 = 0.3" in text and "restitution = 0.6" in text and "zeno_speed = 0.002" in text
    assert "y0" not in lj.save_mechanism(capsule(), tmp_path / "c.toml").read_text()
    path = tmp_path / "t.toml"
    data = tomllib.loads(path.read_text())
    swept = builder(path, data, {"y0": ["bodies.0.y0"]})(y0=np.array([0.1, 0.2]))
    np.testing.assert_array_equal(np.asarray(swept.y0), [[0.1, 0.0], [0.2, 0.0]])
    assert np.all(np.asarray(swept.restitution)[..., 0] == 0.6) and float(swept.zeno_speed) == 2e-3


def test_save_refuses_a_batch(tmp_path):
    batch = lj.Mechanism(masses=[[1.0], [2.0]], friction=lj.Coulomb(), links=[lj.Spring(0, lj.WALL, k=1.0)])
    with pytest.raises(lj.MechanismFileError, match=r"one configuration; got a batch of shape \(2,\)"):
        lj.save_mechanism(batch, tmp_path / "b.toml")


CAPSULE = (EXAMPLES / "capsule.toml").read_text()

BROKEN = {
    "no_bodies": ('kind = "mechanism"\n', r"bodies: expected one \[\[bodies\]\] table per body"),
    "body_field": (CAPSULE.replace("mass = 0.5", "mas = 0.5"), r"line 14: \[\[bodies\]\] #2 mas: unknown field"),
    "body_mass": (CAPSULE.replace("mass = 0.5", 'mass = "heavy"'),
                  r"line 14: \[\[bodies\]\] #2 mass: expected a number, got 'heavy'"),
    "carried_by_self": (CAPSULE.replace("carried_by = 0", "carried_by = 1"),
                        r"line 15: \[\[bodies\]\] #2 carried_by: expected the index of another body \(0 to 1, not 1\)"),
    "friction_type": (CAPSULE.replace('type = "AnisotropicCoulomb"', 'type = "Bristles"'),
                      r"line 11: \[\[bodies\]\] #1 friction.type: expected one of 'Coulomb'"),
    "friction_field": (CAPSULE.replace("mu_k_bwd = 0.15", "mu_k_back = 0.15"),
                       r"line 11: \[\[bodies\]\] #1 friction.mu_k_back: unknown field"),
    "carried_with_friction": (CAPSULE.replace("carried_by = 0", 'carried_by = 0\nfriction = { type = "Coulomb", '
                                                                 "mu_s = 0.5, mu_k = 0.4 }"),
                              r"line 13: friction: body 1 is carried by body 0 .* has a friction law"),
    "link_type": (CAPSULE.replace('type = "Force"', 'type = "Muscle"'),
                  r"line 25: \[\[links\]\] #2 type: expected one of 'Spring', 'TiltedSpring', 'Damper', 'Force', "
                  r"'ExternalForce', "
                  r"got 'Muscle'"),
    "link_missing_body": (CAPSULE.replace("b = 1\nk = 10.0", "b = 2\nk = 10.0"),
                          r"line 20: \[\[links\]\] #1 b: expected a body index \(0 to 1\) or \"wall\", got 2"),
    "link_field": (CAPSULE.replace("k = 10.0", "k = 10.0\nstiffness = 3.0"),
                   r"line 22: \[\[links\]\] #1 stiffness: unknown field"),
    "spring_k": (CAPSULE.replace("k = 10.0", "k = -1.0"),
                 r"line 21: Invalid parameter 'k' of links\[0\] Spring\(0, 1\): got k=-1.0; the valid range is k > 0"),
    "waveform_type": (CAPSULE.replace('type = "Sinusoid"', 'type = "Square"'),
                      r"line 28: \[\[links\]\] #2 waveform.type: expected one of 'Sinusoid', 'Fourier', 'Spline'"),
    "waveform_missing": (CAPSULE.replace(", omega = 3.0, lbar = 0.0 }\n\n[[links]]", ", lbar = 0.0 }\n\n[[links]]"),
                         r"line 28: \[\[links\]\] #2 waveform: missing field 'omega'"),
    "waveform_sin": (CAPSULE.replace("sin = [0.0, 0.0]", "sin = [0.0]"),
                     r"line 33: \[\[links\]\] #3 waveform.sin: expected as many numbers as 'cos' \(2"),
    "waveform_frequency": (CAPSULE.replace("cos = [0.0, 0.1], sin = [0.0, 0.0], omega = 3.0",
                                           "cos = [0.0, 0.1], sin = [0.0, 0.0], omega = 2.0"),
                           r"line 30: links\[2\] ExternalForce\(0\): its waveform's omega=2.0 differs"),
    "external_wall": (CAPSULE.replace("i = 0", 'i = "wall"'),
                      r"line 32: \[\[links\]\] #3 i: expected a body index, not \"wall\""),
    "signal": (CAPSULE.replace("rest = 0.0", 'rest = "zero"'),
               r"line 22: \[\[links\]\] #1 rest: expected a number or a waveform table"),
    "unknown_table": (CAPSULE + "\n[[anchors]]\nx = 0.0\n", r"anchors: unknown field"),
}  # fmt: skip


@pytest.mark.parametrize("case", BROKEN)
def test_broken_mechanism_file_gives_one_message(tmp_path, case):
    text, pattern = BROKEN[case]
    path = tmp_path / "capsule.toml"
    path.write_text(textwrap.dedent(text))
    with pytest.raises(lj.MechanismFileError) as info:
        lj.load_mechanism(path)
    message = str(info.value).replace(str(tmp_path) + "/", "")
    assert "\n" not in message and message.startswith("capsule.toml"), message
    assert re.search(pattern, message), message


def test_examples_readme_names_the_capsule():
    assert "](capsule.toml)" in (EXAMPLES / "README.md").read_text()


def test_cli_simulates_the_capsule_and_sweep_asks_for_vary_by_name(tmp_path):
    res = CliRunner().invoke(_cli.app, ["simulate", str(EXAMPLES / "capsule.toml"), "--dt", "0.02", "--plot", "--out",
                                        str(tmp_path), "--t-end", "10", "--json"])  # fmt: skip
    assert res.exit_code == 0, res.output
    record = json.loads(res.stdout)
    assert record["kind"] == "mechanism" and record["status_name"] == "OK"
    assert Path(record["plot"]).is_file()
    out = CliRunner().invoke(_cli.app, ["sweep", str(EXAMPLES / "capsule.toml"), "--omega", "1,2", "--out",
                                        str(tmp_path / "s.nc")])  # fmt: skip
    assert out.exit_code == 2 and "describes the mechanism (bodies and links); name the numbers of it to sweep with " \
        "--vary PATH=VALUES" in out.output, out.output  # fmt: skip


def test_cli_gait_of_the_capsule_file_equals_the_library():
    """`gait capsule.toml --json` prints what `lj.steady_gait` gives on the loaded file."""
    args = ["gait", str(EXAMPLES / "capsule.toml"), "--periods", "1", "--transient", "10", "--dt", "0.02", "--json"]
    res = CliRunner().invoke(_cli.app, args)
    assert res.exit_code == 0, res.output
    record = json.loads(res.stdout)
    capsule = lj.load_mechanism(EXAMPLES / "capsule.toml")
    g = lj.steady_gait(capsule, periods=1, transient=10, dynamics=lj.Exact(dt=0.02))
    assert record["kind"] == "mechanism" and record["status_name"] == lj.GaitStatus(int(g.status)).name
    assert record["mean_speed"] == float(g.mean_speed) and record["state"] == np.asarray(g.state).tolist()
    assert record["status_name"] == "CONVERGED" and len(record["state"]) == 3


def test_cli_continues_the_capsule_files_spring_as_the_library():
    """`continue capsule.toml --parameter links[0].k`: the branch of `lj.continuation` in the spring
    named by its path, point for point."""
    args = ["continue", str(EXAMPLES / "capsule.toml"), "--parameter", "links[0].k", "--stop", "11", "--periods",
            "1", "--max-points", "3", "--dt", "0.02", "--json"]  # fmt: skip
    res = CliRunner().invoke(_cli.app, args)
    assert res.exit_code == 0, res.output
    record = json.loads(res.stdout)
    capsule = lj.load_mechanism(EXAMPLES / "capsule.toml")
    b = lj.continuation(capsule, "links[0].k", 11.0, periods=1, max_points=3, max_step=0.04, step=0.01,
                        dynamics=lj.Exact(dt=0.02))  # fmt: skip
    n = int(b.n_points)
    assert record["kind"] == "mechanism" and record["n_points"] == n >= 2 and record["lam_start"] == 10.0
    assert record["points"]["lam"] == np.asarray(b.lam)[:n].tolist()
    assert record["points"]["mean_speed"] == np.asarray(b.mean_speed)[:n].tolist()


def test_cli_animate_draws_the_capsule_files_simulation(tmp_path):
    """`animate capsule.toml` writes one GIF frame per saved state of `lj.simulate` on the loaded file,
    and counts each body's stuck frames as the trajectory's `stuck` says; every frame draws body i
    centred on the trajectory's x_i."""
    from PIL import Image

    out = tmp_path / "capsule.gif"
    args = ["animate", str(EXAMPLES / "capsule.toml"), "--t-from", "2", "--t-end", "6", "--frames", "9", "--dt",
            "0.01", "--out", str(out)]  # fmt: skip
    res = CliRunner().invoke(_cli.app, args)
    assert res.exit_code == 0, res.output
    capsule = lj.load_mechanism(EXAMPLES / "capsule.toml")
    traj = lj.simulate(capsule, 6.0, np.linspace(2.0, 6.0, 9), dynamics=lj.Exact(dt=0.01))
    stuck = np.asarray(traj.stuck).sum(axis=0)
    assert f"(9 frames, t = 2..6); body 0 stuck in {stuck[0]}, body 1 stuck in {stuck[1]} frames" in res.stdout
    assert stuck[0] > 0 and stuck[1] == 0  # the capsule sticks, its internal mass never does
    assert getattr(Image.open(out), "n_frames") == 9
    anim = lj.animate(traj, capsule, trace=False)
    fig = anim._fig  # pyright: ignore[reportAttributeAccessIssue]
    for k in (0, 4, 8):
        anim._func(k)  # pyright: ignore[reportAttributeAccessIssue]
        for i in range(2):
            (r,) = [a for a in fig.axes[0].patches if a.get_gid() == f"body{i}"]
            assert abs(r.get_x() + r.get_width() / 2 - float(traj.x[k, i])) < 1e-12
    with pytest.raises(ValueError, match="one mechanism configuration"):
        lj.animate(traj, lj.Mechanism.stack([capsule, capsule]))


def test_cli_optimize_passes_the_capsule_files_mechanism(monkeypatch):
    """`optimize capsule.toml` hands the loaded mechanism and the options to `lj.optimise` (the optimiser
    itself is tested in tests/test_optimise.py); without --a-max it says that it needs one."""
    import equinox as eqx

    seen: dict[str, Any] = {}

    def stand_in(*args, **kwargs):
        seen.update(args=args, kwargs=kwargs)
        raise ValueError("captured")

    monkeypatch.setattr(lj, "optimise", stand_in)
    path = str(EXAMPLES / "capsule.toml")
    res = CliRunner().invoke(_cli.app, ["optimize", path, "--v-min", "0.02", "--a-max", "0.7", "--direction", "-1"])
    assert res.exit_code == 2 and "captured" in res.output, res.output
    mech, v_min, a_max = seen["args"]
    assert bool(eqx.tree_equal(mech, lj.load_mechanism(path))) and (v_min, a_max) == (0.02, 0.7)
    assert seen["kwargs"]["direction"] == -1 and seen["kwargs"]["harmonics"] == 2
    res = CliRunner().invoke(_cli.app, ["optimize", path, "--v-min", "0.02"])
    assert res.exit_code == 2 and "--a-max is required" in res.output
