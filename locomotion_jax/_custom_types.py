"""Type aliases shared across the package (jaxtyping, as in diffrax)."""

from collections.abc import Sequence
from typing import Literal, TypeAlias

import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int, Real


RealScalarLike: TypeAlias = Real[ArrayLike, ""] | float | int
FloatScalar: TypeAlias = Float[Array, ""]
BoolScalar: TypeAlias = Bool[Array, ""]
IntScalar: TypeAlias = Int[Array, ""]
State6: TypeAlias = Float[Array, "6"]
"""Hybrid-integrator state `(x1, v1, x2, v2, e_d, w)`: positions, velocities, and
the running dissipated energy (eq. 15) and actuator work (eq. 16)."""

ValuesLike: TypeAlias = ArrayLike | Sequence[float] | Sequence[Sequence[float]]
"""Per-mass or per-spring values: a scalar, an array, or a (nested) list of numbers."""

Contact: TypeAlias = Literal["strict", "paper", "hop"]
"""Normal-force reading: `"strict"` uses the signed $N_i$ of eq. (5) and stops at
lift-off; `"paper"` uses $n_i = |N_i|$ as eq. (6) prints, flagging lift-off; `"hop"`
(SPEC §10: flight and landing) is accepted as a value but not yet integrated: the front ends
refuse it with a `NotImplementedError`."""

Start: TypeAlias = Literal["paper", "relaxed"]
"""Initial condition: `"paper"` is eq. (14) ($x_2 - x_1 = \\bar\\ell$); `"relaxed"`
starts with the spring at rest length ($x_2 - x_1 = \\sqrt{\\bar\\ell^2 - d^2}$)."""

__all__ = [
    "Array",
    "ArrayLike",
    "Bool",
    "BoolScalar",
    "Contact",
    "Float",
    "FloatScalar",
    "Int",
    "IntScalar",
    "RealScalarLike",
    "Start",
    "State6",
    "ValuesLike",
    "np",
]
