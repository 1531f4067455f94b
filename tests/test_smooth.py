"""The smoothed (diffrax) dynamics (`dynamics/_smoothed.py`), for the paper's model and for chains:
convergence to the exact model as eps -> 0, the energy balance, lift-off, differentiability, the
paper's model and its two-mass chain through one engine, batches of chains."""

from typing import Any

import diffrax
import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from locomotion_jax.dynamics import _smoothed, _smoothed_dynamics
from locomotion_jax.dynamics._smoothed_dynamics import params_physics
from scipy.stats import linregress


T = 20.0
EPSS = np.array([3e-2, 1e-2, 3e-3, 1e-3, 3e-4])


def _error(omega, eps, exact):
    sm = lj.simulate(
        lj.Params(omega=omega), T, save_at=jnp.array([0.0, T]), dynamics=lj.Smoothed(eps=eps, rtol=1e-8, atol=1e-10)
    )
    return abs(float(sm.X[-1] - exact.X[-1])) + abs(float(sm.e_d[-1] - exact.e_d[-1]))


def test_converges_to_exact_as_eps_to_zero():
    # Measured rate ~ eps^0.55 (the Stribeck width is sqrt(eps)); README quotes it.
    for omega in (2.0, 16.0):
        exact = lj.simulate(lj.Params(omega=omega), T, save_at=jnp.array([0.0, T]), dynamics=lj.Exact(dt=0.0025))
        errs = np.array([_error(omega, eps, exact) for eps in EPSS])
        # scipy's stubs do not name the fields of linregress's result
        slope = linregress(np.log(EPSS), np.log(errs)).slope  # pyright: ignore[reportAttributeAccessIssue]
        assert slope > 0.35, (omega, slope, errs)
        assert errs[-1] < 0.1 * errs[0]
        assert errs[-1] < 0.06


def test_energy_balance_smoothed():
    tr = lj.simulate(lj.Params(omega=6.0), 30.0, save_at=jnp.linspace(0, 30, 31), dynamics=lj.Smoothed(1e-3))
    np.testing.assert_allclose(tr.w - tr.e_d - (tr.e - tr.e[0]), 0, atol=1e-6)
    # The motion starts at t = 0 whatever the first save time: saving from t = 10 gives the
    # same states as saving from 0 (to the adaptive solver's tolerance).
    late = lj.simulate(lj.Params(omega=6.0), 30.0, save_at=jnp.linspace(10, 30, 21), dynamics=lj.Smoothed(1e-3))
    for k in ("x1", "v2", "e_d", "w"):
        np.testing.assert_allclose(getattr(late, k), getattr(tr, k)[10:], rtol=1e-5, atol=1e-6, err_msg=k)


def test_smoothed_measure_and_liftoff_flag():
    p = lj.Params(omega=jnp.array([2.0, 9.5]))
    m = lj.measure(p, z=0.5, horizon=60.0, dynamics=lj.Smoothed(1e-3))
    assert int(m.status[0]) == lj.Status.OK and bool(m.reached[0])
    assert int(m.regime[0]) == lj.Regime.SSL
    assert int(m.status[1]) == lj.Status.LIFTOFF and bool(m.liftoff[1])
    np.testing.assert_allclose(m.balance[0], 0, atol=1e-6)


def test_gradient_matches_finite_differences():
    # d X(T) / d a through diffrax (discretise-then-optimise), against central differences.
    def final_x(a):
        p = lj.Params(a=a, omega=6.0, check=False)
        wave = lj.Sinusoid.from_params(p)
        y0 = jnp.array([0.0, 3.0, 0.0, 0.0, 0.0, 0.0])  # (x1, x2, v1, v2, e_d, w)
        dyn = lj.Smoothed(1e-2, rtol=1e-10, atol=1e-12)
        P = params_physics(p, wave)
        sol, _ = _smoothed.solve(P, "paper", dyn, 0.0, 5.0, y0, diffrax.SaveAt(t1=True))
        assert sol.ys is not None
        return _smoothed.centre_of_mass(P, sol.ys[-1])

    g = jax.grad(final_x)(jnp.asarray(0.05))
    h = 1e-5
    fd = (final_x(jnp.asarray(0.05 + h)) - final_x(jnp.asarray(0.05 - h))) / (2 * h)
    np.testing.assert_allclose(g, fd, rtol=1e-4)
    assert abs(float(g)) > 1e-3


def test_initial_state_and_t_start():
    # From the state saved at t1 = 2 pi (two periods of omega = 2: the actuation's phase is that of
    # t = 0) the motion goes on as the run through t1 does, to the solver's tolerance; and a
    # measurement from t_start = t1 starts at that run's X(t1).
    p = lj.Params(omega=2.0)
    dyn = lj.Smoothed(1e-2)
    t1 = 2 * np.pi
    full = lj.simulate(p, t1 + 5.0, save_at=jnp.array([t1, t1 + 5.0]), dynamics=dyn)
    state = tuple(float(getattr(full, k)[0]) for k in ("x1", "v1", "x2", "v2"))
    assert abs(state[1]) + abs(state[3]) > 1e-3  # a moving state, not the start at rest
    cont = lj.simulate(p, 5.0, save_at=jnp.array([0.0, 5.0]), dynamics=dyn, initial=state)
    assert cont.start == "initial"
    for k in ("x1", "v1", "x2", "v2"):
        np.testing.assert_allclose(float(getattr(cont, k)[-1]), float(getattr(full, k)[-1]), rtol=1e-5, atol=1e-6)
    m = lj.measure(p, z=0.1, t_start=t1, horizon=20.0, window=5.0, dynamics=dyn)
    assert int(m.status) == lj.Status.OK
    np.testing.assert_allclose(float(m.t_start), t1)
    np.testing.assert_allclose(float(m.X_start), float(full.X[0]), rtol=1e-6)


