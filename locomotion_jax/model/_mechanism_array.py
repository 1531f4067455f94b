"""A [`Mechanism`][locomotion_jax.Mechanism]'s physics in the array layout: the bodies one entry over
all N, the elements arrays over the elements, so that a mechanism of 64 bodies is a program of the
size of one of 4.

The same forces as [`MechanismPhysics`][locomotion_jax.model._mechanism_physics.MechanismPhysics]
(SPEC §9, §10), term by term, with the sums over elements gathered instead of unrolled:

- an element's ends are static indices into the positions with a zero appended for the wall, so
  its extension $u = x_b - x_a$ (a tilted spring's too) is one gather over the elements;
- every signal (springs' and tilted springs' rest lengths, internal and external forces) is one
  row of a table of Fourier coefficients, padded to the most harmonics (a constant: none), read by
  the angle-addition recurrence at the engine's phase;
- a body's load $F_i$ is the signed sum of the element forces that act on it: a gather of the
  element forces by a static table of (element, sign) per body, padded with a zero force, and its
  normal load $N_i$ (its weight and its carried bodies', `_mechanism_physics.normal_loads`) less
  the tilted springs' vertical forces on it and on the bodies it carries likewise;
- the bodies' friction laws are one law over the entry: the laws' own class stacked over the bodies
  where they are of one class, else a [`MixedFriction`][locomotion_jax.model._friction.MixedFriction]
  whose members are the classes (the law of no friction of a carried or free body one of them);
- a carried body rides in the body that finally carries it (its height, vertical velocity, fall
  and landing are that body's): a static gather of the entries, as the unrolled physics selects them.

The signals driven by other waveforms (splines, a waveform class of the user's own) are rows of a
`_bank.WaveBank` (one evaluation per class and shape), added to the coefficients' rows, which are
zero there; the unrolled physics reads each waveform on its own. Sums over bodies and elements are
summed in another order than the unrolled physics', so the two agree to rounding.
"""

from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array
from ._bank import wave_bank, WaveBank
from ._chain_physics import spring_rates, spring_second, Springs, tilted
from ._elements import Damper, ExternalForce, Force, Spring, TiltedSpring, WALL
from ._friction import AbstractFriction, MixedFriction
from ._mechanism_physics import (
    contact_laws,
    ground_body,
    ground_damping,
    normal_loads,
    SpringState,
    TiltGeometry,
    TiltRates,
)
from ._physics import AbstractArrayPhysics, LoadRates, Loads, Scalars
from ._waveform import AbstractWaveform, Fourier, Sinusoid


class Table(NamedTuple):
    """Per body, the elements whose forces act on it (`elements`: indices into the element forces with
    a zero appended, padded with that zero) and their `signs`, both `(N, K)` nested tuples (static)."""

    elements: tuple[tuple[int, ...], ...]
    signs: tuple[tuple[float, ...], ...]


def _table(n: int, size: int, terms: list[tuple[int, int, float]]) -> Table:
    """The [`Table`][] of `terms` `(body, element, sign)` over `size` element forces (index `size`:
    the appended zero)."""
    rows: list[list[tuple[int, float]]] = [[] for _ in range(n)]
    for body, element, sign in terms:
        rows[body].append((element, sign))
    width = max([len(r) for r in rows] + [1])
    pad = lambda r: r + [(size, 0.0)] * (width - len(r))
    return Table(tuple(tuple(e for e, _ in pad(r)) for r in rows), tuple(tuple(s for _, s in pad(r)) for r in rows))


def _gather(table: Table, forces: Array) -> Array:
    """Per body, the signed sum of the element `forces` in its row of `table`."""
    ext = jnp.concatenate([forces, jnp.zeros_like(forces[..., :1])], -1)
    signs = np.asarray(table.signs, np.float64).astype(forces.dtype)
    return jnp.sum(ext[..., np.asarray(table.elements, np.int32)] * signs, -1)


def _end(i: "int | str", n: int) -> int:
    return n if i == WALL else int(i)


