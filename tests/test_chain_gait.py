"""`steady_gait` for chains of N masses: the periodic orbit against a long direct simulation
averaged over whole periods, its monodromy against finite differences of the period map, and
the N = 2 chain against the two-mass solver (itself compared with the reference in
test_gait.py)."""

import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from locomotion_jax.gaits import _shooting as cg


P = np.pi


pytestmark = pytest.mark.xdist_group("chain_gait")  # the module's worms are solved once, on one worker


@pytest.fixture(scope="module")
def worms():
    """N = 3 worms (travelling waves), strict contact: two stick-slip gaits (waves towards the
    front and the rear), a pure-slip gait driven by anisotropy (d = 0), an anisotropic stick-slip
    gait, and an invalid configuration (omega < 0)."""
    om = np.array([3.0, 6.0, 12.0, 6.0, -1.0])
    a = np.array([0.08, 0.05, 0.03, 0.05, 0.05])
    phi = np.array([2 * P / 3, -2 * P / 3, 2 * P / 3, 2 * P / 3, 1.0])
    d = np.array([0.5, 0.5, 0.0, 0.0, 0.5])
    col = lambda *v: np.array(v)[:, None]
    friction = lj.AnisotropicCoulomb(col(0.7, 0.7, 0.7, 0.7, 0.7), col(0.7, 0.7, 0.9, 0.9, 0.7),
                                     col(0.5, 0.5, 0.5, 0.5, 0.5), col(0.5, 0.5, 0.7, 0.7, 0.5))  # fmt: skip
    chain = lj.Chain(masses=np.ones((5, 3)), d=d[:, None], waveforms=lj.TravellingWave(a, om, phi),
                     friction=friction, check=False)  # fmt: skip
    return chain, lj.steady_gait(chain)


def test_chain_gait_equals_long_direct_simulation(worms):
    """Speed and cost of transport of the orbit equal `simulate` averaged over 12 periods after
    the transient has decayed below 1e-10 (from the orbit's own multipliers), to 1e-8."""
    chain, g = worms
    assert list(np.asarray(g.status)) == [lj.GaitStatus.CONVERGED] * 4 + [lj.GaitStatus.INVALID]
    assert list(np.asarray(g.regime)[:4]) == [lj.Regime.SSL, lj.Regime.SSL, lj.Regime.SL, lj.Regime.SSL]
    assert np.all(np.asarray(g.stable)[:4]) and np.all(np.asarray(g.k)[:4] == 1)
    assert np.all(np.isnan(np.asarray(g.mean_speed)[4])) and not np.any(np.isnan(np.asarray(g.mean_speed)[:4]))
    omega = np.asarray(chain.waves.omega)[:4]
    mu = np.max(np.abs(np.asarray(g.multipliers)[:4]), axis=-1)
    # Saved at every period of its own omega, the direct run restarts its steps where the
    # period map does (one call per omega, the same number of saves: one compilation).
    n0 = int(np.ceil(np.max(np.log(1e-10) / np.log(mu))))
    K = 12
    assert n0 < 800
    speed, cost, status = np.zeros(4), np.zeros(4), []
    for w in np.unique(omega):
        T = 2 * P / w
        tr = lj.simulate(chain, (n0 + K) * T, save_at=np.arange(n0 + K + 1) * T)
        X, ed = np.asarray(tr.X)[:4], np.asarray(tr.e_d)[:4]
        status.append(np.asarray(tr.status)[4])
        dX = X[:, -1] - X[:, n0]
        at = omega == w
        speed[at], cost[at] = (dX / (K * T))[at], ((ed[:, -1] - ed[:, n0]) / np.abs(dX))[at]
    np.testing.assert_allclose(np.asarray(g.mean_speed)[:4], speed, rtol=1e-8)
    np.testing.assert_allclose(np.asarray(g.cost_of_transport)[:4], cost, rtol=1e-8)
    # On the orbit the energy is periodic: the work per period equals the dissipation, up to
    # the integrator's error (worst here the fast pure-slip worm at 52 steps per period:
    # 1.7e-5 at dt = 0.01, 4.8e-7 at 0.005, 1.1e-8 at 0.0025).
    np.testing.assert_allclose(np.asarray(g.work)[:4], np.asarray(g.e_d)[:4], rtol=5e-5)
    assert status == [lj.Status.INVALID] * len(status)


