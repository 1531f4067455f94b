"""The hopping reading `contact="hop"` of a `Chain` (SPEC §10: tilted springs act along
$(u_j, d_j + y_{j+1} - y_j)$) against the independent event-driven reference `tests/reference_hop.py`,
and equal to the strict reading where nothing lifts off (issue 27).

The reference configurations hop (both or all bodies fly and land tens to hundreds of times by
t = 40) but stay well-conditioned: small hops (highest below 0.3), no body thrown high (the
paper's model at omega = 10 is, and its landings there depend on rounding). The package's RK4
error at dt = 1/800 is below 5e-7 on them (fourth order: it halves dt for a 16-fold drop).
"""

import math

import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from chain_cases import CASES as CHAIN_CASES
from reference_chain import chain_config
from reference_hop import paper_config, reference_hop_simulate
from test_against_reference import CASES as TWO_MASS_CASES, GROUPS, to_chain


T_END = 40.0
DT = 1.0 / 800
TOL = 1e-6
"""Positions, heights and e_d at every save (measured 3e-9 to 5e-7 at dt = 1/800)."""

# The paper's model near resonance (omega, a, d), as `Chain.from_params`.
PAPER = [(8.0, 0.05, 0.5), (8.0, 0.08, 0.5), (8.0, 0.1, 0.25), (8.0, 0.12, 0.25), (9.0, 0.05, 0.25),
         (9.0, 0.08, 0.25), (11.0, 0.05, 0.25), (11.0, 0.05, 0.5), (11.0, 0.08, 0.25), (12.0, 0.05, 0.5),
         (12.0, 0.08, 0.25), (12.0, 0.1, 0.25)]  # fmt: skip
# Three-mass chains (masses, omega, a, phi of the wave a sin(omega t - j phi)), d = 0.5.
THREE = [([1.0] * 3, 6.0, 0.08, 2 * math.pi / 3), ([1.0] * 3, 8.0, 0.08, -2 * math.pi / 3),
         ([0.8, 1.2, 1.0], 6.0, 0.12, -2 * math.pi / 3), ([1.0] * 3, 10.0, 0.08, 2 * math.pi / 3)]  # fmt: skip


@pytest.mark.parametrize("family", ["paper", "three"])
def test_hopping_chain_against_reference(family):
    """Positions, heights, e_d at 401 saves and the number of landings by t = 40, within 1e-6,
    on 12 configurations of the paper's model (omega 8 to 12, a 0.05 to 0.12, d = 0.5 and 0.25)
    and 4 three-mass chains, each batch one call; and `w = e_d + Delta e` on each run."""
    if family == "paper":
        cfgs = [paper_config(omega=w, a=a, d=d) for w, a, d in PAPER]
        chains = [lj.Chain.from_params(lj.Params(omega=w, a=a, d=d)) for w, a, d in PAPER]
    else:
        cfgs = [chain_config(m, omega=w, a=a, phi=phi) for m, w, a, phi in THREE]
        chains = [to_chain(c) for c in cfgs]
    ts = np.linspace(0.0, T_END, 401)
    tr = lj.simulate(lj.Chain.stack(chains), t_end=T_END, save_at=ts, contact="hop", dynamics=lj.Exact(dt=DT))
    assert tr.y is not None and tr.n_land is not None
    for i, cfg in enumerate(cfgs):
        ref = reference_hop_simulate(cfg, T_END, ts)
        dx = np.abs(np.asarray(tr.x[i]) - ref["x"]).max()
        dy = np.abs(np.asarray(tr.y[i]) - ref["y"]).max()
        ded = np.abs(np.asarray(tr.e_d[i]) - ref["e_d"]).max()
        bal = np.abs(np.asarray(tr.w[i] - tr.e_d[i] - (tr.e[i] - tr.e[i, 0]))).max()
        n_ref = int(ref["n_landings"].sum())
        print(family, i, "landings", n_ref, int(tr.n_land[i]), f"dx {dx:.2e} dy {dy:.2e} de_d {ded:.2e} bal {bal:.2e}")
        assert int(tr.status[i]) == lj.Status.OK
        assert np.all(ref["n_landings"] >= 1) and ref["max_height"].max() < 0.3  # every body hops, a little
        assert int(tr.n_land[i]) == n_ref
        assert dx < TOL and dy < TOL and ded < TOL
        assert bal <= 1e-6 * float(tr.e_d[i, -1])


