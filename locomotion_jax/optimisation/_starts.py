"""Starts of the exact optimisers: strokes sampled over one period, fitted by each shape family.

Two kinds:

- **Generic shapes** ([`start_shapes`][]): sinusoids of several strokes, sinusoids with a
  third harmonic, saw-tooth ramps of both senses and random smooth waveforms.
- **Tension square waves** ([`tension_waves`][]): the rest length of an idealised inchworm
  gait in which the spring's tension $T$ alternates between a compression $-T_c$ and a
  tension $T_t$, each half a period. Under compression the mass whose normal force eq. (5)
  lowers slides forward while the other is held by static friction (eq. 7), under tension the
  other one; with $T_c$, $T_t$ between the break-away force of the mass that should slide and
  that of the mass that should hold, every slide goes one way, and a slide accelerates while
  its normal force is low, so that the friction it pays per distance is near the
  quasi-static floor at speeds where a sinusoid of the same stroke pays several times more.
  A sinusoid cannot hold the tension: at such speeds a slide lasts a fraction of the
  masses' natural period, and the stroke must jump by $(T_c + T_t)/k$ at each switch. The
  rest length that makes this tension is $\\ell_0(t) = \\ell(u(t)) - T(t)/k$, with the gap
  $u(t)$ of the idealised motion, integrated here with the tension prescribed (a start, not a
  result: the exact engine judges it with the actuation prescribed instead). A chain of N
  masses runs such a square wave on every spring, each a phase lag behind the one before (the
  lag of the chain optimiser's best travelling wave), under its own friction law; the paper's
  model is its one spring.
"""

import math
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ..model._chain import Chain
from ..model._friction import AbstractFriction


def _unit(values: np.ndarray, scale: float = 1.0) -> np.ndarray:
    return values * scale / np.max(np.abs(values))


def start_shapes(grid: int, seed: int, n_random: int) -> list[np.ndarray]:
    """Generic stroke shapes sampled at `grid` phases $2\\pi g/G$, in units of their stroke (at several strokes)."""
    rng = np.random.default_rng(seed)
    phase = np.arange(grid) * 2 * np.pi / grid
    h = np.arange(1, 17)
    series = lambda cos, sin: (
        np.cos(np.outer(phase, h[: len(cos)])) @ cos + np.sin(np.outer(phase, h[: len(sin)])) @ sin
    )
    sine = np.sin(phase)
    shapes = [_unit(sine, scale) for scale in (0.2, 0.35, 0.5, 0.7, 1.0)]
    for scale in (0.35, 0.5, 0.7):
        for third in (0.2, -0.2):  # resonant gaits of small stroke carry such a third harmonic
            shapes.append(_unit(sine + third * np.sin(3 * phase), scale))
            shapes.append(_unit(sine + third * np.cos(3 * phase), scale))
    saw = series(np.zeros(16), (-1.0) ** (h + 1) / h)
    shapes += [_unit(saw), _unit(-saw)]
    for _ in range(n_random):
        c, s = rng.normal(size=16) / h**2, np.eye(1, 16, 0)[0] + rng.normal(size=16) / h**2
        shapes.append(_unit(series(c, s), float(rng.uniform(0.3, 1.0))))
    return shapes