def _ends(x: Array, a: tuple[int, ...], b: tuple[int, ...]) -> Array:
    """$x_b - x_a$ per element ($x = 0$ at the wall, index N)."""
    ext = jnp.concatenate([x, jnp.zeros_like(x[..., :1])], -1)
    return ext[..., np.asarray(b, np.int32)] - ext[..., np.asarray(a, np.int32)]


class Drive(NamedTuple):
    """The actuation at one phase, one array over the elements of each kind with its first two rates:
    the springs' rest lengths `l0`, the tilted springs' `r`, the internal forces `f`, the external
    ones `g`. The per-kind fields are 1-tuples (the engine's entries)."""

    l0: Scalars
    dl0: Scalars
    ddl0: Scalars
    r: Array
    dr: Array
    ddr: Array
    f: Array
    df: Array
    ddf: Array
    g: Array
    dg: Array
    ddg: Array


class ArrayMechanismPhysics(AbstractArrayPhysics):
    """The physics of one mechanism in the array layout (module docstring). The interface's per-body
    tuples have one entry each, over all bodies; the elements' fields are arrays over the elements of
    each kind; their ends and the bodies' [`Table`][]s are static."""

    m: Scalars
    im: Scalars
    c: Scalars
    friction: tuple[AbstractFriction, ...]
    mu_f: Scalars
    mu_b: tuple[Array | None, ...]
    omega: Array
    one: Array
    normal: Array  # the constant normal loads N_i (1 for a body without contact)
    x0: Array
    v0: Array
    y0: Array
    w0: Array
    restitution: Array
    zeno_speed: Array
    inv_mass: Array
    k: Array  # the linear springs'
    tilt: TiltGeometry  # the tilted springs' stiffness, offset and its square (1-tuples of arrays)
    damping: Array  # the relative dampers' c
    lbar: Array  # the signals (means): springs, tilted springs, forces, external forces
    cos: Array
    sin: Array
    nw: Array
    nw2: Array
    # The signals driven by waveforms other than sinusoids and Fourier series (`_bank`), added to
    # the coefficients' (zero in their rows); `None`: there are none.
    bank: WaveBank | None
    kinds: tuple[int, int, int, int] = eqx.field(static=True)  # signals per kind, in the order of `lbar`
    spring_ends: tuple[tuple[int, ...], tuple[int, ...]] = eqx.field(static=True)
    tilt_ends: tuple[tuple[int, ...], tuple[int, ...]] = eqx.field(static=True)
    force_ends: tuple[tuple[int, ...], tuple[int, ...]] = eqx.field(static=True)
    external_body: tuple[int, ...] = eqx.field(static=True)
    damper_ends: tuple[tuple[int, ...], tuple[int, ...]] = eqx.field(static=True)
    horizontal: Table = eqx.field(static=True)  # over (spring tensions, tilted fx, forces, externals)
    vertical: Table = eqx.field(static=True)  # over the tilted springs' fy
    dampers: Table = eqx.field(static=True)  # over the relative dampers' forces
    anchor: bool = eqx.field(static=True)
    ground: tuple[int, ...] = eqx.field(static=True)  # per body, the body that finally carries it
    contact: tuple[bool, ...] = eqx.field(static=True)  # per body, whether it touches the ground

    @property
    def anchored(self) -> bool:
        """Whether a spring, linear or tilted, ties a body to the wall."""
        return self.anchor

    def drive(self, c1: Array, s1: Array) -> Drive:
        """Every signal with its first two rates (the harmonics by the angle-addition recurrence,
        the other waveforms' from their bank), split by kind."""
        A, B = self.cos, self.sin
        val, rate, acc = self.lbar + 0 * c1, jnp.zeros_like(self.lbar), jnp.zeros_like(self.lbar)
        cn, sn = c1, s1
        for h in range(A.shape[-1]):
            if h > 0:
                cn, sn = cn * c1 - sn * s1, sn * c1 + cn * s1
            vn = A[..., h] * cn + B[..., h] * sn
            val = (val + A[..., h] * cn) + B[..., h] * sn  # the unrolled `Fourier.at_phase`'s order
            rate = rate + self.nw[..., h] * (B[..., h] * cn - A[..., h] * sn)
            acc = acc - self.nw2[..., h] * vn
        if self.bank is not None:
            val, rate, acc = self.bank.at_phase(c1, s1, (val, rate, acc))
        return self._split(val, rate, acc)

    def _split(self, val: Array, rate: Array, acc: Array) -> Drive:
        S, T, F, _ = self.kinds
        cut = lambda q: (q[..., :S], q[..., S : S + T], q[..., S + T : S + T + F], q[..., S + T + F :])
        (l0, r, f, g), (dl0, dr, df, dg), (ddl0, ddr, ddf, ddg) = cut(val), cut(rate), cut(acc)
        return Drive((l0,), (dl0,), (ddl0,), r, dr, ddr, f, df, ddf, g, dg, ddg)

    def _horizontal(self, spring: Array, fx: Array | None, f: Array, g: Array) -> Array:
        """$F_i$ (or a rate of it) from the springs' `spring` forces ($+$ on `a`), the tilted springs'
        `fx` ($+$ on `a`), the internal forces `f` ($+$ on `b`) and the external `g`."""
        parts = [spring] + ([] if fx is None else [fx]) + [f, g]
        return _gather(self.horizontal, jnp.concatenate(parts, -1))

    def gaps(self, x: Scalars) -> Scalars:
        """As the unrolled physics', one entry over the tilted springs: a flat one's extension
        $u = x_b - x_a$ (its ends must not meet), a tilted one's infinite."""
        if not self.kinds[1]:
            return ()
        return (jnp.where(self.tilt.d[0] == 0, _ends(x[0], *self.tilt_ends), jnp.inf),)

    def kinks(self, x: Scalars, y: Scalars | None = None) -> tuple[tuple[Array, Array], ...]:
        """As the unrolled physics', one entry over the tilted springs."""
        if not self.kinds[1]:
            return ()
        d = self.tilt.d[0]
        return ((_ends(x[0], *self.tilt_ends), d if y is None else d + _ends(y[0], *self.tilt_ends)),)

    def _tilted(self, drive: Drive, x: Array, y: Array | None) -> Springs | None:
        if not self.kinds[1]:
            return None
        a, b = self.tilt_ends
        h = None if y is None else (self.tilt.d[0] + _ends(y, a, b),)
        return tilted(self.tilt, (drive.r,), (_ends(x, a, b),), h)

    def loads(self, drive: Drive, x: Scalars, keep: Any = None, y: Scalars | None = None) -> Loads:
        (xa,) = x
        u = _ends(xa, *self.spring_ends)
        tension = self.k * (u - drive.l0[0])
        sp = self._tilted(drive, xa, None if y is None else y[0])
        F = self._horizontal(tension, None if sp is None else sp.fx[0], drive.f, drive.g)
        N = self.normal if sp is None else self.normal - _gather(self.vertical, sp.fy[0])
        return Loads((F,), (N,), SpringState((u,), (tension,), sp))

    def load_rates(
        self, drive: Drive, loads: Loads, xd: Scalars, keep: Any = None, yd: Scalars | None = None
    ) -> LoadRates:
        (v,) = xd
        du = _ends(v, *self.spring_ends)
        sp = loads.aux.tilt
        if sp is None:
            dF = self._horizontal(self.k * (du - drive.dl0[0]), None, drive.df, drive.dg)
            return LoadRates((dF,), (jnp.zeros_like(dF),), TiltRates((du,)))
        tdu = _ends(v, *self.tilt_ends)
        dh = None if yd is None or sp.h is None else (_ends(yd[0], *self.tilt_ends),)
        sr = spring_rates(self.tilt, sp, (tdu,), (drive.dr,), dh)
        dF = self._horizontal(self.k * (du - drive.dl0[0]), sr.dfx[0], drive.df, drive.dg)
        dN = -_gather(self.vertical, sr.dfy[0])
        return LoadRates((dF,), (dN,), TiltRates((du,), (tdu,), sr, dh))

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
        spring = self.k * (_ends(a[0], *self.spring_ends) - drive.ddl0[0])
        sp, tr = loads.aux.tilt, rates.aux
        if sp is None or tr.tilt is None:
            ddF = self._horizontal(spring, None, drive.ddf, drive.ddg)
            return (ddF,), (jnp.zeros_like(ddF),)
        ddu = (_ends(a[0], *self.tilt_ends),)
        ddh = None if tr.dh is None or ya is None else (_ends(ya[0], *self.tilt_ends),)
        ddfx, ddfy = spring_second(self.tilt, sp, tr.tilt, tr.tilt_du, ddu, (drive.ddr,), tr.dh, ddh)
        return (self._horizontal(spring, ddfx[0], drive.ddf, drive.ddg),), (-_gather(self.vertical, ddfy[0]),)

    def power(self, drive: Drive, loads: Loads, v: Scalars) -> Array:
        """The power put in (SPEC §9): $\\dot w = \\sum_\\text{springs} -f\\,\\dot r$
        $+ \\sum_\\text{forces} f\\,(v_b - v_a) + \\sum_i g_i v_i$."""
        (va,) = v
        out = -jnp.sum(loads.aux.tension[0] * drive.dl0[0], -1)
        if loads.aux.tilt is not None:
            out = out - jnp.sum(loads.aux.tilt.tension[0] * drive.dr, -1)
        out = out + jnp.sum(drive.f * _ends(va, *self.force_ends), -1)
        return out + jnp.sum(drive.g * va[..., np.asarray(self.external_body, np.int32)], -1)

    def power_rate(self, drive: Drive, loads: Loads, rates: LoadRates, v: Scalars, a: Scalars) -> Array:
        (va,), (aa,) = v, a
        T, dl0, ddl0 = loads.aux.tension[0], drive.dl0[0], drive.ddl0[0]
        dT = self.k * (rates.aux.du[0] - dl0)
        out = -jnp.sum(dT * dl0 + T * ddl0, -1)
        sp, tr = loads.aux.tilt, rates.aux.tilt
        if sp is not None and tr is not None:
            out = out - jnp.sum(tr.dtension[0] * drive.dr + sp.tension[0] * drive.ddr, -1)
        out = out + jnp.sum(drive.df * _ends(va, *self.force_ends) + drive.f * _ends(aa, *self.force_ends), -1)
        at = np.asarray(self.external_body, np.int32)
        return out + jnp.sum(drive.dg * va[..., at] + drive.g * aa[..., at], -1)

    def velocity_forces(self, v: Scalars) -> Scalars | None:
        """The relative dampers' forces $f = c(v_b - v_a)$, $+f$ on `a` and $-f$ on `b` (SPEC §9)."""
        if not self.damper_ends[0]:
            return None
        return (_gather(self.dampers, self.damping * _ends(v[0], *self.damper_ends)),)

    def velocity_power(self, v: Scalars, u: Scalars) -> Array | None:
        """$\\sum c\\,(v_b - v_a)(u_b - u_a)$ over the relative dampers: their dissipation at `u = v`."""
        if not self.damper_ends[0]:
            return None
        return jnp.sum(self.damping * _ends(v[0], *self.damper_ends) * _ends(u[0], *self.damper_ends), -1)

    def energy(self, loads: Loads, v: Scalars) -> Array:
        """$e = \\sum_i m_i v_i^2/2 + \\sum_\\text{springs} f^2/(2k)$ (SPEC §9; a tilted spring's $T^2/(2k)$)."""
        T = loads.aux.tension[0]
        out = jnp.sum(self.m[0] * v[0] * v[0], -1) + jnp.sum(T * T / self.k, -1)
        if loads.aux.tilt is not None:
            Tt = loads.aux.tilt.tension[0]
            out = out + jnp.sum(Tt * Tt / self.tilt.k[0], -1)
        return 0.5 * out

    def centre_of_mass(self, x: Scalars) -> Array:
        return jnp.sum(self.m[0] * x[0], -1) * self.inv_mass

    def initial_positions(self, start: str) -> Array:
        """The mechanism's own `x0` (whatever the named start)."""
        return self.x0

    def initial_velocities(self, start: str) -> Array | None:
        return self.v0

    def contact_values(self, q: tuple[Any, ...], fill: Any) -> tuple[Any, ...]:
        """`q` with `fill` in place of the bodies without ground contact (their loads are the
        placeholder 1)."""
        if all(self.contact):
            return q
        return tuple(jnp.where(np.asarray(self.contact), v, fill) for v in q)

    def hop(self) -> tuple[Array, Array, Scalars, Array]:
        """As the unrolled physics (SPEC §10): per body, the initial height, vertical velocity and
        restitution of the body it rides in (its own where it is not carried; `array_physics` selects
        them)."""
        return self.y0, self.w0, (self.restitution,), self.zeno_speed

    def fall(self, N: Scalars) -> Scalars:
        """The vertical acceleration in flight, $\\dot w_i = -N_g/M_g$ of the body $g$ that body $i$ rides
        in, as the unrolled physics divides."""
        return self.ride((-N[0] / self.normal,))

    def ride(self, q: Scalars) -> Scalars:
        """Per body, the entry of the body that finally carries it (its own where it is not carried)."""
        if self.ground == tuple(range(len(self.ground))):
            return q
        return (q[0][..., np.asarray(self.ground, np.int32)],)

    def landing_masses(self) -> Scalars:
        """A body in contact lands with the bodies it carries, $M_i = N_i$; one without contact alone."""
        return (self.normal,)


