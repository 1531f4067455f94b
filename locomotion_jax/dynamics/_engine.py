"""Exact hybrid stick/slip dynamics of any mechanism of N bodies on a line (SPEC §2 and §8),
written once against the physics interface ([`AbstractPhysics`][locomotion_jax.AbstractPhysics]):
chains of N masses, and the paper's model as the two-mass chain.

**Scheme.** One configuration advances one iteration at a time (`step`; callers run it in a
`lax.while_loop` and batch with `vmap`). Inside a mode the motion is a smooth ODE, integrated
with classical RK4 at the nominal step `dt`; every iteration commits one step and none is
retried. The state's rate and its second time derivative are known at both ends of the step
(the loads and their time derivatives are analytic), so the quintic Hermite interpolant over the
step (the dense output) is accurate to $O(h^5)$, like the step. When an event function changes
sign over the step, its crossing is found on its own quintic Hermite interpolant (safeguarded
Newton), the step is cut there and the interpolated state committed; the switch itself is made
at the start of the next iteration, where every mass is re-decided (SPEC §2), so an event costs
one extra iteration and results converge at fourth order in `dt`
(tests/test_against_reference.py: the paper's model and chains). Of several crossings in one
step, the earliest by each function's secant is located.

The mechanism supplies its loads and their first two time derivatives along the motion
(its physics); the engine owns the rest. The loads on each body depend only on positions,
time and the actuation, so each body's stick condition is decided on its own, and any
number of bodies may switch at one instant. A friction law's rate is its own
[`kinetic_rate`][locomotion_jax.AbstractFriction.kinetic_rate] (by default a forward-mode
derivative of `kinetic`), so a new law or actuator supplies values only.

**Derivatives.** Forward and reverse mode go through the steps. A located crossing enters with its
implicit-function time (`_numerics.root`); a switch made at another event's time (one that ties
the located crossing, or fires at a step's start without one) gets its own time's tangent and
the saltation it implies (`_retimed`; not under `contact="hop"`, whose landings and lift-offs
keep the located time), so several bodies may switch at one instant in the derivatives as well.

**Events** (each fires when its function goes from $\\ge 0$ to $< 0$), in this order:

- mass $i$ slipping in direction $\\sigma_i$: $\\sigma_i v_i$;
- mass $i$ stuck: $\\min(\\mu_{s,\\mathrm{fwd}} n_i - F_i,\\; F_i + \\mu_{s,\\mathrm{bwd}} n_i)$ (eq. 7 generalised);
- strict contact: $\\min_i N_i$ (lift-off), which stops the run;
- paper contact: $\\nu_i N_i$ for each mass, with $\\nu_i = \\pm 1$ the side of $N_i$: $n_i = |N_i|$
  has a kink where $N_i$ changes sign, so the step is cut there and $\\nu_i$ flips (the first
  crossing, from above, sets `t_liftoff`). Inside a step $n_i = \\nu_i N_i$, smooth, so that the
  step's dense output and the derivatives along the motion stay accurate;
- optionally a caller's target $z - |X - X_0|$.

Not an event but a check: a committed step whose end has a gap of the physics'
[`gaps`][locomotion_jax.AbstractPhysics.gaps] $\\le 0$ (a chain's neighbours $x_{j+1} - x_j$:
bodies met or passed through each other, outside the model) stops the run with `Status.COLLISION`.

**Margins** (`_numerics.margins`). A result is smooth in the
parameters only while its switching structure (which events happen, in which order, with which
outcome) stays the same; the engine records how close the run came to changing it, as drive
phases $\\omega\\,\\delta t$ (radians, scale-free, so events of every kind compare). At a located
crossing of an event function $g$: the phase $\\omega|\\dot g/\\ddot g|$ to the vertex of $g$'s
local parabola, from the rate and curvature of its event quintic at the root (0 at a grazing
crossing). Where $g$ turns without reaching zero (a near miss): $\\omega\\sqrt{2 g_{\\min}/\\ddot g}$
from its Taylor parabola at the step's start (0 when it touches zero). Where a slipping mass
stops: $\\omega|s/\\dot s|$, with $s$ its stick margin (which decides between sticking and
reversing) and $\\dot s$ that margin's rate, from the loads and their rates that the step's start
computes anyway. A margin below `SMOOTH_MARGIN` (in `_results`) flags a result whose derivative
may not be one.

**Speed** (benchmarks/NOTES.md). XLA on the CPU duplicates cheap shared subexpressions into
every kernel that uses them, and its float64 `sin` costs more than a force evaluation, so the
state is a flat set of scalars (tuples over masses, so that under `vmap` every kernel is a
vector over the configurations), shared intermediates are pinned with `AbstractPhysics.keep`,
the phase $(\\cos\\omega t, \\sin\\omega t)$ is carried and rotated with a short polynomial
(`_numerics.sincos`) of the step angle, and the earliest event is picked by `where` over the
event list (no gather).
"""

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from .._custom_types import Array, Contact
from .._status import Status
from ..model._friction import static_at_rest
from ..model._physics import AbstractPhysics, contact_loads, Loads, loads_at, Scalars
from . import _motion as motion, _numerics as num
from ._motion import energy as energy, Mode, State


