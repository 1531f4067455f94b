"""Input preparation shared by the front ends: argument types, dtype, batching, validity.

Library functions handle one configuration; this module flattens the batch
shape, applies one `vmap`, and restores the shape.
"""

import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from .._results import PAPER
from ..dynamics._base import AbstractDynamics
from ..dynamics._exact_dynamics import Exact
from ..dynamics._flat import FlatBatch
from ..dynamics._forward import check_static, concrete_value
from ..model._checks import is_concrete
from ..model._mechanism import AbstractMechanism
from ..model._params import Params
from ..model._waveform import AbstractWaveform, Sinusoid


def dynamics_arg(dynamics: Any) -> AbstractDynamics:
    """The `dynamics=` argument of a front end: [`Exact`][] by default, else an [`AbstractDynamics`][]."""
    if dynamics is None:
        return Exact()
    if not isinstance(dynamics, AbstractDynamics):
        raise TypeError(
            "dynamics must be an AbstractDynamics (Exact(), Smoothed() or a subclass of your own), "
            f"got {type(dynamics).__name__}."
        )
    return dynamics


def mechanism_arg(params: Any) -> AbstractMechanism:
    """The mechanism argument of a front end: a [`Params`][] or a [`Chain`][]."""
    if not isinstance(params, AbstractMechanism):
        raise TypeError(f"params must be a locomotion_jax.Params, Chain or Mechanism, got {type(params).__name__}.")
    return params


