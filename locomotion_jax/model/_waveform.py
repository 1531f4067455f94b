"""Actuation waveforms: the rest length $\\ell_0(t)$ and its rate (eq. 13 and beyond)."""

import abc
import dataclasses
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array, ArrayLike, Float, ValuesLike
from ._checks import all_valid, Check, first_invalid, real_array
from ._params import Params


RECURRENCE_MAX = 4
"""Most harmonics that [`Fourier`][] builds by the angle-addition recurrence.

The recurrence is an unrolled chain in which every harmonic uses both of the previous
one's values; XLA on the CPU fuses such cheap chains into each consumer, so the work
and the compile time grow about as $2^N$, and much faster under forward-mode
differentiation (measured for one actuation period with $N = 16$ and 36 tangent
directions: 112 s to compile, 8.9 s to run; with the vector evaluation 12 s and 4 ms)."""


def up_to(x: Array, like: Array) -> Array:
    """`x` with leading unit axes up to the rank of `like` (explicit broadcasting)."""
    return x.reshape((1,) * (like.ndim - x.ndim) + x.shape) if x.ndim < like.ndim else x


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

    stroke_check: ClassVar[tuple[str, str]] = ("stroke", "stroke < lbar")
    """Name and valid range of the bound on the stroke in messages (the rest length stays positive)."""

    def coefficients(self) -> dict[str, Array]:
        """The shape's coefficient arrays by field name, each with a last axis of coefficients
        (checked finite by [`checks`][]); a waveform of your own may list its own."""
        return {}

    def fastest_harmonic(self) -> int:
        """$K$: the waveform's shortest time scale is $2\\pi/(K\\omega)$, which the step guards ask
        the exact engine's `dt` to resolve (`run._resolution`). 1 here; a waveform of your own with
        faster content says so."""
        return 1

    def checks(self) -> list[Check]:
        """`(field, valid mask, valid range)` of every constraint, finite values first: finite
        coefficients, $\\omega \\ge 0$, $\\bar\\ell > 0$, and a stroke below $\\bar\\ell$ (so that
        the rest length stays positive). The masks have the waveform's batch shape."""
        out: list[Check] = [(n, jnp.isfinite(x).all(-1), "finite") for n, x in self.coefficients().items()]
        out.append(("omega", jnp.isfinite(self.omega) & (self.omega >= 0), "omega >= 0 and finite"))
        out.append(("lbar", jnp.isfinite(self.lbar) & (self.lbar > 0), "lbar > 0 and finite"))
        out.append((self.stroke_check[0], self.stroke() < self.lbar, self.stroke_check[1]))
        return out

    def is_valid(self) -> Array:
        """Traceable mask (the waveform's batch shape) of valid waveforms ([`checks`][])."""
        checks = self.checks()
        return all_valid(checks, tuple(np.broadcast_shapes(*(jnp.shape(m) for _, m, _ in checks))))

    def validate(self) -> "AbstractWaveform":
        """Raise `ValueError` at the first invalid value: the field, its valid range, the batch index."""
        values = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)} | {"stroke": self.stroke()}
        first_invalid(type(self).__name__, self.checks(), values)
        return self


