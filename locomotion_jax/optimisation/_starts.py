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
  model is its one spring. A mechanism ([`mechanism_tension_waves`][]) runs one on every actuated
  element with two ends (a spring's rest length, an internal force), its other elements, carried
  weights and friction laws acting as in the engine; both integrate by `_inchworm`.
"""

import math
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ..dynamics._motion import with_velocity
from ..model._bodies import Mechanism
from ..model._chain import Chain
from ..model._elements import ExternalForce, Force, Spring, TiltedSpring, WALL
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


def _inchworm(loads: Callable, signal: Callable, taus: np.ndarray, m: np.ndarray, c: np.ndarray, fwd: np.ndarray,
              bwd: np.ndarray, kinetic: Callable, x0: np.ndarray, periods: np.ndarray, lag: float, grid: int,
              cycles: int) -> np.ndarray:  # fmt: skip
    """The idealised inchworm's signals of [`tension_waves`][] over the last of `cycles` periods at
    `grid` phases, `(rows, elements, grid)`, each centred, integrated from rest at `x0` (bodies) with
    the prescribed tensions `taus` `(rows, elements, 2)` (compression, tension): `loads(tension, x,
    v)` the bodies' horizontal forces and normal loads `(rows, bodies)`, `signal(tension, x)` the
    signals that make these tensions, `m`, `c` the masses and ground damping, `fwd`, `bwd` the
    static limits and `kinetic(speed, direction)` the kinetic coefficient per body (eqs. 7, 9)."""
    S = taus.shape[1]
    # Element j is in compression at phase sample g where (g - shift_j) mod grid < grid / 2.
    shift = np.rint(np.arange(S) * lag / (2 * math.pi) * grid).astype(int)
    compressed = (np.arange(grid)[:, None] - shift[None, :]) % grid < grid // 2
    sub = 8
    dt = periods[:, None] / (grid * sub)
    n = len(periods)
    x = np.tile(x0, (n, 1))
    v, stuck = np.zeros_like(x), np.ones(x.shape, bool)
    out = np.zeros((n, S, grid))
    with np.errstate(invalid="ignore"):
        for cycle in range(cycles):
            for g in range(grid):
                tension = np.where(compressed[g], taus[..., 0], taus[..., 1])
                for _ in range(sub):
                    force, normal = loads(tension, x, v)
                    stuck = stuck & ~((force > fwd * normal) | (force < -bwd * normal))
                    sgn = np.where(v != 0, np.sign(v), np.sign(force))
                    mu = kinetic(np.abs(v), sgn)
                    new = np.where(stuck, 0.0, v + dt * (force - c * v - mu * normal * sgn) / m)
                    halt = ~stuck & (new * sgn < 0)  # the velocity reaches zero within the step
                    stuck = stuck | (halt & (force <= fwd * normal) & (force >= -bwd * normal))
                    v = np.where(halt, 0.0, new)
                    x = x + dt * v
                if cycle == cycles - 1:
                    out[:, :, g] = signal(tension, x)
    return out - 0.5 * (out.max(axis=2, keepdims=True) + out.min(axis=2, keepdims=True))


def _magnitudes(lo: np.ndarray, hi: np.ndarray, levels: np.ndarray) -> np.ndarray:
    """Per row and element, the tension magnitude `level` of the way from `lo` to `hi`."""
    return lo + levels[:, None] * (hi - lo)


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
    gap0 = np.sqrt(lbar * lbar - d * d)
    taus = np.zeros((len(periods), gap0.size, 2))
    for j, sign in enumerate((-1.0, 1.0)):
        taus[..., j] = sign * _magnitudes(*_limits(chain, sign, gap0), levels)

    def loads(tension, x, v):
        u = x[:, 1:] - x[:, :-1]
        length = np.sqrt(u * u + d * d)
        fx, fy = tension * u / length, tension * d / length
        zero = np.zeros((len(x), 1))
        pad = lambda f: (np.concatenate([f, zero], 1), np.concatenate([zero, f], 1))  # spring j's on mass j, j + 1
        own, last = pad(fx)
        force = own - last  # eq. (8)
        own, last = pad(fy)
        return force, m - own + last  # eq. (5)

    def signal(tension, x):
        u = x[:, 1:] - x[:, :-1]
        return np.sqrt(u * u + d * d) - tension / k

    x0 = np.concatenate([[0.0], np.cumsum(gap0)])
    kinetic = _kinetic(chain.friction, m.shape)
    return _inchworm(loads, signal, taus, m, c, fwd, bwd, kinetic, x0, periods, lag, grid, cycles)


def _end_limit(P: Any, contact: list[bool], end: "int | str", pulled: float, h: float, q: float, sign: float) -> float:
    """The tension magnitude at which `end` of an element breaks away at rest, the element alone
    loading it: its horizontal pull $\\tau h$ in direction `pulled` against $\\mu$ times the normal
    load, lowered by $\\text{sign}\\,\\tau q$ (eqs. 5, 7). A wall never slides (infinite); a
    body without ground contact of its own (carried or free) slides at any tension (0)."""
    if end == WALL:
        return math.inf
    i = int(end)
    if not contact[i]:
        return 0.0
    mu_b = P.mu_f[i] if P.mu_b[i] is None else P.mu_b[i]
    mu = float(P.mu_f[i] if pulled > 0 else mu_b)
    den = h + sign * mu * q
    return mu * float(P.normal[i]) / den if den > 0 else math.inf


def mechanism_tension_waves(mech: Mechanism, periods: np.ndarray, levels: np.ndarray, lag: float = 0.0,
                            grid: int = 256, cycles: int = 6) -> np.ndarray | None:  # fmt: skip
    """[`tension_waves`][] of a [`Mechanism`][locomotion_jax.Mechanism] (one configuration): the
    idealised inchworms of its actuated elements (`Mechanism.actuated`), element $j$'s tension a
    square wave lagged by $j$ `lag`, its magnitudes `level` of the way between the break-away
    forces of its two ends at the mechanism's start `x0` (`_end_limit`). The other elements act as
    in the mechanism (its physics' loads, with the actuated ones' rest lengths set to make the
    prescribed tensions), under each body's own friction law, its carried weights included. The
    signals: a spring's rest length $u - T/k$ (a tilted one's $\\ell(u) - T/k$), an internal
    force's $-T$ (it pushes its ends apart). `None` where an actuated element is an external force
    (it has no two ends to alternate between)."""
    periods, levels = np.asarray(periods, float), np.asarray(levels, float)
    mech = mech.broadcast()
    P = mech.physics()
    actuated = mech.actuated()
    elements = [mech.links[i] for i in actuated]
    contact = [law is not None for law in mech.friction]
    if not elements or any(isinstance(el, ExternalForce) for el in elements):
        return None
    n_bodies = mech.n_bodies
    x0 = np.asarray(mech.x0, float)
    at = lambda x, end: 0.0 if end == WALL else x[int(end)]
    # Per element: horizontal fraction h, vertical fraction q and the direction of its pull on `a`
    # under tension (a spring's and a force's along the line; a tilted spring's along (u, d)/l).
    taus = np.zeros((len(periods), len(elements), 2))
    for j, el in enumerate(elements):
        end_a, end_b = el.bodies()
        u = at(x0, end_b) - at(x0, end_a)
        d = float(el.d) if isinstance(el, TiltedSpring) else 0.0
        length = math.hypot(u, d) if isinstance(el, TiltedSpring) else 1.0
        h, q = (abs(u) / length, d / length) if isinstance(el, TiltedSpring) else (1.0, 0.0)
        pull = math.copysign(1.0, u) if isinstance(el, TiltedSpring) else 1.0
        for col, sign in enumerate((-1.0, 1.0)):
            ta = _end_limit(P, contact, end_a, sign * pull, h, q, sign)
            tb = _end_limit(P, contact, end_b, -sign * pull, h, -q, sign)
            taus[:, j, col] = sign * _magnitudes(np.asarray(min(ta, tb)), np.asarray(max(ta, tb)), levels)[:, 0]
    drive = P.drive(P.one, 0 * P.one)
    kinds = (Spring, TiltedSpring, Force)
    # Each actuated element's place among the drive's entries of its kind.
    slots = [sum(isinstance(e, type(mech.links[i])) for e in mech.links[:i]) for i in actuated]

    def rests(T, x):  # the drive that makes the actuated elements' tensions T
        l0, r, f = list(drive.l0), list(drive.r), list(drive.f)
        for j, (el, slot) in enumerate(zip(elements, slots)):
            end_a, end_b = el.bodies()
            u = at(x, end_b) - at(x, end_a)
            if isinstance(el, Spring):
                l0[slot] = u - T[j] / el.k
            elif isinstance(el, TiltedSpring):
                r[slot] = jnp.sqrt(u * u + el.d * el.d) - T[j] / el.k
            else:
                f[slot] = -T[j]
        return drive._replace(l0=tuple(l0), r=tuple(r), f=tuple(f))

    def one(T, x, v):
        xs, vs = tuple(x[i] for i in range(n_bodies)), tuple(v[i] for i in range(n_bodies))
        L = P.loads(rests(T, xs), xs)
        return jnp.stack(with_velocity(P, L.F, vs)), jnp.stack(L.N)

    def own(T, x):
        xs = tuple(x[i] for i in range(n_bodies))
        dr = rests(T, xs)
        return jnp.stack([(dr.l0, dr.r, dr.f)[kinds.index(type(el))][slot] for el, slot in zip(elements, slots)])

    batched, signals = jax.jit(jax.vmap(one)), jax.jit(jax.vmap(own))

    def loads(tension, x, v):
        F, N = batched(tension, x, v)
        return np.asarray(F, float), np.asarray(N, float)

    signal = lambda tension, x: np.asarray(signals(tension, x), float)
    m, c = np.asarray(mech.m, float), np.array([float(q) for q in P.c])
    fwd = np.array([float(q) for q in P.mu_f])
    bwd = np.array([float(f if b is None else b) for f, b in zip(P.mu_f, P.mu_b)])
    laws = [_kinetic(law, ()) for law in P.friction]
    kinetic = lambda speed, direction: np.stack([k(speed[:, i], direction[:, i]) for i, k in enumerate(laws)], 1)
    return _inchworm(loads, signal, taus, m, c, fwd, bwd, kinetic, x0, periods, lag, grid, cycles)


def tension_starts(waves: Callable[[np.ndarray, np.ndarray], np.ndarray | None], a_max: float, periods: Any,
                   levels: Any) -> list[tuple[np.ndarray, float, float]]:  # fmt: skip
    """`(values, omega, level)` of the tension-wave starts over every pair of `periods` and `levels`
    where the idealised gait exists: `waves(periods, levels)` their signals ([`tension_waves`][] of
    a chain, [`mechanism_tension_waves`][] of a mechanism; `None`: none), `values` `(elements, 256)`
    phase samples in units of $a_\\max$ (all elements scaled down together where the idealised gait
    needs more than $a_\\max$)."""
    pp, ll = (a.ravel() for a in np.meshgrid(np.asarray(periods, float), np.asarray(levels, float), indexing="ij"))
    signals = waves(pp, ll)
    out = []
    for wave, period, level in zip([] if signals is None else signals, pp, ll):
        if np.all(np.isfinite(wave)):
            out.append((wave / max(a_max, float(np.max(np.abs(wave)))), 2 * math.pi / float(period), float(level)))
    return out
