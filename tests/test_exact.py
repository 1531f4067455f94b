"""Properties of the exact hybrid engine: energy balance (eq. 16), the paper's
qualitative facts (Figs. 4b, 5), mirror symmetry, batching, dtypes, no retracing."""

import math
from typing import Any

import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from locomotion_jax.dynamics import _paper


def test_energy_balance_along_trajectory():
    # eq. (16): w = e_d + e(t) - e(0), with w integrated from the actuator power.
    for omega in (2.0, 6.0, 23.0):
        tr = lj.simulate(lj.Params(omega=omega), 40.0, save_at=jnp.linspace(0, 40, 81), contact="paper")
        residual = tr.w - tr.e_d - (tr.e - tr.e[0])
        assert bool(jnp.all(tr.valid))
        # dt = 0.01: the residual is the RK4 error (measured 2e-8 at omega = 2, 1e-5 at 23).
        np.testing.assert_allclose(residual, 0, atol=3e-5)


def test_energy_balance_in_measurement():
    p = lj.Params.grid(omega=jnp.array([2.0, 6.0, 16.0, 23.0]))
    m = lj.measure(p, z=1.0, horizon=200.0, contact="paper")
    assert bool(jnp.all(m.reached))
    np.testing.assert_allclose(m.balance, 0, atol=1e-5 * float(jnp.max(m.e_d)))


def test_measure_ends_at_its_horizon_when_the_window_is_longer():
    """A horizon shorter than the regime window (25) ends the run at `t_start + horizon`: the mean
    speed and the dissipation are those of `simulate` at that time, to 1e-12, and the regime is
    undetermined (the window did not end)."""
    p, t0, horizon = lj.Params.grid(omega=jnp.array([2.0, 6.0])), 30.0, 7.3
    m = lj.measure(p, z=1e9, horizon=horizon, t_start=t0)
    tr = lj.simulate(p, t0 + horizon, save_at=jnp.array([t0, t0 + horizon]))
    m1, m2 = (np.broadcast_to(np.asarray(m), (2,))[:, None] for m in (p.m1, p.m2))
    X = (np.asarray(tr.x1) * m1 + np.asarray(tr.x2) * m2) / (m1 + m2)
    np.testing.assert_allclose(np.asarray(m.mean_speed), (X[:, 1] - X[:, 0]) / horizon, rtol=1e-12)
    np.testing.assert_allclose(np.asarray(m.e_d), np.asarray(tr.e_d[:, 1] - tr.e_d[:, 0]), rtol=1e-12)
    assert np.all(np.asarray(m.regime) == lj.Regime.UNDETERMINED)


@pytest.mark.parametrize("omega", [math.pi])
def test_fig4b_direction_follows_d(omega):
    # Fig. 4b: l0 = 0.05 sin(pi t) + 3; forward for d > 0, backward for d < 0, none at d = 0.
    ds = jnp.array([-0.5, -0.25, 0.0, 0.25, 0.5])
    tr = lj.simulate(lj.Params.grid(d=ds, omega=omega), 20.0, save_at=jnp.array([0.0, 20.0]), contact="paper")
    dX = np.asarray(tr.X[:, -1] - tr.X[:, 0])
    assert dX[0] < -0.05 and dX[1] < -0.01
    assert dX[3] > 0.01 and dX[4] > 0.05
    assert abs(dX[2]) < 1e-10  # d = 0, m1 = m2: simultaneous switches keep the symmetry


def test_d0_equal_masses_switch_together():
    tr = lj.simulate(lj.Params(d=0.0, omega=math.pi), 20.0, save_at=jnp.linspace(0, 20, 2001))
    modes = np.asarray(tr.mode)
    # Only "both stick" or "both slip" can occur by symmetry.
    assert set(np.unique(modes)) <= {int(lj.Mode.BOTH_STICK), int(lj.Mode.BOTH_SLIP)}
    np.testing.assert_allclose(tr.v1, -tr.v2, atol=1e-12)


