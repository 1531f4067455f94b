"""The smoothed (diffrax) dynamics: convergence to the exact model as eps -> 0,
energy balance, lift-off, and differentiability."""

import diffrax
import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
from locomotion_jax.dynamics import _smoothed
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
