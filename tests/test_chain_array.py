"""The array layout of a chain (`Chain(..., layout="array")`, `model._chain_array`) against the unrolled
one (the same engine on one scalar per mass), against the independent chain reference
(`tests/reference_chain.py`, an event-driven scipy solver sharing no code with the package), and
its error paths: a bad configuration in a batch, forward-mode derivatives through the events, steady
gaits, what the array layout refuses, and what `layout="auto"` picks."""

from typing import Any

import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from chain_cases import ANISO
from locomotion_jax.dynamics import _smoothed, _smoothed_dynamics
from locomotion_jax.gaits import _shooting as cg
from locomotion_jax.gaits._element_orbit import gait_physics
from locomotion_jax.model._chain_array import (
    ARRAY_FROM,
    array_from,
    ARRAY_FROM_ACCELERATOR,
    ArrayChainPhysics,
    engine_physics,
    GAIT_ARRAY_FROM,
)
from locomotion_jax.model._chain_physics import ChainPhysics
from reference_chain import chain_config, reference_chain_simulate
from reference_hop import reference_hop_simulate


RTOL = 1e-10
"""The layouts run the same formulas; sums over masses are summed in another order (float64)."""

RTOL32 = 2e-4
"""float32: the same runs agree to its rounding accumulated over a few thousand steps."""


def _worm(n: int, layout: str, dtype=jnp.float64, **kw) -> lj.Chain:
    """Two worms of `n` masses on bristles (anisotropic Coulomb), a travelling wave towards the head,
    unequal masses and offsets of both signs, so that every mass and spring differs."""
    base = np.linspace(0.9, 1.2, n)
    masses = np.stack([base, base[::-1]]).astype(dtype)
    d = np.where(np.arange(n - 1) % 2 == 0, 0.4, -0.3).astype(dtype)
    return lj.Chain(
        masses=masses, k=np.linspace(40.0, 60.0, n - 1).astype(dtype), d=d, lbar=3.0, c=0.02,
        waveforms=lj.TravellingWave(a=0.06, omega=3.0, phi=2 * np.pi / 3),
        friction=lj.AnisotropicCoulomb(0.7, 0.9, 0.5, 0.7), layout=layout, **kw,
    )  # fmt: skip


def _close(a, b, rtol):
    a, b = np.asarray(a, float), np.asarray(b, float)
    assert a.shape == b.shape
    scale = np.maximum(np.abs(a), 1e-12)
    same = a == b  # an infinite value (a target not reached) equal in both
    with np.errstate(invalid="ignore"):
        err = np.where(same, 0.0, np.abs(a - b) / scale)
    np.testing.assert_array_less(err, rtol)


MEASURED = ("tau_z", "e_z", "e_d", "work", "mean_speed", "X_start", "stick_fraction")


@pytest.mark.parametrize("contact", ["strict", "paper"])
@pytest.mark.parametrize("n", [2, 3, 5])
def test_array_layout_equals_unrolled(n, contact):
    """`measure`: the centre of mass (X at the start, the time to z, the mean speed), e_d, w and the
    stick fractions of both layouts agree to 1e-10 relative, with the same step and switch counts."""
    kw: dict[str, Any] = dict(z=0.5, t_start=4.0, horizon=40.0, contact=contact)
    got = lj.measure(_worm(n, "array"), **kw).to_numpy()
    ref = lj.measure(_worm(n, "unrolled"), **kw).to_numpy()
    assert np.all(ref["status"] == lj.Status.OK) and np.all(got["status"] == lj.Status.OK)
    assert np.all(ref["reached"]) and np.all(ref["stick_fraction"] > 0.01)  # the runs stick and slip
    for key in MEASURED:
        _close(got[key], ref[key], RTOL)
    np.testing.assert_array_equal(got["n_steps"], ref["n_steps"])
    np.testing.assert_array_equal(got["n_switch"], ref["n_switch"])
    assert got["stick_fraction"].shape == (2, n)