def test_mirror_symmetry():
    # With m1 = m2, d -> -d mirrors the motion: the CoM displacement changes sign.
    p = lj.Params.grid(d=jnp.array([0.5, -0.5]), omega=jnp.array([2.0, 16.0]))
    tr = lj.simulate(p, 30.0, save_at=jnp.array([0.0, 30.0]), contact="paper")
    dX = np.asarray(tr.X[..., -1] - tr.X[..., 0])
    np.testing.assert_allclose(dX[0], -dX[1], rtol=1e-8, atol=1e-10)
    assert np.all(np.abs(dX[0]) > 1e-2)


def test_fig5_regimes():
    # Fig. 5: SSL at omega = 0.2 wn1, SL at omega = 2.3 wn1 (wn1 = 10 for the defaults).
    p = lj.Params.grid(omega=jnp.array([2.0, 23.0]))
    m = lj.measure(p, z=1.0, horizon=200.0, contact="paper")
    assert [int(r) for r in m.regime] == [lj.Regime.SSL, lj.Regime.SL]
    assert float(m.stick_fraction1[0]) > 0.1 and float(m.stick_fraction1[1]) == 0.0
    tr = lj.simulate(lj.Params(omega=2.0), 100.0, save_at=jnp.linspace(80, 100, 2001), contact="paper")
    stuck = np.asarray(tr.mode) != lj.Mode.BOTH_SLIP
    assert stuck.mean() > 0.2
    assert np.all(np.asarray(tr.v1)[np.isin(np.asarray(tr.mode), [0, 3])] == 0.0)  # stuck means v = 0 exactly


def test_natural_frequencies_and_t_start():
    p = lj.Params()
    assert float(p.wn1) == pytest.approx(10.0)
    assert float(p.wn2) == pytest.approx(math.sqrt(50.0))
    assert float(p.t_start) == pytest.approx(80 * 2 * math.pi / math.sqrt(50.0))
    q = lj.Params(mhat=0.05)
    assert float(q.m1 + q.m2) == pytest.approx(2.0)
    assert float(q.wn1**2) == pytest.approx(float(q.wn2**2 + q.wn3**2))


def test_batch_equals_single_runs_and_isolates_failures():
    # One invalid configuration (mhat = 1.2), one that lifts off under the strict
    # reading (omega = 10, near resonance), one that never reaches z (omega = 0.5):
    # the others are unchanged and each failure is flagged in its own result.
    omegas = jnp.array([2.0, 10.0, 0.5, 23.0, 16.0])
    mhat = jnp.array([0.5, 0.5, 0.5, 0.5, 1.2])
    batch = lj.Params(omega=omegas, mhat=mhat, check=False)
    kw: dict[str, Any] = dict(z=0.5, horizon=60.0)
    m = lj.measure(batch, **kw)
    st = [int(s) for s in m.status]
    assert st[0] == lj.Status.OK and st[3] == lj.Status.OK
    assert st[1] == lj.Status.LIFTOFF and bool(m.liftoff[1])
    assert st[4] == lj.Status.INVALID
    assert not bool(m.reached[2]) and math.isinf(float(m.tau_z[2])) and math.isinf(float(m.e_z[2]))
    for i in (0, 2, 3):
        single = lj.measure(lj.Params(omega=float(omegas[i])), **kw)
        np.testing.assert_allclose(m.tau_z[i], single.tau_z, rtol=1e-12)
        np.testing.assert_allclose(m.e_d[i], single.e_d, rtol=1e-12)
    for name, value in m.to_numpy().items():  # no NaN except where documented
        measured = ("mean_speed", "e_d", "work", "delta_e", "balance", "X_start", "stick_fraction1", "stick_fraction2")
        if name in measured + ("transversality", "near_miss", "margin_z"):
            assert not np.any(np.isnan(value[[0, 2, 3]])), name
        else:
            assert not np.any(np.isnan(value)), name


