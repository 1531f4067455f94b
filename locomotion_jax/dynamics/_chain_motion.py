"""The motion of a chain in a fixed mode: rates, and the time derivatives that the exact engine's
dense output and event prediction need (SPEC §2 and §8).

Everything is over tuples of per-mass scalars (see [`_chain_forces`][locomotion_jax.dynamics._chain_forces]).
In a fixed mode the motion is smooth: each mass is stuck ($\\dot x_i = \\dot v_i = 0$) or slips in a
fixed direction $\\sigma_i$, and each normal force enters friction as $n_i = N_i$ (strict contact)
or $\\nu_i N_i$ with a fixed side $\\nu_i$ (paper contact, inside a step). The event functions are
listed in the engine's docstring ([`_chain_exact`][locomotion_jax.dynamics._chain_exact]).
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp

from .._custom_types import Array, Contact
from . import _chain_forces as forces
from ._chain_forces import Consts, Drive, Scalars


class State(NamedTuple):
    """Integrated quantities: positions `x` and velocities `v` (one scalar per mass), $e_d$ (eq. 15), $w$ (eq. 16)."""

    x: Scalars
    v: Scalars
    ed: Array
    w: Array

    def map(self, fn, *others) -> "State":
        return jax.tree_util.tree_map(fn, self, *others)


class Mode(NamedTuple):
    """The mode during a step, per mass: stuck, slip direction $\\sigma_i$, side $\\nu_i$ of $N_i$."""

    stuck: Scalars
    sdir: Scalars
    side: Scalars


def keep(P: Consts, x: Array) -> Array:
    """Materialise `x` once per iteration (`_exact._keep`: XLA on the CPU recomputes a cheap
    value inside every kernel that consumes it, but never duplicates a division)."""
    if x.dtype == jnp.bool_:
        return (x.astype(P.one.dtype) / P.one) > 0.5
    return x / P.one


def kept(P: Consts, dr: Drive) -> Drive:
    """[`keep`][] every entry of an actuation (each feeds every stage that uses it)."""
    kept = lambda q: None if q is None else tuple(keep(P, a) for a in q)
    return Drive(tuple(keep(P, a) for a in dr.l0), kept(dr.dl0), kept(dr.ddl0), kept(dr.f), kept(dr.df), kept(dr.ddf))


def _sum(terms: list) -> Array:
    return sum(terms[1:], terms[0])


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


def stick_margin(P: Consts, F: Scalars, n: Scalars) -> list:
    """The stuck masses' event values $\\min(\\mu_{s,\\mathrm{fwd}} n_i - F_i, F_i + \\mu_{s,\\mathrm{bwd}} n_i)$;
    for an isotropic law $\\mu_s n_i - |F_i|$, the same value in fewer operations."""
    return [mf * q - jnp.abs(f) if mb is None else jnp.minimum(mf * q - f, f + mb * q)
            for mf, mb, q, f in zip(P.mu_f, P.mu_b, n, F)]  # fmt: skip


def stick_margin_rate(P: Consts, F: Scalars, n: Scalars, dF: Scalars, dn: Scalars) -> list:
    """A time derivative of [`stick_margin`][] given those of $F_i$ and $n_i$: the smaller
    branch's, their mean at a tie (as `jax.jvp` of `jnp.minimum`; isotropic: $\\operatorname{sgn} F_i = 0$)."""
    out = []
    for mf, mb, q, f, df, dq in zip(P.mu_f, P.mu_b, n, F, dF, dn):
        if mb is None:
            out.append(mf * dq - jnp.sign(f) * df)
        else:
            a, b = mf * q - f, f + mb * q
            da, db = mf * dq - df, df + mb * dq
            out.append(jnp.where(a < b, da, jnp.where(b < a, db, 0.5 * (da + db))))
    return out


def _in_mode(P: Consts, contact: Contact, mode: Mode, dr: Drive, sp: forces.Springs, F, N, v):
    """The normal forces $n_i$, speeds, kinetic coefficients and the state's rate at a state with
    springs `sp` and loads `F`, `N`: $\\dot x_i = v_i$, $m_i \\dot v_i = F_i - c_i v_i - \\sigma_i \\mu_k n_i$
    (both zero when stuck; eq. 9 generalised), $\\dot e_d = \\sum_i \\mu_k n_i |v_i| + c_i v_i^2$
    (eq. 15) and $\\dot w$, the actuator's power (eq. 16)."""
    n = normal(contact, N, mode.side)
    speed = tuple(sd * vi for sd, vi in zip(mode.sdir, v))  # |v_i| in a slip segment; 0 when stuck
    mu = tuple(law.kinetic(s, sd) for law, s, sd in zip(P.friction, speed, mode.sdir))
    a = tuple(
        keep(P, jnp.where(st, 0, (f - c * vi - sd * m * q) * im))
        for st, f, c, vi, sd, m, q, im in zip(mode.stuck, F, P.c, v, mode.sdir, mu, n, P.im)
    )
    xd = tuple(jnp.where(st, 0, vi) for st, vi in zip(mode.stuck, v))
    ed = _sum([m * q * s + c * vi * vi for m, q, s, c, vi in zip(mu, n, speed, P.c, v)])
    return n, speed, mu, State(xd, a, ed, forces.power(P, sp.tension, dr.dl0, dr.f, v))


