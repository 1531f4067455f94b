"""The work queue (`_queue.run_queue`) and the exact engine run through it."""

import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from locomotion_jax.dynamics import (
    _engine as engine,
    _paper,
    _simulate,
)
from locomotion_jax.dynamics._queue import run_queue, Stream
from locomotion_jax.dynamics._runs import chain_initial_state, start_code
from locomotion_jax.run._batch import prepare, prepare_chain


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


def test_streamed_rows_land_in_their_configurations_rows():
    # Configuration i emits the rows 10 i + k, k < 3 (i % 4), through a buffer of 2:
    # the outer loop drains full buffers, and the last rows of each configuration.
    n, size, buffer = 23, 9, 2
    zi = jnp.zeros((), jnp.int32)
    k = jnp.arange(buffer)
    setup = lambda i: (i, (zi, jnp.zeros(buffer, jnp.int32), zi))
    running = lambda f, d: d[0] < 3 * (f % 4)
    advance = lambda f, d: (d[0] + 1, jnp.where(k == d[2], 10 * f + d[0], d[1]), d[2] + 1)
    full = lambda f, d: d[2] >= buffer
    drain = lambda f, d: ((d[0], d[1], zi), d[1], jnp.where(k < d[2], d[0] - d[2] + k, size))
    results = lambda f, d: {"iterations": d[0]}
    want = np.where(np.arange(size) < 3 * (np.arange(n) % 4)[:, None], 10 * np.arange(n)[:, None] + np.arange(size), 0)
    for lanes in (1, 4, 23):
        run = lambda: run_queue(setup, running, advance, results, n, lanes, None, Stream(full, drain, size))
        out = jax.jit(run)()
        np.testing.assert_array_equal(out["iterations"], 3 * (np.arange(n) % 4))
        np.testing.assert_array_equal(out["stream"], want)


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
    queued = _paper.measure_batch(*args, lanes=3)
    alone = jax.vmap(lambda p, w: _paper.measure_one(p, w, *args[3:]))(flat, wave)
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


def _plain_saves(s, step, row, save_at, max_steps):
    # One configuration's saves in a plain loop of its own (no queue, no buffer): each
    # row written into the full array of saves as it falls.
    n = save_at.shape[0]
    running = lambda c: (c[1] < n) & (c[0].status == lj.Status.OK) & (c[3] < max_steps)

    def body(c):
        s, idx, rows, steps = c
        record = save_at[idx] <= s.t
        new_s = step(s, save_at[idx])
        rows = rows.at[idx].set(jnp.where(record, row(s), rows[idx]))
        s = jax.tree_util.tree_map(lambda a, b: jnp.where(record, b, a), new_s, s)
        return s, idx + record.astype(jnp.int32), rows, steps + 1

    zi = jnp.zeros((), jnp.int32)
    rows = jnp.zeros((n,) + row(s).shape, s.t.dtype)
    s, idx, rows, _ = jax.lax.while_loop(running, body, (s, zi, rows, zi))
    valid = jnp.arange(n) < idx
    rows = jnp.where(valid[:, None], rows, row(s)[None, :])
    status = jnp.where((s.status == lj.Status.OK) & (idx < n), lj.Status.MAX_STEPS, s.status).astype(jnp.int32)
    return rows, valid, status, s.t_liftoff, s.n_switch


def _saves_alone(p, w, save_at, contact, start, dt, max_steps):
    _, P, ok = _paper.physics(p, w)
    s = chain_initial_state(P, ok, contact, start)
    # The state in the two-mass order (x1, v1, x2, v2), modes, slip directions, the margins' records.
    row = lambda s: _simulate._row(s)[jnp.asarray([0, 2, 1, 3, *range(4, 13)])]
    step = lambda s, t_stop: engine.step(P, contact, dt, s, t_stop)[0]
    return _plain_saves(s, step, row, save_at, max_steps)


@pytest.mark.parametrize("dtype", [jnp.float64, jnp.float32])
@pytest.mark.parametrize("max_steps", [40_000, 500])
def test_simulate_queue_matches_one_loop_per_configuration(dtype, max_steps):
    # `simulate`'s work queue (3 lanes, buffers of 4 rows, 26 saves: drained several
    # times per configuration) against one loop per configuration, for every kind of
    # run: an invalid configuration, lift-offs (strict reading: the run stops, later
    # rows hold the last state, invalid), repeated save times and t = 0, and
    # (max_steps = 500) runs stopped by the step cap.
    om = np.array([1.5, 23.0, 4.0, np.nan, 9.0, 2.0, 17.0, 6.0, 12.0, 3.0, 20.0])
    a = np.array([0.05, 0.1, 0.02, 0.05, 0.09, 0.05, 0.03, 0.08, 0.05, 0.06, 0.04])
    flat, wave, axes, _ = prepare(lj.Params(omega=om, a=a, check=False), None, dtype)
    save_at = jnp.asarray(np.concatenate([[0.0, 0.0], np.linspace(0.1, 12.0, 22), [12.0, 12.0]]), dtype)
    args = ("strict", "paper", 0.02, jnp.asarray(max_steps, jnp.int32))
    engine_args = (args[0], start_code(args[1]), *args[2:])  # the engine takes the start's code
    queued = _paper._simulate_rows(flat, wave, axes, save_at, *engine_args, lanes=3, buffer=4)
    alone = jax.vmap(lambda p, w: _saves_alone(p, w, save_at, *args))(flat, wave)
    status, valid = np.asarray(alone[2]), np.asarray(alone[1])
    lifted = status == lj.Status.LIFTOFF
    assert status[3] == lj.Status.INVALID and not valid[3].any()
    assert lifted.sum() == 3 and (valid[lifted].sum(axis=1) < 5).all() and valid[lifted, 0].all()
    capped = status == lj.Status.MAX_STEPS
    assert capped.sum() == (7 if max_steps == 500 else 0) and not valid[capped].all(axis=1).any()
    assert valid[status == lj.Status.OK].all()
    assert np.asarray(queued[0]).dtype == dtype
    for i, name in ((1, "valid"), (2, "status"), (4, "n_switch")):
        np.testing.assert_array_equal(np.asarray(queued[i]), np.asarray(alone[i]), err_msg=name)
    rows, ref = np.asarray(queued[0]), np.asarray(alone[0])
    np.testing.assert_array_equal(rows[..., 6:10], ref[..., 6:10])  # stick flags and slip directions
    if dtype == jnp.float64:  # bit for bit
        np.testing.assert_array_equal(rows, ref)
        np.testing.assert_array_equal(queued[3], alone[3])
    else:
        # XLA vectorises 3 lanes and 11 differently in float32; the last bits part
        # and grow through the events: 3e-5 of a variable's range is measured.
        ran = valid.any(axis=1)  # not the invalid configuration (no motion: a zero scale)
        scale = np.max(np.abs(ref[ran, :, :6]), axis=1, keepdims=True)
        assert np.max(np.abs(rows[ran, :, :6] - ref[ran, :, :6]) / scale) < 2e-4
        np.testing.assert_allclose(queued[3], alone[3], rtol=1e-6)


