"""One compiled, device-sharded evaluation of a chunk of configurations.

The batch axis of a chunk is split over a 1-D mesh of every device JAX sees
(`jax.devices()`: all local devices, or all devices of all hosts under
`jax.distributed`). Each device runs `measure`'s work queue on its own shard
(`_measure.exact_batch`) through `jax.shard_map`, so each device stops as soon as
*its* configurations are done, instead of every device waiting for the globally
slowest one (which a plain `jit` with a sharded input would not guarantee).

The smoothed model (diffrax) does not go through `shard_map` (its closure
conversion rejects the per-device types); it runs under `jit` on the sharded batch,
which XLA partitions automatically (same results; devices wait for each other).
"""

from collections import Counter
from collections.abc import Mapping

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec as P

from ..dynamics._base import AbstractDynamics, Exact, Smoothed
from ..dynamics._compile import engine_jit
from ..model._params import PARAM_NAMES, Params
from ..model._waveform import Sinusoid
from ..run._measure import exact_batch


BATCH_AXIS = "batch"

TRACES: Counter = Counter()
"""Python-level traces of the chunk function, by key `"run_chunk"`.

The body of a jitted function runs in Python only when JAX traces (and so
compiles) it; tests read this counter to check that all chunks of a sweep share
one compilation.
"""


MICRO_BATCH: int | None = None
"""Lanes per device. Exact model: the width of each device's work queue (`None`:
`_batch.MICRO_BATCH_CPU` on a CPU, where wider kernels are split over threads and
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
    """Shape of a chunk of `n` configurations: a whole number of SIMD vectors per device."""
    lanes = max(1, VECTOR_BYTES // np.dtype(dtype).itemsize)
    return -(-n // (n_devices * lanes)) * n_devices * lanes


def batch_mesh(local: bool = False) -> Mesh:
    """A 1-D mesh with the single axis `"batch"`: over all devices, or with `local`
    over this process's own (under `jax.distributed`, chunks computed by one process)."""
    return Mesh(np.asarray(jax.local_devices() if local else jax.devices()), (BATCH_AXIS,))


def device_count(mesh: Mesh) -> int:
    return int(mesh.devices.size)


def _run_chunk(
    flat: Params,
    zhw: jax.Array,
    dynamics: AbstractDynamics,
    contact: str,
    start: str,
    max_steps: int,
    mesh: Mesh,
    micro_batch: int | None,
) -> dict[str, jax.Array]:
    # Runs only while tracing: counts compilations, not calls.
    TRACES["run_chunk"] += 1

    def local(p: Params, zhw: jax.Array, dyn: AbstractDynamics) -> dict[str, jax.Array]:
        z, horizon, window = zhw[0], zhw[1], zhw[2]
        wave = Sinusoid.from_params(p)
        if isinstance(dyn, Exact):
            # A work queue over `micro_batch` lanes (`_queue`): a lane whose
            # configuration is done takes the next one.
            return exact_batch(p, wave, 0, z, horizon, window, contact, start, dyn.dt, max_steps, lanes=micro_batch)
        from ..dynamics._smooth import measure_one

        assert isinstance(dyn, Smoothed)  # `sweep` accepts Exact or Smoothed
        one = lambda q, w: measure_one(q, w, z, horizon, window, contact, start, dyn)
        if not micro_batch or micro_batch >= p.omega.shape[0]:
            return jax.vmap(one)(p, wave)
        # Sub-batches in sequence, each vmapped: a sub-batch's while_loop stops with
        # its own slowest configuration, and its state stays in cache.
        return jax.lax.map(lambda args: one(*args), (p, wave), batch_size=micro_batch)

    if isinstance(dynamics, Smoothed):
        # diffrax's closure conversion rejects shard_map's per-device types, so the
        # smoothed model is left to jit's automatic partitioning of the sharded batch
        # (correct, but every device iterates until the slowest configuration is done).
        return local(flat, zhw, dynamics)
    # check_vma=False: the integrator's while_loop carries mix per-shard and
    # replicated values, which the varying-manual-axes checker rejects.
    sharded = jax.shard_map(
        local, mesh=mesh, in_specs=(P(BATCH_AXIS), P(), P()), out_specs=P(BATCH_AXIS), check_vma=False
    )
    return sharded(flat, zhw, dynamics)


_run_chunk = engine_jit(_run_chunk, ("contact", "start", "max_steps", "mesh", "micro_batch"))


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
    max_steps: int,
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
    - `max_steps`: the step cap (static: fix it once per sweep so all chunks share one compilation).
    - `mesh`: from [`batch_mesh`][].
    - `micro_batch`: configurations vmapped together per device (default [`MICRO_BATCH`][]: all).

    **Returns:** a dict of sharded arrays (one per `Measurement` field); read them with [`fetch`][].
    """
    return _run_chunk(
        *_chunk_args(values, dtype, z, horizon, window, dynamics, contact, start, max_steps, mesh, micro_batch)
    )


def chunk_dtypes(
    values: Mapping[str, np.ndarray],
    dtype: np.dtype,
    z: float,
    horizon: float,
    window: float,
    dynamics: AbstractDynamics,
    contact: str,
    start: str,
    max_steps: int,
    mesh: Mesh,
    micro_batch: int | None = None,
) -> dict[str, np.dtype]:
    """The dtype of each output of [`dispatch_chunk`][] for the same arguments, computed
    without running it (the trace is kept by `jax.jit`: the chunks do not trace again)."""
    args = _chunk_args(values, dtype, z, horizon, window, dynamics, contact, start, max_steps, mesh, micro_batch)
    # `_run_chunk` is the `jax.jit` wrapper (reassigned above), which has `eval_shape`.
    out = _run_chunk.eval_shape(*args)  # pyright: ignore[reportFunctionMemberAccess]
    return {k: np.dtype(v.dtype) for k, v in out.items()}


def _chunk_args(values, dtype, z, horizon, window, dynamics, contact, start, max_steps, mesh, micro_batch) -> tuple:
    sharding = NamedSharding(mesh, P(BATCH_AXIS))
    fields = {n: _global_array(np.asarray(values[n], dtype), sharding) for n in PARAM_NAMES}
    flat = Params(**fields, check=False)
    zhw = jnp.asarray(np.asarray([z, horizon, window], dtype))
    if isinstance(dynamics, Smoothed):
        dynamics = eqx.tree_at(lambda d: d.eps, dynamics, jnp.asarray(dynamics.eps, dtype))
    return flat, zhw, dynamics, contact, start, max_steps, mesh, micro_batch or MICRO_BATCH or None


def fetch(out: Mapping[str, jax.Array], n: int) -> dict[str, np.ndarray]:
    """Block on a dispatched chunk and copy its first `n` (unpadded) entries to the host."""
    return {k: _to_host(v)[:n] for k, v in out.items()}
