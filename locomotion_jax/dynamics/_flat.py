"""`FlatBatch`: what a front end hands a dynamics, for any mechanism.

The front ends check, cast, broadcast and flatten the mechanism they are given (each
mechanism does its own part: `AbstractMechanism.flat_batch`) and pass the dynamics one
`FlatBatch`; the dynamics' `simulate` and `measure` take it whatever the mechanism, so neither
the front ends nor the interface of a dynamics name a kind of mechanism. Inside a dynamics, the
paper's model (whose actuation is given apart from its parameters, `wave`) still runs through
its own translation layer (`_paper` for `Exact`, the two-mass physics for `Smoothed`).
"""

from typing import Any

import equinox as eqx

from .._custom_types import Array
from .._results import BODIES
from ..model._waveform import AbstractWaveform


class FlatBatch(eqx.Module):
    """A flat batch of `n` configurations of one mechanism (every array field with a leading axis of
    `n`), as the front ends hand it to [`AbstractDynamics`][locomotion_jax.AbstractDynamics].

    - `mechanism`: the configurations, batch shape `(n,)` (a [`Params`][locomotion_jax.Params], a
      [`Chain`][locomotion_jax.Chain], a [`Mechanism`][locomotion_jax.Mechanism]); its `physics()` is
      what the engines integrate.
    - `valid`: which configurations run, shape `(n,)`; the others are flagged `Status.INVALID` in
      their own results. A chain's invalid configurations have been replaced by a valid one of the
      batch (so nothing turns into NaN); the paper's model's invalid ones carry NaN, which its
      engines replace themselves (`safe_params`).
    - `wave`, `wave_axes`: the paper's model's actuation $\\ell_0(t)$, batched along its leading axis
      if `wave_axes == 0`, shared if `None`; `None` for a mechanism that carries its own.
    - `t_start`: the measurement's start per configuration, shape `(n,)`, or `None` for each
      configuration's own (`Params.t_start`, `Chain.t_start`).
    - `initial`: the states at $t = 0$, shape `(n, 2N)` (positions, then velocities), or `None`
      for the `start` position at rest.
    - `names`: how the results name their arrays (`Trajectory.names`).
    """

    mechanism: Any
    valid: Array
    wave: AbstractWaveform | None = None
    t_start: Array | None = None
    initial: Array | None = None
    wave_axes: int | None = eqx.field(static=True, default=None)
    names: str = eqx.field(static=True, default=BODIES)

    def own_batch(self) -> "FlatBatch":
        """This batch as it stands (as `AbstractMechanism.own_batch` hands a sweep's chunk)."""
        return self

    @property
    def size(self) -> int:
        """The number of configurations `n`."""
        return self.valid.shape[0]

    @property
    def dtype(self) -> Any:
        """The configurations' floating dtype."""
        return self.mechanism.dtype
