"""Friction laws of one mass on the ground (SPEC §2 and §8).

A law supplies what the exact engine needs: the static limits that hold a stuck
mass and the kinetic coefficient of a slipping one; the smoothed dynamics and the
energy balance are built from the same two methods (`AbstractFriction.smoothed`). Coefficients are per-mass
arrays (trailing axis of length N, or broadcastable to it); any leading axes are
batch axes. The law is elementwise over masses: the engine evaluates it one mass
at a time, with that mass's coefficients (scalars) and speed.
"""

import abc
import dataclasses
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array, ValuesLike
from ._checks import real_array


class AbstractFriction(eqx.Module):
    """Base class of friction laws (abstract/final pattern).

    Sign conventions (SPEC §8): a mass slipping with velocity $v$ in direction
    $\\sigma = \\operatorname{sgn} v$ feels $-\\sigma\\,\\mu_k(\\sigma, |v|)\\,n$; a stuck mass
    stays stuck while $-\\mu_{s,\\mathrm{bwd}}\\,n \\le F \\le \\mu_{s,\\mathrm{fwd}}\\,n$.
    """

    static_at_rest: ClassVar[bool] = False
    """Whether the kinetic coefficient at rest is the static one (Stribeck): a mass breaking away then
    has no acceleration along its slip where its load only grazes the static limit, and the exact
    engine does not look for its stop in the step that starts the slip (`dynamics._engine.step`).
    A law of your own with that property sets it `True`; without it such a run can end `MAX_STEPS`."""

    @abc.abstractmethod
    def static_limits(self) -> tuple[Array, Array]:
        """Static coefficients $(\\mu_{s,\\mathrm{fwd}}, \\mu_{s,\\mathrm{bwd}})$, per mass."""

    @abc.abstractmethod
    def kinetic(self, speed: Array, direction: Array) -> Array:
        """Kinetic coefficient $\\mu_k \\ge 0$ of a mass slipping at `speed` $= |v|$ in
        `direction` $\\sigma = \\pm 1$ (smooth in the speed)."""

    def kinetic_rate(self, speed: Array, direction: Array, speed_rate: Array) -> Array | None:
        """Time derivative of [`kinetic`][locomotion_jax.AbstractFriction.kinetic] while the
        speed changes at `speed_rate` (for the exact engine's dense output and event
        prediction). By default forward-mode differentiation of `kinetic`, so a law supplies
        values only; `None` means zero (a law whose coefficient does not depend on the speed
        returns it, and the engine skips those terms)."""
        return jax.jvp(lambda s: self.kinetic(s, direction), (speed,), (speed_rate,))[1]

    def time_scale(self) -> tuple[Array, Array] | None:
        """The law's own time scale for the resolution guards, per mass, and the speed scale that
        sets it: `None` for a law without one (Coulomb). `Stribeck`: $(v_s/\\mu_s, v_s)$, the time
        over which friction alone (normal force $m_i g$, $g = 1$) changes a speed by $v_s$."""
        return None

    def smoothed(self, v: Array, eps: Array, v_s: Array) -> Array:
        """Smoothed friction coefficient, odd in $v$, for the smoothed dynamics (SPEC §3):

        $$\\mu(v) = \\big[\\mu_{k,\\sigma}(|v|) + (\\mu_{s,\\sigma} - \\mu_{k,\\sigma}(|v|))\\,
        e^{-(v/v_s)^2}\\big] \\tanh(v/\\varepsilon), \\qquad \\sigma = \\operatorname{sgn} v,$$

        a regularised sign with a static bump of width $v_s$; the friction force is
        $-n\\,\\mu(v)$. As $\\varepsilon \\to 0$ with $v_s \\to 0$ and $v_s/\\varepsilon \\to \\infty$
        its peak tends to the static limit and its sliding value to the kinetic law: the
        exact law of this class. At $v = 0$ the factor $\\tanh$ vanishes, so the switch of
        direction $\\sigma$ leaves $\\mu$ continuous. Built from [`static_limits`][] and
        [`kinetic`][], so a new law needs nothing more.
        """
        direction = jnp.where(v >= 0, 1.0, -1.0).astype(v.dtype)
        mu_fwd, mu_bwd = self.static_limits()
        mu_s = jnp.where(direction > 0, mu_fwd, mu_bwd)
        mu_k = self.kinetic(jnp.abs(v), direction)
        return (mu_k + (mu_s - mu_k) * jnp.exp(-((v / v_s) ** 2))) * jnp.tanh(v / eps)

    def fields(self) -> dict[str, Array]:
        """The coefficient arrays by name (every array field of the law)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    def validity(self) -> dict[str, Array]:
        """Per-field masks of valid values; a law with constraints overrides this."""
        return {}

    def valid_ranges(self) -> dict[str, str]:
        """Human-readable valid range of each constrained field, for error messages."""
        return {}


class Coulomb(AbstractFriction):
    """Isotropic Coulomb friction, the paper's law (eqs. 7, 9): static $\\mu_s$, kinetic $\\mu_k$.

    **Arguments:** `mu_s`, `mu_k`: scalars or per-mass arrays, $\\mu_s \\ge \\mu_k \\ge 0$.
    """

    mu_s: Array
    mu_k: Array

    def __init__(self, mu_s: ValuesLike = 0.7, mu_k: ValuesLike = 0.5):
        self.mu_s = real_array("mu_s", mu_s, "Coulomb")
        self.mu_k = real_array("mu_k", mu_k, "Coulomb")

    def static_limits(self) -> tuple[Array, Array]:
        return self.mu_s, self.mu_s

    def kinetic(self, speed: Array, direction: Array) -> Array:
        return jnp.broadcast_to(self.mu_k, jnp.shape(speed)).astype(speed.dtype)

    def kinetic_rate(self, speed: Array, direction: Array, speed_rate: Array) -> None:
        return None

    def validity(self) -> dict[str, Array]:
        return {"mu_s": self.mu_s >= self.mu_k, "mu_k": self.mu_k >= 0}

    def valid_ranges(self) -> dict[str, str]:
        return {"mu_s": "mu_s >= mu_k", "mu_k": "mu_k >= 0"}


class AnisotropicCoulomb(AbstractFriction):
    """Coulomb friction with direction-dependent coefficients (bristles, scales; SPEC §8).

    Slipping forward ($v > 0$) the friction is $-\\mu_{k,\\mathrm{fwd}}\\,n$, backward
    $+\\mu_{k,\\mathrm{bwd}}\\,n$; a stuck mass holds while
    $-\\mu_{s,\\mathrm{bwd}}\\,n \\le F \\le \\mu_{s,\\mathrm{fwd}}\\,n$.

    **Arguments:** `mu_s_fwd`, `mu_s_bwd`, `mu_k_fwd`, `mu_k_bwd`: scalars or per-mass
    arrays with $\\mu_{s,\\cdot} \\ge \\mu_{k,\\cdot} \\ge 0$ in each direction.
    """

    mu_s_fwd: Array
    mu_s_bwd: Array
    mu_k_fwd: Array
    mu_k_bwd: Array

    def __init__(self, mu_s_fwd: ValuesLike, mu_s_bwd: ValuesLike, mu_k_fwd: ValuesLike, mu_k_bwd: ValuesLike):
        self.mu_s_fwd = real_array("mu_s_fwd", mu_s_fwd, "AnisotropicCoulomb")
        self.mu_s_bwd = real_array("mu_s_bwd", mu_s_bwd, "AnisotropicCoulomb")
        self.mu_k_fwd = real_array("mu_k_fwd", mu_k_fwd, "AnisotropicCoulomb")
        self.mu_k_bwd = real_array("mu_k_bwd", mu_k_bwd, "AnisotropicCoulomb")

    def static_limits(self) -> tuple[Array, Array]:
        return self.mu_s_fwd, self.mu_s_bwd

    def kinetic(self, speed: Array, direction: Array) -> Array:
        return jnp.where(direction > 0, self.mu_k_fwd, self.mu_k_bwd).astype(speed.dtype)

    def kinetic_rate(self, speed: Array, direction: Array, speed_rate: Array) -> None:
        return None

    def mirrored(self) -> "AnisotropicCoulomb":
        """The same law with forward and backward swapped (mirror image of the ground)."""
        return AnisotropicCoulomb(self.mu_s_bwd, self.mu_s_fwd, self.mu_k_bwd, self.mu_k_fwd)

    def validity(self) -> dict[str, Array]:
        return {
            "mu_s_fwd": self.mu_s_fwd >= self.mu_k_fwd,
            "mu_s_bwd": self.mu_s_bwd >= self.mu_k_bwd,
            "mu_k_fwd": self.mu_k_fwd >= 0,
            "mu_k_bwd": self.mu_k_bwd >= 0,
        }

    def valid_ranges(self) -> dict[str, str]:
        return {"mu_s_fwd": "mu_s_fwd >= mu_k_fwd", "mu_s_bwd": "mu_s_bwd >= mu_k_bwd",
                "mu_k_fwd": "mu_k_fwd >= 0", "mu_k_bwd": "mu_k_bwd >= 0"}  # fmt: skip


STRIBECK_R_MAX = 40.0
"""Largest $|v|/v_s$ that [`Stribeck`][] evaluates: $e^{-40^2}$ is zero in float64 and float32."""


class Stribeck(AbstractFriction):
    r"""Coulomb friction whose kinetic coefficient falls with speed (Stribeck effect).

    $$\\mu_k(|v|) = \\mu_k + (\\mu_s - \\mu_k)\\, e^{-(|v|/v_s)^2},$$

    so a mass that has just broken away feels the static coefficient, and the
    kinetic one is approached above the Stribeck speed $v_s$. Optionally anisotropic:
    backward motion uses `mu_s_bwd`, `mu_k_bwd` in the same formula (default: the forward ones).

    **Arguments:** `mu_s`, `mu_k` ($\\mu_s \\ge \\mu_k \\ge 0$), `v_s > 0`, and optionally `mu_s_bwd`,
    `mu_k_bwd`; scalars or per mass.
    """

    mu_s: Array
    mu_k: Array
    v_s: Array
    mu_s_bwd: Array
    mu_k_bwd: Array

    static_at_rest: ClassVar[bool] = True

    def __init__(
        self,
        mu_s: ValuesLike = 0.7,
        mu_k: ValuesLike = 0.5,
        v_s: ValuesLike = 0.1,
        *,
        mu_s_bwd: ValuesLike | None = None,
        mu_k_bwd: ValuesLike | None = None,
    ):
        self.mu_s = real_array("mu_s", mu_s, "Stribeck")
        self.mu_k = real_array("mu_k", mu_k, "Stribeck")
        self.v_s = real_array("v_s", v_s, "Stribeck")
        self.mu_s_bwd = self.mu_s if mu_s_bwd is None else real_array("mu_s_bwd", mu_s_bwd, "Stribeck")
        self.mu_k_bwd = self.mu_k if mu_k_bwd is None else real_array("mu_k_bwd", mu_k_bwd, "Stribeck")

    def static_limits(self) -> tuple[Array, Array]:
        return self.mu_s, self.mu_s_bwd

    def kinetic(self, speed: Array, direction: Array) -> Array:
        fwd = direction > 0
        mu_s = jnp.where(fwd, self.mu_s, self.mu_s_bwd)
        mu_k = jnp.where(fwd, self.mu_k, self.mu_k_bwd)
        # Beyond R_MAX the bump is below the dtype's resolution; the clip keeps r * r (and its
        # derivative) finite however small v_s is.
        r = jnp.minimum(speed / self.v_s, STRIBECK_R_MAX)
        return mu_k + (mu_s - mu_k) * jnp.exp(-r * r)

    def time_scale(self) -> tuple[Array, Array] | None:
        mu = jnp.maximum(jnp.maximum(self.mu_s, self.mu_s_bwd), 1e-300)
        return self.v_s / mu, self.v_s

    def validity(self) -> dict[str, Array]:
        # 1 / v_s**2 must be finite: the law's rate (dense output, event prediction) scales with it.
        v_s_ok = (self.v_s > 0) & jnp.isfinite(1 / (self.v_s * self.v_s))
        return {"mu_s": self.mu_s >= self.mu_k, "mu_k": self.mu_k >= 0, "v_s": v_s_ok,
                "mu_s_bwd": self.mu_s_bwd >= self.mu_k_bwd, "mu_k_bwd": self.mu_k_bwd >= 0}  # fmt: skip

    def valid_ranges(self) -> dict[str, str]:
        return {"mu_s": "mu_s >= mu_k", "mu_k": "mu_k >= 0",
                "v_s": "v_s > 0 with 1/v_s**2 finite (v_s > 1e-154 in float64, 1e-19 in float32)",
                "mu_s_bwd": "mu_s_bwd >= mu_k_bwd", "mu_k_bwd": "mu_k_bwd >= 0"}  # fmt: skip


class MixedFriction(AbstractFriction):
    """Bodies under friction laws of several classes as one law over an entry that holds them all (a
    [`Mechanism`][locomotion_jax.Mechanism] in the array layout, `model._mechanism_array`). Each member of
    `laws` holds every body's coefficients (a body of another class a copy of one of the member's own
    bodies, so that each member computes finite values everywhere), and body $i$ reads the member
    `classes[i]` (static): the values, rates and smoothed law of its own class."""

    laws: tuple[AbstractFriction, ...]
    classes: tuple[int, ...] = eqx.field(static=True)

    def _pick(self, values: list[Array]) -> Array:
        out = values[0]
        for k in range(1, len(values)):
            out = jnp.where(np.asarray([c == k for c in self.classes]), values[k], out)
        return out

    def static_limits(self) -> tuple[Array, Array]:
        pairs = [law.static_limits() for law in self.laws]
        fwd = self._pick([f for f, _ in pairs])
        # Symmetric members keep the limits one array: the engine then skips the backward limit.
        return fwd, fwd if all(f is b for f, b in pairs) else self._pick([b for _, b in pairs])

    def kinetic(self, speed: Array, direction: Array) -> Array:
        return self._pick([law.kinetic(speed, direction) for law in self.laws])

    def kinetic_rate(self, speed: Array, direction: Array, speed_rate: Array) -> Array | None:
        rates = [law.kinetic_rate(speed, direction, speed_rate) for law in self.laws]
        if all(r is None for r in rates):
            return None
        return self._pick([jnp.zeros_like(speed) if r is None else r for r in rates])

    def smoothed(self, v: Array, eps: Array, v_s: Array) -> Array:
        return self._pick([law.smoothed(v, eps, v_s) for law in self.laws])


def static_at_rest(law: AbstractFriction) -> bool:
    """[`AbstractFriction.static_at_rest`][] of a law, or of any member of a [`MixedFriction`][]."""
    if isinstance(law, MixedFriction):
        return any(static_at_rest(q) for q in law.laws)
    return type(law).static_at_rest
