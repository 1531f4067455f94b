"""The work queue (`_queue.run_queue`) and the exact engine run through it."""

import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
from locomotion_jax import _measure
from locomotion_jax._batch import prepare
from locomotion_jax._queue import run_queue


def _counting(n, lanes, order=None):
    # Configuration i needs 3 * (i % 4) iterations; records what it saw.
    setup = lambda i: (i, jnp.zeros((), jnp.int32))
    running = lambda f, d: d < 3 * (f % 4)
    advance = lambda f, d: d + 1
    results = lambda f, d: {"index": f, "iterations": d}
    return jax.jit(lambda o: run_queue(setup, running, advance, results, n, lanes, o))(order)


def test_every_configuration_once_in_its_own_slot():
    n = 23
    for lanes in (1, 4, 23, 64):
        out = _counting(n, lanes)
        np.testing.assert_array_equal(out["index"], np.arange(n))
        np.testing.assert_array_equal(out["iterations"], 3 * (np.arange(n) % 4))
    order = jnp.asarray(np.random.default_rng(0).permutation(n))
    out = _counting(n, 5, order)
    np.testing.assert_array_equal(out["index"], np.arange(n))
    np.testing.assert_array_equal(out["iterations"], 3 * (np.arange(n) % 4))


def test_queue_matches_one_loop_per_configuration():
    # Eleven configurations of very different durations (one invalid, one lifting
    # off under the strict reading) through 3 lanes: each result is the one of its
    # own independent loop.
    om = np.array([1.5, 23.0, 4.0, np.nan, 9.0, 2.0, 17.0, 6.0, 12.0, 3.0, 20.0])
    a = np.array([0.05, 0.1, 0.02, 0.05, 0.09, 0.05, 0.03, 0.08, 0.05, 0.06, 0.04])
    flat, wave, axes, _ = prepare(lj.Params(omega=om, a=a, check=False), None, None)
    args = (
        flat,
        wave,
        axes,
        jnp.asarray(0.5, flat.dtype),
        jnp.asarray(30.0, flat.dtype),
        jnp.asarray(5.0, flat.dtype),
        "strict",
        "paper",
        0.02,
        jnp.asarray(40_000, jnp.int32),
    )
    queued = _measure.exact_batch(*args, lanes=3)
    alone = jax.vmap(lambda p, w: _measure._exact_one(p, w, *args[3:]))(flat, wave)
    assert int(queued["status"][3]) == lj.Status.INVALID
    assert len(set(np.asarray(queued["status"]).tolist())) >= 3  # OK, INVALID and LIFTOFF all present
    # Equal to rounding (a lane's position in a SIMD vector can change the last bit);
    # `balance` is a difference of O(1) energies, so its error is absolute.
    for k, v in alone.items():
        np.testing.assert_allclose(
            np.asarray(queued[k], float),
            np.asarray(v, float),
            rtol=1e-12,
            atol=1e-15 if k == "balance" else 0,
            err_msg=k,
        )
