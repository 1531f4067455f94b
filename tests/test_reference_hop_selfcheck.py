"""Self-checks of the independent hopping reference (tests/reference_hop.py), without the package.

* a ball dropped from h: landing times ``sqrt(2h)`` then gaps ``2 e^k sqrt(2h)``, rebound heights
  ``e^(2k) h`` (1e-10), and the Zeno rule ends the sequence at the first rebound slower than ``zeno_speed``;
* a ball landing while sliding: the velocity after the impact by the impulse law, then Coulomb sliding;
* without lift-off the hop reading equals reference_chain's strict one (1e-9);
* ``work = e_d + Delta e`` on runs that hop (the paper's model near resonance, a 3-mass chain);
* halving the tolerances changes the positions at t = 40 by < 1e-8.
"""

import math

import numpy as np
import pytest
from reference_chain import chain_config, reference_chain_simulate
from reference_hop import ball_config, paper_config, reference_hop_simulate


def _balance(r) -> float:
    return float(np.max(np.abs(r["work"] - r["e_d"] - (r["energy"] - r["energy"][0]))))


@pytest.mark.parametrize("h", [1.0, 0.3])
@pytest.mark.parametrize("e", [0.0, 0.5, 0.8])
def test_dropped_ball(h, e):
    zeno = 1e-3
    ts = np.linspace(0.0, 15.0, 31)
    r = reference_hop_simulate(ball_config(), 15.0, ts, restitution=e, y0=[h], zeno_speed=zeno)
    s = math.sqrt(2.0 * h)
    # Landing k (1-based) hits with speed e^(k-1) s; it is the last when its rebound e^k s < zeno.
    K = next(k for k in range(1, 10_000) if e**k * s < zeno)
    times = [t for t, _ in r["landings"]]
    assert len(times) == K and r["n_landings"].tolist() == [K]
    expected = s + np.concatenate(([0.0], np.cumsum([2.0 * e**k * s for k in range(1, K)])))
    assert np.max(np.abs(np.array(times) - expected)) < 1e-10
    heights = [y for _, _, y in r["apexes"]]
    assert len(heights) == K  # the top at t = 0, then one per rebound
    assert np.max(np.abs(np.array(heights) - h * e ** (2.0 * np.arange(K)))) < 1e-10
    assert r["max_height"][0] == pytest.approx(h, abs=1e-14)
    assert r["flight_time"][0] == pytest.approx(expected[-1], abs=1e-10)
    # At rest on the ground afterwards; the whole drop's energy is dissipated.
    assert r["y"][-1, 0] == 0.0 and r["w"][-1, 0] == 0.0 and r["v"][-1, 0] == 0.0
    assert r["e_d"][-1] == pytest.approx(h, abs=1e-10)
    assert _balance(r) < 1e-10


def test_zeno_rule_threshold():
    """A larger threshold ends the bouncing earlier, at the landing it says."""
    h, e = 1.0, 0.8
    s = math.sqrt(2.0 * h)
    for zeno in (1e-3, 0.1, 0.5):
        r = reference_hop_simulate(ball_config(), 15.0, [15.0], restitution=e, y0=[h], zeno_speed=zeno)
        K = next(k for k in range(1, 10_000) if e**k * s < zeno)
        assert r["n_landings"][0] == K
    r = reference_hop_simulate(ball_config(), 15.0, [15.0], restitution=e, y0=[h], zeno_speed=0.5)
    assert r["n_landings"][0] < 10


@pytest.mark.parametrize("v0", [0.3, 2.0])
@pytest.mark.parametrize("e", [0.0, 0.5])
def test_ball_lands_sliding(v0, e):
    """``P_t = min(m |v-|, mu_k P_n)``: with v0 = 0.3 the impact stops the ball (stuck); with v0 = 2 it
    slides on from ``v+ = v0 - mu_k (1 + e) |w-|`` and decelerates by mu_k (after the rebounds)."""
    m, mu_s, mu_k, h = 1.3, 0.6, 0.5, 0.5
    s = math.sqrt(2.0 * h)
    t1 = s
    ts = np.array([t1 * 0.5, t1, t1 + 1e-3])
    r = reference_hop_simulate(ball_config(m, mu_s, mu_k), t1 + 1e-3, ts, restitution=e, y0=[h], v0=[v0])
    assert r["landings"][0][0] == pytest.approx(t1, abs=1e-12)
    vp = max(v0 - mu_k * (1.0 + e) * s, 0.0)
    if e == 0.0:
        # On the ground after the impact: stuck, or sliding with deceleration mu_k (unit gravity).
        want = max(vp - mu_k * 1e-3, 0.0)
    else:
        want = vp  # rebounded: flying, no friction, no damping
    assert r["v"][2, 0] == pytest.approx(want, abs=1e-12)
    assert r["x"][0, 0] == pytest.approx(v0 * t1 * 0.5, abs=1e-12)
    loss = 0.5 * m * (s * s - (e * s) ** 2) + 0.5 * m * (v0 * v0 - vp * vp)
    if e == 0.0 and vp > 0.0:  # then sliding for 1e-3: friction's work mu_k m (distance slid)
        loss += mu_k * m * (vp * 1e-3 - 0.5 * mu_k * 1e-6)
    assert r["e_d"][2] == pytest.approx(loss, abs=1e-12)
    if e == 0.0 and v0 > mu_k * s:
        # Long run: slides to rest at t1 + vp / mu_k and stays stuck.
        T = t1 + vp / mu_k + 1.0
        r2 = reference_hop_simulate(ball_config(m, mu_s, mu_k), T, [0.0, T], y0=[h], v0=[v0])
        assert r2["x"][1, 0] == pytest.approx(v0 * t1 + vp * vp / (2 * mu_k), abs=1e-10)
        assert r2["v"][1, 0] == 0.0 and r2["mode"][1, 0] == 0
        assert _balance(r2) < 1e-10