@pytest.mark.parametrize("max_steps", [40_000, 500])
def test_chain_simulate_queue_matches_one_loop_per_configuration(max_steps):
    # The chain engine's `simulate` through the same queue (3 lanes, buffers of 4 rows)
    # against one plain loop per configuration (values to rounding): runs to the end, lift-offs
    # (two at the start, three later), an invalid chain, and (500) the step cap.
    cases = [(0.06, 2.0, 0.5), (0.3, 20.0, 0.8), (0.08, 5.0, 0.5), (0.06, 3.0, 0.0), (0.2, 15.0, 0.9)]
    cases += [(0.05, 9.0, 0.4), (0.1, 12.0, 0.6)]
    wave = lambda a, om: lj.TravellingWave(a, om, 2.0)
    chains = [lj.Chain(masses=[1.0, 1.0, 1.0], d=d, waveforms=wave(a, om)) for a, om, d in cases]
    chains.append(lj.Chain(masses=[1.0, -1.0, 1.0], waveforms=wave(0.06, 2.0), check=False))
    flat, ok, _ = prepare_chain(lj.Chain.stack(chains), None)
    save_at = jnp.asarray(np.concatenate([[0.0, 0.0], np.linspace(0.1, 12.0, 22), [12.0, 12.0]]))
    cap = jnp.asarray(max_steps, jnp.int32)
    queued = _simulate._simulate_batch(flat, ok, save_at, "strict", start_code("paper"), 0.02, cap, 3, 4)

    def alone(C, ok):
        P = C.physics()
        s = chain_initial_state(P, ok, "strict", "paper")
        step = lambda s, t_stop: engine.step(P, "strict", 0.02, s, t_stop)[0]
        return _plain_saves(s, step, _simulate._row, save_at, cap)

    ref = jax.vmap(alone)(flat, ok)
    S = lj.Status
    want = [S.OK, S.LIFTOFF, S.LIFTOFF, S.OK, S.LIFTOFF, S.LIFTOFF, S.LIFTOFF, S.INVALID]
    if max_steps == 500:
        want[0] = want[3] = S.MAX_STEPS
    np.testing.assert_array_equal(ref[2], want)
    np.testing.assert_array_equal(np.asarray(ref[1]).sum(axis=1)[[2, 5, 6]] > 0, True)
    # Flags, statuses and counts exactly; values to rounding (a lane's position in a SIMD
    # vector can change the last bit of a float64 result, as in the measure test above).
    for q, r, name in zip(queued, ref, ("rows", "valid", "status", "t_liftoff", "n_switch"), strict=True):
        if name in ("rows", "t_liftoff"):
            np.testing.assert_allclose(np.asarray(q), np.asarray(r), rtol=1e-12, atol=1e-15, err_msg=name)
        else:
            np.testing.assert_array_equal(np.asarray(q), np.asarray(r), err_msg=name)


def test_only_the_first_count_configurations_run():
    # A program for 23 configurations run on the first 17: those get what a queue of 17 gives
    # them, in any order of the queue; the padding past them never runs (zero results).
    n, count = 23, 17
    setup = lambda i: (i, jnp.zeros((), jnp.int32))
    running = lambda f, d: d < 3 * (f % 4)
    advance = lambda f, d: d + 1
    results = lambda f, d: {"index": f + 1, "iterations": d}
    want = np.where(np.arange(n) < count, 3 * (np.arange(n) % 4), 0)
    order = jnp.asarray(np.random.default_rng(1).permutation(n))
    for lanes, o in ((4, None), (5, order), (32, order)):
        run = lambda o, c: run_queue(setup, running, advance, results, n, lanes, o, count=c)
        out = jax.jit(run)(o, jnp.asarray(count, jnp.int32))
        np.testing.assert_array_equal(out["index"], np.where(np.arange(n) < count, np.arange(n) + 1, 0))
        np.testing.assert_array_equal(out["iterations"], want)
