"""The chain front ends under `jax.jit` (issue 29): a chain built from traced values measures and
simulates as it does eagerly; an invalid or unresolved one is flagged in its own result."""

from typing import Any

import jax
import locomotion_jax as lj
import numpy as np


SHORT: dict[str, Any] = dict(z=0.1, horizon=5.0, window=2.0)


def _chain(k, omega=2.0):
    return lj.Chain(masses=[1.0, 1.0, 1.0], k=k, waveforms=lj.TravellingWave(0.05, omega, 1.0))


def test_measure_and_simulate_of_a_traced_chain_equal_eager():
    for t_start in (1.0, None):  # an explicit start (checked on the host) and the chain's own
        run = lambda k: lj.measure(_chain(k), t_start=t_start, **SHORT).mean_speed  # noqa: B023
        np.testing.assert_allclose(jax.jit(run)(50.0), run(50.0), rtol=1e-12, atol=1e-15)
    sim = lambda k: lj.simulate(_chain(k), 2.0, np.linspace(0.0, 2.0, 5)).X
    np.testing.assert_allclose(jax.jit(sim)(50.0), sim(50.0), rtol=1e-12, atol=1e-15)


def test_traced_chain_flags_invalid_and_unresolved():
    status = jax.jit(lambda k, om: lj.measure(_chain(k, om), t_start=1.0, **SHORT).status)
    assert int(status(50.0, 2.0)) == lj.Status.OK
    assert int(status(-1.0, 2.0)) == lj.Status.INVALID
    assert int(status(50.0, 1e4)) == lj.Status.UNRESOLVED
