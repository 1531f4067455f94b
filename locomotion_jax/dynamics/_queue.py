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

**Reverse mode.** Traced inside [`reverse_loops`][], [`run_queue`][] builds instead one loop
per configuration (a `vmap` over all of them, no queue, no lanes) that reverse mode can
traverse: `equinox.internal.while_loop(kind="checkpointed")` with [`CHECKPOINTS`][] stored
states (online binomial checkpointing: the backward pass recomputes the steps between two
checkpoints). The same steps in the same order per configuration, so the same values; the
rows of a [`Stream`][] are scattered into the configuration's own rows as they are drained.
`_compile.engine_jit` traces it for the backward pass of `jax.grad`/`jax.vjp`.
"""

import contextlib
import contextvars
from collections.abc import Callable, Iterator
from typing import Any, NamedTuple

import equinox.internal as eqxi
import jax
import jax.numpy as jnp


CHECKPOINTS = 256
"""States a configuration's reverse-mode loop stores: with $c$ of them the backward pass of a run
of up to about $c^2/2$ steps recomputes each step about twice (Stumm and Walther's online
checkpointing, in `equinox.internal`); longer runs recompute more."""

_REVERSE: contextvars.ContextVar[bool] = contextvars.ContextVar("lj_reverse_loops", default=False)


@contextlib.contextmanager
def reverse_loops() -> Iterator[None]:
    """While tracing inside this context, [`run_queue`][] builds loops that reverse mode traverses
    (module docstring). The flag is read at trace time: trace a function that is not itself
    cached by `jax.jit` under the other setting."""
    token = _REVERSE.set(True)
    try:
        yield
    finally:
        _REVERSE.reset(token)


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
    count: jax.Array | None = None,
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
    - `count`: how many of the `n` configurations run (a traced int32, default `n`): the first
      `count`. The others are padding: they do not run, and their results are to be dropped. A
      program compiled for `n` rows then serves every smaller batch (`_runs.BatchRows`).

    **Returns:** the dict of `results`, each with a leading axis of length `n`; with a
    `stream`, also `"stream"`: the rows, shape `(n, stream.size) + row shape` (zeros
    where no row was written).
    """
    if _REVERSE.get():
        return _run_each(setup, running, advance, results, n, stream, count)
    lanes = max(1, lanes)  # more lanes than configurations: the extra ones idle throughout
    order = jnp.arange(n, dtype=jnp.int32) if order is None else order.astype(jnp.int32)
    if count is None:
        count = jnp.asarray(n, jnp.int32)
    else:  # the padding last in the queue, the others in their order
        order = order[jnp.argsort(order >= count, stable=True)]
    config = lambda pos: order[jnp.minimum(pos, count - 1)]
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
        active = pos < count
        # Every active lane is running inside the loop: the select needs only `active`.
        cond = lambda d: jnp.all(needs_outer(fixed, d) | ~active) & jnp.any(active)
        return jax.lax.while_loop(cond, lambda d: _select(active, advance_all(fixed, d), d), dyn)

    def refill(carry):
        pos, nxt, fixed, dyn, out = carry
        dyn = until_one_finishes(pos, fixed, dyn)
        if stream is not None:  # every lane's buffered rows, into its configuration's rows
            dyn, rows, slots = drain_all(fixed, dyn)  # pyright: ignore[reportPossiblyUnboundVariable]  # set with `stream`
            cfg = jnp.where(pos < count, config(pos), n)[:, None]  # n: out of bounds, dropped
            out = {**out, "stream": out["stream"].at[cfg, slots].set(rows, mode="drop")}
        done = (pos < count) & ~running_all(fixed, dyn)
        at = jnp.where(done, config(pos), n)  # n: out of bounds, dropped
        results = results_all(fixed, dyn)
        out = {**out, **{k: out[k].at[at].set(r, mode="drop") for k, r in results.items()}}
        # Finished lanes take the next positions, in lane order; past the end they idle.
        pos = jnp.where(done, nxt + jnp.cumsum(done, dtype=jnp.int32) - 1, pos)
        nxt = nxt + jnp.sum(done, dtype=jnp.int32)
        new_fixed, new_dyn = setup_all(config(pos))
        return pos, nxt, _select(done, new_fixed, fixed), _select(done, new_dyn, dyn), out

    carry = (pos, jnp.asarray(lanes, jnp.int32), fixed, dyn, out)
    *_, out = jax.lax.while_loop(lambda c: jnp.any(c[0] < count), refill, carry)
    return out


def _run_each(
    setup: Callable[[jax.Array], tuple[Any, Any]],
    running: Callable[[Any, Any], jax.Array],
    advance: Callable[[Any, Any], Any],
    results: Callable[[Any, Any], dict[str, jax.Array]],
    n: int,
    stream: Stream | None,
    count: jax.Array | None,
) -> dict[str, jax.Array]:
    """[`run_queue`][]'s outputs by one checkpointed loop per configuration (module docstring).

    An iteration first drains a full buffer (as the queue's outer loop does), then advances a
    configuration that is still running and not full; the rows left in the buffer at the end are
    drained last. Configurations from `count` on are set up but do not run."""

    def one(i):
        fixed, dyn = setup(i)
        live = jnp.asarray(True) if count is None else i < count
        running_ = lambda f, d: live & running(f, d)
        if stream is None:
            loop = lambda d: advance(fixed, d)
            dyn = eqxi.while_loop(lambda d: running_(fixed, d), loop, dyn, kind="checkpointed",
                                  checkpoints=CHECKPOINTS)  # fmt: skip
            return results(fixed, dyn)
        sm: Stream = stream
        rows_shape = jax.eval_shape(lambda d: sm.drain(fixed, d)[1], dyn)
        out = jnp.zeros((sm.size,) + rows_shape.shape[1:], rows_shape.dtype)

        def put(d, out, when):
            drained, rows, slots = sm.drain(fixed, d)
            slots = jnp.where(when, slots, sm.size)  # past the end: dropped
            d = jax.tree_util.tree_map(lambda a, b: jnp.where(when, a, b), drained, d)
            return d, out.at[slots].set(rows, mode="drop")

        def body(c):
            d, out = c
            d, out = put(d, out, sm.full(fixed, d))
            go = running_(fixed, d) & ~sm.full(fixed, d)
            d = jax.tree_util.tree_map(lambda a, b: jnp.where(go, a, b), advance(fixed, d), d)
            return d, out

        cond = lambda c: running_(fixed, c[0])
        dyn, out = eqxi.while_loop(cond, body, (dyn, out), kind="checkpointed", checkpoints=CHECKPOINTS)
        dyn, out = put(dyn, out, jnp.asarray(True))
        return {**results(fixed, dyn), "stream": out}

    return jax.vmap(one)(jnp.arange(n, dtype=jnp.int32))
