"""Exact hybrid stick/slip dynamics of a chain of N masses (SPEC §2 and §8).

The scheme of the two-mass engine (`locomotion_jax._exact`, whose docstring states
it in full) over arrays of masses and springs: one RK4 step per iteration, cut at
the earliest located event; a quintic Hermite dense output from the state's first
and second time derivatives at both ends of the step; every mass re-decided at the
start of the next iteration.

What generalises is written once over arrays: the loads on each mass depend only on
positions, time and the actuation, so each mass's stick condition is decided on its
own, and any number of masses may switch at one instant. The first and second time
derivatives of the rates and of the event functions, which the dense output and the
event prediction need, are forward-mode derivatives (`jax.jvp`) of those functions
along the motion in a fixed mode, so a new friction law or actuator supplies values
only.

**Events** (each fires when its function goes from $\\ge 0$ to $< 0$), an array:

- mass $i$ slipping in direction $\\sigma_i$: $\\sigma_i v_i$;
- mass $i$ stuck: $\\min(\\mu_{s,\\mathrm{fwd}} n_i - F_i,\\; F_i + \\mu_{s,\\mathrm{bwd}} n_i)$ (eq. 7 generalised);
- strict contact: $\\min_i N_i$ (lift-off), which stops the run;
- paper contact: $\\nu_i N_i$ for each mass, with $\\nu_i = \\pm 1$ the side of $N_i$: $n_i = |N_i|$
  has a kink where $N_i$ changes sign, so the step is cut there and $\\nu_i$ flips (the first
  crossing, from above, sets `t_liftoff`). Inside a step $n_i = \\nu_i N_i$, smooth, so that the
  step's dense output and the derivatives along the motion stay accurate;
- optionally a caller's target $z - |X - X_0|$.
"""

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from .. import _exact as two_mass
from .._custom_types import Array, Contact
from .._status import Status
from ..model._chain import Chain


class State(NamedTuple):
    """Integrated quantities: positions `x` (N,), velocities `v` (N,), $e_d$ (eq. 15) and $w$ (eq. 16)."""

    x: Array
    v: Array
    ed: Array
    w: Array

    def map(self, fn, *others) -> "State":
        return State(*(fn(*xs) for xs in zip(self, *others)))


class Hybrid(eqx.Module):
    """Integrator state of one configuration (compare `_exact.Hybrid`).

    `stuck`, `sdir`, `pend` are per-mass arrays: the mode, slip direction and a flag
    for an event located at `t` (the mass is re-decided at the next iteration); `side`
    the side ($\\pm 1$) of each normal force (paper contact: flipped where a crossing is
    located, so that $n_i = \\nu_i N_i$ over a step). `cross`, `near`, `t_switch`: the margins
    to a change of switching structure so far and the last switch (as in `_exact.Hybrid`).
    """

    t: Array
    y: State
    comp: State | None
    cph: Array
    sph: Array
    stuck: Array
    sdir: Array
    pend: Array
    side: Array
    status: Array
    t_liftoff: Array
    n_switch: Array
    cross: Array
    near: Array
    t_switch: Array


class StepInfo(NamedTuple):
    """What one iteration did (compare `_exact.StepInfo`); `stuck` is the mode during `[t0, t1]`."""

    commit: Array
    t0: Array
    y0: State
    tension0: Array
    t1: Array
    y1: State
    stuck: Array
    target_fired: Array
    t_target: Array
    y_target: State


class Drive(NamedTuple):
    """Actuation at one instant: rest lengths and internal forces with their first two rates."""

    l0: Array
    dl0: Array
    ddl0: Array
    f: Array
    df: Array
    ddf: Array


def drive(C: Chain, cph: Array, sph: Array) -> Drive:
    """The springs' rest lengths and internal forces at phase $(\\cos\\omega t, \\sin\\omega t)$."""
    s, ds, dds = C.waves.at_phase(cph, sph)
    split = C.actuator.split
    zero = jnp.zeros_like(C.lbar)
    (l0, f), (dl0, df), (ddl0, ddf) = split(C.lbar, s), split(zero, ds), split(zero, dds)
    return Drive(l0, dl0, ddl0, f, df, ddf)


def _diff(a: Array) -> Array:
    """$a_i - a_{i-1}$ over masses for a per-spring array (missing springs count zero)."""
    zero = jnp.zeros_like(a[:1])
    return jnp.concatenate([a, zero]) - jnp.concatenate([zero, a])


