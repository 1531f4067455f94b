"""The exact optimisers' local step: two monotone quasi-Newton descents on an exact penalty.

Both the two-mass and the chain method minimise the merit
$\\phi = f + \\rho \\sum_j \\max(0, -c_j)$ of a point's figures (cost $f$, constraints
$c_j \\ge 0$, their gradients through the periodic orbit). A backtracking (Armijo) line search
on $\\phi$ accepts only a decrease, so that an iterate never walks into a costlier gait or a
failed orbit; the simple constraints (the stroke, the bounds of $\\log\\omega$) are kept by a
projection that the caller supplies.

- [`descent`][locomotion_jax.optimisation._descent.descent] takes L-BFGS directions on $\\phi$
  itself. Where the speed constraint is active (the optimum of every requirement the cost would
  rather undercut), its steps cross the constraint's kink and backtrack (7 or 8 evaluations an
  iteration in the paper's optimiser, `benchmarks/NOTES.md`); it may stop where the merit
  stalls.
- [`sqp_descent`][locomotion_jax.optimisation._descent.sqp_descent] takes the step of a
  quadratic model of $f$ (its inverse Hessian from L-BFGS pairs of the Lagrangian's gradient)
  subject to the constraints linearised, $c_j + \\nabla c_j^\\top d \\ge 0$ (an SQP step), starts
  each line search near the last accepted step, and stops where the merit stalls: it follows an
  active constraint's tangent instead of crossing it.
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


INSIDE = 1e-9
"""How far inside the figures' linearised constraints a step aims (`_step`), in the units of
the constraints (relative speed, normal force in weights): a curved constraint bends the
iterates across it at second order, and this settles them on the side where it holds."""


def _inverse_hessian(mem: list[tuple[np.ndarray, np.ndarray]]) -> Callable[[np.ndarray], np.ndarray]:
    """$v \\mapsto Hv$ for the L-BFGS inverse Hessian of the pairs `mem` (two-loop recursion),
    scaled by the last pair's $s^\\top y / y^\\top y$; the identity without pairs."""

    def apply(v: np.ndarray) -> np.ndarray:
        q = np.array(v, float)
        alphas = []
        for s_, y_ in reversed(mem):
            alphas.append(s_ @ q / (y_ @ s_))
            q -= alphas[-1] * y_
        if mem:
            s_, y_ = mem[-1]
            q *= (s_ @ y_) / (y_ @ y_)
        for (s_, y_), a_ in zip(mem, reversed(alphas)):
            q += (a_ - y_ @ q / (y_ @ s_)) * s_
        return q

    return apply


STALL_WINDOW = 20
STALL_RTOL = 1e-5
"""`sqp_descent` stops where its merit fell by at most `STALL_RTOL` (relative) over its last
`STALL_WINDOW` evaluations: the cost of transport's last digits do not pay for the lockstep
rounds that the slowest run holds the others in."""


FAR = 1e-2
"""A violation (in the constraints' units: relative speed, normal force in weights) beyond which
an accepted point counts as far from feasible in `descent`'s stall test; a descent along an
active constraint crosses it by far less."""

FAR_STALL_RTOL = 1e-4
"""`descent`'s stall tolerance, at least, from an accepted point `FAR` from feasible (where it
stops on stalls at all): a run whose merit falls by 1e-4 over 20 evaluations cannot close a
violation of several per cent in its budget, and the lockstep rounds wait on it
(`benchmarks/NOTES.md`)."""


def _far(fig: Any) -> bool:
    return bool(np.max(-np.asarray(fig.c, float)) > FAR)


def _stalled(best: list[float], rtol: float) -> bool:
    """Whether the merit accepted so far (`best`: after each evaluation) fell by at most `rtol`
    (relative) over the last `STALL_WINDOW` evaluations."""
    return len(best) > STALL_WINDOW and bool(best[-STALL_WINDOW - 1] - best[-1] <= rtol * abs(best[-1]))


def _recorder(at: Callable[[np.ndarray], Any], rho: float, best: list[float]) -> Callable[[np.ndarray], Any]:
    """`at` that also appends the merit accepted so far to `best` after each evaluation; returns
    the figures, their merit and its gradient."""

    def ask(z):
        fig = at(z)
        value, grad = merit(fig, rho)
        best.append(min(value, best[-1]) if best else value)
        return fig, value, grad

    return ask


