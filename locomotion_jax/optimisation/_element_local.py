"""The local refinement of the chain and mechanism optimisers: a monotone descent on an exact penalty, per start,
in lockstep (a signal per actuated element: `gaits._element_orbit`).

Each start runs in its own thread (`_lockstep.run_lockstep`);
its evaluations are batched into one call of the oracle (`_element_orbit.ChainOracle`:
periodic orbit, figures and their exact gradients). The descent takes L-BFGS directions and
a backtracking line search that accepts only a decrease of the merit, so that an iterate
never walks into a costlier gait or a failed orbit; the stroke of every spring is kept by
radial rescaling of that spring's coefficients onto its exact limit (the set
$\\{\\max_t |s_j(t)| \\le a_\\max\\}$ is convex and contains 0), $\\log\\omega$ by clipping.
"""

import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ..gaits import _element_orbit as orbit
from ._descent import descent


def strokes(cos: np.ndarray, sin: np.ndarray) -> np.ndarray:
    """Exact $\\max_\\phi |s_j(\\phi)|$ per spring (`cos`, `sin`: `(S, H)`): the largest value on a
    grid of $64H + 64$ phases, polished by Newton's method on $s_j' = 0$ within its grid cell
    (as [`_constraints.stroke`][locomotion_jax.optimisation._constraints.stroke], on the host)."""
    S, H = cos.shape
    m = 64 * H + 64
    h = 2 * np.pi / m
    n = np.arange(1, H + 1)
    grid = np.arange(m) * h
    vals = cos @ np.cos(np.outer(n, grid)) + sin @ np.sin(np.outer(n, grid))
    j = np.argmax(np.abs(vals), axis=1)
    phi = grid[j]
    best = np.abs(vals[np.arange(S), j])
    for _ in range(4):
        c, s = np.cos(np.outer(phi, n)), np.sin(np.outer(phi, n))  # one phase per spring
        d1 = (n * (sin * c - cos * s)).sum(1)
        d2 = -(n * n * (cos * c + sin * s)).sum(1)
        phi = phi + np.clip(np.where(d2 != 0, -d1 / np.where(d2 != 0, d2, 1), 0), -h, h)
        best = np.maximum(best, np.abs((cos * np.cos(np.outer(phi, n)) + sin * np.sin(np.outer(phi, n))).sum(1)))
    return best


def unpack(theta: np.ndarray, springs: int, harmonics: int) -> tuple[np.ndarray, np.ndarray, float]:
    """Decision vector -> `(cos, sin)` in units of $a_\\max$ and $\\omega$."""
    c, s = orbit.coefficients(jnp.asarray(theta), springs, harmonics)
    return np.asarray(c), np.asarray(s), float(np.exp(theta[-1]))


def pack(cos: np.ndarray, sin: np.ndarray, omega: float) -> np.ndarray:
    """`(cos, sin)` (units of $a_\\max$, $A_{0,1} = 0$) and $\\omega$ -> decision vector."""
    return np.concatenate([np.ravel(cos)[1:], np.ravel(sin), [math.log(omega)]])


def project(theta: np.ndarray, springs: int, harmonics: int, log_lo: float, log_hi: float) -> np.ndarray:
    """Every spring's coefficients rescaled radially onto stroke <= 1 (units of $a_\\max$), $\\log\\omega$ clipped."""
    c, s, w = unpack(theta, springs, harmonics)
    scale = 1 / np.maximum(strokes(c, s), 1.0)
    return pack(c * scale[:, None], s * scale[:, None], math.exp(float(np.clip(math.log(w), log_lo, log_hi))))


