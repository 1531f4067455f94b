"""The period map of the exact two-mass model, and what one period of it accumulates.

The forcing is $T$-periodic ($T = 2\\pi/\\omega$) and the dynamics (eqs. 2-9) depend on the
positions only through the gap $u = x_2 - x_1$, so the state that repeats on a steady gait is
$y = (u, v_1, v_2)$ at the phase $\\omega t \\equiv 0$; $\\Phi_k$ integrates $k$ periods from there
with the exact engine. Beside the end state it accumulates the centre of mass's drift (eq. 4),
$e_d$ (eq. 15), $w$ (eq. 16), the time each mass is stuck, the switches, and two test functions
of the switching structure: the slip margin (the smallest $|F_i| - \\mu_s n_i$ where a slipping
mass's velocity reaches zero, eq. 7) and the smallest normal force (eq. 5). One configuration;
[`steady_gait`][] and the continuation's corrector batch it.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp

from .._custom_types import Array
from .._status import Status
from ..dynamics import _exact as exact
from ..dynamics._numerics import quintic
from ..model import _two_mass as model
from ..model._params import safe_params


class Period(NamedTuple):
    """One application of the period map: the end state and what the period accumulated."""

    y: Array  # (u, v1, v2) at the end
    dX: Array
    ed: Array
    w: Array
    stuck1: Array
    stuck2: Array
    margin: Array
    n_min: Array
    n_switch: Array
    status: Array
    lifted: Array


def reduced(st: exact.Hybrid) -> Array:
    """The period map's state $(u, v_1, v_2)$ of a hybrid state."""
    return jnp.stack([st.y.x2 - st.y.x1, st.y.v1, st.y.v2])


def section_state(params, wave, contact, y):
    """The hybrid state at phase 0 for $y = (u, v_1, v_2)$ with $x_1 = 0$ ([`_exact.init`][]:
    a mass at rest sticks if eq. (7) allows, a moving one slips along $v_i$)."""
    return exact.init(params, wave, contact, jnp.zeros((), params.dtype), y[0], y[1], y[2])


class Orbit(NamedTuple):
    """What `advance` accumulates besides the state."""

    stuck1: Array  # time each mass was stuck
    stuck2: Array
    margin: Array  # smallest |F_i| - mu_s n_i at a slipping mass's velocity zero (inf: none)
    n_min: Array  # smallest normal force min(N_1, N_2) over the committed steps
    slid1: Array  # whether each mass slipped at all
    slid2: Array


def fy_range(info: exact.StepInfo) -> tuple[Array, Array]:
    """Smallest and largest $f_y$ over a committed step, on the quintic Hermite interpolant
    of its end values and rates (an interior extremum polished by Newton's method)."""
    g0, d0, e0, g1, d1, e1 = info.fy
    h = info.h
    c = quintic(g0, h * d0, h * h * e0, g1, h * d1, h * h * e1)
    end = jnp.clip((info.t1 - info.t0) / jnp.where(h > 0, h, 1), 0, 1)
    p = lambda th: c[0] + th * (c[1] + th * (c[2] + th * (c[3] + th * (c[4] + th * c[5]))))
    dp = lambda th: c[1] + th * (2 * c[2] + th * (3 * c[3] + th * (4 * c[4] + th * 5 * c[5])))
    ddp = lambda th: 2 * c[2] + th * (6 * c[3] + th * (12 * c[4] + th * 20 * c[5]))
    pe = p(end)
    lo, hi = jnp.minimum(g0, pe), jnp.maximum(g0, pe)
    dp0, dpe = c[1], dp(end)
    inside = dp0 * dpe < 0
    th = end * dp0 / jnp.where(inside, dp0 - dpe, 1)
    for _ in range(3):
        curv = ddp(th)
        th = jnp.clip(th - dp(th) / jnp.where(curv != 0, curv, 1), 0, end)
    pm = p(th)
    return jnp.where(inside, jnp.minimum(lo, pm), lo), jnp.where(inside, jnp.maximum(hi, pm), hi)