def test_liftoff_is_located_and_stops_the_run():
    tr = lj.simulate(lj.Params(omega=23.0, a=0.1), 5.0, save_at=jnp.linspace(0, 5, 501))
    assert int(tr.status) == lj.Status.LIFTOFF and bool(tr.liftoff)
    tl = float(tr.t_liftoff)
    assert 0 < tl < 5
    assert not bool(jnp.all(tr.valid))
    ok = np.asarray(tr.valid)
    assert np.all(np.asarray(tr.t)[ok] <= tl)
    assert np.all(np.minimum(np.asarray(tr.N1), np.asarray(tr.N2))[ok] > -1e-9)
    assert not np.any(np.isnan(np.asarray(tr.X)))
    # The paper's reading continues through it and flags it.
    tp = lj.simulate(lj.Params(omega=23.0, a=0.1), 5.0, save_at=jnp.linspace(0, 5, 501), contact="paper")
    assert int(tp.status) == lj.Status.OK and bool(tp.liftoff) and bool(jnp.all(tp.valid))


def test_relaxed_start_avoids_initial_kick():
    p = lj.Params(omega=23.0, a=0.07)
    tr_paper = lj.simulate(p, 3.0, save_at=jnp.linspace(0, 3, 31))
    tr_relax = lj.simulate(p, 3.0, save_at=jnp.linspace(0, 3, 31), start="relaxed")
    assert float(tr_relax.x2[0] - tr_relax.x1[0]) == pytest.approx(math.sqrt(9 - 0.25))
    assert int(tr_relax.status) == lj.Status.OK
    assert int(tr_paper.status) == lj.Status.LIFTOFF


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(mu_s=0.4), "mu_s"),
        (dict(k=0.0), "k"),
        (dict(k=-1.0), "k"),
        (dict(c=-0.1), "c"),
        (dict(mhat=1.0), "mhat"),
        (dict(mhat=0.0), "mhat"),
        (dict(a=3.0), "a"),
        (dict(mu_k=-0.1, mu_s=0.0), "mu_k"),
        (dict(omega=float("nan")), "omega"),
        (dict(d=float("inf")), "d"),
        (dict(lbar=-1.0), "lbar"),
    ],
)
def test_invalid_parameters_are_refused(kwargs, name):
    with pytest.raises(ValueError, match=f"'{name}'") as info:
        lj.Params(**kwargs)
    assert "valid range" in str(info.value)


def test_invalid_parameter_in_batch_names_index():
    with pytest.raises(ValueError, match=r"'mu_s' at batch index \(2,\)"):
        lj.Params(mu_s=jnp.array([0.7, 0.6, 0.3, 0.2]))
    with pytest.raises(ValueError, match="Unknown parameter"):
        lj.Params.grid(omegaa=jnp.array([1.0]))


def test_invalid_call_arguments():
    p = lj.Params()
    with pytest.raises(ValueError, match="z"):
        lj.measure(p, z=0.0)
    with pytest.raises(ValueError, match="horizon"):
        lj.measure(p, horizon=-1.0)
    with pytest.raises(ValueError, match="contact"):
        lj.measure(p, contact="sticky")
    with pytest.raises(ValueError, match="start"):
        lj.simulate(p, 1.0, start="nowhere")
    with pytest.raises(ValueError, match="t_end"):
        lj.simulate(p, 0.0)
    with pytest.raises(ValueError, match="save_at"):
        lj.simulate(p, 1.0, save_at=jnp.array([0.5, 0.2]))
    with pytest.raises(ValueError, match="dt"):
        lj.Exact(dt=0.0)
    with pytest.raises(ValueError, match="eps"):
        lj.Smoothed(eps=0.0)


