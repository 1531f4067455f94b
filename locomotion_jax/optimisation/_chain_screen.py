"""The chain optimiser's baseline: travelling waves screened on a grid and zoomed, on steady gaits.

A travelling wave $s_j(t) = a\\sin(\\omega t - j\\varphi)$ ([`TravellingWave`][]) has the stroke $a$
on every spring. The screen solves the steady gait ([`steady_gait`][], exact model, strict
contact, from the relaxed springs) of every wave of a grid over $(a, \\omega, \\varphi)$ in
chunks of one shape (one compilation, shared with the verification of the refined
actuations: the waves are padded to their number of harmonics), then zooms in around the
best wave that meets the requirement: per level a grid of a few points per variable over one
step either side of it, the step halved. Only the waves whose transient ends at half the
required speed or more (`screen_speed`), and the fastest, have their gaits solved.
"""

import math
import time
from collections.abc import Callable
from typing import Any, cast, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..dynamics._exact_dynamics import Exact
from ..gaits._orbit import PATIENCE
from ..gaits._select import GaitStatus
from ..gaits._shooting import steady_gait_chain, transient_speed
from ..model._chain import Chain
from ..model._springwaves import SpringFourier
from ._element_local import sampled_start, screen_rows, Start
from ._element_optimum import ChainOptimiseSettings
from ._optimum import along
from ._starts import tension_starts, tension_waves


def free_frequencies(chain: Chain) -> np.ndarray:
    """Natural frequencies of the free linearised chain (springs $k_j$ between neighbours; the
    rigid mode dropped): for $N = 2$, $\\omega_{n1} = \\sqrt{k(m_1 + m_2)/(m_1 m_2)}$ (eq. 11)."""
    m = np.asarray(chain.m, np.float64)
    k = np.broadcast_to(np.asarray(chain.k, np.float64), (m.size - 1,))
    K = np.zeros((m.size, m.size))
    for j, kj in enumerate(k):
        K[j : j + 2, j : j + 2] += kj * np.array([[1.0, -1.0], [-1.0, 1.0]])
    s = 1 / np.sqrt(m)
    ev = np.linalg.eigvalsh(K * s[:, None] * s[None, :])
    return np.sqrt(np.clip(np.sort(ev)[1:], 0, None))


def frequency_range(chain: Chain, omega: float | None, settings: ChainOptimiseSettings) -> tuple[float, float]:
    """Range of the base frequency: `omega` if fixed, else from the natural frequencies (settings)."""
    if omega is not None:
        return float(omega), float(omega)
    lo = settings.omega_min * float(chain.omega_min)
    return lo, settings.omega_max * float(free_frequencies(chain).max())


class Gaits(NamedTuple):
    """Steady-gait figures of a batch of actuations (host arrays, one row each)."""

    speed: np.ndarray
    cost: np.ndarray
    ok: np.ndarray  # converged, stable, no lift-off
    liftoff: np.ndarray
    k: np.ndarray
    period: np.ndarray
    radius: np.ndarray  # largest Floquet multiplier modulus
    min_normal: np.ndarray  # the smallest normal force on the orbit (`Gait.min_normal`)
    y: np.ndarray  # the orbit's reduced state at the section


def with_actuation(chain: Chain, cos: np.ndarray, sin: np.ndarray, omega: np.ndarray) -> Chain:
    """A batch of copies of one (broadcast) chain with the given coefficients `(B, S, H)` and `omega` `(B,)`."""
    B = omega.shape[0]
    dtype = chain.dtype
    batch = jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (B,) + x.shape), chain)
    waves = SpringFourier(jnp.asarray(cos, dtype), jnp.asarray(sin, dtype), jnp.asarray(omega, dtype))
    return batch.with_waves(waves)


LAST = 12
"""Periods at the end of the transient over which the screen measures a wave's speed
([`transient_speed`][]): whole gait periods of every $k \\le 4$."""


def fast_enough(v: np.ndarray, v_min: float, direction: int, fraction: float, count: int) -> np.ndarray:
    """Rows, in order, of the waves whose transient speed `v` reaches `fraction` of `v_min` in
    `direction`, and of the `count` fastest (a closest candidate when none is feasible); never one
    whose speed is NaN (its transient stopped)."""
    fast = along(v, direction)
    keep = fast >= fraction * v_min
    keep[np.argsort(-fast, kind="stable")[:count]] = True
    return np.flatnonzero(keep & np.isfinite(v))


