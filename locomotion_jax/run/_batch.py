"""Input preparation shared by `simulate` and `measure`: dtype, batching, validity.

Library functions handle one configuration; this module flattens the batch
shape, applies one `vmap`, and restores the shape.
"""

import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import Contact
from ..dynamics._forward import concrete_value
from ..model._params import Params
from ..model._waveform import AbstractWaveform, Sinusoid


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
        cast: AbstractWaveform = jax.tree_util.tree_map(lambda x: jnp.asarray(x, dt), waveform)
        if shape and jnp.shape(cast.omega) == shape:
            nb = len(shape)
            wave = jax.tree_util.tree_map(lambda x: x.reshape((size,) + x.shape[nb:]), cast)
            axes = 0
        else:
            wave, axes = cast, None
    return flat, wave, axes, shape


def unflatten(tree: Any, shape: tuple[int, ...]) -> Any:
    """Restore the batch shape on the leading axis of every array leaf."""
    return jax.tree_util.tree_map(lambda x: x.reshape(shape + x.shape[1:]), tree)


def horizon_bound(params: Params, t_extra: float) -> float:
    """Host-side bound on the simulated time, for the default step cap."""
    try:
        # Under jvp/vmap the bound comes from the values beneath the tracers.
        ts = np.asarray(concrete_value(params.t_start))
        tmax = float(np.nanmax(np.where(np.isfinite(ts), ts, 0.0)))
    except (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError):
        tmax = 80 * 2 * math.pi / 5.0
    return tmax + t_extra


MICRO_BATCH_CPU = 64
"""Lanes of the exact engine's loops on a CPU (the work queues of `measure` and
`simulate`). Above 64 elements per kernel XLA's CPU runtime splits every kernel
over its thread pool, which costs more than it gains for kernels this small
(benchmarks/NOTES.md, cost model 3)."""


def default_max_steps(t_total: float, dt: float) -> int:
    """Room for the nominal steps plus the event searches (a hard cap, not a cost)."""
    return int(3 * t_total / dt) + 20_000


INITIAL_NAMES = ("x1", "v1", "x2", "v2")


def prepare_initial(initial: Any, shape: tuple[int, ...], dtype: Any) -> jax.Array | None:
    """An initial state `(x1, v1, x2, v2)` (each broadcastable to the batch `shape`) as a
    flat `(size, 4)` array, or `None`. Raises a `ValueError` where its values are known
    here (not under `jit`) and a position or velocity is not finite or `x1 >= x2`; under
    `jit` such a configuration is flagged `INVALID` in its own result ([`initial_state`][])."""
    if initial is None:
        return None
    if not isinstance(initial, (tuple, list)) or len(initial) != 4:
        raise TypeError(f"initial must be a tuple (x1, v1, x2, v2) of arrays, got {type(initial).__name__}.")
    size = math.prod(shape)
    flat = []
    for name, value in zip(INITIAL_NAMES, initial):
        arr = jnp.asarray(value, dtype)
        try:
            arr = jnp.broadcast_to(arr, shape)
        except ValueError:
            raise ValueError(
                f"initial {name} has shape {arr.shape}, which does not broadcast to the batch shape {shape}."
            ) from None
        flat.append(arr.reshape((size,)))
    state = jnp.stack(flat, -1)
    try:
        values = np.asarray(concrete_value(state))
    except (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError, TypeError):
        return state
    if values.dtype.kind != "f":  # a tracer of `jit` beneath: the values are not known here
        return state
    if not np.all(np.isfinite(values)):
        raise ValueError("initial: every position and velocity must be finite.")
    if np.any(values[:, 0] >= values[:, 2]):
        raise ValueError("initial: the masses must be in order, x1 < x2 (eq. 2 measures x2 - x1 > 0).")
    return state


def initial_state(params: Params, wave: AbstractWaveform, contact: Contact, start: str, row: jax.Array | None):
    """The engine's state at $t = 0$ of one configuration: at rest in the `start` position,
    or the given `row` $(x_1, v_1, x_2, v_2)$; with the validity of `row` (an invalid one is
    replaced by the start, so that nothing turns NaN)."""
    from ..dynamics import _exact as exact
    from ..model import _two_mass as model

    dtype = params.dtype
    gap = model.initial_gap(params, start)
    if row is None:
        return exact.init(params, wave, contact, jnp.zeros((), dtype), gap), jnp.asarray(True)
    ok = jnp.all(jnp.isfinite(row)) & (row[0] < row[2])
    zero = jnp.zeros((), dtype)
    x1, v1, x2, v2 = (jnp.where(ok, r, d) for r, d in zip(row, (zero, zero, gap, zero)))
    return exact.init(params, wave, contact, x1, x2, v1, v2), ok
