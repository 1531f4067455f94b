"""Self-checks of the independent N-mass chain reference (tests/reference_chain.py), without the package.

* N = 2 against the independent two-mass reference (tests/reference.py): trajectories,
  dissipated energy, tau_5 and e_5, in the SSL and SL regimes and with paper contact;
* the energy balance ``w = e_d + e(t2) - e(t1)`` for N = 3, 4, 6 with every friction law and actuator;
* the symmetries of SPEC section 8 as they hold exactly (maps of the whole configuration), and a case
  showing that at d = 0 with isotropic friction a chain of N >= 3 can still crawl;
* simultaneous switches of four masses, lift-off location, the default ``t_start`` and bad input.
"""

import math
from collections import Counter

import numpy as np
import pytest
from reference import reference_measure, reference_simulate
from reference_chain import (
    chain_config,
    default_t_start,
    lowest_natural_frequency,
    reference_chain_measure,
    reference_chain_simulate,
)


# -- N = 2 against tests/reference.py -------------------------------------------------------------
# (two-mass params, contact, start, expected regime): SSL, SL with paper contact through lift-off, SSL relaxed.
TWO_MASS_CASES = [
    (dict(omega=2.0), "strict", "paper", "SSL"),
    (dict(omega=9.5, mhat=0.55, d=0.35, a=0.06), "paper", "relaxed", "SL"),
    (dict(omega=4.0, mhat=0.6, d=0.4, a=0.07, mu_s=0.9), "strict", "relaxed", "SSL"),
]


def _two_mass_config(p: dict) -> dict:
    """The chain configuration of tests/reference.py's parameters (m1 = 2 mhat, m2 = 2 (1 - mhat))."""
    mhat = p.get("mhat", 0.5)
    return chain_config(
        [2.0 * mhat, 2.0 * (1.0 - mhat)],
        k=p.get("k", 50.0),
        d=p.get("d", 0.5),
        lbar=p.get("lbar", 3.0),
        c=p.get("c", 0.01),
        omega=p["omega"],
        a=p.get("a", 0.05),
        mu_s_fwd=p.get("mu_s", 0.7),
        mu_k_fwd=p.get("mu_k", 0.5),
    )


@pytest.mark.parametrize("params, contact, start, regime", TWO_MASS_CASES)
def test_two_masses_match_two_mass_reference(params, contact, start, regime):
    """x, v, e_d at saved times (1e-7 absolute) and tau_5, e_5 (1e-7 relative) equal tests/reference.py's."""
    cfg = _two_mass_config(params)
    ts = np.linspace(0.0, 30.0, 61)
    r = reference_simulate(params, 30.0, save_at=ts, contact=contact, start=start)
    q = reference_chain_simulate(cfg, 30.0, ts, contact=contact, start=start)
    for key, col in (("x1", ("x", 0)), ("x2", ("x", 1)), ("v1", ("v", 0)), ("v2", ("v", 1))):
        assert np.max(np.abs(q[col[0]][:, col[1]] - r[key])) < 1e-7, key
    assert np.max(np.abs(q["e_d"] - r["e_d"])) < 1e-7
    assert q["liftoff"] == r["liftoff"]

    rm = reference_measure(params, z=5.0, contact=contact, start=start)
    qm = reference_chain_measure(cfg, z=5.0, contact=contact, start=start)
    assert qm["t_start"] == pytest.approx(rm["t_start"], rel=1e-14)
    assert rm["reached"] and qm["reached"]
    assert qm["tau_z"] == pytest.approx(rm["tau_z"], rel=1e-7)
    assert qm["e_z"] == pytest.approx(rm["e_z"], rel=1e-7)
    assert qm["regime"] == regime and rm["regime"] == (1 if regime == "SSL" else 0)
    assert qm["stick_fraction"] == pytest.approx([rm["stick_fraction1"], rm["stick_fraction2"]], abs=1e-7)
    assert qm["work"] == pytest.approx(qm["e_d"] + qm["delta_e"], abs=1e-8)


