"""Actuation signals of a chain's springs: per-spring Fourier series of one base frequency."""

from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax.numpy as jnp

from .._custom_types import Array, ValuesLike
from ._checks import broadcast_shape, Check, first_invalid, is_concrete, real_array
from ._waveform import AbstractWaveform, Fourier, Sinusoid


class SpringFourier(eqx.Module):
    """Zero-mean signals $s_j(t) = \\sum_{n=1}^{H} A_{jn} \\cos(n\\omega t) + B_{jn} \\sin(n\\omega t)$.

    The normal form of every chain actuation: springs share the base frequency
    $\\omega$ (so the gait has a period), each has its own coefficients.

    **Arguments:** `cos`, `sin`: arrays of shape `(..., S, H)` (S springs, H harmonics;
    leading axes are batch axes); `omega`: base frequency, shape `(...)`.
    """

    cos: Array
    sin: Array
    omega: Array

    def __init__(self, cos: ValuesLike, sin: ValuesLike, omega: ValuesLike):
        self.cos = real_array("cos", cos, "SpringFourier")
        self.sin = real_array("sin", sin, "SpringFourier")
        self.omega = real_array("omega", omega, "SpringFourier")
        if self.cos.ndim < 2 or self.cos.shape[-2:] != self.sin.shape[-2:]:
            raise ValueError(
                f"SpringFourier: 'cos' and 'sin' need shapes (..., springs, harmonics), equal in their last two "
                f"axes; got {self.cos.shape} and {self.sin.shape}."
            )

    @property
    def harmonics(self) -> int:
        return self.cos.shape[-1]

    def at_phase(self, c1: Array, s1: Array) -> tuple[Array, Array, Array]:
        """$(s_j, \\dot s_j, \\ddot s_j)$ of one configuration given $(\\cos\\omega t, \\sin\\omega t)$.

        Harmonics by the angle-addition recurrence: one phase pair whatever $H$.
        """
        w = self.omega
        val = jnp.zeros(self.cos.shape[:-1], c1.dtype)
        rate, acc = val, val
        cn, sn = c1, s1
        for n in range(self.harmonics):
            A, B = self.cos[..., n], self.sin[..., n]
            nw = (n + 1) * w
            val = val + A * cn + B * sn
            rate = rate + nw * (B * cn - A * sn)
            acc = acc - nw * nw * (A * cn + B * sn)
            cn, sn = cn * c1 - sn * s1, sn * c1 + cn * s1
        return val, rate, acc

    def stroke(self) -> Array:
        """Upper bound of $\\max_t |s_j(t)|$ per spring (sum of the harmonics' amplitudes)."""
        return jnp.sqrt(self.cos**2 + self.sin**2).sum(-1)

    def checks(self) -> list[Check]:
        """`(field, valid mask, valid range)`: finite coefficients, $\\omega \\ge 0$ and finite (batch shape)."""
        return [("cos", jnp.isfinite(self.cos).all((-2, -1)), "finite"),
                ("sin", jnp.isfinite(self.sin).all((-2, -1)), "finite"),
                ("omega", jnp.isfinite(self.omega) & (self.omega >= 0), "omega >= 0 and finite")]  # fmt: skip

    def validate(self) -> "SpringFourier":
        """Raise `ValueError` at the first invalid value (field, valid range, batch index)."""
        first_invalid("SpringFourier", self.checks(), {"cos": self.cos, "sin": self.sin, "omega": self.omega})
        return self


class TravellingWave(eqx.Module):
    """A wave along the chain: $s_j(t) = a \\sin(\\omega t - j\\varphi)$ on spring $j = 0, \\dots, S-1$.

    With $\\varphi > 0$ the wave travels from the rear spring (between masses 0 and 1)
    towards the front ($+x$); $\\varphi < 0$ reverses it. $\\varphi = 0$ actuates every
    spring in phase.

    **Arguments:** `a` (amplitude), `omega` (frequency), `phi` (phase lag between neighbours).
    """

    a: Array
    omega: Array
    phi: Array

    def __init__(self, a: ValuesLike, omega: ValuesLike, phi: ValuesLike = 0.0):
        fields = {n: real_array(n, v, "TravellingWave") for n, v in (("a", a), ("omega", omega), ("phi", phi))}
        broadcast_shape({n: x.shape for n, x in fields.items()})  # names the fields that do not broadcast
        # One batch shape for the three (a batch may vary any of them).
        self.a, self.omega, self.phi = jnp.broadcast_arrays(*fields.values())

    def checks(self) -> list[Check]:
        """`(field, valid mask, valid range)`: finite `a` and `phi`, $\\omega \\ge 0$ and finite."""
        return [("a", jnp.isfinite(self.a), "finite"),
                ("omega", jnp.isfinite(self.omega) & (self.omega >= 0), "omega >= 0 and finite"),
                ("phi", jnp.isfinite(self.phi), "finite")]  # fmt: skip

    def validate(self) -> "TravellingWave":
        """Raise `ValueError` at the first invalid value (field, valid range, batch index)."""
        first_invalid("TravellingWave", self.checks(), {"a": self.a, "omega": self.omega, "phi": self.phi})
        return self

    def spring_fourier(self, springs: int) -> SpringFourier:
        """$a \\sin(\\omega t - j\\varphi) = a\\cos(j\\varphi) \\sin\\omega t - a \\sin(j\\varphi) \\cos\\omega t$."""
        j = jnp.arange(springs).reshape((1,) * self.phi.ndim + (springs,))
        lag = self.phi[..., None] * j
        a = self.a[..., None]
        return SpringFourier((-a * jnp.sin(lag))[..., None], (a * jnp.cos(lag))[..., None], self.omega)


