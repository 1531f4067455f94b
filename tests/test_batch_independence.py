"""A configuration's result does not depend on its batch-mates (issue 29).

What independence means numerically, on one machine: a configuration measured alone and in
any batch gets the same status, the same step count and bitwise the same numbers. Two things
used to break it:

- the step cap was the batch's (the longest span of any configuration), so a configuration
  that hits the cap ran longer in a batch with a slow mate; it is now each configuration's
  own, from its own span (`_runs.step_cap`);
- XLA compiles a one-lane kernel (a configuration alone) and the lanes of a vector's
  remainder to scalar code, which rounds differently from the vector code in the last bit
  (4e-16 to 1e-13 relative on `measure`'s results, and another trajectory altogether where
  the forcing is not resolved); the CPU queues now run a multiple of
  `_runs.LANE_QUANTUM` lanes, idle past the batch (`_runs.default_lanes`).
"""

import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
from locomotion_jax.dynamics import _measure, _paper, _simulate
from locomotion_jax.dynamics._flat import FlatBatch
from locomotion_jax.dynamics._runs import CAP_EXTRA, CAP_STEPS_PER_DT
from locomotion_jax.run._batch import prepare, unflatten


FIELDS_TWO_MASS = ("status", "n_steps", "n_switch", "regime", "tau_z", "e_z", "mean_speed", "e_d", "work", "balance",
                   "stick_fraction1", "stick_fraction2", "t_liftoff", "transversality", "near_miss")  # fmt: skip
FIELDS_CHAIN = ("status", "n_steps", "n_switch", "regime", "tau_z", "e_z", "mean_speed", "e_d", "work", "balance",
                "stick_fraction", "t_liftoff")  # fmt: skip


def _assert_same(batch, alone, i, fields):
    for k in fields:
        np.testing.assert_array_equal(np.asarray(getattr(batch, k))[i], np.asarray(getattr(alone, k))[0], err_msg=k)


def _capped(params, t_start, dynamics=None):
    """`measure` straight on the engine: the front end would flag the unresolved forcing these
    tests use to reach the cap (`Status.UNRESOLVED`, tests/test_resolution.py) and not run it."""
    dynamics = lj.Exact() if dynamics is None else dynamics
    flat, wave, axes, shape = prepare(params, None, None)
    ts = jnp.broadcast_to(jnp.asarray(t_start, flat.dtype), shape).reshape((-1,))
    batch = FlatBatch(flat, flat.is_valid(), wave=wave, t_start=ts, wave_axes=axes)
    out = dynamics.measure(batch, 100.0, 20.0, 2.0, "strict", "paper")
    return lj.Measurement(**unflatten(out, shape), z=100.0, start="paper", contact="strict")


def test_step_cap_is_the_configurations_own():
    # omega = 1e5 at dt = 0.01 is forcing the step does not resolve (the case): about 12
    # iterations per nominal step, so the run hits its cap, 3 t_total / dt + 20000 = 26300 over its
    # t_total = 1 + 20. Its mate starts measuring at t = 100: a batch cap from the mate's span
    # (56000) let the first run on to another status and other numbers.
    batch = _capped(lj.Params(omega=jnp.array([1e5, 2.0])), jnp.array([1.0, 100.0]))
    alone = _capped(lj.Params(omega=jnp.array([1e5])), 1.0)
    cap = int(CAP_STEPS_PER_DT * 21.0 / 0.01) + CAP_EXTRA
    assert int(alone.status[0]) == lj.Status.MAX_STEPS and int(alone.n_steps[0]) == cap
    assert int(batch.status[1]) == lj.Status.OK
    _assert_same(batch, alone, 0, FIELDS_TWO_MASS)


def test_explicit_cap_is_per_configuration():
    dyn = lj.Exact(max_steps=3000)
    batch = _capped(lj.Params(omega=jnp.array([1e5, 2.0])), jnp.array([1.0, 100.0]), dyn)
    alone = _capped(lj.Params(omega=jnp.array([2.0])), 100.0, dyn)
    assert [int(s) for s in batch.status] == [lj.Status.MAX_STEPS] * 2
    assert [int(n) for n in batch.n_steps] == [3000, 3000]
    _assert_same(batch, alone, 1, FIELDS_TWO_MASS)


