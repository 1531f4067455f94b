"""The physics of a [`Mechanism`][locomotion_jax.Mechanism] (SPEC §9): bodies with or without ground
contact, linear springs between any two bodies or to a wall, internal and external forces.

Over tuples of per-body scalars, as [`ChainPhysics`][locomotion_jax.model._chain_physics.ChainPhysics]
(the same reason: under `vmap` every intermediate is a vector over the configurations).

With $u = x_b - x_a$ ($x = 0$ for a wall) a spring's force is $f = k(u - r(t))$, $+f$ on `a`
and $-f$ on `b`; an internal force $f(t)$ acts $+f$ on `b`, $-f$ on `a`; an external force
$g_i(t)$ on body $i$. $F_i$ sums them. A tilted spring ([`TiltedSpring`][locomotion_jax.TiltedSpring],
the chain's spring of SPEC §8 between any two bodies; its geometry is `_chain_physics.tilted`'s) adds
its horizontal force $T u/\\ell$ ($+$ on `a`) and a vertical one $V = T h/\\ell$, $+V$ on `a` and $-V$
on `b` ($h = d$, or $d + y_b - y_a$ under `contact="hop"`). A body in contact bears the normal load
$N_i = m_i + $ (the weights that body $i$ carries, directly or through other carried bodies)
$- $ (the vertical forces on it and on the bodies it carries): constant where the mechanism has
no tilted spring.

A body without ground contact (carried, or free) gets a friction law of no friction
(`_NoContact`: kinetic coefficient 0, static limit $-1$) and the normal load 1: it never
sticks (its stick margin $-1 - |F_i|$ is negative), feels no friction and dissipates
nothing, and neither lifts off nor flips a contact side. So the exact engine runs it
unchanged; its only trace is an event where its velocity changes sign. Its smoothed law is
zero (`Smoothed` dynamics). Its `N` in a trajectory is this 1, not a load; the figures over the
normal loads leave it out (`MechanismPhysics.contact_values`).
"""

from typing import Any, NamedTuple

import equinox as eqx
import jax.numpy as jnp

from .._custom_types import Array
from ._chain_physics import spring_rates, spring_second, SpringRates, Springs, tilted
from ._elements import Damper, ExternalForce, Force, signal_at, Spring, TiltedSpring, WALL
from ._friction import AbstractFriction
from ._physics import AbstractPhysics, LoadRates, Loads, Scalars


class _NoContact(AbstractFriction):
    """No ground contact: no friction, and a negative static limit, so that the body never sticks."""

    one: Array

    def static_limits(self) -> tuple[Array, Array]:
        limit = -self.one
        return limit, limit

    def kinetic(self, speed: Array, direction: Array) -> Array:
        return jnp.zeros_like(speed)

    def kinetic_rate(self, speed: Array, direction: Array, speed_rate: Array) -> None:
        return None

    def smoothed(self, v: Array, eps: Array, v_s: Array) -> Array:
        """No friction in the smoothed dynamics either (the static bump of the default law would
        turn the negative static limit into a force along the motion)."""
        return jnp.zeros_like(v)


class Drive(NamedTuple):
    """The actuation at one phase: per spring its rest length and rates, per internal force and
    per external force its value and rates (`None` rates: zero)."""

    l0: Scalars
    dl0: tuple[Array | None, ...]
    ddl0: tuple[Array | None, ...]
    f: Scalars
    df: tuple[Array | None, ...]
    ddf: tuple[Array | None, ...]
    g: Scalars
    dg: tuple[Array | None, ...]
    ddg: tuple[Array | None, ...]
    r: Scalars = ()  # per tilted spring: its rest length and rates
    dr: tuple[Array | None, ...] = ()
    ddr: tuple[Array | None, ...] = ()


class SpringState(NamedTuple):
    """Per spring: its extension $u = x_b - x_a$ and force `tension` $= k(u - r)$; `tilt`: the
    tilted springs (`_chain_physics.Springs`; `None` where there are none)."""

    u: Scalars
    tension: Scalars
    tilt: Springs | None = None


