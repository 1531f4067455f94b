"""Checks at the model's boundary shared by its classes: real input, named shapes, named ranges.

Each class states its constraints as `(name, valid mask, valid range)` triples (finite
values first, so that a NaN is reported as the parameter that holds it, not as a
relation it breaks); [`first_invalid`][] turns the first violated one into the
message, the same for parameters, friction laws and waveforms.
"""

import re
from collections.abc import Mapping, Sequence
from typing import Any

import jax
import jax.core  # (jax.core.Tracer) for type checkers
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array


Check = tuple[str, Array, str]
"""`(parameter name, mask of valid values, human-readable valid range)`."""


def real_array(name: str, value: Any, owner: str = "") -> Array:
    """`value` as a floating array (integers promoted to the default float).

    **Raises:** `ValueError` naming the parameter (and `owner`, e.g. `"Sinusoid"`) for
    complex, boolean or non-numeric input: an imaginary part would be dropped silently.
    """
    of = f" of {owner}" if owner else ""
    try:
        arr = jnp.asarray(value)
    except (TypeError, ValueError):
        raise ValueError(
            f"Invalid parameter {name!r}{of}: expected a real number or an array of real numbers, got {value!r}."
        ) from None
    if jnp.issubdtype(arr.dtype, jnp.floating):
        return arr
    if jnp.issubdtype(arr.dtype, jnp.integer):
        return arr.astype(jnp.result_type(float))
    raise ValueError(
        f"Invalid parameter {name!r}{of}: expected real numbers, got {value!r} of dtype {arr.dtype} "
        "(complex, boolean and text values are refused)."
    )


def broadcast_shape(shapes: Mapping[str, tuple[int, ...]], what: str = "batch") -> tuple[int, ...]:
    """The common broadcast shape of named arrays' shapes.

    **Raises:** `ValueError` naming two parameters whose shapes do not broadcast.
    """
    try:
        return tuple(np.broadcast_shapes(*shapes.values()))
    except ValueError:
        pass
    names = list(shapes)
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            try:
                np.broadcast_shapes(shapes[a], shapes[b])
            except ValueError:
                raise ValueError(
                    f"Parameters {a!r} (shape {shapes[a]}) and {b!r} (shape {shapes[b]}) do not broadcast to one "
                    f"{what} shape; give arrays of equal lengths, or use Params.grid for an outer product."
                ) from None
    raise ValueError(f"The {what} shapes do not broadcast together: {dict(shapes)}.")


def is_concrete(tree: Any) -> bool:
    """Whether every array leaf of `tree` holds known values (no tracer of `jit` or `vmap`)."""
    return not any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(tree))


def all_valid(checks: Sequence[Check], shape: tuple[int, ...]) -> Array:
    """Traceable mask of shape `shape`: every check holds."""
    ok = jnp.ones(shape, bool)
    for _, mask, _ in checks:
        ok = ok & jnp.broadcast_to(mask, shape)
    return ok


def related(name: str, valid: str, values: Mapping[str, Any]) -> list[str]:
    """The other parameters that a valid range such as `"mu_s >= mu_k"` or `"|d_j| < lbar_j"` names,
    so that a message can show their values too (per-index suffixes `_i`, `_j` dropped)."""
    out = []
    for token in re.findall(r"[A-Za-z_]\w*", valid):
        base = re.sub(r"_[ij]$", "", token)
        if base != name and base in values and base not in out:
            out.append(base)
    return out


def first_invalid(owner: str, checks: Sequence[Check], values: Mapping[str, Any]) -> None:
    """Raise `ValueError` for the first check that fails for concrete values of one configuration
    (or a batch): `"Invalid parameter 'phi' of TravellingWave[ at batch index (2,)]: got phi=nan;
    the valid range is finite."`, with the values of the parameters the range relates to."""
    for name, mask, valid in checks:
        bad = ~np.asarray(mask)
        if not bad.any():
            continue
        where = tuple(int(i) for i in np.argwhere(bad)[0]) if bad.ndim else ()
        at = f" at batch index {where}" if where else ""
        got = []
        for n in (name, *related(name, valid, values)):
            v = _at(np.asarray(values[n]), bad.shape, where)
            got.append(f"{n}={v.item()!r}" if v.ndim == 0 else f"{n}={v.tolist()!r}")
        got_s = ", ".join(got)
        raise ValueError(f"Invalid parameter {name!r} of {owner}{at}: got {got_s}; the valid range is {valid}.")


def _at(v: np.ndarray, shape: tuple[int, ...], where: tuple[int, ...]) -> np.ndarray:
    """The value of one configuration: `v`'s leading axes are the batch axes `shape` (broadcast),
    or `v` is shared by the batch (a coefficient vector without batch axes)."""
    if not where:
        return v
    try:
        full = np.broadcast_to(v, shape + v.shape[len(shape) :])
    except ValueError:
        full = np.broadcast_to(v, shape + v.shape)
    return full[where]
