"""Saved states of a flat batch: `simulate`'s loop, shared by both exact engines.

Every configuration runs through the work queue ([`_queue.run_queue`][]), as in
`measure`: a lane whose configuration is done takes the next one, so a batch costs
about the mean duration of its configurations, not the longest of each group of lanes.
Each iteration of a running configuration either saves its state (a save time is
reached: the state stays there) or takes one integrator step towards the next save
time. A lane holds up to `buffer` saved rows in its own state; the queue's outer loop
copies them into the output ([`_queue.Stream`][]), so the hot loop carries no output.
"""

from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from .._custom_types import Array
from .._status import Status
from ._queue import run_queue, Stream


BUFFER = 8
"""Saved rows a lane holds before the work queue's outer loop copies them out."""

FEW_SAVES = 16
"""Up to this many saves per configuration, a save leaves the hot loop instead: the outer loop
writes the row. The buffer's write in the hot loop is a select over a `(lanes, buffer, row)`
array on every iteration, an array large enough that XLA's CPU runtime splits it over threads
(`_runs.MICRO_BATCH_CPU`). Leaving the loop costs an outer iteration per save and lane
instead, which few saves amortise. `benchmarks/simulate_vs_measure.py` (B = 1024, dt = 0.03,
171 time units, throughput against `measure`'s): 1 save 0.58 buffered, 1.05 leaving the loop;
16 saves 0.46-0.55 and 0.73; 64 saves even (0.48); 256 saves 0.49 and 0.35."""


class _Dyn(NamedTuple):
    """The loop state of one configuration.

    `idx` saves are done; the last `n_buffered` of them wait in `rows` (in order) for the
    outer loop, and `targets` are the save times `idx - n_buffered` onwards (so the
    current one is `targets[n_buffered]`, chosen without a gather).
    """

    s: Any  # the engine's hybrid state
    idx: Array
    steps: Array
    rows: Array  # (buffer, row size)
    n_buffered: Array
    targets: Array  # (buffer,)


def _targets(save_at: Array, first: Array, buffer: int) -> Array:
    return save_at[jnp.minimum(first + jnp.arange(buffer), save_at.shape[0] - 1)]


def run_saves(
    init: Callable[[Array], tuple[Any, Any]],
    step: Callable[[Any, Any, Array], Any],
    row: Callable[[Any], Array],
    n: int,
    save_at: Array,
    max_steps: Array,
    lanes: int,
    order: Array | None = None,
    buffer: int = BUFFER,
    count: Array | None = None,
    saves: Array | None = None,
) -> tuple[Array, Array, Array, Array, Array]:
    """The states of `n` configurations at the times `save_at` (the first `saves` of them).

    **Arguments:**

    - `init(i)`: `(fixed, s)` of configuration `i` (a traced int32): what its steps
      need, and its initial hybrid state (`status` `INVALID` for an invalid one).
      A hybrid state has fields `t`, `status`, `t_liftoff` and `n_switch`.
    - `step(fixed, s, t_stop)`: one integrator step, stopping at `t_stop`.
    - `row(s)`: the saved values of a state (1-D, the state's dtype).
    - `save_at`: non-decreasing save times; `max_steps`: cap on the iterations of
      one configuration (a save counts as one).
    - `lanes`, `order`, `count`: as in [`_queue.run_queue`][]; `buffer`: rows per lane.
    - `saves`: how many of `save_at` are requested (traced; `None`: all). The rest pad it to the
      length its program is compiled for (`_runs.BatchRows`: 16 for up to 16 saves, then 32, 48,
      64, 80, ...; `FEW_SAVES` is a bucket's edge, so a padded run loops as the unpadded one) and
      are not run: their rows hold the last state, `valid` false.

    **Returns:** `(rows, valid, status, t_liftoff, n_switch)`: `rows` of shape
    `(n, len(save_at), row size)`; a configuration that stopped early (lift-off
    under the strict reading, step cap, invalid) has `valid` false from there on,
    and those rows hold its last state. `status` is `MAX_STEPS` where the step cap
    came before the last save.
    """
    n_save = save_at.shape[0]
    n_real = jnp.asarray(n_save if saves is None else saves, jnp.int32)
    if n_save <= FEW_SAVES:
        return _run_few_saves(init, step, row, n, save_at, max_steps, lanes, order, count, n_real)
    buffer = max(1, min(buffer, n_save))
    zi = jnp.zeros((), jnp.int32)

    def setup(i):
        fixed, s = init(i)
        rows = jnp.zeros((buffer,) + row(s).shape, s.t.dtype)
        return fixed, _Dyn(s, zi, zi, rows, zi, _targets(save_at, zi, buffer))

    def running(fixed, d: _Dyn) -> Array:
        return (d.idx < n_real) & (d.s.status == Status.OK) & (d.steps < max_steps)

    def advance(fixed, d: _Dyn) -> _Dyn:
        slot = jnp.arange(buffer) == d.n_buffered
        target = jnp.sum(jnp.where(slot, d.targets, 0))
        record = target <= d.s.t
        new_s = step(fixed, d.s, target)
        # The row goes to the lane's buffer by a select over its few slots: a scatter per
        # lane and iteration (into the output, or into a buffer of every save) costs more
        # than the step (benchmarks/simulate_vs_measure.py).
        rows = jnp.where((slot & record)[:, None], row(d.s)[None, :], d.rows)
        s = jax.tree_util.tree_map(lambda a, b: jnp.where(record, b, a), new_s, d.s)
        saved = record.astype(jnp.int32)
        return _Dyn(s, d.idx + saved, d.steps + 1, rows, d.n_buffered + saved, d.targets)

    def drain(fixed, d: _Dyn) -> tuple[_Dyn, Array, Array]:
        k = jnp.arange(buffer)
        slots = jnp.where(k < d.n_buffered, d.idx - d.n_buffered + k, n_save)  # past the end: dropped
        emptied = d._replace(n_buffered=zi, targets=_targets(save_at, d.idx, buffer))
        return emptied, d.rows, slots

    results = lambda fixed, d: _results(d, row, n_real)
    full = lambda fixed, d: d.n_buffered >= buffer
    out = run_queue(setup, running, advance, results, n, lanes, order, Stream(full, drain, n_save), count)
    return _assemble(out, n_save)