def test_default_t_start():
    """80 periods of the lowest frequency with one mass held: N = 2 gives min(sqrt(k/m1), sqrt(k/m2));
    N = 3 equal masses: holding an end leaves a fixed-free pair, omega^2 = (k/m)(3 - sqrt 5)/2."""
    cfg2 = chain_config([0.8, 1.2], k=50.0)
    assert default_t_start(cfg2) == pytest.approx(80 * 2 * math.pi / min(math.sqrt(50 / 0.8), math.sqrt(50 / 1.2)))
    cfg3 = chain_config([1.0, 1.0, 1.0], k=50.0)
    assert lowest_natural_frequency(cfg3) == pytest.approx(math.sqrt(50.0 * (3 - math.sqrt(5)) / 2), rel=1e-12)


# -- energy balance ---------------------------------------------------------------------------------
ENERGY_CASES = {
    "N3 coulomb travelling wave": dict(masses=[1.0, 1.0, 1.0], omega=3.0, a=0.06, phi=2.0),
    "N4 anisotropic, unequal": dict(
        masses=[0.8, 1.2, 1.0, 0.9],
        k=[50.0, 60.0, 45.0],
        d=[0.5, -0.3, 0.2],
        c=[0.01, 0.02, 0.0, 0.05],
        omega=5.0,
        a=0.08,
        phi=-1.2,
        mu_s_fwd=0.6,
        mu_s_bwd=0.9,
        mu_k_fwd=0.4,
        mu_k_bwd=0.7,
    ),
    "N6 stribeck two harmonics": dict(
        masses=[1.0] * 6,
        omega=2.5,
        wave_A=[[0.02, 0.01]] * 5,
        wave_B=[[0.05, -0.02], [0.0, 0.03], [-0.05, 0.0], [0.03, 0.01], [0.04, -0.01]],
        friction="stribeck",
        v_s=0.1,
        mu_s_fwd=0.8,
        mu_k_fwd=0.4,
    ),
    "N4 force actuator anisotropic": dict(
        masses=[1.0, 1.0, 1.0, 1.0],
        omega=2.0,
        a=1.5,
        phi=1.0,
        actuator="force",
        mu_s_bwd=0.9,
        mu_k_bwd=0.7,
    ),
}


@pytest.mark.parametrize("name", list(ENERGY_CASES))
def test_energy_balance(name):
    """w = e_d + e(t) - e(0) to 1e-8, with w integrated from the actuator power and e_d from the friction."""
    cfg = chain_config(**ENERGY_CASES[name])
    r = reference_chain_simulate(cfg, 40.0, np.linspace(0.0, 40.0, 201), contact="paper")
    balance = r["w"] - r["e_d"] - (r["e"] - r["e"][0])
    assert np.max(np.abs(balance)) < 1e-8
    # Not vacuous: energy was dissipated, masses stuck and slipped, and e_d never decreases.
    assert r["e_d"][-1] > 1.0
    assert np.all(np.diff(r["e_d"]) >= -1e-12)
    assert r["n_switches"] > 10
    # A stuck mass is exactly at rest in every sample.
    assert np.all(r["v"][r["stuck"]] == 0.0)


def test_tolerance_convergence_chain():
    """N = 4, anisotropic, d != 0, stick-slip: positions at rtol 1e-8 and 1e-10 agree with rtol 1e-12 (to 1e-6
    and 1e-8), so the located events and the segments between them converge with the tolerance."""
    cfg = chain_config(**ENERGY_CASES["N4 anisotropic, unequal"])
    ts = np.linspace(0.0, 30.0, 61)
    runs = {rtol: reference_chain_simulate(cfg, 30.0, ts, contact="paper", rtol=rtol) for rtol in (1e-8, 1e-10, 1e-12)}
    err = {rtol: np.max(np.abs(runs[rtol]["x"] - runs[1e-12]["x"])) for rtol in (1e-8, 1e-10)}
    assert err[1e-8] < 1e-6 and err[1e-10] < 1e-8
    assert runs[1e-8]["n_switches"] == runs[1e-12]["n_switches"] > 10