def test_random_two_mass_configurations_alone_and_batched_are_bitwise_equal():
    rng = np.random.default_rng(29)
    n = 8
    ranges = dict(omega=(1.0, 25.0), a=(0.01, 0.08), d=(-0.5, 0.5), mhat=(0.3, 0.7), mu_s=(0.6, 0.9))
    cols = {k: jnp.asarray(rng.uniform(lo, hi, n)) for k, (lo, hi) in ranges.items()}
    ts = rng.uniform(2.0, 8.0, n)
    run = lambda p, t: lj.measure(p, z=0.3, horizon=30.0, window=10.0, t_start=t, contact="paper")
    params = lambda s: lj.Params(omega=cols["omega"][s], a=cols["a"][s], d=cols["d"][s], mhat=cols["mhat"][s],
                                 mu_s=cols["mu_s"][s])  # fmt: skip
    batch = run(params(slice(None)), jnp.asarray(ts))
    assert len(set(np.asarray(batch.n_steps).tolist())) == n  # spans and step counts all differ
    for i in range(n):
        alone = run(params(slice(i, i + 1)), ts[i])
        _assert_same(batch, alone, i, FIELDS_TWO_MASS)


def test_random_chains_alone_and_batched_are_bitwise_equal():
    rng = np.random.default_rng(2929)
    n = 8
    a, omega, phi = rng.uniform(0.02, 0.08, n), rng.uniform(1.5, 12.0, n), rng.uniform(-2.0, 2.0, n)
    d = rng.uniform(-0.5, 0.5, (n, 2))

    def chains(i):
        w = lj.TravellingWave(jnp.asarray(a[i]), jnp.asarray(omega[i]), jnp.asarray(phi[i]))
        return lj.Chain(masses=np.ones(a[i].shape + (3,)), d=jnp.asarray(d[i]), waveforms=w)

    run = lambda c: lj.measure(c, z=0.3, horizon=20.0, window=10.0, t_start=5.0)
    batch = run(chains(slice(None)))
    assert len(set(np.asarray(batch.n_steps).tolist())) == n
    for i in range(n):
        alone = run(chains(slice(i, i + 1)))
        _assert_same(batch, alone, i, FIELDS_CHAIN)


def _same_rows(part, full, k, fields):
    for f in fields:
        np.testing.assert_array_equal(np.asarray(getattr(part, f)), np.asarray(getattr(full, f))[:k], err_msg=f)


def _programs():
    # The engine's `jax.jit` wrappers have `_cache_size` (pyright sees the functions they wrap).
    fns = (_measure._measure_batch, _simulate._simulate_batch, _paper._measure_batch, _paper._simulate_rows)
    return tuple(f._cache_size() for f in fns)  # pyright: ignore[reportFunctionMemberAccess]


def test_batch_sizes_of_one_bucket_share_a_program_and_padding_changes_nothing():
    # 3 and 5 configurations run padded to 16 rows (`_runs.batch_rows`) through the program that 16
    # run unpadded: no new compilation, and each one's fields bitwise those of the unpadded batch.
    rng = np.random.default_rng(31)
    n = 16
    a, omega, phi = rng.uniform(0.02, 0.08, n), rng.uniform(1.5, 12.0, n), rng.uniform(-2.0, 2.0, n)

    def chains(k):
        w = lj.TravellingWave(jnp.asarray(a[:k]), jnp.asarray(omega[:k]), jnp.asarray(phi[:k]))
        return lj.Chain(masses=np.ones((k, 3)), waveforms=w)

    params = lambda k: lj.Params(omega=jnp.asarray(omega[:k]), a=jnp.asarray(a[:k]))
    save_at = jnp.linspace(0.0, 6.0, 4)
    runs = [
        (chains, lambda c: lj.measure(c, z=0.3, horizon=10.0, window=5.0, t_start=2.0), FIELDS_CHAIN),
        (params, lambda p: lj.measure(p, z=0.3, horizon=10.0, window=5.0, t_start=2.0), FIELDS_TWO_MASS),
        (chains, lambda c: lj.simulate(c, 6.0, save_at=save_at), ("x", "v", "e", "status", "n_switch")),
        (params, lambda p: lj.simulate(p, 6.0, save_at=save_at), ("x", "v", "e", "status", "n_switch")),
    ]
    full = [run(make(n)) for make, run, _ in runs]
    before = _programs()
    for k in (3, 5):
        for (make, run, fields), whole in zip(runs, full):
            _same_rows(run(make(k)), whole, k, fields)
    assert _programs() == before