def test_array_layout_stribeck_and_force_actuator_equal_unrolled():
    """The other friction law and actuator: Stribeck friction (a kinetic coefficient with its own rate)
    under the internal-force actuator (power through the force terms), paper contact."""
    fr = lj.Stribeck(0.7, 0.5, 0.1, mu_s_bwd=0.9, mu_k_bwd=0.7)
    waves = lj.TravellingWave(a=3.0, omega=2.0, phi=2 * np.pi / 3)
    kw: dict[str, Any] = dict(z=0.3, t_start=4.0, horizon=40.0, contact="paper")
    out = {}
    for layout in ("array", "unrolled"):
        C = lj.Chain(masses=[[1.0, 1.1, 0.9], [0.9, 1.0, 1.2]], d=0.0, lbar=3.0, waveforms=waves, friction=fr,
                     actuator=lj.InternalForce(), layout=layout)  # fmt: skip
        out[layout] = lj.measure(C, **kw).to_numpy()
    got, ref = out["array"], out["unrolled"]
    assert np.all(ref["status"] == lj.Status.OK) and np.all(ref["reached"])
    assert np.all(ref["stick_fraction"].max(-1) > 0.01) and np.all(ref["work"] > 0)
    for key in MEASURED:
        _close(got[key], ref[key], RTOL)


def test_array_layout_simulate_equals_unrolled():
    """`simulate`: positions, velocities, X, e_d, w, modes, normal forces and tensions at the saves."""
    ts = np.linspace(0.0, 20.0, 41)
    got = lj.simulate(_worm(5, "array"), 20.0, ts, contact="paper")
    ref = lj.simulate(_worm(5, "unrolled"), 20.0, ts, contact="paper")
    for key in ("x", "v", "X", "e_d", "w", "e", "N", "tension", "rest_length"):
        a, b = np.asarray(getattr(ref, key)), np.asarray(getattr(got, key))
        np.testing.assert_allclose(b, a, rtol=RTOL, atol=RTOL * np.abs(a).max(), err_msg=key)
    np.testing.assert_array_equal(np.asarray(got.stuck), np.asarray(ref.stuck))
    assert np.asarray(got.stuck).any() and not np.asarray(got.stuck).all()


def test_array_layout_float32_equals_unrolled():
    kw: dict[str, Any] = dict(z=0.5, t_start=4.0, horizon=40.0, dtype=jnp.float32)
    got = lj.measure(_worm(3, "array", jnp.float32), **kw).to_numpy()
    ref = lj.measure(_worm(3, "unrolled", jnp.float32), **kw).to_numpy()
    assert got["e_d"].dtype == np.float32 and np.all(got["status"] == lj.Status.OK)
    for key in ("tau_z", "e_d", "work", "mean_speed"):
        _close(got[key], ref[key], RTOL32)
    np.testing.assert_allclose(got["stick_fraction"], ref["stick_fraction"], atol=RTOL32)