def _fourier(s: Any, like: Array) -> tuple[Array, Array, Array]:
    """A signal's `(lbar, cos, sin)`: a constant's value and no harmonics, a sinusoid's one, zero
    for another waveform (its row of the bank, `_bank`)."""
    if isinstance(s, Fourier):
        return s.lbar, s.cos, s.sin
    if isinstance(s, Sinusoid):
        return s.lbar, jnp.zeros_like(s.a)[..., None], s.a[..., None]
    mean = jnp.zeros((), like.dtype) if isinstance(s, AbstractWaveform) else jnp.asarray(s, like.dtype)
    none = jnp.zeros(jnp.shape(mean) + (0,), like.dtype)
    return mean, none, none


def _friction(laws: tuple[AbstractFriction, ...], batch: tuple[int, ...]) -> AbstractFriction:
    """The bodies' laws as one law over the entry: a law's class stacked over the bodies, or where they
    are of several classes a `MixedFriction` of one member a class (the other bodies' coefficients in
    a member: those of its class's first body)."""
    keys = [jax.tree_util.tree_structure(law) for law in laws]
    kinds = list(dict.fromkeys(keys))
    classes = tuple(kinds.index(k) for k in keys)
    stack = lambda *xs: jnp.stack([jnp.broadcast_to(q, batch) for q in xs], -1)
    members = [jax.tree_util.tree_map(stack, *[law if c == k else laws[classes.index(k)]
                                               for law, c in zip(laws, classes)])  # fmt: skip
               for k in range(len(kinds))]  # fmt: skip
    return members[0] if len(members) == 1 else MixedFriction(tuple(members), classes)