def _equal_runs(chains: list[lj.Chain], start: str, t_end: float) -> None:
    ts = np.linspace(0.0, t_end, 201)
    batch = lj.Chain.stack(chains)
    a = lj.simulate(batch, t_end=t_end, save_at=ts, contact="strict", start=start)
    b = lj.simulate(batch, t_end=t_end, save_at=ts, contact="hop", start=start)
    assert np.all(np.asarray(a.status) == lj.Status.OK) and np.all(np.asarray(b.status) == lj.Status.OK)
    assert b.y is not None and np.all(np.asarray(b.y) == 0) and np.all(np.asarray(b.n_land) == 0)
    worst = 0.0
    for k in ("x", "v", "e_d", "w", "e", "N"):
        d = float(np.abs(np.asarray(getattr(a, k)) - np.asarray(getattr(b, k))).max())
        worst = max(worst, d)
        assert d <= 1e-12, k
    assert np.array_equal(np.asarray(a.stuck), np.asarray(b.stuck))
    assert np.array_equal(np.asarray(a.n_switch), np.asarray(b.n_switch))
    print(len(chains), "configurations, start", start, "max |hop - strict|", worst)


@pytest.mark.parametrize("start", ["paper", "relaxed"])
def test_two_mass_reference_cases_hop_equals_strict(start):
    """Every two-mass reference case (tests/test_against_reference.py) measured under the strict
    reading that never lifts off (27 from the paper start, 4 relaxed), as `Chain.from_params`:
    `"hop"` equals `"strict"` to 1e-12 over 40 time units (measured: 3e-17 and 0)."""
    cases = [p for g, p, kind in TWO_MASS_CASES if kind != "liftoff" and GROUPS[g][:2] == ("strict", start)]
    assert len(cases) >= 4
    _equal_runs([lj.Chain.from_params(lj.Params(**p)) for p in cases], start, 40.0)


def test_chain_reference_cases_hop_equals_strict():
    """Every chain reference case (tests/chain_cases.py: none lifts off) under the strict reading,
    grouped by structure (one batch per number of masses, friction law, actuator and start)."""
    groups: dict[tuple, list[lj.Chain]] = {}
    for case in CHAIN_CASES:
        if case["contact"] != "strict":
            continue
        chain = to_chain(chain_config(**case["config"]))
        key = (chain.n_masses, type(chain.friction), type(chain.actuator), chain.waves.cos.shape, case["start"])
        groups.setdefault(key, []).append(chain)
    assert sum(len(g) for g in groups.values()) >= 10
    for key, chains in groups.items():
        _equal_runs(chains, key[-1], 20.0)


