"""Decision vectors of the exact optimiser: the families of stroke shapes it searches.

A decision vector $\\theta$ holds a waveform's shape in units of $a_\\max$ and, last,
$\\log\\omega$. Two families:

- [`FourierShape`][]: $\\theta = (A_2, \\dots, A_N, B_1, \\dots, B_N, \\log\\omega)$ of a
  [`Fourier`][] series with $A_1 = 0$ (a shift of the time origin changes no gait, and fixing
  the first harmonic's phase removes that direction). Its stroke is a norm of the
  coefficients, kept by radial rescaling.
- [`SplineShape`][]: $\\theta = (c_0, \\dots, c_{M-1}, \\log\\omega)$, the control values of a
  periodic cubic B-spline ([`Spline`][]). Its stroke is bounded by $\\max_j |c_j|$ (convex
  hull), so the stroke constraint is the box $|c_j| \\le 1$, kept by clipping, and a
  step-like stroke carries no Gibbs overshoot.

Each family maps $\\theta$ to its waveform (traced, batched along leading axes), fits
$\\theta$ to a stroke sampled over one period (the starts, and a start of the other family),
keeps $\\theta$ within the stroke, and gives the stroke constraint to scipy's local solvers.
"""

import abc
import math
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array
from ..model._waveform import AbstractWaveform, Fourier, Spline
from . import _constraints as cons