class TiltRates(NamedTuple):
    """The rates of the linear springs' extensions `du` and the tilted springs' (`tilt_du`, their
    `SpringRates`, and under `contact="hop"` the vertical offsets' rates `dh`)."""

    du: Scalars
    tilt_du: Scalars = ()
    tilt: SpringRates | None = None
    dh: Scalars | None = None


class TiltGeometry(NamedTuple):
    """Per tilted spring: stiffness, vertical offset and its square (`_chain_physics.SpringGeometry`)."""

    k: Scalars
    d: Scalars
    dd: Scalars


def _pos(x: Scalars, end: "int | str", like: Array) -> Array:
    return jnp.zeros_like(like) if end == WALL else x[int(end)]


def _add(terms: list[list[Array]], end: "int | str", value: Array | None, sign: float) -> None:
    if end != WALL and value is not None:
        terms[int(end)].append(value if sign > 0 else -value)


def _sum(terms: list[Array], like: Array) -> Array:
    return sum(terms[1:], terms[0]) if terms else jnp.zeros_like(like)


def _rate(x: Array | None, like: Array) -> Array:
    return jnp.zeros_like(like) if x is None else x


class MechanismPhysics(AbstractPhysics):
    """The [`AbstractPhysics`][locomotion_jax.AbstractPhysics] of one [`Mechanism`][locomotion_jax.Mechanism]
    (module docstring): what the exact engine integrates it with. `loads(...).aux` is a [`SpringState`][]."""

    m: Scalars
    im: Scalars
    c: Scalars
    friction: tuple[AbstractFriction, ...]
    mu_f: Scalars
    mu_b: tuple[Array | None, ...]
    omega: Array
    one: Array
    normal: Scalars  # the constant normal loads N_i (1 for a body without contact)
    x0: Scalars
    v0: Scalars
    y0: Scalars
    w0: Scalars
    restitution: Scalars
    zeno_speed: Array
    inv_mass: Array
    springs: tuple[Spring, ...]
    forces: tuple[Force, ...]
    externals: tuple[ExternalForce, ...]
    ground: tuple[int, ...] = eqx.field(static=True)  # per body, the body that finally carries it
    dampers: tuple[Damper, ...] = ()  # between two bodies (one to a wall is in `c`)
    tilted: tuple[TiltedSpring, ...] = ()

    @property
    def anchored(self) -> bool:
        """Whether a spring, linear or tilted, ties a body to the wall."""
        return any(WALL in (s.a, s.b) for s in (*self.springs, *self.tilted))

    def contact_values(self, q: tuple[Any, ...], fill: Any) -> tuple[Any, ...]:
        """The entries of the bodies with a friction law of their own: a body without ground contact has
        the placeholder load 1 (module docstring), and its entry is left out."""
        return tuple(v for v, touches in zip(q, self._touches()) if touches)

    def _touches(self) -> list[bool]:
        """Per body, whether it has ground contact (a friction law of its own)."""
        return [not isinstance(law, _NoContact) for law in self.friction]

    def drive(self, c1: Array, s1: Array) -> Drive:
        at = lambda s: signal_at(s, c1, s1)
        sp = [at(s.rest) for s in self.springs]
        fo = [at(f.waveform) for f in self.forces]
        ex = [at(g.waveform) for g in self.externals]
        ti = [at(s.rest) for s in self.tilted]
        col = lambda q, k: tuple(p[k] for p in q)
        return Drive(col(sp, 0), col(sp, 1), col(sp, 2), col(fo, 0), col(fo, 1), col(fo, 2),
                     col(ex, 0), col(ex, 1), col(ex, 2), col(ti, 0), col(ti, 1), col(ti, 2))  # fmt: skip

    def _geometry(self) -> TiltGeometry:
        d = tuple(s.d for s in self.tilted)
        return TiltGeometry(tuple(s.k for s in self.tilted), d, tuple(q * q for q in d))

    def _ends(self, q: Scalars) -> Scalars:
        """$q_b - q_a$ per tilted spring ($q = 0$ at a wall)."""
        return tuple(_pos(q, s.b, q[0]) - _pos(q, s.a, q[0]) for s in self.tilted)

    def gaps(self, x: Scalars) -> Scalars:
        """A flat tilted spring's extension $u = x_b - x_a$: with $d = 0$ it is a spring of length
        $|u|$, whose force turns over where its ends meet (a kink no step resolves), so its ends
        must not meet, as a chain's neighbours must not (SPEC §8); a tilted one ($d \\ne 0$) passes
        $u = 0$ smoothly and has no gap (infinite)."""
        return tuple(jnp.where(s.d == 0, u, jnp.inf) for s, u in zip(self.tilted, self._ends(x)))

    def kinks(self, x: Scalars, y: Scalars | None = None) -> tuple[tuple[Array, Array], ...]:
        """Each tilted spring's extension $u$ and vertical offset $h$ ($d$, or $d + y_b - y_a$
        under `contact="hop"`): its force turns over within $|u| \\lesssim |h|$."""
        h = tuple(s.d for s in self.tilted) if y is None else tuple(s.d + q for s, q in zip(self.tilted, self._ends(y)))
        return tuple(zip(self._ends(x), h))

    def _tilt_terms(self, F: Scalars, N: Scalars, fx: Scalars, fy: Scalars) -> tuple[Scalars, Scalars]:
        """`F` plus the tilted springs' horizontal forces `fx` ($+$ on `a`), `N` minus their vertical
        forces `fy` ($+$ on `a`), each body's share on the body in contact that carries it."""
        terms: list[list[Array]] = [[q] for q in F]
        lift: list[list[Array]] = [[] for _ in self.m]
        contact = self._touches()
        for s, a, b in zip(self.tilted, fx, fy):
            _add(terms, s.a, a, 1.0)
            _add(terms, s.b, a, -1.0)
            for end, sign in ((s.a, 1.0), (s.b, -1.0)):
                if end != WALL and contact[self.ground[int(end)]]:
                    _add(lift, self.ground[int(end)], b, sign)
        N = tuple(n if not t else n - _sum(t, n) for n, t in zip(N, lift))
        return tuple(_sum(t, t[0]) for t in terms), N

    def _forces(self, u: Scalars, r: tuple, f: tuple, g: tuple, like: Array) -> Scalars:
        """$F_i$ (or a rate of it) from the springs' `k (u - r)`, the forces `f` and the external `g`."""
        terms: list[list[Array]] = [[] for _ in self.m]
        for s, uj, rj in zip(self.springs, u, r):
            T = s.k * (uj if rj is None else uj - rj)
            _add(terms, s.a, T, 1.0)
            _add(terms, s.b, T, -1.0)
        for el, fj in zip(self.forces, f):
            _add(terms, el.b, fj, 1.0)
            _add(terms, el.a, fj, -1.0)
        for el, gj in zip(self.externals, g):
            _add(terms, el.i, gj, 1.0)
        return tuple(_sum(t, like) for t in terms)

    def _u(self, x: Scalars) -> Scalars:
        return tuple(_pos(x, s.b, x[0]) - _pos(x, s.a, x[0]) for s in self.springs)

    def loads(self, drive: Drive, x: Scalars, keep: Any = None, y: Scalars | None = None) -> Loads:
        u = self._u(x)
        tension = tuple(s.k * (uj - r) for s, uj, r in zip(self.springs, u, drive.l0))
        F = self._forces(u, drive.l0, drive.f, drive.g, x[0])
        if not self.tilted:
            return Loads(F, self.normal, SpringState(u, tension))
        geo = self._geometry()
        h = None if y is None else tuple(d + q for d, q in zip(geo.d, self._ends(y)))
        sp = tilted(geo, drive.r, self._ends(x), h)
        F, N = self._tilt_terms(F, self.normal, sp.fx, sp.fy)
        return Loads(F, N, SpringState(u, tension, sp))

    def load_rates(
        self, drive: Drive, loads: Loads, xd: Scalars, keep: Any = None, yd: Scalars | None = None
    ) -> LoadRates:
        du = self._u(xd)
        dF = self._forces(du, drive.dl0, drive.df, drive.dg, xd[0])
        zero = tuple(jnp.zeros_like(q) for q in dF)
        sp = loads.aux.tilt
        if sp is None:
            return LoadRates(dF, zero, TiltRates(du))
        tdu = self._ends(xd)
        dh = None if yd is None or sp.h is None else self._ends(yd)
        sr = spring_rates(self._geometry(), sp, tdu, self._rates(drive.dr, tdu), dh)
        dF, dN = self._tilt_terms(dF, zero, sr.dfx, sr.dfy)
        return LoadRates(dF, dN, TiltRates(du, tdu, sr, dh))

    @staticmethod
    def _rates(rates: tuple[Array | None, ...], like: Scalars) -> Scalars:
        """Rates of the tilted springs' rest lengths, zero for a constant one."""
        return tuple(_rate(r, q) for r, q in zip(rates, like))

    def load_second(
        self,
        drive: Drive,
        loads: Loads,
        rates: LoadRates,
        xd: Scalars,
        a: Scalars,
        yd: Scalars | None = None,
        ya: Scalars | None = None,
    ) -> tuple[Scalars, Scalars]:
        ddF = self._forces(self._u(a), drive.ddl0, drive.ddf, drive.ddg, a[0])
        zero = tuple(jnp.zeros_like(q) for q in ddF)
        sp, tr = loads.aux.tilt, rates.aux
        if sp is None or tr.tilt is None:
            return ddF, zero
        ddu = self._ends(a)
        ddh = None if tr.dh is None or ya is None else self._ends(ya)
        ddfx, ddfy = spring_second(self._geometry(), sp, tr.tilt, tr.tilt_du, ddu, self._rates(drive.ddr, ddu),
                                   tr.dh, ddh)  # fmt: skip
        return self._tilt_terms(ddF, zero, ddfx, ddfy)

    def power(self, drive: Drive, loads: Loads, v: Scalars) -> Array:
        """The power put in (SPEC §9): $\\dot w = \\sum_\\text{springs} -f\\,\\dot r$
        $+ \\sum_\\text{forces} f\\,(v_b - v_a) + \\sum_i g_i v_i$."""
        like = v[0]
        terms = [-(T * dr) for T, dr in zip(loads.aux.tension, drive.dl0) if dr is not None]
        if loads.aux.tilt is not None:
            terms += [-(T * dr) for T, dr in zip(loads.aux.tilt.tension, drive.dr) if dr is not None]
        terms += [f * (_pos(v, e.b, like) - _pos(v, e.a, like)) for e, f in zip(self.forces, drive.f)]
        terms += [g * v[e.i] for e, g in zip(self.externals, drive.g)]
        return _sum(terms, like)

    def power_rate(self, drive: Drive, loads: Loads, rates: LoadRates, v: Scalars, a: Scalars) -> Array:
        like = v[0]
        terms = []
        for s, T, du, dr, ddr in zip(self.springs, loads.aux.tension, rates.aux.du, drive.dl0, drive.ddl0):
            if dr is not None:
                dT = s.k * (du - dr)
                terms.append(-(dT * dr + T * _rate(ddr, like)))
        sp, tr = loads.aux.tilt, rates.aux.tilt
        if sp is not None and tr is not None:
            for T, dT, dr, ddr in zip(sp.tension, tr.dtension, drive.dr, drive.ddr):
                if dr is not None:
                    terms.append(-(dT * dr + T * _rate(ddr, like)))
        for e, f, df in zip(self.forces, drive.f, drive.df):
            dv = _pos(v, e.b, like) - _pos(v, e.a, like)
            terms.append(_rate(df, like) * dv + f * (_pos(a, e.b, like) - _pos(a, e.a, like)))
        for e, g, dg in zip(self.externals, drive.g, drive.dg):
            terms.append(_rate(dg, like) * v[e.i] + g * a[e.i])
        return _sum(terms, like)

    def velocity_forces(self, v: Scalars) -> Scalars | None:
        """The relative dampers' forces $f = c(v_b - v_a)$, $+f$ on `a` and $-f$ on `b` (SPEC §9)."""
        if not self.dampers:
            return None
        terms: list[list[Array]] = [[] for _ in self.m]
        for d in self.dampers:
            f = d.c * (v[int(d.b)] - v[int(d.a)])
            _add(terms, d.a, f, 1.0)
            _add(terms, d.b, f, -1.0)
        return tuple(_sum(t, v[0]) for t in terms)

    def velocity_power(self, v: Scalars, u: Scalars) -> Array | None:
        """$\\sum c\\,(v_b - v_a)(u_b - u_a)$ over the relative dampers: their dissipation at `u = v`."""
        if not self.dampers:
            return None
        return _sum([d.c * (v[int(d.b)] - v[int(d.a)]) * (u[int(d.b)] - u[int(d.a)]) for d in self.dampers], v[0])

    def energy(self, loads: Loads, v: Scalars) -> Array:
        """$e = \\sum_i m_i v_i^2/2 + \\sum_\\text{springs} f^2/(2k)$ (SPEC §9; a tilted spring's $T^2/(2k)$)."""
        kin = [m * q * q for m, q in zip(self.m, v)]
        pot = [T * T / s.k for s, T in zip(self.springs, loads.aux.tension)]
        if loads.aux.tilt is not None:
            pot += [T * T / s.k for s, T in zip(self.tilted, loads.aux.tilt.tension)]
        return 0.5 * _sum(kin + pot, v[0])

    def centre_of_mass(self, x: Scalars) -> Array:
        return _sum([m * q for m, q in zip(self.m, x)], x[0]) * self.inv_mass

    def initial_positions(self, start: str) -> Array:
        """The mechanism's own `x0` (whatever the named start)."""
        return jnp.stack(self.x0, -1)

    def initial_velocities(self, start: str) -> Array | None:
        return jnp.stack(self.v0, -1)

    def hop(self) -> tuple[Array, Array, Scalars, Array]:
        """Under `contact="hop"` the linear springs and the forces stay horizontal; the tilted springs
        act along $(u, d + y_b - y_a)$ (the heights `y` that `loads` and the rates take). Without
        a tilted spring no vertical force acts on a body, so a body in flight falls freely and one
        on the ground never lifts off by itself (it flies from its `y0`, `w0` or a rebound); a
        tilted spring's pull can lift a body as a chain's does. A carried body rides in the body
        that finally carries it: its height, vertical velocity and restitution are that body's
        (`mechanism_physics`), so that it flies, falls and lands with it."""
        return jnp.stack(self.y0, -1), jnp.stack(self.w0, -1), self.restitution, self.zeno_speed

    def fall(self, N: Scalars) -> Scalars:
        """The vertical acceleration in flight, $\\dot w_i = -N_g / M_g$: the ground body's load (its
        weight and its carried bodies', less the tilted springs' vertical forces on them) over the
        mass that flies with it, one expression for a body and those it carries, so that they fall
        alike to the last bit (free fall, $-1$, without a tilted spring). Linear in `N`, so also
        the rate of that acceleration from the loads' rates."""
        return self.ride(tuple(-q / M for q, M in zip(N, self.landing_masses())))

    def ride(self, q: Scalars) -> Scalars:
        """A carried body flies with the body that finally carries it: that body's entry (a body in
        contact, or a free one, its own), so that the springs that lift a capsule lift what it
        carries, and a gait's section state moves them together."""
        return tuple(q[g] for g in self.ground)

    def landing_masses(self) -> Scalars:
        """A body in contact lands with the bodies it carries: $M_i = N_i$, its mass and theirs; a
        body without contact (its load the placeholder 1) lands alone, $M_i = 1$ (it feels no
        tangential impulse)."""
        return self.normal