# -- symmetries --------------------------------------------------------------------------------------
def _mirror(kw: dict) -> dict:
    """The mirror image x -> -x of a configuration with d = 0: masses and springs in reverse order,
    forward and backward friction coefficients swapped (the paper start maps onto itself)."""
    out = dict(kw)
    out["masses"] = kw["masses"][::-1]
    for key in ("k", "lbar", "c"):
        if np.ndim(kw.get(key, 0.0)):
            out[key] = kw[key][::-1]
    for key in ("wave_A", "wave_B"):
        if key in kw:
            out[key] = np.asarray(kw[key])[::-1]
    out["mu_s_fwd"], out["mu_s_bwd"] = kw.get("mu_s_bwd", kw.get("mu_s_fwd", 0.7)), kw.get("mu_s_fwd", 0.7)
    out["mu_k_fwd"], out["mu_k_bwd"] = kw.get("mu_k_bwd", kw.get("mu_k_fwd", 0.5)), kw.get("mu_k_fwd", 0.5)
    return out


def _run(kw: dict, t_end=60.0):
    return reference_chain_simulate(chain_config(**kw), t_end, np.linspace(0.0, t_end, 241))


def _wave(n_springs: int, a: float, phi: float):
    """Coefficients of a sin(omega t - j phi) per spring, as (A, B) columns."""
    j = np.arange(n_springs)
    return (-a * np.sin(j * phi))[:, None], (a * np.cos(j * phi))[:, None]


def test_d0_isotropic_symmetric_waveform_centre_of_mass_fixed():
    """d = 0, equal masses, isotropic friction, a waveform symmetric under the mirror (s_j = s_{N-2-j}),
    N = 5 with two harmonics: the motion is its own mirror image, so X stays at X(0) (to 1e-9)."""
    A = np.array([[0.02, 0.01], [-0.03, 0.02], [-0.03, 0.02], [0.02, 0.01]])
    B = np.array([[0.06, 0.0], [0.02, -0.01], [0.02, -0.01], [0.06, 0.0]])
    r = _run(dict(masses=[1.0] * 5, d=0.0, omega=2.0, wave_A=A, wave_B=B))
    assert np.max(np.abs(r["X"] - r["X"][0])) < 1e-9
    assert r["n_switches"] > 20 and np.max(np.abs(r["v"])) > 0.05  # the masses do move


def test_d0_isotropic_travelling_wave_and_its_reverse_mirror():
    """d = 0, isotropic: a travelling wave (N = 4, phi = pi/2) displaces the centre of mass (it has no
    mirror symmetry of its own), and the wave with the spring order reversed gives exactly the mirror motion."""
    A, B = _wave(3, 0.08, math.pi / 2)
    kw = dict(masses=[1.0] * 4, d=0.0, omega=2.0, wave_A=A, wave_B=B)
    r, rm = _run(kw), _run(_mirror(kw))
    dX, dXm = r["X"] - r["X"][0], rm["X"] - rm["X"][0]
    assert np.max(np.abs(dX)) > 1e-3
    assert np.max(np.abs(dX + dXm)) < 1e-9
    assert np.max(np.abs(r["v"] + rm["v"][:, ::-1])) < 1e-9


