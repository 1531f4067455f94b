"""Exact hybrid stick/slip dynamics of a chain of N masses (SPEC §2 and §8).

The scheme of the two-mass engine (`locomotion_jax.dynamics._exact`, whose docstring states
it in full): one RK4 step per iteration, cut at the earliest located event; a
quintic Hermite dense output from the state's first and second time derivatives at
both ends of the step; every mass re-decided at the start of the next iteration.

What generalises is written once per mass and per spring: the loads on each mass
depend only on positions, time and the actuation, so each mass's stick condition is
decided on its own, and any number of masses may switch at one instant. The first and
second time derivatives of the rates and of the event functions, which the dense output
and the event prediction need, are written out by the chain rule
([`_chain_forces`][locomotion_jax.dynamics._chain_forces]); a friction law's rate is
its own [`kinetic_rate`][locomotion_jax.AbstractFriction.kinetic_rate] (by default a
forward-mode derivative of `kinetic`), so a new law or actuator supplies values only.

**Events** (each fires when its function goes from $\\ge 0$ to $< 0$), in this order:

- mass $i$ slipping in direction $\\sigma_i$: $\\sigma_i v_i$;
- mass $i$ stuck: $\\min(\\mu_{s,\\mathrm{fwd}} n_i - F_i,\\; F_i + \\mu_{s,\\mathrm{bwd}} n_i)$ (eq. 7 generalised);
- strict contact: $\\min_i N_i$ (lift-off), which stops the run;
- paper contact: $\\nu_i N_i$ for each mass, with $\\nu_i = \\pm 1$ the side of $N_i$: $n_i = |N_i|$
  has a kink where $N_i$ changes sign, so the step is cut there and $\\nu_i$ flips (the first
  crossing, from above, sets `t_liftoff`). Inside a step $n_i = \\nu_i N_i$, smooth, so that the
  step's dense output and the derivatives along the motion stay accurate;
- optionally a caller's target $z - |X - X_0|$.

**Margins** to a change of switching structure, as in the two-mass engine (`_numerics.margins`):
a located crossing's from the rate and curvature of its event quintic at the root; where a
slipping mass stops, from its stick margin and that margin's rate, both from the loads and
their rates that the step's start computes anyway; near misses from the event functions'
Taylor parabolas there.

**Speed.** As in the two-mass engine (its docstring, benchmarks/NOTES.md): the state is a
flat set of scalars (tuples over masses, so that under `vmap` every kernel is a vector
over the configurations), shared intermediates are pinned with [`keep`][], the phase
$(\\cos\\omega t, \\sin\\omega t)$ is carried and rotated, and the earliest event is picked
by `where` over the event list (no gather).
"""

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from .._custom_types import Array, Contact
from .._status import Status
from ..model._chain import Chain
from . import _chain_forces as forces, _chain_motion as motion, _numerics as num
from ._chain_forces import Consts, consts, drive, Scalars
from ._chain_motion import energy as energy, keep, Mode, State


class Hybrid(eqx.Module):
    """Integrator state of one configuration (compare `_exact.Hybrid`): a flat pytree of scalars.

    `stuck`, `sdir`, `pend`, `side` have one entry per mass: the mode, slip direction, a
    flag for an event located at `t` (the mass is re-decided at the next iteration), and the
    side ($\\pm 1$) of its normal force (paper contact: flipped where a crossing is located,
    so that $n_i = \\nu_i N_i$ over a step). `cross`, `near`, `t_switch`: the margins to a
    change of switching structure so far and the time of the last switch (as in `_exact.Hybrid`).
    """

    t: Array
    y: State
    comp: State | None
    cph: Array
    sph: Array
    stuck: Scalars
    sdir: Scalars
    pend: Scalars
    side: Scalars
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
    tension0: Scalars
    t1: Array
    y1: State
    stuck: Scalars
    target_fired: Array
    t_target: Array
    y_target: State


