"""A chain's physics in the array layout: every per-mass and per-spring quantity one array with a
body axis, so that a chain of 64 masses is a program of the size of a chain of 4.

[`ChainPhysics`][locomotion_jax.model._chain_physics.ChainPhysics] hands the engine one scalar
per mass (the unrolled layout): the fastest on a CPU for a few masses, but the program, its
compile time and its cost per mass grow with N. [`ArrayChainPhysics`][] hands it *one* entry
holding all N masses (shape `(N,)` per configuration) in each per-body tuple of the interface
([`AbstractPhysics`][locomotion_jax.AbstractPhysics]). The engine's per-body code is elementwise,
so it runs unchanged on those entries; where it reduces over bodies (the earliest event, the
lowest normal force, sums of powers, a collision, a switch) it reduces within the entry too
(`dynamics._numerics.union`, `least`, `total`, `lowest_first`). Springs are shifted slices:
$u = x_{1:} - x_{:-1}$ (under `contact="hop"` also $h = d + y_{1:} - y_{:-1}$, SPEC §10), and a
mass's load is $a_{i} - a_{i-1}$ of a per-spring array padded with zeros. The same formulas as the
unrolled physics, term by term (module docstring of `_chain_physics`); only sums over bodies are
summed in another order.

Which layout a run uses: [`engine_physics`][], from the chain's `layout` (`"auto"`: the array
layout from [`array_from`][]`()` masses on, where it supports the chain).
"""

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp

from .._custom_types import Array
from ._actuator import AbstractActuator
from ._bank import wave_bank, WaveBank
from ._chain_physics import Drive, SpringRates, Springs
from ._friction import AbstractFriction
from ._physics import AbstractArrayPhysics, AbstractPhysics, LoadRates, Loads, Scalars, ZENO_SPEED


ARRAY_FROM = 16
"""On a CPU, `layout="auto"` runs a chain of this many masses or more in the array layout, fewer
unrolled (the crossover of `benchmarks/chain_scaling.py`, benchmarks/NOTES.md "Chains in the array
layout")."""

ARRAY_FROM_ACCELERATOR = 4
"""On any other backend (a GPU), the same threshold: on one H200 at 4 masses the array layout ran
1.5x faster than the unrolled one and compiled in 0.42 of its time, while at 2 the unrolled layout
was 1.4x faster (benchmarks/NOTES.md "On a GPU")."""


def array_from() -> int:
    """`layout="auto"`'s threshold for `measure`, `simulate` and `sweep` on JAX's default backend:
    [`ARRAY_FROM`][] on a CPU, [`ARRAY_FROM_ACCELERATOR`][] elsewhere."""
    return ARRAY_FROM if jax.default_backend() == "cpu" else ARRAY_FROM_ACCELERATOR


GAIT_ARRAY_FROM = 3
"""`layout="auto"` finds the steady gaits of a chain (or a `Mechanism`) of this many bodies or more in
the array layout. Their period maps run under forward-mode differentiation, whose unrolled program grows
much faster with N than `measure`'s (a 4-mass worm's first `steady_gait`: 313 s and 9.7 GB
unrolled, 32 s and 1.7 GB in the array layout; benchmarks/NOTES.md "Steady gaits in the array
layout")."""

LAYOUTS = ("auto", "unrolled", "array")


