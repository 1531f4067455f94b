"""Steady gaits of a chain under per-spring Fourier actuation, with exact sensitivities
(the chain optimiser's oracle): the decision vectors of chains and mechanisms, on the one
oracle of `_orbit` (its period map, Newton's method and implicit-function gradients).

The decision vector is
$\\theta = (A_{0,2}, \\dots, A_{0,H}, A_{1,1}, \\dots, A_{S-1,H}, B_{0,1}, \\dots, B_{S-1,H}, \\log\\omega)$:
the Fourier coefficients of the $S = N - 1$ springs' signals
$s_j(t) = a_\\max \\sum_n A_{jn}\\cos n\\omega t + B_{jn}\\sin n\\omega t$ ([`SpringFourier`][]),
in units of $a_\\max$, and the common base frequency. $A_{0,1} = 0$: a shift of the time
origin changes no gait, and fixing the phase of spring 0's first harmonic removes that
direction (a travelling wave $a\\sin(\\omega t - j\\varphi)$ has this form).

For a given $\\theta$ the steady gait is the fixed point $y^*$ of the period map
$\\Phi_k(y, \\theta)$ of the reduced state $y = (u_1, \\dots, u_{N-1}, v_1, \\dots, v_N)$ at the
phase $\\omega t \\equiv 0$ (as in `steady_gait(chain)`), found by Newton's method from a warm
start with $M = \\partial\\Phi_k/\\partial y$ by forward mode through the N-mass exact engine.
Over the $k$ periods the engine accumulates the drift of the centre of mass $\\Delta X$, the
dissipated energy $e_d$ (SPEC §8) and the smallest normal force $\\min_{i,t} N_i$ (eq. 5
generalised, at the step ends). Their total derivatives follow from the implicit function
theorem, $dy^*/d\\theta = (I - M)^{-1}\\partial\\Phi/\\partial\\theta$ and
$dF/d\\theta = \\partial F/\\partial\\theta + (\\partial F/\\partial y)\\,dy^*/d\\theta$: one forward
pass over the gait period in the $2N - 1 + p$ directions $(y, \\theta)$ gives every gradient,
located events entering with their implicit-function times (the saltation of each switch).

A [`Mechanism`][locomotion_jax.Mechanism] takes one signal per actuated element (`Mechanism.actuated`)
in place of one per spring. With `knots` $M > 0$ (a chain or a mechanism), the decision vector is
$\\theta = (c_{0,0}, \\dots, c_{0,M-1}, c_{1,0}, \\dots, c_{S-1,M-1}, \\log\\omega)$, the control
values of a periodic cubic B-spline per signal ([`Spline`][], units of $a_\\max$; no phase is
fixed), instead of Fourier coefficients.
"""

from collections import Counter
from typing import Any, ClassVar

import equinox as eqx
import jax.numpy as jnp

from .._custom_types import Array, Contact
from .._loops import lane_while_loop
from ..model._bodies import Mechanism
from ..model._chain import Chain
from ..model._chain_array import engine_physics, GAIT_ARRAY_FROM
from ..model._physics import AbstractPhysics
from . import _orbit as orbit
from ._orbit import Orbit, Period


TRACES: Counter = Counter()
"""Python-level traces of the compiled functions (keys `"evaluate"`, `"relax"`)."""


def size(springs: int, harmonics: int) -> int:
    """Length of the decision vector."""
    return 2 * springs * harmonics


def coefficients(theta: Array, springs: int, harmonics: int) -> tuple[Array, Array]:
    """Decision vector(s) -> `(cos, sin)` of shape `(..., springs, harmonics)`, units of $a_\\max$."""
    SH = springs * harmonics
    zero = jnp.zeros(theta.shape[:-1] + (1,), theta.dtype)
    cos = jnp.concatenate([zero, theta[..., : SH - 1]], axis=-1)
    sin = theta[..., SH - 1 : 2 * SH - 1]
    shape = theta.shape[:-1] + (springs, harmonics)
    return cos.reshape(shape), sin.reshape(shape)


def with_waves(chain: Chain | Mechanism, theta: Array, a_max: Array, harmonics: int,
               knots: int = 0) -> Chain | Mechanism:  # fmt: skip
    """One chain or mechanism (broadcast, unbatched) driven by the decision vector `theta`: a
    Fourier series per actuated signal (`n_signals` of them), or with `knots > 0` a spline."""
    S = chain.n_signals
    if knots > 0:
        return chain.with_spline(a_max * theta[:-1].reshape(S, knots), jnp.exp(theta[-1]))
    cos, sin = coefficients(theta, S, harmonics)
    return chain.with_fourier(a_max * cos, a_max * sin, jnp.exp(theta[-1]))


