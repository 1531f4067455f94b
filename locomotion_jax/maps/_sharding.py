"""One compiled, device-sharded evaluation of a chunk of configurations.

The batch axis of a chunk is split over a 1-D mesh of every device JAX sees
(`jax.devices()`: all local devices, or all devices of all hosts under
`jax.distributed`). How the chunk is run over the mesh is the dynamics' choice
(`AbstractDynamics.measure_chunk`): the exact engine runs `measure`'s work queue on
each device's own shard through `jax.shard_map`, so each device stops as soon as
*its* configurations are done, instead of every device waiting for the globally
slowest one (which a plain `jit` with a sharded input would not guarantee). The
smoothed model (diffrax) does not go through `shard_map` (its closure conversion
rejects the per-device types); it runs under `jit` on the sharded batch, which XLA
partitions automatically (same results; devices wait for each other).
"""

import dataclasses
from collections import Counter
from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec as P

from .._results import PAPER
from ..dynamics._base import AbstractDynamics
from ..dynamics._compile import engine_jit
from ..dynamics._flat import FlatBatch
from ..dynamics._runs import batch_rows
from ..model._params import PARAM_NAMES, Params
from ..run._resolution import flag, guard_values
from ._dataset import per_mass_columns


BATCH_AXIS = "batch"

UNRESOLVED_KEY = "_unresolved"
"""The host mask of a chunk's unresolved configurations, carried from `dispatch_chunk` to `fetch`."""

TRACES: Counter = Counter()
"""Python-level traces of the chunk function, by key `"run_chunk"` (a map of the paper's model
or of a builder's mechanisms).

The body of a jitted function runs in Python only when JAX traces (and so
compiles) it; tests read this counter to check that all chunks of a sweep share
one compilation.
"""


MICRO_BATCH: int | None = None
"""Lanes per device. Exact model: the width of each device's work queue (`None`:
`_runs.MICRO_BATCH_CPU` on a CPU, where wider kernels are split over threads and
run slower, benchmarks/NOTES.md; the whole shard elsewhere). Smoothed model: if
set, a shard runs as sub-batches of this many configurations (`lax.map`)."""


VECTOR_BYTES = 64
"""Each device's shard of a chunk is padded to whole vectors of this many bytes (512 bits,
the widest SIMD registers of a CPU). XLA's CPU code computes a lane left over after the
whole vectors (or a shard of one lane) differently: with 9 float64 lanes (8 + 1) `tau_z`,
`e_d` and others came out 1 ulp off for whichever configuration sat in the ninth lane, so
a result depended on its place in the chunk, and a cost-ordered sweep did not reproduce a
natural-order one bit for bit (tests/test_sweep.py checks it with chunks of 9)."""


