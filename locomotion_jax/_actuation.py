"""Actuation waveforms: the rest length $\\ell_0(t)$ and its rate (eq. 13 and beyond)."""

import abc

import equinox as eqx
import jax.numpy as jnp

from ._custom_types import Array, ArrayLike, Float
from ._params import Params


class AbstractWaveform(eqx.Module):
    """A periodic rest length $\\ell_0(t)$ of base frequency `omega` around `lbar`.

    Concrete waveforms are final pytrees whose array fields may be differentiated
    (the optimiser works on their coefficients).
    """

    omega: eqx.AbstractVar[Array]
    lbar: eqx.AbstractVar[Array]

    @abc.abstractmethod
    def __call__(self, t: ArrayLike) -> tuple[Array, Array]:
        """Return $(\\ell_0(t), \\dot\\ell_0(t))$."""

    @abc.abstractmethod
    def at_phase(self, cos: ArrayLike, sin: ArrayLike) -> tuple[Array, Array, Array]:
        """$(\\ell_0, \\dot\\ell_0, \\ddot\\ell_0)$ given $(\\cos\\omega t, \\sin\\omega t)$.

        The exact engine carries the phase and rotates it step by step, because
        XLA's CPU `sin` costs more than a whole force evaluation (benchmarks/NOTES.md).
        """

    @abc.abstractmethod
    def stroke(self) -> Array:
        """An upper bound of $\\max_t |\\ell_0(t) - \\bar\\ell|$ (sum of harmonic amplitudes)."""


class Sinusoid(AbstractWaveform):
    """The paper's actuation, eq. (13): $\\ell_0(t) = a \\sin(\\omega t) + \\bar\\ell$."""

    a: Array
    omega: Array
    lbar: Array

    def __init__(self, a: ArrayLike, omega: ArrayLike, lbar: ArrayLike):
        self.a = jnp.asarray(a)
        self.omega = jnp.asarray(omega)
        self.lbar = jnp.asarray(lbar)

    @classmethod
    def from_params(cls, params: Params) -> "Sinusoid":
        return cls(params.a, params.omega, params.lbar)

    def __call__(self, t: ArrayLike) -> tuple[Array, Array]:
        phase = self.omega * t
        return self.at_phase(jnp.cos(phase), jnp.sin(phase))[:2]

    def at_phase(self, cos: ArrayLike, sin: ArrayLike) -> tuple[Array, Array, Array]:
        As = self.a * sin
        return As + self.lbar, self.a * self.omega * cos, -(self.omega * self.omega) * As

    def stroke(self) -> Array:
        return jnp.abs(self.a)


class Fourier(AbstractWaveform):
    """Truncated Fourier series in the base frequency $\\omega$:

    $$\\ell_0(t) = \\bar\\ell + \\sum_{n=1}^{N} \\big(A_n \\cos(n\\omega t) + B_n \\sin(n\\omega t)\\big).$$

    With $N = 1$, $A_1 = 0$, $B_1 = a$ it is eq. (13). Higher harmonics are built
    from $\\cos\\omega t, \\sin\\omega t$ by the angle-addition recurrence, so one
    `sin`/`cos` pair is evaluated per call whatever $N$.

    **Arguments:**

    - `cos`, `sin`: coefficient arrays $A_n$, $B_n$ of shape `(N,)`.
    - `omega`: base frequency; `lbar`: mean rest length.
    """

    cos: Float[Array, " N"]
    sin: Float[Array, " N"]
    omega: Array
    lbar: Array

    def __init__(self, cos: ArrayLike, sin: ArrayLike, omega: ArrayLike, lbar: ArrayLike):
        self.cos = jnp.asarray(cos)
        self.sin = jnp.asarray(sin)
        self.omega = jnp.asarray(omega)
        self.lbar = jnp.asarray(lbar)
        if self.cos.shape[-1:] != self.sin.shape[-1:] or self.cos.ndim == 0:
            raise ValueError(
                f"Fourier: 'cos' and 'sin' need the same number of harmonics N >= 1 "
                f"(got shapes {self.cos.shape} and {self.sin.shape})."
            )

    @classmethod
    def from_sinusoid(cls, a: ArrayLike, omega: ArrayLike, lbar: ArrayLike, harmonics: int = 1):
        if harmonics < 1:
            raise ValueError(f"harmonics must be >= 1, got {harmonics}.")
        sin = jnp.zeros(harmonics).at[0].set(a)
        return cls(jnp.zeros(harmonics), sin, omega, lbar)

    @property
    def harmonics(self) -> int:
        return self.cos.shape[-1]

    def __call__(self, t: ArrayLike) -> tuple[Array, Array]:
        return self.at_phase(jnp.cos(self.omega * t), jnp.sin(self.omega * t))[:2]

    def at_phase(self, cos: ArrayLike, sin: ArrayLike) -> tuple[Array, Array, Array]:
        c1, s1 = jnp.asarray(cos), jnp.asarray(sin)
        l0, dl0, ddl0 = self.lbar, jnp.zeros_like(c1), jnp.zeros_like(c1)
        cn, sn = c1, s1
        for n in range(self.harmonics):  # static N: a short unrolled recurrence
            A, B = self.cos[..., n], self.sin[..., n]
            l0 = l0 + A * cn + B * sn
            dl0 = dl0 + (n + 1) * self.omega * (B * cn - A * sn)
            ddl0 = ddl0 - ((n + 1) * self.omega) ** 2 * (A * cn + B * sn)
            cn, sn = cn * c1 - sn * s1, sn * c1 + cn * s1
        return l0, dl0, ddl0

    def stroke(self) -> Array:
        return jnp.sum(jnp.sqrt(self.cos**2 + self.sin**2), axis=-1)