def loads(
    C: Chain, contact: Contact, l0: Array, f: Array, x: Array, side: Array | None = None
) -> tuple[Array, Array, Array, Array]:
    """Tensions $T_j$, horizontal loads $F_i$, signed normal forces $N_i$ and the normal forces
    $n_i$ entering friction, SPEC §8: $N_i$ (strict) or $|N_i|$ (paper); with `side`
    $\\nu_i$ (paper, inside a step) $\\nu_i N_i$, which is $|N_i|$ on the side the step started on,
    continued smoothly past a crossing (where the step is cut)."""
    u = x[1:] - x[:-1]
    length = jnp.sqrt(u * u + C.d * C.d)
    tension = C.k * (length - l0)
    per_len = tension / length
    F = _diff(per_len * u + f)
    N = C.m - _diff(per_len * C.d)
    if contact != "paper":
        n = N
    elif side is None:
        n = jnp.abs(N)
    else:
        n = side * N
    return tension, F, N, n


def _accel(C: Chain, contact, stuck, sdir, side, l0, f, x, v) -> Array:
    """Accelerations in a fixed mode: $m_i \\dot v_i = F_i - c_i v_i - \\sigma_i \\mu_k n_i$; zero when stuck."""
    _, F, _, n = loads(C, contact, l0, f, x, side)
    mu = C.friction.kinetic(sdir * v, sdir)
    return jnp.where(stuck, 0, (F - C.c * v - sdir * mu * n) / C.m)


def _rates(C: Chain, contact, stuck, sdir, side, l0, dl0, f, x, v) -> State:
    """Rates of every state entry: $\\dot x_i$, $\\dot v_i$, and the integrands of $e_d$ and $w$."""
    tension, F, _, n = loads(C, contact, l0, f, x, side)
    speed = sdir * v  # |v_i| in a slip segment; 0 when stuck
    mu = C.friction.kinetic(speed, sdir)
    a = jnp.where(stuck, 0, (F - C.c * v - sdir * mu * n) / C.m)
    xd = jnp.where(stuck, 0, v)
    ed = (mu * n * speed + C.c * v * v).sum()
    return State(xd, a, ed, C.actuator.power(tension, dl0, f, v))


def mass_events(C: Chain, stuck: Array, sdir: Array, F: Array, n: Array, v: Array) -> Array:
    """The per-mass event functions (module docstring)."""
    mu_f, mu_b = C.friction.static_limits()
    return jnp.where(stuck, jnp.minimum(mu_f * n - F, F + mu_b * n), sdir * v)


def _events(C: Chain, contact, stuck, sdir, side, target, l0, f, x, v) -> Array:
    """Event values: per mass, then lift-off (strict: one) or the normal forces' crossings
    (paper: one per mass), then the target (module docstring)."""
    _, F, N, n = loads(C, contact, l0, f, x, side)
    gs = [mass_events(C, stuck, sdir, F, n, v)]
    if contact == "strict":
        gs.append(N.min()[None])
    else:
        gs.append(side * N)
    if target is not None:
        rel = (C.m * x).sum() / C.m.sum() - target.X0
        gs.append(jnp.where(target.active, target.z - jnp.abs(rel), jnp.inf)[None])
    return jnp.concatenate(gs)


def _with_derivatives(C, contact, stuck, sdir, side, target, dr: Drive, y: State):
    """Rates and event values with their first and second time derivatives along the motion.

    Returns `(r, j, g, dg, ddg)`: the state's rate $\\dot y$ and second derivative $\\ddot y$, and
    the events' values and first two derivatives, by nested `jax.jvp` in a fixed mode.
    """

    def both(l0, dl0, f, x, v):
        rates = _rates(C, contact, stuck, sdir, side, l0, dl0, f, x, v)
        return rates, _events(C, contact, stuck, sdir, side, target, l0, f, x, v)

    def first(l0, dl0, f, df, x, v):
        a = _accel(C, contact, stuck, sdir, side, l0, f, x, v)
        xd = jnp.where(stuck, 0, v)
        return jax.jvp(both, (l0, dl0, f, x, v), (dl0, dr.ddl0, df, xd, a))

    args = (dr.l0, dr.dl0, dr.f, dr.df, y.x, y.v)
    a = _accel(C, contact, stuck, sdir, side, dr.l0, dr.f, y.x, y.v)
    xd = jnp.where(stuck, 0, y.v)
    # The outer jvp differentiates `first` along the motion once more; only the events'
    # second derivative is taken from it (the rates' would need the third rate of l0).
    ((r, g), (rd, gd)), (_, (_, gdd)) = jax.jvp(first, args, (dr.dl0, dr.ddl0, dr.df, dr.ddf, xd, a))
    return r, rd, g, gd, gdd


