"""Every input checked at the model's boundary (issue 29): a clear error naming the parameter and its
valid range for known values, a flagged `INVALID` in a batch, never status OK with a NaN."""

import math
from typing import Any

import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from locomotion_jax.dynamics._flat import FlatBatch
from locomotion_jax.model._params import safe_params


SHORT: dict[str, Any] = dict(z=0.1, t_start=1.0, horizon=5.0, window=2.0)


def _no_nan_with_ok(m) -> None:
    """Where `status` is OK, no field of the measurement is NaN."""
    ok = np.asarray(m.status) == lj.Status.OK
    for name, value in m.to_numpy().items():
        v = np.asarray(value)
        if v.dtype.kind == "f":
            bad = np.isnan(v).reshape(ok.shape + (-1,)).any(-1) & ok
            assert not bad.any(), f"{name} is NaN with status OK"


# -- waveforms ------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "wave, match",
    [
        (lj.Sinusoid(float("nan"), 2.0, 3.0), r"'a' of Sinusoid: got a=nan; the valid range is finite"),
        (lj.Sinusoid(5.0, 2.0, 3.0), r"'a' of Sinusoid: got a=5.0, lbar=3.0; the valid range is \|a\| < lbar"),
        (lj.Sinusoid(0.05, 2.0, -3.0), r"'lbar' of Sinusoid: got lbar=-3.0; the valid range is lbar > 0"),
        (lj.Sinusoid(0.05, math.inf, 3.0), r"'omega' of Sinusoid: got omega=inf; the valid range is omega >= 0"),
        (
            lj.Fourier(np.array([0.0, math.nan]), np.array([0.05, 0.0]), 2.0, 3.0),
            r"'cos' of Fourier: got cos=\[0.0, nan\]",
        ),
        (lj.Fourier(np.array([3.0]), np.array([3.0]), 2.0, 3.0), r"'stroke' of Fourier: got stroke=4.24.*lbar=3.0"),
        (lj.Spline(np.array([0.0, 0.1, math.inf, 0.0]), 2.0, 3.0), r"'control' of Spline"),
    ],
)
def test_waveform_of_params_is_validated(wave, match):
    """A waveform given to `Params` was not checked at all: NaN ran to status OK with NaN
    results, a > lbar or lbar < 0 came back LIFTOFF."""
    with pytest.raises(ValueError, match=match):
        lj.measure(lj.Params(), waveform=wave, **SHORT)
    with pytest.raises(ValueError, match=match):
        lj.simulate(lj.Params(), 1.0, waveform=wave)


def test_invalid_waveform_in_the_engine_is_flagged():
    """Where the front end does not see the values (a waveform built under `jit`, as the
    optimisers do), the engine flags the configuration INVALID in its own result; a batch-mate
    is unchanged."""
    flat = jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (3,)), lj.Params().broadcast())
    wave = lj.Sinusoid(jnp.asarray([0.05, math.nan, 5.0]), jnp.full(3, 2.0), jnp.full(3, 3.0))
    ts = jnp.full(3, SHORT["t_start"])
    batch = FlatBatch(flat, jnp.ones(3, bool), wave=wave, t_start=ts, wave_axes=0)
    out = lj.Exact().measure(batch, 0.1, 5.0, 2.0, "strict", "paper")
    assert list(np.asarray(out["status"])) == [lj.Status.OK, lj.Status.INVALID, lj.Status.INVALID]
    alone = lj.measure(lj.Params(), waveform=lj.Sinusoid(0.05, 2.0, 3.0), **SHORT)
    np.testing.assert_allclose(out["mean_speed"][0], alone.mean_speed, rtol=1e-9)
    _, valid = jax.jit(lambda a: safe_params(lj.Params(), lj.Sinusoid(a, 2.0, 3.0)))(jnp.asarray(math.nan))
    assert not bool(valid)