def _unsolved(n: int, n_red: int) -> Gaits:
    """Rows of waves whose gaits are not solved (each field its own array: the screen fills them in)."""
    nan, no = lambda: np.full(n, np.nan), lambda: np.zeros(n, bool)
    return Gaits(nan(), nan(), no(), no(), np.zeros(n, np.int32), nan(), nan(), nan(), np.full((n, n_red), np.nan))


def _chunks(n: int, chunk: int, order: np.ndarray):
    """`(rows, count)` per chunk of `chunk` rows in `order`; the last padded by repeats: one shape."""
    for b in range(0, n, chunk):
        yield order[np.minimum(np.arange(b, b + chunk), n - 1)], min(chunk, n - b)


def solve(chain: Chain, cos: np.ndarray | None, sin: np.ndarray | None, omega: np.ndarray,
          settings: ChainOptimiseSettings, say: Callable[[str], None] = lambda message: None,
          need: tuple[float, int] | None = None, control: np.ndarray | None = None, guarded: bool = True,
          ) -> Gaits:  # fmt: skip
    """Steady gaits (strict contact, relaxed start) of a batch of actuations (Fourier coefficients
    `cos`, `sin` `(B, S, H)`, or the splines of control values `control` `(B, S, M)`), in chunks of
    `settings.chunk` in order of frequency (a chunk integrates as long as its lowest frequency's
    periods), the longer gait periods on the waves still open only (`compact`); `say` reports
    each chunk.

    With `need = (v_min, direction)` and `settings.screen_speed > 0`, the transient's speed
    ([`transient_speed`][], over its last [`LAST`][] periods) comes first, and only the waves that
    reach `screen_speed` of `v_min` in `direction`, and the `chunk` fastest, have their gaits
    solved; the others are left unsolved (not `ok`, NaN): a wave far slower than required
    at the end of its transient is no start for the optimum. `guarded=False`: the search's
    splines, at a step that need not resolve their knots (`gaits._shooting.bodies_problem`)."""
    n, chunk = omega.shape[0], settings.chunk
    if control is None:
        assert cos is not None and sin is not None
        gaits = lambda idx: with_actuation(chain, cos[idx], sin[idx], omega[idx])
    else:
        dtype = chain.dtype
        gaits = lambda idx: chain.with_spline(jnp.asarray(control[idx], dtype), jnp.asarray(omega[idx], dtype))
    t0 = time.perf_counter()
    solved = np.arange(n)
    # Not with n <= chunk (every wave among the fastest), nor a transient too short to have an end.
    if need is not None and settings.screen_speed > 0 and n > chunk and settings.transient >= 2:
        v_min, direction = need
        v = np.full(n, np.nan)
        last = min(LAST, settings.transient - 1)
        for idx, m in _chunks(n, chunk, np.argsort(omega, kind="stable")):
            v[idx[:m]] = transient_speed(gaits(idx), transient=settings.transient, last=last, guarded=guarded,
                                         dynamics=Exact(dt=settings.dt), contact="strict")[:m]  # fmt: skip
        solved = fast_enough(v, v_min, direction, settings.screen_speed, chunk)
        say(f"  transient speeds of {n} waves ({time.perf_counter() - t0:.0f} s): {solved.size} reach "
            f"{settings.screen_speed:g} v_min or are among the {chunk} fastest")  # fmt: skip
    out = _unsolved(n, 2 * chain.n_masses - 1)
    done = 0
    for idx, m in _chunks(solved.size, chunk, solved[np.argsort(omega[solved], kind="stable")]):
        g = steady_gait_chain(
            gaits(idx), transient=settings.transient, dynamics=Exact(dt=settings.dt), contact="strict",
            start="relaxed", patience=PATIENCE, compact=True, guarded=guarded,
        )  # fmt: skip
        rows, take = idx[:m], slice(0, m)
        conv = np.asarray(g.status)[take] == GaitStatus.CONVERGED
        mult = np.abs(np.asarray(g.multipliers)[take])
        out.speed[rows] = np.asarray(g.mean_speed, np.float64)[take]
        out.cost[rows] = np.asarray(g.cost_of_transport, np.float64)[take]
        out.ok[rows] = conv & np.asarray(g.stable)[take] & ~np.asarray(g.liftoff)[take]
        out.liftoff[rows] = np.asarray(g.liftoff)[take]
        out.k[rows] = np.asarray(g.k)[take]
        out.period[rows] = np.asarray(g.period, np.float64)[take]
        out.radius[rows] = np.where(conv, np.max(np.nan_to_num(mult, nan=np.inf), axis=-1), np.nan)
        out.min_normal[rows] = np.where(conv, np.asarray(g.min_normal, np.float64)[take], np.nan)
        out.y[rows] = np.asarray(g.state, np.float64)[take]
        done += m
        say(f"  {done} of {solved.size} waves ({time.perf_counter() - t0:.0f} s)")
    return out


