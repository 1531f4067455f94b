"""The physics of a chain of N masses (SPEC §8): [`ChainPhysics`][], the chain's [`AbstractPhysics`][].

Written over Python tuples of scalars, one entry per mass or per spring (the chain's N is
static), not over arrays with a mass axis: under `vmap` every intermediate is then a
vector over the configurations only, which is what XLA's CPU backend runs fastest (a
kernel over a `(lanes, N)` array is split over the intra-op thread pool and costs several
times more; benchmarks/NOTES.md).

Spring $j$ joins masses $j$ and $j+1$: $u_j = x_{j+1} - x_j$, $\\ell_j = \\sqrt{u_j^2 + d_j^2}$
(eq. 2), $T_j = k_j(\\ell_j - \\ell_{0,j})$, $f_{x,j} = T_j u_j/\\ell_j$, $f_{y,j} = T_j d_j/\\ell_j$;
mass $i$ feels $F_i = (f_{x,i} + f_i) - (f_{x,i-1} + f_{i-1})$ and $N_i = m_i - (f_{y,i} - f_{y,i-1})$
(eqs. 5 and 8 generalised; missing springs count zero). Their first and second time
derivatives along the motion are written out by the chain rule (for the engines' quintic
dense output and event prediction); an actuator's derivatives follow from the linearity of
[`AbstractActuator.split`][locomotion_jax.AbstractActuator.split], so it supplies values only.
"""

from typing import Any, NamedTuple, Protocol, runtime_checkable

import equinox as eqx
import jax
import jax.numpy as jnp

from .._custom_types import Array
from ._actuator import AbstractActuator
from ._friction import AbstractFriction
from ._physics import AbstractPhysics, LoadRates, Loads, Scalars, ZENO_SPEED
from ._waveform import AbstractWaveform