def _results(d: Any, row: Callable[[Any], Array], n_real: Array) -> dict[str, Array]:
    """A configuration's outputs once done (either loop's state: `s`, `idx` saves done of `n_real`)."""
    s = d.s
    capped = (s.status == Status.OK) & (d.idx < n_real)  # stopped by the step cap before the last save
    status = jnp.where(capped, Status.MAX_STEPS, s.status).astype(jnp.int32)
    return dict(saved=d.idx, last=row(s), status=status, t_liftoff=s.t_liftoff, n_switch=s.n_switch)


def _assemble(out: dict, n_save: int) -> tuple[Array, Array, Array, Array, Array]:
    valid = jnp.arange(n_save)[None, :] < out["saved"][:, None]
    rows = jnp.where(valid[..., None], out["stream"], out["last"][:, None, :])
    return rows, valid, out["status"], out["t_liftoff"], out["n_switch"]


class _Few(NamedTuple):
    """The loop state of one configuration with few saves: `idx` saves done, the next at `target`."""

    s: Any
    idx: Array
    steps: Array
    target: Array


def _run_few_saves(
    init, step, row, n, save_at, max_steps, lanes, order, count, n_real
) -> tuple[Array, Array, Array, Array, Array]:
    """[`run_saves`][] for at most `FEW_SAVES` saves: the hot loop only steps (landing on each save
    time); reaching a save time ends the inner loop, and the queue's outer loop writes the row
    ([`_queue.Stream`][] with a one-row buffer that is full exactly then). The same steps as the
    buffered loop, so the same rows; a save is not counted as an iteration."""
    n_save = save_at.shape[0]
    zi = jnp.zeros((), jnp.int32)
    target_of = lambda idx: save_at[jnp.minimum(idx, n_save - 1)]

    def setup(i):
        fixed, s = init(i)
        return fixed, _Few(s, zi, zi, target_of(zi))

    def running(fixed, d: _Few) -> Array:
        return (d.idx < n_real) & (d.s.status == Status.OK) & (d.steps < max_steps)

    def due(fixed, d: _Few) -> Array:  # a save time reached: the outer loop records it
        return (d.idx < n_real) & (d.s.status == Status.OK) & (d.target <= d.s.t)

    def advance(fixed, d: _Few) -> _Few:
        return d._replace(s=step(fixed, d.s, d.target), steps=d.steps + 1)

    def drain(fixed, d: _Few) -> tuple[_Few, Array, Array]:
        record = due(fixed, d)
        idx = d.idx + record.astype(jnp.int32)
        slot = jnp.where(record, d.idx, n_save)[None]  # past the end: dropped
        return d._replace(idx=idx, target=target_of(idx)), row(d.s)[None, :], slot

    results = lambda fixed, d: _results(d, row, n_real)

    # The inner loop ends where a lane is due: `running` stays true there (its save is pending),
    # so the queue drains before it decides which lanes are done.
    out = run_queue(setup, running, advance, results, n, lanes, order, Stream(due, drain, n_save), count)
    return _assemble(out, n_save)