def test_transient_speed_equals_simulation_and_the_gait(worms):
    """`transient_speed` (the chain optimiser's screen reads it before solving gaits): the centre
    of mass's mean speed over periods 18 to 30 from the start at rest equals `simulate`'s, saved
    at those times (where the steps restart, as in the transient), to 1e-9; it nears the steady
    gait's speed as the transient decays; NaN for the invalid configuration."""
    chain, g = worms
    v = cg.transient_speed(chain, transient=30, last=12, dynamics=lj.Exact(), start="paper")
    assert v.shape == (5,) and np.isnan(v[4]) and np.all(np.isfinite(v[:4]))
    omega = np.asarray(chain.waves.omega)[:4]
    direct = np.zeros(4)
    for w in np.unique(omega):
        T = 2 * P / w
        X = np.asarray(lj.simulate(chain, 30 * T, save_at=np.array([18 * T, 30 * T])).X)[:4]
        direct[omega == w] = ((X[:, 1] - X[:, 0]) / (12 * T))[omega == w]
    np.testing.assert_allclose(v[:4], direct, rtol=1e-9)
    # Its error against the gait decays like the transient, |mu|^n after n periods: 1e-5 (mu = 0.70)
    # to 0.14 for the pure-slip worm (mu = 0.97), which the screen's margin (half of v_min) allows.
    mu = np.max(np.abs(np.asarray(g.multipliers)[:4]), axis=-1)
    gait = np.asarray(g.mean_speed)[:4]
    assert np.all(np.abs(v[:4] - gait) <= (mu**18 + 1e-8) * np.abs(gait))  # 1e-8: the integration error
    with pytest.raises(ValueError, match="1 <= last < transient"):
        cg.transient_speed(chain, transient=10, last=10, dynamics=lj.Exact())


def test_chain_monodromy_against_finite_differences(worms):
    """The monodromy of the pure-slip worm (every mass moving at the section) against central
    differences of the period map, and so its multipliers, to 1e-5."""
    chain, g = worms
    i = 2
    one = jax.tree_util.tree_map(lambda x: x[i], chain.broadcast())
    Pc = one.physics()
    y = jnp.asarray(g.state[i])
    phi = jax.jit(lambda y: cg.period_map(Pc, "strict", 0.01, 100_000, 1.0, y).y)
    h = 1e-6
    cols = [(phi(y + h * e) - phi(y - h * e)) / (2 * h) for e in jnp.eye(y.shape[0], dtype=y.dtype)]
    M_fd = np.stack([np.asarray(c) for c in cols], axis=1)
    M = np.asarray(g.monodromy[i])
    np.testing.assert_allclose(M, M_fd, atol=1e-5 * np.max(np.abs(M)))
    ev = lambda A: np.sort_complex(np.linalg.eigvals(A))
    np.testing.assert_allclose(ev(M), ev(M_fd), atol=1e-5)
    assert np.all(np.asarray(g.state[i])[2:] != 0)  # no mass at rest at the section


@pytest.mark.parametrize("layout", ["array", "unrolled"])
def test_monodromy_through_coincident_events(layout):
    """A symmetric worm (equal masses, springs in antiphase) whose end masses break away and stop at
    the same instants: each switch is differentiated at its own time (`_engine._retimed`), so
    the monodromy equals central differences of the period map to 1e-5, as where the events are
    apart; a mass at rest at the section has a zero column in both."""
    fr = lj.AnisotropicCoulomb(0.5, 0.9, 0.3, 0.7)
    chain = lj.Chain(masses=[1.0] * 3, d=0.0, waveforms=lj.TravellingWave(0.05, 3.5, P), friction=fr, layout=layout)
    g = lj.steady_gait(chain, periods=(1,), start="relaxed")
    y = jnp.asarray(g.state)
    assert bool(g.converged) and float(y[2]) == 0.0 and float(y[4]) == 0.0  # the end masses stuck at phase 0
    assert abs(float(y[0] + y[1]) - 6.0) < 1e-9  # x_3 - x_1 = 2 lbar: the end masses move (and switch) together
    Pc = cg.physics_for(chain, "strict")(chain)[0]
    phi = jax.jit(lambda y: cg.period_map(Pc, "strict", 0.01, 100_000, 1.0, y).y)
    h = 1e-6
    M_fd = np.stack([np.asarray((phi(y + h * e) - phi(y - h * e)) / (2 * h)) for e in jnp.eye(5, dtype=y.dtype)], 1)
    M = np.asarray(g.monodromy)
    assert np.max(np.abs(M)) > 0.1
    np.testing.assert_allclose(M, M_fd, atol=1e-5 * np.max(np.abs(M)))


def test_two_mass_chain_gait_equals_the_two_mass_solver():
    """`Chain.from_params` (the paper's model as N = 2) on the N-mass solver equals the two-mass
    `steady_gait`: a stick-slip and a pure-slip gait."""
    p = lj.Params(omega=np.array([2.0, 5.0]))
    g2 = lj.steady_gait(p)
    gc = lj.steady_gait(lj.Chain.from_params(p))
    assert list(np.asarray(gc.regime)) == [lj.Regime.SSL, lj.Regime.SL]
    for a, b in ((gc.mean_speed, g2.mean_speed), (gc.cost_of_transport, g2.cost_of_transport),
                 (gc.stick_fraction[:, 0], g2.stick_fraction1), (gc.stick_fraction[:, 1], g2.stick_fraction2),
                 (gc.state[:, 0], g2.u), (gc.state[:, 1], g2.v1), (gc.state[:, 2], g2.v2)):  # fmt: skip
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(np.abs(np.asarray(gc.multipliers)), np.abs(np.asarray(g2.multipliers)), atol=1e-10)