def test_measure_hop_against_reference():
    """`measure(..., contact="hop")` over [0, 40] of two hopping configurations of the paper's
    model (one batch): the flight fraction per body, landings per period and highest hop equal
    the reference's flight time / 40, landings / (40 omega / 2 pi) and highest height to 1e-6;
    the energy balance $|w - e_d - \\Delta e| \\le 10^{-6} e_d$; outside "hop" the fields are None."""
    cfgs = [(9.0, 0.08, 0.25), (12.0, 0.05, 0.5)]
    chains = lj.Chain.stack([lj.Chain.from_params(lj.Params(omega=w, a=a, d=d)) for w, a, d in cfgs])
    kw = dict(z=1e3, horizon=T_END, window=T_END, t_start=0.0, dynamics=lj.Exact(dt=DT))
    m = lj.measure(chains, contact="hop", **kw)  # type: ignore[arg-type]
    assert m.flight_fraction is not None and m.landings_per_period is not None and m.highest_hop is not None
    assert m.flight_fraction.shape == (2, 2) and m.highest_hop.shape == (2, 2) and m.landings_per_period.shape == (2,)
    for i, (w, a, d) in enumerate(cfgs):
        ref = reference_hop_simulate(paper_config(omega=w, a=a, d=d), T_END, [T_END])
        got = (np.asarray(m.flight_fraction[i]), float(m.landings_per_period[i]), np.asarray(m.highest_hop[i]))
        want = (ref["flight_time"] / T_END, ref["n_landings"].sum() / (T_END * w / (2 * math.pi)), ref["max_height"])
        print("measure hop", i, got, want, "balance / e_d", float(m.balance[i] / m.e_d[i]))
        assert int(m.status[i]) == lj.Status.OK and float(m.e_d[i]) > 0
        np.testing.assert_allclose(got[0], want[0], rtol=0, atol=TOL)
        assert abs(got[1] - want[1]) < TOL
        np.testing.assert_allclose(got[2], want[2], rtol=0, atol=TOL)
        assert abs(float(m.balance[i])) <= 1e-6 * float(m.e_d[i])
    strict = lj.measure(lj.Chain(masses=[1.0, 1.0, 1.0]), z=0.5, horizon=20.0, window=5.0, t_start=0.0)
    assert strict.flight_fraction is None and strict.highest_hop is None and "flight_fraction" not in strict.to_numpy()


def test_measure_hop_mechanism_energy_balance():
    """A two-body `Mechanism` whose body 0 is thrown up and lands (partly elastic) while an actuated
    spring drives it: `measure` under "hop" balances energy to 1e-6 e_d; body 0 flies, body 1
    (never leaving the ground: its springs are horizontal) does not."""
    wave = lj.Sinusoid(a=0.3, omega=2.0, lbar=1.0)
    M = lj.Mechanism(
        masses=[1.0, 0.8], friction=[lj.Coulomb(0.5, 0.3), lj.Coulomb(0.6, 0.4)],
        links=[lj.Spring(0, 1, k=4.0, rest=wave)], c=[0.05, 0.02], x0=[0.0, 1.0], y0=[0.4, 0.0], w0=[0.5, 0.0],
        restitution=[0.6, 0.0],
    )  # fmt: skip
    m = lj.measure(M, z=1e3, horizon=20.0, window=20.0, t_start=0.0, contact="hop")
    assert m.flight_fraction is not None and m.highest_hop is not None and m.landings_per_period is not None
    print("mechanism hop", m.flight_fraction, m.landings_per_period, m.highest_hop, float(m.balance / m.e_d))
    assert int(m.status) == lj.Status.OK
    # Thrown from 0.4 at 0.5 upwards: the top is 0.4 + 0.5^2 / 2 = 0.525 (free fall, no vertical force).
    assert abs(float(m.highest_hop[0]) - 0.525) < 1e-12 and float(m.highest_hop[1]) == 0
    # Its flights in closed form: up and down to the first landing at speed w1, then rebounds
    # e^k w1 while faster than the Zeno speed 1e-3 (each flight 2 e^k w1 long), all before t = 20.
    w1, e = math.sqrt(2 * 0.525), 0.6
    rebounds = [e**k * w1 for k in range(1, 60) if e**k * w1 >= 1e-3]
    flight = 0.5 + w1 + sum(2 * q for q in rebounds)
    landings = 1 + len(rebounds)
    assert abs(float(m.flight_fraction[0]) - flight / 20.0) < 1e-10 and float(m.flight_fraction[1]) == 0
    assert abs(float(m.landings_per_period) - landings / (20.0 * 2.0 / (2 * math.pi))) < 1e-12
    assert abs(float(m.balance)) <= 1e-6 * float(m.e_d)


