"""Exact hybrid stick/slip dynamics (eqs. 7, 9; corrected per SPEC §2).

One configuration, one iteration at a time: callers run [`step`][] inside a
`lax.while_loop` and batch with `vmap`.

**Scheme.** Inside a mode the dynamics is a smooth ODE, integrated with classical
RK4 at a nominal step `dt`. Every iteration commits one step; nothing is retried.
At both ends of the step the engine has the state, its rate and its second time
derivative (forces and their time derivatives are analytic), so the quintic
Hermite interpolant of the state over the step is accurate to $O(h^5)$, like the
RK4 step itself. If an event function changed sign over the step, its crossing
is located on its own quintic Hermite interpolant (value, first and second
derivative at both ends; safeguarded Newton), the step is cut there and the
interpolated state is committed. The mode switch is applied at the start of the
next iteration, where the forces at that state are computed anyway. An event
thus costs one extra iteration, and the results converge at fourth order in `dt`
(tests/test_against_reference.py).

**Events** (each fires when its function goes from $\\ge 0$ to $< 0$):

- a slipping mass $i$ with slip direction $\\sigma_i$: $\\sigma_i v_i$ (velocity zero);
- a stuck mass $i$: $\\mu_s n_i - |F_i|$ (static friction exceeded, eq. 7);
- strict contact: $\\min(N_1, N_2)$ (lift-off, eq. 5), which stops the run;
- paper contact: $\\min(\\nu_1 N_1, \\nu_2 N_2)$ with $\\nu_i = \\pm 1$ the side of $N_i$, a
  sign change of a normal force: $n_i = |N_i|$ has a kink there, so the step is cut
  at it and $\\nu_i$ flips (the first one, from above, sets `t_liftoff`). Inside a
  step $n_i = \\nu_i N_i$, smooth, so that the step's dense output stays accurate.
- optionally a caller's target (`measure`: $|X - X_0| = z$).

Not an event but a check: a committed step whose end has $x_2 - x_1 \\le 0$ (the masses
met or passed through each other, outside the model) stops the run with `Status.COLLISION`.

When several events cross in one step, the earliest by the secant of each
function is located. At the start of every iteration both masses are re-checked
(SPEC §2): the located one switches, and so does any mass whose event function is
negative there (simultaneous events, e.g. by symmetry when $d = 0$, $m_1 = m_2$).
The forces depend only on positions and time, never on the other mass's mode, so
each mass's stick condition is decided on its own.

**Margins** ([`margins`][]). A result is a smooth function of the parameters only
while its switching structure (which events happen, in which order, with which
outcome) stays the same; the engine records how close the run came to a change of
it. Each margin is a drive phase $\\omega\\,\\delta t$ (radians): at a located crossing
of an event function $g$, the phase between the crossing and the vertex of $g$'s
local parabola, $\\omega|\\dot g/\\ddot g|$ (0 at a grazing crossing, which a small change
removes); at a turning point of $g$ that stays above zero, the same phase for the
parabola lowered by its minimum $g_{\\min}$, $\\omega\\sqrt{2 g_{\\min}/\\ddot g}$ (0 when it
touches zero); where a slipping mass stops, the phase $\\omega|s/\\dot s|$ to the instant
at which $s = \\mu_s n_i - |F_i|$, which decides between sticking and reversing,
changes sign. Scale-free, they compare events of every kind; a typical switch is at
0.1-1 rad, and a margin below `SMOOTH_MARGIN` (in `_results`) flags a result whose
derivative may not be a derivative.

**Speed** (benchmarks/NOTES.md). XLA on the CPU duplicates shared cheap
subexpressions into every kernel that uses them (one kernel per carried scalar),
and its float64 `sin` costs more than a force evaluation. So the state is a flat
set of scalars, shared intermediates are pinned with [`_keep`][], and the
actuation phase $(\\cos\\omega t, \\sin\\omega t)$ is carried and rotated with a
short polynomial [`sincos`][] of the step angle.

Limitation: a sign change that starts and ends inside one step (a grazing
excursion shorter than `dt`) is not seen; only grazing contacts are affected.
"""

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from .._custom_types import Array, Contact
from .._status import Status
from ..model import _two_mass as model
from ..model._params import Params
from ..model._waveform import AbstractWaveform
from ._numerics import (
    hermite_basis,
    margins,
    predict,
    PREDICT_MARGIN,
    quintic,
    root,
    rotate,
    sincos,
    Target,
    union,
)


class Consts(NamedTuple):
    """Per-configuration constants, computed once outside the time loop."""

    k: Array
    c: Array
    d: Array
    dd: Array
    m1: Array
    m2: Array
    im1: Array
    im2: Array
    mhat: Array
    mu_s: Array
    mu_k: Array
    one: Array  # 1.0, but a runtime value: see `_keep`


def consts(params: Params, wave: AbstractWaveform) -> Consts:
    """Per-configuration constants; the phase rotates at the *waveform's* base frequency."""
    return Consts(
        k=params.k,
        c=params.c,
        d=params.d,
        dd=params.d * params.d,
        m1=params.m1,
        m2=params.m2,
        im1=1 / params.m1,
        im2=1 / params.m2,
        mhat=params.mhat,
        mu_s=params.mu_s,
        mu_k=params.mu_k,
        one=params.k / params.k,
    )


