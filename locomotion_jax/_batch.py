"""Input preparation shared by `simulate` and `measure`: dtype, batching, validity.

Library functions handle one configuration; this module flattens the batch
shape, applies one `vmap`, and restores the shape.
"""

import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ._actuation import AbstractWaveform, Sinusoid
from ._params import DEFAULTS, PARAM_NAMES, Params


def prepare(params: Params, waveform: AbstractWaveform | None, dtype: Any):
    """Cast, broadcast and flatten; returns `(flat_params, flat_wave, wave_axes, shape)`.

    A waveform whose `omega` carries the params' batch shape is batched with
    them; otherwise it is shared by every configuration.
    """
    if not isinstance(params, Params):
        raise TypeError(f"params must be a locomotion_jax.Params, got {type(params).__name__}.")
    if dtype is not None:
        params = params.astype(dtype)
    params = params.broadcast()
    shape = params.batch_shape
    size = math.prod(shape)
    if size == 0:
        raise ValueError("params has an empty batch (a zero-length axis).")
    flat = jax.tree_util.tree_map(lambda x: x.reshape((size,)), params)
    dt = params.dtype
    if waveform is None:
        wave, axes = Sinusoid.from_params(flat), 0
    else:
        if not isinstance(waveform, AbstractWaveform):
            raise TypeError(f"waveform must be an AbstractWaveform, got {type(waveform).__name__}.")
        waveform = jax.tree_util.tree_map(lambda x: jnp.asarray(x, dt), waveform)
        if shape and jnp.shape(waveform.omega) == shape:
            nb = len(shape)
            wave = jax.tree_util.tree_map(lambda x: x.reshape((size,) + x.shape[nb:]), waveform)
            axes = 0
        else:
            wave, axes = waveform, None
    return flat, wave, axes, shape


def safe_params(params: Params) -> tuple[Params, jax.Array]:
    """Replace an invalid configuration by the defaults (so nothing becomes NaN) and
    return the validity flag; the caller marks it `Status.INVALID` and skips it."""
    valid = params.is_valid()
    values = {
        n: jnp.where(valid, getattr(params, n), jnp.asarray(DEFAULTS[n], params.dtype)) for n in PARAM_NAMES
    }
    return Params(**values, check=False), valid


def unflatten(tree: Any, shape: tuple[int, ...]) -> Any:
    """Restore the batch shape on the leading axis of every array leaf."""
    return jax.tree_util.tree_map(lambda x: x.reshape(shape + x.shape[1:]), tree)


def horizon_bound(params: Params, t_extra: float) -> float:
    """Host-side bound on the simulated time, for the default step cap."""
    try:
        ts = np.asarray(params.t_start)
        tmax = float(np.nanmax(np.where(np.isfinite(ts), ts, 0.0)))
    except jax.errors.ConcretizationTypeError:
        tmax = 80 * 2 * math.pi / 5.0
    return tmax + t_extra


MICRO_BATCH_CPU = 64
"""Configurations per `while_loop` on a CPU (see [`map_batched`][])."""


def map_batched(fn, params: Params, wave: AbstractWaveform, wave_axes, size: int | None = None):
    """`vmap(fn)(params, wave)`, run on a CPU as a sequence of 64-wide sub-batches (`lax.map`).

    Each sub-batch's integration loop stops with its own slowest configuration, and
    its state (a few hundred arrays of 64 scalars) stays in the core's cache: on the
    CPU this runs the exact engine 2x faster than one wide `vmap` (benchmarks/NOTES.md).
    Other backends (GPU) take the whole batch at once. `size` overrides the width.
    Configurations are grouped by `omega` (similar rates of mode switches) and the
    batch is padded to a whole number of sub-batches, so the loop body is compiled once.
    """
    n = params.omega.shape[0]
    mb = size if size is not None else (MICRO_BATCH_CPU if jax.default_backend() == "cpu" else None)
    if not mb or n <= mb:
        return jax.vmap(fn, in_axes=(0, wave_axes))(params, wave)
    # Neighbours in frequency switch modes at similar rates: sorting by omega groups
    # similar costs into the same sub-batch (a gather; results are put back in order).
    order = jnp.argsort(jnp.where(jnp.isfinite(params.omega), params.omega, jnp.inf))
    k = -(-n // mb)
    idx = jnp.concatenate([order, jnp.repeat(order[-1:], k * mb - n)]).reshape(k, mb)
    take = lambda x: x[idx]
    sub = lambda p, w: jax.vmap(fn, in_axes=(0, wave_axes))(p, w)
    if wave_axes is None:
        out = jax.lax.map(lambda p: sub(p, wave), jax.tree_util.tree_map(take, params))
    else:
        out = jax.lax.map(lambda a: sub(*a), jax.tree_util.tree_map(take, (params, wave)))
    inv = jnp.zeros(n, order.dtype).at[order].set(jnp.arange(n, dtype=order.dtype))
    return jax.tree_util.tree_map(lambda x: x.reshape((k * mb,) + x.shape[2:])[inv], out)


def default_max_steps(t_total: float, dt: float) -> int:
    """Room for the nominal steps plus the event searches (a hard cap, not a cost)."""
    return int(3 * t_total / dt) + 20_000