class ChainPhysics(AbstractPhysics):
    """The physics of one chain (module docstring), split by mass and by spring once per run
    ([`chain_physics`][]): the [`AbstractPhysics`][] that the engines integrate a
    [`Chain`][locomotion_jax.Chain] with. `loads(...).aux` is the chain's [`Springs`][].
    """

    m: Scalars
    im: Scalars  # 1 / m_i
    c: Scalars
    mu_f: Scalars  # static limits, forward and backward; `None` backward: the same as forward
    mu_b: tuple[Array | None, ...]
    friction: tuple[AbstractFriction, ...]  # the law with mass i's coefficients, per mass
    k: Scalars
    d: Scalars
    dd: Scalars  # d_j^2
    lbar: Scalars
    cos: tuple[Scalars, ...]  # Fourier coefficients of each spring's signal, per harmonic
    sin: tuple[Scalars, ...]
    omega: Array
    nw: Scalars  # n omega and (n omega)^2 per harmonic n = 1, ..., H
    nw2: Scalars
    inv_mass: Array  # 1 / sum_i m_i
    one: Array  # 1.0 as a runtime value (`AbstractPhysics.keep`)
    # The chain's actuator, one for the whole batch (`Chain.actuator` is static): its fields are
    # constants of the program, not batched values.
    actuator: AbstractActuator = eqx.field(static=True)
    # Each spring's signal as a waveform of its own (any `AbstractWaveform`, the base frequency
    # `omega`), in place of the Fourier coefficients `cos`, `sin`; `None`: the coefficients.
    waveforms: tuple[AbstractWaveform, ...] | None = None

    def drive(self, c1: Array, s1: Array) -> "Drive":
        return drive(self, c1, s1)

    def loads(self, drive: "Drive", x: Scalars, keep: Any = None, y: Scalars | None = None) -> Loads:
        sp = springs(self, drive.l0, x, y)
        if keep is not None:
            sp = sp._replace(
                fx=tuple(map(keep, sp.fx)), fy=tuple(map(keep, sp.fy)), tension=tuple(map(keep, sp.tension))
            )
        F, N = loads(self, sp.fx, sp.fy, drive.f)
        return Loads(F, N, sp)

    def load_rates(
        self, drive: "Drive", loads: Loads, xd: Scalars, keep: Any = None, yd: Scalars | None = None
    ) -> LoadRates:
        du = tuple(q - p for p, q in zip(xd[:-1], xd[1:]))
        dh = None if yd is None else tuple(q - p for p, q in zip(yd[:-1], yd[1:]))
        kp = (lambda q: q) if keep is None else keep
        sr = spring_rates(self, loads.aux, du, drive.dl0, dh)
        # dl and dp feed the rates and the second derivatives: pinned once, not recomputed in each.
        sr = sr._replace(dp=tuple(map(kp, sr.dp)), dl=tuple(map(kp, sr.dl)))
        dF, dN = load_rates(tuple(map(kp, sr.dfx)), tuple(map(kp, sr.dfy)), drive.df)
        return LoadRates(dF, dN, (du, sr, dh))

    def load_second(
        self,
        drive: "Drive",
        loads: Loads,
        rates: LoadRates,
        xd: Scalars,
        a: Scalars,
        yd: Scalars | None = None,
        ya: Scalars | None = None,
    ) -> tuple[Scalars, Scalars]:
        du, sr, dh = rates.aux
        ddu = tuple(q - p for p, q in zip(a[:-1], a[1:]))
        ddh = None if ya is None else tuple(q - p for p, q in zip(ya[:-1], ya[1:]))
        ddfx, ddfy = spring_second(self, loads.aux, sr, du, ddu, drive.ddl0, dh, ddh)
        return load_rates(ddfx, ddfy, drive.ddf)

    def power(self, drive: "Drive", loads: Loads, v: Scalars) -> Array:
        return power(self, loads.aux.tension, drive.dl0, drive.f, v)

    def power_rate(self, drive: "Drive", loads: Loads, rates: LoadRates, v: Scalars, a: Scalars) -> Array:
        sr = rates.aux[1]
        return power_rate(self, loads.aux.tension, sr.dtension, drive.dl0, drive.ddl0, drive.f, drive.df, v, a)

    def energy(self, loads: Loads, v: Scalars) -> Array:
        return energy(self, v, loads.aux.tension)

    def centre_of_mass(self, x: Scalars) -> Array:
        return centre_of_mass(self, x)

    def hop(self) -> tuple[Array, Array, Scalars, Array]:
        """Under `contact="hop"` (SPEC §10) the springs act along $(u_j, d_j + y_{j+1} - y_j)$: a chain
        starts on the ground at rest vertically ($y_i = w_i = 0$) and lands plastically ($e_i = 0$,
        SPEC's default), with the default Zeno speed (moot for plastic landings)."""
        zero = jnp.zeros_like(self.omega)
        heights = jnp.stack([zero for _ in self.m], -1)
        return heights, heights, tuple(zero for _ in self.m), zero + ZENO_SPEED

    def gaps(self, x: Scalars) -> Scalars:
        """Neighbours' gaps $x_{j+1} - x_j$ (SPEC §8: the masses stay in order)."""
        return tuple(b - a for a, b in zip(x[:-1], x[1:]))

    def initial_positions(self, start: str) -> Array:
        """Gaps $\\bar\\ell_j$ (`"paper"`, eq. 14) or the relaxed springs $\\sqrt{\\ell_{0,j}(0)^2 - d_j^2}$
        (`"relaxed"`), with $x_0 = 0$ (SPEC §8)."""
        if start == "paper":
            gaps = jnp.stack(self.lbar, -1)
        elif start == "relaxed":
            l0 = jnp.stack(self.drive(jnp.ones_like(self.omega), jnp.zeros_like(self.omega)).l0, -1)
            gaps = jnp.sqrt(jnp.maximum(l0 * l0 - jnp.stack(self.dd, -1), 0))
        else:
            raise ValueError(f"start must be 'paper' (eq. 14) or 'relaxed', got {start!r}.")
        return jnp.concatenate([jnp.zeros_like(gaps[..., :1]), jnp.cumsum(gaps, -1)], -1)