def _keep(P: Consts, x: Array) -> Array:
    """Materialise `x` once per iteration.

    XLA on the CPU fuses cheap elementwise producers into *every* consumer
    kernel, so a value feeding many carried outputs (the commit decision, the
    RK4 end state) is recomputed in each of them (measured: 7,400 flops per
    iteration instead of ~1,400). XLA treats a division as expensive and never
    duplicates it: dividing by a runtime 1.0 pins the value to one buffer.
    """
    if x.dtype == jnp.bool_:
        return (x.astype(P.one.dtype) / P.one) > 0.5
    return x / P.one


class State(NamedTuple):
    """The integrated quantities: positions, velocities, $e_d$ (eq. 15) and $w$ (eq. 16)."""

    x1: Array
    v1: Array
    x2: Array
    v2: Array
    ed: Array
    w: Array

    def map(self, fn, *others) -> "State":
        return State(*(fn(*xs) for xs in zip(self, *others)))


class Hybrid(eqx.Module):
    """Integrator state of one configuration: a flat pytree of scalars.

    `y` is the [`State`][] and `comp` its Kahan compensation (float32 only, else
    `None`); `cph, sph` are $\\cos\\omega t, \\sin\\omega t$ (carried, see the module
    docstring); `stuck*`/`s*` the mode and slip direction of each mass; `pend*`
    flags a mass whose event was located at `t` (it switches at the start of the
    next iteration); `nu*` the side ($\\pm 1$) of each normal force (paper contact:
    flipped where a crossing is located, so that $n_i = \\nu_i N_i$ over a step).
    `cross`, `near`: the squares of the smallest margins to a change of switching
    structure met so far ([`margins`][]), at located switches and at near misses;
    `t_switch` the time of the last located crossing other than the target's.
    """

    t: Array
    y: State
    comp: State | None
    cph: Array
    sph: Array
    stuck1: Array
    stuck2: Array
    s1: Array
    s2: Array
    pend1: Array
    pend2: Array
    nu1: Array
    nu2: Array
    status: Array
    t_liftoff: Array
    n_switch: Array
    cross: Array
    near: Array
    t_switch: Array


class StepInfo(NamedTuple):
    """What one iteration did, for measurements.

    - `commit`: False only when the run stopped at the start (lift-off found there).
    - `t0`, `y0`, `tension0`: the start, after its switches (tension for eq. 10).
    - `t1`, `y1`: the committed end (before the switches pending there).
    - `stuck1`, `stuck2`: the mode during `[t0, t1]`.
    - `target_fired`, `t_target`, `y_target`: the caller's target event, if it fired.
    - `zero1`, `zero2`: a slipping mass's velocity reached zero at `t0` (it stuck or
      reversed there); `slack1`, `slack2`: $\\mu_s n_i - |F_i|$ at `t0` (eq. 7: it sticks
      where this is $\\ge 0$).
    - `h`: the step's full length ($t_1 - t_0$ unless cut at an event) and `fy`: the
      vertical spring force $f_y$ with its first and second time derivatives at $t_0$
      and at $t_0 + h$, six values for its quintic Hermite interpolant over the step.
    """

    commit: Array
    t0: Array
    y0: State
    tension0: Array
    t1: Array
    y1: State
    stuck1: Array
    stuck2: Array
    target_fired: Array
    t_target: Array
    y_target: State
    zero1: Array
    zero2: Array
    slack1: Array
    slack2: Array
    h: Array
    fy: tuple[Array, Array, Array, Array, Array, Array]


# -- forces, rates, events -----------------------------------------------------------


class _F(NamedTuple):
    fx: Array
    fy: Array
    tension: Array
    N1: Array
    N2: Array
    n1: Array
    n2: Array


class _D(NamedTuple):
    """First and second time derivatives along the motion of what the events need."""

    fx: Array
    fy: Array
    tension: Array
    fx2: Array
    fy2: Array


def _forces(P: Consts, contact: Contact, l0, x1, x2, sides=None) -> tuple[_F, tuple]:
    """Spring and normal forces (eqs. 2, 5, 8), as in `_two_mass.spring_forces`; also
    returns the geometry `(u, il, pl)` reused by [`_derivs`][]. With `sides`
    $(\\nu_1, \\nu_2)$ (paper contact, inside a step) $n_i = \\nu_i N_i$: $|N_i|$ on the side
    the step started on, continued smoothly past a crossing (where the step is cut)."""
    u = x2 - x1
    length = jnp.sqrt(u * u + P.dd)
    il = 1 / length
    tension = P.k * (length - l0)
    pl = tension * il
    fx = pl * u
    fy = pl * P.d
    N1 = P.m1 - fy
    N2 = P.m2 + fy
    if contact != "paper":
        n1, n2 = N1, N2
    elif sides is None:
        n1, n2 = jnp.abs(N1), jnp.abs(N2)
    else:
        n1, n2 = sides[0] * N1, sides[1] * N2
    return _F(fx, fy, tension, N1, N2, n1, n2), (u, il, pl)


def _derivs(P: Consts, geo, y: "State", a1, a2, dl0, ddl0) -> _D:
    """Time derivatives of $f_x$, $f_y$, $T$ (first) and $f_x$, $f_y$ (second) along the
    motion, from eqs. (2, 8): $u = x_2 - x_1$, $\\ell = \\sqrt{u^2 + d^2}$, $T = k(\\ell - \\ell_0)$,
    $f_x = (T/\\ell) u$, $f_y = (T/\\ell) d$."""
    u, il, pl = geo
    u1 = y.v2 - y.v1
    u2 = a2 - a1
    l1 = u * u1 * il
    l2 = (u1 * u1 + u * u2 - l1 * l1) * il
    T1 = P.k * (l1 - dl0)
    T2 = P.k * (l2 - ddl0)
    pl1 = (T1 - pl * l1) * il
    pl2 = (T2 - 2 * pl1 * l1 - pl * l2) * il
    return _D(
        fx=pl1 * u + pl * u1,
        fy=pl1 * P.d,
        tension=T1,
        fx2=pl2 * u + 2 * pl1 * u1 + pl * u2,
        fy2=pl2 * P.d,
    )