def descent(
    x0: np.ndarray,
    at: Callable[[np.ndarray], Any],
    proj: Callable[[np.ndarray], np.ndarray],
    max_iter: int,
    trust_radius: float,
    rho: float,
    strict: bool = False,
    stall_rtol: float = 0.0,
) -> None:
    """Monotone L-BFGS descent on [`merit`][locomotion_jax.optimisation._descent.merit] from `x0`.

    `at(x)` gives the figures at `x` (or `None`); `proj` maps onto the simple constraints. A
    step is at most `trust_radius` in its largest coordinate; a trial point is accepted on
    Armijo's condition (and, if `strict`, only if the merit falls). The history keeps the last
    8 curvature pairs and is dropped where a direction does not descend or no step is
    accepted; the descent stops after `max_iter` iterations, where steepest descent finds
    no decrease (a local, possibly nonsmooth, minimum) or, if `stall_rtol > 0`, where the merit
    fell by at most `stall_rtol` (relative) over its last `STALL_WINDOW` evaluations: its steps
    cross an active constraint and backtrack, so that it can creep along the constraint for
    digits that do not pay for the lockstep rounds. From a point `FAR` from feasible the
    tolerance is at least `FAR_STALL_RTOL`. The caller records what it wants from the
    points `at` is asked for."""
    best: list[float] = []
    ask = _recorder(at, rho, best)
    x = proj(x0)
    fig, phi, g = ask(x)
    if g is None:
        return
    mem: list[tuple[np.ndarray, np.ndarray]] = []
    for _ in range(max_iter):
        rtol = max(stall_rtol, FAR_STALL_RTOL) if _far(fig) else stall_rtol
        if stall_rtol > 0 and _stalled(best, rtol):
            return
        d = -_inverse_hessian(mem)(g)
        if g @ d >= 0:  # not a descent direction: restart from steepest descent
            mem.clear()
            d = -g
        step = min(1.0, trust_radius / max(float(np.max(np.abs(d))), 1e-300))
        accepted, xn, phin, gn, fign = False, x, phi, None, fig
        for _ in range(12):
            xn = proj(x + step * d)
            fign, phin, gn = ask(xn)
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
        x, phi, g, fig = xn, phin, gn, fign


def direction(
    g: np.ndarray, c: np.ndarray, a: np.ndarray, hv: Callable[[np.ndarray], np.ndarray]
) -> tuple[np.ndarray, np.ndarray]:
    """The step $d$ of $\\min_d g^\\top d + \\tfrac12 d^\\top H^{-1} d$ s.t. $c_j + a_j^\\top d \\ge 0$
    (rows $a_j$ of `a`), and its multipliers $\\lambda \\ge 0$; `hv` applies $H$.

    A small active-set method: starting from the free step $-Hg$, the most violated constraint
    joins the set and the constraint with the most negative multiplier leaves it; on the set
    $d = -H(g - A^\\top\\lambda)$ with $A H A^\\top \\lambda = A H g - c_A$. Degenerate sets
    (parallel constraints) are solved in the least-squares sense."""
    lam = np.zeros(len(c))
    free = -hv(g)
    d = free
    active: list[int] = []
    for _ in range(3 * len(c) + 1):
        lam[:] = 0.0
        if active:
            A = a[active]
            HA = np.stack([hv(row) for row in A], axis=1)
            lam_a = np.linalg.lstsq(A @ HA, A @ (-free) - c[active], rcond=None)[0]
            if np.any(lam_a < 0):
                active.pop(int(np.argmin(lam_a)))
                continue
            lam[active] = lam_a
            d = free + HA @ lam_a
        else:
            d = free
        slack = c + a @ d
        slack[active] = np.inf
        worst = int(np.argmin(slack))
        if slack[worst] >= -1e-12 * (1.0 + abs(c[worst])):
            break
        active.append(worst)
    return d, lam


def _step(fig: Any, x: np.ndarray, proj: Callable[[np.ndarray], np.ndarray], hv) -> tuple[np.ndarray, np.ndarray]:
    """[`direction`][locomotion_jax.optimisation._descent.direction] for the figures at `x`, its
    constraints aimed `INSIDE`, and the simple constraints that `proj` keeps added as they are
    met: where `proj` moves the full step's end point, the supporting half-space of the (convex)
    set at the projected point becomes a linear constraint and the step is solved again. Returns
    the step and the multipliers of the figures' constraints."""
    g, a = np.asarray(fig.df, float), np.asarray(fig.dc, float)
    c = np.asarray(fig.c, float) - INSIDE
    m = len(c)
    d, lam = direction(g, c, a, hv)
    for _ in range(PROJECTION_ROUNDS):
        q = proj(x + d)
        gap = x + d - q
        size = float(np.linalg.norm(gap))
        if size <= 1e-12 * (1.0 + float(np.linalg.norm(d))):
            break
        n = gap / size  # outward normal of the set at q: n.(z - q) <= 0 for every z in it
        a = np.vstack([a, -n])
        c = np.append(c, n @ (q - x))
        d, lam = direction(g, c, a, hv)
    return d, lam[:m]


PROJECTION_ROUNDS = 4
"""Half-spaces of the simple constraints that one step may add (`_step`)."""


