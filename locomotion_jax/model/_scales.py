"""The time scales a mechanism sets, which a fixed step must resolve (issue 29).

Each mechanism reports its own through `AbstractMechanism.time_scales` (the forcing's
highest harmonic, its highest natural period, its damping and Stribeck times) and
`AbstractMechanism.start_scale` (the default measurement start), so that the resolution
guards of `run._resolution` never ask which kind of mechanism they hold.
"""

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp

from ._springwaves import SpringFourier
from ._waveform import AbstractWaveform


STEPS_PER_PERIOD = 4
"""Least steps per forcing or natural period: $\\omega\\,\\Delta t \\le \\pi/2$, inside RK4's
stability interval ($|\\omega \\Delta t| < 2\\sqrt 2$) with a margin of 1.8, and twice the
sampling theorem's two points per period. The paper's figures take at least 8.8 steps per
period (Fig. 12, quick size: $\\omega_{n1} = 35.7$ at $\\hat m = 0.02$ with `dt = 0.02`),
so none of them is affected."""

STEPS_PER_TIME = 1
"""Least steps per damping time $m_i/c_i$ or Stribeck time $v_s/\\mu_s$ (not periods:
RK4 is stable for a decay rate up to $2.78/\\Delta t$)."""

MAX_START_STEPS = 10**8
"""Most nominal steps the default measurement start (`t_start`: 80 periods of the lowest
natural frequency, or a mechanism's actuation periods) may take. A valid but very soft spring
(`k = 1e-20`) would otherwise set a start of $10^{12}$ time units and a run of ages. The
paper's model at $k = 1$ starts after about 500 time units, 5e4 steps at `dt = 0.01`; an
explicit `t_start=` is never limited."""


@dataclasses.dataclass(frozen=True)
class TimeScale:
    """One time scale of every configuration of a flat batch, and what sets it.

    A scale of `unit` "period" or "time" (a decay) needs a step `dt <= time / steps`; a "span"
    (the default measurement start) needs `time / dt <= steps`, i.e. at most `steps` steps."""

    name: str  # the parameter a message names
    what: str  # e.g. "forcing period 2*pi/(K*omega)"
    time: jax.Array  # shape (size,)
    steps: int
    unit: str  # "period", a decay "time", or "span"
    shown: Mapping[str, jax.Array]  # values a message shows, each shape (size,)

    def limit(self) -> jax.Array:
        """The longest step that resolves it (a span: the shortest step that keeps it under `steps` steps)."""
        return self.time / self.steps

    def exceeded(self, dt: float) -> jax.Array:
        """Mask of the configurations that step `dt` does not serve (False for a NaN scale)."""
        if self.unit == "span":
            return self.time > dt * self.steps
        return dt > self.limit()


def flat(x: Any, size: int) -> jax.Array:
    """`x` (one value, or one per configuration) as shape `(size,)`."""
    x = jnp.asarray(x)
    return jnp.broadcast_to(x.reshape((-1,)) if x.size == size else x.reshape(()), (size,))


def harmonics(wave: Any) -> int:
    """$K$: the forcing's shortest period is $2\\pi/(K\\omega)$: a waveform's
    [`fastest_harmonic`][locomotion_jax.AbstractWaveform.fastest_harmonic] (1 for a `Sinusoid`, the
    number of harmonics of a `Fourier`, the number of knots of a `Spline`, whose pieces span
    $2\\pi/(M\\omega)$), the number of harmonics of a `SpringFourier`, 1 for a `TravellingWave`."""
    if isinstance(wave, AbstractWaveform):
        return int(wave.fastest_harmonic())
    if isinstance(wave, SpringFourier):
        return int(wave.harmonics)
    return 1


def forcing(wave: Any, omega: jax.Array) -> TimeScale:
    """The forcing's highest harmonic of a waveform."""
    K = harmonics(wave)
    what = f"forcing period 2*pi/(K*omega) (K = {K})"
    return TimeScale("omega", what, 2 * math.pi / (K * omega), STEPS_PER_PERIOD, "period", {"omega": omega})


def forcing_step(wave: Any, dt: float) -> float:
    """`dt`, or a tenth less than the longest step that resolves the forcing of `wave` (one
    waveform) where that is shorter: a step that the resolution guards accept for it."""
    limit = 2 * math.pi / (harmonics(wave) * float(wave.omega)) / STEPS_PER_PERIOD
    return min(dt, 0.9 * limit)


def free_frequency(m: jax.Array, K: jax.Array) -> jax.Array:
    """Highest natural frequency of the free linearised bodies: masses `m` (..., N), stiffness
    matrix `K` (..., N, N); batch shape."""
    s = 1 / jnp.sqrt(m)
    return jnp.sqrt(jnp.clip(jnp.linalg.eigvalsh(K * s[..., :, None] * s[..., None, :])[..., -1], 0))


def start_span(t_start: jax.Array, owner: str, shown: Mapping[str, jax.Array]) -> TimeScale:
    """The default measurement start `t_start` (flat), at most `MAX_START_STEPS` steps."""
    return TimeScale("t_start", f"default start {owner}", t_start, MAX_START_STEPS, "span", shown)
