"""A new integrator is one subclass of `AbstractDynamics` (docs/index.md's `HalfStep`): `simulate`,
`measure` and `sweep` run it (on the paper's model and on chains, through the same methods) without
knowing its class, and refuse what is not a dynamics."""

from typing import Any

import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from docs_examples import doc_class


HalfStep = doc_class("index.md", "HalfStep")  # the exact engine at half its step, delegating every method


RTOL = 1e-4
"""Exact at dt = 0.005 against dt = 0.01 (float64): measured 3e-6 relative on tau_z and e_z, 3e-5 on
the work (two masses), 1e-6 on a chain's; a dynamics that ran Exact's default step would agree to 0
and is caught by the iteration count."""

PARAMS = lj.Params(omega=jnp.array([2.0, 6.0, 16.0]))
CHAIN = lj.Chain(masses=[1.0, 1.0, 1.0], waveforms=lj.TravellingWave(a=0.06, omega=2.0, phi=1.0))


def _close(new, ref, rtol=RTOL, atol=1e-8):
    np.testing.assert_allclose(np.asarray(new, float), np.asarray(ref, float), rtol=rtol, atol=atol)


def test_simulate():
    save = np.linspace(0.0, 20.0, 41)
    new, ref = (lj.simulate(PARAMS, 20.0, save, dynamics=d) for d in (HalfStep(), lj.Exact()))
    for field in ("x1", "x2", "v1", "v2", "X", "e_d"):
        _close(getattr(new, field), getattr(ref, field), atol=1e-6)
    np.testing.assert_array_equal(new.status, ref.status)
    new, ref = (lj.simulate(CHAIN, 20.0, save, dynamics=d) for d in (HalfStep(), lj.Exact()))
    assert isinstance(new, lj.Trajectory)
    _close(new.x, ref.x, atol=1e-6)
    _close(new.e_d, ref.e_d, atol=1e-6)


def test_measure():
    kw: dict[str, Any] = dict(z=1.0, horizon=200.0)
    new, ref = (lj.measure(PARAMS, **kw, dynamics=d) for d in (HalfStep(), lj.Exact()))
    assert np.all(np.asarray(new.reached))
    for field in ("tau_z", "e_z", "mean_speed", "e_d", "work"):
        _close(getattr(new, field), getattr(ref, field))
    np.testing.assert_array_equal(new.regime, ref.regime)
    # The step is the new class's: about twice the iterations.
    assert np.all(np.asarray(new.n_steps) > 1.5 * np.asarray(ref.n_steps))
    new, ref = (lj.measure(CHAIN, **kw, t_start=20.0, dynamics=d) for d in (HalfStep(), lj.Exact()))
    assert isinstance(new, lj.Measurement) and bool(new.reached)
    for field in ("tau_z", "e_z", "mean_speed", "stick_fraction"):
        _close(getattr(new, field), getattr(ref, field))


def test_sweep():
    axes = {"omega": [2.0, 6.0, 16.0]}
    kw: dict[str, Any] = dict(z=1.0, horizon=200.0, progress=False, chunk_size=2)  # two chunks
    new, ref = (lj.sweep(axes, **kw, dynamics=d) for d in (HalfStep(), lj.Exact()))
    for field in ("tau_z", "e_z", "mean_speed"):
        _close(new[field].values, ref[field].values)
    assert new.attrs["dynamics"] == "half-step exact" and new.attrs["dynamics_dt"] == 0.005
    # The sweep's measurements are `measure`'s.
    alone = lj.measure(PARAMS, z=1.0, horizon=200.0, dynamics=HalfStep())
    _close(new["tau_z"].values, alone.tau_z, rtol=1e-12)
    # An inner `Exact(max_steps=...)` caps the sweep as it caps `measure` (the class hands the
    # sweep no cap of its own: `AbstractDynamics.chunk_program`'s default).
    capped = HalfStep(inner=lj.Exact(dt=0.005, max_steps=3000))
    new, alone = lj.sweep(axes, **kw, dynamics=capped), lj.measure(PARAMS, z=1.0, horizon=200.0, dynamics=capped)
    assert (np.asarray(alone.status) == lj.Status.MAX_STEPS).all()
    np.testing.assert_array_equal(new["n_steps"].values, alone.n_steps)
    np.testing.assert_array_equal(new["status"].values, alone.status)