def init(C: Chain, contact: Contact, x: Array, P: Consts | None = None) -> Hybrid:
    """State at $t = 0$, at rest at positions `x` (shape `(N,)`); each mass sticks if its stick condition holds."""
    P = consts(C) if P is None else P
    dtype = x.dtype
    zero = jnp.zeros((), dtype)
    xs = forces.unstack(x)
    cph, sph = jnp.ones((), dtype), zero
    dr = drive(P, cph, sph)
    sp = forces.springs(P, dr.l0, xs)
    F, N = forces.loads(P, sp.fx, sp.fy, dr.f)
    n = motion.normal(contact, N)
    stuck = tuple(p >= 0 for p in motion.stick_margin(P, F, n))
    sdir = tuple(jnp.where(f >= 0, 1.0, -1.0).astype(dtype) for f in F)
    lifted = jnp.any(jnp.stack([q <= 0 for q in N]))
    status = jnp.where(lifted & (contact == "strict"), Status.LIFTOFF, Status.OK).astype(jnp.int32)
    f32 = jnp.finfo(dtype).bits < 64
    y = State(xs, tuple(jnp.zeros_like(a) for a in xs), zero, zero)
    return Hybrid(
        t=zero, y=y, comp=y.map(jnp.zeros_like) if f32 else None, cph=cph, sph=sph, stuck=stuck, sdir=sdir,
        pend=tuple(jnp.zeros_like(s) for s in stuck), side=tuple(jnp.where(q > 0, 1.0, -1.0).astype(dtype) for q in N),
        status=status, t_liftoff=jnp.where(lifted, zero, jnp.inf).astype(dtype), n_switch=jnp.zeros((), jnp.int32),
        cross=jnp.asarray(jnp.inf, dtype), near=jnp.asarray(jnp.inf, dtype), t_switch=jnp.asarray(-jnp.inf, dtype),
    )  # fmt: skip


def probe(
    C: Chain | None, contact: Contact, t: Array, y: State, target: num.Target, P: Consts | None = None
) -> tuple[list, list, list]:
    """The event functions with their first and second time derivatives at time `t` and
    state `y`, in the mode the state implies (a mass at rest sticks where its static limits
    hold; compare `_exact.probe`): lists in the order of the module docstring (target last).
    For margins at a measured instant; not for the hot loop. `P` as in [`step`][]."""
    if P is None:
        if C is None:
            raise TypeError("probe needs the chain C or its constants P.")
        P = consts(C)
    dtype = t.dtype
    dr = drive(P, jnp.cos(P.omega * t), jnp.sin(P.omega * t))
    sp = forces.springs(P, dr.l0, y.x)
    F, N = forces.loads(P, sp.fx, sp.fy, dr.f)
    n = motion.normal(contact, N)
    stuck = tuple((p >= 0) & (v == 0) for p, v in zip(motion.stick_margin(P, F, n), y.v))
    one = jnp.ones((), dtype)
    sdir = tuple(jnp.where(v > 0, one, jnp.where(v < 0, -one, jnp.where(f >= 0, one, -one))) for v, f in zip(y.v, F))
    side = tuple(jnp.where(q > 0, one, -one) for q in N)
    v = tuple(jnp.where(s, 0, vi) for s, vi in zip(stuck, y.v))
    D = motion.derivatives(P, contact, Mode(stuck, sdir, side), target, dr, sp, F, N, y.x, v)
    return D.g, D.dg, D.ddg


def initial_positions(C: Chain, start: str) -> Array:
    """Positions at $t = 0$: gaps $\\bar\\ell_j$ (`"paper"`, eq. 14) or the relaxed springs
    $\\sqrt{\\ell_{0,j}(0)^2 - d_j^2}$ (`"relaxed"`), with $x_0 = 0$ (SPEC §8)."""
    if start == "paper":
        gaps = C.lbar
    elif start == "relaxed":
        P = consts(C)
        l0 = jnp.stack(drive(P, jnp.ones_like(P.omega), jnp.zeros_like(P.omega)).l0, -1)
        gaps = jnp.sqrt(jnp.maximum(l0 * l0 - C.d * C.d, 0))
    else:
        raise ValueError(f"start must be 'paper' (eq. 14) or 'relaxed', got {start!r}.")
    return jnp.concatenate([jnp.zeros_like(gaps[..., :1]), jnp.cumsum(gaps, -1)], -1)


