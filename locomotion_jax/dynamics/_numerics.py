"""The engine's generic numerics: what an exact hybrid step needs whatever the mechanism.

The quintic Hermite dense output over a step ([`quintic`][], [`hermite_basis`][]), the
first root of an event function's quintic with its implicit-function derivative
([`root`][]), the time to an event predicted by its Taylor quadratic ([`predict`][]), the
margins to a change of switching structure ([`margins`][], [`target_margin`][]), a
caller's target event ([`Target`][]) and the carried actuation phase ([`sincos`][],
[`rotate`][]). Pure functions of scalars (vectors over the configurations under `vmap`);
the mechanisms' physics and the stick/slip logic live in the engines that call them.
"""

import math
from collections.abc import Sequence
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array


NEWTON_ITERS = 4
"""Newton iterations on the event quintic, from its secant root (it is nearly linear)."""

PREDICT_MARGIN = 1.2
"""A step predicted to contain an event ends this factor past the predicted crossing."""


class Target(NamedTuple):
    """A caller's event $g = z - |X - X_0|$ (fires when $|X - X_0|$ reaches $z$); `active` gates it."""

    active: Array
    X0: Array
    z: Array


def sincos(x: Array) -> tuple[Array, Array]:
    """$(\\sin x, \\cos x)$ by quadrant reduction and Taylor polynomials on $[-\\pi/4, \\pi/4]$.

    A few ulps in float64 for moderate $|x|$ (the engine passes step angles
    $\\omega h$); about 40 flops, where XLA's CPU float64 `sin` costs several times more.
    """
    dtype = x.dtype
    p1 = np.asarray(math.pi / 2, dtype)
    p2 = np.asarray(math.pi / 2 - float(p1), dtype)
    q = jnp.round(x * np.asarray(2 / math.pi, dtype))
    r = (x - q * p1) - q * p2
    r2 = r * r
    s = np.asarray(1 / math.factorial(17), dtype)
    for n in (15, 13, 11, 9, 7, 5, 3):
        s = s * r2 + np.asarray((-1) ** ((n - 1) // 2) / math.factorial(n), dtype)
    s = r + r * r2 * s
    c = np.asarray(-1 / math.factorial(18), dtype)
    for n in (16, 14, 12, 10, 8, 6, 4, 2):
        c = c * r2 + np.asarray((-1) ** (n // 2) / math.factorial(n), dtype)
    c = 1 + r2 * c
    quad = jnp.mod(q, 4)
    swap = (quad == 1) | (quad == 3)
    sin = jnp.where(swap, c, s)
    cos = jnp.where(swap, s, c)
    sin = jnp.where(quad >= 2, -sin, sin)
    cos = jnp.where((quad == 1) | (quad == 2), -cos, cos)
    return sin, cos


def quintic(g0, D0, E0, g1, D1, E1):
    """Monomial coefficients of the quintic Hermite interpolant on $\\theta \\in [0, 1]$
    with values $g$, scaled slopes $D = h\\dot g$ and curvatures $E = h^2\\ddot g$ at both ends."""
    dg = g1 - g0
    c3 = 10 * dg - 6 * D0 - 4 * D1 - 1.5 * E0 + 0.5 * E1
    c4 = -15 * dg + 8 * D0 + 7 * D1 + 1.5 * E0 - E1
    c5 = 6 * dg - 3 * D0 - 3 * D1 - 0.5 * E0 + 0.5 * E1
    return g0, D0, 0.5 * E0, c3, c4, c5


@jax.custom_jvp
def root(coef, g1):
    """First root in $[0, 1]$ of the event quintic ($p(0) \\ge 0 > p(1) = g_1$) by
    safeguarded Newton from the secant root. When $p(0) = 0$ (the event function of
    a mass that has just switched) $p(\\theta)/\\theta$ is solved, so the start is skipped.

    Differentiated by the implicit function theorem ([`_root_jvp`][]), not through
    the iterations."""
    c0, c1, c2, c3, c4, c5 = coef
    defl = c0 == 0
    a = [jnp.where(defl, hi, lo) for lo, hi in zip((c0, c1, c2, c3, c4), (c1, c2, c3, c4, c5))]
    a.append(jnp.where(defl, 0, c5))
    den = a[0] - g1
    th = jnp.clip(jnp.where(den > 0, a[0] / jnp.where(den > 0, den, 1), 0.5), 0, 1)
    lo, hi = jnp.zeros_like(th), jnp.ones_like(th)
    for _ in range(NEWTON_ITERS):
        p = a[5]
        dp = jnp.zeros_like(th)
        for ak in reversed(a[:5]):
            dp = dp * th + p
            p = p * th + ak
        pos = p >= 0
        lo = jnp.where(pos, th, lo)
        hi = jnp.where(pos, hi, th)
        ok = dp != 0
        nt = th - p / jnp.where(ok, dp, 1)
        # Inclusive: a converged Newton step lands on the bracket end it came from.
        th = jnp.where(ok & (nt >= lo) & (nt <= hi), nt, 0.5 * (lo + hi))
    return th


@root.defjvp
def _root_jvp(primals, tangents):
    """The event time's derivative: $p(\\theta^*; c) = 0$ gives
    $\\dot\\theta^* = -\\sum_k \\dot c_k \\theta^{*k} / p'(\\theta^*)$ (implicit function theorem;
    the root's tangent does not depend on the Newton iterations that found it). The
    state committed at $\\theta^*$ then moves with it, which is the saltation of the
    switch. A grazing crossing ($p'(\\theta^*) = 0$) has no derivative: its tangent is 0, as
    where the quintic is not finite (the engine's pick of an event that did not cross, whose
    root it discards). The tangent is linear in `dcoef` with finite factors only, so that its
    transpose (reverse mode) multiplies no zero cotangent by `inf`."""
    coef, g1 = primals
    dcoef, _ = tangents
    th = root(coef, g1)
    slope = jnp.zeros_like(th)
    for k in reversed(range(1, 6)):
        slope = slope * th + k * coef[k]
    ok = (slope != 0) & jnp.isfinite(slope) & jnp.isfinite(th)
    ths = jnp.where(ok, th, 0)
    dp = jnp.zeros_like(th)
    for k in reversed(range(6)):
        dp = dp * ths + dcoef[k]
    return th, jnp.where(ok, -dp / jnp.where(ok, slope, 1), 0)


def predict(g, d, e):
    r"""Time to the root of the Taylor quadratic $g + \dot g s + \ddot g s^2/2$ of an event
    function that is approaching zero (linear estimate plus one Newton step); `inf` if none."""
    ok = (g > 0) & (d < 0)
    s1 = g / jnp.where(ok, -d, 1)
    slope = d + e * s1
    ok = ok & (slope < 0)
    s2 = s1 - 0.5 * e * s1 * s1 / jnp.where(ok, slope, -1)
    return jnp.where(ok & (s2 > 0), s2, jnp.inf)


def hermite_basis(th):
    """Quintic Hermite basis $(H_1, H_2, H_3, H_4, H_5)$ ($H_0 = 1 - H_3$)."""
    t2 = th * th
    t3 = t2 * th
    t4 = t3 * th
    t5 = t4 * th
    H1 = th - 6 * t3 + 8 * t4 - 3 * t5
    H2 = 0.5 * t2 - 1.5 * t3 + 1.5 * t4 - 0.5 * t5
    H3 = 10 * t3 - 15 * t4 + 6 * t5
    H4 = -4 * t3 + 7 * t4 - 3 * t5
    H5 = 0.5 * t3 - t4 + 0.5 * t5
    return H1, H2, H3, H4, H5


def margins(omega, h, located, decide, crossed, g0s, d0s, e0s):
    """One step's margins to a change of switching structure, as squared drive phases
    (the exact engine's docstring, "Margins"): `(cross, near)`, each `inf` where there is none.

    - `cross`: at each located crossing `located = ((fired, rate, curvature), ...)` of an
      event function $g$ (its rate and curvature there, in the mode before the switch),
      $(\\omega\\,\\dot g/\\ddot g)^2$; at each decision `decide = ((fired, s, rate), ...)` (a
      slipping mass whose velocity reached zero sticks if $s = \\mu_s n_i - |F_i| \\ge 0$, else
      reverses), $(\\omega s/\\dot s)^2$.
    - `near`: over every event function $g_0 + \\dot g_0 s + \\ddot g_0 s^2/2$ (values at the
      step's start) that turns inside the step of length `h` without crossing,
      $2\\omega^2 g_{\\min}/\\ddot g_0$ ($0$ if the parabola dips below zero: an excursion
      shorter than the step).

    Without a drive ($\\omega = 0$) a margin at an event is 0 and stays `inf` where there is none.

    Values only: they are held out of forward-mode derivatives (`stop_gradient`). Each
    function is a scalar of its own: a stacked `(lanes, n)` array would exceed the 64
    elements per kernel above which XLA's CPU runtime splits a kernel over threads
    (`_runs.MICRO_BATCH_CPU`).
    """
    sq = jax.lax.stop_gradient
    h = sq(h)
    w2 = sq(omega * omega)
    zero = jnp.zeros_like(h)
    cross = []
    for fired, num, den in (*located, *decide):
        num, den = sq(num), sq(den)
        cross.append((jnp.where(fired, num * num, 1), jnp.where(fired, den * den, zero)))
    near = []
    for c_i, g0, d0, e0 in zip(crossed, g0s, d0s, e0s):
        g0, d0, e0 = sq(g0), sq(d0), sq(e0)
        turns = (e0 > 0) & (d0 < 0) & (-d0 <= h * e0) & ~c_i
        near.append((jnp.where(turns, jnp.maximum(2 * g0 * e0 - d0 * d0, 0), 1), jnp.where(turns, e0 * e0, zero)))
    # `inf` (no margin) stays `inf` without a drive too (w2 = 0), not NaN.
    return tuple(jnp.where(r < jnp.inf, w2 * r, r) for r in (_smallest_ratio(pairs) for pairs in (cross, near)))


def _smallest_ratio(pairs: list) -> Array:
    """$\\min_i a_i / b_i$ over pairs with $a_i \\ge 0$, $b_i \\ge 0$ (none: $a_i > 0 = b_i$, `inf`),
    chosen by cross-multiplied comparisons, so that one division serves them all (XLA
    makes a kernel of each division, and fuses their operands into every one of them)."""
    pairs = [_least_pair(a, b) for a, b in pairs]
    a, b = pairs[0]
    for ai, bi in pairs[1:]:
        smaller = ai * b < a * bi
        a, b = jnp.where(smaller, ai, a), jnp.where(smaller, bi, b)
    return jnp.where(b > 0, a / jnp.where(b > 0, b, 1), jnp.inf)


def _least_pair(a: Array, b: Array) -> tuple[Array, Array]:
    """A pair $(a, b)$ of [`_smallest_ratio`][] as it is for a scalar entry; for an entry with a body
    axis (the array layout) the smallest ratio over the bodies as $(r, 1)$ (none: $(1, 0)$)."""
    if jnp.ndim(a) == 0 and jnp.ndim(b) == 0:
        return a, b
    r = jnp.min(jnp.where(b > 0, a / jnp.where(b > 0, b, 1), jnp.inf))
    ok = r < jnp.inf
    return jnp.where(ok, r, 1), jnp.where(ok, 1, 0).astype(r.dtype)


def target_margin(before: Array, gs: list, ds: list, es: list) -> Array:
    """The time between the caller's target crossing and the nearest change of its
    switching structure, from the engine's `probe` there (target last): the vertex of the target
    function's local parabola ($|\\dot g/\\ddot g|$), the last switch (`before`: the time
    since it) or the next one predicted by the Taylor quadratic of each other event
    function. A switch that crosses the target's time leaves that time differentiable
    (the velocities are continuous) but changes its curvature in the parameters, so
    that the derivative holds over a smaller range."""
    inf = jnp.asarray(jnp.inf, before.dtype)
    vertex = jnp.where(es[-1] != 0, ds[-1] / jnp.where(es[-1] != 0, es[-1], 1), inf)
    after = inf
    for g, d, e in zip(gs[:-1], ds[:-1], es[:-1]):
        after = jnp.minimum(after, within(predict(g, d, e), jnp.min))
    return jax.lax.stop_gradient(jnp.minimum(jnp.minimum(before, after), jnp.abs(vertex)))


def union(flags: Sequence[Array]) -> Array:
    """The `or` of a list of boolean entries (one per event or per body); `False` for none (a
    one-body mechanism has no gaps between neighbours). An entry with a body axis (the array
    layout, `_chain_array`: one entry holds every body) counts as the `or` over it."""
    if not flags:
        return jnp.asarray(False)
    flags = [within(f, jnp.any) for f in flags]
    out = flags[0]
    for f in flags[1:]:
        out = out | f
    return out


def within(x: Array, reduce) -> Array:
    """`reduce(x)` over an entry's body axis, `x` itself for a scalar entry. The engine runs one
    configuration at a time (under `vmap`), so an entry is a scalar (one body: the unrolled
    layout) or a vector over bodies (the array layout); a scalar entry is returned as it is."""
    return x if jnp.ndim(x) == 0 else reduce(x)


def least(values: Sequence[Array]) -> Array:
    """The smallest value over a list of entries (and over the bodies of an array entry)."""
    out = within(values[0], jnp.min)
    for q in values[1:]:
        out = jnp.minimum(out, within(q, jnp.min))
    return out


def total(terms: Sequence[Array]) -> Array:
    """The sum over a list of entries (and over the bodies of an array entry), left to right, in
    the entries' dtype (a count of int32 entries stays int32 under float64)."""
    terms = [within(q, lambda a: jnp.sum(a, dtype=a.dtype)) for q in terms]
    return sum(terms[1:], terms[0])


def lowest_first(first: Sequence[Array], values: Sequence[Sequence[Array]]) -> list[Array]:
    """Of the events flagged `first` (a list of entries), the `values` (per event, a tuple of
    arrays shaped like its entry) of the lowest index, bodies ordered within an entry; the last
    event's (its first body's) where none is flagged."""

    def at(flag: Array, vals: Sequence[Array]) -> tuple[Array, list[Array]]:
        if jnp.ndim(flag) == 0:
            return flag, list(vals)
        i = jnp.argmax(flag)  # the first flagged body, or 0
        return jnp.any(flag), [v[i] for v in vals]

    pick = at(first[-1], values[-1])[1]
    for i in reversed(range(len(first) - 1)):
        hit, vals = at(first[i], values[i])
        pick = [jnp.where(hit, v, p) for v, p in zip(vals, pick)]
    return pick


def rotate(c: Array, s: Array, ca: Array, sa: Array) -> tuple[Array, Array]:
    """The phase $(\\cos, \\sin)$ = `(c, s)` advanced by the angle whose cosine and sine are `ca`, `sa`."""
    return c * ca - s * sa, s * ca + c * sa