def test_jacfwd_in_turn_equals_jacfwd():
    """The corrector's Jacobian (`_forward.jacfwd_in_turn`: directions in turn on a CPU) is
    `jax.jacfwd`'s, with the auxiliary output of the primal, under `vmap` as well."""
    from locomotion_jax.dynamics._forward import jacfwd_in_turn

    def f(x):
        y = jnp.stack([jnp.sin(x[0]) * x[1], x[2] ** 3 - x[0], jnp.exp(x[1] * x[2])])
        return y, (jnp.sum(x), x[0] > 0)

    X = jnp.asarray(np.random.default_rng(0).normal(size=(4, 3)))
    for a, b in zip(jax.tree_util.tree_leaves(jax.vmap(jacfwd_in_turn(f, has_aux=True))(X)),
                    jax.tree_util.tree_leaves(jax.vmap(jax.jacfwd(f, has_aux=True))(X))):  # fmt: skip
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-14, atol=0)
    g = lambda x: f(x)[0]
    np.testing.assert_allclose(np.asarray(jacfwd_in_turn(g)(X[0])), np.asarray(jax.jacfwd(g)(X[0])), rtol=1e-14)


def test_patience_stops_only_the_stalled_configurations(monkeypatch):
    """`patience` (the optimiser's screen) stops a configuration whose Newton residual has not
    halved for that many iterations: the paper's model at omega = 4.2 has no gait of period 1 to
    4, and its residual cycles near 5e-3. The gaits found are the same to the last bit, with the
    same iterations; the stalled configuration stops within `patience` + 2 iterations instead of 12."""
    its = []
    newton = cg.newton
    monkeypatch.setattr(cg, "newton", lambda *a, **k: (lambda r: its.append(r["it"]) or r)(newton(*a, **k)))
    chain = lj.Chain.from_params(lj.Params(omega=np.array([2.0, 4.2, 5.0, 4.2])))
    runs = {}
    for patience in (None, 3):
        its.clear()
        g = cg.steady_gait_chain(chain, dynamics=lj.Exact(), patience=patience)
        runs[patience] = g, np.array(its)
    (g0, it0), (g3, it3) = runs[None], runs[3]
    assert list(np.asarray(g0.converged)) == [True, False, True, False]
    assert it0.shape == it3.shape and np.all(it0[:, [1, 3]] == 12)
    assert np.all(it3[:, [1, 3]] <= 5)
    np.testing.assert_array_equal(it3[:, [0, 2]], it0[:, [0, 2]])
    for a, b in zip(jax.tree_util.tree_leaves(g0), jax.tree_util.tree_leaves(g3)):
        np.testing.assert_array_equal(np.asarray(a)[[0, 2]], np.asarray(b)[[0, 2]])


def test_chain_gait_bad_input():
    chain = lj.Chain(masses=np.ones(3), waveforms=lj.TravellingWave(0.05, 3.0, 1.0))
    with pytest.raises(ValueError, match="carries its own waveforms"):
        lj.steady_gait(chain, waveform=lj.Sinusoid(0.1, 2.0, 3.0))
    with pytest.raises(ValueError, match=r"section states .* of shape \(5,\)"):
        lj.steady_gait(chain, start=np.zeros(4))
    with pytest.raises(ValueError, match="the gaps u_j must be > 0"):
        lj.steady_gait(chain, start=np.zeros(5))
    with pytest.raises(ValueError, match="contact"):
        lj.steady_gait(chain, contact="soft")


def test_chain_basins_and_gaits_from_given_starts(worms):
    """`steady_gait(chain, start=states)` and `basins` on a chain: starts near and far from the
    anisotropic worm's stick-slip gait (section states: gaps, then velocities) all end on it, its
    speed and cost to 1e-9; a start whose masses are out of order is flagged, never run."""
    chain, gaits = worms
    worm, gait = chain[3], jax.tree_util.tree_map(lambda x: x[3], gaits)
    y = np.asarray(gait.state)
    assert y.shape == (5,) and bool(gait.converged)
    starts = np.stack([y, y + np.array([0.02, -0.02, 0.05, 0.0, -0.05]), y + np.array([-0.1, 0.1, 0, 0, 0]),
                       np.array([3.0, 3.0, 0.0, 0.0, 0.0]), np.array([-1.0, 3.0, 0.0, 0.0, 0.0])])  # fmt: skip
    b = lj.basins(worm, starts)
    assert list(np.asarray(b.label)) == [0, 0, 0, 0, -1] and list(np.asarray(b.count)) == [4]
    assert int(b.per_start.status[-1]) == lj.GaitStatus.INVALID
    np.testing.assert_allclose(float(b.gaits.mean_speed[0]), float(gait.mean_speed), rtol=1e-9)
    np.testing.assert_allclose(float(b.gaits.cost_of_transport[0]), float(gait.cost_of_transport), rtol=1e-9)
    with pytest.raises(ValueError, match=r"starts must have shape grid \+ \(5,\)"):
        lj.basins(worm, np.zeros((2, 3)))
    with pytest.raises(ValueError, match="section states"):
        lj.steady_gait(chain, start=np.zeros((5, 3)))
