"""The motion of a mechanism in a fixed mode: rates, and the time derivatives that the exact engine's
dense output and event prediction need (SPEC §2 and §8), from the mechanism's
[`AbstractPhysics`][locomotion_jax.AbstractPhysics].

Everything is over tuples of per-body scalars. In a fixed mode the motion is smooth: each
body is stuck ($\\dot x_i = \\dot v_i = 0$) or slips in a fixed direction $\\sigma_i$, and each
normal force enters friction as $n_i = N_i$ (strict contact) or $\\nu_i N_i$ with a fixed side
$\\nu_i$ (paper contact, inside a step). The event functions are listed in the engine's
docstring ([`_engine`][locomotion_jax.dynamics._engine]).
"""

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from .._custom_types import Array, Contact
from ..model._physics import AbstractPhysics, load_rates_at, load_second_at, Loads, loads_at, Scalars
from . import _numerics as num


class State(NamedTuple):
    """Integrated quantities: positions `x` and velocities `v` (one scalar per mass), $e_d$ (eq. 15), $w$ (eq. 16);
    under `contact="hop"` only, the heights `y` and vertical velocities `vy` per body (else `None`, so
    that the other readings' programs carry nothing more)."""

    x: Scalars
    v: Scalars
    ed: Array
    w: Array
    y: Scalars | None = None
    vy: Scalars | None = None

    def map(self, fn, *others) -> "State":
        return jax.tree_util.tree_map(fn, self, *others)


class Mode(NamedTuple):
    """The mode during a step, per mass: stuck, slip direction $\\sigma_i$, side $\\nu_i$ of $N_i$, and
    (`contact="hop"` only) in flight."""

    stuck: Scalars
    sdir: Scalars
    side: Scalars
    fly: Scalars | None = None


def kept(P: AbstractPhysics, dr: Any) -> Any:
    """[`AbstractPhysics.keep`][locomotion_jax.AbstractPhysics.keep] every entry of an actuation
    (each feeds every stage that uses it)."""
    return jax.tree_util.tree_map(P.keep, dr)


def _sum(terms: list) -> Array:
    """The sum over per-body terms (and over an array layout's body axis: `_numerics.total`)."""
    return num.total(terms)


def normal(contact: Contact, N: Scalars, side: Scalars | None = None) -> Scalars:
    """The normal forces $n_i$ entering friction (SPEC §8): $N_i$ (strict contact), $|N_i|$ (paper),
    or inside a step (paper, `side` given) $\\nu_i N_i$: $|N_i|$ on the side the step started on,
    continued smoothly past a crossing (where the step is cut). Also maps rates of $N_i$ to those of $n_i$."""
    if contact != "paper":
        return N
    if side is None:
        return tuple(jnp.abs(q) for q in N)
    return tuple(s * q for s, q in zip(side, N))


def normal_rate(contact: Contact, N: Scalars, dN: Scalars) -> Scalars:
    """Time derivatives of the normal forces $n_i$ of [`normal`][] without `side` from those of
    $N_i$: $\\dot N_i$ (strict) or $\\operatorname{sgn}(N_i)\\dot N_i$ (paper; $+\\dot N_i$ at $N_i = 0$,
    as `jax.jvp` of `jnp.abs`)."""
    if contact != "paper":
        return dN
    return tuple(jnp.where(q >= 0, r, -r) for q, r in zip(N, dN))


def stick_margin(P: AbstractPhysics, F: Scalars, n: Scalars) -> list:
    """The stuck masses' event values $\\min(\\mu_{s,\\mathrm{fwd}} n_i - F_i, F_i + \\mu_{s,\\mathrm{bwd}} n_i)$;
    for an isotropic law $\\mu_s n_i - |F_i|$, the same value in fewer operations."""
    return [mf * q - jnp.abs(f) if mb is None else jnp.minimum(mf * q - f, f + mb * q)
            for mf, mb, q, f in zip(P.mu_f, P.mu_b, n, F)]  # fmt: skip


def stick_margin_rate(
    P: AbstractPhysics, F: Scalars, n: Scalars, dF: Scalars, dn: Scalars, sgn: Scalars | None = None
) -> list:
    """A time derivative of [`stick_margin`][] given those of $F_i$ and $n_i$: the smaller
    branch's, their mean at a tie (as `jax.jvp` of `jnp.minimum`). Isotropic: $\\mu n_i - s_i F_i$
    with $s_i$ the sign `sgn` of $F_i$ over the step (default $\\operatorname{sgn} F_i$, 0 at $F_i = 0$)."""
    sgn = tuple(jnp.sign(f) for f in F) if sgn is None else sgn
    out = []
    for mf, mb, q, f, df, dq, s in zip(P.mu_f, P.mu_b, n, F, dF, dn, sgn):
        if mb is None:
            out.append(mf * dq - s * df)
        else:
            a, b = mf * q - f, f + mb * q
            da, db = mf * dq - df, df + mb * dq
            out.append(jnp.where(a < b, da, jnp.where(b < a, db, 0.5 * (da + db))))
    return out