class Evaluator:
    """The batched oracle for the lockstep solvers: warm starts per solver, and where Newton fails
    from them, a transient and period-1 then period-2 gaits."""

    def __init__(self, oracle: orbit.ChainOracle, lanes: int, transient: int, make):
        self.oracle, self.lanes, self.transient, self.make = oracle, lanes, transient, make
        self.y: dict[int, np.ndarray] = {}
        self.k: dict[int, int] = {}
        self.calls = 0

    def solve(self, theta: np.ndarray, y0: np.ndarray, k: np.ndarray) -> tuple[Any, np.ndarray]:
        dtype = self.oracle.chain.dtype
        th = jnp.asarray(theta, dtype)
        run = lambda y, kk: jax.tree_util.tree_map(
            np.asarray, self.oracle.orbits(th, jnp.asarray(y, dtype), jnp.asarray(kk, jnp.int32))
        )
        orb = run(y0, k)
        k = np.array(k)
        if not orb.ok.all():
            periods = jnp.asarray(self.transient, jnp.int32)
            y1 = np.asarray(self.oracle.transient(th, jnp.asarray(y0, dtype), jnp.asarray(~orb.ok), periods))
            for kk in (1, 2):
                if orb.ok.all():
                    break
                again = run(y1, np.full_like(k, kk))
                take = ~orb.ok & again.ok
                orb = jax.tree_util.tree_map(lambda a, b: np.where(take.reshape((-1,) + (1,) * (a.ndim - 1)), b, a),
                                             orb, again)  # fmt: skip
                k = np.where(take, kk, k)
        self.calls += 1
        return orb, k

    def __call__(self, idx: list[int], xs: list[np.ndarray]) -> list[Any]:
        pad = idx + [idx[0]] * (self.lanes - len(idx))
        theta = np.stack([xs[idx.index(i)] for i in pad])
        orb, ks = self.solve(theta, np.stack([self.y[i] for i in pad]), np.array([self.k[i] for i in pad]))
        out = []
        for r, i in enumerate(idx):
            one = jax.tree_util.tree_map(lambda x: x[r], orb)
            if one.ok:
                self.y[i], self.k[i] = one.y, int(ks[r])
                out.append(self.make(theta[r], one, int(ks[r])))
            else:
                out.append(None)
        return out


def local_solver(x0: np.ndarray, proj, stroke_ok, max_iter: int, trust_radius: float, rho: float, log: list):
    """One local run from `x0` for [`run_lockstep`][locomotion_jax.optimisation._lockstep.run_lockstep]:
    returns the cheapest point evaluated that meets every constraint, else the one with the
    smallest violation."""

    def solve(ask):
        cache: dict[bytes, Any] = {}
        trace: list[dict] = []
        best: dict[str, Any] = {"key": (math.inf, math.inf), "x": np.array(x0, float)}

        def at(x):
            key = np.asarray(x).tobytes()
            if key not in cache:
                cache.clear()
                fig = cache[key] = ask(np.array(x, float))
                if fig is not None:
                    trace.append({"f": fig.f, "cot": fig.cot, "c_speed": float(fig.c[0]), "c_normal": float(fig.c[1])})
                    held = min(fig.c[0], fig.c[1]) >= 0 and stroke_ok(x)
                    key_ = (0.0, fig.cot) if held else (1.0, -min(fig.c[0], 0.0) - min(fig.c[1], 0.0))
                    if key_ < best["key"]:
                        best["key"], best["x"] = key_, np.array(x, float)
            return cache[key]

        descent(np.array(x0, float), at, proj, max_iter, trust_radius, rho, strict=True)
        log.append({"evaluations": len(trace), "trace": trace})
        return best["x"]

    return solve


def on_bound(x: np.ndarray, S: int, H: int, a_max: float) -> tuple[np.ndarray, np.ndarray, float]:
    """A refined point's coefficients and frequency, each spring's stroke rescaled onto the bound
    `a_max` where it exceeds it (what the line search's tolerance let through)."""
    c, s, w = unpack(x, S, H)
    scale = 1 / np.maximum(strokes(c, s), 1.0)
    return a_max * c * scale[:, None], a_max * s * scale[:, None], w