def rates(P: Consts, contact: Contact, mode: Mode, dr: Drive, x: Scalars, v: Scalars) -> State:
    """The state's rate (an RK4 stage): see [`_in_mode`][]."""
    sp = forces.springs(P, dr.l0, x)
    F, N = forces.loads(P, sp.fx, sp.fy, dr.f)
    return _in_mode(P, contact, mode, dr, sp, F, N, v)[3]


class Derivs(NamedTuple):
    """The state's rate and second time derivative; the events' values and first two time
    derivatives; the loads' first time derivatives $\\dot F_i$, $\\dot N_i$."""

    rate: State
    second: State
    g: list
    dg: list
    ddg: list
    dF: Scalars
    dN: Scalars


def derivatives(P: Consts, contact: Contact, mode: Mode, target, dr: Drive, sp: forces.Springs, F, N, x, v) -> Derivs:
    """Rates and event values with their first and second time derivatives along the motion in a
    fixed mode, at a state whose springs `sp` and loads `F`, `N` are given (the chain rule through
    [`_chain_forces`][locomotion_jax.dynamics._chain_forces]; the friction law's own `kinetic_rate`)."""
    n, speed, mu, rate = _in_mode(P, contact, mode, dr, sp, F, N, v)
    xd, a = rate.x, rate.v

    # First derivatives: the springs along (xd, dl0), the loads, the kinetic coefficients.
    du = tuple(q - p for p, q in zip(xd[:-1], xd[1:]))
    sr = forces.spring_rates(P, sp, du, dr.dl0)
    dF, dN = forces.load_rates(tuple(map(lambda q: keep(P, q), sr.dfx)), tuple(map(lambda q: keep(P, q), sr.dfy)),
                               dr.df)  # fmt: skip
    dn = normal(contact, dN, mode.side)
    dspeed = tuple(sd * ai for sd, ai in zip(mode.sdir, a))
    dmu = [law.kinetic_rate(s, sd, ds) for law, s, sd, ds in zip(P.friction, speed, mode.sdir, dspeed)]
    fric = [m * q1 if r is None else r * q + m * q1 for m, q, r, q1 in zip(mu, n, dmu, dn)]  # d(mu_i n_i)/dt
    jerk = tuple(
        jnp.where(st, 0, (f - c * ai - sd * fr) * im)
        for st, f, c, ai, sd, fr, im in zip(mode.stuck, dF, P.c, a, mode.sdir, fric, P.im)
    )
    ded = _sum([fr * s + m * q * ds + 2 * c * vi * ai
                for fr, s, m, q, ds, c, vi, ai in zip(fric, speed, mu, n, dspeed, P.c, v, a)])  # fmt: skip
    dw = forces.power_rate(P, sp.tension, sr.dtension, dr.dl0, dr.ddl0, dr.f, dr.df, v, a)
    second = State(a, jerk, ded, dw)

    # Second derivatives of the loads, for the events' curvature.
    ddu = tuple(q - p for p, q in zip(a[:-1], a[1:]))
    ddfx, ddfy = forces.spring_second(P, sp, sr, du, ddu, dr.ddl0)
    ddF, ddN = forces.load_rates(ddfx, ddfy, dr.ddf)
    ddn = normal(contact, ddN, mode.side)

    stick = (stick_margin(P, F, n), stick_margin_rate(P, F, n, dF, dn), stick_margin_rate(P, F, n, ddF, ddn))
    g, dg, ddg = (
        [jnp.where(st, p, sd * q) for st, p, sd, q in zip(mode.stuck, margin, mode.sdir, slip)]
        for margin, slip in zip(stick, (v, a, jerk))
    )
    if contact == "strict":  # min_i N_i, its rates averaged over ties (as `jax.jvp` of `jnp.min`)
        low = N[0]
        for q in N[1:]:
            low = jnp.minimum(low, q)
        at = [q == low for q in N]
        count = _sum([w.astype(low.dtype) for w in at])
        g.append(low)
        dg.append(_sum([jnp.where(w, r, 0) for w, r in zip(at, dN)]) / count)
        ddg.append(_sum([jnp.where(w, r, 0) for w, r in zip(at, ddN)]) / count)
    else:
        g += list(n)
        dg += list(dn)
        ddg += list(ddn)
    if target is not None:
        rel = forces.centre_of_mass(P, x) - target.X0
        sgn = jnp.where(rel >= 0, 1.0, -1.0).astype(rel.dtype)  # d|r| = sgn(r) dr, sgn(0) = 1 (as `jax.jvp`)
        inf = jnp.asarray(jnp.inf, rel.dtype)
        g.append(jnp.where(target.active, target.z - jnp.abs(rel), inf))
        dg.append(jnp.where(target.active, -sgn * forces.centre_of_mass(P, xd), 0))
        ddg.append(jnp.where(target.active, -sgn * forces.centre_of_mass(P, a), 0))
    return Derivs(rate, second, g, dg, ddg, dF, dN)


def energy(P: Consts, y: State, tension: Scalars) -> Array:
    """$e = \\sum_i m_i v_i^2/2 + \\sum_j T_j^2/(2 k_j)$ (eq. 10 generalised)."""
    return forces.energy(P, y.v, tension)
