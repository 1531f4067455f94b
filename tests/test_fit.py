"""Parameter identification on synthetic measurements from the independent reference."""

import sys
from pathlib import Path

import jax
import locomotion_jax as lj
import numpy as np
import pytest


sys.path.insert(0, str(Path(__file__).parent))
from reference import DEFAULTS, reference_simulate  # noqa: E402


TRUE = dict(omega=2.0, mu_s=0.7, mu_k=0.5, c=0.01, k=50.0)
NAMES = ("mu_s", "mu_k", "c", "k")
SIGMA = 1e-4


@pytest.fixture(scope="module")
def data():
    # Positions of both masses at 200 times, with Gaussian noise: what a camera would give.
    t = np.linspace(0.1, 20.0, 200)
    ref = reference_simulate({**DEFAULTS, **TRUE}, 20.0, t)
    rng = np.random.default_rng(7)
    x = np.stack([ref["x1"], ref["x2"]], -1) + SIGMA * rng.standard_normal((t.size, 2))
    x[::7, 0] = np.nan  # missing samples are skipped
    return t, x


def test_fit_recovers_parameters_within_their_errors(data):
    assert jax.numpy.asarray(1.0).dtype == np.float64  # tests/conftest.py
    t, x = data
    guess = lj.Params(omega=2.0, mu_s=0.65, mu_k=0.45, c=0.02, k=45.0)
    fit = lj.fit_trajectory(t, x, guess, NAMES)
    assert fit.success and fit.status == lj.Status.OK, fit.message
    truth = np.array([TRUE[n] for n in NAMES])
    # Within 4 standard errors, and the errors are informative: friction and stiffness to
    # about 1e-3 relative; the small damping (c = 0.01) much less well determined (~30 %).
    assert np.all(np.abs(fit.values - truth) < 4 * fit.stderr), (fit.values, fit.stderr)
    assert np.all(fit.stderr / truth < np.array([2e-3, 2e-3, 0.5, 2e-3])), fit.stderr / truth
    # The noise level estimated from the residuals is the one put in.
    assert abs(fit.sigma / SIGMA - 1) < 0.15, fit.sigma
    # Known noise: the same errors (the residuals are those of the noise).
    known = lj.fit_trajectory(t, x, fit.params, NAMES, sigma=SIGMA)
    # (The same optimum to far below its errors: c, known to 30 %, moves by ~1e-6 relative
    # with the Jacobian's rounding.)
    assert np.all(np.abs(known.values - fit.values) < 1e-3 * fit.stderr), (known.values, fit.values)
    np.testing.assert_allclose(known.stderr, fit.stderr, rtol=0.2)
    assert "| mu_s |" in fit.summary()


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(names=("mu_x",)), "names: 'mu_x' is not a field of the Params"),
        (dict(names=()), "names must be distinct parameter names"),
        (dict(t=np.array([1.0, 0.5])), "t must be a non-empty 1-D array of increasing"),
        (dict(x=np.zeros((2, 3))), r"x must have shape \(len\(t\), 2\)"),
        (dict(params=lj.Chain(masses=[1.0, 1.0, 1.0]), x=np.zeros((2, 2))), r"x must have shape \(len\(t\), 3\)"),
        (dict(params=lj.Chain(masses=[1.0, 1.0, 1.0]), names=("mu_k_fwd",)), "'mu_k_fwd' is not a field of the Chain"),
        (dict(sigma=0.0), "sigma must be > 0"),
        (dict(params=lj.Params(omega=np.array([1.0, 2.0]))), "params must be one configuration"),
    ],
)
def test_bad_input_is_refused(kwargs, match):
    args = dict(t=np.array([0.5, 1.0]), x=np.zeros((2, 2)), params=lj.Params(), names=("mu_k",))
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        lj.fit_trajectory(args.pop("t"), args.pop("x"), args.pop("params"), **args)


CHAIN_TRUE = dict(k=50.0, mu_k_fwd=0.3, mu_k_bwd=0.7)


def _worm(k, mu_k_fwd, mu_k_bwd):
    return lj.Chain(
        masses=[1.0, 1.0, 1.0], k=k, d=0.0, lbar=3.0, c=0.01,
        friction=lj.AnisotropicCoulomb(0.5, 0.9, mu_k_fwd, mu_k_bwd),
        waveforms=lj.TravellingWave(0.1, 2.0, 0.785),
    )  # fmt: skip


def test_fit_of_a_chain_with_anisotropic_friction():
    """The same fit on any mechanism: a 3-mass worm on bristles, its positions from the
    independent chain reference with noise, fitted per spring (`k[0]`, `k[1]`) and per
    direction of the kinetic friction from a start 2 % off (from 5 % off the fit stalls in a
    local minimum: the stick durations make the positions rough functions of the parameters)."""
    from reference_chain import chain_config, reference_chain_simulate

    t = np.linspace(0.1, 15.0, 120)
    cfg = chain_config([1.0, 1.0, 1.0], k=50.0, d=0.0, lbar=3.0, c=0.01, omega=2.0, a=0.1, phi=0.785,
                       mu_s_fwd=0.5, mu_s_bwd=0.9, mu_k_fwd=0.3, mu_k_bwd=0.7)  # fmt: skip
    ref = reference_chain_simulate(cfg, 15.0, t)
    rng = np.random.default_rng(11)
    x = ref["x"] + SIGMA * rng.standard_normal(ref["x"].shape)
    names = ("k", "friction.mu_k_fwd", "friction.mu_k_bwd")
    fit = lj.fit_trajectory(t, x, _worm([49.0, 51.0], 0.306, 0.686), names)
    assert fit.success and fit.status == lj.Status.OK, fit.message
    assert fit.names == ("k[0]", "k[1]", "friction.mu_k_fwd", "friction.mu_k_bwd")
    truth = np.array([50.0, 50.0, 0.3, 0.7])
    assert np.all(np.abs(fit.values - truth) < 4 * fit.stderr), (fit.values, fit.stderr)
    assert np.all(fit.stderr / truth < 1e-2), fit.stderr / truth
    assert abs(fit.sigma / SIGMA - 1) < 0.2, fit.sigma
    assert isinstance(fit.params, lj.Chain)
    np.testing.assert_allclose(np.asarray(fit.params.k), fit.values[:2])