def ground_body(carried_by: tuple[int | None, ...], i: int) -> int:
    """The body in contact that finally carries body `i` (`i` itself if it is not carried)."""
    seen = {i}
    while carried_by[i] is not None:
        i = int(carried_by[i])  # type: ignore[arg-type]
        if i in seen:
            raise ValueError(f"carried_by: bodies {sorted(seen)} carry each other in a loop.")
        seen.add(i)
    return i


def normal_loads(M: Any) -> list[Array]:
    """Per body, its constant normal load: its weight and the weights of the bodies it carries (directly
    or through others) for a body in contact, the placeholder 1 for one without (module docstring)."""
    m = [M.m[..., i] for i in range(M.m.shape[-1])]
    one = m[0] / m[0]
    contact = [law is not None for law in M.friction]
    normal = [mi if c else one for mi, c in zip(m, contact)]
    for i, j in enumerate(M.carried_by):
        if j is not None:
            g = ground_body(M.carried_by, i)
            if contact[g]:
                normal[g] = normal[g] + m[i]
    return normal


def contact_laws(M: Any, one: Array) -> tuple[AbstractFriction, ...]:
    """Per body, its friction law, or for a body without ground contact the law of no friction."""
    return tuple(law if law is not None else _NoContact(one) for law in M.friction)