def _at(x: Array, i: int) -> Array:
    """Entry `i` of the last axis of a per-mass or per-spring field (a length-1 axis or a scalar is broadcast)."""
    x = jnp.asarray(x)
    if x.ndim == 0:
        return x
    return x[..., i if x.shape[-1] > 1 else 0]


def chain_physics(C: Any) -> ChainPhysics:
    """The physics of a [`Chain`][locomotion_jax.Chain]: its fields split by mass and by spring."""
    n = C.m.shape[-1]
    masses, springs = range(n), range(n - 1)
    friction = tuple(jax.tree_util.tree_map(lambda x, i=i: _at(x, i), C.friction) for i in masses)
    # An isotropic law returns one array for both limits: then mu_b is None (the engine's
    # stick margin is mu n - |F|, fewer operations for the same values).
    limits = [law.static_limits() for law in friction]
    limits = [(f, None if b is f else b) for f, b in limits]
    H = C.waves.cos.shape[-1]
    nw = tuple((h + 1) * C.waves.omega for h in range(H))
    per_spring = lambda x: tuple(_at(x, j) for j in springs)
    wave = lambda x: tuple(tuple(x[..., j if x.shape[-2] > 1 else 0, h] for h in range(H)) for j in springs)
    return ChainPhysics(
        m=tuple(_at(C.m, i) for i in masses),
        im=tuple(1 / _at(C.m, i) for i in masses),
        c=tuple(_at(C.c, i) for i in masses),
        mu_f=tuple(f for f, _ in limits),
        mu_b=tuple(b for _, b in limits),
        friction=friction,
        k=per_spring(C.k),
        d=per_spring(C.d),
        dd=tuple(d * d for d in per_spring(C.d)),
        lbar=per_spring(C.lbar),
        cos=wave(C.waves.cos),
        sin=wave(C.waves.sin),
        omega=C.waves.omega,
        nw=nw,
        nw2=tuple(w * w for w in nw),
        inv_mass=1 / C.m.sum(-1),
        one=C.m[..., 0] / C.m[..., 0],
        actuator=C.actuator,
    )


# -- actuation --------------------------------------------------------------------------------------


class Drive(NamedTuple):
    """Per spring: rest lengths and internal forces with their first two rates. An entry is `None`
    where the actuator does not drive that quantity (its rates are zero and the rest length is
    $\\bar\\ell_j$), so that nothing is spent on it."""

    l0: Scalars
    dl0: Scalars | None
    ddl0: Scalars | None
    f: Scalars | None
    df: Scalars | None
    ddf: Scalars | None


def drive(P: ChainPhysics, c1: Array, s1: Array) -> Drive:
    """The actuation at phase $(\\cos\\omega t, \\sin\\omega t)$: each spring's signal $s_j$ and its
    rates ([`_fourier_signals`][], or each spring's waveform, $\\ell_0(t) - \\bar\\ell$ of
    `AbstractWaveform.at_phase`), turned into rest lengths and forces by the actuator (linear, so
    the rates map as `split(0, ds)`). Unused entries cost nothing (the compiler drops them)."""
    act = P.actuator
    base = P.lbar
    if P.waveforms is None:
        val, rate, acc = _fourier_signals(P, c1, s1)
    else:
        at = [w.at_phase(c1, s1) for w in P.waveforms]
        rate, acc = [q[1] for q in at], [q[2] for q in at]
        if act.applies_force:
            val = [q[0] - w.lbar for q, w in zip(at, P.waveforms)]
        else:  # rest length lbar_j + (l0 - lbar_w): the waveform's l0 itself where the means agree
            val = [q[0] for q in at]
            base = tuple(lb - w.lbar for lb, w in zip(P.lbar, P.waveforms))
    split = [act.split(lb, s) for lb, s in zip(base, val)]
    dsplit = [act.split(jnp.zeros_like(s), s) for s in rate]
    ddsplit = [act.split(jnp.zeros_like(s), s) for s in acc]
    pick = lambda pairs, k: tuple(p[k] for p in pairs)
    length, force = act.varies_rest_length, act.applies_force
    return Drive(
        l0=pick(split, 0) if length else P.lbar, dl0=pick(dsplit, 0) if length else None,
        ddl0=pick(ddsplit, 0) if length else None, f=pick(split, 1) if force else None,
        df=pick(dsplit, 1) if force else None, ddf=pick(ddsplit, 1) if force else None,
    )  # fmt: skip