def with_velocity(P: AbstractPhysics, F: Scalars, v: Scalars) -> Scalars:
    """$F_i$ with the physics' velocity forces at velocities `v` (relative dampers); `F` itself
    when it has none (every chain), so their runs are unchanged."""
    D = P.velocity_forces(v)
    return F if D is None else tuple(f + d for f, d in zip(F, D))


def _add_power(P: AbstractPhysics, ed: Any, v: Scalars, u: Scalars, scale: float = 1.0) -> Any:
    p = P.velocity_power(v, u)
    return ed if p is None else ed + scale * p


def _in_mode(P: AbstractPhysics, contact: Contact, mode: Mode, dr: Any, L: Loads, v: Scalars, vy=None):
    """The normal forces $n_i$, speeds, kinetic coefficients and the state's rate at a state with
    loads `L`: $\\dot x_i = v_i$, $m_i \\dot v_i = F_i - c_i v_i - \\sigma_i \\mu_k n_i$
    (both zero when stuck; eq. 9 generalised), $\\dot e_d = \\sum_i \\mu_k n_i |v_i| + c_i v_i^2$
    (eq. 15) and $\\dot w$, the actuator's power (eq. 16). Under `contact="hop"` a body in flight
    feels no friction ($n_i = 0$) and falls: $\\dot y_i = w_i$, $\\dot w_i$ = `P.fall(N)`
    ($m_i \\dot w_i = -m_i + V_i = -N_i$ for a body that carries nothing)."""
    F, N = with_velocity(P, L.F, v), L.N
    n = normal(contact, N, mode.side)
    if mode.fly is not None:  # no friction in flight
        n = tuple(jnp.where(f, 0, q) for f, q in zip(mode.fly, n))
    speed = tuple(sd * vi for sd, vi in zip(mode.sdir, v))  # |v_i| in a slip segment; 0 when stuck
    mu = tuple(law.kinetic(s, sd) for law, s, sd in zip(P.friction, speed, mode.sdir))
    a = tuple(
        P.keep(jnp.where(st, 0, (f - c * vi - sd * m * q) * im))
        for st, f, c, vi, sd, m, q, im in zip(mode.stuck, F, P.c, v, mode.sdir, mu, n, P.im)
    )
    xd = tuple(jnp.where(st, 0, vi) for st, vi in zip(mode.stuck, v))
    ed = _add_power(P, _sum([m * q * s + c * vi * vi for m, q, s, c, vi in zip(mu, n, speed, P.c, v)]), v, v)
    rate = State(xd, a, ed, P.power(dr, L, v))
    if mode.fly is not None:  # in flight m_i w_i' = -m_i + V_i = -N_i; on the ground y_i = w_i = 0
        assert vy is not None, "contact='hop' needs the vertical velocities"
        rate = rate._replace(
            y=tuple(jnp.where(f, q, 0) for f, q in zip(mode.fly, vy)),
            vy=tuple(jnp.where(f, q, 0) for f, q in zip(mode.fly, P.fall(N))),
        )
    return n, speed, mu, rate


def rates(P: AbstractPhysics, contact: Contact, mode: Mode, dr: Any, y: State) -> State:
    """The state's rate (an RK4 stage): see [`_in_mode`][]."""
    return _in_mode(P, contact, mode, dr, loads_at(P, dr, y.x, y=y.y), y.v, y.vy)[3]


class Derivs(NamedTuple):
    """The state's rate and second time derivative; the events' values and first two time
    derivatives; the loads' first time derivatives $\\dot F_i$, $\\dot N_i$, and $\\ddot N_i$."""

    rate: State
    second: State
    g: list
    dg: list
    ddg: list
    dF: Scalars
    dN: Scalars
    ddN: Scalars