class ArrayChainPhysics(AbstractArrayPhysics):
    """The physics of one chain in the array layout (module docstring). The interface's per-body
    tuples (`m`, `im`, `c`, `mu_f`, `mu_b`, `friction`) have one entry each, over all masses; the
    springs' fields are arrays over the springs (`cos`, `sin`: springs by harmonics). Drives,
    springs and their rates are the unrolled physics' named tuples with one entry per field."""

    m: Scalars
    im: Scalars
    c: Scalars
    mu_f: Scalars
    mu_b: tuple[Array | None, ...]
    friction: tuple[AbstractFriction, ...]
    k: Array
    d: Array
    dd: Array
    lbar: Array
    cos: Array
    sin: Array
    omega: Array
    nw: Array  # n omega and (n omega)^2, harmonics on the last axis
    nw2: Array
    inv_mass: Array
    one: Array
    # The chain's actuator, one for the whole batch (`Chain.actuator` is static): its fields are
    # constants of the program, not batched values.
    actuator: AbstractActuator = eqx.field(static=True)
    # The springs' own waveforms (`Chain.signals`) as one bank, in place of the Fourier coefficients
    # `cos`, `sin`; `None`: the coefficients.
    bank: WaveBank | None = None

    def drive(self, c1: Array, s1: Array) -> Drive:
        """Each spring's Fourier signal with its first two rates (the harmonics by the angle-addition
        recurrence, summed in the unrolled physics' order), or its own waveform's, split by the actuator."""
        if self.bank is not None:
            return self._split(*self._bank_signals(c1, s1))
        H = self.cos.shape[-1]
        A, B = self.cos, self.sin
        cn, sn = c1, s1
        val = rate = acc = None
        for n in range(H):
            if n > 0:
                cn, sn = cn * c1 - sn * s1, sn * c1 + cn * s1
            vn = A[..., n] * cn + B[..., n] * sn
            rn = self.nw[..., n] * (B[..., n] * cn - A[..., n] * sn)
            if val is None or rate is None or acc is None:
                val, rate, acc = vn, rn, -(self.nw2[..., 0] * vn)
            else:
                val, rate, acc = (val + A[..., n] * cn) + B[..., n] * sn, rate + rn, acc - self.nw2[..., n] * vn
        if val is None or rate is None or acc is None:  # no harmonics: no actuation
            val = rate = acc = jnp.zeros_like(self.lbar) * c1
        return self._split(self.lbar, val, rate, acc)

    def _bank_signals(self, c1: Array, s1: Array) -> tuple[Array, Array, Array, Array]:
        """The mean rest lengths and the signals with their rates of the springs' own waveforms, as
        the unrolled physics reads a waveform: its rest length itself under the rest-length actuator
        (about $\\bar\\ell_j$), its deviation from its own mean under the force actuator."""
        assert self.bank is not None
        l0, rate, acc = self.bank.at_phase(c1, s1)
        if self.actuator.applies_force:
            return self.lbar, l0 - self.bank.lbar, rate, acc
        return self.lbar - self.bank.lbar, l0, rate, acc

    def _split(self, base: Array, val: Array, rate: Array, acc: Array) -> Drive:
        """Rest lengths and forces with their rates from the signals (the actuator is linear, so the
        rates map as `split(0, ds)`)."""
        act = self.actuator
        l0, f = act.split(base, val)
        dl0, df = act.split(jnp.zeros_like(rate), rate)
        ddl0, ddf = act.split(jnp.zeros_like(acc), acc)
        length, force = act.varies_rest_length, act.applies_force
        one = lambda q, used: (q,) if used else None
        return Drive(
            l0=(l0,) if length else (self.lbar,), dl0=one(dl0, length), ddl0=one(ddl0, length),
            f=one(f, force), df=one(df, force), ddf=one(ddf, force),
        )  # fmt: skip

    def loads(self, drive: Drive, x: Scalars, keep: Any = None, y: Scalars | None = None) -> Loads:
        (xa,) = x
        kp = (lambda q: q) if keep is None else keep
        u = xa[1:] - xa[:-1]
        # Under contact="hop" a spring acts along (u_j, h_j), h_j = d_j + y_{j+1} - y_j (SPEC §10).
        h = None if y is None else self.d + (y[0][1:] - y[0][:-1])
        length = jnp.sqrt(u * u + (self.dd if h is None else h * h))
        il = 1 / length
        tension = kp(self.k * (length - drive.l0[0]))
        p = tension * il
        fx, fy = kp(p * u), kp(p * (self.d if h is None else h))
        F, N = _loads(self.m[0], fx, fy, drive.f)
        return Loads((F,), (N,), Springs((u,), (il,), (p,), (tension,), (fx,), (fy,), None if h is None else (h,)))

    def load_rates(
        self, drive: Drive, loads: Loads, xd: Scalars, keep: Any = None, yd: Scalars | None = None
    ) -> LoadRates:
        (v,) = xd
        kp = (lambda q: q) if keep is None else keep
        sp = loads.aux
        u, il, p = sp.u[0], sp.il[0], sp.p[0]
        du = v[1:] - v[:-1]
        h = None if sp.h is None or yd is None else sp.h[0]
        dh = None if h is None or yd is None else yd[0][1:] - yd[0][:-1]
        dl = kp((u * du if h is None or dh is None else u * du + h * dh) * il)
        dT = self.k * (dl if drive.dl0 is None else dl - drive.dl0[0])
        dp = kp((dT - p * dl) * il)
        dfx = kp(dp * u + p * du)
        dfy = kp(dp * self.d if h is None or dh is None else dp * h + p * dh)
        dF, dN = _load_rates(dfx, dfy, drive.df)
        return LoadRates((dF,), (dN,), (du, SpringRates((dl,), (dT,), (dp,), (dfx,), (dfy,)), dh))

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
        du, sr, dh = rates.aux
        sp = loads.aux
        u, il, p = sp.u[0], sp.il[0], sp.p[0]
        dl, dp = sr.dl[0], sr.dp[0]
        ddu = a[0][1:] - a[0][:-1]
        ddl = (du * du + u * ddu - dl * dl) * il
        h, ddh = None, None
        if sp.h is not None and dh is not None and ya is not None:  # contact="hop": the tilt's rates
            h, ddh = sp.h[0], ya[0][1:] - ya[0][:-1]
            ddl = ddl + (dh * dh + h * ddh) * il
        ddT = self.k * (ddl if drive.ddl0 is None else ddl - drive.ddl0[0])
        ddp = (ddT - 2 * dp * dl - p * ddl) * il
        ddfx = ddp * u + 2 * dp * du + p * ddu
        ddfy = ddp * self.d if h is None or ddh is None else ddp * h + 2 * dp * dh + p * ddh
        ddF, ddN = _load_rates(ddfx, ddfy, drive.ddf)
        return (ddF,), (ddN,)

    def power(self, drive: Drive, loads: Loads, v: Scalars) -> Array:
        T = loads.aux.tension[0]
        pick = lambda q: None if q is None else q[0]
        return _power(self.actuator, T, pick(drive.dl0), pick(drive.f), v[0])

    def power_rate(self, drive: Drive, loads: Loads, rates: LoadRates, v: Scalars, a: Scalars) -> Array:
        T, dT = loads.aux.tension[0], rates.aux[1].dtension[0]
        if type(self.actuator).power is not AbstractActuator.power:  # a user's own: its derivative
            zeros = jnp.zeros_like(T)
            fill = lambda q: zeros if q is None else q[0]
            args = (T, fill(drive.dl0), fill(drive.f), v[0])
            rates_ = (dT, fill(drive.ddl0), fill(drive.df), a[0])
            return jax.jvp(lambda *xs: _power(self.actuator, *xs), args, rates_)[1]
        pick = lambda q: None if q is None else q[0]
        dl0, ddl0, f, df = pick(drive.dl0), pick(drive.ddl0), pick(drive.f), pick(drive.df)
        va, aa = v[0], a[0]
        out = jnp.zeros_like(va[0])
        if dl0 is not None and ddl0 is not None:
            out = out + jnp.sum(-(dT * dl0 + T * ddl0))
        if f is not None and df is not None:
            out = out + jnp.sum(df * (va[:-1] - va[1:]) + f * (aa[:-1] - aa[1:]))
        return out

    def energy(self, loads: Loads, v: Scalars) -> Array:
        T, va = loads.aux.tension[0], v[0]
        return 0.5 * (jnp.sum(self.m[0] * va * va) + jnp.sum(T * T / self.k))

    def centre_of_mass(self, x: Scalars) -> Array:
        return jnp.sum(self.m[0] * x[0]) * self.inv_mass

    def gaps(self, x: Scalars) -> Scalars:
        """Neighbours' gaps $x_{j+1} - x_j$, one entry over the springs."""
        return (x[0][1:] - x[0][:-1],)

    def hop(self) -> tuple[Array, Array, Scalars, Array]:
        """As the unrolled physics (SPEC §10): on the ground at rest vertically, plastic landings
        ($e_i = 0$) and the default Zeno speed; the restitution one entry over the masses."""
        heights = jnp.zeros_like(self.m[0])
        return heights, heights, (heights,), jnp.zeros_like(self.omega) + ZENO_SPEED

    def initial_positions(self, start: str) -> Array:
        """As the unrolled physics: gaps $\\bar\\ell_j$ (`"paper"`) or the relaxed springs, $x_0 = 0$."""
        if start == "paper":
            gaps = self.lbar
        elif start == "relaxed":
            l0 = self.drive(jnp.ones_like(self.omega), jnp.zeros_like(self.omega)).l0[0]
            gaps = jnp.sqrt(jnp.maximum(l0 * l0 - self.dd, 0))
        else:
            raise ValueError(f"start must be 'paper' (eq. 14) or 'relaxed', got {start!r}.")
        return jnp.concatenate([jnp.zeros_like(gaps[..., :1]), jnp.cumsum(gaps, -1)], -1)