def test_travelling_wave_names_its_fields():
    with pytest.raises(ValueError, match=r"'omega' of TravellingWave: got omega=inf; the valid range is omega >= 0"):
        lj.Chain(masses=[1.0, 1.0, 1.0], waveforms=lj.TravellingWave(0.05, math.inf, 1.0))
    # phi was refused only as "'waveforms' ... stroke=nan"
    with pytest.raises(ValueError, match=r"'phi' of TravellingWave: got phi=nan; the valid range is finite"):
        lj.Chain(masses=[1.0, 1.0, 1.0], waveforms=lj.TravellingWave(0.05, 2.0, math.nan))
    with pytest.raises(ValueError, match=r"waveforms\[1\] \(the waveform of spring 1\).*'a' of Sinusoid"):
        lj.Chain(masses=[1.0] * 3, waveforms=[lj.Sinusoid(0.05, 2.0, 3.0), lj.Sinusoid(math.nan, 2.0, 3.0)])


def test_chain_omega_inf_flagged_in_batch():
    """`measure` of a chain with omega = inf gave status OK with NaN results; in a batch built
    with check=False it is flagged INVALID and the other configuration is its own result."""
    wave = lj.TravellingWave(0.05, jnp.asarray([2.0, math.inf]), 1.0)
    batch = lj.Chain(masses=[1.0, 1.0, 1.0], waveforms=wave, check=False)
    m = lj.measure(batch, **SHORT)
    assert list(np.asarray(m.status)) == [lj.Status.OK, lj.Status.INVALID]
    _no_nan_with_ok(m)
    alone = lj.measure(lj.Chain(masses=[1.0, 1.0, 1.0], waveforms=lj.TravellingWave(0.05, 2.0, 1.0)), **SHORT)
    np.testing.assert_allclose(m.mean_speed[0], alone.mean_speed, rtol=1e-9)


# -- friction laws --------------------------------------------------------------------------------


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_invalid_mu_k_is_named(bad):
    """An invalid mu_k was reported as "Invalid parameter 'mu_s' ... got mu_s=0.7"."""
    with pytest.raises(ValueError, match=rf"'mu_k' of mass 0: got mu_k={bad}; the valid range is finite"):
        lj.Chain(masses=[1.0, 1.0], friction=lj.Coulomb(0.7, bad))
    with pytest.raises(ValueError, match=rf"'mu_k': got mu_k={bad}"):
        lj.Params(mu_k=bad)


def test_relation_shows_both_values():
    with pytest.raises(ValueError, match=r"'mu_s' of mass 1: got mu_s=0.4, mu_k=0.5; the valid range is mu_s >= mu_k"):
        lj.Chain(masses=[1.0, 1.0], friction=lj.Coulomb([0.7, 0.4], 0.5))
    with pytest.raises(ValueError, match=r"'d' of spring 0: got d=4.0, lbar=3.0"):
        lj.Chain(masses=[1.0, 1.0], d=4.0)


@pytest.mark.parametrize(
    "law, name",
    [(lj.Coulomb(0.7, -0.1), "mu_k"), (lj.AnisotropicCoulomb(0.7, 0.9, 0.5, -0.1), "mu_k_bwd"),
     (lj.Stribeck(0.7, 0.5, -0.1), "v_s")],
)  # fmt: skip
def test_friction_bounds(law, name):
    with pytest.raises(ValueError, match=rf"Invalid parameter '{name}' of mass 0"):
        lj.Chain(masses=[1.0, 1.0], friction=law)


def test_stribeck_tiny_v_s():
    """v_s = 1e-160 ran to status OK with NaN (1/v_s**2 overflows in the law's rate)."""
    with pytest.raises(ValueError, match=r"'v_s' of mass 0: got v_s=1e-160; the valid range is v_s > 0 with 1/v_s"):
        lj.Chain(masses=[1.0, 1.0], friction=lj.Stribeck(0.7, 0.5, 1e-160))
    # The law itself stays finite however small v_s is (values and rate).
    law = lj.Stribeck(0.7, 0.5, 1e-160)
    speed, one = jnp.asarray([0.0, 1e-170, 1.0]), jnp.ones(3)
    assert np.all(np.isfinite(np.asarray(law.kinetic(speed, one))))
    assert np.all(np.isfinite(np.asarray(law.kinetic_rate(speed, one, one))))
    np.testing.assert_allclose(law.kinetic(jnp.asarray([1.0]), jnp.ones(1)), [0.5])


# -- Params ---------------------------------------------------------------------------------------


