"""Starts of the exact optimiser: strokes sampled over one period, fitted by each shape family.

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
  result: the exact engine judges it with the actuation prescribed instead).
"""

import math

import numpy as np

from ..model._params import Params


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


def _limits(params: Params, sign: float, gap: float) -> tuple[float, float]:
    """Tension magnitudes at which each mass breaks away (eq. 7) at rest at the gap `gap`, for a
    compression (`sign = -1`) or a tension (`sign = +1`): the smaller and the larger."""
    m1, m2, d, mu = float(params.m1), float(params.m2), float(params.d), float(params.mu_s)
    length = math.hypot(gap, d)
    # |fx| = tau u / l against mu_s n_i, n_1 = m1 - sign tau d / l, n_2 = m2 + sign tau d / l.
    t1 = mu * m1 * length / (gap + sign * mu * d) if gap + sign * mu * d > 0 else math.inf
    t2 = mu * m2 * length / (gap - sign * mu * d) if gap - sign * mu * d > 0 else math.inf
    return min(t1, t2), max(t1, t2)


def tension_waves(
    params: Params, periods: np.ndarray, levels: np.ndarray, grid: int = 256, cycles: int = 6
) -> np.ndarray:
    """The rest lengths $\\ell_0 - \\bar\\ell$ (physical units, centred) of the idealised inchworm
    gaits of the module docstring over their last of `cycles` periods, at `grid` phases:
    one row per pair of `periods` and `levels` (equal shapes).

    The tension magnitudes are `level` of the way from the smaller break-away force to the
    larger one (so only the mass with the smaller one slides). Integrated from rest at the
    relaxed gap by a semi-implicit Euler method, 8 sub-steps per phase sample, with the
    Coulomb law of eqs. (7, 9) (a slide ends where the velocity reaches zero and static
    friction holds); all rows at once. A row is NaN where a mass cannot be held at any
    tension (a break-away force without bound)."""
    periods, levels = np.asarray(periods, float), np.asarray(levels, float)
    m = np.array([float(params.m1), float(params.m2)])
    k, c, d, mu_k = float(params.k), float(params.c), float(params.d), float(params.mu_k)
    mu_s, lbar = float(params.mu_s), float(params.lbar)
    gap0 = math.sqrt(lbar * lbar - d * d)
    taus = np.zeros((len(periods), 2))
    for j, sign in enumerate((-1.0, 1.0)):
        lo, hi = _limits(params, sign, gap0)
        taus[:, j] = sign * (lo + levels * (hi - lo))
    sub = 8
    dt = periods[:, None] / (grid * sub)
    n = len(periods)
    x = np.tile([0.0, gap0], (n, 1))
    v, stuck = np.zeros((n, 2)), np.ones((n, 2), bool)
    out = np.zeros((n, grid))
    with np.errstate(invalid="ignore"):
        for cycle in range(cycles):
            for g in range(grid):
                tension = taus[:, :1] if g < grid // 2 else taus[:, 1:]
                for _ in range(sub):
                    u = x[:, 1:] - x[:, :1]
                    length = np.sqrt(u * u + d * d)
                    fx, fy = tension * u / length, tension * d / length
                    force = np.concatenate([fx, -fx], axis=1)  # eq. (8)
                    normal = m + np.concatenate([-fy, fy], axis=1)  # eq. (5)
                    stuck = stuck & ~(np.abs(force) > mu_s * normal)
                    sgn = np.where(v != 0, np.sign(v), np.sign(force))
                    new = np.where(stuck, 0.0, v + dt * (force - c * v - mu_k * normal * sgn) / m)
                    halt = ~stuck & (new * sgn < 0)  # the velocity reaches zero within the step
                    stuck = stuck | (halt & (np.abs(force) <= mu_s * normal))
                    v = np.where(halt, 0.0, new)
                    x = x + dt * v
                if cycle == cycles - 1:
                    u = x[:, 1] - x[:, 0]
                    out[:, g] = np.sqrt(u * u + d * d) - tension[:, 0] / k
    return out - 0.5 * (out.max(axis=1, keepdims=True) + out.min(axis=1, keepdims=True))


def tension_starts(params: Params, a_max: float, periods, levels) -> list[tuple[np.ndarray, float]]:
    """`(values, omega)` of the tension-wave starts over every pair of `periods` and `levels`:
    256 phase samples in units of $a_\\max$ (scaled down where the idealised gait needs more
    than $a_\\max$)."""
    pp, ll = (a.ravel() for a in np.meshgrid(np.asarray(periods, float), np.asarray(levels, float), indexing="ij"))
    waves = tension_waves(params, pp, ll)
    out = []
    for wave, period in zip(waves, pp):
        if np.all(np.isfinite(wave)):
            out.append((wave / max(a_max, float(np.max(np.abs(wave)))), 2 * math.pi / float(period)))
    return out
