"""Actuators of a chain's springs: how the actuation signal $s_j(t)$ enters (SPEC §8).

An actuator is a stateless strategy. It splits each spring's signal into a rest
length $\\ell_{0,j}$ and an internal force $f_j$ (the map is linear, so the rates of
the signal map the same way), and states the actuator's power, whose integral is
the work $w$ of eq. (16) generalised.
"""

import abc
from typing import ClassVar

import equinox as eqx

from .._custom_types import Array


class AbstractActuator(eqx.Module):
    """Base class of actuators (abstract/final pattern).

    `varies_rest_length` and `applies_force` say whether
    [`split`][locomotion_jax.AbstractActuator.split] moves the rest length and applies a
    force at all; where one is `False`, the exact engine takes the rest length
    $\\bar\\ell_j$ (or no force) and spends nothing on its rates.
    """

    varies_rest_length: ClassVar[bool] = True
    applies_force: ClassVar[bool] = True

    @abc.abstractmethod
    def split(self, lbar: Array, s: Array) -> tuple[Array, Array]:
        """Rest lengths $\\ell_{0,j}$ and internal forces $f_j$ for signal values `s`.

        Linear in `(lbar, s)`: the rates follow from `split(0, ds)`. Elementwise over
        springs: the engine calls it one spring at a time.
        """

    def power(self, tension: Array, dl0: Array, f: Array, v: Array) -> Array:
        """Power delivered, $\\sum_j -T_j \\dot\\ell_{0,j} + \\sum_j f_j (v_j - v_{j+1})$ (SPEC §8)."""
        return -(tension * dl0).sum(-1) + (f * (v[..., :-1] - v[..., 1:])).sum(-1)


class RestLength(AbstractActuator):
    """The paper's actuator (eq. 13): a prescribed rest length $\\ell_{0,j}(t) = \\bar\\ell_j + s_j(t)$."""

    applies_force: ClassVar[bool] = False

    def split(self, lbar: Array, s: Array) -> tuple[Array, Array]:
        return lbar + s, 0 * s


class InternalForce(AbstractActuator):
    """A prescribed internal force $f_j(t) = s_j(t)$ between masses $j$ and $j+1$.

    $+f_j$ acts on mass $j$ and $-f_j$ on mass $j+1$ (a positive force draws them
    together); the spring keeps its rest length $\\bar\\ell_j$. Models inchworm and
    capsule robots driven by an internal motor.
    """

    varies_rest_length: ClassVar[bool] = False

    def split(self, lbar: Array, s: Array) -> tuple[Array, Array]:
        return lbar + 0 * s, s