class AbstractShape(eqx.Module):
    """A family of stroke shapes (static: its size is a compile-time constant)."""

    name: ClassVar[str]

    @property
    @abc.abstractmethod
    def size(self) -> int:
        """Length of the decision vector, $\\log\\omega$ included."""

    @abc.abstractmethod
    def waveform(self, theta: Array, a_max: Array, lbar: Array) -> AbstractWaveform:
        """Decision vector(s) -> waveform (traced; batched along leading axes)."""

    @abc.abstractmethod
    def fit(self, values: np.ndarray, omega: float) -> np.ndarray:
        """The decision vector of a stroke sampled at the phases $2\\pi g/G$, $g = 0..G-1$
        (`values`: $\\ell_0 - \\bar\\ell$ in units of $a_\\max$), within the stroke limit."""

    @abc.abstractmethod
    def project(self, theta: np.ndarray) -> np.ndarray:
        """`theta` moved into $\\{\\text{stroke} \\le 1\\}$ (identity inside); $\\omega$ untouched."""

    @abc.abstractmethod
    def stroke(self, theta: np.ndarray) -> float:
        """$\\max_t |\\ell_0 - \\bar\\ell|$ in units of $a_\\max$, located exactly."""

    @abc.abstractmethod
    def constraint(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Stroke constraints $g(\\theta) \\ge 0$ and their Jacobian, for scipy's local solvers."""

    @abc.abstractmethod
    def fields(self, theta: np.ndarray, a_max: float) -> dict:
        """The [`Optimum`][locomotion_jax.optimisation._optimum.Optimum] fields of the waveform
        (`cos`, `sin`, `control`, `harmonics`, `shape`)."""

    @property
    def origins(self) -> tuple[float, ...]:
        """Time shifts (in periods) that [`shift`][locomotion_jax.optimisation._shapes.AbstractShape.shift]
        represents exactly."""
        return (0.0,)

    def shift(self, theta: np.ndarray, turns: float) -> np.ndarray:
        """The same stroke with its time origin moved by `turns` periods: $\\ell_0(\\phi + 2\\pi\\,\\text{turns})$."""
        if turns != 0:
            raise ValueError(f"{type(self).__name__} represents no time shift of {turns!r} periods.")
        return np.array(theta, float)

    def sample(self, wave: AbstractWaveform, grid: int) -> np.ndarray:
        """$\\ell_0 - \\bar\\ell$ of any waveform at `grid` phases over one period."""
        phase = np.arange(grid) * 2 * np.pi / grid
        l0, _, _ = wave.at_phase(jnp.asarray(np.cos(phase)), jnp.asarray(np.sin(phase)))
        return np.asarray(l0, float) - float(np.asarray(wave.lbar))


# -- Fourier series --------------------------------------------------------------------


def normalise_phase(cos: np.ndarray, sin: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Shift the time origin so that $A_1 = 0$, $B_1 \\ge 0$ (the same gait). `cos`, `sin`: `(H,)`,
    or `(S, H)` for `S` signals of one gait, all shifted by the time that zeroes the first one's $A_1$."""
    n = np.arange(1, np.shape(cos)[-1] + 1)
    d = math.atan2(-np.ravel(cos)[0], np.ravel(sin)[0])
    return cos * np.cos(n * d) + sin * np.sin(n * d), sin * np.cos(n * d) - cos * np.sin(n * d)


def to_theta(cos, sin, omega: float, a_max: float, harmonics: int) -> np.ndarray:
    """Fourier coefficients (padded or truncated to `harmonics`) -> decision vector."""
    c = np.zeros(harmonics)
    s = np.zeros(harmonics)
    m = min(harmonics, len(cos))
    c[:m], s[:m] = np.asarray(cos, float)[:m], np.asarray(sin, float)[:m]
    c, s = normalise_phase(c, s)
    return np.concatenate([c[1:] / a_max, s / a_max, [math.log(omega)]])


def from_theta(theta: np.ndarray, a_max: float, harmonics: int) -> tuple[np.ndarray, np.ndarray, float]:
    """Decision vector -> `(cos, sin, omega)` of a Fourier series."""
    n = harmonics
    cos = a_max * np.concatenate([[0.0], theta[: n - 1]])
    return cos, a_max * theta[n - 1 : 2 * n - 1], float(np.exp(theta[-1]))


def _stroke_rows(harmonics: int, phases: np.ndarray) -> np.ndarray:
    """$s(\\phi_j) = \\text{rows} \\cdot \\theta$ (units of $a_\\max$) at the given phases."""
    n = np.arange(1, harmonics + 1)
    arg = np.outer(phases, n)
    return np.concatenate([np.cos(arg)[:, 1:], np.sin(arg), np.zeros((len(phases), 1))], axis=1)


class StrokePeaks:
    """The Fourier stroke constraint by local reduction: $1 - \\max_{\\phi \\in W_k} |s(\\phi)| \\ge 0$
    on `count` fixed, equal windows $W_k$ of the phase (units of $a_\\max$).

    The maximum over a fixed window is a continuous function of $\\theta$ (unlike, say, the
    $k$-th highest local maximum, which jumps when a ripple appears), so a local solver
    sees no jumps. It is bracketed on a grid of 64 phases per harmonic and polished by
    Newton's method on $s' = 0$ within the window; its gradient is
    $\\operatorname{sgn} s(\\phi_k)\\,\\partial s(\\phi_k)/\\partial\\theta$ at the maximiser (envelope
    theorem). With two windows per harmonic, every maximum of $|s|$ is in some window, so
    bounding them all linearises $|s(\\phi)| \\le 1$ for all $\\phi$.
    """

    def __init__(self, harmonics: int):
        self.harmonics = harmonics
        self.count = 2 * harmonics
        m = 64 * harmonics
        self.grid = np.arange(m) * 2 * np.pi / m
        self.rows = _stroke_rows(harmonics, self.grid)
        self.width = 2 * np.pi / self.count

    def peaks(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per window: the phase of the largest $|s|$ and the signed value there."""
        n = np.arange(1, self.harmonics + 1)
        a = np.abs(self.rows @ theta).reshape(self.count, -1)
        j = np.argmax(a, axis=1)
        phi = self.grid.reshape(self.count, -1)[np.arange(self.count), j]
        lo = np.arange(self.count) * self.width
        c = np.concatenate([[0.0], theta[: self.harmonics - 1]])
        s = theta[self.harmonics - 1 : 2 * self.harmonics - 1]
        h = self.grid[1]
        for _ in range(4):
            arg = np.outer(phi, n)
            d1 = (n * (s * np.cos(arg) - c * np.sin(arg))).sum(1)
            d2 = -(n * n * (c * np.cos(arg) + s * np.sin(arg))).sum(1)
            # Newton on s' = 0 toward a maximum of |s| (a minimum of s where s < 0).
            val = _stroke_rows(self.harmonics, phi) @ theta
            step = np.where(val * d2 < 0, -d1 / np.where(d2 != 0, d2, 1), 0)
            new = np.clip(phi + np.clip(step, -h, h), lo, lo + self.width)
            better = np.abs(_stroke_rows(self.harmonics, new) @ theta) > np.abs(val)
            phi = np.where(better, new, phi)
        return phi, _stroke_rows(self.harmonics, phi) @ theta

    def __call__(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Constraint values `(count,)` and their Jacobian `(count, p)`."""
        phi, val = self.peaks(theta)
        return 1 - np.abs(val), -np.sign(val)[:, None] * _stroke_rows(self.harmonics, phi)


class FourierShape(AbstractShape):
    """A [`Fourier`][] series of `harmonics` harmonics (module docstring)."""

    harmonics: int = eqx.field(static=True)
    name: ClassVar[str] = "fourier"

    def __check_init__(self):
        if self.harmonics < 2:
            raise ValueError(f"FourierShape: harmonics must be >= 2, got {self.harmonics!r}.")

    @property
    def size(self) -> int:
        return 2 * self.harmonics

    def waveform(self, theta: Array, a_max: Array, lbar: Array) -> Fourier:
        n = self.harmonics
        zero = jnp.zeros(theta.shape[:-1] + (1,), theta.dtype)
        cos = a_max * jnp.concatenate([zero, theta[..., : n - 1]], axis=-1)
        sin = a_max * theta[..., n - 1 : 2 * n - 1]
        return Fourier(cos, sin, jnp.exp(theta[..., -1]), lbar + 0 * theta[..., -1])

    def fit(self, values: np.ndarray, omega: float) -> np.ndarray:
        # The discrete Fourier transform is exact for a series of fewer than G/2 harmonics.
        c = np.fft.rfft(np.asarray(values, float)) / len(values)
        m = min(self.harmonics, len(c) - 1)
        cos, sin = np.zeros(self.harmonics), np.zeros(self.harmonics)
        cos[:m], sin[:m] = 2 * c.real[1 : m + 1], -2 * c.imag[1 : m + 1]
        return self.project(to_theta(cos, sin, omega, 1.0, self.harmonics))

    def project(self, theta: np.ndarray) -> np.ndarray:
        theta = np.array(theta, float)
        s = self.stroke(theta)
        if s > 1:
            theta[:-1] /= s
        return theta

    def stroke(self, theta: np.ndarray) -> float:
        c, s, _ = from_theta(theta, 1.0, self.harmonics)
        return float(cons.stroke(jnp.asarray(c), jnp.asarray(s)))

    def constraint(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return StrokePeaks(self.harmonics)(theta)

    def fields(self, theta: np.ndarray, a_max: float) -> dict:
        c, s, _ = from_theta(theta, a_max, self.harmonics)
        return dict(cos=c, sin=s, control=None, harmonics=self.harmonics, shape=self.name)


# -- periodic cubic B-spline -----------------------------------------------------------


def spline_stroke(control: np.ndarray) -> float:
    """Exact $\\max_\\phi |\\ell_0 - \\bar\\ell|$ of a [`Spline`][] with these control values: on each
    knot interval the stroke is a cubic in the local coordinate $u$, whose extremes are at
    $u = 0$, $u = 1$ or a root of its derivative (a quadratic)."""
    c = np.asarray(control, float)
    p = np.stack([np.roll(c, 1), c, np.roll(c, -1), np.roll(c, -2)], axis=-1)  # c_{j-1} .. c_{j+2}
    # Power-basis coefficients of the cubic a0 + a1 u + a2 u^2 + a3 u^3 per interval.
    basis = np.array([[1, 4, 1, 0], [-3, 0, 3, 0], [3, -6, 3, 0], [-1, 3, -3, 1]]) / 6
    a = p @ basis.T
    qa, qb, qc = 3 * a[:, 3], 2 * a[:, 2], a[:, 1]
    disc = np.maximum(qb * qb - 4 * qa * qc, 0.0)
    sq = np.sqrt(disc)
    safe = np.where(np.abs(qa) > 1e-300, qa, 1.0)
    roots = np.stack([(-qb + sq) / (2 * safe), (-qb - sq) / (2 * safe)], axis=-1)
    linear = np.where(np.abs(qb) > 1e-300, -qc / np.where(np.abs(qb) > 1e-300, qb, 1.0), 0.0)
    roots = np.where(np.abs(qa)[:, None] > 1e-300, roots, linear[:, None])
    u = np.concatenate([np.zeros((len(c), 1)), np.ones((len(c), 1)), np.clip(roots, 0.0, 1.0)], axis=-1)
    vals = a[:, :1] + u * (a[:, 1:2] + u * (a[:, 2:3] + u * a[:, 3:4]))
    return float(np.max(np.abs(vals)))


class SplineShape(AbstractShape):
    """A periodic cubic B-spline of `knots` control values (module docstring)."""

    knots: int = eqx.field(static=True)
    name: ClassVar[str] = "spline"

    def __check_init__(self):
        if self.knots < 4:
            raise ValueError(f"SplineShape: knots must be >= 4, got {self.knots!r}.")

    @property
    def size(self) -> int:
        return self.knots + 1

    def waveform(self, theta: Array, a_max: Array, lbar: Array) -> Spline:
        return Spline(a_max * theta[..., :-1], jnp.exp(theta[..., -1]), lbar + 0 * theta[..., -1])

    def fit(self, values: np.ndarray, omega: float) -> np.ndarray:
        # Interpolate at the knots: the spline's value there is (c_{j-1} + 4 c_j + c_{j+1})/6, a
        # circulant system that the discrete Fourier transform diagonalises.
        g = len(values)
        phase = np.arange(self.knots) * g / self.knots
        y = np.interp(phase, np.arange(g + 1), np.r_[values, values[:1]])
        k = np.arange(self.knots)
        eig = (4 + 2 * np.cos(2 * np.pi * k / self.knots)) / 6
        c = np.real(np.fft.ifft(np.fft.fft(y) / eig))
        return self.project(np.r_[c, math.log(omega)])

    @property
    def origins(self) -> tuple[float, ...]:
        # Quarter periods: a section a quarter period away from one where a mass is about to
        # stop (the inchworm gaits' two halves mirror each other, so half a period is not).
        return (0.0, (self.knots // 4) / self.knots)

    def shift(self, theta: np.ndarray, turns: float) -> np.ndarray:
        j = round(turns * self.knots)
        if abs(j - turns * self.knots) > 1e-9:
            raise ValueError(f"a spline of {self.knots} knots shifts by whole knots, not {turns!r} periods.")
        theta = np.array(theta, float)
        theta[:-1] = np.roll(theta[:-1], -j)
        return theta

    def project(self, theta: np.ndarray) -> np.ndarray:
        theta = np.array(theta, float)
        theta[:-1] = np.clip(theta[:-1], -1.0, 1.0)
        return theta

    def stroke(self, theta: np.ndarray) -> float:
        return spline_stroke(theta[:-1])

    def constraint(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        c = np.asarray(theta[:-1], float)
        jac = np.zeros((self.knots, self.size))
        jac[np.arange(self.knots), np.arange(self.knots)] = -np.sign(c)
        return 1 - np.abs(c), jac

    def fields(self, theta: np.ndarray, a_max: float) -> dict:
        empty = np.zeros(0)
        return dict(cos=empty, sin=empty, control=a_max * np.asarray(theta[:-1], float), harmonics=0, shape=self.name)