def test_mismatched_lengths_name_parameters():
    """Mismatched lengths gave numpy's "arg 4 with shape (3,) and arg 5 with shape (5,)"."""
    with pytest.raises(ValueError, match=r"'a' \(shape \(3,\)\) and 'omega' \(shape \(5,\)\) do not broadcast"):
        lj.Params(a=np.array([0.01, 0.02, 0.03]), omega=np.linspace(1.0, 5.0, 5))
    with pytest.raises(ValueError, match=r"'a' \(shape \(2,\)\) and 'omega' \(shape \(3,\)\)"):
        lj.TravellingWave(np.array([0.01, 0.02]), np.array([1.0, 2.0, 3.0]))
    with pytest.raises(ValueError, match=r"'masses' \(shape \(2,\)\) and 'c' \(shape \(3,\)\)"):
        lj.Chain(masses=jnp.ones((2, 2)), c=jnp.full((3, 1), 0.01))


@pytest.mark.parametrize(
    "values, name",
    [
        (dict(mu_s=0.4, mu_k=0.5), "mu_s"),
        (dict(mu_k=-0.1, mu_s=0.5), "mu_k"),
        (dict(d=4.0), "d"),
        (dict(a=5.0), "a"),
        (dict(a=-0.01), "a"),
        (dict(mhat=1.0), "mhat"),
        (dict(c=-0.01), "c"),
        (dict(omega=-1.0), "omega"),
        # Subnormal values are flushed to zero by XLA's CPU code (a NaN with status OK, found by
        # tests/test_fuzz.py), and a length whose square under- or overflows breaks eq. (2).
        (dict(k=1e-310), "k"),
        (dict(mhat=1e-310), "mhat"),
        (dict(lbar=1e-300, a=0.0, d=0.0), "lbar"),
        (dict(lbar=1e300), "lbar"),
    ],
)
def test_params_bounds(values, name):
    with pytest.raises(ValueError, match=rf"Invalid parameter '{name}'"):
        lj.Params(**values)
    assert not bool(lj.Params(**values, check=False).is_valid())


@pytest.mark.parametrize(
    "kwargs, name",
    [(dict(masses=[1.0, 0.0]), "masses"), (dict(masses=[1.0, 1e-310]), "masses"), (dict(k=1e-310), "k"),
     (dict(k=0.0), "k"), (dict(lbar=1e-300, d=0.0), "lbar"), (dict(c=-0.01), "c")],
)  # fmt: skip
def test_chain_bounds(kwargs, name):
    with pytest.raises(ValueError, match=rf"Invalid parameter '{name}'"):
        lj.Chain(**{"masses": [1.0, 1.0], **kwargs})


@pytest.mark.parametrize(
    "build, name",
    [
        (lambda v: lj.Params(omega=v), "omega"),
        (lambda v: lj.Chain(masses=np.array([v, v])), "masses"),
        (lambda v: lj.Chain(masses=[1.0, 1.0], k=v), "k"),
        (lambda v: lj.Coulomb(0.7, v), "mu_k"),
        (lambda v: lj.Sinusoid(0.05, v, 3.0), "omega"),
        (lambda v: lj.TravellingWave(0.05, 2.0, v), "phi"),
    ],
)
@pytest.mark.parametrize("value", [2 + 1j, True, "2.0"])
def test_complex_and_non_numeric_refused(build, name, value):
    """`omega=2+1j` was accepted with its imaginary part dropped. (Text is refused by the
    tests' runtime type checker where the annotation excludes it, naming the parameter too.)"""
    error = (ValueError, TypeError) if isinstance(value, str) else ValueError
    with pytest.raises(error, match=rf"'{name}'"):
        build(value)


def test_no_drive_gives_no_nan_margins():
    """`Params(omega=0)` (and a chain's default, no actuation) gave NaN margins with status OK."""
    m = lj.measure(lj.Params(omega=0.0), **SHORT)
    assert int(m.status) == lj.Status.OK
    _no_nan_with_ok(m)
    _no_nan_with_ok(lj.measure(lj.Chain(masses=[1.0, 1.0, 1.0]), **SHORT))


def test_gait_without_period_is_invalid():
    """A gait needs a period 2 pi / omega: omega = 0 is flagged INVALID, not solved."""
    g = lj.steady_gait(lj.Chain(masses=[1.0, 1.0, 1.0], waveforms=lj.TravellingWave(0.05, 0.0, 1.0)), periods=1)
    assert int(g.status) == lj.GaitStatus.INVALID and not bool(g.converged)