def _fourier_signals(P: ChainPhysics, c1: Array, s1: Array) -> tuple[list, list, list]:
    """$s_j = \\sum_n A_{jn}\\cos n\\omega t + B_{jn}\\sin n\\omega t$ per spring with its first two rates
    (the harmonics' phases by the angle-addition recurrence)."""
    H = len(P.cos[0]) if P.cos else 0
    phases = [(c1, s1)]
    for _ in range(H - 1):
        cn, sn = phases[-1]
        phases.append((cn * c1 - sn * s1, sn * c1 + cn * s1))
    val, rate, acc = [], [], []
    for A, B in zip(P.cos, P.sin):
        terms = [(A[n] * cn + B[n] * sn, P.nw[n] * (B[n] * cn - A[n] * sn)) for n, (cn, sn) in enumerate(phases)]
        v, r, q = terms[0][0], terms[0][1], -(P.nw2[0] * terms[0][0])
        for n, ((cn, sn), (vn, rn)) in enumerate(zip(phases[1:], terms[1:]), start=1):
            v, r, q = (v + A[n] * cn) + B[n] * sn, r + rn, q - P.nw2[n] * vn
        val.append(v)
        rate.append(r)
        acc.append(q)
    return val, rate, acc


# -- springs and loads ------------------------------------------------------------------------------


class Springs(NamedTuple):
    """Per spring: $u_j$, $1/\\ell_j$, $T_j/\\ell_j$, $T_j$, $f_{x,j}$, $f_{y,j}$ (eqs. 2, 8); `h`, under
    `contact="hop"` only (else `None`): the vertical offsets $h_j = d_j + y_{j+1} - y_j$ (SPEC §10)."""

    u: Scalars
    il: Scalars
    p: Scalars
    tension: Scalars
    fx: Scalars
    fy: Scalars
    h: Scalars | None = None


@runtime_checkable
class SpringGeometry(Protocol):
    """Per tilted spring: stiffness `k`, vertical offset `d` and its square `dd` (a chain's physics,
    or a mechanism's tilted springs)."""

    @property
    def k(self) -> Scalars: ...

    @property
    def d(self) -> Scalars: ...

    @property
    def dd(self) -> Scalars: ...


def springs(P: ChainPhysics, l0: Scalars, x: Scalars, y: Scalars | None = None) -> Springs:
    """The springs at positions `x` and (`contact="hop"`) heights `y`: a spring acts along
    $(u_j, h_j)$ with $h_j = d_j + y_{j+1} - y_j$ (SPEC §10), $h_j = d_j$ where `y` is `None`."""
    u = tuple(b - a for a, b in zip(x[:-1], x[1:]))
    h = None if y is None else tuple(d + (b - a) for d, a, b in zip(P.d, y[:-1], y[1:]))
    return tilted(P, l0, u, h)


def tilted(P: SpringGeometry, l0: Scalars, u: Scalars, h: Scalars | None) -> Springs:
    """Tilted springs of extensions `u` and vertical offsets `h` (`None`: their `d`), whatever bodies
    they join: $\\ell = \\sqrt{u^2 + h^2}$, $T = k(\\ell - \\ell_0)$, $(f_x, f_y) = T(u, h)/\\ell$."""
    vert = P.dd if h is None else tuple(q * q for q in h)
    length = [jnp.sqrt(uj * uj + dd) for uj, dd in zip(u, vert)]
    il = tuple(1 / lj for lj in length)
    tension = tuple(k * (lj - l0j) for k, lj, l0j in zip(P.k, length, l0))
    p = tuple(T * i for T, i in zip(tension, il))
    fy = tuple(a * d for a, d in zip(p, P.d if h is None else h))
    return Springs(u, il, p, tension, tuple(a * b for a, b in zip(p, u)), fy, h)