def _slope(fig: Any, s: np.ndarray, rho: float) -> float:
    """The change of the merit's model (cost linearised, constraints linearised in the penalty)
    over the step `s`: negative for a step that descends."""
    c, a = np.asarray(fig.c, float), np.asarray(fig.dc, float)
    lin = c + a @ s
    return float(fig.df @ s + rho * (np.maximum(0.0, -lin).sum() - np.maximum(0.0, -c).sum()))


def _lagrangian_gradient(fig: Any, lam: np.ndarray) -> np.ndarray:
    return np.asarray(fig.df, float) - np.asarray(fig.dc, float).T @ lam


GROW = 4.0
"""A line search starts at most `GROW` times the last accepted step (in its largest coordinate)
from the point, and at most at `trust_radius`: where the constraints' linearisation holds only
over short steps, the first trial lands near the last accepted one instead of several
backtracks away."""


def sqp_descent(
    x0: np.ndarray,
    at: Callable[[np.ndarray], Any],
    proj: Callable[[np.ndarray], np.ndarray],
    max_iter: int,
    trust_radius: float,
    rho: float,
    strict: bool = False,
) -> None:
    """Monotone SQP descent on [`merit`][locomotion_jax.optimisation._descent.merit] from `x0`
    (arguments as [`descent`][locomotion_jax.optimisation._descent.descent]'s).

    The simple constraints that `proj` keeps form a convex set. Each direction is `_step`'s, with
    the L-BFGS inverse Hessian of the last 8 pairs (steps and changes of the Lagrangian's gradient
    at the step's multipliers); a line search starts at `GROW` times the last accepted step, at
    most `trust_radius` in the largest coordinate, and accepts a trial point on Armijo's condition
    against the model's decrease (and, if `strict`, only if the merit falls). The pairs are
    dropped where a direction does not descend or no step is accepted. The descent stops after
    `max_iter` iterations, where the direction without pairs finds no decrease or its model
    predicts none beyond rounding (a local, possibly nonsmooth, minimum), or where the merit
    stalled (`STALL_RTOL` over `STALL_WINDOW` evaluations)."""
    best: list[float] = []  # the merit accepted so far, after each evaluation
    ask = _recorder(at, rho, best)
    x = proj(x0)
    fig, phi, _ = ask(x)
    if not math.isfinite(phi):
        return
    mem: list[tuple[np.ndarray, np.ndarray]] = []
    radius = trust_radius
    for _ in range(max_iter):
        if _stalled(best, STALL_RTOL):
            return
        d, lam = _step(fig, x, proj, _inverse_hessian(mem))
        if _slope(fig, d, rho) >= 0 and mem:  # not a descent direction: restart without pairs
            mem.clear()
            d, lam = _step(fig, x, proj, _inverse_hessian(mem))
        if -_slope(fig, d, rho) <= 1e-14 * max(1.0, abs(phi)):  # stationary to rounding
            return
        step = min(1.0, radius / max(float(np.max(np.abs(d))), 1e-300))
        accepted, xn, phin, fign = False, x, phi, fig
        for _ in range(12):
            xn = proj(x + step * d)
            fign, phin, _ = ask(xn)
            if math.isfinite(phin) and phin <= phi + 1e-4 * _slope(fig, xn - x, rho) and (phin < phi or not strict):
                accepted = True
                break
            step *= 0.4
        if not accepted:
            if not mem:
                return
            mem.clear()
            radius = trust_radius
            continue
        radius = min(trust_radius, max(GROW * float(np.max(np.abs(xn - x))), 1e-12))
        sv = xn - x
        yv = _lagrangian_gradient(fign, lam) - _lagrangian_gradient(fig, lam)
        if sv @ yv > 1e-12 * np.linalg.norm(sv) * np.linalg.norm(yv):
            mem.append((sv, yv))
            mem[:] = mem[-8:]
        x, phi, fig = xn, phin, fign


METHODS = ("descent", "sqp")
"""The local steps by the names that the optimisers' `local_method` setting gives them."""


def local_step(
    method: str,
    x0: np.ndarray,
    at: Callable[[np.ndarray], Any],
    proj: Callable[[np.ndarray], np.ndarray],
    max_iter: int,
    trust_radius: float,
    rho: float,
    strict: bool = False,
    stall_rtol: float = 0.0,
) -> None:
    """The local step named `method` (of `METHODS`) from `x0`, arguments as
    [`descent`][locomotion_jax.optimisation._descent.descent]'s; `stall_rtol` is the descent's
    (`sqp_descent` stops at its own `STALL_RTOL`)."""
    if method == "sqp":
        sqp_descent(x0, at, proj, max_iter, trust_radius, rho, strict)
    elif method == "descent":
        descent(x0, at, proj, max_iter, trust_radius, rho, strict, stall_rtol)
    else:
        raise ValueError(f"local_method must be one of {METHODS}, got {method!r}.")