def wave_coefficients(a, phi, springs: int, harmonics: int) -> tuple[np.ndarray, np.ndarray]:
    """`(cos, sin)` of travelling waves, shape `(B, springs, harmonics)` (harmonics above the first zero)."""
    a, phi = np.asarray(a, np.float64), np.asarray(phi, np.float64)
    lag = phi[:, None] * np.arange(springs)[None, :]
    cos = np.zeros((a.size, springs, harmonics))
    sin = np.zeros_like(cos)
    cos[..., 0], sin[..., 0] = -a[:, None] * np.sin(lag), a[:, None] * np.cos(lag)
    return cos, sin


class Screen(NamedTuple):
    """Every travelling wave solved: its `(a, omega, phi)` and its steady gait."""

    a: np.ndarray
    omega: np.ndarray
    phi: np.ndarray
    gaits: Gaits

    def join(self, other: "Screen") -> "Screen":
        cat = lambda x, y: np.concatenate([x, y])
        return Screen(cat(self.a, other.a), cat(self.omega, other.omega), cat(self.phi, other.phi),
                      Gaits(*(cat(x, y) for x, y in zip(self.gaits, other.gaits))))  # fmt: skip


class Inchworms(NamedTuple):
    """The idealised inchworms' starts ([`inchworms`][]): each one's signals in the search's
    family, its period and level, and its steady gait."""

    starts: list[Start]
    period: np.ndarray
    level: np.ndarray
    gaits: Gaits


def inchworms(chain: Chain, lag: float, a_max: float, lo: float, hi: float, harmonics: int, knots: int,
              settings: ChainOptimiseSettings, say: Callable[[str], None] = lambda message: None,
              need: tuple[float, int] | None = None) -> Inchworms | None:  # fmt: skip
    """The tension-wave starts of a chain (`_starts.tension_starts`: each spring's tension a square
    wave, spring $j$'s lagged by $j$ `lag`), over `settings.tension_periods` periods (`None`: 10
    for a spline search, none for a Fourier series) from 0.7 to 4
    times the slowest natural period with one mass held ($2\\pi$/[`Chain.omega_min`][locomotion_jax.Chain.omega_min])
    and `settings.tension_levels`, in the search's family (Fourier series of `harmonics`, or splines
    of `knots` control values), their frequencies clipped to `[lo, hi]`, and their steady gaits
    ([`solve`][], `need` as there). `None` where there are none (no periods, or an internal-force
    actuator: its signal is no rest length)."""
    count = settings.tension_periods if settings.tension_periods is not None else (10 if knots else 0)
    if not count or not chain.actuator.varies_rest_length:
        return None
    slowest = 2 * math.pi / float(chain.omega_min)
    periods = slowest * np.geomspace(0.7, 4.0, count)
    levels = np.asarray(settings.tension_levels, float)
    state = np.zeros(2 * chain.n_masses - 1)
    waves = tension_starts(lambda pp, ll: tension_waves(chain, pp, ll, lag), a_max, periods, levels)
    if not waves:
        return None
    starts = [sampled_start(a_max * v, omega, harmonics, knots, a_max, lo, hi, state) for v, omega, _ in waves]
    omega = np.array([st.omega for st in starts])
    say(f"solving the steady gaits of {len(starts)} idealised inchworms (phase lag {lag:.4g})...")
    if knots:
        control = np.stack([cast(np.ndarray, st.control) for st in starts])
        g = solve(chain, None, None, omega, settings, say, need, control=control, guarded=False)
    else:
        cos, sin = np.stack([st.cos for st in starts]), np.stack([st.sin for st in starts])
        g = solve(chain, cos, sin, omega, settings, say, need)
    starts = [st._replace(y=g.y[i], k=int(g.k[i]), cost=float(g.cost[i]), fresh=False) for i, st in enumerate(starts)]
    return Inchworms(starts, np.array([2 * math.pi / w for _, w, _ in waves]), np.array([q for _, _, q in waves]), g)


