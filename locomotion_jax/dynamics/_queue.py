"""A work queue: many configurations through a fixed number of vmapped lanes.

Under `vmap`, a `while_loop` runs until its slowest lane is done: a lane whose
configuration finished early idles (its updates are selected away) while the
others continue. Here a lane takes the next configuration of the queue as soon
as its own is done (compaction), so every lane works until the queue is empty
and a batch costs about the *mean* duration of its configurations times the
batch size over the lanes, not the maximum duration of every group of lanes.

Two nested loops: the inner one advances every lane until one of them finishes
(it carries only the lanes' changing state, so an iteration costs what the step
costs); the outer one then stores the finished lanes' results and gives them the
next configurations. Configurations finish in a small fraction of the iterations,
so the outer loop's work is a small part of the whole.

Results are written to the configuration's own index, so they do not depend on
the lane a configuration ran in nor on the order of the queue.

A configuration may also produce rows while it runs (`simulate`'s saved states:
a [`Stream`][]). A lane keeps them in a small buffer of its own state, and the inner
loop also stops when a buffer is full; the outer loop then copies every lane's
buffered rows into its configuration's rows of the output. A row is written once,
by one scatter per outer iteration: a write into the output inside the hot loop
(a scatter per lane and iteration) would cost more than the step itself.
"""

from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp


class Stream(NamedTuple):
    """Rows that a configuration produces while it runs (functions of *one* configuration).

    - `full(fixed, dyn)`: the lane's buffer is full: hand it over before the next iteration.
    - `drain(fixed, dyn)`: `(dyn, rows, slots)`: the state with an empty buffer, the
      buffered rows (leading axis: the buffer), and each row's index among the
      configuration's `size` rows (`size` or more for an empty slot: dropped).
    - `size`: rows per configuration.
    """

    full: Callable[[Any, Any], jax.Array]
    drain: Callable[[Any, Any], tuple[Any, jax.Array, jax.Array]]
    size: int


def _select(flags: jax.Array, new: Any, old: Any) -> Any:
    """Per-lane `where` over two pytrees with a leading lane axis."""

    def pick(a, b):
        return jnp.where(flags.reshape(flags.shape + (1,) * (a.ndim - 1)), a, b)

    return jax.tree_util.tree_map(pick, new, old)


def run_queue(
    setup: Callable[[jax.Array], tuple[Any, Any]],
    running: Callable[[Any, Any], jax.Array],
    advance: Callable[[Any, Any], Any],
    results: Callable[[Any, Any], dict[str, jax.Array]],
    n: int,
    lanes: int,
    order: jax.Array | None = None,
    stream: Stream | None = None,
) -> dict[str, jax.Array]:
    """Run `n` configurations to completion on `lanes` lanes.

    **Arguments** (functions of *one* configuration; they are vmapped here):

    - `setup(i)`: the loop state of configuration `i` (a traced int32), as a pair
      `(fixed, dyn)`: what stays constant during its run, and what the loop updates.
    - `running(fixed, dyn)`: whether it needs another iteration.
    - `advance(fixed, dyn)`: one iteration; returns the new `dyn`.
    - `results(fixed, dyn)`: its outputs once done (a dict of scalars or arrays;
      with a `stream`, no key `"stream"`).
    - `n`, `lanes`: number of configurations, and of lanes (static; lanes past `n` idle).
    - `order`: the queue's order (a permutation of `range(n)`; default: as given).
      Longest first shortens the tail, where lanes run out of work.
    - `stream`: rows produced during the run ([`Stream`][]), if any.

    **Returns:** the dict of `results`, each with a leading axis of length `n`; with a
    `stream`, also `"stream"`: the rows, shape `(n, stream.size) + row shape` (zeros
    where no row was written).
    """
    lanes = max(1, lanes)  # more lanes than configurations: the extra ones idle throughout
    order = jnp.arange(n, dtype=jnp.int32) if order is None else order.astype(jnp.int32)
    config = lambda pos: order[jnp.minimum(pos, n - 1)]
    setup_all = jax.vmap(setup)
    running_all = jax.vmap(running)
    results_all = jax.vmap(results)

    advance_all = jax.vmap(advance)

    pos = jnp.arange(lanes, dtype=jnp.int32)  # position in the queue of each lane's configuration
    fixed, dyn = setup_all(config(pos))
    shapes = jax.eval_shape(results_all, fixed, dyn)
    out = jax.tree_util.tree_map(lambda s: jnp.zeros((n,) + s.shape[1:], s.dtype), shapes)
    if stream is not None:
        full_all = jax.vmap(stream.full)
        drain_all = jax.vmap(stream.drain)
        rows = jax.eval_shape(drain_all, fixed, dyn)[1]
        out = {**out, "stream": jnp.zeros((n, stream.size) + rows.shape[2:], rows.dtype)}
        needs_outer = lambda f, d: running_all(f, d) & ~full_all(f, d)
    else:
        needs_outer = running_all

    def until_one_finishes(pos, fixed, dyn):
        # The hot loop carries only `dyn`: `fixed` and the lanes' positions are
        # loop-invariant here, and no output buffer passes through it.
        active = pos < n
        # Every active lane is running inside the loop: the select needs only `active`.
        cond = lambda d: jnp.all(needs_outer(fixed, d) | ~active) & jnp.any(active)
        return jax.lax.while_loop(cond, lambda d: _select(active, advance_all(fixed, d), d), dyn)

    def refill(carry):
        pos, nxt, fixed, dyn, out = carry
        dyn = until_one_finishes(pos, fixed, dyn)
        if stream is not None:  # every lane's buffered rows, into its configuration's rows
            dyn, rows, slots = drain_all(fixed, dyn)  # pyright: ignore[reportPossiblyUnboundVariable]  # set with `stream`
            cfg = jnp.where(pos < n, config(pos), n)[:, None]  # n: out of bounds, dropped
            out = {**out, "stream": out["stream"].at[cfg, slots].set(rows, mode="drop")}
        done = (pos < n) & ~running_all(fixed, dyn)
        at = jnp.where(done, config(pos), n)  # n: out of bounds, dropped
        results = results_all(fixed, dyn)
        out = {**out, **{k: out[k].at[at].set(r, mode="drop") for k, r in results.items()}}
        # Finished lanes take the next positions, in lane order; past the end they idle.
        pos = jnp.where(done, nxt + jnp.cumsum(done, dtype=jnp.int32) - 1, pos)
        nxt = nxt + jnp.sum(done, dtype=jnp.int32)
        new_fixed, new_dyn = setup_all(config(pos))
        return pos, nxt, _select(done, new_fixed, fixed), _select(done, new_dyn, dyn), out

    carry = (pos, jnp.asarray(lanes, jnp.int32), fixed, dyn, out)
    *_, out = jax.lax.while_loop(lambda c: jnp.any(c[0] < n), refill, carry)
    return out