def _as_fourier(w: AbstractWaveform, harmonics: int) -> tuple[Array, Array]:
    if isinstance(w, Sinusoid):
        A, B = jnp.zeros(jnp.shape(w.a) + (1,)), jnp.asarray(w.a)[..., None]
    elif isinstance(w, Fourier):
        A, B = w.cos, w.sin
    else:
        raise TypeError(f"a spring's waveform must be a Sinusoid or Fourier, got {type(w).__name__}.")
    pad = [(0, 0)] * (A.ndim - 1) + [(0, harmonics - A.shape[-1])]
    return jnp.pad(A, pad), jnp.pad(B, pad)


def to_spring_fourier(waveforms, springs: int) -> tuple[SpringFourier, Array | None]:
    """Normal form of a chain's actuation, and the mean rest lengths the waveforms carry (or `None`).

    Accepts a [`SpringFourier`][], a [`TravellingWave`][], one `Sinusoid`/`Fourier`
    (every spring in phase) or a sequence of them, one per spring, with a common
    base frequency.
    """
    if isinstance(waveforms, SpringFourier):
        if waveforms.cos.shape[-2] != springs:
            raise ValueError(
                f"waveforms: SpringFourier has {waveforms.cos.shape[-2]} springs; the chain has {springs}."
            )
        return waveforms, None
    if isinstance(waveforms, TravellingWave):
        return waveforms.spring_fourier(springs), None
    if isinstance(waveforms, AbstractWaveform):
        waveforms = [waveforms] * springs
    if not isinstance(waveforms, Sequence) or not all(isinstance(w, AbstractWaveform) for w in waveforms):
        raise TypeError(
            "waveforms must be a TravellingWave, a SpringFourier, a Sinusoid/Fourier, or a list of "
            f"Sinusoid/Fourier (one per spring); got {type(waveforms).__name__}."
        )
    if len(waveforms) != springs:
        raise ValueError(f"waveforms: got {len(waveforms)} waveforms for {springs} springs (one per spring).")
    omegas = [w.omega for w in waveforms]
    for j, om in enumerate(omegas[1:], start=1):
        try:
            same = bool(jnp.all(om == omegas[0]))
        except Exception:  # traced: the caller vouches for a common frequency
            same = True
        if not same:
            raise ValueError(
                f"waveforms: spring {j} has omega={om!r} but spring 0 has omega={omegas[0]!r}; "
                "a chain's springs share one base frequency (use harmonics for other frequencies)."
            )
    if not all(isinstance(w, (Sinusoid, Fourier)) for w in waveforms):
        # Any other waveform (a Spline) drives its spring itself (`Chain.signals`); the normal form
        # keeps the base frequency, with no harmonics.
        zeros = jnp.zeros(jnp.shape(omegas[0]) + (springs, 1))
        lbar = jnp.stack(jnp.broadcast_arrays(*(jnp.asarray(w.lbar) for w in waveforms)), axis=-1)
        return SpringFourier(zeros, zeros, omegas[0]), lbar
    H = max(w.harmonics if isinstance(w, Fourier) else 1 for w in waveforms)
    coeffs = [_as_fourier(w, H) for w in waveforms]
    A = jnp.stack(jnp.broadcast_arrays(*(c[0] for c in coeffs)), axis=-2)
    B = jnp.stack(jnp.broadcast_arrays(*(c[1] for c in coeffs)), axis=-2)
    lbar = jnp.stack(jnp.broadcast_arrays(*(jnp.asarray(w.lbar) for w in waveforms)), axis=-1)
    return SpringFourier(A, B, omegas[0]), lbar


def spring_signals(waveforms: Any, springs: int) -> tuple[AbstractWaveform, ...] | None:
    """The waveform of each spring where one is neither a `Sinusoid` nor a `Fourier` (a `Spline`:
    it drives its spring itself), else `None` (the normal form [`SpringFourier`][] holds the actuation)."""
    if isinstance(waveforms, AbstractWaveform):
        waveforms = [waveforms] * springs
    if isinstance(waveforms, Sequence) and not all(isinstance(w, (Sinusoid, Fourier)) for w in waveforms):
        return tuple(waveforms)
    return None


def check_waveforms(waveforms: Any) -> None:
    """Raise `ValueError` at the first invalid value of a chain's `waveforms` argument (as
    [`to_spring_fourier`][] accepts it) whose values are known, named by the waveform's own
    field (`phi` of a `TravellingWave`, `a` of the `Sinusoid` of spring `j`); values under
    `jit` are left to the chain's validity mask."""
    if isinstance(waveforms, (SpringFourier, TravellingWave, AbstractWaveform)):
        if is_concrete(waveforms):
            waveforms.validate()
        return
    if isinstance(waveforms, Sequence):
        for j, w in enumerate(waveforms):
            if isinstance(w, AbstractWaveform) and is_concrete(w):
                try:
                    w.validate()
                except ValueError as err:
                    raise ValueError(f"waveforms[{j}] (the waveform of spring {j}): {err}") from None