def test_array_layout_eight_mass_worm_against_reference():
    """An 8-mass worm on bristles in the array layout against the independent reference: positions,
    e_d and w over time. At dt = 0.01 the positions differ by up to 6e-6 (RK4's error, that of the unrolled
    layout); at dt = 0.005 by 16x less, within 1e-6."""
    n, omega, a, phi = 8, 3.0, 0.05, 2 * np.pi / 3
    fr: dict[str, Any] = dict(ANISO)
    cfg = chain_config([1.0] * n, k=50.0, d=0.5, lbar=3.0, c=0.01, omega=omega, a=a, phi=phi, **fr)
    chain = lj.Chain(masses=[1.0] * n, k=50.0, d=0.5, lbar=3.0, c=0.01,
                     waveforms=lj.SpringFourier(cfg["A"], cfg["B"], cfg["omega"]),
                     friction=lj.AnisotropicCoulomb(**ANISO), layout="array")  # fmt: skip
    assert isinstance(engine_physics(chain), ArrayChainPhysics)
    ts = np.linspace(0.0, 30.0, 61)
    ref = reference_chain_simulate(cfg, 30.0, ts)
    tr = lj.simulate(chain, 30.0, ts, dynamics=lj.Exact(dt=0.005))
    assert int(tr.status) == lj.Status.OK and ref["status"] == "ok"
    np.testing.assert_allclose(np.asarray(tr.x), ref["x"], atol=1e-6)
    np.testing.assert_allclose(np.asarray(tr.e_d), ref["e_d"], rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(np.asarray(tr.w), ref["w"], rtol=1e-5, atol=1e-7)
    assert float(np.ptp(np.asarray(tr.X))) > 0.01 and np.asarray(tr.stuck).any()  # it crawls, sticking


SMOOTH_RTOL = 1e-8
"""The smoothed engine's runs in both layouts at diffrax tolerances rtol 1e-10, atol 1e-12: the step-size
controller follows each layout's rounding, so the runs agree to the solver's error (measured 1e-9),
not to the rounding of the right-hand side (which agrees to 1e-13)."""


@pytest.mark.parametrize("contact", ["strict", "paper"])
def test_array_layout_smoothed_rates_equal_unrolled(contact):
    """The smoothed engine's right-hand side and smallest normal force (`_smoothed.rates_and_normal`)
    on the array layout's one entry over the masses equal the unrolled layout's, at random states of a
    5-mass worm on bristles and of a Stribeck chain under the force actuator."""
    stribeck = lambda layout: lj.Chain(
        masses=[1.0, 1.1, 0.9, 1.2, 0.8], d=0.1, lbar=3.0, friction=lj.Stribeck(0.7, 0.5, 0.1),
        waveforms=lj.TravellingWave(a=3.0, omega=2.0, phi=1.0), actuator=lj.InternalForce(), layout=layout,
    )  # fmt: skip
    rng = np.random.default_rng(3)
    for chain in (lambda layout: _worm(5, layout)[0], stribeck):
        Pa, Pu = engine_physics(chain("array")), engine_physics(chain("unrolled"))
        assert isinstance(Pa, ArrayChainPhysics) and isinstance(Pu, ChainPhysics)
        for _ in range(5):
            x = 3.0 * np.arange(5) + rng.normal(0.0, 0.3, 5)
            y = jnp.asarray(np.concatenate([x, rng.normal(0.0, 0.5, 5), [0.3, 0.4]]))
            t, eps = jnp.asarray(rng.uniform(0, 10)), jnp.asarray(1e-3)
            got = _smoothed.rates_and_normal(Pa, contact, eps, t, y)
            ref = _smoothed.rates_and_normal(Pu, contact, eps, t, y)
            np.testing.assert_allclose(np.asarray(got[0]), np.asarray(ref[0]), rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(float(got[1]), float(ref[1]), rtol=1e-12)


def test_array_layout_smoothed_runs_equal_unrolled(monkeypatch):
    """`Smoothed` dynamics run a chain in its layout: `measure` (strict contact) and `simulate` (paper
    contact) of a 5-mass worm in the array layout agree with the unrolled layout to `SMOOTH_RTOL`, with
    the same stick fractions and modes, and the energy balance w = e_d + (e - e0) holds in both."""
    seen = []  # the physics each traced run integrates (these tolerances are this test's: traced here)

    def spy(mechanism):
        seen.append(type(P := engine_physics(mechanism)))
        return P

    monkeypatch.setattr(_smoothed_dynamics, "engine_physics", spy)
    dyn = lj.Smoothed(1e-3, rtol=1e-10, atol=1e-12)
    kw: dict[str, Any] = dict(z=0.5, t_start=4.0, horizon=30.0, contact="strict", dynamics=dyn)
    got = lj.measure(_worm(5, "array"), **kw).to_numpy()
    assert seen == [ArrayChainPhysics]
    ref = lj.measure(_worm(5, "unrolled"), **kw).to_numpy()
    assert seen == [ArrayChainPhysics, ChainPhysics]
    assert np.all(ref["status"] == lj.Status.OK) and np.all(got["status"] == lj.Status.OK)
    assert np.all(ref["reached"]) and np.all(ref["stick_fraction"] > 0.01)
    for key in MEASURED:
        _close(got[key], ref[key], SMOOTH_RTOL)
    ts = np.linspace(0.0, 20.0, 41)
    got_s = lj.simulate(_worm(5, "array"), 20.0, ts, contact="paper", dynamics=dyn)
    ref_s = lj.simulate(_worm(5, "unrolled"), 20.0, ts, contact="paper", dynamics=dyn)
    for key in ("x", "v", "X", "e_d", "w", "e", "N", "tension", "rest_length"):
        a, b = np.asarray(getattr(ref_s, key)), np.asarray(getattr(got_s, key))
        np.testing.assert_allclose(b, a, rtol=SMOOTH_RTOL, atol=SMOOTH_RTOL * np.abs(a).max(), err_msg=key)
    np.testing.assert_array_equal(np.asarray(got_s.stuck), np.asarray(ref_s.stuck))
    for tr in (got_s, ref_s):
        balance = np.asarray(tr.w - tr.e_d - (tr.e - tr.e[:, :1]))
        assert np.max(np.abs(balance)) < 1e-8 * max(1.0, float(np.max(tr.e_d)))


def test_array_layout_smoothed_bad_configuration_flagged_others_unchanged():
    """The smoothed engine in the array layout: an invalid chain of a batch is flagged `INVALID` with no
    NaN, and the others measure what they measure alone."""
    masses = np.ones((3, 4))
    masses[1, 2] = -1.0
    masses[2] = [1.2, 0.9, 1.0, 1.1]
    wave = lj.TravellingWave(0.06, 3.0, np.pi / 3)
    fr = lj.AnisotropicCoulomb(0.7, 0.9, 0.5, 0.7)
    dyn = lj.Smoothed(1e-2, rtol=1e-10, atol=1e-12)
    kw: dict[str, Any] = dict(z=0.3, t_start=4.0, horizon=30.0, window=5.0, dynamics=dyn)
    m = lj.measure(lj.Chain(masses=masses, waveforms=wave, friction=fr, check=False, layout="array"), **kw)
    assert list(np.asarray(m.status)) == [lj.Status.OK, lj.Status.INVALID, lj.Status.OK]
    assert not np.any(np.isnan(np.asarray(m.tau_z)))
    alone = lj.measure(lj.Chain(masses=masses[2], waveforms=wave, friction=fr, layout="array"), **kw)
    assert bool(alone.reached)
    np.testing.assert_allclose(m.tau_z[2], alone.tau_z, rtol=SMOOTH_RTOL)
    np.testing.assert_allclose(m.e_d[2], alone.e_d, rtol=SMOOTH_RTOL)


def test_array_layout_bad_configuration_flagged_others_unchanged():
    masses = np.ones((3, 4))
    masses[1, 2] = -1.0
    masses[2] = [1.2, 0.9, 1.0, 1.1]
    wave = lj.TravellingWave(0.06, 3.0, np.pi / 3)
    fr = lj.AnisotropicCoulomb(0.7, 0.9, 0.5, 0.7)
    batch = lj.Chain(masses=masses, waveforms=wave, friction=fr, check=False, layout="array")
    m = lj.measure(batch, z=0.5, t_start=4.0, horizon=40.0)
    assert list(np.asarray(m.status)) == [lj.Status.OK, lj.Status.INVALID, lj.Status.OK]
    assert not np.any(np.isnan(np.asarray(m.tau_z)))
    alone = lj.measure(lj.Chain(masses=masses[2], waveforms=wave, friction=fr, layout="array"), z=0.5,
                       t_start=4.0, horizon=40.0)  # fmt: skip
    assert bool(alone.reached)
    np.testing.assert_allclose(m.tau_z[2], alone.tau_z, rtol=1e-12)
    np.testing.assert_allclose(m.e_d[2], alone.e_d, rtol=1e-12)


def test_array_layout_jacfwd_through_events():
    """Forward mode through the stick/slip events: `jacfwd` of tau_z and e_z in the stiffness and the
    amplitude equals the unrolled layout's and central differences of the array layout itself."""

    def run(theta, layout):
        k, a = theta
        C = lj.Chain(masses=[1.0, 1.1, 0.9, 1.0], k=k, d=0.3, lbar=3.0, c=0.02,
                     waveforms=lj.TravellingWave(a, 3.0, 2 * np.pi / 3),
                     friction=lj.AnisotropicCoulomb(0.7, 0.9, 0.5, 0.7), layout=layout)  # fmt: skip
        m = lj.measure(C, z=0.3, t_start=4.0, horizon=40.0)
        return jnp.stack([m.tau_z, m.e_z]), (m.smooth, m.n_switch)

    theta = jnp.array([50.0, 0.06])
    jac, (smooth, n_switch) = jax.jacfwd(lambda t: run(t, "array"), has_aux=True)(theta)
    jac_u = jax.jacfwd(lambda t: run(t, "unrolled")[0])(theta)
    assert bool(smooth) and int(n_switch) > 10  # a run through many switches, flagged differentiable
    np.testing.assert_allclose(np.asarray(jac), np.asarray(jac_u), rtol=1e-8)
    fd = []
    for i in range(2):
        h = 1e-6 * float(theta[i])
        e = jnp.zeros(2).at[i].set(h)
        fd.append((run(theta + e, "array")[0] - run(theta - e, "array")[0]) / (2 * h))
    fd = np.stack([np.asarray(q) for q in fd], -1)
    assert np.all(np.isfinite(np.asarray(jac)))
    np.testing.assert_allclose(np.asarray(jac), fd, rtol=1e-4, atol=1e-6 * np.abs(fd).max())


GAIT_KEYS = ("state", "monodromy", "mean_speed", "cost_of_transport", "e_d", "work", "stick_fraction", "min_normal",
             "slip_margin", "period")  # fmt: skip


def test_array_layout_steady_gait_equals_unrolled():
    """`steady_gait`: the fixed point, its monodromy (forward mode through the events), speed, cost of
    transport, e_d, w, stick fractions, smallest normal force and slip margin of both layouts agree to
    1e-9 relative (the monodromy's entries near zero: to 1e-9 of its largest), with the same gait
    period, status and Newton iterations."""
    got = lj.steady_gait(_worm(3, "array"), periods=(1, 2))
    ref = lj.steady_gait(_worm(3, "unrolled"), periods=(1, 2))
    assert np.all(np.asarray(ref.converged)) and np.all(np.asarray(ref.stick_fraction) > 0.01)
    for key in ("status", "k", "n_iter", "regime", "n_switch", "stable", "liftoff"):
        np.testing.assert_array_equal(np.asarray(getattr(got, key)), np.asarray(getattr(ref, key)), err_msg=key)
    for key in GAIT_KEYS:
        a, b = np.asarray(getattr(ref, key)), np.asarray(getattr(got, key))
        np.testing.assert_allclose(b, a, rtol=1e-9, atol=1e-9 * np.abs(a).max(), err_msg=key)


def test_gait_layout_choice():
    """Steady gaits (and continuation and the optimiser's oracle) take the array layout from
    `GAIT_ARRAY_FROM` masses on under `"auto"` (whatever the contact reading); `"unrolled"` stays
    unrolled."""
    arr, unr = cg.array_mechanism_physics, cg.mechanism_physics
    assert cg.physics_for(_worm(GAIT_ARRAY_FROM, "auto")) is arr
    assert cg.physics_for(_worm(GAIT_ARRAY_FROM - 1, "auto")) is unr
    assert cg.physics_for(_worm(GAIT_ARRAY_FROM, "unrolled")) is unr
    assert cg.physics_for(_worm(2, "array")) is arr
    assert isinstance(gait_physics(_worm(GAIT_ARRAY_FROM, "auto")), ArrayChainPhysics)
    assert isinstance(gait_physics(_worm(GAIT_ARRAY_FROM - 1, "auto")), ChainPhysics)


def test_layout_choice_and_refusals(monkeypatch):
    assert jax.default_backend() != "cpu" or array_from() == ARRAY_FROM
    assert isinstance(engine_physics(_worm(ARRAY_FROM, "auto")), ArrayChainPhysics)
    assert isinstance(engine_physics(_worm(ARRAY_FROM - 1, "auto")), ChainPhysics)
    assert isinstance(engine_physics(_worm(ARRAY_FROM, "unrolled")), ChainPhysics)
    with pytest.raises(ValueError, match="'layout'.*'auto', 'unrolled', 'array'"):
        _worm(3, "arrays")
    # On a GPU "auto" takes the array layout from ARRAY_FROM_ACCELERATOR masses on.
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    assert array_from() == ARRAY_FROM_ACCELERATOR < ARRAY_FROM
    assert isinstance(engine_physics(_worm(ARRAY_FROM_ACCELERATOR, "auto")), ArrayChainPhysics)
    assert isinstance(engine_physics(_worm(ARRAY_FROM_ACCELERATOR - 1, "auto")), ChainPhysics)
    # Every waveform runs in the array layout: a mix of kinds, splines of several sizes.
    spline = lj.Spline(np.array([0.05, -0.05, 0.05, -0.05]), 2.0, 3.0)
    longer = lj.Spline(np.array([0.05, -0.05, 0.05, -0.05, 0.0]), 2.0, 3.0)
    for mixed in ([spline, lj.Sinusoid(0.05, 2.0, 3.0)], [spline, longer]):
        chain = lj.Chain(masses=[1.0] * 3, waveforms=mixed, layout="array")
        assert isinstance(engine_physics(chain), ArrayChainPhysics)
        auto = lj.Chain(masses=[1.0] * ARRAY_FROM, waveforms=mixed * ((ARRAY_FROM - 1) // 2) + [spline])
        assert isinstance(engine_physics(auto), ArrayChainPhysics)


def test_array_layout_sweep_equals_measure():
    """`sweep` of chains in the array layout: each point equals `measure` of its own chain (chunks of
    2, the last one padded): the lanes of the array layout do not depend on the batch."""

    def worm(phi):
        return lj.Chain(masses=np.ones(np.shape(phi) + (4,)), d=0.3, waveforms=lj.TravellingWave(0.06, 3.0, phi),
                        friction=lj.AnisotropicCoulomb(0.7, 0.9, 0.5, 0.7), layout="array")  # fmt: skip

    phi = np.array([-1.0, 1.0, 2.0])
    kw: dict[str, Any] = dict(z=0.5, horizon=40.0, t_start=4.0)
    ds = lj.sweep({"phi": phi}, mechanism=worm, chunk_size=2, progress=False, **kw)
    ref = lj.measure(worm(phi), **kw)
    assert np.all(np.asarray(ref.status) == lj.Status.OK)
    for name in ("tau_z", "e_z", "mean_speed", "stick_fraction", "n_steps"):
        np.testing.assert_array_equal(ds[name].values, np.asarray(getattr(ref, name)), err_msg=name)


def test_array_layout_initial_states_checked_per_configuration():
    """Initial states in the array layout: past the front end's check (as under `jit`) a row whose
    masses are out of order is flagged INVALID in its own result; the other row runs as in the
    unrolled layout."""
    from locomotion_jax.dynamics._flat import FlatBatch
    from locomotion_jax.run._batch import prepare_chain

    rows = jnp.asarray([[0.0, 3.0, 6.0, 9.0, 0.0, 0.1, 0.0, -0.1], [0.0, 3.0, 2.0, 9.0, 0.0, 0.0, 0.0, 0.0]])
    out = {}
    for layout in ("array", "unrolled"):
        worm = lj.Chain(masses=[1.0] * 4, waveforms=lj.TravellingWave(0.05, 2.0, 1.0), layout=layout)
        flat, valid, _ = prepare_chain(lj.Chain.stack([worm, worm]), None)
        batch = FlatBatch(flat, valid, t_start=jnp.zeros(2), initial=rows)
        out[layout] = lj.Exact().measure(batch, 0.1, 5.0, 2.0, "strict", "paper")
    assert [int(s) for s in np.asarray(out["array"]["status"])] == [lj.Status.OK, lj.Status.INVALID]
    for key in ("tau_z", "e_d", "work", "mean_speed"):
        _close(np.asarray(out["array"][key])[0], np.asarray(out["unrolled"][key])[0], RTOL)


# The hopping three-mass chains of tests/test_hop_reference.py (masses, omega, a, phi; d = 0.5).
HOPPING = [([1.0] * 3, 6.0, 0.08, 2 * np.pi / 3), ([1.0] * 3, 8.0, 0.08, -2 * np.pi / 3),
           ([0.8, 1.2, 1.0], 6.0, 0.12, -2 * np.pi / 3), ([1.0] * 3, 10.0, 0.08, 2 * np.pi / 3)]  # fmt: skip


def _hopping(layout: str, cases=HOPPING, **friction) -> lj.Chain:
    """The chains of `cases` (a batch) from the reference's conventions (`chain_config`)."""
    cfgs = [chain_config(m, omega=w, a=a, phi=phi, **friction) for m, w, a, phi in cases]
    law = lj.AnisotropicCoulomb(**friction) if friction else lj.Coulomb(0.7, 0.5)
    return lj.Chain.stack([
        lj.Chain(masses=c["m"], k=c["k"], d=c["d"], lbar=c["lbar"], c=c["c"], friction=law, layout=layout,
                 waveforms=lj.SpringFourier(c["A"], c["B"], c["omega"]))
        for c in cfgs
    ])  # fmt: skip


def test_array_layout_hop_equals_unrolled():
    """`contact="hop"` (SPEC §10: springs along $(u_j, d_j + y_{j+1} - y_j)$, flight, landing): four
    hopping chains in both layouts. `simulate`: positions, velocities, heights, vertical velocities,
    e_d, w, e and N at 401 saves to 1e-10 of their largest, the same stuck masks and landings;
    `measure`: every figure (flight fractions, highest hops and landings per period included) to
    1e-10 relative, the same steps and switches."""
    ts = np.linspace(0.0, 40.0, 401)
    kw: dict[str, Any] = dict(contact="hop", dynamics=lj.Exact(dt=0.01))
    got, ref = (lj.simulate(_hopping(lay), 40.0, ts, **kw) for lay in ("array", "unrolled"))
    assert np.all(np.asarray(ref.status) == lj.Status.OK) and np.all(np.asarray(ref.n_land) > 50)  # they hop
    assert isinstance(engine_physics(_hopping("array")), ArrayChainPhysics)
    for key in ("x", "v", "y", "vy", "e_d", "w", "e", "N"):
        a, b = np.asarray(getattr(ref, key)), np.asarray(getattr(got, key))
        np.testing.assert_allclose(b, a, rtol=RTOL, atol=RTOL * np.abs(a).max(), err_msg=key)
    for key in ("stuck", "n_land", "status"):
        np.testing.assert_array_equal(np.asarray(getattr(got, key)), np.asarray(getattr(ref, key)), err_msg=key)
    m = {lay: lj.measure(_hopping(lay), z=0.3, t_start=5.0, horizon=40.0, contact="hop").to_numpy()
         for lay in ("array", "unrolled")}  # fmt: skip
    assert np.all(m["unrolled"]["flight_fraction"].max(-1) > 0.05)
    for key in (*MEASURED, "flight_fraction", "highest_hop", "landings_per_period", "e_d", "work", "delta_e"):
        assert m["array"][key].shape == m["unrolled"][key].shape, key
        _close(m["array"][key], m["unrolled"][key], RTOL)
    for key in ("n_steps", "n_switch", "status", "zeno"):
        np.testing.assert_array_equal(m["array"][key], m["unrolled"][key], err_msg=key)


def test_array_layout_hopping_worm_against_reference():
    """A 16-mass worm on bristles hopping: `layout="auto"` runs it in the array layout, and it agrees
    with the independent reference (`tests/reference_hop.py`) at dt = 1/800: positions within 1e-7
    (measured 5e-9), heights within 1e-8 (4e-10), e_d within 1e-6 (3e-8), the landings counted
    alike (211); w = e_d + Delta e to 1e-6 of e_d."""
    n, t_end = 16, 20.0
    worm = _hopping("auto", [(list(np.linspace(0.9, 1.1, n)), 8.0, 0.08, 2 * np.pi / 3)], **ANISO)
    assert isinstance(engine_physics(worm), ArrayChainPhysics)
    cfg = chain_config(list(np.linspace(0.9, 1.1, n)), omega=8.0, a=0.08, phi=2 * np.pi / 3, **dict[str, Any](ANISO))
    ts = np.linspace(0.0, t_end, 201)
    ref = reference_hop_simulate(cfg, t_end, ts)
    tr = lj.simulate(worm, t_end, ts, contact="hop", dynamics=lj.Exact(dt=1 / 800))
    assert tr.y is not None and tr.n_land is not None
    dx, dy = np.abs(np.asarray(tr.x[0]) - ref["x"]).max(), np.abs(np.asarray(tr.y[0]) - ref["y"]).max()
    ded = np.abs(np.asarray(tr.e_d[0]) - ref["e_d"]).max()
    bal = np.abs(np.asarray(tr.w[0] - tr.e_d[0] - (tr.e[0] - tr.e[0, 0]))).max()
    print("16-mass hopping worm: landings", int(tr.n_land[0]), ref["n_landings"], dx, dy, ded, bal)
    assert int(tr.status[0]) == lj.Status.OK and np.sum(ref["n_landings"] >= 1) >= 12  # most masses hop (15 of 16)
    assert int(tr.n_land[0]) == int(ref["n_landings"].sum())
    assert dx < 1e-7 and dy < 1e-8 and ded < 1e-6
    assert bal <= 1e-6 * float(tr.e_d[0, -1])


def test_array_layout_hop_gait_equals_unrolled():
    """Hopping steady gaits (three masses, omega 6 and 10: at 10 a body is in flight at the section) in
    both layouts: the same status, gait period and Newton iterations, every figure to 1e-9; restarted
    on its own section states (heights and vertical velocities given) the array layout's gait is found
    again with no Newton iteration."""
    cases = [HOPPING[0], HOPPING[3]]
    got, ref = (lj.steady_gait(_hopping(lay, cases), contact="hop") for lay in ("array", "unrolled"))
    assert np.all(np.asarray(ref.converged)) and float(np.asarray(ref.state)[1, 5:].max()) > 0
    for key in ("status", "k", "n_iter", "stable"):
        np.testing.assert_array_equal(np.asarray(getattr(got, key)), np.asarray(getattr(ref, key)), err_msg=key)
    for key in GAIT_KEYS:
        a, b = np.asarray(getattr(ref, key)), np.asarray(getattr(got, key))
        np.testing.assert_allclose(b, a, rtol=1e-9, atol=1e-9 * np.abs(a).max(), err_msg=key)
    again = lj.steady_gait(_hopping("array", cases), contact="hop", start=got.state, transient=1)
    assert np.all(np.asarray(again.n_iter) == 0) and np.abs(np.asarray(again.state - got.state)).max() < 1e-10


def _spline_worms(layout: str, force: bool = False, mixed: bool = False) -> lj.Chain:
    """Two 4-mass worms on bristles, each spring its own periodic spline of 6 control values (its own
    mean rest length), under the rest-length or the internal-force actuator; `mixed`: the middle spring
    driven by a waveform class of a user's own (`mechanism_cases.Cubed`, its amplitude broadcast over the
    batch or not), the last spline of 5 values."""
    from mechanism_cases import Cubed

    rng = np.random.default_rng(1)
    scale = 2.0 if force else 0.06
    splines: list[Any] = [lj.Spline(rng.uniform(-scale, scale, (2, 6 - (mixed and j == 2))), 3.0, 3.0 + 0.1 * j)
               for j in range(3)]  # fmt: skip
    if mixed:
        # Its amplitude per configuration under the force, one for both under the rest length.
        splines[1] = Cubed((jnp.asarray([0.5, -0.7]) if force else jnp.asarray(0.5)) * scale, jnp.asarray(3.0),
                           jnp.asarray(3.1))  # fmt: skip
    return lj.Chain(masses=[[1.0, 1.1, 0.9, 1.0], [0.9, 1.0, 1.2, 1.1]], d=0.3, lbar=None, c=0.02, waveforms=splines,
                    friction=lj.AnisotropicCoulomb(0.7, 0.9, 0.5, 0.7), layout=layout,
                    actuator=lj.InternalForce() if force else lj.RestLength())  # fmt: skip


@pytest.mark.parametrize("force, mixed", [(False, False), (True, False), (False, True), (True, True)])
def test_array_layout_splines_equal_unrolled(force, mixed):
    """Springs driven by periodic splines (`Spline`, one per spring), and (`mixed`) by splines of two
    sizes and a waveform class of a user's own: both layouts' `measure` agree to 1e-10 relative with
    the same steps and switches, under the rest-length actuator and the internal force (whose
    waveform is a force about its own mean)."""
    kw: dict[str, Any] = dict(z=0.3, t_start=4.0, horizon=40.0, contact="paper")
    got, ref = (lj.measure(_spline_worms(lay, force, mixed), **kw).to_numpy() for lay in ("array", "unrolled"))
    P = engine_physics(_spline_worms("array", force, mixed))
    assert isinstance(P, ArrayChainPhysics) and P.bank is not None
    assert P.bank.rows == (((0,), (1,), (2,)) if mixed else ((0, 1, 2),))
    assert np.all(ref["status"] == lj.Status.OK) and np.all(ref["stick_fraction"].max(-1) > 0.05)
    for key in MEASURED:
        _close(got[key], ref[key], RTOL)
    for key in ("n_steps", "n_switch"):
        np.testing.assert_array_equal(got[key], ref[key], err_msg=key)


def test_array_layout_spline_gait_equals_unrolled():
    """Steady gaits of the spline-driven worms (`"auto"` takes the array layout for gaits from
    `GAIT_ARRAY_FROM` masses on, splines included): both layouts to 1e-9, the same Newton iterations."""
    got = lj.steady_gait(_spline_worms("auto"))
    ref = lj.steady_gait(_spline_worms("unrolled"))
    assert isinstance(gait_physics(_spline_worms("auto")), ArrayChainPhysics)
    assert np.all(np.asarray(ref.converged))
    for key in ("status", "k", "n_iter", "stable"):
        np.testing.assert_array_equal(np.asarray(getattr(got, key)), np.asarray(getattr(ref, key)), err_msg=key)
    for key in GAIT_KEYS:
        a, b = np.asarray(getattr(ref, key)), np.asarray(getattr(got, key))
        np.testing.assert_allclose(b, a, rtol=1e-9, atol=1e-9 * np.abs(a).max(), err_msg=key)