def period(
    C: Chain | Mechanism,
    contact: Contact,
    dt: float | Array,
    max_steps: Array,
    y: Array,
    k: Array,
    loop=lane_while_loop,
) -> Period:
    """The `k`-period map $\\Phi_k$ of one chain or mechanism from the reduced state `y`, with the
    figures the optimiser needs (`max_steps` per actuation period): `_orbit.period` of its physics.
    `loop`: the time loop, `lax.while_loop`'s signature (`gaits._adjoint` passes one that reverse
    mode traverses)."""
    return orbit.period(gait_physics(C), contact, dt, max_steps, y, k, loop)


def gait_physics(C: Chain | Mechanism) -> AbstractPhysics:
    """The physics a gait integrates `C` with: a chain's in the array layout from
    `GAIT_ARRAY_FROM` masses on (`model._chain_array`, as `steady_gait`), else its own."""
    return engine_physics(C, GAIT_ARRAY_FROM)


class ChainActuation(orbit.AbstractActuation):
    """A chain or mechanism driven by the decision vector's signals (`with_waves`: Fourier series of
    `harmonics` harmonics, or with `knots > 0` periodic splines)."""

    harmonics: int
    knots: int = 0
    traces: ClassVar[Counter] = TRACES

    def physics(self, model: Chain | Mechanism, theta: Array, a_max: Array) -> AbstractPhysics:
        return gait_physics(with_waves(model, theta, a_max, self.harmonics, self.knots))

    def rest(self, model: Chain | Mechanism, P: AbstractPhysics) -> Array:
        return P.initial_positions("relaxed")


def evaluate(C, a_max, theta, y0, k, harmonics, knots, contact, dt, max_steps, tol, max_iter, patience=None) -> Orbit:
    """Orbits and sensitivities of a batch of decision vectors (`_orbit.evaluate`, compiled once
    per chain structure, batch size and static choice; `dt` and `max_iter` are data)."""
    act = ChainActuation(harmonics, knots)
    return orbit.evaluate(C, a_max, theta, y0, k, act, contact, dt, max_steps, tol, max_iter, monodromy_only=False,
                          gradient=True, patience=patience)  # fmt: skip


def relax(C, a_max, theta, y0, fresh, periods, harmonics, knots, contact, dt, max_steps) -> Array:
    """`periods` actuation periods from the section states `y0`, or from the relaxed springs at
    rest where `fresh` (`_orbit.relax`): the reduced states at the end."""
    return orbit.relax(C, a_max, theta, y0, fresh, periods, ChainActuation(harmonics, knots), contact, dt, max_steps)


class ChainOracle(eqx.Module):
    """The compiled evaluations of one chain problem (static: harmonics, knots, contact; the step and
    Newton's iterations reach the program as data).

    `chain` is one configuration, broadcast (its waveforms are replaced by the decision vector's): a
    chain (one signal per spring), or a [`Mechanism`][locomotion_jax.Mechanism] (one signal per
    actuated element); with `knots > 0` a spline of `knots` control values per signal, `harmonics`
    unused.
    """

    chain: Chain | Mechanism
    a_max: Array
    max_steps: Array
    tol: Array
    harmonics: int = eqx.field(static=True)
    contact: Contact = eqx.field(static=True)
    dt: float = eqx.field(static=True)
    max_iter: int = eqx.field(static=True)
    knots: int = eqx.field(static=True, default=0)
    patience: Array | None = None

    @property
    def dtype(self) -> Any:
        return self.chain.dtype

    def orbits(self, theta: Array, y0: Array, k: Array) -> Orbit:
        """Steady gaits of `k` actuation periods (int32, per row) and their sensitivities, for a
        batch of decision vectors, from warm starts `y0`."""
        dt, max_iter = jnp.asarray(self.dt, self.dtype), jnp.asarray(self.max_iter, jnp.int32)
        return evaluate(self.chain, self.a_max, theta, y0, k, self.harmonics, self.knots, self.contact, dt,
                        self.max_steps, self.tol, max_iter, self.patience)  # fmt: skip

    def transient(self, theta: Array, y0: Array, fresh: Array, periods: Array) -> Array:
        """The reduced state after `periods` periods (from `y0`, or from rest where `fresh`)."""
        return relax(self.chain, self.a_max, theta, y0, fresh, periods, self.harmonics, self.knots, self.contact,
                     jnp.asarray(self.dt, self.dtype), self.max_steps)  # fmt: skip
