"""Mechanism files (`lj.load_mechanism`, `lj.save_mechanism`): exact round trips of every kind, friction
law, actuator and waveform; the examples; broken files give one error naming the file, line and field."""

import re
import textwrap
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest


ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"


def assert_same(a, b) -> None:
    """Equal pytrees: the same structure (classes, static fields), and every leaf of the same shape,
    dtype and values (bit for bit: `-0.0` and `0.0` compare equal, as the engines treat them)."""
    la, ta = jax.tree_util.tree_flatten(a)
    lb, tb = jax.tree_util.tree_flatten(b)
    assert ta == tb
    for x, y in zip(la, lb):
        assert jnp.shape(x) == jnp.shape(y) and jnp.result_type(x) == jnp.result_type(y)
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


def round_trip(tmp_path, mech, **kwargs):
    path = lj.save_mechanism(mech, tmp_path / "m.toml", **kwargs)
    return lj.load_mechanism(path, with_waveform=True)


def write(tmp_path, text: str, name: str = "worm.toml") -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


# -- the paper's model --------------------------------------------------------------------------------------


PAPER_WAVES = {
    "eq13": None,
    "sinusoid": lj.Sinusoid(0.04, 3.0, 2.5),
    "fourier": lj.Fourier(np.array([0.01, -0.003, 0.0]), np.array([0.05, 0.0, 0.002]), 2.5, 3.0),
    "spline": lj.Spline(np.array([0.0, 0.03, 0.05, -0.02, -0.04]), 1.7, 3.0),
}


@pytest.mark.parametrize("wave", PAPER_WAVES, ids=list(PAPER_WAVES))
def test_paper_round_trip(tmp_path, wave):
    params = lj.Params(omega=1.0 / 3.0, a=0.0625, d=-0.2, mhat=0.3, mu_s=0.8, mu_k=0.45, k=37.5, c=0.02, lbar=2.5)
    loaded, loaded_wave = round_trip(tmp_path, params, waveform=PAPER_WAVES[wave])
    assert_same(loaded, params)
    assert_same(loaded_wave, PAPER_WAVES[wave])
    if wave == "eq13":
        assert_same(lj.load_mechanism(tmp_path / "m.toml"), params)  # no waveform: a Params alone
    else:
        with pytest.raises(lj.MechanismFileError, match=r"with_waveform=True"):
            lj.load_mechanism(tmp_path / "m.toml")  # a Params alone would drop the waveform


def test_paper_defaults_and_partial_params(tmp_path):
    path = write(tmp_path, 'kind = "paper"\n[params]\nomega = 6\n[waveform]\ntype = "Sinusoid"\na = 0.02\n')
    params, wave = lj.load_mechanism(path, with_waveform=True)
    assert_same(params, lj.Params(omega=6.0))  # integers read as floats; the rest the paper's defaults
    assert_same(wave, lj.Sinusoid(0.02, 6.0, 3.0))  # the waveform's omega and lbar default to the params'


# -- chains: every friction law, actuator and waveform ------------------------------------------------------


FRICTIONS = {
    "coulomb": lj.Coulomb(0.7, 0.5),
    "coulomb_per_mass": lj.Coulomb([0.7, 0.8, 0.9], [0.5, 0.5, 0.6]),
    "anisotropic": lj.AnisotropicCoulomb(0.5, 0.9, 0.3, 0.7),
    "stribeck": lj.Stribeck(0.7, 0.5, 0.05),
    "stribeck_backward": lj.Stribeck(0.7, 0.5, [0.05, 0.1, 0.2], mu_s_bwd=0.9, mu_k_bwd=0.6),
}
WAVES = {
    "travelling": lj.TravellingWave(0.06, 2.0, 0.7),
    "spring_fourier": lj.SpringFourier([[0.01, 0.0], [0.0, -0.02]], [[0.05, 0.01], [0.04, 0.0]], 1.5),
    "sinusoids": [lj.Sinusoid(0.05, 2.0, 3.0), lj.Sinusoid(-0.03, 2.0, 2.5)],
    "fouriers": [
        lj.Fourier(np.array([0.01]), np.array([0.05]), 2.0, 3.0),
        lj.Fourier(np.array([0.0, 0.02]), np.array([0.04, 0.0]), 2.0, 2.5),
    ],
    "none": None,
}


