"""Self-checks of the independent scipy reference solver (tests/reference.py).

These tests check the reference on its own (no package import): the energy balance of
eq. (16), the symmetries of the model (SPEC section 2; paper Fig. 4b), the SSL/SL regimes
of Fig. 5, and convergence of tau_5 in the integrator tolerance.
"""

import functools
import math
import os
import sys

import numpy as np
import pytest


sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from reference import DEFAULTS, reference_measure, reference_simulate  # noqa: E402


@functools.cache
def _measure(omega, rtol=1e-11, contact="paper"):
    return reference_measure(dict(omega=omega), z=5.0, contact=contact, start="paper", rtol=rtol)


@pytest.mark.parametrize("omega", [2.0, 23.0])
def test_energy_balance(omega):
    """Eq. (16): w = e_d + e(t) - e(0), with w and e_d integrated independently."""
    r = reference_simulate(dict(d=0.5, a=0.05, omega=omega), 100.0, contact="strict")
    assert not r["liftoff"] and r["valid_until"] == 100.0
    balance = r["w"] - r["e_d"] - (r["e"] - r["e"][0])
    assert np.max(np.abs(balance)) < 1e-7
    # The check is not vacuous: energy was dissipated and work was done.
    assert r["e_d"][-1] > 1.0
    assert np.all(np.diff(r["e_d"]) >= -1e-12)


def test_symmetric_d0_no_net_motion():
    """d = 0, m1 = m2 (Fig. 4b, omega = pi): both masses switch together, X stays put."""
    r = reference_simulate(dict(d=0.0, mhat=0.5, omega=math.pi), 50.0, save_at=np.linspace(0, 50, 2001))
    assert r["n_switches"] > 50  # the masses do stick and slip
    assert np.max(np.abs(r["X"] - r["X"][0])) < 1e-8
    # Simultaneous switches: every switch of m1 has a partner of m2 at the same instant.
    t1 = np.array([t for t, kind in r["events"] if kind.startswith("m1") and "reverse" not in kind])
    t2 = np.array([t for t, kind in r["events"] if kind.startswith("m2") and "reverse" not in kind])
    assert t1.shape == t2.shape and np.max(np.abs(t1 - t2)) < 1e-12
    # Modes are only "both stuck" or "both slip".
    assert set(np.unique(r["mode"])) <= {0, 1}


def test_mirror_symmetry_d():
    """d -> -d with m1 = m2: the mirror x1' = -x2, x2' = -x1 maps N1 <-> N2 (eq. 5) and the
    translated initial condition onto itself, so the CoM displacement reverses sign."""
    ts = np.linspace(0.0, 50.0, 501)
    rp = reference_simulate(dict(d=0.5, omega=math.pi), 50.0, save_at=ts)
    rm = reference_simulate(dict(d=-0.5, omega=math.pi), 50.0, save_at=ts)
    dXp = rp["X"] - rp["X"][0]
    dXm = rm["X"] - rm["X"][0]
    assert dXp[-1] > 0.1  # Fig. 4b: d > 0 moves forward
    assert np.max(np.abs(dXp + dXm)) < 1e-8
    # The mirror also swaps the masses' velocities: v1(+d) = -v2(-d).
    assert np.max(np.abs(rp["v1"] + rm["v2"])) < 1e-8


def test_fig4b_direction():
    """Fig. 4b: forward for d > 0, backward for d < 0, faster for larger |d|."""
    disp = {d: reference_simulate(dict(d=d, omega=math.pi), 30.0, save_at=[0.0, 30.0])["X"] for d in (0.25, 0.5)}
    assert 0.0 < disp[0.25][1] - disp[0.25][0] < disp[0.5][1] - disp[0.5][0]


@pytest.mark.parametrize("omega, regime", [(2.0, 1), (23.0, 0)])
def test_regimes_fig5(omega, regime):
    """Fig. 5: omega = 0.2 wn1 is stick-slip (SSL), omega = 2.3 wn1 is pure slip (SL)."""
    m = _measure(omega)
    assert m["regime"] == regime
    assert m["reached"] and math.isfinite(m["tau_z"]) and m["e_z"] > 0
    if regime == 1:
        assert m["stick_fraction1"] > 0.05 and m["stick_fraction2"] > 0.05
    else:
        assert m["stick_fraction1"] == 0.0 and m["stick_fraction2"] == 0.0
    assert m["mean_speed"] == pytest.approx(5.0 / m["tau_z"], rel=1e-9)
    assert m["t_start"] == pytest.approx(80 * 2 * math.pi / math.sqrt(50.0))


def test_tau5_rtol_convergence():
    """tau_5 at omega = 23 agrees between rtol 1e-9 and 1e-11 to 1e-6 relative."""
    fine = _measure(23.0, 1e-11)["tau_z"]
    coarse = _measure(23.0, 1e-9)["tau_z"]
    assert abs(coarse - fine) <= 1e-6 * fine


def test_strict_liftoff_stops_and_paper_continues():
    """SPEC section 1: a >= 0.08 at omega = 23 lifts a mass off early (the reference finds
    t = 0.316, i.e. 1.16 actuation periods; a = 0.065 stays in contact, a = 0.07 does not)."""
    params = dict(omega=23.0, a=0.08)
    rs = reference_simulate(params, 3.0, contact="strict")
    assert rs["liftoff"] and rs["t_liftoff"] < 2 * (2 * math.pi / 23.0)
    assert not reference_simulate(dict(omega=23.0, a=0.065), 3.0, contact="strict")["liftoff"]
    assert rs["valid_until"] == rs["t_liftoff"]
    for key in ("x1", "v1", "x2", "v2", "X", "e_d", "w", "e"):
        assert np.all(np.isfinite(rs[key]))
    rp = reference_simulate(params, 3.0, contact="paper")
    assert rp["liftoff"] and rp["t_liftoff"] == pytest.approx(rs["t_liftoff"], abs=1e-12)
    assert rp["valid_until"] == 3.0
    # The paper reading (n = |N|) still satisfies the energy balance.
    assert np.max(np.abs(rp["w"] - rp["e_d"] - (rp["e"] - rp["e"][0]))) < 1e-8
    m = reference_measure(params, contact="strict")
    assert m["regime"] == -1 and not m["reached"] and m["tau_z"] == math.inf and m["e_z"] == math.inf


def test_stuck_masses_are_at_rest():
    """Eq. (7): in a sample taken while a mass is stuck its velocity is exactly zero."""
    r = reference_simulate(dict(omega=2.0), 20.0, save_at=np.linspace(0, 20, 4001))
    stuck1 = np.isin(r["mode"], (0, 3))
    stuck2 = np.isin(r["mode"], (0, 2))
    assert stuck1.any() and stuck2.any()
    assert np.all(r["v1"][stuck1] == 0.0) and np.all(r["v2"][stuck2] == 0.0)
    assert set(DEFAULTS) == {"k", "c", "d", "lbar", "a", "omega", "mu_s", "mu_k", "mhat"}