def _accel(P: Consts, f: _F, y: State, st1, st2, s1, s2):
    """Accelerations in a fixed mode: eq. (9) corrected per SPEC §2,
    $m_i \\dot v_i = F_i - c v_i - \\mu_k n_i \\sigma_i$, $F_1 = f_x = -F_2$; zero when stuck."""
    zero = jnp.zeros_like(y.v1)
    a1 = jnp.where(st1, zero, (f.fx - P.c * y.v1 - P.mu_k * f.n1 * s1) * P.im1)
    a2 = jnp.where(st2, zero, (-f.fx - P.c * y.v2 - P.mu_k * f.n2 * s2) * P.im2)
    return a1, a2


def _rates(P: Consts, f: _F, y: State, a1, a2, s1, s2, dl0) -> State:
    """The rate of every state entry: $\\dot x_i = v_i$ (a stuck mass has $v_i = 0$
    exactly), $\\dot v_i = a_i$, and the integrands of $e_d$ (eq. 15; $|v_i| = \\sigma_i v_i$
    in a slip segment) and of $w$ (eq. 16, $-T\\dot\\ell_0$)."""
    pd = P.mu_k * (f.n1 * s1 * y.v1 + f.n2 * s2 * y.v2) + P.c * (y.v1 * y.v1 + y.v2 * y.v2)
    return State(y.v1, a1, y.v2, a2, pd, -f.tension * dl0)


def _normal_rates(contact, D: _D, sides):
    """$\\dot n_i$, $\\ddot n_i$ from $N_1 = m_1 - f_y$, $N_2 = m_2 + f_y$ (eq. 5);
    paper contact: $n_i = \\nu_i N_i$ over the step."""
    n1d, n2d, n1dd, n2dd = -D.fy, D.fy, -D.fy2, D.fy2
    if contact == "paper":
        nu1, nu2 = sides
        n1d, n1dd, n2d, n2dd = nu1 * n1d, nu1 * n1dd, nu2 * n2d, nu2 * n2dd
    return n1d, n2d, n1dd, n2dd


def _second(P: Consts, contact, f: _F, D: _D, y: State, a1, a2, st1, st2, s1, s2, dl0, ddl0, sides) -> State:
    """Second time derivative of every state entry in a fixed mode (for the quintic
    dense output): $\\ddot x_i = a_i$, $\\ddot v_i = \\dot a_i$, and the rates of the integrands."""
    n1d, n2d, _, _ = _normal_rates(contact, D, sides)
    zero = jnp.zeros_like(a1)
    j1 = jnp.where(st1, zero, (D.fx - P.c * a1 - P.mu_k * n1d * s1) * P.im1)
    j2 = jnp.where(st2, zero, (-D.fx - P.c * a2 - P.mu_k * n2d * s2) * P.im2)
    pd = P.mu_k * (n1d * s1 * y.v1 + f.n1 * s1 * a1 + n2d * s2 * y.v2 + f.n2 * s2 * a2) + 2 * P.c * (
        y.v1 * a1 + y.v2 * a2
    )
    pw = -(D.tension * dl0 + f.tension * ddl0)
    return State(a1, j1, a2, j2, pd, pw)


def _mass_events(P: Consts, f: _F, y: State, st1, st2, s1, s2) -> tuple[Array, Array]:
    """The two mass events' values (module docstring)."""
    absF = jnp.abs(f.fx)
    g1 = jnp.where(st1, P.mu_s * f.n1 - absF, s1 * y.v1)
    g2 = jnp.where(st2, P.mu_s * f.n2 - absF, s2 * y.v2)
    return g1, g2


def _events(P, contact, f: _F, D: _D, y: State, r: State, j: State, st1, st2, s1, s2, target, sides):
    """Values, first and second time derivatives of all events (lists); `sides` are the
    signs $\\nu_i$ of the normal forces at the step's start (paper contact)."""
    n1d, n2d, n1dd, n2dd = _normal_rates(contact, D, sides)
    sg = jnp.where(f.fx >= 0, 1.0, -1.0).astype(f.fx.dtype)  # |F_i| = |fx|: d|F|/dt = sgn(fx) dfx/dt
    g1, g2 = _mass_events(P, f, y, st1, st2, s1, s2)
    gs = [g1, g2]
    ds = [
        jnp.where(st1, P.mu_s * n1d - sg * D.fx, s1 * r.v1),
        jnp.where(st2, P.mu_s * n2d - sg * D.fx, s2 * r.v2),
    ]
    es = [
        jnp.where(st1, P.mu_s * n1dd - sg * D.fx2, s1 * j.v1),
        jnp.where(st2, P.mu_s * n2dd - sg * D.fx2, s2 * j.v2),
    ]
    if contact == "strict":
        low1 = f.N1 <= f.N2
        gs.append(jnp.minimum(f.N1, f.N2))
        ds.append(jnp.where(low1, -D.fy, D.fy))
        es.append(jnp.where(low1, -D.fy2, D.fy2))
    else:  # paper: a sign change of N_i, from the side `sides` it starts the step on
        nu1, nu2 = sides
        q1, q2 = nu1 * f.N1, nu2 * f.N2
        low1 = q1 <= q2
        gs.append(jnp.minimum(q1, q2))
        ds.append(jnp.where(low1, -nu1 * D.fy, nu2 * D.fy))
        es.append(jnp.where(low1, -nu1 * D.fy2, nu2 * D.fy2))
    if target is not None:
        active, X0, z = target
        rel = P.mhat * y.x1 + (1 - P.mhat) * y.x2 - X0
        sr = jnp.where(rel >= 0, 1.0, -1.0).astype(rel.dtype)
        zero = jnp.zeros_like(rel)
        gs.append(jnp.where(active, z - jnp.abs(rel), jnp.asarray(jnp.inf, rel.dtype)))
        ds.append(jnp.where(active, -sr * (P.mhat * r.x1 + (1 - P.mhat) * r.x2), zero))
        es.append(jnp.where(active, -sr * (P.mhat * j.x1 + (1 - P.mhat) * j.x2), zero))
    return gs, ds, es