def test_every_method_is_required():
    class DescribeOnly(lj.AbstractDynamics):
        def describe(self):
            return {}

    with pytest.raises(TypeError, match="abstract"):
        DescribeOnly()  # pyright: ignore[reportAbstractUsage]


@pytest.mark.parametrize("run", ["simulate", "measure", "sweep"])
def test_not_a_dynamics_is_refused(run):
    # A TypeError naming the argument: the package's, or the test suite's type checker's.
    call = {
        "simulate": lambda d: lj.simulate(lj.Params(), 1.0, dynamics=d),
        "measure": lambda d: lj.measure(lj.Params(), dynamics=d),
        "sweep": lambda d: lj.sweep({"omega": [1.0, 2.0]}, dynamics=d, progress=False),
    }[run]
    for wrong in ("exact", lj.Params(), object()):
        with pytest.raises(TypeError, match="dynamics"):
            call(wrong)


def test_not_a_mechanism_is_refused():
    for run in (lambda p: lj.simulate(p, 1.0), lambda p: lj.measure(p)):
        with pytest.raises(TypeError, match="params"):
            run({"omega": 2.0})


def test_the_interface_names_no_kind_of_mechanism():
    """`AbstractDynamics` has one `simulate` and one `measure` for every mechanism; the front ends
    hand them a mechanism's flat batch, and the solvers (steady gaits, continuation, the optimisers)
    ask the mechanism for its problem, without enumerating the kinds of mechanism."""
    from pathlib import Path

    from locomotion_jax.model._mechanism import AbstractMechanism

    abstract = sorted(lj.AbstractDynamics.__abstractmethods__)
    assert abstract == ["describe", "measure", "measure_chunk", "nominal_step", "simulate", "spec", "step_cap"]
    assert not [n for n in dir(lj.AbstractDynamics) if "two_mass" in n or "chain" in n]
    assert not [n for n in dir(AbstractMechanism) if "dispatch" in n or "two_mass" in n or "chain" in n]
    root = Path(lj.__file__).parent
    for src in root.rglob("*.py"):
        assert ".dispatch(" not in src.read_text(), src


def test_smoothed_sweep_equals_measure():
    """`Smoothed.measure_chunk` takes a sweep's chunk as any other batch: the map equals `measure`."""
    smooth = lj.Smoothed(eps=1e-2)
    kw: dict[str, Any] = dict(z=0.5, horizon=40.0)
    ds = lj.sweep({"omega": [2.0, 6.0]}, **kw, dynamics=smooth, progress=False, chunk_size=2)
    alone = lj.measure(lj.Params(omega=jnp.array([2.0, 6.0])), **kw, dynamics=smooth)
    assert np.all(np.asarray(alone.reached))
    # To the solver's tolerance (rtol 1e-7): the chunk program and `measure`'s are compiled apart, and the
    # adaptive steps follow their roundings (measured: 8e-9 relative on tau_z at omega = 6).
    for field in ("tau_z", "e_z", "stick_fraction1", "stick_fraction2"):
        _close(ds[field].values, getattr(alone, field), rtol=1e-6, atol=0)


def test_a_fixed_step_dynamics_of_ones_own_is_guarded_at_its_step():
    """The resolution guard asks the dynamics for its step (`nominal_step()`), not its class: the
    half-step dynamics refuses one configuration whose forcing its step does not resolve, naming the
    parameter, and flags it `UNRESOLVED` in a batch beside a resolved one, which runs."""
    with pytest.raises(ValueError, match=r"Invalid parameter 'omega': Exact\(dt=0.005\) does not resolve"):
        lj.measure(lj.Params(omega=1e4), z=0.3, horizon=5.0, dynamics=HalfStep())
    m = lj.measure(lj.Params(omega=jnp.array([2.0, 1e4])), z=0.3, horizon=5.0, dynamics=HalfStep())
    assert list(np.asarray(m.status)) == [lj.Status.OK, lj.Status.UNRESOLVED]
    assert np.isnan(float(m.mean_speed[1])) and np.isfinite(float(m.mean_speed[0]))