def padded_size(n: int, n_devices: int, dtype: np.dtype) -> int:
    """Shape of a chunk of `n` configurations: a whole number of SIMD vectors per device, and
    one of a few sizes (`_runs.batch_rows` of each device's share: a multiple of 16 up to 64,
    then four sizes per octave), so that sweeps of different sizes share a compiled program."""
    lanes = max(1, VECTOR_BYTES // np.dtype(dtype).itemsize)
    share = -(-n // (n_devices * lanes)) * lanes
    rows = batch_rows(share)
    return n_devices * (rows if rows % lanes == 0 else share)


def batch_mesh(local: bool = False) -> Mesh:
    """A 1-D mesh with the single axis `"batch"`: over all devices, or with `local`
    over this process's own (under `jax.distributed`, chunks computed by one process)."""
    return Mesh(np.asarray(jax.local_devices() if local else jax.devices()), (BATCH_AXIS,))


def device_count(mesh: Mesh) -> int:
    return int(mesh.devices.size)


def _run_chunk(
    flat: Params | FlatBatch,
    zhw: jax.Array,
    dynamics: AbstractDynamics,
    contact: str,
    start: str,
    max_steps: jax.Array,
    mesh: Mesh,
    micro_batch: int | None,
) -> dict[str, jax.Array]:
    # Runs only while tracing: counts compilations, not calls.
    TRACES["run_chunk"] += 1
    batch = flat.own_batch()  # the paper's chunk with its sinusoid of eq. (13); a mechanism's as it stands
    out = dynamics.measure_chunk(batch, zhw, contact, start, max_steps, mesh, micro_batch)
    # The paper's per-mass fields as one array per mass (the dataset's variables; under "hop" the hopping ones).
    return per_mass_columns(out) if batch.names == PAPER else out


_run_chunk = engine_jit(_run_chunk, ("contact", "start", "mesh", "micro_batch"))


def _global_array(host: np.ndarray, sharding: NamedSharding) -> jax.Array:
    # Each process supplies only its addressable shards: the same call works on
    # one host and under jax.distributed (every process holds the full chunk).
    return jax.make_array_from_callback(host.shape, sharding, lambda index: host[index])


def _to_host(x: jax.Array) -> np.ndarray:
    if x.is_fully_addressable:  # one process, or a mesh of this process's devices
        return np.asarray(x)
    from jax.experimental import multihost_utils

    return np.asarray(multihost_utils.process_allgather(x, tiled=True))


def dispatch_chunk(
    values: Mapping[str, np.ndarray],
    dtype: np.dtype,
    z: float,
    horizon: float,
    window: float,
    dynamics: AbstractDynamics,
    contact: str,
    start: str,
    mesh: Mesh,
    micro_batch: int | None = None,
) -> dict[str, jax.Array]:
    """Start the computation of one chunk (asynchronously) and return its device outputs.

    **Arguments:**

    - `values`: one host array per name of `PARAM_NAMES`, all of the same length,
      a multiple of the mesh size (padding entries should be NaN: they are then
      invalid, flagged `Status.INVALID` and cost no integration steps).
    - `dtype`: floating dtype of the computation.
    - `z`, `horizon`, `window`, `dynamics`, `contact`, `start`: as in `measure`.
    - `mesh`: from [`batch_mesh`][].
    - `micro_batch`: configurations vmapped together per device (default [`MICRO_BATCH`][]: all).

    A configuration whose step does not resolve its time scales, or whose `Params.t_start` takes
    more than `MAX_START_STEPS` steps (`run._resolution`), is run as an invalid one (not
    integrated) and [`fetch`][] flags it `Status.UNRESOLVED`.

    **Returns:** a dict of sharded arrays (one per `Measurement` field; under `contact="hop"` the per-mass
    hopping fields one per mass, `_dataset.HOP_FIELDS`); read them with [`fetch`][].
    """
    values, unresolved = guard_values(values, dtype, dynamics, default_start=True)  # a sweep starts at Params.t_start
    out = _run_chunk(*_chunk_args(values, dtype, z, horizon, window, dynamics, contact, start, mesh, micro_batch))
    return out if unresolved is None else {**out, UNRESOLVED_KEY: jnp.asarray(unresolved)}


def dispatch_mechanism_chunk(
    mechanism: Any,
    live: np.ndarray,
    dtype: np.dtype,
    z: float,
    horizon: float,
    window: float,
    t_start: float | None,
    dynamics: AbstractDynamics,
    contact: str,
    start: str,
    mesh: Mesh,
    micro_batch: int | None = None,
) -> dict[str, jax.Array]:
    """[`dispatch_chunk`][] for a map over a builder's mechanisms (`sweep(axes, mechanism=build)`):
    start the computation of one chunk (asynchronously) and return its device outputs.

    **Arguments:**

    - `mechanism`: the chunk, a [`Chain`][locomotion_jax.Chain] or
      [`Mechanism`][locomotion_jax.Mechanism] of batch shape `(n,)`, `n` a multiple of the mesh size.
    - `live`: host mask of shape `(n,)`, `False` for padding: run as an invalid configuration
      (not integrated, flagged `Status.INVALID`; [`fetch`][] drops it).
    - `t_start`: the measurement's start for every configuration, or `None` for each one's own
      (`Chain.t_start`, `Mechanism.t_start`, computed here on the host: a batched eigensolver
      inside the chunk's program can deadlock XLA's CPU thread pool).
    - the rest as in [`dispatch_chunk`][].

    The mechanism flattens itself as for `measure` (`AbstractMechanism.flat_batch`: checks, the
    resolution guard, whose unresolved configurations [`fetch`][] flags `Status.UNRESOLVED`), and
    each device runs its own shard (`AbstractDynamics.measure_chunk`).

    **Returns:** a dict of sharded arrays, one per array field of a `Measurement` (per-body fields
    with a trailing body axis); read them with [`fetch`][].
    """
    batch, unresolved, _ = mechanism.flat_batch(dynamics, dtype=dtype, t_start=t_start, measuring=True,
                                                contact=contact, start=start)  # fmt: skip
    ts = batch.mechanism.t_start if batch.t_start is None else batch.t_start
    batch = dataclasses.replace(batch, valid=batch.valid & jnp.asarray(live), t_start=jnp.asarray(ts, batch.dtype))
    sharding = NamedSharding(mesh, P(BATCH_AXIS))
    batch = jax.tree_util.tree_map(lambda x: _global_array(np.asarray(x), sharding), batch)
    zhw, dyn, cap = _settings(dtype, z, horizon, window, dynamics)
    out = _run_chunk(batch, zhw, dyn, contact, start, cap, mesh, micro_batch or MICRO_BATCH or None)
    return out if unresolved is None else {**out, UNRESOLVED_KEY: jnp.asarray(unresolved)}


def chunk_dtypes(
    values: Mapping[str, np.ndarray],
    dtype: np.dtype,
    z: float,
    horizon: float,
    window: float,
    dynamics: AbstractDynamics,
    contact: str,
    start: str,
    mesh: Mesh,
    micro_batch: int | None = None,
) -> dict[str, np.dtype]:
    """The dtype of each output of [`dispatch_chunk`][] for the same arguments, computed
    without running it (the trace is kept by `jax.jit`: the chunks do not trace again)."""
    args = _chunk_args(values, dtype, z, horizon, window, dynamics, contact, start, mesh, micro_batch)
    # `_run_chunk` is the `jax.jit` wrapper (reassigned above), which has `eval_shape`.
    out = _run_chunk.eval_shape(*args)  # pyright: ignore[reportFunctionMemberAccess]
    return {k: np.dtype(v.dtype) for k, v in out.items()}


def _chunk_args(values, dtype, z, horizon, window, dynamics, contact, start, mesh, micro_batch) -> tuple:
    sharding = NamedSharding(mesh, P(BATCH_AXIS))
    fields = {n: _global_array(np.asarray(values[n], dtype), sharding) for n in PARAM_NAMES}
    flat = Params(**fields, check=False)
    zhw, dynamics, cap = _settings(dtype, z, horizon, window, dynamics)
    return flat, zhw, dynamics, contact, start, cap, mesh, micro_batch or MICRO_BATCH or None


def _settings(dtype, z, horizon, window, dynamics) -> tuple[jax.Array, AbstractDynamics, jax.Array]:
    """A chunk program's `(z, horizon, window)` array, dynamics and loop cap."""
    zhw = jnp.asarray(np.asarray([z, horizon, window], dtype))
    # Its array settings (`Smoothed.eps`) in the chunk's dtype, its loop cap as data: sweeps of any cap share a program.
    dynamics, max_steps = dynamics.astype(dtype).chunk_program()
    cap = jnp.asarray(min(int(max_steps), np.iinfo(np.int32).max), jnp.int32)
    return zhw, dynamics, cap


def fetch(out: Mapping[str, jax.Array], n: int) -> dict[str, np.ndarray]:
    """Block on a dispatched chunk and copy its first `n` (unpadded) entries to the host."""
    host = {k: _to_host(v)[:n] for k, v in out.items() if k != UNRESOLVED_KEY}
    mask = out.get(UNRESOLVED_KEY)
    return host if mask is None else flag(host, np.asarray(mask)[:n])


def from_process0(x: np.ndarray) -> np.ndarray:
    """Process 0's copy of a host array (under `jax.distributed`; unchanged on one process)."""
    if jax.process_count() == 1:
        return x
    from jax.experimental import multihost_utils

    return np.asarray(multihost_utils.broadcast_one_to_all(x))


def agree(done: set[int], n_chunks: int) -> set[int]:
    """Under `jax.distributed`, all processes must run the same chunks: take process 0's view."""
    if jax.process_count() == 1:
        return done
    mask = np.zeros(n_chunks, np.int32)
    mask[sorted(done)] = 1
    return {int(i) for i in np.flatnonzero(from_process0(mask))}