def derivatives(
    P: AbstractPhysics, contact: Contact, mode: Mode, target, dr: Any, L: Loads, x, v, y=None, vy=None
) -> Derivs:
    """Rates and event values with their first and second time derivatives along the motion in a
    fixed mode, at a state whose loads `L` are given (the loads' rates from the physics, along the
    vertical motion too under `contact="hop"`; the friction law's own `kinetic_rate`)."""
    F, N = with_velocity(P, L.F, v), L.N
    n, speed, mu, rate = _in_mode(P, contact, mode, dr, L, v, vy)
    xd, a = rate.x, rate.v
    fly = mode.fly
    grounded = (lambda q: q) if fly is None else (lambda q: tuple(jnp.where(f, 0, r) for f, r in zip(fly, q)))

    # First derivatives: the loads along (xd, the actuation's rate), the kinetic coefficients.
    R = load_rates_at(P, dr, L, xd, P.keep, yd=rate.y)
    dF, dN = with_velocity(P, R.dF, a), R.dN
    dn = grounded(normal(contact, dN, mode.side))
    dspeed = tuple(sd * ai for sd, ai in zip(mode.sdir, a))
    dmu = [law.kinetic_rate(s, sd, ds) for law, s, sd, ds in zip(P.friction, speed, mode.sdir, dspeed)]
    fric = [m * q1 if r is None else r * q + m * q1 for m, q, r, q1 in zip(mu, n, dmu, dn)]  # d(mu_i n_i)/dt
    jerk = tuple(
        jnp.where(st, 0, (f - c * ai - sd * fr) * im)
        for st, f, c, ai, sd, fr, im in zip(mode.stuck, dF, P.c, a, mode.sdir, fric, P.im)
    )
    ded = _sum([fr * s + m * q * ds + 2 * c * vi * ai
                for fr, s, m, q, ds, c, vi, ai in zip(fric, speed, mu, n, dspeed, P.c, v, a)])  # fmt: skip
    ded = _add_power(P, ded, v, a, 2.0)
    dw = P.power_rate(dr, L, R, v, a)
    second = State(a, jerk, ded, dw)
    if fly is not None:
        second = second._replace(y=rate.vy, vy=tuple(jnp.where(f, q, 0) for f, q in zip(fly, P.fall(dN))))

    # Second derivatives of the loads, for the events' curvature.
    ddF, ddN = load_second_at(P, dr, L, R, xd, a, yd=rate.y, ya=rate.vy)
    ddF = with_velocity(P, ddF, jerk)
    ddn = grounded(normal(contact, ddN, mode.side))

    # A stuck body's $|F_i|$ has a kink where $F_i = 0$ (a start from rest with its springs relaxed):
    # its rates are those of the side $F_i$ moves to over the step, the sign of its first nonzero
    # derivative, so that the margin's quintic follows the one-sided motion (the breakaway located
    # where $\mu n_i = |F_i|$, not where a two-sided rate of 0 puts it).
    sgn = jnp.sign
    lead = tuple(jnp.where(f != 0, sgn(f), jnp.where(df != 0, sgn(df), sgn(ddf))) for f, df, ddf in zip(F, dF, ddF))
    stick = (
        stick_margin(P, F, n),
        stick_margin_rate(P, F, n, dF, dn, lead),
        stick_margin_rate(P, F, n, ddF, ddn, lead),
    )
    g, dg, ddg = (
        [jnp.where(st, p, sd * q) for st, p, sd, q in zip(mode.stuck, margin, mode.sdir, slip)]
        for margin, slip in zip(stick, (v, a, jerk))
    )
    if fly is not None:  # no friction in flight: a sign change of v_i is no event there
        inf = jnp.asarray(jnp.inf, F[0].dtype)
        g = [jnp.where(f, inf, q) for f, q in zip(fly, g)]
        dg = [jnp.where(f, 0, q) for f, q in zip(fly, dg)]
        ddg = [jnp.where(f, 0, q) for f, q in zip(fly, ddg)]
    if contact == "strict":  # min_i N_i, its rates averaged over ties (as `jax.jvp` of `jnp.min`)
        low = num.least(N)
        at = [q == low for q in N]
        count = _sum([w.astype(low.dtype) for w in at])
        g.append(low)
        dg.append(_sum([jnp.where(w, r, 0) for w, r in zip(at, dN)]) / count)
        ddg.append(_sum([jnp.where(w, r, 0) for w, r in zip(at, ddN)]) / count)
    elif fly is not None:  # per body: on the ground its lift-off load (P.ride), in flight y_i (landing)
        assert y is not None and vy is not None and rate.vy is not None, "contact='hop' needs the heights"
        g += [jnp.where(f, h, q) for f, h, q in zip(fly, y, P.ride(N))]
        dg += [jnp.where(f, h, q) for f, h, q in zip(fly, vy, P.ride(dN))]
        ddg += [jnp.where(f, h, q) for f, h, q in zip(fly, rate.vy, P.ride(ddN))]
    else:
        g += list(n)
        dg += list(dn)
        ddg += list(ddn)
    if target is not None:
        rel = P.centre_of_mass(x) - target.X0
        sgn = jnp.where(rel >= 0, 1.0, -1.0).astype(rel.dtype)  # d|r| = sgn(r) dr, sgn(0) = 1 (as `jax.jvp`)
        inf = jnp.asarray(jnp.inf, rel.dtype)
        g.append(jnp.where(target.active, target.z - jnp.abs(rel), inf))
        dg.append(jnp.where(target.active, -sgn * P.centre_of_mass(xd), 0))
        ddg.append(jnp.where(target.active, -sgn * P.centre_of_mass(a), 0))
    return Derivs(rate, second, g, dg, ddg, dF, dN, ddN)


def energy(P: AbstractPhysics, y: State, L: Loads) -> Array:
    """The mechanical energy at state `y` with loads `L` there (eq. 10 generalised); under
    `contact="hop"` with each body's gravity $m_i y_i$ and vertical kinetic energy $m_i w_i^2/2$."""
    e = P.energy(L, y.v)
    if y.y is not None and y.vy is not None:
        e = e + _sum([m * (h + 0.5 * q * q) for m, h, q in zip(P.m, y.y, y.vy)])
    return e
