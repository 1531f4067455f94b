"""What the exact engines' batched runs share: lanes, step caps, initial states.

The exact engine runs a flat batch through a work queue (`_queue`, `_saves`); these are
the settings and the start of each configuration that both `simulate` and `measure` use.
"""

import functools
import math
from collections.abc import Callable
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._status import Status
from ..model._params import Params
from ..model._physics import AbstractPhysics
from . import _engine as engine
from ._forward import concrete_value, is_traced


STICK_TOL = 1e-6
"""A mass counts as stuck in the window (SSL) only for a total stuck time above this."""


MICRO_BATCH_CPU = 64
"""Lanes of the exact engine's loops on a CPU (the work queues of `measure` and
`simulate`). Above 64 elements per kernel XLA's CPU runtime splits every kernel
over its thread pool, which costs more than it gains for kernels this small
(benchmarks/NOTES.md, cost model 3)."""


LANE_QUANTUM = 16
"""The CPU queues' lanes are a multiple of this (16 float32 or 8 float64 fill an AVX-512 vector)."""


def default_lanes(n: int, width: int = 1) -> int:
    """The lanes of the exact engine's work queue for a flat batch of `n` configurations.

    On a CPU, `MICRO_BATCH_CPU`, or fewer for a small batch, rounded *up* to a multiple of
    `LANE_QUANTUM` (the lanes past `n` idle). XLA compiles a vmapped kernel of one lane,
    and the lanes of a vector's remainder, to scalar code, whose rounding differs from the
    vector code's in the last bit (measured: 4e-16 to 1e-13 relative on `measure`'s results,
    and a different trajectory where the forcing is not resolved). With every lane inside
    full vectors a configuration gets bitwise the same result alone and in any batch, on the
    same machine (tests/test_batch_independence.py). Elsewhere, the whole batch in one `vmap`.

    `width`: elements per configuration in each kernel (a chain's masses in the array layout,
    `model._chain_array`): then `MICRO_BATCH_CPU // width` lanes (at least 1) whatever `n`, so that
    a kernel stays within 64 elements and a configuration's result does not depend on its batch.
    """
    if jax.default_backend() != "cpu":
        return n
    if width > 1:
        return max(1, MICRO_BATCH_CPU // width)
    return min(MICRO_BATCH_CPU, -(-n // LANE_QUANTUM) * LANE_QUANTUM)


def batch_rows(n: int) -> int:
    """The rows that the exact engine's programs are compiled for, for a flat batch of `n`
    configurations: a multiple of `LANE_QUANTUM` up to `MICRO_BATCH_CPU` (so the CPU's lanes are
    those of `n`), then the next of $2^k \\cdot \\{4, 5, 6, 7\\}$ (four sizes per octave, at most a
    quarter of padding; on a CPU the padding never runs). The batch sizes of one bucket share one
    compiled program (`BatchRows`); 0 stays 0."""
    if n <= MICRO_BATCH_CPU:
        return -(-n // LANE_QUANTUM) * LANE_QUANTUM
    step = 1 << max(0, n.bit_length() - 3)
    return -(-n // step) * step


@functools.partial(jax.jit, static_argnums=1)
def _pad(tree: Any, m: int) -> Any:
    def one(x):
        return jnp.concatenate([x, jnp.broadcast_to(x[-1:], (m - x.shape[0],) + x.shape[1:])])

    return jax.tree_util.tree_map(one, tree)


@functools.partial(jax.jit, static_argnums=1)
def _cut(tree: Any, n: int) -> Any:
    return jax.tree_util.tree_map(lambda x: x[:n], tree)


class BatchRows(NamedTuple):
    """A flat batch of `n` configurations laid out as `m` rows for the engine's programs. Called
    eagerly, `m` is `batch_rows(n)`: the configurations are padded with copies of the last one
    (`pad`), which the work queue does not run (`queue_count`, `_queue.run_queue`'s `count`), and
    the results are cut back to `n` (`cut`). Under a transformation (`jit`, `vmap`, `jvp`, ...) the
    enclosing program is compiled anyway: `m = n`.

    A configuration's result is the same in any batch (`default_lanes`), so in a padded one too,
    bitwise on a CPU."""

    n: int
    m: int

    @classmethod
    def of(cls, n: int, *args: Any) -> "BatchRows":
        """The rows of `n` configurations given by `args` (any pytrees)."""
        return cls(n, n if is_traced(args) else batch_rows(n))

    @property
    def queue_count(self) -> jax.Array:
        """The number of configurations, as the work queue's traced `count`."""
        return jnp.asarray(self.n, jnp.int32)

    def pad(self, tree: Any) -> Any:
        """`tree` (every leaf with a leading axis of `n`) with `m` rows."""
        return tree if self.m == self.n else _pad(tree, self.m)

    def cut(self, tree: Any) -> Any:
        """`tree` (every leaf with a leading axis of `m`) with its first `n` rows."""
        return tree if self.m == self.n else _cut(tree, self.n)


CAP_STEPS_PER_DT = 3
"""Iterations per nominal step that the default step cap allows (steps cut at events included)."""

CAP_EXTRA = 20_000
"""Iterations the default step cap adds for the event searches."""


def default_max_steps(t_total: float, dt: float) -> int:
    """Room for the nominal steps plus the event searches (a hard cap, not a cost)."""
    return int(CAP_STEPS_PER_DT * t_total / dt) + CAP_EXTRA


def step_cap(t_total: jax.Array, dt: float | jax.Array, max_steps: jax.Array) -> jax.Array:
    """The cap on one configuration's loop iterations (traced; int32).

    `max_steps` where it is positive (an explicit `Exact(max_steps=...)`), else
    `default_max_steps` of the configuration's *own* simulated time `t_total` (its
    measurement start plus the horizon). A cap from its own time span, not the batch's
    longest, makes a configuration's status and step count independent of its batch-mates.
    Computed in the configuration's dtype, the same way alone and in a batch; a non-finite
    `t_total` (an invalid configuration, which never runs) gives the bare `CAP_EXTRA`.
    """
    steps = jnp.floor(CAP_STEPS_PER_DT * t_total / dt)
    # 2.1e9 + CAP_EXTRA < 2**31: the cap stays a valid int32 for any span.
    steps = jnp.where(jnp.isfinite(steps), jnp.clip(steps, 0, 2.1e9), 0).astype(jnp.int32)
    return jnp.where(max_steps > 0, max_steps, steps + CAP_EXTRA).astype(jnp.int32)


def horizon_bound(params: Params, t_extra: float) -> float:
    """Host-side bound on the simulated time, for the default step cap."""
    try:
        # Under jvp/vmap the bound comes from the values beneath the tracers.
        ts = np.asarray(concrete_value(params.t_start))
        tmax = float(np.nanmax(np.where(np.isfinite(ts), ts, 0.0)))
    except (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError):
        tmax = 80 * 2 * math.pi / 5.0
    return tmax + t_extra


STARTS = ("paper", "relaxed")
"""The named starts, in the order of [`start_code`][locomotion_jax.dynamics._runs.start_code]."""


def start_code(start: str) -> jax.Array:
    """A named start as the engine's traced index into `STARTS`: both starts then run one
    compiled program (`chain_initial_state` selects the positions)."""
    return jnp.asarray(STARTS.index(start), jnp.int32)


def _by_start(at: Callable[[str], Any], start: str | jax.Array) -> Any:
    """`at(start)` for a named start; for a `start_code`, `at` of both named starts, selected by the
    code (`None` where both give `None`; zeros stand for one `None`)."""
    if isinstance(start, str):
        return at(start)
    paper, relaxed = (at(s) for s in STARTS)
    if paper is None and relaxed is None:
        return None
    paper = jnp.zeros_like(relaxed) if paper is None else paper
    relaxed = jnp.zeros_like(paper) if relaxed is None else relaxed
    return jnp.where(start == 0, paper, relaxed)


def overflow_failed(status: jax.Array, valid: jax.Array, finite: jax.Array) -> tuple[jax.Array, jax.Array]:
    """A trajectory's `status` and `valid` (rows: configurations, then saves) where a valid save is
    not `finite`: its state left the floating-point range (a spring stretched by 1e300: its energy
    overflows). That is the integration's failure, `SOLVER_FAILED`, never an OK run with NaN states,
    and its saves from there are not valid."""
    failed = (status == Status.OK) & jnp.any(valid & ~finite, -1)
    return jnp.where(failed, Status.SOLVER_FAILED, status), valid & finite


def chain_initial_state(P: AbstractPhysics, valid, contact, start: str | jax.Array, row=None) -> engine.Hybrid:
    """The N-body engine's state at $t = 0$ of one mechanism (its physics `P`): at rest in the
    `start` position (a name of `STARTS` or its traced `start_code`), or the state `row`
    $(x_0, \\dots, x_{N-1}, v_0, \\dots, v_{N-1})$ if given, under `contact="hop"` followed by the
    heights and vertical velocities $(y_0, \\dots, y_{N-1}, w_0, \\dots, w_{N-1})$ where the row has
    them (else the physics' own, `AbstractPhysics.hop`);
    flagged `Status.INVALID` where the mechanism is not `valid` or `row` is not finite or one of
    its [`gaps`][locomotion_jax.AbstractPhysics.gaps] is not positive (a chain's positions not in
    increasing order) or a height is negative (then it starts from `start`, so that nothing turns
    NaN). Without `row`, a mechanism's own initial velocities (`AbstractPhysics.initial_velocities`)
    if it has them."""
    x = _by_start(P.initial_positions, start)
    vert = P.hop()[:2] if contact == "hop" else (None, None)
    if row is None:
        st = engine.init(P, contact, x, _by_start(P.initial_velocities, start), *vert)
    else:
        n = x.shape[-1]
        gaps = P.gaps(P.bodies(row[:n]))
        ok = jnp.all(jnp.isfinite(row)) & jnp.all(jnp.stack([jnp.all(g > 0) for g in gaps] or [jnp.asarray(True)]))
        if contact == "hop" and row.shape[-1] == 4 * n:  # heights and vertical velocities given
            ok = ok & jnp.all(row[2 * n : 3 * n] >= 0)
            vert = (jnp.where(ok, row[2 * n : 3 * n], 0), jnp.where(ok, row[3 * n :], 0))
        st = engine.init(P, contact, jnp.where(ok, row[:n], x), jnp.where(ok, row[n : 2 * n], 0), *vert)
        valid = valid & ok
    return eqx.tree_at(lambda s: s.status, st, jnp.where(valid, st.status, Status.INVALID).astype(jnp.int32))