def energy(C: Chain, y: State, tension: Array) -> Array:
    """$e = \\sum_i m_i v_i^2/2 + \\sum_j T_j^2/(2 k_j)$ (eq. 10 generalised)."""
    return 0.5 * ((C.m * y.v * y.v).sum() + (tension * tension / C.k).sum())


def init(C: Chain, contact: Contact, x: Array) -> Hybrid:
    """State at $t = 0$, at rest at positions `x`; each mass sticks if its stick condition holds."""
    dtype = x.dtype
    zero = jnp.zeros((), dtype)
    cph, sph = jnp.ones((), dtype), zero
    dr = drive(C, cph, sph)
    _, F, N, n = loads(C, contact, dr.l0, dr.f, x)
    mu_f, mu_b = C.friction.static_limits()
    stuck = (F <= mu_f * n) & (F >= -mu_b * n)
    sdir = jnp.where(F >= 0, 1.0, -1.0).astype(dtype)
    lifted = jnp.any(N <= 0)
    status = jnp.where(lifted & (contact == "strict"), Status.LIFTOFF, Status.OK).astype(jnp.int32)
    f32 = jnp.finfo(dtype).bits < 64
    y = State(x, jnp.zeros_like(x), zero, zero)
    return Hybrid(
        t=zero, y=y, comp=y.map(jnp.zeros_like) if f32 else None, cph=cph, sph=sph, stuck=stuck, sdir=sdir,
        pend=jnp.zeros_like(stuck), side=jnp.where(N > 0, 1.0, -1.0).astype(dtype), status=status,
        t_liftoff=jnp.where(lifted, zero, jnp.inf).astype(dtype), n_switch=jnp.zeros((), jnp.int32),
        cross=jnp.asarray(jnp.inf, dtype), near=jnp.asarray(jnp.inf, dtype), t_switch=jnp.asarray(-jnp.inf, dtype),
    )  # fmt: skip


def probe(C: Chain, contact: Contact, t: Array, y: State, target: two_mass.Target) -> tuple[Array, Array, Array]:
    """The event functions with their first and second time derivatives at time `t` and
    state `y`, in the mode the state implies (a mass at rest sticks where its static limits
    hold; compare `_exact.probe`). For margins at a measured instant; not for the hot loop."""
    omega = C.waves.omega
    dr = drive(C, jnp.cos(omega * t), jnp.sin(omega * t))
    _, F, N, n = loads(C, contact, dr.l0, dr.f, y.x)
    mu_f, mu_b = C.friction.static_limits()
    stuck = (F <= mu_f * n) & (F >= -mu_b * n) & (y.v == 0)
    one = jnp.ones_like(y.v)
    sdir = jnp.where(y.v > 0, one, jnp.where(y.v < 0, -one, jnp.where(F >= 0, one, -one)))
    side = jnp.where(N > 0, one, -one)
    y = y._replace(v=jnp.where(stuck, 0, y.v))
    _, _, g, d, e = _with_derivatives(C, contact, stuck, sdir, side, target, dr, y)
    return g, d, e


def initial_positions(C: Chain, start: str) -> Array:
    """Positions at $t = 0$: gaps $\\bar\\ell_j$ (`"paper"`, eq. 14) or the relaxed springs
    $\\sqrt{\\ell_{0,j}(0)^2 - d_j^2}$ (`"relaxed"`), with $x_0 = 0$ (SPEC §8)."""
    if start == "paper":
        gaps = C.lbar
    elif start == "relaxed":
        l0 = drive(C, jnp.ones_like(C.waves.omega), jnp.zeros_like(C.waves.omega)).l0
        gaps = jnp.sqrt(jnp.maximum(l0 * l0 - C.d * C.d, 0))
    else:
        raise ValueError(f"start must be 'paper' (eq. 14) or 'relaxed', got {start!r}.")
    return jnp.concatenate([jnp.zeros_like(gaps[:1]), jnp.cumsum(gaps)])