# -- public pieces ------------------------------------------------------------------


def rates(params: Params, f: model.Forces, y: Array, stuck: Array, sdir: Array) -> Array:
    """Right-hand side in a fixed mode (eq. 9 corrected per SPEC §2) as a stacked
    `(6,)` vector: $\\dot x_i, \\dot v_i$ and the integrands of $e_d$ (eq. 15) and $w$ (eq. 16).

    Slipping: $m_i \\dot v_i = F_i - c v_i - \\mu_k n_i \\sigma_i$ with $F_1 = f_x$,
    $F_2 = -f_x$. Stuck: $\\dot x_i = \\dot v_i = 0$. For saved states (not the hot loop).
    """
    v1, v2 = y[1], y[3]
    a1 = (f.fx - params.c * v1 - params.mu_k * f.n1 * sdir[0]) / params.m1
    a2 = (-f.fx - params.c * v2 - params.mu_k * f.n2 * sdir[1]) / params.m2
    zero = jnp.zeros_like(v1)
    dx1 = jnp.where(stuck[0], zero, v1)
    dx2 = jnp.where(stuck[1], zero, v2)
    a1 = jnp.where(stuck[0], zero, a1)
    a2 = jnp.where(stuck[1], zero, a2)
    p_d = params.mu_k * (f.n1 * sdir[0] * dx1 + f.n2 * sdir[1] * dx2) + params.c * (dx1 * dx1 + dx2 * dx2)
    return jnp.stack([dx1, a1, dx2, a2, p_d, model.actuator_power(f)])


def init(
    params: Params,
    wave: AbstractWaveform,
    contact: Contact,
    x1: Array,
    x2: Array,
    v1: Array | None = None,
    v2: Array | None = None,
    phase: tuple[Array, Array] | None = None,
) -> Hybrid:
    """State at $t = 0$: positions `x1, x2` and velocities `v1, v2` (default at rest);
    `phase` $(\\cos\\omega t, \\sin\\omega t)$ of the drive (default $t = 0$) decides the modes.

    A mass at rest sticks if eq. (7) allows (its velocity then carries no tangent), and
    otherwise slips in the direction of its spring force; a moving one slips along its
    velocity."""
    dtype = params.dtype
    P = consts(params, wave)
    zero = jnp.zeros((), dtype)
    x1 = jnp.asarray(x1, dtype)
    x2 = jnp.asarray(x2, dtype)
    cph, sph = (jnp.ones((), dtype), zero) if phase is None else phase
    l0, _, _ = wave.at_phase(cph, sph)
    f, _ = _forces(P, contact, l0, x1, x2)
    absF = jnp.abs(f.fx)
    s1 = jnp.where(f.fx >= 0, 1.0, -1.0).astype(dtype)
    s2 = -s1
    stuck1 = absF <= P.mu_s * f.n1
    stuck2 = absF <= P.mu_s * f.n2
    if v1 is None or v2 is None:
        y = State(x1, 0 * x1, x2, 0 * x2, zero, zero)
    else:
        v1, v2 = jnp.asarray(v1, dtype), jnp.asarray(v2, dtype)
        stuck1, stuck2 = stuck1 & (v1 == 0), stuck2 & (v2 == 0)
        sgn = lambda v, s: jnp.where(v > 0, 1.0, jnp.where(v < 0, -1.0, s)).astype(dtype)
        s1, s2 = sgn(v1, s1), sgn(v2, s2)
        y = State(x1, jnp.where(stuck1, 0, v1), x2, jnp.where(stuck2, 0, v2), zero, zero)
    lifted = (f.N1 <= 0) | (f.N2 <= 0)
    status = jnp.where(lifted & (contact == "strict"), Status.LIFTOFF, Status.OK).astype(jnp.int32)
    no = jnp.asarray(False)
    f32 = jnp.finfo(dtype).bits < 64
    side = lambda N: jnp.where(N > 0, 1.0, -1.0).astype(dtype)
    return Hybrid(
        t=zero,
        y=y,
        comp=State(*(zero,) * 6) if f32 else None,
        cph=cph,
        sph=sph,
        stuck1=stuck1,
        stuck2=stuck2,
        s1=s1,
        s2=s2,
        pend1=no,
        pend2=no,
        nu1=side(f.N1),
        nu2=side(f.N2),
        status=status,
        t_liftoff=jnp.where(lifted, zero, jnp.inf).astype(dtype),
        n_switch=jnp.zeros((), jnp.int32),
        cross=jnp.asarray(jnp.inf, dtype),
        near=jnp.asarray(jnp.inf, dtype),
        t_switch=jnp.asarray(-jnp.inf, dtype),
    )


