"""`locomotion-jax measure FILE`: a mechanism file's measurement equals the library's on the loaded file;
an unreadable or broken file is one line `Error: ...`, exit code 2, no traceback (typer's CliRunner)."""

import json
from pathlib import Path

import locomotion_jax as lj
import numpy as np
import pytest
from cli_helpers import invoke


pytestmark = pytest.mark.usefixtures("isolate_xla_flags")
EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
# Short runs; the settings of tests/test_files.py's measurement, so the compilation is shared.
SHORT = ["--z", "1", "--horizon", "40", "--window", "10", "--t-start", "20", "--dt", "0.02"]


def assert_record_equals(record: dict, m) -> None:
    for name, value in m.to_numpy().items():
        expected = np.asarray(value)
        got = np.asarray(record[name], dtype=float)  # null (non-finite) reads as NaN
        finite = np.isfinite(expected)
        np.testing.assert_array_equal(got[finite], expected[finite], err_msg=name)  # identical, not close
        assert np.isnan(got[~finite]).all(), name


def test_measure_worm_json_equals_the_library():
    res = invoke("measure", str(EXAMPLES / "worm.toml"), *SHORT, "--json")
    assert res.exit_code == 0, res.output
    record = json.loads(res.stdout)
    worm = lj.load_mechanism(EXAMPLES / "worm.toml")
    m = lj.measure(worm, z=1.0, horizon=40.0, window=10.0, t_start=20.0, dynamics=lj.Exact(dt=0.02))
    assert_record_equals(record, m)
    assert record["status_name"] == "OK" and record["kind"] == "chain" and len(record["stick_fraction"]) == 4
    assert record["mechanism"].endswith("worm.toml") and record["dt"] == 0.02 and record["contact"] == "strict"
    text = invoke("measure", str(EXAMPLES / "worm.toml"), *SHORT)
    assert text.exit_code == 0 and "chain of 4 masses, AnisotropicCoulomb friction" in text.stdout
    assert "mean_speed" in text.stdout


def test_measure_paper_with_a_waveform_equals_the_library(tmp_path):
    params, wave = lj.Params(omega=2.0), lj.Fourier(np.array([0.0, 0.01]), np.array([0.05, 0.0]), 2.0, 3.0)
    path = lj.save_mechanism(params, tmp_path / "paper.toml", waveform=wave)
    res = invoke("measure", str(path), *SHORT, "--json")
    assert res.exit_code == 0, res.output
    m = lj.measure(params, z=1.0, horizon=40.0, window=10.0, t_start=20.0, waveform=wave, dynamics=lj.Exact(dt=0.02))
    record = json.loads(res.stdout)
    assert_record_equals(record, m)
    assert record["kind"] == "paper"
    text = invoke("measure", str(path), *SHORT)
    assert "the paper's two-mass model, Fourier waveform" in text.stdout


@pytest.mark.parametrize(
    "content, expected",
    [
        (None, "cannot read the mechanism file (No such file or directory)"),
        ('kind = "chain"\n[chain]\nmasses = [1.0, "x"]\n', "line 3: [chain] masses: expected a list of at least 2"),
        ('kind = "chain"\n[chain\n', "line 2: not valid TOML"),
        ('kind = "chain"\n[chain]\nmasses = [1.0, 0.0]\n', "Invalid parameter 'masses' of mass 1"),
    ],
    ids=["missing", "wrong_type", "syntax", "constructor"],
)
def test_measure_broken_file_is_one_line(tmp_path, content, expected):
    path = tmp_path / "robot.toml"
    if content is not None:
        path.write_text(content)
    res = invoke("measure", str(path))
    assert res.exit_code == 2
    assert res.output.strip().count("\n") == 0 and "Traceback" not in res.output
    assert res.output.startswith(f"Error: {path}") and expected in res.output, res.output


def test_measure_bad_option_is_one_line():
    res = invoke("measure", str(EXAMPLES / "worm.toml"), "--z", "-1")
    assert res.exit_code == 2 and "Traceback" not in res.output and res.output.startswith("Error:"), res.output
