"""Margins to a change of switching structure, as the front ends report them.

The engines record, in squared radians of drive phase, how close a run came to a
change of its switching structure (`_engine` module docstring, "Margins"); these
functions turn those records into the result fields of `measure` and `simulate`.
The target's margin is relative to `tau_z` instead: a switch that meets $t_z$ is not
locked to the drive as the switches are to each other, and $t_z$ moves by about
$\\tau_z$ times a relative change of a parameter (its logarithmic sensitivity is of
order one), so `margin_z` estimates the relative change that reaches it.
"""

import jax
import jax.numpy as jnp

from .._custom_types import Array


def margin_fields(
    started: Array, reached: Array, cross: Array, near: Array, gap: Array, tau: Array, nan: Array
) -> dict[str, Array]:
    """`transversality`, `near_miss` (radians, from the squared phases) and `margin_z` (the
    time `gap` from $t_z$ to the nearest change of structure, relative to `tau` $= \\tau_z$)
    of a measurement; NaN where it did not start, `margin_z` 0 where `z` was not reached
    (`tau_z = inf` has no derivative). Values only, like the records (no derivative: `gap` may be
    `inf`, whose product with a zero cotangent would be NaN in reverse mode)."""
    root = lambda m: jnp.where(started, jnp.sqrt(m), nan)
    tau = jax.lax.stop_gradient(tau)
    rel = jnp.where(reached, gap / jnp.where(reached & (tau > 0), tau, 1), 0)
    return dict(transversality=root(cross), near_miss=root(near), margin_z=jnp.where(started, rel, nan))


def switch_gap(omega: Array, t: Array, t_switch: Array) -> Array:
    """Drive phase between each save time `t` and the nearest located switch, from the time
    of the last switch at each save (`t_switch`; last axis: saves; `omega`: one per row).

    The first switch after save $i$ is the last one at save $i + 1$ if that is later than
    $t_i$; otherwise none falls before $t_{i+1}$, which then bounds the gap (as the end
    of the run does for the last save). Values only (no derivative: the gap may be `inf`)."""
    omega = jax.lax.stop_gradient(omega)
    later = jnp.concatenate([t_switch[..., 1:], jnp.full_like(t_switch[..., :1], jnp.inf)], -1)
    t_next = jnp.concatenate([t[..., 1:], jnp.full_like(t[..., :1], jnp.inf)], -1)
    after = jnp.where(later > t, later, t_next) - t
    return omega[..., None] * jnp.minimum(t - t_switch, after)