class _Mode(NamedTuple):
    """The mode during a step: stuck flags, slip directions, sides of the normal forces."""

    st1: Array
    st2: Array
    s1: Array
    s2: Array
    sides: tuple[Array, Array]


class _Switched(NamedTuple):
    """An iteration's start after its switches."""

    f0: _F
    geo0: tuple
    y0: State
    comp: State | None
    mode: _Mode
    vel1: Array  # a slipping mass's velocity reached zero here (it sticks or reverses)
    vel2: Array
    n_switch: Array


class _Motion(NamedTuple):
    """Accelerations, rates, their time derivatives and the event functions at one end of a step."""

    a1: Array
    a2: Array
    r: State
    D: _D
    j: State
    g: list
    d: list
    e: list


class _Length(NamedTuple):
    """The step's length and the drive at its midpoint and end."""

    h: Array
    t1: Array
    ce: Array
    se: Array
    mid: tuple[Array, Array]  # (l0, dl0)
    end: tuple[Array, Array, Array]  # (l0, dl0, ddl0)


class _Crossing(NamedTuple):
    """The earliest crossing of the step: which functions crossed, which came first, where."""

    crossed: list
    cut: Array
    first: list
    theta: Array


def _switch(P: Consts, contact: Contact, st: "Hybrid", l0: Array, keep) -> _Switched:
    """Forces at the start, then the switches (SPEC §2). A mass located at t (pend) or whose
    event function is negative here switches: a stuck one slips in the direction of $F_i$; a
    slipping one ($v_i = 0$) sticks if $|F_i| \\le \\mu_s n_i$ (eq. 7), else its friction reverses."""
    dtype = st.t.dtype
    yA = st.y
    zero = jnp.zeros_like(st.t)
    f0, geo0 = _forces(P, contact, l0, yA.x1, yA.x2)
    f0 = f0._replace(fx=keep(f0.fx), fy=keep(f0.fy), tension=keep(f0.tension))
    f0 = f0._replace(N1=P.m1 - f0.fy, N2=P.m2 + f0.fy)
    f0 = f0._replace(n1=jnp.abs(f0.N1), n2=jnp.abs(f0.N2)) if contact == "paper" else f0._replace(n1=f0.N1, n2=f0.N2)
    gA1, gA2 = _mass_events(P, f0, yA, st.stuck1, st.stuck2, st.s1, st.s2)
    fire1 = keep(st.pend1 | (gA1 < 0))
    fire2 = keep(st.pend2 | (gA2 < 0))
    absF = jnp.abs(f0.fx)
    to1 = jnp.where(f0.fx >= 0, 1.0, -1.0).astype(dtype)
    vel1, vel2 = fire1 & ~st.stuck1, fire2 & ~st.stuck2
    st1 = jnp.where(fire1, vel1 & (absF <= P.mu_s * f0.n1), st.stuck1)
    st2 = jnp.where(fire2, vel2 & (absF <= P.mu_s * f0.n2), st.stuck2)
    s1 = jnp.where(fire1, to1, st.s1)
    s2 = jnp.where(fire2, -to1, st.s2)
    y0 = yA._replace(v1=jnp.where(vel1, zero, yA.v1), v2=jnp.where(vel2, zero, yA.v2))
    comp = st.comp
    if comp is not None:  # a switch sets velocities exactly (to 0): drop their compensation
        comp = comp._replace(v1=jnp.where(vel1, zero, comp.v1), v2=jnp.where(vel2, zero, comp.v2))
    n_switch = st.n_switch + (fire1 | fire2).astype(jnp.int32)
    mode = _Mode(st1, st2, s1, s2, (st.nu1, st.nu2))
    return _Switched(f0, geo0, y0, comp, mode, vel1, vel2, n_switch)


def _motion(P: Consts, contact: Contact, f: _F, geo, y: State, mode: _Mode, dl0, ddl0, target, keep, pin) -> _Motion:
    """What the step needs at one of its ends, in `mode`; `pin` also materialises the forces'
    second rates (at the start, where the margins read them too)."""
    st1, st2, s1, s2, sides = mode
    a1, a2 = (keep(x) for x in _accel(P, f, y, st1, st2, s1, s2))
    r = _rates(P, f, y, a1, a2, s1, s2, dl0)
    D = _derivs(P, geo, y, a1, a2, dl0, ddl0)
    if pin:
        D = D._replace(fx=keep(D.fx), fy=keep(D.fy), fx2=keep(D.fx2), fy2=keep(D.fy2))
    else:
        D = D._replace(fx=keep(D.fx), fy=keep(D.fy))
    j = _second(P, contact, f, D, y, a1, a2, st1, st2, s1, s2, dl0, ddl0, sides)
    g, d, e = _events(P, contact, f, D, y, r, j, st1, st2, s1, s2, target, sides)
    return _Motion(a1, a2, r, D, j, list(g), list(d), list(e))


