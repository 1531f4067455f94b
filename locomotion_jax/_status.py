"""Per-configuration status codes and the locomotion regime.

Failures of one configuration are recorded here, never raised, so that one bad
configuration in a batch cannot poison the others (compare diffrax `RESULTS`).
Plain integer codes are used instead of `eqx.Enumeration` because results are
exported as labelled arrays (xarray/NetCDF), where integers travel unchanged.
"""

import enum

import jax.numpy as jnp

from ._custom_types import Array


class Status(enum.IntEnum):
    """Outcome of one simulated configuration.

    - `OK`: integrated to the requested end.
    - `LIFTOFF`: a normal force reached zero (eq. 5) under the strict contact
      reading; the run stopped at the located lift-off time.
    - `MAX_STEPS`: the hard cap on integrator iterations was hit (the horizon was
      not reached); results cover the part that was integrated.
    - `INVALID`: the parameters are outside the model's valid range; nothing
      was integrated and every measurement holds its sentinel.
    - `SOLVER_FAILED`: the smoothed (diffrax) solver reported a failure, or the exact engine's
      state left the floating-point range (a spring stretched by $10^{300}$: its energy
      overflows); a trajectory's saves from there are not `valid`.
    - `COLLISION`: two neighbouring bodies met, a gap $x_{j+1} - x_j$ (two masses:
      $x_2 - x_1$) reached zero, which the model does not cover (the masses would pass
      through each other). The exact engines check every committed step's end and stop
      the run there (not located in time: the step that closed the gap is kept, so the
      last state has a gap $\\le 0$); the smoothed dynamics locate the gap's zero as a
      terminating event. Results cover the part that was integrated. Under `contact="hop"`
      the same holds for bodies in flight, whatever their heights: SPEC §10 gives the bodies
      heights but no shape, so their order on the line stays part of the model (docs/model.md).
      A mechanism's horizontal tilted spring ($d = 0$) keeps its ends apart in the same way
      ([`TiltedSpring`][locomotion_jax.TiltedSpring]).
    - `UNRESOLVED`: the fixed step of [`Exact`][locomotion_jax.Exact] dynamics is too long for
      one of the configuration's time scales (the forcing's highest harmonic, a natural
      period, a damping or Stribeck time; docs/engines.md, "Resolution guards"); nothing
      was integrated and every measurement holds its sentinel, as for `INVALID`. Also a
      measurement whose default start (`t_start` not given) would take more than
      `MAX_START_STEPS` steps (a very soft spring). During a run of the exact engine: a step
      in which a mechanism's tilted spring's ends passed each other while its extension moved more
      than half its vertical offset $|d|$, the width over which its force turns over (a near-kink,
      [`AbstractPhysics.kinks`][locomotion_jax.AbstractPhysics.kinks]); the run stops after that
      step and results cover the part that was integrated.
    """

    OK = 0
    LIFTOFF = 1
    MAX_STEPS = 2
    INVALID = 3
    SOLVER_FAILED = 4
    COLLISION = 5
    UNRESOLVED = 6


class Regime(enum.IntEnum):
    """Locomotion regime by the paper's window rule (Sect. 3).

    `SSL` (stick-slip locomotion): a mass is stuck for an interval of positive
    length inside the window $[t_\\text{start}, t_\\text{start} + \\Delta\\tau]$;
    `SL` (slip locomotion) otherwise; `UNDETERMINED` when the run stopped
    (lift-off, step cap, invalid input) before the window ended.
    """

    UNDETERMINED = -1
    SL = 0
    SSL = 1


class Mode(enum.IntEnum):
    """The paper's four contact modes (Sect. 2.2)."""

    BOTH_STICK = 0
    BOTH_SLIP = 1
    M1_SLIPS = 2
    M2_SLIPS = 3


def mode_code(stuck1: Array, stuck2: Array) -> Array:
    """Sect. 2.2 modes: 0 both stick, 1 both slip, 2 m1 slips, 3 m2 slips."""
    return jnp.where(stuck1, jnp.where(stuck2, 0, 3), jnp.where(stuck2, 2, 1)).astype(jnp.int32)
