"""`locomotion-jax gait` and `locomotion-jax continue` (typer's CliRunner; one configuration each)."""

import json

import locomotion_jax as lj
import numpy as np
import pytest
from cli_helpers import invoke


# The gait group shares the compiled solver with the other gait tests.
pytestmark = [pytest.mark.xdist_group("gait"), pytest.mark.usefixtures("isolate_xla_flags")]


def _strict_json(text: str):
    def refuse(name):
        raise AssertionError(f"non-standard JSON literal {name}")

    return json.loads(text, parse_constant=refuse)


def test_gait_json_matches_steady_gait_and_text():
    res = invoke("gait", "--omega", "16", "--json")
    assert res.exit_code == 0, res.output
    rec = _strict_json(res.stdout)
    g = lj.steady_gait(lj.Params(omega=16.0))
    assert rec["status_name"] == "CONVERGED" and rec["k"] == int(g.k) and rec["regime_name"] == "SL"
    assert rec["mean_speed"] == pytest.approx(float(g.mean_speed), rel=1e-12)
    assert rec["cost_of_transport"] == pytest.approx(float(g.cost_of_transport), rel=1e-12)
    mult = np.asarray(rec["multipliers"])  # [re, im] pairs
    np.testing.assert_allclose(mult[:, 0] + 1j * mult[:, 1], np.asarray(g.multipliers), atol=1e-12)
    assert rec["params"]["omega"] == 16.0 and rec["contact"] == "strict" and rec["stable"] is True
    # The paper's names, as the paper's model's gait has always printed them.
    assert {"u", "v1", "v2", "stick_fraction1", "stick_fraction2", "state"} <= set(rec) and "stick_fraction" not in rec
    assert rec["v2"] == pytest.approx(float(g.v2), rel=1e-12) and rec["state"][2] == rec["v2"]
    text = invoke("gait", "--omega", "16")
    assert text.exit_code == 0 and "CONVERGED" in text.stdout and "multipliers" in text.stdout


def test_gait_liftoff_is_flagged_with_nulls():
    res = invoke("gait", "--omega", "10", "--a", "0.3", "--json")
    assert res.exit_code == 0, res.output
    rec = _strict_json(res.stdout)
    assert rec["status_name"] == "LIFTOFF" and rec["liftoff"] is True and rec["k"] == 0
    assert rec["mean_speed"] is None and rec["cost_of_transport"] is None
    assert all(x is None for pair in rec["multipliers"] for x in pair)


def test_continue_json_out_and_text(tmp_path):
    args = ["continue", "--omega", "16", "--parameter", "a", "--stop", "0.06", "--max-points", "4"]
    res = invoke(*args, "--json", "--out", str(tmp_path / "branch.json"))
    assert res.exit_code == 0, res.output
    rec = _strict_json(res.stdout)
    assert rec == _strict_json((tmp_path / "branch.json").read_text())
    b = lj.continuation(lj.Params(omega=16.0), "a", 0.06, max_points=4)
    assert rec["n_points"] == 4 and rec["status_name"] == "MAX_POINTS" and rec["lam_start"] == 0.05
    np.testing.assert_allclose(rec["points"]["lam"], np.asarray(b.lam), rtol=1e-12)
    np.testing.assert_allclose(rec["points"]["mean_speed"], np.asarray(b.mean_speed), rtol=1e-10)
    np.testing.assert_allclose(rec["points"]["state"], np.asarray(b.state), rtol=1e-10, atol=1e-12)
    assert rec["points"]["u"] == [q[0] for q in rec["points"]["state"]] and rec["points"]["n_land"] == [0] * 4
    text = invoke(*args)
    assert text.exit_code == 0 and "4 points" in text.stdout and "MAX_POINTS" in text.stdout


@pytest.mark.parametrize(
    "args, mention",
    [
        (["continue", "--parameter", "foo", "--stop", "1"], "parameter"),
        (["continue", "--parameter", "omega", "--stop", "2"], "stop"),
        (["gait", "--periods", "0"], "--periods"),
        (["gait", "--mu-s", "0.3"], "mu_s"),
    ],
)
def test_argument_errors(args, mention):
    res = invoke(*args)
    assert res.exit_code == 2 and mention in res.output