def _plus(a: Scalars, b: Scalars | None) -> Scalars:
    return a if b is None else tuple(x + y for x, y in zip(a, b))


def _minus(a: Scalars, b: Scalars | None) -> Scalars:
    return a if b is None else tuple(x - y for x, y in zip(a, b))


def per_mass(a: Scalars) -> Scalars:
    """$a_i - a_{i-1}$ for a per-spring list (missing springs count zero)."""
    return (a[0], *(a[i] - a[i - 1] for i in range(1, len(a))), -a[-1])


def loads(P: ChainPhysics, fx: Scalars, fy: Scalars, f: Scalars | None) -> tuple[Scalars, Scalars]:
    """Horizontal loads $F_i$ and signed normal forces $N_i$ (module docstring)."""
    F = per_mass(_plus(fx, f))
    N = tuple(m - q for m, q in zip(P.m, per_mass(fy)))
    return F, N


def load_rates(fx: Scalars, fy: Scalars, f: Scalars | None) -> tuple[Scalars, Scalars]:
    """Time derivatives of $F_i$ and $N_i$ from those of $f_{x,j}$, $f_{y,j}$ and $f_j$."""
    return per_mass(_plus(fx, f)), tuple(-q for q in per_mass(fy))


class SpringRates(NamedTuple):
    """First time derivatives along the motion of $\\ell_j$, $T_j$, $T_j/\\ell_j$, $f_{x,j}$, $f_{y,j}$."""

    dl: Scalars
    dtension: Scalars
    dp: Scalars
    dfx: Scalars
    dfy: Scalars


def spring_rates(
    P: SpringGeometry, sp: Springs, du: Scalars, dl0: Scalars | None, dh: Scalars | None = None
) -> SpringRates:
    """With $p = T/\\ell$ and $\\dot u_j = \\dot x_{j+1} - \\dot x_j$: $\\dot\\ell = u\\dot u/\\ell$,
    $\\dot T = k(\\dot\\ell - \\dot\\ell_0)$, $\\dot p = (\\dot T - p\\dot\\ell)/\\ell$,
    $\\dot f_x = \\dot p u + p\\dot u$, $\\dot f_y = \\dot p d$. Under `contact="hop"` (`dh`, the rates
    $\\dot h_j = \\dot y_{j+1} - \\dot y_j$, given): $\\dot\\ell = (u\\dot u + h\\dot h)/\\ell$,
    $\\dot f_y = \\dot p h + p\\dot h$."""
    if dh is None or sp.h is None:
        dl = tuple(u * a * il for u, a, il in zip(sp.u, du, sp.il))
    else:
        dl = tuple((u * a + h * b) * il for u, a, h, b, il in zip(sp.u, du, sp.h, dh, sp.il))
    dT = tuple(k * e for k, e in zip(P.k, _minus(dl, dl0)))
    dp = tuple((a - p * b) * il for a, p, b, il in zip(dT, sp.p, dl, sp.il))
    dfx = tuple(a * u + p * b for a, u, p, b in zip(dp, sp.u, sp.p, du))
    if dh is None or sp.h is None:
        return SpringRates(dl, dT, dp, dfx, tuple(a * d for a, d in zip(dp, P.d)))
    return SpringRates(dl, dT, dp, dfx, tuple(a * h + p * b for a, h, p, b in zip(dp, sp.h, sp.p, dh)))