def test_swapping_friction_directions_mirrors_the_motion():
    """d = 0, symmetric chain and waveform, anisotropic friction: the chain crawls (towards its easy
    direction), and swapping forward and backward coefficients gives X - X(0) -> -(X - X(0)) (to 1e-9)."""
    kw = dict(masses=[1.0] * 4, d=0.0, omega=2.0, a=0.08, phi=0.0, mu_s_bwd=0.9, mu_k_bwd=0.7)
    r, rm = _run(kw), _run(_mirror(kw))
    dX, dXm = r["X"] - r["X"][0], rm["X"] - rm["X"][0]
    assert dX[-1] > 0.1  # backward friction is larger: forward motion
    assert np.max(np.abs(dX + dXm)) < 1e-9


def test_d0_reversed_negated_waveform_keeps_the_motion_and_swapped_friction_mirrors_it():
    """d = 0 makes every spring force affine in the gaps (l_j = u_j), so relabelling the masses in reverse order
    with every waveform negated (s'_j = -s_{N-2-j}, friction unchanged) is an exact symmetry that keeps
    X - X(0): the direction of a travelling wave does not pick the direction of motion.  Reversing the
    spring order and swapping forward and backward friction instead is the mirror x -> -x."""
    A, B = _wave(3, 0.08, 1.0)
    kw = dict(masses=[1.0] * 4, d=0.0, omega=2.0, wave_A=A, wave_B=B, mu_s_bwd=0.9, mu_k_bwd=0.7)
    r = _run(kw)
    rr = _run(dict(kw, wave_A=-A[::-1], wave_B=-B[::-1]))
    rm = _run(_mirror(kw))
    dX, dXr, dXm = (q["X"] - q["X"][0] for q in (r, rr, rm))
    assert dX[-1] > 0.5  # backward friction is larger: forward motion
    assert np.max(np.abs(dXr - dX)) < 1e-9
    assert np.max(np.abs(rr["v"] - r["v"][:, ::-1])) < 1e-9
    assert np.max(np.abs(dXm + dX)) < 1e-9


def test_d0_isotropic_two_harmonic_wave_locomotes():
    """d = 0, equal masses, isotropic friction, N = 3: a travelling wave with a second harmonic
    (s(t + T/2) != -s(t), so the two symmetries above do not force zero drift) crawls steadily
    (about -0.025 per time unit here): "no waveform moves the centre of mass" holds for N = 2 and for
    mirror-symmetric waveforms, not for every waveform."""
    j = np.arange(2)
    phi, a1, a2 = 2 * math.pi / 3, 0.06, 0.05
    A = np.stack([-a1 * np.sin(j * phi), a2 * np.sin(math.pi / 3 - 2 * j * phi)], axis=1)
    B = np.stack([a1 * np.cos(j * phi), a2 * np.cos(math.pi / 3 - 2 * j * phi)], axis=1)
    r = _run(dict(masses=[1.0] * 3, d=0.0, omega=3.0, wave_A=A, wave_B=B), t_end=100.0)
    dX = r["X"] - r["X"][0]
    assert dX[-1] < -1.5
    assert np.all(np.diff(dX[r["t"] >= 40.0][::20]) < 0.0)  # steady drift, not a transient shift


def test_simultaneous_switch_of_four_masses():
    """Masses (1, 2, 2, 1), d = 0, s_0 = s_2 = -s_1: while all are stuck F = (-ks, 2ks, -2ks, ks), so all four
    reach their static limits (mu_s m_i) at one instant.  The run ends without a RuntimeError, the four
    switches share one time, and the centre of mass stays put (the configuration is mirror-symmetric)."""
    r = reference_chain_simulate(
        chain_config([1.0, 2.0, 2.0, 1.0], d=0.0, omega=2.0, wave_B=[[0.1], [-0.1], [0.1]]),
        60.0,
        np.linspace(0.0, 60.0, 241),
    )
    switches = [(t, kind) for t, kind in r["events"] if "reverse" not in kind]
    times = np.array([t for t, _ in switches])
    first = [kind for t, kind in switches if t == times[0]]
    assert sorted(first) == ["m0 stick->slip bwd", "m1 stick->slip fwd", "m2 stick->slip bwd", "m3 stick->slip fwd"]
    assert max(Counter(times.tolist()).values()) >= 4
    assert r["n_switches"] > 100
    assert np.max(np.abs(r["X"] - r["X"][0])) < 1e-9


