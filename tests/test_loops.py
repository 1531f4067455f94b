"""`_loops.lane_while_loop`: the same results as `lax.while_loop`, its body batched once under `vmap`."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax._src.interpreters import batching
from locomotion_jax._loops import along_lanes, lane_while_loop


def _loop(while_loop):
    """A loop that ends lane by lane: Newton's method for sqrt(a), with a counter and a flag that
    start unbatched and a float that becomes batched only in the body."""

    def run(a):
        def cond(c):
            x, n, done, _ = c
            return ~done & (n < 50)

        def body(c):
            x, n, _, s = c
            x1 = 0.5 * (x + a / x)
            return x1, n + 1, jnp.abs(x1 - x) <= 1e-14 * x1, s + x1

        return while_loop(cond, body, (a, jnp.zeros((), jnp.int32), jnp.asarray(False), jnp.zeros(())))

    return run


def _body_batchings(monkeypatch, fun, *args) -> set:
    """The distinct sets of batched values that JAX's while-loop batching rule batches the body for."""
    seen = set()
    batch_jaxpr = batching.batch_jaxpr

    def spy(closed_jaxpr, axis_data, in_batched, instantiate):
        if len(closed_jaxpr.out_avals) > 1:  # the body (the predicate has one output)
            seen.add(tuple(in_batched))
        return batch_jaxpr(closed_jaxpr, axis_data, in_batched, instantiate)

    monkeypatch.setattr(batching, "batch_jaxpr", spy)
    jax.make_jaxpr(jax.vmap(fun))(*args)
    return seen


def test_lane_while_loop_gives_the_loops_results_bit_for_bit():
    a = jnp.asarray([0.5, 2.0, 9.0, 1e6, 3.0])
    plain = jax.jit(jax.vmap(_loop(jax.lax.while_loop)))(a)
    lane = jax.jit(jax.vmap(_loop(lane_while_loop)))(a)
    for p, q in zip(plain, lane):
        np.testing.assert_array_equal(np.asarray(p), np.asarray(q))
    # The lanes end at different iterations (the loop's end is per lane).
    assert len(set(np.asarray(lane[1]).tolist())) > 1
    # Outside vmap, and differentiated, the same too.
    np.testing.assert_array_equal(np.asarray(_loop(lane_while_loop)(a[2])[0]), 3.0)
    g = jax.jacfwd(lambda x: _loop(lane_while_loop)(x)[0])(a[2])
    assert g == pytest.approx(1 / 6, rel=1e-12)


def test_lane_while_loop_batches_its_body_once(monkeypatch):
    a = jnp.asarray([0.5, 2.0, 9.0])
    # lax.while_loop: a fixpoint over which values the body makes batched (the counter, flag and
    # sum start unbatched), then every value batched.
    assert len(_body_batchings(monkeypatch, _loop(jax.lax.while_loop), a)) > 1
    monkeypatch.undo()
    assert len(_body_batchings(monkeypatch, _loop(lane_while_loop), a)) == 1


def test_along_lanes_keeps_every_value():
    tree = (jnp.asarray([1.0, jnp.nan, jnp.inf]), jnp.asarray(3, jnp.int32), jnp.asarray(True), jnp.zeros((2, 0)))
    out = along_lanes(tree)
    for x, y in zip(tree, out):
        assert x.dtype == y.dtype and x.shape == y.shape
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
    assert along_lanes(()) == ()