def _step_length(wave: AbstractWaveform, dt: float | Array, st: "Hybrid", t_stop: Array, m0: _Motion, keep) -> _Length:
    """`dt`, or less to land on `t_stop`, or less to end just past the earliest event
    predicted by the Taylor quadratic of each event function. A crossing is then cut late in
    a short step, so the dense output there is as accurate as a step of that length (an
    interpolant inherits the error of the step's end state: cutting early in a full step
    would cost ~10x in accuracy)."""
    t0 = st.t
    dtype = t0.dtype
    span = t_stop - t0
    h_nom = jnp.minimum(jnp.asarray(dt, dtype), span)
    s_pred = jnp.asarray(jnp.inf, dtype)
    for g, d, e in zip(m0.g, m0.d, m0.e):
        s_pred = jnp.minimum(s_pred, predict(g, d, e))
    # Never shorter than a few ulps of t, or float32 time would stop advancing.
    h_pred = jnp.maximum(PREDICT_MARGIN * s_pred, 64 * jnp.finfo(dtype).eps * jnp.maximum(jnp.abs(t0), 1))
    short = h_pred < h_nom
    lands = (span <= dt) & ~short
    h = jnp.where(short, h_pred, h_nom)
    t1 = jnp.where(lands, t_stop, t0 + h)
    # Step by the representable difference so that time and state stay consistent
    # (in float32 at t ~ 1e3, t + h rounds h by up to 1e-3 relative).
    h = keep(t1 - t0)
    sa, ca = (keep(x) for x in sincos(wave.omega * (0.5 * h)))
    cm, sm = rotate(st.cph, st.sph, ca, sa)
    ce, se = (keep(x) for x in rotate(cm, sm, ca, sa))
    l0m, dl0m, _ = wave.at_phase(cm, sm)
    l0e, dl0e, ddl0e = wave.at_phase(ce, se)
    return _Length(h, t1, ce, se, (l0m, dl0m), (l0e, dl0e, ddl0e))


def _rk4(P: Consts, contact: Contact, y0: State, k1: State, L: _Length, mode: _Mode, keep) -> tuple[State, State]:
    """One RK4 step of length `L.h` from `y0` (rates `k1`): the increment and the end state."""
    st1, st2, s1, s2, sides = mode
    h = L.h

    def stage(l0, dl0, y):
        f, _ = _forces(P, contact, l0, y.x1, y.x2, sides)
        a1, a2 = _accel(P, f, y, st1, st2, s1, s2)
        return _rates(P, f, y, keep(a1), keep(a2), s1, s2, dl0)

    k2 = stage(*L.mid, y0.map(lambda a, b: a + (0.5 * h) * b, k1))
    k3 = stage(*L.mid, y0.map(lambda a, b: a + (0.5 * h) * b, k2))
    k4 = stage(*L.end[:2], y0.map(lambda a, b: a + h * b, k3))
    incr = k1.map(lambda a, b, c, d: keep((h / 6) * (a + 2 * (b + c) + d)), k2, k3, k4)
    return incr, y0.map(lambda a, b: keep(a + b), incr)


def _first_crossing(h: Array, m0: _Motion, m1: _Motion, keep) -> _Crossing:
    """The earliest crossing by the secant of each crossed function, then located on the
    quintic Hermite interpolant of the first one ([`root`][]: implicit-function derivative)."""
    h2 = h * h
    dtype = h.dtype
    crossed = [g < 0 for g in m1.g]
    cut = union(crossed)
    inf = jnp.asarray(jnp.inf, dtype)
    thl = []
    for c, g0, d0, g1 in zip(crossed, m0.g, m0.d, m1.g):
        a0 = jnp.where(g0 == 0, h * d0, g0)  # deflated when starting on the surface
        den = a0 - g1
        thl.append(jnp.where(c, a0 / jnp.where(den > 0, den, 1), inf))
    th_min = thl[0]
    for x in thl[1:]:
        th_min = jnp.minimum(th_min, x)
    first = [keep(c & (x <= th_min)) for c, x in zip(crossed, thl)]
    pick = [m0.g[-1], m0.d[-1], m0.e[-1], m1.g[-1], m1.d[-1], m1.e[-1]]
    for i in reversed(range(len(m1.g) - 1)):
        vals = (m0.g[i], m0.d[i], m0.e[i], m1.g[i], m1.d[i], m1.e[i])
        pick = [jnp.where(first[i], v, p) for v, p in zip(vals, pick)]
    cg0, cd0, ce0, cg1, cd1, ce1 = pick
    coef = quintic(jnp.maximum(cg0, 0), h * cd0, h2 * ce0, jnp.minimum(cg1, 0), h * cd1, h2 * ce1)
    theta = keep(jnp.where(cut, root(coef, jnp.minimum(cg1, 0)), 1))
    return _Crossing(crossed, cut, first, theta)