TS = jnp.linspace(0.0, 10.0, 21)


CHAIN_SMOOTH = pytest.mark.xdist_group("chain_smooth")  # the chain batch is run once, on one worker


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


@CHAIN_SMOOTH
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


@CHAIN_SMOOTH
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


def _count(jaxpr: Any, primitive: str) -> int:
    """The equations of `primitive` in a jaxpr, its sub-jaxprs (calls, loops) included."""
    n = 0
    for eqn in jaxpr.eqns:
        n += eqn.primitive.name == primitive
        for param in eqn.params.values():
            for sub in param if isinstance(param, (list, tuple)) else [param]:
                sub = getattr(sub, "jaxpr", sub)
                if hasattr(sub, "eqns"):
                    n += _count(sub, primitive)
    return n


def test_natural_frequencies_call_the_eigensolver_once():
    """`Chain.natural_frequencies` (the default measurement start) calls the batched eigensolver once
    for every held mass together: on a CPU, concurrent batched eigensolver calls inside one program
    can deadlock XLA's thread pool (each waits for workers the other holds)."""
    worm = lj.Chain(masses=np.ones((4, 6)), k=np.linspace(40.0, 60.0, 5), lbar=3.0)
    assert _count(jax.make_jaxpr(lambda c: c.natural_frequencies())(worm).jaxpr, "eigh") == 1
    got = np.asarray(worm.natural_frequencies())
    assert got.shape == (4, 6, 5)
    K = np.diag(np.r_[worm.k, 0.0] + np.r_[0.0, worm.k]) - np.diag(worm.k, 1) - np.diag(worm.k, -1)
    for held in range(6):  # masses of 1: the eigenvalues of K with the held mass's row and column removed
        keep = [i for i in range(6) if i != held]
        np.testing.assert_allclose(got[0, held], np.sqrt(np.linalg.eigvalsh(K[np.ix_(keep, keep)])), rtol=1e-12)


def test_the_smoothed_program_of_a_chain_has_no_eigensolver(monkeypatch):
    """The default measurement start of a chain (`Chain.t_start`, from eigenvalues) is computed
    outside the smoothed engine's program, as the exact engine's: a 16-mass worm measured in a batch
    of 64 hung there on the 2-core machine, with both XLA threads in the eigensolver."""
    seen = {}

    class Stop(Exception):
        pass

    def record(*args):
        seen["args"] = args
        raise Stop

    real = _smoothed_dynamics._measure_bodies
    monkeypatch.setattr(_smoothed_dynamics, "_measure_bodies", record)
    worm = lj.Chain(masses=np.ones((3, 5)), k=np.linspace(40.0, 60.0, 4), lbar=3.0,
                    waveforms=lj.TravellingWave(0.05, 2.0, 1.0))  # fmt: skip
    with pytest.raises(Stop):
        lj.measure(worm, 0.1, horizon=1.0, window=1.0, dynamics=lj.Smoothed(1e-2))
    np.testing.assert_allclose(np.asarray(seen["args"][2]), np.asarray(worm.t_start), rtol=1e-15)
    text = real.lower(*seen["args"]).as_text()  # pyright: ignore[reportFunctionMemberAccess]
    assert "syevd" not in text and "eigh" not in text


def test_the_smoothed_engine_in_float32():
    """float32 under `jax_enable_x64` (as a float32 batch beside float64 ones runs): the paper's model
    (its two-mass physics) and a 3-mass worm on bristles in the array layout, `simulate` and `measure`
    with both events armed (strict contact's lift-off, the first passage), keep float32, and `measure`
    agrees with float64 to 1e-3 relative (measured 3e-4: the adaptive solver's rtol of 1e-7 is float32's
    rounding). diffrax evaluates an event not yet armed as the default float, and the event times are
    located to float32's resolution."""
    worm = lambda dtype: lj.Chain(masses=np.array([[1.0, 1.1, 0.9]], dtype), k=50.0, d=0.3, lbar=3.0, c=0.02,
                                  waveforms=lj.TravellingWave(0.06, 3.0, 2.0), layout="array",
                                  friction=lj.AnisotropicCoulomb(0.7, 0.9, 0.5, 0.7))  # fmt: skip
    cases = (("paper's model", lambda dtype: lj.Params(omega=jnp.array([2.0, 16.0]))), ("worm", worm))
    dyn = lj.Smoothed(1e-2)
    for name, make in cases:
        kw: dict = dict(dynamics=dyn, contact="strict")
        s32 = lj.simulate(make(jnp.float32), 10.0, np.linspace(0.0, 10.0, 6), dtype=jnp.float32, **kw).to_numpy()
        assert np.all(s32["status"] == lj.Status.OK) and s32["e_d"].dtype == np.float32, name
        m32, m64 = (lj.measure(make(dtype), 0.2, horizon=30.0, window=2.0, t_start=4.0, dtype=dtype, **kw).to_numpy()
                    for dtype in (jnp.float32, jnp.float64))  # fmt: skip
        assert np.all(m32["status"] == lj.Status.OK) and m32["tau_z"].dtype == np.float32, name
        assert np.all(m32["reached"]), name
        for key in ("tau_z", "e_z", "mean_speed", "work"):
            np.testing.assert_allclose(m32[key], m64[key], rtol=1e-3, err_msg=f"{name} {key}")