class Hybrid(eqx.Module):
    """Integrator state of one configuration: a flat pytree of scalars.

    `stuck`, `sdir`, `pend`, `side` have one entry per mass: the mode, slip direction, a
    flag for an event located at `t` (the mass is re-decided at the next iteration), and the
    side ($\\pm 1$) of its normal force (paper contact: flipped where a crossing is located,
    so that $n_i = \\nu_i N_i$ over a step). `cross`, `near`, `t_switch`: the margins to a
    change of switching structure so far and the time of the last switch.
    Under `contact="hop"` only (else `None`): `fly` per body (in flight), `vpend` (a landing or
    lift-off located at `t`), `n_land`, the number of landings so far, and `zeno`, whether the
    Zeno rule has made a rebound plastic (`restitution > 0` but $e_i |w^-| <$ `zeno_speed`).
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
    fly: Scalars | None = None
    vpend: Scalars | None = None
    n_land: Array | None = None
    zeno: Array | None = None


class StepInfo(NamedTuple):
    """What one iteration did; `stuck` is the mode during `[t0, t1]`.

    For the steady gaits' switching test functions (`gaits._shooting`): `vel`, per mass, a slipping
    mass whose velocity reached zero at `t0` (re-decided there); `hold`, per mass, its stick margin at
    `t0` (eq. 7 generalised, $\\ge 0$ where the static limits hold); `h`, the step's full length;
    `normal`, per body, the signed normal load $N_i$ with its first two time derivatives at `t0` and
    at the full step's end, `(N0, dN0, ddN0, N1, dN1, ddN1)`. Unused by a measurement (XLA drops them).
    """

    commit: Array
    t0: Array
    y0: State
    loads0: Loads
    t1: Array
    y1: State
    stuck: Scalars
    target_fired: Array
    t_target: Array
    y_target: State
    vel: Scalars
    hold: list
    h: Array
    normal: tuple


def init(
    P: AbstractPhysics,
    contact: Contact,
    x: Array,
    v: Array | None = None,
    height: Array | None = None,
    vy: Array | None = None,
) -> Hybrid:
    """State at $t = 0$ of the mechanism with physics `P` at positions `x` and velocities `v`
    (shape `(N,)` each; `v=None`: at rest). A body at rest sticks where its stick condition
    holds (eq. 7 generalised), else slips along its load; a moving one slips along its velocity.
    Under `contact="hop"`: the heights `height` and vertical velocities `vy` (default 0); a body
    above the ground, moving up, or with $N_i < 0$ starts in flight."""
    dtype = x.dtype
    zero = jnp.zeros((), dtype)
    xs = P.bodies(x)
    cph, sph = jnp.ones((), dtype), zero
    dr = P.drive(cph, sph)
    heights = None
    if contact == "hop" and height is not None:
        heights = P.bodies(height)
    L = loads_at(P, dr, xs, y=heights)
    vs = tuple(jnp.zeros_like(a) for a in xs)
    if v is not None:
        vs = P.bodies(v)
    F, N = motion.with_velocity(P, L.F, vs), L.N
    n = motion.normal(contact, N)
    fly = None
    if contact == "hop":
        zeros = jnp.zeros(x.shape[-1], dtype)
        height = zeros if height is None else height
        vy = zeros if vy is None else vy
        fly = tuple((h > 0) | (w > 0) | (q < 0) for h, w, q in zip(P.bodies(height), P.bodies(vy), P.ride(N)))
        n = tuple(jnp.where(f, 0, q) for f, q in zip(fly, n))
    stuck = tuple(p >= 0 for p in motion.stick_margin(P, F, n))
    sdir = tuple(jnp.where(f >= 0, 1.0, -1.0).astype(dtype) for f in F)
    if v is not None:
        stuck = tuple(s & (q == 0) for s, q in zip(stuck, vs))
        one = jnp.ones((), dtype)
        sdir = tuple(jnp.where(q > 0, one, jnp.where(q < 0, -one, s)) for s, q in zip(sdir, vs))
        vs = tuple(jnp.where(s, 0, q) for s, q in zip(stuck, vs))
    lifted = jnp.any(jnp.stack([q <= 0 for q in N] if fly is None else list(fly)))
    status = jnp.where(lifted & (contact == "strict"), Status.LIFTOFF, Status.OK).astype(jnp.int32)
    f32 = jnp.finfo(dtype).bits < 64
    y = State(xs, vs, zero, zero)
    extra: dict = {}
    if fly is not None and height is not None and vy is not None:
        y = y._replace(y=P.bodies(height), vy=P.bodies(vy))
        stuck = tuple(s & ~f for s, f in zip(stuck, fly))
        extra = dict(fly=fly, vpend=tuple(jnp.zeros_like(f) for f in fly), n_land=jnp.zeros((), jnp.int32),
                     zeno=jnp.asarray(False))  # fmt: skip
    return Hybrid(
        t=zero, y=y, comp=y.map(jnp.zeros_like) if f32 else None, cph=cph, sph=sph, stuck=stuck, sdir=sdir,
        pend=tuple(jnp.zeros_like(s) for s in stuck), side=tuple(jnp.where(q > 0, 1.0, -1.0).astype(dtype) for q in N),
        status=status, t_liftoff=jnp.where(lifted, zero, jnp.inf).astype(dtype), n_switch=jnp.zeros((), jnp.int32),
        cross=jnp.asarray(jnp.inf, dtype), near=jnp.asarray(jnp.inf, dtype), t_switch=jnp.asarray(-jnp.inf, dtype),
        **extra,
    )  # fmt: skip


def _impact(P: AbstractPhysics, restitution: Scalars, zeno: Array, st: Hybrid, N0: Scalars, keep):
    """The hopping reading's switches of vertical mode at the start of an iteration (SPEC §10):
    a body in flight whose landing was located (or that is below the ground) lands: $w^+ = -e_i w^-$
    (plastic, $w^+ = 0$, where $e_i |w^-| <$ `zeno`), normal impulse $P_n = M_i (w^+ - w^-)$ ($M_i$ the
    mass that lands with it, `P.landing_masses()`: $m_i$ and the masses it carries) and
    tangential $P_t = \\min(m_i |v^-|, \\mu_k P_n)$ against $v^-$; it stays on the ground after a
    plastic landing if its lift-off load (`P.ride`: $N_i$, a carried body's carrier's) is
    $\\ge 0$. A body on the ground whose lift-off load fell through 0 lifts off with $w = 0$.
    Returns the new state, flight flags, the bodies that landed at rest horizontally (to be
    re-decided stuck or slipping), the landings' count (of the bodies in contact), and whether the
    Zeno rule made one plastic."""
    yA = st.y
    assert st.fly is not None and st.vpend is not None and yA.y is not None and yA.vy is not None
    zero = jnp.zeros_like(st.t)
    hs, ws, vs, fly, rest, lost, count, zeno_rule = [], [], [], [], [], [], [], []
    lifts = P.ride(N0)
    for i, (f, pe, h, w, v, q, M) in enumerate(zip(st.fly, st.vpend, yA.y, yA.vy, yA.v, lifts, P.landing_masses())):
        land = f & (pe | (h < 0))
        lift = ~f & (pe | (q < 0))
        m, e = P.m[i], restitution[i]
        slow = e * jnp.abs(w) < zeno
        wp = jnp.where(slow, zero, -e * w)
        zeno_rule.append(land & slow & (e > 0))
        Pn = M * (wp - w)
        sgn = jnp.where(v >= 0, 1.0, -1.0).astype(v.dtype)
        mu = P.friction[i].kinetic(jnp.abs(v), sgn)
        Pt = jnp.minimum(m * jnp.abs(v), mu * Pn)
        vp = jnp.where(Pt >= m * jnp.abs(v), zero, v - sgn * Pt / m)
        airborne = (wp > 0) | (q < 0)
        lost.append(jnp.where(land, 0.5 * m * (w * w - wp * wp + v * v - vp * vp), zero))
        hs.append(jnp.where(land | lift, zero, h))
        ws.append(jnp.where(land, wp, jnp.where(lift, zero, w)))
        vs.append(jnp.where(land, vp, v))
        fly.append(keep(jnp.where(land, airborne, f | lift)))
        rest.append(land & ~airborne & (vp == 0))
        count.append(land.astype(jnp.int32))
    y = yA._replace(y=tuple(hs), vy=tuple(ws), v=tuple(vs), ed=yA.ed + motion._sum(lost))
    landed = contact_loads(P, tuple(count), 0)  # a carried body lands with its carrier: one landing, the carrier's
    n_land = motion._sum(list(landed)) if landed else jnp.zeros((), jnp.int32)
    return y, tuple(fly), tuple(rest), n_land, num.union(zeno_rule)


@jax.custom_jvp
def _shifted(v: Array, tau: Array, jump: Array) -> Array:
    """`v` itself; its tangent gains `jump` times the tangent of `tau` (a switch time's offset)."""
    return v


@_shifted.defjvp
def _shifted_jvp(primals, tangents):
    v, _, jump = primals
    dv, dtau, _ = tangents
    return v, dv + jump * dtau


def _retimed(P: AbstractPhysics, contact: Contact, old: Mode, new: Mode, fire: Scalars, dr, L: Loads, yA: State,
             y0: State) -> State:  # fmt: skip
    """The state after the switches `fire`, with the tangent of each switch at its own time.

    A step commits at the time located for one event; another that ties it, or whose function is
    already negative at the next start, switches at that time too, whose tangent is not its own.
    Body $j$'s own switch time is $t + \\tau_j$, $\\tau_j = -g_j/\\dot g_j$ (its event function and
    rate in the old mode: zero up to rounding in value, the true offset in its tangent), and until
    then it moves in the old mode: its velocity's tangent gains $(a_j^{old} - a_j^{new})\\,\\delta\\tau_j$
    (the saltation of the switch). Positions, $e_d$ and $w$ have no jump in rate ($v_j = 0$ at a
    switch), and a body that sticks keeps $v_j = 0$ whatever the time. For the located event
    $\\delta\\tau_j$ is about 0 (its time is already the root's). Only tangents change
    ([`_shifted`][]): the primal program does not use `tau`, and XLA removes it."""
    Do = motion.derivatives(P, contact, old, None, dr, L, yA.x, yA.v)
    a_new = motion.rates(P, contact, new, dr, y0).v
    v = []
    for f, s, g, d, a0, a1, q in zip(fire, new.stuck, Do.g, Do.dg, Do.rate.v, a_new, y0.v):
        tau = jnp.where(f & (d != 0), -g / jnp.where(d != 0, d, 1), 0)
        v.append(_shifted(q, tau, jnp.where(s, 0, a0 - a1)))
    return y0._replace(v=tuple(v))


def probe(P: AbstractPhysics, contact: Contact, t: Array, y: State, target: num.Target) -> tuple[list, list, list]:
    """The event functions with their first and second time derivatives at time `t` and
    state `y`, in the mode the state implies (a mass at rest sticks where its static limits
    hold): lists in the order of the module docstring (target last).
    Under `contact="hop"` a body above the ground ($y_i > 0$, or $y_i = 0$ rising) is in flight
    there, with its landing ($y_i$) as its event, and a grounded one has its lift-off ($N_i$).
    For margins at a measured instant; not for the hot loop."""
    dtype = t.dtype
    dr = P.drive(jnp.cos(P.omega * t), jnp.sin(P.omega * t))
    L = loads_at(P, dr, y.x, y=y.y)
    F, N = motion.with_velocity(P, L.F, y.v), L.N
    n = motion.normal(contact, N)
    stuck = tuple((p >= 0) & (v == 0) for p, v in zip(motion.stick_margin(P, F, n), y.v))
    one = jnp.ones((), dtype)
    sdir = tuple(jnp.where(v > 0, one, jnp.where(v < 0, -one, jnp.where(f >= 0, one, -one))) for v, f in zip(y.v, F))
    side = tuple(jnp.where(q > 0, one, -one) for q in N)
    fly = None
    if contact == "hop" and y.y is not None and y.vy is not None:  # inside a step y_i stays 0 on the ground
        fly = tuple((h > 0) | ((h == 0) & (w > 0)) for h, w in zip(y.y, y.vy))
        stuck = tuple(s & ~f for s, f in zip(stuck, fly))
    v = tuple(jnp.where(s, 0, vi) for s, vi in zip(stuck, y.v))
    D = motion.derivatives(P, contact, Mode(stuck, sdir, side, fly), target, dr, L, y.x, v, y.y, y.vy)
    return D.g, D.dg, D.ddg


def step(
    P: AbstractPhysics,
    contact: Contact,
    dt: float | Array,
    st: Hybrid,
    t_stop: Array,
    target: num.Target | None = None,
    hop: tuple[Scalars, Array] | None = None,
) -> tuple[Hybrid, StepInfo]:
    """One iteration: re-decide the bodies, one RK4 step, cut at the first event (module docstring).

    `P` is the mechanism's physics (its `physics()`, computed once per run); `hop`, under
    `contact="hop"` only: the restitution per body and the Zeno speed."""
    kp = P.keep
    dtype = st.t.dtype
    t0, yA = st.t, st.y
    n_mass = len(P.m)
    zero = jnp.zeros_like(t0)

    # -- switch: every mass whose event was located here (pend) or whose event function is
    # negative switches: a stuck one slips in the direction of F_i; a slipping one (v_i = 0)
    # sticks if the static limits hold, else it slips the other way.
    dr0 = motion.kept(P, P.drive(st.cph, st.sph))
    L0 = loads_at(P, dr0, yA.x, kp, y=yA.y)
    N0 = L0.N
    nA = motion.normal(contact, N0)
    fly, n_land, zeno_now, st_stuck, st_sdir = st.fly, st.n_land, st.zeno, st.stuck, st.sdir
    if contact == "hop":  # landings and lift-offs first (SPEC §10); a flying body never sticks
        assert hop is not None, "contact='hop' needs the mechanism's restitution and zeno_speed"
        assert st.fly is not None and st.n_land is not None, "contact='hop' needs a state from init(contact='hop')"
        yA, fly, rest, landed, zeno_hit = _impact(P, hop[0], hop[1], st, N0, kp)
        zeno_now = zeno_hit if st.zeno is None else st.zeno | zeno_hit
        L0 = loads_at(P, dr0, yA.x, kp, y=yA.y)  # the impacts set heights to 0 exactly
        N0 = L0.N
        n_land = st.n_land + landed
        nA = tuple(jnp.where(f, 0, q) for f, q in zip(fly, N0))
        one = jnp.ones((), dtype)
        # In flight (or landing) the slip direction is that of v (no event follows its sign there).
        st_sdir = tuple(jnp.where(f, jnp.where(v > 0, one, jnp.where(v < 0, -one, s)), s)
                        for f, v, s in zip(st.fly, yA.v, st.sdir))  # fmt: skip
        st_stuck = tuple(s & ~f for s, f in zip(st.stuck, fly))
    else:
        rest = None
    F0 = motion.with_velocity(P, L0.F, yA.v)  # after the impacts' velocity jumps
    margin = motion.stick_margin(P, F0, nA)
    gA = [jnp.where(s, p, sd * v) for s, p, sd, v in zip(st_stuck, margin, st_sdir, yA.v)]
    if fly is not None:  # no slip event in flight
        gA = [jnp.where(f, 0, g) for f, g in zip(fly, gA)]
    fire = tuple(kp(pe | (g < 0)) for pe, g in zip(st.pend, gA))
    if rest is not None:  # a landing at rest horizontally: re-decided stuck or slipping
        fire = tuple(kp(f | r) for f, r in zip(fire, rest))
    holds = [p >= 0 for p in margin]  # -mu_b n <= F <= mu_f n
    if fly is not None:
        holds = [ho & ~f for ho, f in zip(holds, fly)]
    vel = tuple(f & ~s for f, s in zip(fire, st_stuck))
    stuck = tuple(jnp.where(f, ve & ho, s) for f, ve, ho, s in zip(fire, vel, holds, st_stuck))
    sdir = tuple(jnp.where(fi, jnp.where(f >= 0, 1.0, -1.0).astype(dtype), s) for fi, f, s in zip(fire, F0, st_sdir))
    y0 = yA._replace(v=tuple(jnp.where(ve, zero, v) for ve, v in zip(vel, yA.v)))
    if contact != "hop":
        y0 = _retimed(P, contact, Mode(st_stuck, st_sdir, st.side), Mode(stuck, sdir, st.side), fire, dr0, L0, yA, y0)
    comp = st.comp
    if comp is not None:  # a switch sets velocities exactly (to 0): drop their compensation
        comp = comp._replace(v=tuple(jnp.where(ve, zero, v) for ve, v in zip(vel, comp.v)))
        if fly is not None and st.fly is not None and comp.y is not None and comp.vy is not None:
            jump = [f != g for f, g in zip(fly, st.fly)]  # an impact or a lift-off sets y, w, v exactly
            comp = comp._replace(
                y=tuple(jnp.where(j, zero, q) for j, q in zip(jump, comp.y)),
                vy=tuple(jnp.where(j, zero, q) for j, q in zip(jump, comp.vy)),
                v=tuple(jnp.where(j, zero, q) for j, q in zip(jump, comp.v)),
            )
    n_switch = st.n_switch + num.union(fire).astype(jnp.int32)

    lifted0 = num.union([q < 0 for q in N0])
    if fly is not None:
        lifted0 = num.union(list(fly))
    stop0 = lifted0 if contact == "strict" else jnp.asarray(False)
    t_lift = jnp.where(lifted0 & ~jnp.isfinite(st.t_liftoff), t0, st.t_liftoff)
    if target is not None:
        X_A = P.centre_of_mass(yA.x)
        target_now = target.active & (jnp.abs(X_A - target.X0) >= target.z)
        target = target._replace(active=target.active & ~target_now)
    else:
        target_now = jnp.asarray(False)

    # -- derivatives at the start, in the (new) mode.
    mode = Mode(stuck, sdir, st.side, fly)
    D0 = motion.derivatives(P, contact, mode, target, dr0, L0, y0.x, y0.v, y0.y, y0.vy)

    # -- step length: dt, or less to land on t_stop or just past the earliest predicted event.
    span = t_stop - t0
    h_nom = jnp.minimum(jnp.asarray(dt, dtype), span)
    s_pred = jnp.asarray(jnp.inf, dtype)
    for g, d, e in zip(D0.g, D0.dg, D0.ddg):
        s_pred = jnp.minimum(s_pred, num.within(num.predict(g, d, e), jnp.min))
    h_pred = jnp.maximum(num.PREDICT_MARGIN * s_pred, 64 * jnp.finfo(dtype).eps * jnp.maximum(jnp.abs(t0), 1))
    short = h_pred < h_nom
    lands = (span <= dt) & ~short
    t1 = jnp.where(lands, t_stop, t0 + jnp.where(short, h_pred, h_nom))
    h = kp(t1 - t0)
    sa, ca = (kp(q) for q in num.sincos(P.omega * (0.5 * h)))
    cm, sm = num.rotate(st.cph, st.sph, ca, sa)
    ce, se = (kp(q) for q in num.rotate(cm, sm, ca, sa))
    drm, dre = motion.kept(P, P.drive(cm, sm)), motion.kept(P, P.drive(ce, se))

    # -- RK4: one step of length h.
    def stage(dr, y):
        return motion.rates(P, contact, mode, dr, y)

    k1 = D0.rate
    k2 = stage(drm, y0.map(lambda a, b: a + (0.5 * h) * b, k1))
    k3 = stage(drm, y0.map(lambda a, b: a + (0.5 * h) * b, k2))
    k4 = stage(dre, y0.map(lambda a, b: a + h * b, k3))
    # The increment and (below) the Hermite basis are not kept: they feed the committed state
    # only (kept), and pinning them changes the rounding (a kept factor is not contracted into
    # the fused multiply-adds of its consumers) for no measurable gain (benchmarks/NOTES.md).
    incr = k1.map(lambda a, b, c, d: (h / 6) * (a + 2 * (b + c) + d), k2, k3, k4)
    y1 = y0.map(lambda a, b: kp(a + b), incr)
    L1 = loads_at(P, dre, y1.x, y=y1.y)
    D1_N = L1.N
    D1 = motion.derivatives(P, contact, mode, target, dre, L1, y1.x, y1.v, y1.y, y1.vy)

    # -- first crossing: the earliest by the secant of each crossed function, located on its quintic.
    g0s, d0s, e0s, d1s, e1s = D0.g, D0.dg, D0.ddg, D1.dg, D1.ddg
    g1s = [kp(g) for g in D1.g]
    h2 = h * h
    crossed = [g < 0 for g in g1s]
    if any(static_at_rest(law) for law in P.friction):
        # A mass that breaks away here with no acceleration along its slip (a law whose kinetic
        # coefficient at rest is the static one, Stribeck's, where the load only grazes the static
        # limit) starts its slip function on the surface at zero rate, so its stop would be located
        # at the step's start, and it would stick and break away again at the same time. Its stop is
        # not looked for in this step; if it slips backwards by the step's end it stops at the next
        # iteration. (Static: the programs of the other laws do not carry the check.)
        grazing = [f & s & ~q & (d <= 0) for f, s, q, d in zip(fire, st_stuck, stuck, d0s)]
        crossed[:n_mass] = [c & ~r for c, r in zip(crossed[:n_mass], grazing)]
    if fly is not None and y0.y is not None and y0.vy is not None:
        # A body in flight at height 0 with no vertical velocity (it lifted off here, or a landing
        # left it airborne) starts its landing function on the surface at zero rate, so a crossing
        # would be located at the step's start: a flight of no length, repeated at the same time
        # where its normal force grazes 0. Its landing is not looked for in this step; if it is
        # below the ground at the step's end it lands at the next iteration.
        at_rest = [f & (q == 0) & (w == 0) for f, q, w in zip(fly, y0.y, y0.vy)]
        crossed[n_mass : 2 * n_mass] = [c & ~r for c, r in zip(crossed[n_mass : 2 * n_mass], at_rest)]
    cut = num.union(crossed)
    inf = jnp.asarray(jnp.inf, dtype)
    thl = []
    for c, g0, d0, g1 in zip(crossed, g0s, d0s, g1s):
        a0 = jnp.where(g0 == 0, h * d0, g0)  # deflated when starting on the surface
        den = a0 - g1
        thl.append(jnp.where(c, a0 / jnp.where(den > 0, den, 1), inf))
    th_min = num.least(thl)
    first = [kp(c & (q <= th_min)) for c, q in zip(crossed, thl)]
    # The lowest index among the first (bodies in order within an array layout's entry).
    pick = num.lowest_first(first, list(zip(g0s, d0s, e0s, g1s, d1s, e1s)))
    # Pinned: the event quintic's coefficients feed the root and the located margin, and XLA
    # would recompute the picks (a `where` chain over every event) in each (benchmarks/NOTES.md).
    cg0, cd0, ce0, cg1, cd1, ce1 = (kp(q) for q in pick)
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
    # The committed state is pinned: it feeds the new state, the caller's records (a
    # measurement's target state, its sums) and the gaps, and XLA would otherwise recompute
    # the dense output (the Hermite basis and the RK4 increment) in each of those kernels:
    # 13 of them at N = 2 (benchmarks/NOTES.md, "Where the paper's model lost its 10 %").
    if comp is None:
        yc = y0.map(lambda a, b: kp(a + b), delta)
        comp_new = None
    else:  # compensated (Kahan) sums in float32
        corr = delta.map(lambda a, b: a - b, comp)
        yc = y0.map(lambda a, b: kp(a + b), corr)
        comp_new = yc.map(lambda tot, a, b: (tot - a) - b, y0, corr)

    # A normal force's crossing: the first one is a lift-off (from above: no earlier one),
    # which stops the run under the strict reading; under the paper's the crossing force
    # changes side.
    side = st.side
    vpend = None
    if contact == "strict":
        lift_cut = first[n_mass]
        lift = stop0 | lift_cut
    elif fly is not None:  # a landing or a lift-off: the body switches at the next iteration
        vpend = tuple(first[n_mass : 2 * n_mass])  # (stop0 is False here: only strict stops)
        lift_cut = num.union([f & ~g for f, g in zip(first[n_mass : 2 * n_mass], fly)])
        lift = stop0
    else:
        flip = first[n_mass : 2 * n_mass]
        lift_cut = num.union(flip)
        lift = stop0
        side = tuple(jnp.where(f, -s, s) for f, s in zip(flip, side))
    t_lift = jnp.where(lift_cut & ~jnp.isfinite(t_lift), tc, t_lift)
    commit = ~stop0
    # Bodies met (outside the model; the gaps the mechanism declares, a chain's neighbours'):
    # the run stops after this step (`Status.COLLISION`).
    met = commit & num.union([g <= 0 for g in P.gaps(yc.x)])
    # A force that turns over within |u| < |h| (a tilted spring's direction) passed in a step that
    # moved u by more than |h| / 2: no fixed step resolves it there (`Status.UNRESOLVED`).
    turned = [(u0 * u1 <= 0) & (2 * jnp.abs(u1 - u0) > jnp.minimum(jnp.abs(h0), jnp.abs(h1)))
              for (u0, h0), (u1, h1) in zip(P.kinks(y0.x, y0.y), P.kinks(yc.x, yc.y))]  # fmt: skip
    status = st.status
    if turned:
        status = jnp.where(commit & num.union(turned), Status.UNRESOLVED, status)
    status = jnp.where(lift, Status.LIFTOFF, jnp.where(met, Status.COLLISION, status)).astype(jnp.int32)

    keepc = lambda new, old: jnp.where(commit, new, old)
    new = Hybrid(
        t=keepc(tc, t0), y=yc.map(keepc, yA), comp=None if comp_new is None else comp_new.map(keepc, st.comp),
        cph=keepc(cph, st.cph), sph=keepc(sph, st.sph), stuck=tuple(map(keepc, stuck, st.stuck)),
        sdir=tuple(map(keepc, sdir, st.sdir)), pend=tuple(commit & f for f in first[:n_mass]),
        side=tuple(map(keepc, side, st.side)), status=status, t_liftoff=t_lift.astype(dtype), n_switch=n_switch,
        cross=jnp.where(commit, jnp.minimum(st.cross, m_cross), st.cross),
        near=jnp.where(commit, jnp.minimum(st.near, m_near), st.near),
        t_switch=jnp.where(commit & cut & ~target_cut, jax.lax.stop_gradient(tc), st.t_switch),
        fly=fly, vpend=vpend, n_land=n_land, zeno=zeno_now,
    )  # fmt: skip
    info = StepInfo(
        commit=commit, t0=t0, y0=y0, loads0=L0, t1=tc, y1=yc, stuck=stuck,
        target_fired=target_now | (commit & target_cut), t_target=jnp.where(target_now, t0, tc),
        y_target=yc.map(lambda a, b: jnp.where(target_now, b, a), yA), vel=vel, hold=margin, h=h,
        normal=(N0, D0.dN, D0.ddN, D1_N, D1.dN, D1.ddN),
    )  # fmt: skip
    return new, info