def spring_second(
    P: SpringGeometry,
    sp: Springs,
    r: SpringRates,
    du: Scalars,
    ddu: Scalars,
    ddl0: Scalars | None,
    dh: Scalars | None = None,
    ddh: Scalars | None = None,
) -> tuple[Scalars, Scalars]:
    """Second time derivatives $\\ddot f_{x,j}$, $\\ddot f_{y,j}$ (differentiating [`spring_rates`][] once
    more; under `contact="hop"` with the vertical offsets' rates `dh`, `ddh`)."""
    ddl = [(a * a + u * b - c * c) * il for a, u, b, c, il in zip(du, sp.u, ddu, r.dl, sp.il)]
    tilt = dh is not None and ddh is not None and sp.h is not None
    if tilt:
        assert dh is not None and ddh is not None and sp.h is not None
        ddl = [q + (a * a + h * b) * il for q, a, h, b, il in zip(ddl, dh, sp.h, ddh, sp.il)]
    ddT = tuple(k * e for k, e in zip(P.k, _minus(tuple(ddl), ddl0)))
    ddp = tuple((a - 2 * b * c - p * e) * il for a, b, c, p, e, il in zip(ddT, r.dp, r.dl, sp.p, ddl, sp.il))
    ddfx = tuple(a * u + 2 * b * c + p * e for a, u, b, c, p, e in zip(ddp, sp.u, r.dp, du, sp.p, ddu))
    if not tilt:
        return ddfx, tuple(a * d for a, d in zip(ddp, P.d))
    assert dh is not None and ddh is not None and sp.h is not None
    return ddfx, tuple(a * h + 2 * b * c + p * e for a, h, b, c, p, e in zip(ddp, sp.h, r.dp, dh, sp.p, ddh))


def power(P: ChainPhysics, tension: Scalars, dl0: Scalars | None, f: Scalars | None, v: Scalars) -> Array:
    """The actuator's power (eq. 16 generalised): [`AbstractActuator.power`][locomotion_jax.AbstractActuator.power]."""
    act = P.actuator
    if type(act).power is not AbstractActuator.power:  # a user's own: called on arrays
        stack = lambda a: jnp.stack(a, -1) if a is not None else jnp.zeros_like(jnp.stack(tension, -1))
        return act.power(stack(tension), stack(dl0), stack(f), jnp.stack(v, -1))
    terms = [] if dl0 is None else [-(T * r) for T, r in zip(tension, dl0)]
    if f is not None:
        terms += [fj * (a - b) for fj, a, b in zip(f, v[:-1], v[1:])]
    return sum(terms[1:], terms[0]) if terms else jnp.zeros_like(v[0])


def power_rate(P: ChainPhysics, tension, dtension, dl0, ddl0, f, df, v, a) -> Array:
    """Time derivative of [`power`][] along the motion."""
    act = P.actuator
    if type(act).power is not AbstractActuator.power:
        zeros = lambda: tuple(jnp.zeros_like(T) for T in tension)
        args = (tension, dl0 or zeros(), f or zeros(), v)
        rates = (dtension, ddl0 or zeros(), df or zeros(), a)
        return jax.jvp(lambda *xs: power(P, *xs), args, rates)[1]
    terms = [] if dl0 is None else [-(dT * r + T * rr) for T, dT, r, rr in zip(tension, dtension, dl0, ddl0)]
    if f is not None:
        terms += [dfj * (x - y) + fj * (p - q) for fj, dfj, x, y, p, q in zip(f, df, v[:-1], v[1:], a[:-1], a[1:])]
    return sum(terms[1:], terms[0]) if terms else jnp.zeros_like(v[0])


def energy(P: ChainPhysics, v: Scalars, tension: Scalars) -> Array:
    """$e = \\sum_i m_i v_i^2/2 + \\sum_j T_j^2/(2 k_j)$ (eq. 10 generalised)."""
    kin = [m * a * a for m, a in zip(P.m, v)]
    pot = [T * T / k for T, k in zip(tension, P.k)]
    return 0.5 * (sum(kin[1:], kin[0]) + sum(pot[1:], pot[0]))


def centre_of_mass(P: ChainPhysics, x: Scalars) -> Array:
    """$X = \\sum_i m_i x_i / \\sum_i m_i$."""
    terms = [m * a for m, a in zip(P.m, x)]
    return sum(terms[1:], terms[0]) * P.inv_mass