def test_both_named_starts_share_a_program():
    # The engine takes the start as a traced code (`_runs.start_code`): the second start compiles
    # nothing, and a chain starts where its physics' `initial_positions` puts it for that start.
    w = lj.TravellingWave(jnp.asarray([0.05, 0.08]), jnp.asarray([3.0, 7.0]), jnp.asarray([1.0, -1.0]))
    chains = lj.Chain(masses=np.ones((2, 3)), d=jnp.asarray([[0.3, -0.2], [0.0, 0.4]]), waveforms=w)
    params = lj.Params(omega=jnp.asarray([3.0, 7.0]), d=jnp.asarray([0.0, 0.5]))
    save_at = jnp.asarray([0.0, 1.0])
    runs = lambda mech, start: (lj.simulate(mech, 1.0, save_at=save_at, start=start),
                                lj.measure(mech, z=0.1, horizon=2.0, start=start))  # fmt: skip
    for first, second in (("paper", "relaxed"), ("relaxed", "paper")):
        runs(chains, first), runs(params, first)
        before = _programs()
        traj, _ = runs(chains, second)
        runs(params, second)
        assert _programs() == before
        want = jax.vmap(lambda c: c.physics().initial_positions(second))(chains.broadcast())
        np.testing.assert_array_equal(np.asarray(traj.x)[:, 0], np.asarray(want))


def test_steps_of_any_size_share_a_program():
    # The engine takes the step as data: a second step compiles nothing, and it is the step the
    # runs take (half the step, about twice the iterations).
    w = lj.TravellingWave(jnp.asarray([0.05, 0.08]), jnp.asarray([3.0, 7.0]), jnp.asarray([1.0, -1.0]))
    chains = lj.Chain(masses=np.ones((2, 3)), waveforms=w)
    params = lj.Params(omega=jnp.asarray([3.0, 7.0]))
    save_at = jnp.asarray([0.0, 4.0])
    runs = lambda mech, dt: (lj.simulate(mech, 4.0, save_at=save_at, dynamics=lj.Exact(dt=dt)),
                             lj.measure(mech, z=0.1, horizon=4.0, dynamics=lj.Exact(dt=dt)))  # fmt: skip
    coarse = [runs(mech, 0.02) for mech in (chains, params)]
    before = _programs()
    fine = [runs(mech, 0.01) for mech in (chains, params)]
    assert _programs() == before
    for (_, m2), (_, m1) in zip(coarse, fine):
        ratio = np.asarray(m1.n_steps) / np.asarray(m2.n_steps)
        assert np.all((ratio > 1.7) & (ratio < 2.3)), ratio
    for (t2, _), (t1, _) in zip(coarse, fine):
        x2, x1 = np.asarray(t2.x)[:, -1], np.asarray(t1.x)[:, -1]
        assert np.all(x1 != x2) and np.allclose(x1, x2, rtol=0, atol=1e-5)


def test_save_counts_of_one_bucket_share_a_program():
    # `simulate` pads its save times to the bucket of their count (`_runs.BatchRows`: 16 up to 16),
    # repeating the last, and runs only those asked for: 3, 5 and 13 saves run one program, each
    # run's rows are bitwise the first ones of the longest, and none is reported capped or invalid.
    w = lj.TravellingWave(jnp.asarray([0.05, 0.08]), jnp.asarray([3.0, 7.0]), jnp.asarray([1.0, -1.0]))
    mechs = (lj.Chain(masses=np.ones((2, 3)), waveforms=w), lj.Params(omega=jnp.asarray([3.0, 7.0])))
    times = jnp.arange(13) * 0.5
    whole = [lj.simulate(mech, 6.0, save_at=times, contact="paper") for mech in mechs]
    before = _programs()
    for k in (3, 5):
        for mech, full in zip(mechs, whole):
            part = lj.simulate(mech, float(times[k - 1]), save_at=times[:k], contact="paper")
            for f in ("x", "v", "e", "valid"):
                np.testing.assert_array_equal(np.asarray(getattr(part, f)), np.asarray(getattr(full, f))[:, :k], f)
            assert np.asarray(part.valid).all() and (np.asarray(part.status) == lj.Status.OK).all()
    assert _programs() == before