def ground_damping(M: Any) -> list[Array]:
    """Per body, its ground damping $c_i$ plus that of the dampers joining it to a wall (a damper
    between two bodies is `velocity_forces`')."""
    c = [M.c[..., i] for i in range(M.m.shape[-1])]
    for el in M.links:
        if isinstance(el, Damper) and WALL in (el.a, el.b):
            i = int(el.b if el.a == WALL else el.a)
            c[i] = c[i] + el.c
    return c


def mechanism_physics(M: Any) -> MechanismPhysics:
    """The physics of a [`Mechanism`][locomotion_jax.Mechanism] (one configuration or a flat batch)."""
    n = M.m.shape[-1]
    m = tuple(M.m[..., i] for i in range(n))
    one = m[0] / m[0]
    normal = normal_loads(M)
    c = ground_damping(M)
    friction = contact_laws(M, one)
    limits = [law.static_limits() for law in friction]
    limits = [(f, None if b is f else b) for f, b in limits]
    waves = M.waveforms()
    omega = jnp.broadcast_to(waves[0].omega, one.shape).astype(one.dtype) if waves else jnp.zeros_like(one)
    links = M.links
    ground = tuple(ground_body(M.carried_by, i) for i in range(n))
    # A carried body rides in its ground body: under "hop" its vertical state and restitution are that body's.
    ride = lambda q: tuple(q[..., g] for g in ground)
    return MechanismPhysics(
        m=m, im=tuple(1 / q for q in m), c=tuple(c), friction=friction,
        mu_f=tuple(f for f, _ in limits), mu_b=tuple(b for _, b in limits), omega=omega, one=one,
        normal=tuple(normal), x0=tuple(M.x0[..., i] for i in range(n)), v0=tuple(M.v0[..., i] for i in range(n)),
        y0=ride(M.y0), w0=ride(M.w0), restitution=ride(M.restitution), ground=ground,
        zeno_speed=jnp.broadcast_to(M.zeno_speed, one.shape).astype(one.dtype),
        inv_mass=1 / M.m.sum(-1),
        springs=tuple(e for e in links if isinstance(e, Spring)),
        tilted=tuple(e for e in links if isinstance(e, TiltedSpring)),
        forces=tuple(e for e in links if isinstance(e, Force)),
        externals=tuple(e for e in links if isinstance(e, ExternalForce)),
        dampers=tuple(e for e in links if isinstance(e, Damper) and WALL not in (e.a, e.b)),
    )  # fmt: skip
