"""Resolution guards (issue 29): a step that does not resolve a configuration's time scales
is refused (one configuration) or flagged `Status.UNRESOLVED` (a batch), never answered."""

from typing import Any

import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from locomotion_jax.paper import _fig_map as fmap, _fig_sweep as fsw, _fig_time as ftime
from locomotion_jax.run._resolution import STEPS_PER_PERIOD, two_mass_scales, unresolved


SHORT: dict[str, Any] = dict(z=0.1, t_start=1.0, horizon=5.0, window=2.0)


@pytest.mark.parametrize("dt", [0.01, 1e-3])
def test_unresolved_forcing_is_refused_with_the_step_it_needs(dt):
    # The case: status OK with mean speeds 0.031 and 3.1e-4 at these steps.
    with pytest.raises(ValueError, match=r"'omega'.*omega=10000.*dt <= 0\.000157 \(4 steps per period\)"):
        lj.measure(lj.Params(omega=1e4), **SHORT, dynamics=lj.Exact(dt=dt))


def test_very_high_forcing_is_refused_not_reported_as_liftoff():
    with pytest.raises(ValueError, match=r"'omega'.*omega=1e\+09.*dt <= 1\.57e-09"):
        lj.measure(lj.Params(omega=1e9), **SHORT)
    with pytest.raises(ValueError, match="'omega'"):
        lj.simulate(lj.Params(omega=1e9), 1.0)


def test_highest_harmonic_sets_the_forcing_period():
    # omega = 100 is resolved at dt = 0.01 (6.3 steps per period); its third harmonic is not.
    wave = lj.Fourier(jnp.zeros(3), jnp.array([0.02, 0.0, 0.01]), 100.0, 3.0)
    with pytest.raises(ValueError, match=r"K = 3"):
        lj.measure(lj.Params(omega=100.0), **SHORT, waveform=wave)


@pytest.mark.parametrize(
    "change, name",
    [(dict(k=1e7), "k"), (dict(mhat=1e-6), "k"), (dict(c=1e3), "c")],
)
def test_unresolved_natural_period_or_damping_is_refused(change, name):
    with pytest.raises(ValueError, match=rf"Invalid parameter '{name}'.*Exact\(dt=0\.01\) does not resolve"):
        lj.measure(lj.Params(**change), **SHORT)


def test_chain_scales_are_refused():
    with pytest.raises(ValueError, match=r"'omega'.*forcing period"):
        lj.measure(lj.Chain(masses=[1.0, 1.0, 1.0], waveforms=lj.TravellingWave(0.05, 1e4, 1.0)), **SHORT)
    with pytest.raises(ValueError, match=r"'k'.*natural period 2\*pi/w_max of the free chain"):
        lj.simulate(lj.Chain(masses=[1.0, 1e-6, 1.0]), 1.0)
    with pytest.raises(ValueError, match=r"'v_s'.*Stribeck time.*v_s \(smallest\)=1e-05"):
        lj.measure(lj.Chain(masses=[1.0, 1.0], friction=lj.Stribeck(0.7, 0.5, 1e-5)), **SHORT)


def test_a_finer_step_resolves_it():
    m = lj.measure(lj.Params(omega=300.0), **SHORT, dynamics=lj.Exact(dt=0.005))
    assert int(m.status) != lj.Status.UNRESOLVED


def test_batch_flags_only_the_unresolved_and_leaves_the_others_bitwise_equal():
    omega = jnp.array([2.0, 1e4, 3.0, 1e9])
    batch = lj.measure(lj.Params(omega=omega), **SHORT)
    U = lj.Status.UNRESOLVED
    assert [int(s) for s in batch.status] == [lj.Status.OK, U, lj.Status.OK, U]
    assert int(batch.n_steps[1]) == 0 and not np.isfinite(float(batch.mean_speed[1]))  # never run: sentinels
    alone = lj.measure(lj.Params(omega=jnp.array([2.0, 3.0])), **SHORT)
    for k in ("status", "n_steps", "tau_z", "mean_speed", "e_d", "balance"):
        np.testing.assert_array_equal(np.asarray(getattr(batch, k))[[0, 2]], np.asarray(getattr(alone, k)), k)


def test_invalid_stays_invalid_and_chain_batch_is_flagged():
    p = lj.Params(omega=jnp.array([1e4, 1e4]), a=jnp.array([0.05, 5.0]), check=False)
    assert [int(s) for s in lj.measure(p, **SHORT).status] == [lj.Status.UNRESOLVED, lj.Status.INVALID]
    c = lj.Chain(masses=[1.0, 1.0, 1.0], waveforms=lj.TravellingWave(0.05, jnp.array([2.0, 1e4]), 1.0))
    assert [int(s) for s in lj.measure(c, **SHORT).status] == [lj.Status.OK, lj.Status.UNRESOLVED]
    assert [int(s) for s in lj.simulate(c, 1.0).status] == [lj.Status.OK, lj.Status.UNRESOLVED]


def test_under_jit_it_is_flagged():
    f = jax.jit(lambda om: lj.measure(lj.Params(omega=om), **SHORT).status)
    assert int(f(1e4)) == lj.Status.UNRESOLVED and int(f(2.0)) == lj.Status.OK


def test_sweep_flags_it():
    ds = lj.sweep(dict(omega=np.array([2.0, 1e4, 3.0])), z=0.1, horizon=5.0, window=2.0, progress=False)
    assert ds.status.values.tolist() == [lj.Status.OK, lj.Status.UNRESOLVED, lj.Status.OK]


def test_smoothed_dynamics_are_not_guarded():
    # Adaptive steps: the error control resolves the forcing (or the run ends MAX_STEPS / SOLVER_FAILED).
    m = lj.measure(lj.Params(omega=1e4), z=0.1, horizon=0.05, window=0.05, dynamics=lj.Smoothed(max_steps=200))
    assert int(m.status) in (lj.Status.MAX_STEPS, lj.Status.SOLVER_FAILED)


def _figure_grids():
    """Every (omega, mhat, dt) corner of the paper's figures (both sizes); the other parameters are
    the paper's defaults, and the scales grow with omega and with mhat's distance from 1/2."""
    out = []
    for sizes in (fsw.SIZES_7, fsw.SIZES_8, fsw.SIZES_9, fsw.SIZES_12, fmap.SIZES_6, ftime.SIZES_4B, ftime.SIZES_5):
        for size in sizes.values():
            out.append((max(fmap.OMEGA_RANGE[1], 2.5 * fsw.WN1, max(fsw.OMEGAS_5)), 0.02, size["dt"]))
    out.append((25.0, 0.02, 0.01))  # Fig. 6's check at dt = 0.01
    return out


@pytest.mark.parametrize("omega, mhat, dt", _figure_grids())
def test_no_configuration_of_the_paper_figures_is_flagged(omega, mhat, dt):
    # The threshold (STEPS_PER_PERIOD = 4) leaves the figures alone: the tightest, Fig. 12 quick, has
    # omega_n1 = 35.7 at mhat = 0.02 with dt = 0.02, 8.8 steps per period.
    grid = lj.Params.grid(omega=np.linspace(0.1, omega, 64), mhat=np.array([mhat, 0.5, 1 - mhat]))
    flat = jax.tree_util.tree_map(lambda x: x.reshape(-1), grid.broadcast())
    scales = two_mass_scales(flat, lj.Sinusoid.from_params(flat))
    assert not np.asarray(unresolved(scales, dt, flat.is_valid())).any()
    steps = min(float(np.min(np.asarray(s.limit()))) * s.steps for s in scales) / dt
    assert steps > 2 * STEPS_PER_PERIOD