def test_float32_runs_and_preserves_dtype():
    p32 = lj.Params.grid(omega=jnp.array([2.0, 23.0])).astype(jnp.float32)
    m32 = lj.measure(p32, z=1.0, horizon=200.0, contact="paper")
    m64 = lj.measure(lj.Params.grid(omega=jnp.array([2.0, 23.0])), z=1.0, horizon=200.0, contact="paper")
    assert m32.tau_z.dtype == jnp.float32 and m64.tau_z.dtype == jnp.float64
    assert [int(r) for r in m32.regime] == [int(r) for r in m64.regime]
    # float32 round-off in the time and positions limits it to ~1e-3 (README).
    np.testing.assert_allclose(m32.tau_z, m64.tau_z, rtol=3e-3)
    np.testing.assert_allclose(m32.e_z, m64.e_z, rtol=3e-3)


def test_one_compilation_for_new_values():
    f = _paper._measure_batch
    p1 = lj.Params.grid(omega=jnp.array([2.0, 3.0]))
    p2 = lj.Params.grid(omega=jnp.array([5.0, 7.0]), a=0.06, d=0.4)
    lj.measure(p1, z=0.2, horizon=20.0)
    # `f` is the `jax.jit` wrapper, which has `_cache_size` (pyright sees the function it wraps).
    before = f._cache_size()  # pyright: ignore[reportFunctionMemberAccess]
    lj.measure(p2, z=0.3, horizon=25.0, window=20.0)
    assert f._cache_size() == before  # pyright: ignore[reportFunctionMemberAccess]


def test_fourier_waveform_matches_sinusoid():
    p = lj.Params(omega=6.0)
    wave = lj.Fourier.from_sinusoid(0.05, 6.0, 3.0, harmonics=3)
    a = lj.simulate(p, 10.0, save_at=jnp.linspace(0, 10, 11))
    b = lj.simulate(p, 10.0, save_at=jnp.linspace(0, 10, 11), waveform=wave)
    np.testing.assert_allclose(a.X, b.X, rtol=1e-12, atol=1e-12)
    l0, dl0 = wave(jnp.asarray(0.3))
    assert float(l0) == pytest.approx(3 + 0.05 * math.sin(1.8))
    assert float(dl0) == pytest.approx(0.05 * 6 * math.cos(1.8))


@pytest.mark.parametrize("contact", ["strict", "paper"])
def test_random_configurations_never_stall_and_stay_consistent(contact):
    # Wild random parameters: every run ends on its own (no Zeno stall: the step cap
    # is never hit), the results are consistent with each other, and the energy balance
    # holds. dt = 0.005: at dt = 0.01 the stiffest of them (omega = 26, k = 97, a = 0.13)
    # leaves an integration error of 7e-4 of e_d in the balance (2e-5 at 0.005, 4e-7 at 0.0025).
    rng = np.random.default_rng(1)
    B = 32
    mu_k = rng.uniform(0.1, 0.8, B)
    p = lj.Params(
        omega=rng.uniform(0.5, 30, B),
        a=rng.uniform(0.0, 0.3, B),
        d=rng.uniform(-1, 1, B),
        mhat=rng.uniform(0.05, 0.95, B),
        mu_k=mu_k,
        mu_s=mu_k + rng.uniform(0, 0.5, B),
        c=rng.uniform(0, 0.1, B),
        k=rng.uniform(20, 100, B),
    )
    horizon = 20.0
    m = lj.measure(p, z=0.5, horizon=horizon, contact=contact, dynamics=lj.Exact(dt=0.005))
    r = m.to_numpy()
    status = r["status"]
    assert not np.any(status == lj.Status.MAX_STEPS)
    if contact == "paper":
        assert np.all(status == lj.Status.OK)
    else:  # a lift-off, and only a lift-off, stops a strict run
        np.testing.assert_array_equal(status == lj.Status.LIFTOFF, r["liftoff"])
    assert 5 <= np.sum(r["liftoff"]) and np.sum(status == lj.Status.OK) >= 5  # both kinds are present
    # tau_z and e_z are finite exactly when z was reached, and then inside the horizon.
    np.testing.assert_array_equal(np.isfinite(r["tau_z"]), r["reached"])
    np.testing.assert_array_equal(np.isfinite(r["e_z"]), r["reached"])
    assert np.all((r["tau_z"][r["reached"]] > 0) & (r["tau_z"][r["reached"]] <= horizon))
    ok = status == lj.Status.OK
    # Dissipation (eq. 15) never decreases: mu_k n |v| and c v^2 are >= 0 (n = |N| under the paper's reading).
    # (A configuration stuck throughout dissipates nothing.)
    assert np.all(r["e_d"][ok] >= 0) and np.all(r["e_z"][r["reached"]] <= r["e_d"][r["reached"]] * (1 + 1e-12))
    # Energy balance (eq. 16); measured 5.7e-7 (strict) and 2.0e-5 (paper) of e_d.
    bal = np.abs(r["balance"][ok]) / np.maximum(1, np.abs(r["e_d"][ok]))
    assert np.all(bal < {"strict": 3e-6, "paper": 1e-4}[contact]), np.max(bal)