def chain(friction="coulomb", wave="travelling", actuator: lj.AbstractActuator = lj.RestLength()) -> lj.Chain:
    lbar = [3.0, 2.5] if wave in ("sinusoids", "fouriers") else 3.0
    return lj.Chain(masses=[1.0, 0.5, 1.5], k=[50.0, 40.0], d=0.25, lbar=lbar, c=[0.01, 0.0, 0.02],
                    waveforms=WAVES[wave], friction=FRICTIONS[friction], actuator=actuator)  # fmt: skip


@pytest.mark.parametrize("friction", FRICTIONS)
def test_chain_round_trip_friction(tmp_path, friction):
    mech = chain(friction)
    loaded, wave = round_trip(tmp_path, mech)
    assert wave is None
    assert_same(loaded, mech)


@pytest.mark.parametrize("wave", WAVES)
@pytest.mark.parametrize("actuator", [lj.RestLength(), lj.InternalForce()], ids=["rest_length", "internal_force"])
def test_chain_round_trip_waveform_actuator(tmp_path, wave, actuator):
    mech = chain("anisotropic", wave, actuator)
    loaded, _ = round_trip(tmp_path, mech)
    assert_same(loaded, mech)
    again = lj.save_mechanism(loaded, tmp_path / "again.toml")  # a written file is written again identically
    assert again.read_text() == (tmp_path / "m.toml").read_text()


def test_chain_of_the_paper_round_trip(tmp_path):
    mech = lj.Chain.from_params(lj.Params(omega=2.0))  # per-mass coefficients of shape (1,), one spring
    assert_same(round_trip(tmp_path, mech)[0], mech)


HAND_WAVES = {
    "travelling": '[waveform]\ntype = "TravellingWave"\na = 0.06\nomega = 2\nphi = 0.7\n',
    "spring_fourier": '[waveform]\ntype = "SpringFourier"\ncos = [[0.01, 0.0], [0.0, -0.02]]\n'
    "sin = [[0.05, 0.01], [0.04, 0.0]]\nomega = 1.5\n",
    "sinusoids": '[[waveforms]]\ntype = "Sinusoid"\na = 0.05\nomega = 2.0\n'
    '[[waveforms]]\ntype = "Sinusoid"\na = -0.03\nomega = 2.0\n',
    "fouriers": '[[waveforms]]\ntype = "Fourier"\ncos = [0.01]\nsin = [0.05]\nomega = 2.0\n'
    '[[waveforms]]\ntype = "Fourier"\ncos = [0.0, 0.02]\nsin = [0.04, 0.0]\nomega = 2.0\n',
    "none": "",
}


@pytest.mark.parametrize("wave", HAND_WAVES)
def test_hand_written_chain_equals_python(tmp_path, wave):
    lbar = "[3.0, 2.5]" if wave in ("sinusoids", "fouriers") else "3.0"
    text = (
        'schema = 1\nkind = "chain"\n[chain]\nmasses = [1.0, 0.5, 1.5]\nk = [50, 40]\nd = 0.25\n'
        f"lbar = {lbar}\nc = [0.01, 0.0, 0.02]\n"
        '[friction]\ntype = "Stribeck"\nmu_s = 0.7\nmu_k = 0.5\nv_s = [0.05, 0.1, 0.2]\nmu_s_bwd = 0.9\n'
        'mu_k_bwd = 0.6\n[actuator]\ntype = "InternalForce"\n' + HAND_WAVES[wave]
    )
    loaded = lj.load_mechanism(write(tmp_path, text))
    assert_same(loaded, chain("stribeck_backward", wave, lj.InternalForce()))


def test_save_refuses_what_a_file_cannot_hold(tmp_path):
    class Viscous(lj.Coulomb):
        pass

    with pytest.raises(lj.MechanismFileError, match="one configuration"):
        lj.save_mechanism(lj.Params(omega=np.array([1.0, 2.0])), tmp_path / "x.toml")
    with pytest.raises(lj.MechanismFileError, match="friction law Viscous"):
        own = lj.Chain(masses=[1.0, 1.0], friction=Viscous(jnp.asarray(0.7), jnp.asarray(0.5)))
        lj.save_mechanism(own, tmp_path / "x.toml")
    with pytest.raises(lj.MechanismFileError, match="waveform= is for Params"):
        lj.save_mechanism(chain(), tmp_path / "x.toml", waveform=lj.Sinusoid(0.1, 1.0, 3.0))