def _step_margins(P: Consts, contact: Contact, omega, st: "Hybrid", sw: _Switched, m0: _Motion, h, crossed):
    """Margins to a change of switching structure ([`margins`][]); they feed nothing back.
    The events located at t (pend) are measured here, at their crossing, in the mode before
    the switch, from values this iteration has (forces and their rates here)."""
    dtype = st.t.dtype
    f0, D0, (u, il, pl) = sw.f0, m0.D, sw.geo0
    absF = jnp.abs(f0.fx)
    sg0 = jnp.where(f0.fx >= 0, 1.0, -1.0).astype(dtype)
    n1d0, n2d0, _, _ = _normal_rates(contact, D0, sw.mode.sides)
    ao1, ao2 = _accel(P, f0, st.y, st.stuck1, st.stuck2, st.s1, st.s2)  # the mode before the switch
    # Second rates of the forces in that mode: fx2, fy2 depend on the accelerations only
    # through u'' = a2 - a1, linearly (eqs. 2, 8): d fx2/d u'' = pl + u^2 (k - pl)/l^2.
    kk = u * il * il * (P.k - pl)
    du2 = (ao2 - ao1) - (m0.a2 - m0.a1)
    fx2o = D0.fx2 + (pl + u * kk) * du2
    fy2o = D0.fy2 + P.d * kk * du2
    n1ddo, n2ddo = (-fy2o, fy2o) if contact != "paper" else (-st.nu1 * fy2o, st.nu2 * fy2o)
    located = []
    for pend, stuck, sdir, ao, sgn, n_d, n_dd, im in (
        (st.pend1, st.stuck1, st.s1, ao1, 1.0, n1d0, n1ddo, P.im1),
        (st.pend2, st.stuck2, st.s2, ao2, -1.0, n2d0, n2ddo, P.im2),
    ):
        # A stuck mass's event is mu_s n_i - |F_i|, a slipping one's sigma_i v_i (at v_i = 0).
        aod = (sgn * D0.fx - P.c * ao - P.mu_k * n_d * sdir) * im
        rate = jnp.where(stuck, P.mu_s * n_d - sg0 * D0.fx, sdir * ao)
        curv = jnp.where(stuck, P.mu_s * n_dd - sg0 * fx2o, sdir * aod)
        located.append((pend, rate, curv))
    decide = (
        (sw.vel1, P.mu_s * f0.n1 - absF, P.mu_s * n1d0 - sg0 * D0.fx),
        (sw.vel2, P.mu_s * f0.n2 - absF, P.mu_s * n2d0 - sg0 * D0.fx),
    )
    return margins(omega, h, located, decide, crossed, m0.g, m0.d, m0.e)


def step(
    params: Params,
    wave: AbstractWaveform,
    contact: Contact,
    dt: float | Array,
    st: Hybrid,
    t_stop: Array,
    target: Target | None = None,
    P: Consts | None = None,
) -> tuple[Hybrid, StepInfo]:
    """One iteration: switch what is pending, then one RK4 step, cut at the first event.

    The step never passes `t_stop` (a measurement boundary or save time) and lands
    on it exactly unless an event comes first. `target` adds the caller's event
    (`StepInfo.target_fired`). `P` are the constants of `params` (pass them to
    hoist them out of a loop).

    Stages: the switches at the start ([`_switch`][]), the rates and event functions there
    ([`_motion`][]), the step's length ([`_step_length`][]), one RK4 step ([`_rk4`][]), the
    same quantities at its end, the first crossing ([`_first_crossing`][]), the margins
    ([`_step_margins`][]), and the commit: the full step, or the dense output at the crossing.
    """
    P = consts(params, wave) if P is None else P
    keep = lambda x: _keep(P, x)
    dtype = st.t.dtype
    t0 = st.t
    yA = st.y

    l00, dl00, ddl00 = wave.at_phase(st.cph, st.sph)
    sw = _switch(P, contact, st, l00, keep)
    f0, y0, mode = sw.f0, sw.y0, sw.mode
    st1, st2, s1, s2, sides = mode

    # Lift-off or the target found negative here (a crossing located after another
    # one in the same step) count at t.
    lifted0 = (f0.N1 < 0) | (f0.N2 < 0)
    stop0 = lifted0 if contact == "strict" else jnp.asarray(False)
    t_lift = st.t_liftoff
    t_lift = jnp.where(lifted0 & ~jnp.isfinite(t_lift), t0, t_lift)  # flagged (paper) or stopping (strict)
    if target is not None:
        X_A = P.mhat * yA.x1 + (1 - P.mhat) * yA.x2
        target_now = target.active & (jnp.abs(X_A - target.X0) >= target.z)
        target = target._replace(active=target.active & ~target_now)
    else:
        target_now = jnp.asarray(False)

    m0 = _motion(P, contact, f0, sw.geo0, y0, mode, dl00, ddl00, target, keep, pin=True)
    L = _step_length(wave, dt, st, t_stop, m0, keep)
    h = L.h
    incr, y1 = _rk4(P, contact, y0, m0.r, L, mode, keep)
    f1, geo1 = _forces(P, contact, L.end[0], y1.x1, y1.x2, sides)
    m1 = _motion(P, contact, f1, geo1, y1, mode, L.end[1], L.end[2], target, keep, pin=False)
    m1 = m1._replace(g=[keep(g) for g in m1.g])
    cr = _first_crossing(h, m0, m1, keep)
    cut, first = cr.cut, cr.first
    target_cut = first[-1] if target is not None else jnp.asarray(False)
    m_cross, m_near = _step_margins(P, contact, wave.omega, st, sw, m0, h, cr.crossed)

    # -- commit: the full step, or the quintic dense output at the crossing.
    h2 = h * h
    H1, H2, H3, H4, H5 = (keep(x) for x in hermite_basis(cr.theta))
    hH1, hH4, h2H2, h2H5 = h * H1, h * H4, h2 * H2, h2 * H5
    part = incr.map(lambda i, a, b, c, d: H3 * i + hH1 * a + hH4 * b + h2H2 * c + h2H5 * d, m0.r, m1.r, m0.j, m1.j)
    delta = incr.map(lambda i, p: jnp.where(cut, p, i), part)
    tc = jnp.where(cut, t0 + cr.theta * h, L.t1)
    sc, cc = sincos(wave.omega * (tc - t0))
    cph, sph = rotate(st.cph, st.sph, cc, sc)
    cph = jnp.where(cut, cph, L.ce)
    sph = jnp.where(cut, sph, L.se)
    # Renormalise the carried phase (rounding would otherwise let its radius drift).
    norm = 1.5 - 0.5 * (cph * cph + sph * sph)
    cph, sph = cph * norm, sph * norm
    comp = sw.comp
    if comp is None:
        yc = y0.map(lambda a, b: a + b, delta)
        comp_new = None
    else:
        # Compensated (Kahan) update: positions and energies grow to O(10-100) while
        # increments are O(1e-4); plain float32 sums would lose ~1e-3 over 1e5 steps.
        corr = delta.map(lambda a, b: a - b, comp)
        yc = y0.map(lambda a, b: a + b, corr)
        comp_new = yc.map(lambda tot, a, b: (tot - a) - b, y0, corr)

    # A normal force's crossing: the first one is a lift-off (from above: no earlier one),
    # which stops the run under the strict reading.
    lift_cut = first[2]
    t_lift = jnp.where(lift_cut & ~jnp.isfinite(t_lift), tc, t_lift)
    lift = stop0 | lift_cut if contact == "strict" else stop0
    nu1, nu2 = sides
    if contact == "paper":
        # The crossing normal force changes side. N1 + N2 = m1 + m2 > 0, so only one
        # can be at zero: the lower of the two at the step's end.
        low1 = nu1 * f1.N1 <= nu2 * f1.N2
        nu1, nu2 = jnp.where(lift_cut & low1, -nu1, nu1), jnp.where(lift_cut & ~low1, -nu2, nu2)
    commit = ~stop0
    # The masses met (outside the model): the run stops after this step (`Status.COLLISION`).
    met = commit & (yc.x2 - yc.x1 <= 0)
    status = jnp.where(lift, Status.LIFTOFF, jnp.where(met, Status.COLLISION, st.status)).astype(jnp.int32)

    keepc = lambda new, old: jnp.where(commit, new, old)
    new = Hybrid(
        t=keepc(tc, t0),
        y=yc.map(keepc, yA),
        comp=None if comp_new is None else comp_new.map(keepc, st.comp),
        cph=keepc(cph, st.cph),
        sph=keepc(sph, st.sph),
        stuck1=keepc(st1, st.stuck1),
        stuck2=keepc(st2, st.stuck2),
        s1=keepc(s1, st.s1),
        s2=keepc(s2, st.s2),
        pend1=commit & first[0],
        pend2=commit & first[1],
        nu1=keepc(nu1, st.nu1),
        nu2=keepc(nu2, st.nu2),
        status=status,
        t_liftoff=t_lift.astype(dtype),
        n_switch=sw.n_switch,
        cross=jnp.where(commit, jnp.minimum(st.cross, m_cross), st.cross),
        near=jnp.where(commit, jnp.minimum(st.near, m_near), st.near),
        t_switch=jnp.where(commit & cut & ~target_cut, jax.lax.stop_gradient(tc), st.t_switch),
    )
    t_target = jnp.where(target_now, t0, tc)
    y_target = yc.map(lambda a, b: jnp.where(target_now, b, a), yA)
    absF = jnp.abs(f0.fx)
    info = StepInfo(
        commit=commit,
        t0=t0,
        y0=y0,
        tension0=f0.tension,
        t1=tc,
        y1=yc,
        stuck1=st1,
        stuck2=st2,
        target_fired=target_now | (commit & target_cut),
        t_target=t_target,
        y_target=y_target,
        zero1=sw.vel1,
        zero2=sw.vel2,
        slack1=P.mu_s * f0.n1 - absF,
        slack2=P.mu_s * f0.n2 - absF,
        h=h,
        fy=(f0.fy, m0.D.fy, m0.D.fy2, f1.fy, m1.D.fy, m1.D.fy2),
    )
    return new, info