def _limits(chain: Chain, sign: float, gap: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tension magnitudes at which each end of each spring breaks away (eq. 7, per friction
    direction) at rest at the gaps `gap`, the spring alone loading its masses, for a compression
    (`sign = -1`) or a tension (`sign = +1`): per spring, the smaller and the larger."""
    m, d = np.asarray(chain.m, float), np.asarray(chain.d, float)
    fwd, bwd = (np.broadcast_to(np.asarray(mu, float), m.shape) for mu in chain.friction.static_limits())
    length = np.hypot(gap, d)
    # Spring j pulls mass j towards `sign` and mass j + 1 away from it with |fx| = tau u / l, against
    # mu n with n_j = m_j - sign tau d / l and n_{j+1} = m_{j+1} + sign tau d / l (eq. 5).
    mu0, mu1 = (fwd[:-1], bwd[1:]) if sign > 0 else (bwd[:-1], fwd[1:])
    den0, den1 = gap + sign * mu0 * d, gap - sign * mu1 * d
    with np.errstate(divide="ignore", invalid="ignore"):
        t0 = np.where(den0 > 0, mu0 * m[:-1] * length / den0, np.inf)
        t1 = np.where(den1 > 0, mu1 * m[1:] * length / den1, np.inf)
    return np.minimum(t0, t1), np.maximum(t0, t1)


def _kinetic(law: AbstractFriction, shape: tuple[int, ...]) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """The law's kinetic coefficient per mass as a function of `(speed, direction)` on the host: two
    arrays read once where it does not depend on the speed (its `kinetic_rate` is `None`), else
    the law itself, compiled."""
    one = jnp.ones(shape)
    if law.kinetic_rate(one, one, one) is None:
        fwd, bwd = (np.broadcast_to(np.asarray(law.kinetic(one, sign * one), float), shape) for sign in (1, -1))
        return lambda speed, direction: np.where(direction > 0, fwd, bwd)
    kinetic = jax.jit(lambda law, speed, direction: law.kinetic(speed, direction))
    return lambda speed, direction: np.asarray(kinetic(law, speed, direction), float)


def tension_waves(chain: Chain, periods: np.ndarray, levels: np.ndarray, lag: float = 0.0, grid: int = 256,
                  cycles: int = 6) -> np.ndarray:  # fmt: skip
    """The rest lengths $\\ell_{0,j} - \\bar\\ell_j$ (physical units, each centred) of the idealised
    inchworm gaits of the module docstring over their last of `cycles` periods, at `grid` phases:
    shape `(rows, springs, grid)`, one row per pair of `periods` and `levels` (equal shapes).

    Spring $j$'s tension is a compression for the first half of its period and a tension for the
    second, its period starting `j * lag` radians later than spring 0's (a travelling inchworm; one
    spring, $N = 2$: the paper's model). Its magnitudes are `level` of the way from the smaller
    break-away force of its two masses to the larger one (so only the mass with the smaller one
    slides, under this spring's load alone). Integrated from rest at the relaxed gaps by a
    semi-implicit Euler method, 8 sub-steps per phase sample, with the chain's friction law (eqs. 7,
    9 per mass and direction: a slide ends where the velocity reaches zero and static friction
    holds); all rows at once. A row is NaN where a mass cannot be held at any tension (a
    break-away force without bound). `chain`: one configuration, the rest-length actuator.

    The prescribed tensions do not tie the masses' mean speeds together, so a gap of the idealised
    motion need not return after a period: the rest length then jumps at the period's end too
    (a start; the engine runs it with the rest lengths prescribed, where the springs hold the
    gaps)."""
    periods, levels = np.asarray(periods, float), np.asarray(levels, float)
    chain = chain.broadcast()
    m, c = np.asarray(chain.m, float), np.asarray(chain.c, float)
    k, d, lbar = np.asarray(chain.k, float), np.asarray(chain.d, float), np.asarray(chain.lbar, float)
    fwd, bwd = (np.broadcast_to(np.asarray(mu, float), m.shape) for mu in chain.friction.static_limits())
    kinetic = _kinetic(chain.friction, m.shape)
    gap0 = np.sqrt(lbar * lbar - d * d)
    S = gap0.size
    taus = np.zeros((len(periods), S, 2))
    for j, sign in enumerate((-1.0, 1.0)):
        lo, hi = _limits(chain, sign, gap0)
        taus[..., j] = sign * (lo + levels[:, None] * (hi - lo))
    # Spring j is in compression at phase sample g where (g - shift_j) mod grid < grid / 2.
    shift = np.rint(np.arange(S) * lag / (2 * math.pi) * grid).astype(int)
    compressed = (np.arange(grid)[:, None] - shift[None, :]) % grid < grid // 2
    sub = 8
    dt = periods[:, None] / (grid * sub)
    n = len(periods)
    x = np.tile(np.concatenate([[0.0], np.cumsum(gap0)]), (n, 1))
    v, stuck = np.zeros((n, S + 1)), np.ones((n, S + 1), bool)
    out = np.zeros((n, S, grid))
    zero = np.zeros((n, 1))
    pad = lambda f: (np.concatenate([f, zero], 1), np.concatenate([zero, f], 1))  # spring j's on mass j, j + 1
    with np.errstate(invalid="ignore"):
        for cycle in range(cycles):
            for g in range(grid):
                tension = np.where(compressed[g], taus[..., 0], taus[..., 1])
                for _ in range(sub):
                    u = x[:, 1:] - x[:, :-1]
                    length = np.sqrt(u * u + d * d)
                    fx, fy = tension * u / length, tension * d / length
                    own, last = pad(fx)
                    force = own - last  # eq. (8)
                    own, last = pad(fy)
                    normal = m - own + last  # eq. (5)
                    stuck = stuck & ~((force > fwd * normal) | (force < -bwd * normal))
                    sgn = np.where(v != 0, np.sign(v), np.sign(force))
                    mu = kinetic(np.abs(v), sgn)
                    new = np.where(stuck, 0.0, v + dt * (force - c * v - mu * normal * sgn) / m)
                    halt = ~stuck & (new * sgn < 0)  # the velocity reaches zero within the step
                    stuck = stuck | (halt & (force <= fwd * normal) & (force >= -bwd * normal))
                    v = np.where(halt, 0.0, new)
                    x = x + dt * v
                if cycle == cycles - 1:
                    u = x[:, 1:] - x[:, :-1]
                    out[:, :, g] = np.sqrt(u * u + d * d) - tension / k
    return out - 0.5 * (out.max(axis=2, keepdims=True) + out.min(axis=2, keepdims=True))


def tension_starts(chain: Chain, a_max: float, periods: Any, levels: Any, lag: float = 0.0,
                   ) -> list[tuple[np.ndarray, float, float]]:  # fmt: skip
    """`(values, omega, level)` of the tension-wave starts ([`tension_waves`][]) over every pair
    of `periods` and `levels` where the idealised gait exists: `values` `(springs, 256)` phase
    samples in units of $a_\\max$ (all springs scaled down together where the idealised gait
    needs more than $a_\\max$)."""
    pp, ll = (a.ravel() for a in np.meshgrid(np.asarray(periods, float), np.asarray(levels, float), indexing="ij"))
    waves = tension_waves(chain, pp, ll, lag)
    out = []
    for wave, period, level in zip(waves, pp, ll):
        if np.all(np.isfinite(wave)):
            out.append((wave / max(a_max, float(np.max(np.abs(wave)))), 2 * math.pi / float(period), float(level)))
    return out
