"""The exact optimisers' local step: a monotone L-BFGS descent on an exact penalty.

Both the two-mass and the chain method minimise the merit
$\\phi = f + \\rho \\sum_j \\max(0, -c_j)$ of a point's figures (cost $f$, constraints
$c_j \\ge 0$, their gradients through the periodic orbit) with quasi-Newton directions and a
backtracking (Armijo) line search that accepts only a decrease, so that an iterate never walks
into a costlier gait or a failed orbit. The simple constraints (the stroke, the bounds of
$\\log\\omega$) are kept by a projection that the caller supplies.
"""

import math
from collections.abc import Callable
from typing import Any

import numpy as np


def merit(fig: Any, rho: float) -> tuple[float, np.ndarray | None]:
    """The exact penalty $f + \\rho \\sum_j \\max(0, -c_j)$ of `fig` (fields `f`, `df`, `c`, `dc`,
    `ok`) and its gradient; `inf` and `None` where there is no orbit (`fig` `None` or not `ok`)."""
    if fig is None or not fig.ok:
        return math.inf, None
    viol = [max(0.0, -c) for c in fig.c]
    g = fig.df - rho * sum(fig.dc[j] for j in range(len(fig.c)) if fig.c[j] < 0)
    return fig.f + rho * sum(viol), g


def descent(
    x0: np.ndarray,
    at: Callable[[np.ndarray], Any],
    proj: Callable[[np.ndarray], np.ndarray],
    max_iter: int,
    trust_radius: float,
    rho: float,
    strict: bool = False,
) -> None:
    """Monotone L-BFGS descent on [`merit`][locomotion_jax.optimisation._descent.merit] from `x0`.

    `at(x)` gives the figures at `x` (or `None`); `proj` maps onto the simple constraints. A
    step is at most `trust_radius` in its largest coordinate; a trial point is accepted on
    Armijo's condition (and, if `strict`, only if the merit falls). The history keeps the last
    8 curvature pairs and is dropped where a direction does not descend or no step is
    accepted; the descent stops after `max_iter` iterations or where steepest descent finds
    no decrease (a local, possibly nonsmooth, minimum). The caller records what it wants from
    the points `at` is asked for."""
    x = proj(x0)
    phi, g = merit(at(x), rho)
    if g is None:
        return
    mem: list[tuple[np.ndarray, np.ndarray]] = []
    for _ in range(max_iter):
        # Two-loop recursion for the L-BFGS direction.
        q = g.copy()
        alphas = []
        for s_, y_ in reversed(mem):
            alphas.append(s_ @ q / (y_ @ s_))
            q -= alphas[-1] * y_
        if mem:
            s_, y_ = mem[-1]
            q *= (s_ @ y_) / (y_ @ y_)
        for (s_, y_), a_ in zip(mem, reversed(alphas)):
            q += (a_ - y_ @ q / (y_ @ s_)) * s_
        d = -q
        if g @ d >= 0:  # not a descent direction: restart from steepest descent
            mem.clear()
            d = -g
        step = min(1.0, trust_radius / max(float(np.max(np.abs(d))), 1e-300))
        accepted, xn, phin, gn = False, x, phi, None
        for _ in range(12):
            xn = proj(x + step * d)
            phin, gn = merit(at(xn), rho)
            if gn is not None and phin <= phi + 1e-4 * float(g @ (xn - x)) and (phin < phi or not strict):
                accepted = True
                break
            step *= 0.4
        if not accepted or gn is None:
            if not mem:
                return
            mem.clear()
            continue
        sv, yv = xn - x, gn - g
        if sv @ yv > 1e-12 * np.linalg.norm(sv) * np.linalg.norm(yv):
            mem.append((sv, yv))
            mem[:] = mem[-8:]
        x, phi, g = xn, phin, gn