def step(
    C: Chain, contact: Contact, dt: float, st: Hybrid, t_stop: Array, target: two_mass.Target | None = None
) -> tuple[Hybrid, StepInfo]:
    """One iteration: re-decide the masses, one RK4 step, cut at the first event (see `_exact.step`)."""
    dtype = st.t.dtype
    t0, yA = st.t, st.y
    n_mass = C.m.shape[-1]

    # -- start: every mass whose event was located here (pend) or whose event function is
    # negative switches: a stuck one slips in the direction of F_i; a slipping one (v_i = 0)
    # sticks if the static limits hold, else it slips the other way.
    dr0 = drive(C, st.cph, st.sph)
    tension0, F0, N0, n0 = loads(C, contact, dr0.l0, dr0.f, yA.x)
    gA = mass_events(C, st.stuck, st.sdir, F0, n0, yA.v)
    fire = st.pend | (gA < 0)
    mu_f, mu_b = C.friction.static_limits()
    holds = (F0 <= mu_f * n0) & (F0 >= -mu_b * n0)
    vel = fire & ~st.stuck
    stuck = jnp.where(fire, vel & holds, st.stuck)
    sdir = jnp.where(fire, jnp.where(F0 >= 0, 1.0, -1.0).astype(dtype), st.sdir)
    y0 = yA._replace(v=jnp.where(vel, 0, yA.v))
    comp = st.comp
    if comp is not None:
        comp = comp._replace(v=jnp.where(vel, 0, comp.v))
    n_switch = st.n_switch + jnp.any(fire).astype(jnp.int32)

    lifted0 = jnp.any(N0 < 0)
    stop0 = lifted0 if contact == "strict" else jnp.asarray(False)
    t_lift = jnp.where(lifted0 & ~jnp.isfinite(st.t_liftoff), t0, st.t_liftoff)
    if target is not None:
        X_A = (C.m * yA.x).sum() / C.m.sum()
        target_now = target.active & (jnp.abs(X_A - target.X0) >= target.z)
        target = target._replace(active=target.active & ~target_now)
    else:
        target_now = jnp.asarray(False)

    side = st.side
    k1, j0, g0, d0, e0 = _with_derivatives(C, contact, stuck, sdir, side, target, dr0, y0)

    # -- step length: dt, or less to land on t_stop or just past the earliest predicted event.
    span = t_stop - t0
    h_nom = jnp.minimum(jnp.asarray(dt, dtype), span)
    s_pred = two_mass._predict(g0, d0, e0).min()
    h_pred = jnp.maximum(two_mass.PREDICT_MARGIN * s_pred, 64 * jnp.finfo(dtype).eps * jnp.maximum(jnp.abs(t0), 1))
    short = h_pred < h_nom
    lands = (span <= dt) & ~short
    t1 = jnp.where(lands, t_stop, t0 + jnp.where(short, h_pred, h_nom))
    h = t1 - t0
    omega = C.waves.omega
    sa, ca = two_mass.sincos(omega * (0.5 * h))
    cm, sm = two_mass._rotate(st.cph, st.sph, ca, sa)
    ce, se = two_mass._rotate(cm, sm, ca, sa)
    drm, dre = drive(C, cm, sm), drive(C, ce, se)

    # -- one RK4 step of length h.
    def stage(dr, y):
        return _rates(C, contact, stuck, sdir, side, dr.l0, dr.dl0, dr.f, y.x, y.v)

    k2 = stage(drm, y0.map(lambda a, b: a + (0.5 * h) * b, k1))
    k3 = stage(drm, y0.map(lambda a, b: a + (0.5 * h) * b, k2))
    k4 = stage(dre, y0.map(lambda a, b: a + h * b, k3))
    incr = k1.map(lambda a, b, c, d: (h / 6) * (a + 2 * (b + c) + d), k2, k3, k4)
    y1 = y0.map(lambda a, b: a + b, incr)
    r1, j1, g1, d1, e1 = _with_derivatives(C, contact, stuck, sdir, side, target, dre, y1)

    # -- events: the earliest crossing by the secant of each crossed function.
    crossed = g1 < 0
    cut = jnp.any(crossed)
    a0 = jnp.where(g0 == 0, h * d0, g0)  # deflated when starting on the surface
    den = a0 - g1
    theta_sec = jnp.where(crossed, a0 / jnp.where(den > 0, den, 1), jnp.inf)
    th_min = theta_sec.min()
    first = crossed & (theta_sec <= th_min)
    i = jnp.argmin(theta_sec)
    h2 = h * h
    coef = two_mass._quintic(jnp.maximum(g0[i], 0), h * d0[i], h2 * e0[i], jnp.minimum(g1[i], 0), h * d1[i], h2 * e1[i])
    theta = jnp.where(cut, two_mass._root(coef, jnp.minimum(g1[i], 0)), 1)

    # -- margins to a change of switching structure (`_exact.margins`); they feed nothing back.
    # A slipping mass that stopped sticks where s = min(mu_f n - F, F + mu_b n) >= 0.
    def limits(l0, f, x):
        _, F, _, n = loads(C, contact, l0, f, x)
        return jnp.minimum(mu_f * n - F, F + mu_b * n)

    hold, hold_rate = jax.jvp(limits, (dr0.l0, dr0.f, y0.x), (dr0.dl0, dr0.df, jnp.where(stuck, 0, y0.v)))
    target_cut = first[-1] if target is not None else jnp.asarray(False)
    decide = [(vel[i], hold[i], hold_rate[i]) for i in range(n_mass)]
    # The located crossing's rate and curvature from the event quintic at its root:
    # p'(theta)/h and p''(theta)/h^2.
    c = jax.lax.stop_gradient(coef)
    th = jax.lax.stop_gradient(theta)
    p1 = c[1] + th * (2 * c[2] + th * (3 * c[3] + th * (4 * c[4] + th * 5 * c[5])))
    p2 = 2 * c[2] + th * (6 * c[3] + th * (12 * c[4] + th * 20 * c[5]))
    located = [(cut & ~target_cut, h * p1, p2)]
    m_cross, m_near = two_mass.margins(omega, h, located, decide, list(crossed), list(g0), list(d0), list(e0))

    # -- commit: the full step, or the quintic dense output at the crossing.
    H1, H2, H3, H4, H5 = two_mass._hermite_basis(theta)
    part = incr.map(
        lambda inc, a, b, c, d: H3 * inc + h * H1 * a + h * H4 * b + h2 * H2 * c + h2 * H5 * d, k1, r1, j0, j1
    )
    delta = incr.map(lambda inc, p: jnp.where(cut, p, inc), part)
    tc = jnp.where(cut, t0 + theta * h, t1)
    sc, cc = two_mass.sincos(omega * (tc - t0))
    cph, sph = two_mass._rotate(st.cph, st.sph, cc, sc)
    cph, sph = jnp.where(cut, cph, ce), jnp.where(cut, sph, se)
    norm = 1.5 - 0.5 * (cph * cph + sph * sph)  # keeps the carried phase on the unit circle
    cph, sph = cph * norm, sph * norm
    if comp is None:
        yc = y0.map(lambda a, b: a + b, delta)
        comp_new = None
    else:  # compensated (Kahan) sums in float32, as in the two-mass engine
        corr = delta.map(lambda a, b: a - b, comp)
        yc = y0.map(lambda a, b: a + b, corr)
        comp_new = yc.map(lambda tot, a, b: (tot - a) - b, y0, corr)

    # A normal force's crossing: the first one is a lift-off (from above: no earlier one),
    # which stops the run under the strict reading; under the paper's the crossing force
    # changes side.
    if contact == "strict":
        lift_cut = first[n_mass]
        lift = stop0 | lift_cut
    else:
        flip = first[n_mass : 2 * n_mass]
        lift_cut = jnp.any(flip)
        lift = stop0
        side = jnp.where(flip, -side, side)
    t_lift = jnp.where(lift_cut & ~jnp.isfinite(t_lift), tc, t_lift)
    commit = ~stop0
    status = jnp.where(lift, Status.LIFTOFF, st.status).astype(jnp.int32)

    keep = lambda new, old: jnp.where(commit, new, old)
    new = Hybrid(
        t=keep(tc, t0), y=yc.map(keep, yA), comp=None if comp_new is None else comp_new.map(keep, st.comp),
        cph=keep(cph, st.cph), sph=keep(sph, st.sph), stuck=keep(stuck, st.stuck), sdir=keep(sdir, st.sdir),
        pend=commit & first[:n_mass], side=keep(side, st.side), status=status, t_liftoff=t_lift.astype(dtype),
        n_switch=n_switch, cross=jnp.where(commit, jnp.minimum(st.cross, m_cross), st.cross),
        near=jnp.where(commit, jnp.minimum(st.near, m_near), st.near),
        t_switch=jnp.where(commit & cut & ~target_cut, jax.lax.stop_gradient(tc), st.t_switch),
    )  # fmt: skip
    info = StepInfo(
        commit=commit, t0=t0, y0=y0, tension0=tension0, t1=tc, y1=yc, stuck=stuck,
        target_fired=target_now | (commit & target_cut), t_target=jnp.where(target_now, t0, tc),
        y_target=yc.map(lambda a, b: jnp.where(target_now, b, a), yA),
    )  # fmt: skip
    return new, info