def _per_mass(a: Array) -> Array:
    """$a_i - a_{i-1}$ per mass of a per-spring array (missing springs count zero)."""
    zero = jnp.zeros_like(a[..., :1])
    return jnp.concatenate([a, zero], -1) - jnp.concatenate([zero, a], -1)


def _loads(m: Array, fx: Array, fy: Array, f: Scalars | None) -> tuple[Array, Array]:
    return _per_mass(fx if f is None else fx + f[0]), m - _per_mass(fy)


def _load_rates(dfx: Array, dfy: Array, df: Scalars | None) -> tuple[Array, Array]:
    return _per_mass(dfx if df is None else dfx + df[0]), -_per_mass(dfy)


def _power(act: AbstractActuator, T: Array, dl0: Array | None, f: Array | None, v: Array) -> Array:
    """The actuator's power: a user's own `power` on the arrays, else $-\\sum_j T_j\\dot\\ell_{0,j}
    + \\sum_j f_j (v_j - v_{j+1})$ (the terms it drives)."""
    if type(act).power is not AbstractActuator.power:
        zeros = jnp.zeros_like(T)
        return act.power(T, zeros if dl0 is None else dl0, zeros if f is None else f, v)
    out = jnp.zeros_like(v[0])
    if dl0 is not None:
        out = out + jnp.sum(-(T * dl0))
    if f is not None:
        out = out + jnp.sum(f * (v[:-1] - v[1:]))
    return out