def advance(params, wave, P, contact, dt, st, t_end, max_steps):
    """Integrate to `t_end` (or a strict lift-off, or the step cap); also what [`Orbit`][] accumulates."""
    dtype = params.dtype
    zero = jnp.zeros((), dtype)
    inf = jnp.asarray(jnp.inf, dtype)
    no = jnp.asarray(False)

    def cond(c):
        s, _, n = c
        return (s.t < t_end) & (s.status == Status.OK) & (n < max_steps)

    def body(c):
        s, a, n = c
        new, info = exact.step(params, wave, contact, dt, s, t_end, None, P)
        span = jnp.where(info.commit, info.t1 - info.t0, 0)
        lo, hi = fy_range(info)
        n_step = jnp.minimum(P.m1 - hi, P.m2 + lo)  # eq. (5): N_1 = m_1 - f_y, N_2 = m_2 + f_y
        zero1, zero2 = info.commit & info.zero1, info.commit & info.zero2
        a = Orbit(
            stuck1=a.stuck1 + jnp.where(info.stuck1, span, 0),
            stuck2=a.stuck2 + jnp.where(info.stuck2, span, 0),
            margin=jnp.minimum(
                a.margin, jnp.minimum(jnp.where(zero1, -info.slack1, inf), jnp.where(zero2, -info.slack2, inf))
            ),
            n_min=jnp.minimum(a.n_min, jnp.where(info.commit, n_step, inf)),
            slid1=a.slid1 | (~info.stuck1 & (span > 0)),
            slid2=a.slid2 | (~info.stuck2 & (span > 0)),
        )
        return new, a, n + 1

    init = Orbit(zero, zero, inf, inf, no, no)
    st, a, _ = jax.lax.while_loop(cond, body, (st, init, jnp.zeros((), jnp.int32)))
    return st, a


def period_map(params, wave, P, contact, dt, max_steps, k, y) -> Period:
    """$\\Phi_k(y)$ and what the $k$ periods accumulate ([`Period`][]).

    A normal force that dips below zero between two step ends (a grazing excursion shorter than
    the step, which the engine does not locate) still counts: under the strict reading such a
    period ends with `Status.LIFTOFF` like a located one, so that lift-off does not depend on the
    step."""
    t_end = k * (2 * jnp.pi) / wave.omega
    st0 = section_state(params, wave, contact, y)
    st, a = advance(params, wave, P, contact, dt, st0, t_end, max_steps)
    com = lambda s: P.mhat * s.y.x1 + (1 - P.mhat) * s.y.x2
    ok = (st.status == Status.OK) & (st.t >= t_end)
    status = jnp.where(ok, Status.OK, jnp.where(st.status == Status.OK, Status.MAX_STEPS, st.status))
    if contact == "strict":
        status = jnp.where(a.n_min < 0, Status.LIFTOFF, status)
    return Period(
        y=reduced(st),
        dX=com(st) - com(st0),
        ed=st.y.ed,
        w=st.y.w,
        stuck1=a.stuck1,
        stuck2=a.stuck2,
        # A mass that never slips is stuck throughout: a stick interval without a velocity zero.
        margin=jnp.where(a.slid1 & a.slid2, a.margin, -jnp.inf),
        n_min=a.n_min,
        n_switch=st.n_switch,
        status=status,
        lifted=jnp.isfinite(st.t_liftoff) | (a.n_min < 0),
    )


def transient_one(params, wave, contact, start, dt, transient, max_steps):
    """`transient` actuation periods from the start: the end's reduced state, the parameters'
    validity, the run's `Status` and whether a normal force reached zero. One configuration.
    `start` names an initial condition at rest (`"paper"`, `"relaxed"`), or is a section state
    $(u, v_1, v_2)$ at phase 0."""
    params, valid = safe_params(params, wave)
    P = exact.consts(params, wave)
    if isinstance(start, str):
        st = exact.init(params, wave, contact, jnp.zeros((), params.dtype), model.initial_gap(params, start))
    else:
        st = section_state(params, wave, contact, start)
    st, _ = advance(params, wave, P, contact, dt, st, transient * (2 * jnp.pi) / wave.omega, max_steps)
    return reduced(st), valid, st.status, jnp.isfinite(st.t_liftoff)
