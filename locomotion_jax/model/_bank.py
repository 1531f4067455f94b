"""Waveforms of any classes as one bank of signals over a trailing axis, for the array layouts.

The array layouts (`_chain_array`, `_mechanism_array`) read their Fourier signals by one
angle-addition recurrence over a padded table of coefficients. Every other waveform (a
[`Spline`][locomotion_jax.Spline], a waveform class of the user's own) goes into a
[`WaveBank`][]: waveforms of one structure (one class, the same leaf shapes: splines of one number
of control values, say) form a group whose leaves are stacked along a new signal axis, so a group
costs one evaluation whatever its size, and each group's values are scattered to its rows of the
bank by static indices. The program grows with the number of groups, not of signals.
"""

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp

from .._custom_types import Array
from ._waveform import AbstractWaveform


class WaveBank(eqx.Module):
    """`size` signals, some of them driven by the waveforms of `groups` (module docstring): group `g`
    holds the waveforms of rows `rows[g]`, its leaves stacked along the axis after the batch axes.

    Read one configuration at a time (under the engine's `vmap`), where that axis is each leaf's
    first: a group is evaluated by `vmap` of its class's own `at_phase`, so any waveform that reads
    one configuration reads a group."""

    groups: tuple[AbstractWaveform, ...]
    rows: tuple[tuple[int, ...], ...] = eqx.field(static=True)
    size: int = eqx.field(static=True)

    def _place(self, parts: list[Array], base: Array | None) -> Array:
        """The groups' values in their rows, added to `base` (zero elsewhere without one)."""
        if base is None and len(parts) == 1 and self.rows[0] == tuple(range(self.size)):
            return parts[0]
        out = jnp.zeros(parts[0].shape[:-1] + (self.size,), parts[0].dtype) if base is None else base
        for rows, q in zip(self.rows, parts):
            out = out.at[..., jnp.asarray(rows)].add(q)
        return out

    def at_phase(
        self, c1: Array, s1: Array, base: tuple[Array, Array, Array] | None = None
    ) -> tuple[Array, Array, Array]:
        """Each row's signal with its first two time derivatives at the phase $(\\cos, \\sin)$ of
        one configuration, added to `base` (the other rows' signals) where given."""
        at = [jax.vmap(lambda w: w.at_phase(c1, s1))(g) for g in self.groups]
        parts = [[jnp.moveaxis(q[k], 0, -1) for q in at] for k in range(3)]
        return tuple(self._place(p, None if base is None else base[k]) for k, p in enumerate(parts))  # type: ignore[return-value]

    @property
    def lbar(self) -> Array:
        """Each row's mean `lbar` (zero in a row that no group drives)."""
        return self._place([g.lbar for g in self.groups], None)


def wave_bank(waves: dict[int, AbstractWaveform], size: int, batch: tuple[int, ...]) -> WaveBank:
    """The bank of `size` rows whose row `j` is driven by `waves[j]` (each broadcast to the batch
    shape `batch` and its own trailing axes): one group per structure, in order of first row."""
    groups: dict[Any, list[int]] = {}
    for j, w in waves.items():
        leaves, tree = jax.tree_util.tree_flatten(w)
        groups.setdefault((tree, tuple(jnp.shape(x) for x in leaves)), []).append(j)
    axis = len(batch)
    stack = lambda *xs: jnp.stack(xs, axis)
    return WaveBank(
        tuple(jax.tree_util.tree_map(stack, *[waves[j] for j in rows]) for rows in groups.values()),
        tuple(tuple(rows) for rows in groups.values()),
        size,
    )