class Sinusoid(AbstractWaveform):
    """The paper's actuation, eq. (13): $\\ell_0(t) = a \\sin(\\omega t) + \\bar\\ell$."""

    a: Array
    omega: Array
    lbar: Array

    stroke_check: ClassVar[tuple[str, str]] = ("a", "|a| < lbar")

    def __init__(self, a: ArrayLike, omega: ArrayLike, lbar: ArrayLike):
        self.a = real_array("a", a, "Sinusoid")
        self.omega = real_array("omega", omega, "Sinusoid")
        self.lbar = real_array("lbar", lbar, "Sinusoid")

    def coefficients(self) -> dict[str, Array]:
        return {"a": self.a[..., None]}

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

    With $N = 1$, $A_1 = 0$, $B_1 = a$ it is eq. (13). Up to
    `RECURRENCE_MAX` (4) harmonics they are
    built from $\\cos\\omega t, \\sin\\omega t$ by the angle-addition recurrence (no
    transcendental call); above, from the phase $\\phi = \\operatorname{atan2}(\\sin, \\cos)$
    as one vector $\\cos n\\phi, \\sin n\\phi$, $n = 1..N$.

    **Arguments:**

    - `cos`, `sin`: coefficient arrays $A_n$, $B_n$ of shape `(N,)`.
    - `omega`: base frequency; `lbar`: mean rest length.
    """

    cos: Float[Array, " N"]
    sin: Float[Array, " N"]
    omega: Array
    lbar: Array

    stroke_check: ClassVar[tuple[str, str]] = ("stroke", "stroke = sum_n sqrt(cos_n^2 + sin_n^2) < lbar")

    def __init__(self, cos: ValuesLike, sin: ValuesLike, omega: ArrayLike, lbar: ArrayLike):
        self.cos = real_array("cos", cos, "Fourier")
        self.sin = real_array("sin", sin, "Fourier")
        self.omega = real_array("omega", omega, "Fourier")
        self.lbar = real_array("lbar", lbar, "Fourier")
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

    def fastest_harmonic(self) -> int:
        """The number of harmonics $N$."""
        return self.harmonics

    def coefficients(self) -> dict[str, Array]:
        return {"cos": self.cos, "sin": self.sin}

    def __call__(self, t: ArrayLike) -> tuple[Array, Array]:
        return self.at_phase(jnp.cos(self.omega * t), jnp.sin(self.omega * t))[:2]

    def at_phase(self, cos: ArrayLike, sin: ArrayLike) -> tuple[Array, Array, Array]:
        c1, s1 = jnp.asarray(cos), jnp.asarray(sin)
        if self.harmonics > RECURRENCE_MAX:
            return self._at_phase_vector(c1, s1)
        l0, dl0, ddl0 = self.lbar, jnp.zeros_like(c1), jnp.zeros_like(c1)
        cn, sn = c1, s1
        for n in range(self.harmonics):  # static N: a short unrolled recurrence
            A, B = self.cos[..., n], self.sin[..., n]
            l0 = l0 + A * cn + B * sn
            dl0 = dl0 + (n + 1) * self.omega * (B * cn - A * sn)
            ddl0 = ddl0 - ((n + 1) * self.omega) ** 2 * (A * cn + B * sn)
            cn, sn = cn * c1 - sn * s1, sn * c1 + cn * s1
        return l0, dl0, ddl0

    def _at_phase_vector(self, c1: Array, s1: Array) -> tuple[Array, Array, Array]:
        phase = jnp.arctan2(s1, c1)[..., None]
        n = jnp.arange(1, self.harmonics + 1, dtype=self.cos.dtype)
        w = jnp.asarray(self.omega)[..., None]
        ndim = max(phase.ndim, self.cos.ndim, w.ndim)
        up = lambda x: x.reshape((1,) * (ndim - x.ndim) + x.shape)  # explicit broadcasting
        phase, n, w, A, B = up(phase), up(n), up(w), up(self.cos), up(self.sin)
        arg = phase * n
        cn, sn = jnp.cos(arg), jnp.sin(arg)
        val = A * cn + B * sn
        rate = B * cn - A * sn
        nw = n * w
        lbar = jnp.asarray(self.lbar)
        l0 = jnp.sum(val, axis=-1)
        return up_to(lbar, l0) + l0, jnp.sum(nw * rate, axis=-1), -jnp.sum(nw * nw * val, axis=-1)

    def stroke(self) -> Array:
        return jnp.sum(jnp.sqrt(self.cos**2 + self.sin**2), axis=-1)


def _bspline_basis(u: Array) -> tuple[Array, Array, Array]:
    """The four uniform cubic B-spline weights at the local coordinate $u \\in [0, 1)$ and their
    first two derivatives in $u$ (last axis: the control points $j - 1, j, j + 1, j + 2$)."""
    v = 1 - u
    u2, u3 = u * u, u * u * u
    w = jnp.stack([v * v * v, 3 * u3 - 6 * u2 + 4, -3 * u3 + 3 * u2 + 3 * u + 1, u3], axis=-1) / 6
    dw = jnp.stack([-3 * v * v, 9 * u2 - 12 * u, -9 * u2 + 6 * u + 3, 3 * u2], axis=-1) / 6
    ddw = jnp.stack([6 * v, 18 * u - 12, 6 - 18 * u, 6 * u], axis=-1) / 6
    return w, dw, ddw


class Spline(AbstractWaveform):
    """Periodic uniform cubic B-spline in the phase $\\phi = \\omega t$:

    $$\\ell_0(t) = \\bar\\ell + \\sum_{j=0}^{M-1} c_j\\, B_3\\Big(\\frac{M\\phi}{2\\pi} - j\\Big),$$

    with $B_3$ the cubic B-spline on four unit intervals and the control values $c_j$ repeated
    with period $M$; the curve passes near $c_j$ at the phase $2\\pi j/M$
    ($\\ell_0 - \\bar\\ell = (c_{j-1} + 4c_j + c_{j+1})/6$ there). The B-spline weights are
    non-negative and sum to one, so the stroke is bounded by the control values:
    $\\max_t |\\ell_0 - \\bar\\ell| \\le \\max_j |c_j|$, with equality where three neighbours are
    equal (a plateau). A bound on the stroke is therefore a box on the $c_j$, and a
    step-like stroke (a few control values from one bound to the other) carries no overshoot,
    unlike a truncated Fourier series. $\\ell_0$ is twice continuously differentiable, so the
    fixed-step engine keeps its order away from the knots.

    **Arguments:**

    - `control`: control values $c_j$, shape `(M,)` with $M \\ge 4$ (batched along leading axes).
    - `omega`: base frequency; `lbar`: mean rest length.
    """

    control: Float[Array, " M"]
    omega: Array
    lbar: Array

    stroke_check: ClassVar[tuple[str, str]] = ("stroke", "stroke = max_j |control_j| < lbar")

    def __init__(self, control: ArrayLike, omega: ArrayLike, lbar: ArrayLike):
        self.control = real_array("control", control, "Spline")
        self.omega = real_array("omega", omega, "Spline")
        self.lbar = real_array("lbar", lbar, "Spline")
        if self.control.ndim == 0 or self.control.shape[-1] < 4:
            raise ValueError(
                f"Spline: 'control' needs M >= 4 values along its last axis (got shape {self.control.shape})."
            )

    @property
    def knots(self) -> int:
        return self.control.shape[-1]

    def fastest_harmonic(self) -> int:
        """The number of control values $M$: the pieces span $2\\pi/(M\\omega)$."""
        return self.knots

    def coefficients(self) -> dict[str, Array]:
        return {"control": self.control}

    def __call__(self, t: ArrayLike) -> tuple[Array, Array]:
        phase = self.omega * t
        return self.at_phase(jnp.cos(phase), jnp.sin(phase))[:2]

    def at_phase(self, cos: ArrayLike, sin: ArrayLike) -> tuple[Array, Array, Array]:
        m = self.knots
        c = jnp.asarray(self.control)
        # The phase in units of the knot spacing, in [0, M).
        s = jnp.mod(jnp.arctan2(jnp.asarray(sin), jnp.asarray(cos)) * (m / (2 * jnp.pi)), m)
        j = jnp.floor(s)
        w, dw, ddw = _bspline_basis(s - j)
        offsets = jnp.arange(-1, 3, dtype=jnp.int32).reshape((1,) * j.ndim + (4,))
        idx = (j.astype(jnp.int32)[..., None] + offsets) % m
        ndim = max(idx.ndim, c.ndim)
        up = lambda x: x.reshape((1,) * (ndim - x.ndim) + x.shape)  # explicit broadcasting
        idx, c, w, dw, ddw = up(idx), up(c), up(w), up(dw), up(ddw)
        shape = jnp.broadcast_shapes(idx.shape[:-1], c.shape[:-1])
        cj = jnp.take_along_axis(jnp.broadcast_to(c, shape + c.shape[-1:]), jnp.broadcast_to(idx, shape + (4,)), -1)
        rate = jnp.asarray(self.omega) * (m / (2 * jnp.pi))  # d(s)/dt
        value, d1, d2 = jnp.sum(cj * w, -1), jnp.sum(cj * dw, -1), jnp.sum(cj * ddw, -1)
        rate, lbar = up_to(rate, value), up_to(jnp.asarray(self.lbar), value)
        return lbar + value, rate * d1, rate * rate * d2

    def stroke(self) -> Array:
        return jnp.max(jnp.abs(self.control), axis=-1)