def array_physics(C: Any) -> ArrayChainPhysics:
    """The physics of a [`Chain`][locomotion_jax.Chain] in the array layout (every field broadcast
    to the chain's batch shape, with its mass or spring axis)."""
    C = C.broadcast()
    law = C.friction
    f, b = law.static_limits()
    nw = jnp.stack([(h + 1) * C.waves.omega for h in range(C.waves.cos.shape[-1])], -1)
    return ArrayChainPhysics(
        m=(C.m,), im=(1 / C.m,), c=(C.c,), mu_f=(f,), mu_b=(None if b is f else b,), friction=(law,),
        k=C.k, d=C.d, dd=C.d * C.d, lbar=C.lbar, cos=C.waves.cos, sin=C.waves.sin, omega=C.waves.omega,
        nw=nw, nw2=nw * nw, inv_mass=1 / C.m.sum(-1), one=C.m[..., 0] / C.m[..., 0], actuator=C.actuator,
        bank=None if C.signals is None else wave_bank(dict(enumerate(C.signals)), len(C.signals), C.batch_shape),
    )  # fmt: skip


def uses_array(mechanism: Any, start: int | None = None) -> bool:
    """Whether `measure` and `simulate` run a mechanism in the array layout: a
    [`Chain`][locomotion_jax.Chain] or a [`Mechanism`][locomotion_jax.Mechanism] with `layout="array"`,
    or `"auto"` from `start` bodies on (default [`array_from`][]`()`); any other mechanism, or
    `layout="unrolled"`: no. Steady gaits pass `start=`[`GAIT_ARRAY_FROM`][]."""
    layout = getattr(mechanism, "layout", "unrolled")
    if layout == "unrolled":
        return False
    return layout == "array" or mechanism.n_masses >= (array_from() if start is None else start)


def engine_physics(mechanism: Any, start: int | None = None) -> AbstractPhysics:
    """The physics that `measure` and `simulate` (and, with `start=GAIT_ARRAY_FROM`, steady gaits)
    integrate a mechanism with ([`uses_array`][]): its `array_physics()` in the array layout, else
    its own `physics()`."""
    return mechanism.array_physics() if uses_array(mechanism, start) else mechanism.physics()