# -- lift-off ------------------------------------------------------------------------------------------
def _normal_forces(cfg: dict, t: float, x: np.ndarray) -> np.ndarray:
    """N_i = m_i - fy_i + fy_{i-1} of the conventions, written out here for the check."""
    A, B, om = cfg["A"], cfg["B"], cfg["omega"]
    n = np.arange(1, A.shape[1] + 1)
    s = A @ np.cos(n * om * t) + B @ np.sin(n * om * t)
    u = np.diff(x)
    ell = np.sqrt(u**2 + cfg["d"] ** 2)
    fy = cfg["k"] * (ell - cfg["lbar"] - s) * cfg["d"] / ell
    return cfg["m"] - np.append(fy, 0.0) + np.insert(fy, 0, 0.0)


def test_strict_liftoff_is_located_and_paper_contact_continues():
    """N = 3, d = 0.5, a = 0.1 at omega = 10: strict contact stops at the first N_i = 0 (located there),
    paper contact integrates through with the same lift-off time and a closed energy balance."""
    cfg = chain_config([1.0, 1.0, 1.0], d=0.5, omega=10.0, a=0.1, phi=1.0)
    rs = reference_chain_simulate(cfg, 3.0, np.linspace(0.0, 3.0, 61), contact="strict")
    assert rs["status"] == "liftoff" and rs["liftoff"]
    assert 0.0 < rs["t_liftoff"] < 2 * (2 * math.pi / 10.0)
    assert rs["valid_until"] == rs["t_liftoff"]
    x_off = rs["x"][-1]
    assert abs(np.min(_normal_forces(cfg, rs["t_liftoff"], x_off))) < 1e-9
    early = rs["t"] < rs["t_liftoff"] - 1e-3
    assert all(np.min(_normal_forces(cfg, t, x)) > 0.0 for t, x in zip(rs["t"][early], rs["x"][early]))
    rp = reference_chain_simulate(cfg, 3.0, np.linspace(0.0, 3.0, 61), contact="paper")
    assert rp["liftoff"] and rp["valid_until"] == 3.0
    assert rp["t_liftoff"] == pytest.approx(rs["t_liftoff"], abs=1e-12)
    assert np.max(np.abs(rp["w"] - rp["e_d"] - (rp["e"] - rp["e"][0]))) < 1e-8
    m = reference_chain_measure(cfg, t_start=1.0, horizon=10.0, contact="strict")
    assert m["liftoff"] and not m["reached"] and m["tau_z"] == math.inf and m["regime"] is None


# -- bad input -------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "kw, match",
    [
        (dict(masses=[1.0, -1.0, 1.0]), r"masses\[1\]"),
        (dict(masses=[1.0, 1.0, 1.0], k=[50.0, 0.0]), r"k\[1\]"),
        (dict(masses=[1.0, 1.0, 1.0], k=[50.0, 50.0, 50.0]), "k must"),
        (dict(masses=[1.0, 1.0], mu_s_fwd=0.4, mu_k_fwd=0.5), r"mu_s_fwd\[0\] >= mu_k_fwd\[0\]"),
        (dict(masses=[1.0, 1.0, 1.0], mu_s_bwd=[0.7, 0.3, 0.7], mu_k_bwd=0.5), r"mu_s_bwd\[1\]"),
        (dict(masses=[1.0, 1.0], d=3.0), r"d\[0\]"),
        (dict(masses=[1.0, 1.0], friction="stribeck"), "v_s"),
        (dict(masses=[1.0, 1.0], actuator="torque"), "actuator"),
    ],
)
def test_bad_input(kw, match):
    with pytest.raises(ValueError, match=match):
        chain_config(**kw)
