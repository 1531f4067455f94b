"""The exact engine against the independent float64 event-driven scipy solver in
`tests/reference.py` (which shares no code with the package)."""

import math
from concurrent.futures import ProcessPoolExecutor

import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from reference import reference_measure, reference_simulate
from scipy.stats import linregress


# 24 configurations over the SSL and SL regimes (none lifts off under the strict
# reading, so both readings agree); (omega, a, d, mhat, mu_s).
CONFIGS = [
    (1.5, 0.05, 0.5, 0.5, 0.7),
    (2.0, 0.05, 0.5, 0.5, 0.7),
    (2.0, 0.07, 0.5, 0.5, 0.7),
    (2.0, 0.05, 0.5, 0.5, 0.9),
    (2.5, 0.05, 0.5, 0.5, 0.6),
    (3.0, 0.05, 0.5, 0.5, 0.7),
    (3.0, 0.05, -0.5, 0.5, 0.7),
    (4.0, 0.04, 0.5, 0.5, 0.7),
    (5.0, 0.05, 0.3, 0.5, 0.7),
    (6.0, 0.05, 0.5, 0.5, 0.7),
    (4.5, 0.05, 0.5, 0.5, 0.7),
    (6.0, 0.05, 0.5, 0.45, 0.7),
    (7.0, 0.03, 0.5, 0.5, 0.7),
    (12.0, 0.03, 0.5, 0.5, 0.7),
    (14.0, 0.04, 0.5, 0.5, 0.7),
    (16.0, 0.05, 0.5, 0.5, 0.7),
    (16.0, 0.05, 0.5, 0.5, 1.0),
    (16.0, 0.05, 0.25, 0.5, 0.7),
    (18.0, 0.05, 0.5, 0.5, 0.7),
    (20.0, 0.05, 0.5, 0.5, 0.7),
    (23.0, 0.05, 0.5, 0.5, 0.7),
    (23.0, 0.05, -0.5, 0.5, 0.7),
    (23.0, 0.04, 0.5, 0.55, 0.7),
    (25.0, 0.06, 0.5, 0.5, 0.7),
    (30.0, 0.06, 0.5, 0.5, 0.7),
    (1.0, 0.08, 0.5, 0.5, 0.7),
]
Z = 5.0
HORIZON = 1200.0


def _as_dict(cfg):
    omega, a, d, mhat, mu_s = cfg
    return dict(omega=omega, a=a, d=d, mhat=mhat, mu_s=mu_s)


def _ref(cfg):
    return reference_measure(_as_dict(cfg), z=Z, horizon=HORIZON, contact="strict", rtol=1e-10, atol=1e-12)


@pytest.fixture(scope="module")
def reference_results():
    with ProcessPoolExecutor(max_workers=2) as pool:
        return list(pool.map(_ref, CONFIGS))


@pytest.fixture(scope="module")
def batch():
    cols = list(zip(*CONFIGS))
    return lj.Params(
        omega=jnp.array(cols[0]),
        a=jnp.array(cols[1]),
        d=jnp.array(cols[2]),
        mhat=jnp.array(cols[3]),
        mu_s=jnp.array(cols[4]),
    )


def test_tau5_e5_regime_float64(reference_results, batch):
    m = lj.measure(batch, z=Z, horizon=HORIZON)
    ref_tau = np.array([r["tau_z"] for r in reference_results])
    ref_e = np.array([r["e_z"] for r in reference_results])
    ref_regime = np.array([r["regime"] for r in reference_results])
    assert np.all(np.isfinite(ref_tau)), "every configuration must reach z in the reference"
    assert {0, 1} <= set(ref_regime.tolist()), "both regimes must be represented"
    assert np.all(np.asarray(m.status) == lj.Status.OK)
    np.testing.assert_allclose(m.tau_z, ref_tau, rtol=1e-4)  # required: 1e-3; measured ~1e-6
    np.testing.assert_allclose(m.e_z, ref_e, rtol=1e-4)
    np.testing.assert_array_equal(np.asarray(m.regime), ref_regime)
    for name in ("stick_fraction1", "stick_fraction2"):
        np.testing.assert_allclose(getattr(m, name), [r[name] for r in reference_results], atol=1e-4)
    np.testing.assert_allclose(m.mean_speed, [r["mean_speed"] for r in reference_results], rtol=1e-4)


def test_tau5_float32(reference_results, batch):
    m = lj.measure(batch.astype(jnp.float32), z=Z, horizon=HORIZON)
    ref_tau = np.array([r["tau_z"] for r in reference_results])
    ref_e = np.array([r["e_z"] for r in reference_results])
    err = np.abs(np.asarray(m.tau_z, np.float64) / ref_tau - 1)
    # float32: round-off in t and X over 1e5 steps; the README quotes this figure.
    assert np.max(err) < 1e-2
    assert np.median(err) < 2e-4
    np.testing.assert_allclose(np.asarray(m.e_z, np.float64), ref_e, rtol=1e-2)


@pytest.mark.parametrize("omega", [2.0, 16.0])
def test_fourth_order_convergence(omega):
    # Located switches: the error falls at the integrator's order (4), not at
    # first order as it would if switches were snapped to the grid.
    T = 30.0
    ref = reference_simulate(dict(omega=omega), T, save_at=np.array([0.0, T]), rtol=1e-12, atol=1e-13)
    dts = np.array([0.08, 0.04, 0.02, 0.01])
    errs = []
    for dt in dts:
        tr = lj.simulate(lj.Params(omega=omega), T, save_at=jnp.array([0.0, T]), dynamics=lj.Exact(dt=float(dt)))
        errs.append(abs(float(tr.X[-1]) - ref["X"][-1]) + abs(float(tr.e_d[-1]) - ref["e_d"][-1]))
    slope = linregress(np.log(dts), np.log(errs)).slope
    assert slope > 3.5, (slope, errs)


def test_trajectory_matches_reference():
    save = np.linspace(0.0, 40.0, 401)
    for omega in (2.0, 23.0):
        ref = reference_simulate(dict(omega=omega), 40.0, save_at=save, contact="paper")
        tr = lj.simulate(
            lj.Params(omega=omega), 40.0, save_at=jnp.asarray(save), contact="paper", dynamics=lj.Exact(dt=0.005)
        )
        for name in ("x1", "x2", "v1", "v2", "e_d", "w"):
            np.testing.assert_allclose(getattr(tr, name), ref[name], atol=2e-6, err_msg=name)
        agree = np.mean(np.asarray(tr.mode) == ref["mode"])
        assert agree > 0.99  # modes differ only at samples within ~dt of a switch


def test_liftoff_time_matches_reference():
    p = dict(omega=23.0, a=0.08)
    ref = reference_simulate(p, 2.0, save_at=np.linspace(0, 2, 21))
    tr = lj.simulate(lj.Params(**p), 2.0, save_at=jnp.linspace(0, 2, 21))
    assert bool(tr.liftoff) and ref["liftoff"]
    assert math.isclose(float(tr.t_liftoff), ref["t_liftoff"], rel_tol=1e-5)  # RK4 at dt = 0.01: 4e-7
