"""The smoothed engine (`dynamics/_smoothed.py`) on chains: the paper's model and its two-mass chain
through one engine, convergence to the exact N-mass engine, the energy balance, batches."""

import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest


TS = jnp.linspace(0.0, 10.0, 21)


pytestmark = pytest.mark.xdist_group("chain_smooth")  # the module's chain batch is run once, on one worker


@pytest.fixture(scope="module")
def aniso_chain():
    # Three masses on bristles (anisotropic friction), flat springs: moves by the ground's
    # asymmetry alone; the third configuration is invalid (mu_s_fwd < mu_k_fwd) and flagged.
    friction = lj.AnisotropicCoulomb(
        mu_s_fwd=np.array([0.6, 0.6, 0.3])[:, None], mu_s_bwd=0.9, mu_k_fwd=0.4, mu_k_bwd=0.7
    )
    return lj.Chain(
        masses=np.ones((3, 3)),
        d=0.0,
        waveforms=lj.TravellingWave(np.array([0.08, 0.06, 0.08]), 2.0, 1.0),
        friction=friction,
        check=False,
    )


def test_two_mass_chain_equals_the_two_mass_smoothed_model():
    # The same ODE (N = 2, Coulomb friction) through two code paths, one SSL and one SL
    # configuration: equal to the adaptive solver's tolerance (rtol 1e-7).
    p = lj.Params(omega=jnp.array([2.0, 16.0]))
    dyn = lj.Smoothed(eps=1e-2)
    a = lj.simulate(p, 10.0, save_at=TS, dynamics=dyn)
    b = lj.simulate(lj.Chain.from_params(p), 10.0, save_at=TS, dynamics=dyn)
    assert np.asarray(b.x).shape == (2, TS.size, 2)
    for mine, theirs in ((b.x[..., 0], a.x1), (b.x[..., 1], a.x2), (b.v[..., 1], a.v2), (b.e_d, a.e_d), (b.w, a.w)):
        np.testing.assert_allclose(np.asarray(mine), np.asarray(theirs), rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(np.asarray(b.e), np.asarray(a.e), rtol=1e-6)
    np.testing.assert_allclose(np.asarray(b.N[..., 0]), np.asarray(a.N1), rtol=1e-6)

    ma = lj.measure(p, z=0.3, horizon=30.0, window=5.0, dynamics=dyn)
    mb = lj.measure(lj.Chain.from_params(p), z=0.3, horizon=30.0, window=5.0, dynamics=dyn)
    assert np.all(np.asarray(ma.reached)) and np.all(np.asarray(mb.reached))
    for k in ("tau_z", "e_z", "mean_speed", "work"):
        np.testing.assert_allclose(np.asarray(getattr(mb, k)), np.asarray(getattr(ma, k)), rtol=1e-6, err_msg=k)
    np.testing.assert_array_equal(np.asarray(mb.regime), np.asarray(ma.regime))
    np.testing.assert_allclose(np.asarray(mb.stick_fraction[:, 0]), np.asarray(ma.stick_fraction1), atol=1e-3)


def test_converges_to_the_exact_engine_with_energy_balance(aniso_chain):
    # The smoothed law tends to the exact one as eps -> 0: the error of the centre of mass
    # at t = 10 against the exact N-mass engine falls with eps. The energy balance
    # w = e_d + (e - e0) (eq. 16) holds to the solver's tolerance; the invalid chain is
    # flagged and leaves the others as they are alone.
    exact = lj.simulate(aniso_chain, 10.0, save_at=TS)
    assert np.asarray(exact.status).tolist() == [lj.Status.OK, lj.Status.OK, lj.Status.INVALID]
    errors = []
    for eps in (3e-2, 1e-2, 3e-3):
        s = lj.simulate(aniso_chain, 10.0, save_at=TS, dynamics=lj.Smoothed(eps=eps))
        assert np.asarray(s.status).tolist() == [lj.Status.OK, lj.Status.OK, lj.Status.INVALID]
        assert not np.asarray(s.valid[2]).any()
        errors.append(np.abs(np.asarray(s.X[:2, -1] - exact.X[:2, -1])))
        balance = np.asarray(s.w[:2] - s.e_d[:2] - (s.e[:2] - s.e[:2, :1]))
        assert np.max(np.abs(balance)) < 1e-6 * max(1.0, float(np.max(s.e_d[:2])))
    errors = np.array(errors)
    assert np.all(np.asarray(exact.X[:2, -1]) > 0.05)  # the bristles move it forward
    assert np.all(errors[1:] < errors[:-1])  # monotone in eps
    slopes = np.polyfit(np.log([3e-2, 1e-2, 3e-3]), np.log(errors), 1)[0]  # one per configuration
    assert np.all(slopes > 0.2), (errors, slopes)
    # Alone, the first chain moves as in the batch, to the adaptive solver's tolerance (a
    # vectorised batch rounds differently, and the step-size controller follows its rounding).
    alone = lj.simulate(aniso_chain[0], 10.0, save_at=TS, dynamics=lj.Smoothed(eps=3e-3))
    np.testing.assert_allclose(np.asarray(alone.x), np.asarray(s.x[0]), rtol=1e-6, atol=1e-7)


def test_measure_a_chain_on_the_smoothed_engine(aniso_chain):
    m = lj.measure(aniso_chain, z=0.1, t_start=5.0, horizon=30.0, window=5.0, dynamics=lj.Smoothed(eps=1e-2))
    assert np.asarray(m.status).tolist() == [lj.Status.OK, lj.Status.OK, lj.Status.INVALID]
    assert np.asarray(m.reached).tolist() == [True, True, False]
    assert np.asarray(m.stick_fraction).shape == (3, 3)
    # The first passage and the energy spent are those of the same motion saved by `simulate`:
    # |X - X(t_start)| reaches z = 0.1 at t_start + tau_z, with e_d grown by e_z.
    tau = np.asarray(m.tau_z[:2])
    ends = 5.0 + np.sort(tau)
    s = lj.simulate(
        aniso_chain[:2], float(ends[-1]), save_at=np.concatenate([[5.0], ends]), dynamics=lj.Smoothed(eps=1e-2)
    )
    for i in range(2):
        j = 1 + int(np.searchsorted(ends, 5.0 + tau[i]))
        np.testing.assert_allclose(abs(float(s.X[i, j] - s.X[i, 0])), 0.1, rtol=1e-5)
        np.testing.assert_allclose(float(s.e_d[i, j] - s.e_d[i, 0]), float(m.e_z[i]), rtol=1e-5)
    assert np.all(np.asarray(m.mean_speed[:2]) > 0)
    assert np.max(np.abs(np.asarray(m.balance[:2]))) < 1e-6