NO_LIFTOFF = {
    "paper small a": paper_config(omega=2.0, a=0.05, d=0.5),
    "3-mass worm": chain_config([1.0, 1.0, 1.0], omega=3.0, a=0.06, phi=2.0),
}


@pytest.mark.parametrize("name", list(NO_LIFTOFF))
def test_no_liftoff_equals_strict(name):
    cfg = NO_LIFTOFF[name]
    ts = np.linspace(0.0, 30.0, 61)
    q = reference_chain_simulate(cfg, 30.0, ts, contact="strict", rtol=1e-12, atol=1e-12)
    assert not q["liftoff"]
    r = reference_hop_simulate(cfg, 30.0, ts)
    assert r["n_landings"].sum() == 0 and np.all(r["y"] == 0.0) and np.all(r["flight_time"] == 0.0)
    assert np.max(np.abs(r["x"] - q["x"])) < 1e-9
    assert np.max(np.abs(r["v"] - q["v"])) < 1e-9
    assert np.max(np.abs(r["e_d"] - q["e_d"])) < 1e-9
    assert np.max(np.abs(r["work"] - q["w"])) < 1e-9
    assert q["n_switches"] > 10  # stick-slip happened


HOPPING = {
    "paper w8 a0.12 d0.5": paper_config(omega=8.0, a=0.12, d=0.5),
    "paper w10 a0.05 d0.5": paper_config(omega=10.0, a=0.05, d=0.5),
    "paper w12 a0.08 d0.25": paper_config(omega=12.0, a=0.08, d=0.25),
    "paper w9 a0.08 d0.25": paper_config(omega=9.0, a=0.08, d=0.25),
    "3-mass w10 a0.1 phi0.5": chain_config([1.0, 1.0, 1.0], omega=10.0, a=0.1, phi=0.5),
    "3-mass unequal anisotropic w9": chain_config(
        [0.8, 1.2, 1.0], omega=9.0, a=0.1, phi=0.7, mu_s_bwd=0.9, mu_k_bwd=0.7
    ),
}


@pytest.mark.parametrize("name", list(HOPPING))
def test_energy_balance_hopping(name):
    cfg = HOPPING[name]
    strict = reference_chain_simulate(cfg, 40.0, [40.0], contact="strict")
    assert strict["liftoff"]  # the strict reading stops: these do lift off
    ts = np.linspace(0.0, 40.0, 201)
    r = reference_hop_simulate(cfg, 40.0, ts)
    print(name, "landings", r["n_landings"].tolist(), "flight fraction", np.round(r["flight_time"] / 40.0, 3).tolist())
    assert np.all(r["n_landings"] > 0)
    assert _balance(r) <= 1e-8 * (1.0 + r["e_d"][-1])
    assert np.all(np.diff(r["e_d"]) >= -1e-12)
    assert np.all(r["y"] >= 0.0)


@pytest.mark.parametrize("name", ["paper w12 a0.08 d0.25", "3-mass w10 a0.1 phi0.5"])
def test_tolerance_convergence(name):
    cfg = HOPPING[name]
    a = reference_hop_simulate(cfg, 40.0, [40.0])
    b = reference_hop_simulate(cfg, 40.0, [40.0], rtol=5e-13, atol=5e-13)
    assert np.max(np.abs(a["x"] - b["x"])) < 1e-8
    assert a["n_landings"].tolist() == b["n_landings"].tolist()
    assert a["n_landings"].sum() > 50


def test_bad_input():
    with pytest.raises(ValueError, match="restitution"):
        reference_hop_simulate(ball_config(), 1.0, [1.0], restitution=1.5)
    with pytest.raises(ValueError, match="y0"):
        reference_hop_simulate(ball_config(), 1.0, [1.0], y0=[-0.1])
    with pytest.raises(ValueError, match="zeno_speed"):
        reference_hop_simulate(ball_config(), 1.0, [1.0], zeno_speed=0.0)