def feasible(g: Gaits, speed: float, direction: int) -> np.ndarray:
    return g.ok & (along(g.speed, direction) >= speed)


def preference(g: Gaits, speed: float, direction: int) -> np.ndarray:
    """The key of [`rank`][], one row `(tier, value)` per gait, smaller first: a feasible gait
    `(0, cost)`, another stable gait `(1, -speed in direction)`, the others `(2, 0)`."""
    feas = feasible(g, speed, direction)
    v = along(g.speed, direction)
    tier = np.where(feas, 0.0, np.where(g.ok, 1.0, 2.0))
    value = np.where(feas, np.nan_to_num(g.cost, nan=np.inf), np.where(g.ok, np.nan_to_num(-v, nan=np.inf), 0.0))
    return np.stack([tier, value], axis=-1)


def preferred(keys: np.ndarray, than: np.ndarray) -> np.ndarray:
    """Whether each row of `keys` ([`preference`][]) is preferred to the key `than`."""
    return (keys[:, 0] < than[0]) | ((keys[:, 0] == than[0]) & (keys[:, 1] < than[1]))


def order(keys: np.ndarray) -> np.ndarray:
    """The rows of `keys` ([`preference`][]) in order of preference (ties in order)."""
    return np.lexsort((np.arange(len(keys)), keys[:, 1], keys[:, 0]))


def rank(g: Gaits, speed: float, direction: int) -> np.ndarray:
    """Order of preference: feasible waves by cost, then the other stable gaits by speed in `direction`."""
    return order(preference(g, speed, direction))


def _run(chain, a, omega, phi, harmonics, settings, say, need) -> Screen:
    S = chain.n_masses - 1
    cos, sin = wave_coefficients(a, phi, S, harmonics)
    return Screen(a, omega, phi, solve(chain, cos, sin, omega, settings, say, need))


def grid_steps(springs: int, a_max: float, lo: float, hi: float, settings: ChainOptimiseSettings) -> dict[str, float]:
    """The coarse grid's steps in `a`, $\\log\\omega$ and $\\varphi$ (what [`distinct_starts`][] measures by)."""
    return {
        "a": a_max / settings.amplitudes,
        "log_omega": (math.log(hi / lo) / max(settings.frequencies - 1, 1)) if hi > lo else 0.0,
        "phi": 2 * np.pi / settings.phases if springs > 1 else 0.0,
    }


def record(sc: Screen) -> dict[str, np.ndarray]:
    """The screen as an optimum keeps it (`ChainOptimum.screen`): each wave's `a`, `omega`, `phi`
    and every figure of its gait ([`Gaits`][])."""
    return dict(a=sc.a, omega=sc.omega, phi=sc.phi, **sc.gaits._asdict())


def from_record(given: Any, n_red: int, a_max: float, lo: float, hi: float) -> Screen:
    """The screen of an earlier optimum's `screen` ([`record`][]), for `optimise(chain, ..., sweep=)`:
    its waves within the bound and the frequency range (`_element_local.screen_rows`, which raises a
    `ValueError` naming `sweep` for a record of another kind or chain)."""
    state = f"a chain of {(n_red + 1) // 2} masses"
    rows = screen_rows(given, ("a", "omega", "phi", *Gaits._fields), n_red, a_max, lo, hi, ("chain", "wave"), state)
    return Screen(rows["a"], rows["omega"], rows["phi"], Gaits(*(rows[key] for key in Gaits._fields)))