def test_waveform_frequency_is_the_waveforms_own():
    # A waveform carries its own base frequency: params.omega must not leak into it.
    wave = lj.Fourier(jnp.zeros(1), jnp.array([0.05]), 6.0, 3.0)
    a = lj.simulate(lj.Params(omega=2.0), 10.0, save_at=jnp.linspace(0, 10, 11), waveform=wave)
    b = lj.simulate(lj.Params(omega=6.0), 10.0, save_at=jnp.linspace(0, 10, 11))
    np.testing.assert_allclose(a.X, b.X, rtol=1e-12, atol=1e-12)
    ma = lj.measure(lj.Params(omega=2.0), z=0.3, horizon=30.0, waveform=wave)
    mb = lj.measure(lj.Params(omega=6.0), z=0.3, horizon=30.0)
    np.testing.assert_allclose(ma.tau_z, mb.tau_z, rtol=1e-12)


@pytest.mark.parametrize("contact", ["strict", "paper"])
@pytest.mark.parametrize("omega, a, mhat", [(20.0, 0.1, 0.3), (6.0, 0.05, 0.5), (2.0, 0.09, 0.2)])
def test_breakaway_from_relaxed_springs_is_located_exactly(contact, omega, a, mhat):
    # d = 0, at rest at l = lbar = l0(0): F_1 = -k a sin(omega t) and N_1 = m_1 = 2 mhat while both
    # masses stick, so the lighter one (both at mhat = 0.5) breaks away at sin(omega t*) = mu_s m_1 / (k a). |F_1| has a
    # kink at t = 0 (F_1 = 0); the first iteration must end on t*, not where a two-sided rate puts it.
    from locomotion_jax.dynamics import _engine
    from locomotion_jax.dynamics._runs import chain_initial_state
    from locomotion_jax.model._waveform import Sinusoid

    p = lj.Params(omega=omega, a=a, d=0.0, mhat=mhat).astype(jnp.float64)
    _, P, valid = _paper.physics(p, Sinusoid.from_params(p))
    st = chain_initial_state(P, valid, contact, "paper", None)
    assert all(bool(s) for s in st.stuck)
    t_star = math.asin(p.mu_s * 2 * mhat / (p.k * a)) / omega
    while float(st.t) < t_star * (1 - 1e-6):  # steps shortened on the predicted event
        st, _ = _engine.step(P, contact, 0.01, st, jnp.asarray(1.0))
        assert all(bool(s) for s in st.stuck)
    assert float(st.t) == pytest.approx(t_star, rel=1e-10, abs=1e-13)
    assert bool(st.pend[0]) and bool(st.pend[1]) == (mhat == 0.5)  # equal masses break away together