def probe(params: Params, wave: AbstractWaveform, contact: Contact, t: Array, y: State, target: Target):
    """The event functions, with their first and second time derivatives, at time `t` and
    state `y` (in the mode [`init`][] decides there): lists `(g, dg/dt, d2g/dt2)` as in a
    step's start. For margins at a measured instant; not for the hot loop."""
    P = consts(params, wave)
    phase = (jnp.cos(wave.omega * t), jnp.sin(wave.omega * t))
    st = init(params, wave, contact, y.x1, y.x2, y.v1, y.v2, phase)
    l0, dl0, ddl0 = wave.at_phase(*phase)
    f, geo = _forces(P, contact, l0, st.y.x1, st.y.x2)
    a1, a2 = _accel(P, f, st.y, st.stuck1, st.stuck2, st.s1, st.s2)
    r = _rates(P, f, st.y, a1, a2, st.s1, st.s2, dl0)
    D = _derivs(P, geo, st.y, a1, a2, dl0, ddl0)
    sides = (st.nu1, st.nu2)
    j = _second(P, contact, f, D, st.y, a1, a2, st.stuck1, st.stuck2, st.s1, st.s2, dl0, ddl0, sides)
    return _events(P, contact, f, D, st.y, r, j, st.stuck1, st.stuck2, st.s1, st.s2, target, sides)


def energy(P: Consts, y: State, tension: Array) -> Array:
    """Eq. (10) from the tension $T = k(\\ell - \\ell_0)$: $\\tfrac12(m_1 v_1^2 + m_2 v_2^2 + T^2/k)$."""
    return 0.5 * (P.m1 * y.v1 * y.v1 + P.m2 * y.v2 * y.v2 + tension * tension / P.k)