def screen(chain: Chain, speed: float, direction: int, a_max: float, lo: float, hi: float, harmonics: int,
           settings: ChainOptimiseSettings, say: Callable[[str], None] = lambda message: None,
           ) -> tuple[Screen, int, dict[str, float]]:  # fmt: skip
    """The grid and its zoom (module docstring). Returns every wave solved, the index of the best
    (feasible by cost, else the fastest stable gait) and the coarse grid's steps; `say` reports
    progress."""
    S = chain.n_masses - 1
    amps = a_max * np.arange(1, settings.amplitudes + 1) / settings.amplitudes
    omegas = np.geomspace(lo, hi, settings.frequencies) if hi > lo else np.array([lo])
    phases = -np.pi + 2 * np.pi * np.arange(settings.phases) / settings.phases if S > 1 else np.zeros(1)
    A, W, F = (x.ravel() for x in np.meshgrid(amps, omegas, phases, indexing="ij"))
    out = _run(chain, A, W, F, harmonics, settings, say, (speed, direction))
    steps = grid_steps(S, a_max, lo, hi, settings)
    step = dict(steps)
    for level in range(settings.zoom_levels):
        best = int(rank(out.gaits, speed, direction)[0])
        if not out.gaits.ok[best]:
            break
        n = settings.zoom_points
        grid = lambda c, h: c + h * np.linspace(-1, 1, n) if h > 0 else np.array([c])
        a_ = np.clip(grid(out.a[best], step["a"]), a_max * 1e-3, a_max)
        w_ = np.exp(np.clip(grid(math.log(out.omega[best]), step["log_omega"]), math.log(lo), math.log(hi)))
        p_ = grid(out.phi[best], step["phi"])
        A, W, F = (x.ravel() for x in np.meshgrid(np.unique(a_), np.unique(w_), p_, indexing="ij"))
        say(f"zoom level {level + 1}: {A.size} waves around a = {out.a[best]:.4g}, omega = {out.omega[best]:.4g}, "
            f"phi = {out.phi[best]:.4g}")  # fmt: skip
        out = out.join(_run(chain, A, W, F, harmonics, settings, say, (speed, direction)))
        step = {k: v / 2 for k, v in step.items()}
    return out, int(rank(out.gaits, speed, direction)[0]), steps


def distinct_starts(sc: Screen, best: int, count: int, speed: float, direction: int, steps: dict) -> list[int]:
    """`best`, then the next waves in order of preference at least two coarse steps (in $\\log\\omega$ or
    $\\varphi$) from every one chosen: different gaits rather than neighbours of one."""
    chosen = [best]

    def far(i, j):
        dw = abs(math.log(sc.omega[i] / sc.omega[j])) / max(steps["log_omega"], 1e-300)
        dp = abs((sc.phi[i] - sc.phi[j] + np.pi) % (2 * np.pi) - np.pi) / max(steps["phi"], 1e-300)
        return max(dw, dp) >= 1.99

    for i in rank(sc.gaits, speed, direction):
        if len(chosen) == count:
            break
        if sc.gaits.ok[i] and all(far(int(i), j) for j in chosen):
            chosen.append(int(i))
    return chosen


def best_distinct(keys: np.ndarray, count: int) -> list[int]:
    """The indices of the `count` most preferred `keys` ([`preference`][]), in order, one of each
    run of stable gaits of equal keys (to 1e-9 relative: time shifts and mirror images of one
    gait), repeating the first where fewer are left; the first index where no gait is stable."""
    chosen: list[int] = []
    same = lambda i, j: keys[i, 0] == keys[j, 0] and abs(keys[i, 1] - keys[j, 1]) <= 1e-9 * abs(keys[j, 1])
    for i in order(keys):
        if len(chosen) == count:
            break
        if keys[i, 0] < 2 and np.isfinite(keys[i, 1]) and not any(same(i, j) for j in chosen):
            chosen.append(int(i))
    chosen = chosen or [0]
    return chosen + chosen[:1] * (count - len(chosen))


def as_inchworm(worms: Inchworms, i: int, lag: float) -> dict[str, Any]:
    """An idealised inchworm's start as an optimum's history keeps it (as [`as_dict`][] a wave)."""
    g, st = worms.gaits, worms.starts[i]
    return dict(
        inchworm=dict(period=float(worms.period[i]), level=float(worms.level[i]), lag=lag),
        omega=st.omega,
        mean_speed=float(g.speed[i]),
        cost_of_transport=float(g.cost[i]),
        k=int(g.k[i]),
    )


def as_dict(sc: Screen, i: int) -> dict[str, Any]:
    g = sc.gaits
    return dict(a=float(sc.a[i]), omega=float(sc.omega[i]), phi=float(sc.phi[i]), mean_speed=float(g.speed[i]),
                cost_of_transport=float(g.cost[i]), k=int(g.k[i]))  # fmt: skip