def prepare(params: Params, waveform: AbstractWaveform | None, dtype: Any):
    """Cast, broadcast and flatten; returns `(flat_params, flat_wave, wave_axes, shape)`.

    A waveform whose `omega` carries the params' batch shape is batched with
    them; otherwise it is shared by every configuration. A `waveform` whose values are
    known here is validated (`AbstractWaveform.validate`: `ValueError` naming the field
    and its valid range); under `jit` the engines flag an invalid one `Status.INVALID`.
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
        if is_concrete(waveform):
            waveform.validate()  # under `jit` an invalid waveform is flagged INVALID instead (`safe_params`)
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


INITIAL_NAMES = ("x1", "v1", "x2", "v2")


def prepare_initial(initial: Any, shape: tuple[int, ...], dtype: Any) -> jax.Array | None:
    """An initial state `(x1, v1, x2, v2)` (each broadcastable to the batch `shape`) as a
    flat `(size, 4)` array, or `None`. Raises a `ValueError` where its values are known
    here (not under `jit`) and a position or velocity is not finite or `x1 >= x2`; under
    `jit` such a configuration is flagged `INVALID` in its own result (`_runs.chain_initial_state`)."""
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
    values = _known_finite(state)
    if values is not None and np.any(values[:, 0] >= values[:, 2]):
        raise ValueError("initial: the masses must be in order, x1 < x2 (eq. 2 measures x2 - x1 > 0).")
    return state


def _known_finite(state: jax.Array) -> np.ndarray | None:
    """The values of an initial state where they are known here (`None` under `jit`), refused
    with a `ValueError` if one is not finite."""
    try:
        values = np.asarray(concrete_value(state))
    except (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError, TypeError):
        return None
    if values.dtype.kind != "f":  # a tracer of `jit` beneath: the values are not known here
        return None
    if not np.all(np.isfinite(values)):
        raise ValueError("initial: every position and velocity must be finite.")
    return values


def prepare_chain_initial(
    initial: Any, shape: tuple[int, ...], n_bodies: int, dtype: Any, mechanism: Any = None
) -> jax.Array | None:
    """A chain's or a mechanism's initial state `(x, v)` (positions and velocities, each a
    scalar or an array whose last axis has length N, broadcastable to `shape + (N,)`) as a flat
    `(size, 2N)` array, or `None`. Raises a
    `ValueError` where its values are known here (not under `jit`) and one is not finite or a
    gap that must stay positive is not (`AbstractPhysics.gaps` of the flat `mechanism`'s
    physics; a chain's: its positions in increasing order; `mechanism=None`: a chain's); under
    `jit` such a configuration is flagged `INVALID` in its own result (`_runs.chain_initial_state`)."""
    if initial is None:
        return None
    if not isinstance(initial, (tuple, list)) or len(initial) != 2:
        raise TypeError(
            f"initial for a Chain must be a tuple (x, v) of positions and velocities, got {type(initial).__name__}."
        )
    size = math.prod(shape)
    flat = []
    for name, value in zip(("x", "v"), initial):
        arr = jnp.asarray(value, dtype)
        if arr.ndim >= 1 and arr.shape[-1] != n_bodies:  # one value for all is a scalar, not a length-1 axis
            raise ValueError(
                f"initial {name} has shape {arr.shape}, which does not broadcast to one value per mass: its last "
                f"axis must have length {n_bodies} (or give a scalar for all)."
            )
        try:
            arr = jnp.broadcast_to(arr, shape + (n_bodies,))
        except ValueError:
            raise ValueError(
                f"initial {name} has shape {arr.shape}, which does not broadcast to {shape + (n_bodies,)} "
                f"(the batch shape and one value per mass)."
            ) from None
        flat.append(arr.reshape((size, n_bodies)))
    state = jnp.concatenate(flat, -1)
    values = _known_finite(state)
    if values is None:
        bad = np.empty((0, 2))
    elif mechanism is None:
        bad = np.argwhere(np.diff(values[:, :n_bodies], axis=-1) <= 0)
    else:
        gaps = mechanism.physics().gaps(tuple(jnp.asarray(values[:, i]) for i in range(n_bodies)))
        bad = np.argwhere(np.stack([np.asarray(g) <= 0 for g in gaps], -1)) if gaps else np.empty((0, 2))
    if bad.size:
        j = int(bad[0][1])
        raise ValueError(f"initial: the masses must be in order along the chain, x_{j} < x_{j + 1} (mass {j}).")
    return state


def check_hop_dynamics(contact: str, dynamics: AbstractDynamics) -> None:
    """`contact="hop"` runs on the dynamics that locate lift-off and landing ([`Exact`][]); elsewhere
    it raises `NotImplementedError`."""
    if contact == "hop" and not isinstance(dynamics, Exact):
        raise NotImplementedError(f"contact='hop' runs with Exact dynamics only, got {type(dynamics).__name__}.")


def check_contact_start(contact: str, start: str, mechanism: AbstractMechanism) -> None:
    """Validate `contact` and `start`. Under `contact="hop"`, refuse what `mechanism` (a
    [`Chain`][locomotion_jax.Chain] or a [`Mechanism`][locomotion_jax.Mechanism]) has that flight and
    landing do not support (its `check_hop`: a `NotImplementedError`)."""
    if contact == "hop":
        mechanism.check_hop()
    if contact not in ("strict", "paper", "hop"):
        raise ValueError(f"contact must be 'strict', 'paper' or 'hop', got {contact!r}.")
    if start not in ("paper", "relaxed"):
        raise ValueError(f"start must be 'paper' (eq. 14) or 'relaxed', got {start!r}.")


def prepare_chain(chain: Any, dtype: Any) -> tuple[Any, jax.Array, tuple[int, ...]]:
    """Cast, broadcast and flatten a [`Chain`][] or any mechanism of the N-body path (a
    [`Mechanism`][locomotion_jax.Mechanism]: `astype`, `broadcast`, `batch_shape`, `is_valid`
    and `physics`); returns `(flat, valid, batch_shape)`.

    An invalid configuration is replaced by a valid one of the batch (so nothing
    turns into NaN) and flagged in `valid`; its result says `Status.INVALID`.
    """
    if not isinstance(chain, AbstractMechanism):
        raise TypeError(f"expected a locomotion_jax.Chain or Mechanism, got {type(chain).__name__}.")
    mech: Any = chain
    if dtype is not None:
        mech = mech.astype(dtype)
    chain = mech.broadcast()
    shape = chain.batch_shape
    size = math.prod(shape)
    if size == 0:
        raise ValueError(f"the {type(chain).__name__} batch is empty (a zero-length axis).")
    nb = len(shape)
    flat = jax.tree_util.tree_map(lambda x: x.reshape((size,) + x.shape[nb:]), chain)
    valid = flat.is_valid()
    try:
        ok = np.asarray(valid)
        fallback = int(np.argmax(ok)) if ok.any() else 0
    except (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError):
        fallback = 0  # under `jit`: the first configuration (an invalid one only runs flagged)
    pick = lambda x: jnp.where(valid.reshape((size,) + (1,) * (x.ndim - 1)), x, x[fallback])
    return jax.tree_util.tree_map(pick, flat), valid, shape


def start_times(t_start: Any, shape: tuple[int, ...], dtype: Any) -> jax.Array | None:
    """Explicit measurement starts, broadcast to the batch and flattened (`None`: each configuration's own)."""
    if t_start is None:
        return None
    check_static("t_start", t_start)
    ts = np.broadcast_to(np.asarray(t_start, float), shape)
    if not np.all(np.isfinite(ts)) or np.any(ts < 0):
        raise ValueError(f"t_start must be finite and >= 0, got {t_start!r}.")
    return jnp.asarray(ts.reshape((-1,)), dtype)


def params_batch(params: Params, dynamics: AbstractDynamics, waveform: Any, dtype: Any, t_start: Any,
                 initial: Any, measuring: bool) -> tuple[FlatBatch, Any, tuple[int, ...]]:  # fmt: skip
    """[`Params.flat_batch`][locomotion_jax.Params.flat_batch]: the paper's model, actuated by
    `waveform` (default the sinusoid of eq. 13), with its initial states `(x1, v1, x2, v2)`."""
    from ._resolution import _flat, guard_two_mass

    flat, wave, axes, shape = prepare(params, waveform, dtype)
    ts = start_times(t_start, shape, flat.dtype)
    flat, unresolved = guard_two_mass(dynamics, flat, wave, shape, default_start=measuring and ts is None)
    y0 = prepare_initial(initial, shape, flat.dtype)
    y0 = None if y0 is None else y0[:, jnp.asarray((0, 2, 1, 3))]  # positions, then velocities
    valid = flat.is_valid() & _flat(wave.is_valid(), flat.batch_shape[0])
    batch = FlatBatch(flat, valid, wave=wave, t_start=ts, initial=y0, wave_axes=axes, names=PAPER)
    return batch, unresolved, shape


def bodies_batch(mechanism: Any, dynamics: AbstractDynamics, waveform: Any, dtype: Any, t_start: Any,
                 initial: Any, measuring: bool, contact: str, start: str
                 ) -> tuple[FlatBatch, Any, tuple[int, ...]]:  # fmt: skip
    """`flat_batch` of a mechanism of the N-body path ([`Chain`][], [`Mechanism`][locomotion_jax.Mechanism]),
    which carries its own waveforms, with its initial states `(x, v)`."""
    from ._resolution import guard_chain

    if waveform is not None:
        raise ValueError(
            f"waveform= applies to Params; a {type(mechanism).__name__} carries its own waveforms (springs or links)."
        )
    check_contact_start(contact, start, mechanism)
    flat, valid, shape = prepare_chain(mechanism, dtype)
    ts = start_times(t_start, shape, flat.dtype)  # checked on the host, as for the paper's model
    valid, unresolved = guard_chain(dynamics, flat, valid, shape, default_start=measuring and ts is None)
    y0 = prepare_chain_initial(initial, shape, flat.n_masses, flat.dtype, flat)
    return FlatBatch(flat, valid, t_start=ts, initial=y0), unresolved, shape