# -- broken files: one message naming the file, the line and the field --------------------------------------


WORM = """\
schema = 1
kind = "chain"

[chain]
masses = [1.0, 1.0, 1.0]
d = 0.0

[friction]
type = "AnisotropicCoulomb"
mu_s_fwd = 0.5
mu_s_bwd = 0.9
mu_k_fwd = 0.3
mu_k_bwd = 0.7

[waveform]
type = "TravellingWave"
a = 0.1
omega = 2.0
phi = 0.785
"""

BROKEN = {
    "syntax": (WORM.replace("d = 0.0", "d = 0.0.1"), r"worm.toml, line 6: not valid TOML: .*\(at line 6"),
    "unclosed_table": (WORM.replace("[friction]", "[friction"), r"worm.toml, line 8: not valid TOML"),
    "unknown_kind": (
        WORM.replace('"chain"', '"capsule"', 1),
        r"worm.toml, line 2: kind: expected one of 'paper', "
        r"'chain', 'mechanism', got 'capsule'",
    ),
    "missing_kind": (WORM.replace('kind = "chain"', ""), r"worm.toml: missing field 'kind'"),
    "missing_masses": (
        WORM.replace("masses = [1.0, 1.0, 1.0]", ""),
        r"worm.toml, line 4: \[chain\] missing field "
        r"'masses'",
    ),
    "missing_table": (WORM.replace("[chain]\nmasses = [1.0, 1.0, 1.0]\nd = 0.0\n", ""), r"missing table \[chain\]"),
    "wrong_type": (
        WORM.replace("mu_k_bwd = 0.7", "mu_k_bwd = 'abc'"),
        r"worm.toml, line 13: \[friction\] mu_k_bwd: "
        r"expected a number or a list of 3 numbers \(one per mass\), got 'abc'",
    ),
    "wrong_length": (
        WORM.replace("mu_s_fwd = 0.5", "mu_s_fwd = [0.5, 0.5]"),
        r"line 10: \[friction\] mu_s_fwd: "
        r"expected a number or a list of 3 numbers \(one per mass\), got \[0.5, 0.5\]",
    ),
    "spring_length": (
        WORM.replace("d = 0.0", "d = [0.0, 0.0, 0.0]"),
        r"line 6: \[chain\] d: expected a number or "
        r"a list of 2 numbers \(one per spring\)",
    ),
    "unknown_law": (
        WORM.replace('"AnisotropicCoulomb"', '"Bristles"'),
        r"line 9: \[friction\] type: expected one "
        r"of 'Coulomb', 'AnisotropicCoulomb', 'Stribeck', got 'Bristles'",
    ),
    "unknown_field": (
        WORM.replace("phi = 0.785", "phase = 0.785"),
        r"line 19: \[waveform\] phase: unknown field; "
        r"the fields of this table are type, a, omega, phi",
    ),
    "negative_mass": (
        WORM.replace("[1.0, 1.0, 1.0]", "[1.0, -1.0, 1.0]"),
        r"^worm.toml, line 5: Invalid "
        r"parameter 'masses' of mass 1: got masses=-1.0; the valid range is m_i > 0, a normal float\.$",
    ),
    "friction_range": (
        WORM.replace("mu_s_bwd = 0.9", "mu_s_bwd = 0.6"),
        r"^worm.toml, line 11: Invalid "
        r"parameter 'mu_s_bwd' of mass 0: got mu_s_bwd=0.6, mu_k_bwd=0.7",
    ),
    "boolean": (WORM.replace("a = 0.1", "a = true"), r"line 17: \[waveform\] a: expected a number, got True"),
    "one_mass": (WORM.replace("[1.0, 1.0, 1.0]", "[1.0]"), r"\[chain\] masses: expected a list of at least 2"),
    "unknown_actuator": (
        WORM + '[actuator]\ntype = "Muscle"\n',
        r"line 21: \[actuator\] type: expected one of "
        r"'RestLength', 'InternalForce', got 'Muscle'",
    ),
    "both_waveforms": (WORM + '[[waveforms]]\ntype = "Sinusoid"\na = 0.1\nomega = 2.0\n', r"give either \[waveform\]"),
    "waveforms_count": (
        WORM.replace('[waveform]\ntype = "TravellingWave"', '[[waveforms]]\ntype = "Sinusoid"').replace(
            "phi = 0.785\n", ""
        ),
        r"expected 2 \[\[waveforms\]\] tables \(one per spring\), "
        r"got 1",
    ),
    "spring_lbar": (
        WORM.replace('[waveform]\ntype = "TravellingWave"', '[waveform]\ntype = "Sinusoid"').replace(
            "phi = 0.785", "lbar = 3.0"
        ),
        r"\[waveform\] lbar: unknown field \('lbar' is the "
        r"spring's: give it in \[chain\] lbar\)",
    ),
    "schema": (
        "schema = 2\n" + WORM.replace("schema = 1\n", ""),
        r"line 1: schema: this version of locomotion_jax "
        r"reads schema 1, got 2",
    ),
    "paper_field": ('kind = "paper"\n[params]\nomgea = 2.0\n', r"line 3: \[params\] omgea: unknown field"),
    "paper_range": (
        'kind = "paper"\n[params]\nmu_s = 0.2\n',
        r"^worm.toml, line 3: Invalid parameter 'mu_s': got "
        r"mu_s=0.2, mu_k=0.5; the valid range is mu_s >= mu_k",
    ),
    "spline_short": (
        'kind = "paper"\n[waveform]\ntype = "Spline"\ncontrol = [0.0, 0.1]\n',
        r"line 4: \[waveform\] "
        r"control: expected a list of at least 4 number\(s\)",
    ),
    "not_a_table": ('kind = "chain"\nchain = 3\n', r"\[chain\]: expected a table, got 3"),
    "binary": (None, r"worm.toml: not a text file in UTF-8"),
}


