"""`experiments/resonance.py` (issue 27) on a small batch of its own configurations: the energy balance
`|w - e_d - Delta e| <= 1e-6 e_d` holds on every measured run of each reading (as the script checks on
every run), hop equals strict where strict measures, hop goes on where strict stops at lift-off, and
the script's outputs (json, png) are written."""

import importlib.util
import json
from pathlib import Path

import locomotion_jax as lj
import numpy as np


SCRIPT = Path(__file__).resolve().parents[1] / "experiments" / "resonance.py"


def _script():
    spec = importlib.util.spec_from_file_location("resonance_experiment", SCRIPT)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_resonance_small_batch_balances_energy(tmp_path):
    """omega/omega_n1 = 0.5 (no lift-off), 1.5 and 2.0 (strict lifts off; hop flies at a = 0.1), both
    amplitudes, each reading one call with the script's settings."""
    res = _script()
    ratios = np.asarray([0.5, 1.5, 2.0])
    results, seconds = res.run(ratios)
    worst = res.balance_check(results)
    print("max |balance| / e_d", worst)
    assert all(0 < w <= res.BALANCE_TOL for w in worst.values())
    strict, paper, hop = (results[c] for c in res.READINGS)
    st, sh = np.asarray(strict.status), np.asarray(hop.status)
    assert np.all(np.asarray(paper.status) == lj.Status.OK) and np.all(sh == lj.Status.OK)
    assert st[0].tolist() == [lj.Status.OK] * 2 and st[2, 1] == lj.Status.LIFTOFF
    # Where strict measures, hop is the same run (nothing lifts off): to rounding.
    ok = st == lj.Status.OK
    np.testing.assert_allclose(np.asarray(hop.tau_z)[ok], np.asarray(strict.tau_z)[ok], rtol=1e-9)
    assert hop.flight_fraction is not None and hop.highest_hop is not None
    ff = np.asarray(hop.flight_fraction)
    assert np.all(ff[ok] == 0) and ff[1, 1].min() > 0.1 and ff[2, 1].min() > 0.1  # a = 0.1 hops at 1.5, 2.0
    assert np.all(np.isfinite(np.asarray(hop.tau_z))) and np.all(np.asarray(hop.landings_per_period)[1:, 1] > 0.5)
    out = res.to_json(ratios, results, worst, seconds)
    assert out["hop"]["status"] == sh.tolist() and len(out["hop"]["flight_fraction"]) == 3
    res.plot(ratios, results, tmp_path / "resonance.png")
    (tmp_path / "resonance.json").write_text(json.dumps(out))
    assert (tmp_path / "resonance.png").stat().st_size > 10_000