def test_jvp_through_liftoff_and_landing_against_reference():
    """`jax.jvp` in the actuation amplitude `a` of positions and heights at t = 3 and 6, through
    every lift-off and landing on the way (5 configurations of the paper's model, one batch),
    against the reference's central differences (step 1e-5): relative agreement 1e-5 (measured:
    below 1e-7 of the larger derivatives, which reach 140)."""
    cfgs = [(9.0, 0.08, 0.25), (12.0, 0.05, 0.5), (8.0, 0.1, 0.25), (11.0, 0.05, 0.25), (8.0, 0.08, 0.5)]
    t_end, ts = 6.0, np.array([3.0, 6.0])
    omega, d = (jnp.asarray([c[k] for c in cfgs]) for k in (0, 2))

    def f(a):
        chain = lj.Chain.from_params(lj.Params(omega=omega, a=a, d=d))
        tr = lj.simulate(chain, t_end=t_end, save_at=ts, contact="hop", dynamics=lj.Exact(dt=DT))
        assert tr.y is not None and tr.n_land is not None
        return jnp.concatenate([tr.x, tr.y], -1), tr.n_land

    a0 = jnp.asarray([c[1] for c in cfgs])
    (_, n_land), (tangent, _) = jax.jvp(f, (a0,), (jnp.ones_like(a0),))
    eps = 1e-5
    for i, (w, a, dd) in enumerate(cfgs):
        hi, lo = (reference_hop_simulate(paper_config(omega=w, a=a + s, d=dd), t_end, ts) for s in (eps, -eps))
        fd = np.concatenate([hi["x"] - lo["x"], hi["y"] - lo["y"]], -1) / (2 * eps)
        got = np.asarray(tangent[i])
        err = np.abs(got - fd).max() / max(1.0, np.abs(fd).max())
        print("jvp", i, "landings", int(n_land[i]), "max |d|", np.abs(fd).max(), "relative error", err)
        assert int(n_land[i]) >= 2 and np.abs(fd).max() > 1.0  # it hops, and the derivative is not trivially small
        assert err < 1e-5


def test_grazing_liftoff_does_not_stall_a_coarse_step():
    """Where a body's normal force grazes 0 at a located lift-off, the body is airborne at height 0
    with no vertical velocity, and its landing would be located at the step's start: before, a flight
    of no length repeated at one instant (tens of thousands of landings, `Status.MAX_STEPS`), on
    these very chains at dt = 0.03 (simulate and measure) and 0.01 (measure). Now their landings
    by t = 40 are those of dt = 1/800, positions within 0.02 of its run (measured 0.012) and heights
    within 1e-3 (5e-4; RK4 at a coarse step), and w = e_d + Delta e to 1e-3 of e_d (its truncation
    error: 1e-4 to 6e-4, the largest on a chain that ran before too)."""
    chains = lj.Chain.stack([to_chain(chain_config(m, omega=w, a=a, phi=phi)) for m, w, a, phi in THREE])
    ts = np.linspace(0.0, T_END, 401)
    fine = lj.simulate(chains, T_END, ts, contact="hop", dynamics=lj.Exact(dt=DT))
    coarse = lj.simulate(chains, T_END, ts, contact="hop", dynamics=lj.Exact(dt=0.03))
    assert fine.y is not None and coarse.y is not None and coarse.n_land is not None and fine.n_land is not None
    dx = np.abs(np.asarray(coarse.x - fine.x)).max()
    dy = np.abs(np.asarray(coarse.y - fine.y)).max()
    bal = np.abs(np.asarray(coarse.w - coarse.e_d - (coarse.e - coarse.e[:, :1]))).max(-1) / np.asarray(
        coarse.e_d[:, -1]
    )
    print("dt 0.03: landings", np.asarray(coarse.n_land), np.asarray(fine.n_land), "dx", dx, "dy", dy, "balance", bal)
    assert np.all(np.asarray(coarse.status) == lj.Status.OK)
    np.testing.assert_array_equal(np.asarray(coarse.n_land), np.asarray(fine.n_land))
    assert dx < 0.02 and dy < 1e-3
    assert np.all(bal <= 1e-3)
    for dt in (0.01, 0.03):
        m = lj.measure(chains, z=0.3, horizon=T_END, t_start=5.0, contact="hop", dynamics=lj.Exact(dt=dt))
        print("measure at dt", dt, np.asarray(m.status), np.asarray(m.n_steps))
        assert np.all(np.asarray(m.status) == lj.Status.OK) and np.all(np.asarray(m.n_steps) < 5 * T_END / dt)