def step(
    C: Chain | None,
    contact: Contact,
    dt: float,
    st: Hybrid,
    t_stop: Array,
    target: num.Target | None = None,
    P: Consts | None = None,
) -> tuple[Hybrid, StepInfo]:
    """One iteration: re-decide the masses, one RK4 step, cut at the first event (see `_exact.step`).

    `P` are the constants of `C` ([`_chain_forces.consts`][locomotion_jax.dynamics._chain_forces.consts];
    pass them to compute them once per run rather than per iteration)."""
    if P is None:
        if C is None:
            raise TypeError("step needs the chain C or its constants P.")
        P = consts(C)
    kp = lambda x: keep(P, x)
    dtype = st.t.dtype
    t0, yA = st.t, st.y
    n_mass = len(P.m)
    zero = jnp.zeros_like(t0)

    # -- switch: every mass whose event was located here (pend) or whose event function is
    # negative switches: a stuck one slips in the direction of F_i; a slipping one (v_i = 0)
    # sticks if the static limits hold, else it slips the other way.
    dr0 = motion.kept(P, drive(P, st.cph, st.sph))
    sp0 = forces.springs(P, dr0.l0, yA.x)
    sp0 = sp0._replace(fx=tuple(map(kp, sp0.fx)), fy=tuple(map(kp, sp0.fy)), tension=tuple(map(kp, sp0.tension)))
    F0, N0 = forces.loads(P, sp0.fx, sp0.fy, dr0.f)
    nA = motion.normal(contact, N0)
    margin = motion.stick_margin(P, F0, nA)
    gA = [jnp.where(s, p, sd * v) for s, p, sd, v in zip(st.stuck, margin, st.sdir, yA.v)]
    fire = tuple(kp(pe | (g < 0)) for pe, g in zip(st.pend, gA))
    holds = [p >= 0 for p in margin]  # -mu_b n <= F <= mu_f n
    vel = tuple(f & ~s for f, s in zip(fire, st.stuck))
    stuck = tuple(jnp.where(f, ve & ho, s) for f, ve, ho, s in zip(fire, vel, holds, st.stuck))
    sdir = tuple(jnp.where(fi, jnp.where(f >= 0, 1.0, -1.0).astype(dtype), s) for fi, f, s in zip(fire, F0, st.sdir))
    y0 = yA._replace(v=tuple(jnp.where(ve, zero, v) for ve, v in zip(vel, yA.v)))
    comp = st.comp
    if comp is not None:  # a switch sets velocities exactly (to 0): drop their compensation
        comp = comp._replace(v=tuple(jnp.where(ve, zero, v) for ve, v in zip(vel, comp.v)))
    n_switch = st.n_switch + num.union(fire).astype(jnp.int32)

    lifted0 = num.union([q < 0 for q in N0])
    stop0 = lifted0 if contact == "strict" else jnp.asarray(False)
    t_lift = jnp.where(lifted0 & ~jnp.isfinite(st.t_liftoff), t0, st.t_liftoff)
    if target is not None:
        X_A = forces.centre_of_mass(P, yA.x)
        target_now = target.active & (jnp.abs(X_A - target.X0) >= target.z)
        target = target._replace(active=target.active & ~target_now)
    else:
        target_now = jnp.asarray(False)

    # -- derivatives at the start, in the (new) mode.
    mode = Mode(stuck, sdir, st.side)
    D0 = motion.derivatives(P, contact, mode, target, dr0, sp0, F0, N0, y0.x, y0.v)

    # -- step length: dt, or less to land on t_stop or just past the earliest predicted event.
    span = t_stop - t0
    h_nom = jnp.minimum(jnp.asarray(dt, dtype), span)
    s_pred = jnp.asarray(jnp.inf, dtype)
    for g, d, e in zip(D0.g, D0.dg, D0.ddg):
        s_pred = jnp.minimum(s_pred, num.predict(g, d, e))
    h_pred = jnp.maximum(num.PREDICT_MARGIN * s_pred, 64 * jnp.finfo(dtype).eps * jnp.maximum(jnp.abs(t0), 1))
    short = h_pred < h_nom
    lands = (span <= dt) & ~short
    t1 = jnp.where(lands, t_stop, t0 + jnp.where(short, h_pred, h_nom))
    h = kp(t1 - t0)
    sa, ca = (kp(q) for q in num.sincos(P.omega * (0.5 * h)))
    cm, sm = num.rotate(st.cph, st.sph, ca, sa)
    ce, se = (kp(q) for q in num.rotate(cm, sm, ca, sa))
    drm, dre = motion.kept(P, drive(P, cm, sm)), motion.kept(P, drive(P, ce, se))

    # -- RK4: one step of length h.
    def stage(dr, y):
        return motion.rates(P, contact, mode, dr, y.x, y.v)

    k1 = D0.rate
    k2 = stage(drm, y0.map(lambda a, b: a + (0.5 * h) * b, k1))
    k3 = stage(drm, y0.map(lambda a, b: a + (0.5 * h) * b, k2))
    k4 = stage(dre, y0.map(lambda a, b: a + h * b, k3))
    # The increment and (below) the Hermite basis are not kept: recomputing them where used
    # costs fewer kernels than it adds flops (benchmarks/NOTES.md).
    incr = k1.map(lambda a, b, c, d: (h / 6) * (a + 2 * (b + c) + d), k2, k3, k4)
    y1 = y0.map(lambda a, b: kp(a + b), incr)
    sp1 = forces.springs(P, dre.l0, y1.x)
    F1, N1 = forces.loads(P, sp1.fx, sp1.fy, dre.f)
    D1 = motion.derivatives(P, contact, mode, target, dre, sp1, F1, N1, y1.x, y1.v)

    # -- first crossing: the earliest by the secant of each crossed function, located on its quintic.
    g0s, d0s, e0s, d1s, e1s = D0.g, D0.dg, D0.ddg, D1.dg, D1.ddg
    g1s = [kp(g) for g in D1.g]
    h2 = h * h
    crossed = [g < 0 for g in g1s]
    cut = num.union(crossed)
    inf = jnp.asarray(jnp.inf, dtype)
    thl = []
    for c, g0, d0, g1 in zip(crossed, g0s, d0s, g1s):
        a0 = jnp.where(g0 == 0, h * d0, g0)  # deflated when starting on the surface
        den = a0 - g1
        thl.append(jnp.where(c, a0 / jnp.where(den > 0, den, 1), inf))
    th_min = thl[0]
    for q in thl[1:]:
        th_min = jnp.minimum(th_min, q)
    first = [kp(c & (q <= th_min)) for c, q in zip(crossed, thl)]
    pick = [g0s[-1], d0s[-1], e0s[-1], g1s[-1], d1s[-1], e1s[-1]]  # the lowest index among the first
    for i in reversed(range(len(g1s) - 1)):
        vals = (g0s[i], d0s[i], e0s[i], g1s[i], d1s[i], e1s[i])
        pick = [jnp.where(first[i], v, p) for v, p in zip(vals, pick)]
    cg0, cd0, ce0, cg1, cd1, ce1 = pick
    coef = num.quintic(jnp.maximum(cg0, 0), h * cd0, h2 * ce0, jnp.minimum(cg1, 0), h * cd1, h2 * ce1)
    theta = kp(jnp.where(cut, num.root(coef, jnp.minimum(cg1, 0)), 1))

    # -- margins to a change of switching structure (`_numerics.margins`); they feed nothing back.
    # A slipping mass that stopped (vel) sticks where its stick margin is >= 0 (`margin`, from
    # n_i = |N_i|); the margin's rate along the motion in the new mode from the loads' rates
    # that the start's derivatives computed anyway.
    dnA = motion.normal_rate(contact, N0, D0.dN)
    hold_rate = motion.stick_margin_rate(P, F0, nA, D0.dF, dnA)
    target_cut = first[-1] if target is not None else jnp.asarray(False)
    decide = list(zip(vel, margin, hold_rate))
    # The located crossing's rate and curvature from the event quintic at its root:
    # p'(theta) = h g' and p''(theta) = h^2 g'' (their ratio is what counts).
    c = [jax.lax.stop_gradient(q) for q in coef]
    th = jax.lax.stop_gradient(theta)
    p1 = c[1] + th * (2 * c[2] + th * (3 * c[3] + th * (4 * c[4] + th * 5 * c[5])))
    p2 = 2 * c[2] + th * (6 * c[3] + th * (12 * c[4] + th * 20 * c[5]))
    located = [(cut & ~target_cut, h * p1, p2)]
    m_cross, m_near = num.margins(P.omega, h, located, decide, crossed, g0s, d0s, e0s)

    # -- commit: the full step, or the quintic dense output at the crossing.
    H1, H2, H3, H4, H5 = num.hermite_basis(theta)
    hH1, hH4, h2H2, h2H5 = h * H1, h * H4, h2 * H2, h2 * H5
    part = incr.map(
        lambda i, a, b, c, d: H3 * i + hH1 * a + hH4 * b + h2H2 * c + h2H5 * d, k1, D1.rate, D0.second, D1.second
    )
    delta = incr.map(lambda i, p: jnp.where(cut, p, i), part)
    tc = jnp.where(cut, t0 + theta * h, t1)
    sc, cc = num.sincos(P.omega * (tc - t0))
    cph, sph = num.rotate(st.cph, st.sph, cc, sc)
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
    side = st.side
    if contact == "strict":
        lift_cut = first[n_mass]
        lift = stop0 | lift_cut
    else:
        flip = first[n_mass : 2 * n_mass]
        lift_cut = num.union(flip)
        lift = stop0
        side = tuple(jnp.where(f, -s, s) for f, s in zip(flip, side))
    t_lift = jnp.where(lift_cut & ~jnp.isfinite(t_lift), tc, t_lift)
    commit = ~stop0
    status = jnp.where(lift, Status.LIFTOFF, st.status).astype(jnp.int32)

    keepc = lambda new, old: jnp.where(commit, new, old)
    new = Hybrid(
        t=keepc(tc, t0), y=yc.map(keepc, yA), comp=None if comp_new is None else comp_new.map(keepc, st.comp),
        cph=keepc(cph, st.cph), sph=keepc(sph, st.sph), stuck=tuple(map(keepc, stuck, st.stuck)),
        sdir=tuple(map(keepc, sdir, st.sdir)), pend=tuple(commit & f for f in first[:n_mass]),
        side=tuple(map(keepc, side, st.side)), status=status, t_liftoff=t_lift.astype(dtype), n_switch=n_switch,
        cross=jnp.where(commit, jnp.minimum(st.cross, m_cross), st.cross),
        near=jnp.where(commit, jnp.minimum(st.near, m_near), st.near),
        t_switch=jnp.where(commit & cut & ~target_cut, jax.lax.stop_gradient(tc), st.t_switch),
    )  # fmt: skip
    info = StepInfo(
        commit=commit, t0=t0, y0=y0, tension0=sp0.tension, t1=tc, y1=yc, stuck=stuck,
        target_fired=target_now | (commit & target_cut), t_target=jnp.where(target_now, t0, tc),
        y_target=yc.map(lambda a, b: jnp.where(target_now, b, a), yA),
    )  # fmt: skip
    return new, info