@pytest.mark.parametrize("case", BROKEN)
def test_broken_file_gives_one_message(tmp_path, case):
    text, pattern = BROKEN[case]
    path = tmp_path / "worm.toml"
    if text is None:
        path.write_bytes(b"\xff\xfe\x00kind")
    else:
        path.write_text(text)
    with pytest.raises(lj.MechanismFileError) as info:
        lj.load_mechanism(path)
    message = str(info.value).replace(str(tmp_path) + "/", "")
    assert "\n" not in message and "Traceback" not in message
    assert re.search(pattern, message), message


def test_the_broken_worm_reads_when_mended(tmp_path):
    """The base of the broken files is itself valid (each case breaks one thing)."""
    worm = lj.load_mechanism(write(tmp_path, WORM))
    assert isinstance(worm, lj.Chain) and worm.n_masses == 3


# -- the examples ---------------------------------------------------------------------------------------------


def example_worm() -> lj.Chain:
    """examples/worm.toml built in Python."""
    return lj.Chain(
        masses=[1.0, 1.0, 1.0, 1.0], k=50.0, d=0.0, lbar=3.0, c=0.01,
        friction=lj.AnisotropicCoulomb(mu_s_fwd=0.5, mu_s_bwd=0.9, mu_k_fwd=0.3, mu_k_bwd=0.7),
        actuator=lj.RestLength(), waveforms=lj.TravellingWave(a=0.1, omega=2.0, phi=0.785),
    )  # fmt: skip


def test_examples_load_and_the_worm_measures_as_in_python():
    assert_same(lj.load_mechanism(EXAMPLES / "paper.toml"), lj.Params())
    loaded = lj.load_mechanism(EXAMPLES / "worm.toml")
    assert_same(loaded, example_worm())
    settings: dict[str, Any] = dict(z=1.0, horizon=40.0, window=10.0, t_start=20.0, dynamics=lj.Exact(dt=0.02))
    a, b = lj.measure(loaded, **settings), lj.measure(example_worm(), **settings)
    assert int(a.status) == int(lj.Status.OK) and np.isfinite(float(a.tau_z))
    assert_same(a, b)  # identical results


def test_examples_readme_names_every_example():
    readme = (EXAMPLES / "README.md").read_text()
    for path in EXAMPLES.glob("*.toml"):
        assert f"]({path.name})" in readme
