"""The chain optimiser's baseline: travelling waves screened on a grid and zoomed, on steady gaits.

A travelling wave $s_j(t) = a\\sin(\\omega t - j\\varphi)$ ([`TravellingWave`][]) has the stroke $a$
on every spring. The screen solves the steady gait ([`steady_gait`][], exact model, strict
contact, from the relaxed springs) of every wave of a grid over $(a, \\omega, \\varphi)$ in
chunks of one shape (one compilation, shared with the verification of the refined
actuations: the waves are padded to their number of harmonics), then zooms in around the
best wave that meets the requirement: per level a grid of a few points per variable over one
step either side of it, the step halved.
"""

import math
import time
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..dynamics._exact_dynamics import Exact
from ..gaits._chain_gait import steady_gait_chain
from ..gaits._select import GaitStatus
from ..model._chain import Chain
from ..model._springwaves import SpringFourier
from ._chain_optimum import ChainOptimiseSettings


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
    y: np.ndarray  # the orbit's reduced state at the section


def with_actuation(chain: Chain, cos: np.ndarray, sin: np.ndarray, omega: np.ndarray) -> Chain:
    """A batch of copies of one (broadcast) chain with the given coefficients `(B, S, H)` and `omega` `(B,)`."""
    B = omega.shape[0]
    dtype = chain.dtype
    batch = jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (B,) + x.shape), chain)
    waves = SpringFourier(jnp.asarray(cos, dtype), jnp.asarray(sin, dtype), jnp.asarray(omega, dtype))
    return batch.with_waves(waves)


PATIENCE = 3
"""The screen's Newton iterations without progress before a wave is given up at a gait period
(`_corrector`): a converging wave halves its residual at every iteration, one with no gait of
that period cycles, and the chunk runs in lockstep."""


def solve(chain: Chain, cos: np.ndarray, sin: np.ndarray, omega: np.ndarray, settings: ChainOptimiseSettings,
          say: Callable[[str], None] = lambda message: None) -> Gaits:  # fmt: skip
    """Steady gaits (strict contact, relaxed start) of a batch of actuations, in chunks of
    `settings.chunk` in order of frequency (a chunk integrates as long as its lowest frequency's
    periods), the longer gait periods on the waves still open only (`compact`); `say` reports
    each chunk."""
    n, chunk = omega.shape[0], settings.chunk
    order = np.argsort(omega, kind="stable")
    rows = []
    t0 = time.perf_counter()
    for b in range(0, n, chunk):
        idx = order[np.minimum(np.arange(b, b + chunk), n - 1)]  # the last chunk padded by repeats: one shape
        g = steady_gait_chain(
            with_actuation(chain, cos[idx], sin[idx], omega[idx]), transient=settings.transient,
            dynamics=Exact(dt=settings.dt), contact="strict", start="relaxed", patience=PATIENCE, compact=True,
        )  # fmt: skip
        take = slice(0, min(chunk, n - b))
        conv = np.asarray(g.status)[take] == GaitStatus.CONVERGED
        mult = np.abs(np.asarray(g.multipliers)[take])
        rows.append(
            Gaits(
                speed=np.asarray(g.mean_speed, np.float64)[take],
                cost=np.asarray(g.cost_of_transport, np.float64)[take],
                ok=conv & np.asarray(g.stable)[take] & ~np.asarray(g.liftoff)[take],
                liftoff=np.asarray(g.liftoff)[take],
                k=np.asarray(g.k)[take],
                period=np.asarray(g.period, np.float64)[take],
                radius=np.where(conv, np.max(np.nan_to_num(mult, nan=np.inf), axis=-1), np.nan),
                y=np.asarray(g.state, np.float64)[take],
            )
        )
        say(f"  {min(b + chunk, n)} of {n} waves ({time.perf_counter() - t0:.0f} s)")
    back = np.argsort(order)
    return Gaits(*(np.concatenate(parts)[back] for parts in zip(*rows)))


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


def feasible(g: Gaits, speed: float, direction: int) -> np.ndarray:
    return g.ok & (direction * np.nan_to_num(g.speed, nan=-np.inf) >= speed)


def rank(g: Gaits, speed: float, direction: int) -> np.ndarray:
    """Order of preference: feasible waves by cost, then the other stable gaits by speed in `direction`."""
    feas = feasible(g, speed, direction)
    v = direction * np.nan_to_num(g.speed, nan=-np.inf)
    key = np.where(feas, np.nan_to_num(g.cost, nan=np.inf), np.where(g.ok, 1e300 - v, np.inf))
    return np.argsort(key, kind="stable")


def _run(chain, a, omega, phi, harmonics, settings, say) -> Screen:
    S = chain.n_masses - 1
    cos, sin = wave_coefficients(a, phi, S, harmonics)
    return Screen(a, omega, phi, solve(chain, cos, sin, omega, settings, say))


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
    out = _run(chain, A, W, F, harmonics, settings, say)
    steps = {
        "a": a_max / settings.amplitudes,
        "log_omega": (math.log(hi / lo) / max(settings.frequencies - 1, 1)) if hi > lo else 0.0,
        "phi": 2 * np.pi / settings.phases if S > 1 else 0.0,
    }
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
        out = out.join(_run(chain, A, W, F, harmonics, settings, say))
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


def as_dict(sc: Screen, i: int) -> dict[str, Any]:
    g = sc.gaits
    return dict(a=float(sc.a[i]), omega=float(sc.omega[i]), phi=float(sc.phi[i]), mean_speed=float(g.speed[i]),
                cost_of_transport=float(g.cost[i]), k=int(g.k[i]))  # fmt: skip