def array_physics(M: Any) -> ArrayMechanismPhysics:
    """The physics of a [`Mechanism`][locomotion_jax.Mechanism] in the array layout (every field
    broadcast to the mechanism's batch shape, with its body or element axis)."""
    M = M.broadcast()
    n, batch = M.n_bodies, M.batch_shape
    links = M.links
    springs = [e for e in links if isinstance(e, Spring)]
    tilts = [e for e in links if isinstance(e, TiltedSpring)]
    forces = [e for e in links if isinstance(e, Force)]
    externals = [e for e in links if isinstance(e, ExternalForce)]
    dampers = [e for e in links if isinstance(e, Damper) and WALL not in (e.a, e.b)]
    ends = lambda els: (tuple(_end(e.a, n) for e in els), tuple(_end(e.b, n) for e in els))
    stack = lambda xs: jnp.stack([jnp.broadcast_to(q, batch) for q in xs], -1) if xs else jnp.zeros(batch + (0,))
    # The signals, in the order springs, tilted springs, forces, externals.
    signals = [e.rest for e in springs] + [e.rest for e in tilts] + [e.waveform for e in forces + externals]
    coefs = [_fourier(s, M.m) for s in signals]
    # Every other waveform is read from its row of the bank of waveforms.
    waves: dict[int, AbstractWaveform] = {j: s for j, s in enumerate(signals) if isinstance(s, AbstractWaveform)
                                          and not isinstance(s, (Fourier, Sinusoid))}  # fmt: skip
    H = max([q[1].shape[-1] for q in coefs] + [0])
    pad = lambda q: jnp.broadcast_to(jnp.pad(q, [(0, 0)] * (q.ndim - 1) + [(0, H - q.shape[-1])]), batch + (H,))
    cos = jnp.stack([pad(c) for _, c, _ in coefs], -2) if coefs else jnp.zeros(batch + (0, H))
    sin = jnp.stack([pad(s) for _, _, s in coefs], -2) if coefs else jnp.zeros(batch + (0, H))
    first = M.waveforms()[:1]
    one = M.m[..., 0] / M.m[..., 0]
    omega = jnp.broadcast_to(first[0].omega, batch).astype(one.dtype) if first else jnp.zeros_like(one)
    nw = jnp.stack([(h + 1) * omega for h in range(H)], -1)[..., None, :] if H else jnp.zeros(batch + (1, 0))
    # The element forces on the bodies: +T on a spring's a, +fx on a tilted spring's a, +f on a force's b.
    S, T, F = len(springs), len(tilts), len(forces)
    terms = []
    for base, els, sign in ((0, springs, 1.0), (S, tilts, 1.0), (S + T, forces, -1.0)):
        for j, e in enumerate(els):
            terms += [(int(e.a), base + j, sign)] if e.a != WALL else []
            terms += [(int(e.b), base + j, -sign)] if e.b != WALL else []
    terms += [(e.i, S + T + F + j, 1.0) for j, e in enumerate(externals)]
    # A tilted spring's vertical force on a body bears on the body in contact that carries it.
    ground = tuple(ground_body(M.carried_by, i) for i in range(n))
    contact = tuple(law is not None for law in M.friction)
    lift = [(ground[int(end)], j, sign) for j, e in enumerate(tilts) for end, sign in ((e.a, 1.0), (e.b, -1.0))
            if end != WALL and contact[ground[int(end)]]]  # fmt: skip
    plain = all(contact) and ground == tuple(range(n))  # no carried or free body: the bodies' own
    ride = lambda q: q if plain else q[..., np.asarray(ground, np.int32)]
    damp = [(int(end), j, sign) for j, e in enumerate(dampers) for end, sign in ((e.a, 1.0), (e.b, -1.0))]
    c = jnp.stack(ground_damping(M), -1)
    law = _friction(contact_laws(M, one), batch)
    f, b = law.static_limits()
    d = stack([e.d for e in tilts])
    dt = one.dtype
    means = stack([q[0] for q in coefs]).astype(dt)
    return ArrayMechanismPhysics(
        m=(M.m,), im=(1 / M.m,), c=(c,), friction=(law,), mu_f=(f,), mu_b=(None if b is f else b,), omega=omega,
        one=one, normal=M.m if plain else jnp.stack(normal_loads(M), -1), x0=M.x0, v0=M.v0, y0=ride(M.y0),
        w0=ride(M.w0), restitution=ride(M.restitution),
        zeno_speed=jnp.broadcast_to(M.zeno_speed, batch).astype(dt), inv_mass=1 / M.m.sum(-1),
        k=stack([e.k for e in springs]).astype(dt), tilt=TiltGeometry((stack([e.k for e in tilts]).astype(dt),),
                                                                       (d.astype(dt),), ((d * d).astype(dt),)),
        damping=stack([e.c for e in dampers]).astype(dt),
        lbar=means, cos=cos.astype(dt), sin=sin.astype(dt),
        bank=wave_bank(waves, len(signals), batch) if waves else None,
        nw=jnp.broadcast_to(nw, cos.shape).astype(dt), nw2=jnp.broadcast_to(nw * nw, cos.shape).astype(dt),
        kinds=(S, T, F, len(externals)), spring_ends=ends(springs), tilt_ends=ends(tilts), force_ends=ends(forces),
        external_body=tuple(e.i for e in externals), damper_ends=ends(dampers),
        horizontal=_table(n, S + T + F + len(externals), terms), vertical=_table(n, T, lift),
        dampers=_table(n, len(dampers), damp),
        anchor=any(WALL in (e.a, e.b) for e in springs + tilts), ground=ground, contact=contact,
    )  # fmt: skip
