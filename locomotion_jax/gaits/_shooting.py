"""Steady gaits as periodic orbits: the one period map and Newton solver of every mechanism (a
chain of N masses, a `Mechanism`, and the paper's model as the two-mass chain, through `_gait`).

Every waveform of a [`Chain`][] shares the base frequency $\\omega$, so the forcing is
$T$-periodic ($T = 2\\pi/\\omega$), and the loads depend on the positions only through the
gaps $u_j = x_{j+1} - x_j$ (SPEC §8). A steady gait is then a fixed point of the $k$-period
map $\\Phi_k$ of the reduced state $y = (u_1, \\dots, u_{N-1}, v_1, \\dots, v_N)$ at the phase
$\\omega t \\equiv 0$, while the centre of mass drifts by $\\Delta X$ per gait period $kT$.
A transient from the start, then Newton's method on $\\Phi_k(y) = y$ with
the monodromy matrix $M = \\partial\\Phi_k/\\partial y$ from forward-mode differentiation through
the N-mass exact engine (located events enter with their implicit-function times, so $M$
includes the saltation of every switch); the Floquet multipliers are the eigenvalues of $M$.

A mass at rest at the section sticks where its static limits hold, so its velocity carries
no tangent there (its column of $M$ is zero), as in the two-mass model.

A [`Mechanism`][locomotion_jax.Mechanism] (SPEC §9) runs on the same solver through its physics.
Its forces depend on the positions only through the springs' extensions; where no spring ties a
body to the wall they are invariant under a common translation, and the reduced state is the
chain's, $(u_1, \\dots, u_{N-1}, v_1, \\dots, v_N)$ with $u_j = x_{j+1} - x_j$ the positions relative
to body 0 (of any sign: a carried mass passes its carrier). A mechanism with a spring to the wall
(an anchored one) is not: its section state holds the absolute positions,
$(x_1, \\dots, x_N, v_1, \\dots, v_N)$, and its centre of mass returns to where it was over a period.
"""

from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array, ArrayLike, Contact
from .._loops import lane_while_loop
from .._results import BODIES
from .._status import Regime, Status
from ..dynamics import _engine as engine, _numerics as num, _paper as paper
from ..dynamics._compile import engine_jit
from ..dynamics._exact_dynamics import Exact
from ..dynamics._runs import batch_rows, BatchRows, chain_initial_state, default_max_steps, MICRO_BATCH_CPU, STICK_TOL
from ..model._bodies import Mechanism
from ..model._chain import Chain
from ..model._chain_array import GAIT_ARRAY_FROM, uses_array
from ..model._physics import AbstractPhysics, contact_loads
from ..run._batch import check_contact_start, prepare_chain, unflatten
from ..run._resolution import guard_chain
from . import _select as select
from ._result import Gait
from ._select import GaitStatus


class _Period(NamedTuple):
    """One application of the period map: the end state and what the period accumulated (the
    slip margin and the smallest normal force: [`Gait`][]`.slip_margin`, `.min_normal`)."""

    y: Array
    dX: Array
    ed: Array
    w: Array
    stuck: Array  # time each mass was stuck, shape (N,)
    n_switch: Array
    status: Array
    lifted: Array
    margin: Array
    n_min: Array
    n_land: Array  # landings over the periods (0 unless contact="hop")
    sequence: Array  # the order of the bodies' mode changes over the periods (`_sequence`)


def reduced_size(P: AbstractPhysics) -> int:
    """Length of the section state: $2N - 1$, or $2N$ for an anchored mechanism."""
    return 2 * P.n_bodies - (0 if P.anchored else 1)


def _reduced(st: engine.Hybrid, P: AbstractPhysics | None = None) -> Array:
    """The section state of a hybrid state; under `contact="hop"` followed by the heights and
    vertical velocities $(y_1, \\dots, y_N, w_1, \\dots, w_N)$."""
    x, v = _flat(st.y.x), _flat(st.y.v)
    vert = [] if st.y.y is None or st.y.vy is None else [_flat(st.y.y), _flat(st.y.vy)]
    if P is not None and P.anchored:
        return jnp.concatenate([x, v] + vert)
    return jnp.concatenate([x[1:] - x[:-1], v] + vert)


def displacement(P: AbstractPhysics, st0: engine.Hybrid, st: engine.Hybrid) -> Array:
    """The centre of mass's displacement from `st0` to `st` over a gait's periods; 0 for an anchored
    mechanism, whose positions are part of its section state and so periodic on its orbit (what
    the integration gives there is Newton's residual, not a distance)."""
    dX = P.centre_of_mass(st.y.x) - P.centre_of_mass(st0.y.x)
    return jnp.zeros_like(dX) if P.anchored else dX


def _flat(entries: tuple) -> Array:
    """Per-body entries as one vector over the bodies (an entry is one body's scalar, or every
    body's vector in the array layout, `model._chain_array`)."""
    return jnp.concatenate([jnp.atleast_1d(q) for q in entries])


def _positions(P: AbstractPhysics, y: Array) -> Array:
    """The positions of a section state: $x_1 = 0$ and the gaps' sums, or the anchored state's own."""
    n = P.n_bodies
    if P.anchored:
        return y[:n]
    return jnp.concatenate([jnp.zeros((1,), y.dtype), jnp.cumsum(y[: n - 1])])


def _section_state(P: AbstractPhysics, contact: Contact, y: Array) -> engine.Hybrid:
    """The hybrid state at phase 0 for a reduced state `y` (with $x_1 = 0$ unless anchored): a mass
    at rest sticks where its static limits hold (eq. 7 generalised), a moving one slips along $v_i$."""
    n, base = P.n_bodies, reduced_size(P)
    if contact != "hop":
        return engine.init(P, contact, _positions(P, y), y[base - n : base])
    # A body on the ground (y_i = 0, not rising) has no vertical tangent: its height and vertical
    # velocity are set to the constant 0 there (`where`), so a grounded body adds a zero multiplier.
    # A carried body takes its carrier's (`P.ride`): its own coordinates add zero multipliers too.
    h = P.stacked(P.ride(P.bodies(y[base : base + n])))
    w = P.stacked(P.ride(P.bodies(y[base + n : base + 2 * n])))
    up = (h > 0) | (w > 0)
    h, w = jnp.where(up, h, 0), jnp.where(up, w, 0)
    return engine.init(P, contact, _positions(P, y), y[base - n : base], h, w)


def _range(q: tuple, h: Array, t0: Array, t1: Array) -> tuple[Array, Array]:
    """Smallest and largest value over a committed step `[t0, t1]` of a quantity given by its value
    and first two time derivatives at the step's start and at the full step's end (`q`, length `h`),
    on their quintic Hermite interpolant (an interior extremum polished by Newton's method).

    An interior extremum is differentiated at its location held fixed: $p'(\\theta^*) = 0$ there,
    so its value's derivative is $\\partial p/\\partial c$ alone (the envelope theorem), as the
    event roots are differentiated by the implicit function theorem rather than through their
    iterations. Tangents carried through the polish would add nothing at convergence, and XLA's
    CPU fusion recomputes them so often that they make the corrector hundreds of times slower
    (benchmarks/NOTES.md)."""
    g0, d0, e0, g1, d1, e1 = q
    c = num.quintic(g0, h * d0, h * h * e0, g1, h * d1, h * h * e1)
    end = jnp.clip((t1 - t0) / jnp.where(h > 0, h, 1), 0, 1)
    p = lambda th, c: c[0] + th * (c[1] + th * (c[2] + th * (c[3] + th * (c[4] + th * c[5]))))
    dp = lambda th, c: c[1] + th * (2 * c[2] + th * (3 * c[3] + th * (4 * c[4] + th * 5 * c[5])))
    ddp = lambda th, c: 2 * c[2] + th * (6 * c[3] + th * (12 * c[4] + th * 20 * c[5]))
    pe = p(end, c)
    lo, hi = jnp.minimum(g0, pe), jnp.maximum(g0, pe)
    cs, ends = jax.lax.stop_gradient((c, end))
    dp0, dpe = cs[1], dp(ends, cs)
    inside = dp0 * dpe < 0
    th = ends * dp0 / jnp.where(inside, dp0 - dpe, 1)
    for _ in range(3):
        curv = ddp(th, cs)
        th = jnp.clip(th - dp(th, cs) / jnp.where(curv != 0, curv, 1), 0, ends)
    pm = p(th, c)
    return jnp.where(inside, jnp.minimum(lo, pm), lo), jnp.where(inside, jnp.maximum(hi, pm), hi)


class _Acc(NamedTuple):
    """What `_advance` accumulates besides the state."""

    stuck: tuple  # time each mass was stuck
    margin: Array  # smallest -(stick margin) at a slipping mass's velocity zero (inf: none)
    n_min: Array  # smallest normal load over the committed steps
    slid: tuple  # whether each mass slipped at all
    sequence: Array  # the order of the bodies' mode changes (`_sequence`)


SEQUENCE_PRIME = 16777619
"""The multiplier of `_sequence`'s code (FNV's 32-bit prime): odd, so no change is lost to the wrap."""


def _modes(s: Any) -> list[Array]:
    """Per entry of a hybrid state (`engine.Hybrid`: `stuck`, `sdir`, `fly`), each body's contact mode:
    0 stuck, 1 slipping forwards, 2 backwards, 3 in flight."""
    fly = s.fly if s.fly is not None else tuple(jnp.zeros(jnp.shape(b), bool) for b in s.stuck)
    return [jnp.where(f, 3, jnp.where(b, 0, jnp.where(d > 0, 1, 2))) for b, d, f in zip(s.stuck, s.sdir, fly)]


def _sequence(code: Array, before: Any, after: Any) -> Array:
    """The sequence code after a step, in uint32 (wrapping): where a body's mode changed, `code`
    times `SEQUENCE_PRIME` plus the step's changes as a base-5 number, whose digit $i$ is 0 where
    body $i$ kept its mode and its new mode + 1 where it changed. The digits keep apart changes made
    in one step (mass 0 starts to slip as mass 1 sticks, and the other way round), exactly for up
    to 13 bodies ($5^{13} < 2^{32}$); the multiplication orders the steps. Two periods with the same
    switch and landing counts but another order of events, or the same events at other bodies, get
    other codes (up to a collision of the hash): a change of switching structure that the counts
    miss."""
    terms, changed, offset = [], [], 0
    for old, new in zip(_modes(before), _modes(after)):
        n = 1 if jnp.ndim(new) == 0 else jnp.shape(new)[-1]
        digit = np.array([pow(5, offset + i, 2**32) for i in range(n)], np.uint32).reshape(jnp.shape(new))
        terms.append(jnp.where(old != new, (new.astype(jnp.uint32) + 1) * digit, jnp.uint32(0)))
        changed.append((old != new).astype(jnp.int32))
        offset += n
    step = num.total(terms)
    return jnp.where(num.total(changed) > 0, code * jnp.uint32(SEQUENCE_PRIME) + step, code)


def _step(P, contact, dt, st, t_end):
    """One engine step (under `contact="hop"` with the physics' restitution and Zeno speed)."""
    return engine.step(P, contact, dt, st, t_end, hop=P.hop()[2:] if contact == "hop" else None)


def _advance(P, contact, dt, st, t_end, max_steps):
    """Integrate to `t_end` (or a strict lift-off, or the step cap); also what [`_Acc`][] holds."""
    inf = jnp.asarray(jnp.inf, st.t.dtype)

    def cond(c):
        s, _, n = c
        return (s.t < t_end) & (s.status == Status.OK) & (n < max_steps)

    def body(c):
        s, a, n = c
        new, info = _step(P, contact, dt, s, t_end)
        span = jnp.where(info.commit, info.t1 - info.t0, 0)
        # eq. (7) generalised: a slipping mass whose velocity reached zero sticks where its stick
        # margin is >= 0; the slip margin is its negative ($|F_i| - \\mu_s n_i$ for Coulomb friction).
        margin = num.least([a.margin] + [jnp.where(info.commit & z, -q, inf) for z, q in zip(info.vel, info.hold)])
        lows = tuple(_range(q, info.h, info.t0, info.t1)[0] for q in zip(*info.normal))
        low = num.least([inf, *contact_loads(P, lows, inf)])
        a = _Acc(
            stuck=tuple(q + jnp.where(b, span, 0) for q, b in zip(a.stuck, info.stuck)),
            margin=margin,
            n_min=jnp.minimum(a.n_min, jnp.where(info.commit, low, inf)),
            slid=tuple(q | (~b & (span > 0)) for q, b in zip(a.slid, info.stuck)),
            sequence=_sequence(a.sequence, s, new),
        )
        return new, a, n + 1

    zero = tuple(jnp.zeros_like(a) for a in st.y.x)
    init = _Acc(zero, inf, inf, tuple(jnp.zeros(jnp.shape(a), bool) for a in st.y.x), jnp.zeros((), jnp.uint32))
    st, acc, _ = lane_while_loop(cond, body, (st, init, jnp.zeros((), jnp.int32)))
    return st, acc


def period_map(P, contact, dt, max_steps, k, y) -> _Period:
    """$\\Phi_k(y)$ and what the $k$ periods accumulate ([`_Period`][]).

    A normal load that dips below zero between two step ends (a grazing excursion shorter than
    the step, which the engine does not locate) still counts: under the strict reading such a
    period ends with `Status.LIFTOFF` like a located one, so that lift-off does not depend on the
    step."""
    t_end = k * (2 * jnp.pi) / P.omega
    st0 = _section_state(P, contact, y)
    st, a = _advance(P, contact, dt, st0, t_end, max_steps)
    ok = (st.status == Status.OK) & (st.t >= t_end)
    status = jnp.where(ok, Status.OK, jnp.where(st.status == Status.OK, Status.MAX_STEPS, st.status))
    lifted = jnp.isfinite(st.t_liftoff)
    if contact == "strict":
        status = jnp.where(a.n_min < 0, Status.LIFTOFF, status)
    if contact != "hop":
        lifted = lifted | (a.n_min < 0)
    slid = jnp.all(_flat(a.slid))
    return _Period(
        y=_reduced(st, P),
        dX=displacement(P, st0, st),
        ed=st.y.ed,
        w=st.y.w,
        stuck=_flat(a.stuck),
        n_switch=st.n_switch,
        status=status.astype(jnp.int32),
        lifted=lifted,
        # A mass that never slips is stuck throughout: a stick interval without a velocity zero.
        margin=jnp.where(slid, a.margin, -jnp.inf),
        n_min=a.n_min,
        n_land=jnp.zeros((), jnp.int32) if st.n_land is None or st0.n_land is None else st.n_land - st0.n_land,
        sequence=a.sequence,
    )


def mechanism_physics(c) -> tuple[AbstractPhysics, Array]:
    """`(physics, valid)` of one configuration of a mechanism of the N-body path (a [`Chain`][], a
    [`Mechanism`][locomotion_jax.Mechanism])."""
    return c.physics(), c.is_valid()


def array_mechanism_physics(c) -> tuple[AbstractPhysics, Array]:
    """[`mechanism_physics`][] in the array layout (`model._chain_array`, `model._mechanism_array`):
    the bodies as one entry, so that the corrector's program does not grow with N."""
    return c.array_physics(), c.is_valid()


def physics_for(mechanism: Chain | Mechanism) -> Callable[[Any], tuple[AbstractPhysics, Array]]:
    """The `physics_of` of a mechanism's gaits: in the array layout for a chain's `layout="array"`,
    or `"auto"` from `GAIT_ARRAY_FROM` masses on (`model._chain_array.uses_array`), else one entry
    per body."""
    return array_mechanism_physics if uses_array(mechanism, GAIT_ARRAY_FROM) else mechanism_physics


def paper_physics(c) -> tuple[AbstractPhysics, Array]:
    """`(physics, valid)` of one configuration `(params, waveform)` of the paper's model: the
    two-mass chain ([`Params.physics`][locomotion_jax.Params.physics]) of its parameters, an
    invalid set replaced by the defaults (`safe_params`), and their validity."""
    _, P, valid = paper.physics(*c)
    return P, valid


def _transient_batch(C, physics_of, valid, contact, start, dt, transient, max_steps, y_start=None):
    """The reduced states after `transient` actuation periods from the start at rest `start`, or
    from the section states `y_start` (flat, `(n, 2N - 1)`, under `contact="hop"` `(n, 4N - 1)`:
    the heights and vertical velocities after) where given, their statuses, whether
    they lifted off, and the centre of mass's displacement over the periods; each configuration of
    the flat batch `C` has the physics `physics_of(c)`."""

    def one(c, ok, y):
        P, ok_c = physics_of(c)
        base = reduced_size(P)  # positions then velocities, under "hop" the heights and vertical velocities after
        row = None if y is None else jnp.concatenate([_positions(P, y), y[base - P.n_bodies :]])
        st0 = chain_initial_state(P, ok & ok_c, contact, start, row)
        st, _ = _advance(P, contact, dt, st0, transient * (2 * jnp.pi) / P.omega, max_steps)
        dX = P.centre_of_mass(st.y.x) - P.centre_of_mass(st0.y.x)
        return _reduced(st, P), st.status, jnp.isfinite(st.t_liftoff), dX

    return jax.vmap(one)(C, valid, y_start)


# `dt` traced: a solve at another step (the optimiser's check at dt/2) reuses the program.
_transient_batch = engine_jit(_transient_batch, ("physics_of", "contact", "start"))


COMPACT = 4
"""`solve(compact=True)`: a gait period tried on at most `1 / COMPACT` of the batch (fewer than
that many configurations still open) runs on a batch of that size."""


def newton(C, physics_of, contact, dt, y0, go, k, tol, max_iter, max_steps, compact: bool = False,
           patience: int | None = None, key: np.ndarray | None = None) -> dict:  # fmt: skip
    """Newton's method on $\\Phi_k(y) = y$ from `y0` where `go`: the continuation's corrector
    ([`_corrector`][]) with the parameter held (no parameter selected, arclength scale 0),
    a configuration stopped after `patience` iterations without progress (`None`: `max_iter`).

    The batch runs in lockstep (every row costs what the slowest one does), so with `compact`
    the rows to solve, when fewer than `B // COMPACT`, are gathered into a batch of
    `B // COMPACT` rows (one more compiled program per batch size; each row's result is the
    same, the rows being independent) and the rest take a padding row's unsolved result; when
    more, the whole batch runs as batches of `B // COMPACT` rows in the order of `key` (host;
    `solve` passes each row's forcing period over $2\\pi$, $1/\\omega$), so that the long periods
    share batches and the short ones do not wait for them: the same program, and the same result
    per row."""
    from . import _corrector as corrector

    B, n = y0.shape
    go_rows = np.flatnonzero(np.asarray(go))
    part = B // COMPACT
    if compact and part > 0 and go_rows.size >= part and key is not None:
        order = np.argsort(np.asarray(key, float), kind="stable")
        order = np.concatenate([order, np.full((-B) % part, order[-1])])
        go_np = np.asarray(go)
        subs = []
        for j in range(0, order.size, part):
            rows = order[j : j + part]
            sub_go = go_np[rows] & (np.arange(j, j + part) < B)  # a padding row is not solved
            subs.append(newton(jax.tree_util.tree_map(lambda x: x[rows], C), physics_of, contact, dt,
                               jnp.asarray(y0)[rows], jnp.asarray(sub_go), k, tol, max_iter, max_steps,
                               patience=patience))  # fmt: skip
        back = np.empty(B, int)
        back[order[:B]] = np.arange(B)
        return jax.tree_util.tree_map(lambda *xs: np.concatenate(xs)[back] if np.ndim(xs[0]) else xs[0], *subs)
    if compact and 0 < go_rows.size < part:
        m = go_rows.size
        rows = np.concatenate([go_rows, np.full(part - m, go_rows[0])])
        sub = newton(jax.tree_util.tree_map(lambda x: x[rows], C), physics_of, contact, dt, jnp.asarray(y0)[rows],
                     jnp.asarray(np.arange(part) < m), k, tol, max_iter, max_steps, patience=patience)  # fmt: skip
        back = np.full(B, part - 1)  # a padding row: not solved (`done` False)
        back[go_rows] = np.arange(m)
        return jax.tree_util.tree_map(lambda x: x[back] if np.ndim(x) else x, sub)
    dtype = y0.dtype
    z0 = jnp.concatenate([jnp.asarray(y0, dtype), jnp.zeros((B, 1), dtype)], axis=1)
    c = jnp.zeros((B, n + 1), dtype).at[:, n].set(1)
    zero = jnp.zeros((B,), dtype)
    sel = corrector.no_selection(C)
    r = corrector.correct_batch(C, physics_of, sel, contact, dt, jnp.full((B,), k, dtype), zero, zero, z0, z0, c,
                                jnp.asarray(go), jnp.asarray(tol, dtype), jnp.asarray(max_iter, jnp.int32),
                                jnp.asarray(max_steps, jnp.int32),
                                jnp.asarray(max_iter if patience is None else patience, jnp.int32))  # fmt: skip
    r = jax.tree_util.tree_map(np.asarray, r)
    y = r.z[:, :n]
    return dict(y=y, M=r.J[:, :n, :n], out=r.out, it=r.it, done=r.done, residual=np.max(np.abs(r.out.y - y), axis=1))


class GaitProblem(NamedTuple):
    """The steady gaits to solve, as a mechanism hands them to the solver
    ([`AbstractMechanism.gait_problem`][locomotion_jax.model._mechanism.AbstractMechanism.gait_problem]):
    a flat batch of configurations `configs`, each integrated with the physics
    `physics_of(config) -> (physics, valid)`; which run (`valid`), which the resolution guard skips
    (`unresolved`, or `None`), the batch `shape`, the forcing frequencies `omega` (host, flat), the
    floating `dtype`, the start at rest `start` or the flat section states `y_start` to start from
    instead, and how the [`Gait`][] names its arrays (`names`)."""

    configs: Any
    physics_of: Callable[[Any], tuple[AbstractPhysics, Array]]
    valid: Array
    unresolved: Array | None
    shape: tuple[int, ...]
    omega: np.ndarray
    dtype: Any
    start: str
    y_start: Array | None = None
    names: str = BODIES


def bodies_problem(mechanism: Any, dynamics: Exact, contact: str, start: str | ArrayLike,
                   dtype: Any, guarded: bool = True) -> GaitProblem:  # fmt: skip
    """The [`GaitProblem`][] of a [`Chain`][] or a [`Mechanism`][locomotion_jax.Mechanism]: `start` names a
    start at rest (a mechanism: its own `x0`, `v0`), or gives section states at phase 0: gaps then
    velocities $(u_0, \\dots, u_{N-2}, v_0, \\dots, v_{N-1})$, shape `batch + (2N - 1,)`, or for an
    anchored mechanism positions then velocities, `batch + (2N,)`; under `contact="hop"` followed by
    the heights $y_i \\ge 0$ and vertical velocities $w_i$ (a [`Gait`][]'s `state`). Checks the input
    (`ValueError`, `NotImplementedError`) and the step's resolution (refused alone, skipped in a
    batch; `guarded=False` skips that: only for a search whose figures only steer, verified at a
    resolved step)."""
    check_contact_start(contact, start if isinstance(start, str) else "paper", mechanism)
    flat, valid, shape = prepare_chain(mechanism, dtype)
    unresolved = None
    if guarded:
        valid, unresolved = guard_chain(dynamics, flat, valid, shape)  # refused alone, skipped in a batch
    y_start = None
    if not isinstance(start, str):
        P = flat.physics()
        base, n = reduced_size(P), P.n_bodies
        hop = contact == "hop"
        n_red = base + (2 * n if hop else 0)
        what = ("positions x_0..x_N-1" if P.anchored else "gaps u_0..u_N-2") + ", velocities v_0..v_N-1"
        what += ", heights y_0..y_N-1 >= 0, vertical velocities w_0..w_N-1" if hop else ""
        y = np.asarray(start, np.float64)
        fits = y.shape == shape + (n_red,)
        low = fits and hop and bool(np.any(y[..., base : base + n] < 0))
        if not fits or not np.all(np.isfinite(y)) or low:
            got = f"shape {y.shape}" + ("" if not fits else ", a height < 0" if low else ", not all finite")
            raise ValueError(
                f"start must be 'paper', 'relaxed' or finite section states ({what}) of shape {shape + (n_red,)}, "
                f"got {got}."
            )
        if shape == ():  # refused alone
            mechanism.check_section(y)
        y_start = jnp.asarray(y.reshape(-1, n_red), flat.m.dtype)
        start = "paper"
    omega = np.asarray(flat.omega, np.float64)
    return GaitProblem(flat, physics_for(flat), valid, unresolved, shape, omega, flat.m.dtype, start, y_start)


def steady_gaits(
    problem: GaitProblem,
    *,
    periods: int | Sequence[int] = (1, 2, 3, 4),
    transient: int = 30,
    tol: float | None = None,
    max_iter: int = 12,
    dynamics: Exact,
    contact: str = "strict",
    say=lambda message: None,
    patience: int | None = None,
    compact: bool = False,
    bucket: bool = False,
) -> Gait:
    """The [`Gait`][] of every configuration of `problem` ([`steady_gait`][]'s arguments; `patience` and
    `compact` as in [`newton`][]: the optimisers' screens). With `bucket`, solved as the rows of the
    batch's bucket ([`gait_rows`][locomotion_jax.gaits._shooting.gait_rows],
    [`in_rows`][locomotion_jax.gaits._shooting.in_rows]), so that the batch sizes of a bucket share
    the compiled programs."""
    n = int(np.prod(problem.shape, dtype=np.int64))
    rows = BatchRows(n, gait_rows(n) if bucket else n)
    p = problem if rows.m == n else in_rows(problem, rows)
    best = solve(p.configs, p.physics_of, p.valid, p.unresolved, p.shape, p.omega, periods=periods,
                 transient=transient, tol=tol, max_iter=max_iter, dynamics=dynamics, contact=contact, start=p.start,
                 y_start=p.y_start, say=say, compact=compact, patience=patience)  # fmt: skip
    if rows.m != n:  # host arrays: cut here, not by `BatchRows.cut`'s compiled slice
        best = jax.tree_util.tree_map(lambda x: x[:n], best)
    return unflatten(as_gait(best, problem.dtype, contact, problem.names), problem.shape)


def gait_rows(n: int) -> int:
    """The rows a batch of `n` steady gaits is solved as: the next power of two up to
    `_runs.MICRO_BATCH_CPU`, then `_runs.batch_rows`' four sizes per octave. The rows of a gait's
    solve run in lockstep, a padding row costing about what a real one does (a 3-mass worm's warm
    solve took 3.2 times as long padded to 16 rows as alone), so small batches are padded less than
    `batch_rows` pads them."""
    if n <= 1:
        return n
    return 1 << (n - 1).bit_length() if n <= MICRO_BATCH_CPU else batch_rows(n)


def in_rows(problem: GaitProblem, rows: BatchRows) -> GaitProblem:
    """`problem` as `rows.m` rows (`BatchRows.pad`: the last configuration repeated), the padding
    flagged invalid, so that it is not solved (its transient stops at once)."""
    no = lambda mask: jnp.concatenate([jnp.asarray(mask), jnp.zeros(rows.m - rows.n, bool)])
    omega = np.broadcast_to(problem.omega, (rows.n,))  # host, in float64 whatever JAX's default
    return problem._replace(
        configs=rows.pad(problem.configs),
        valid=no(problem.valid),
        unresolved=None if problem.unresolved is None else no(problem.unresolved),
        shape=(rows.m,),
        omega=np.concatenate([omega, np.repeat(omega[-1:], rows.m - rows.n)]),
        y_start=None if problem.y_start is None else rows.pad(problem.y_start),
    )


def steady_gait_chain(
    chain: Chain | Mechanism,
    *,
    dynamics: Exact,
    contact: str = "strict",
    start: str | ArrayLike = "paper",
    dtype: Any = None,
    guarded: bool = True,
    **kwargs: Any,
) -> Gait:
    """[`steady_gait`][] of a [`Chain`][] or a [`Mechanism`][locomotion_jax.Mechanism] with the solver's
    own options (`patience`, `compact`: [`steady_gaits`][]; `guarded`: [`bodies_problem`][]; the
    chain optimiser's screen)."""
    return steady_gaits(bodies_problem(chain, dynamics, contact, start, dtype, guarded), dynamics=dynamics,
                        contact=contact, **kwargs)  # fmt: skip


def _transient_setup(valid, omega: np.ndarray, shape, transient: int, dynamics: Exact):
    """`(valid, T_max, max_steps)` of a transient: `valid` without the configurations whose
    actuation is not periodic, the longest period, and the transient's step cap."""
    valid = valid & jnp.asarray(select.periodic(omega, shape))
    T_max = float(np.max(2 * np.pi / omega[np.isfinite(omega) & (omega > 0)], initial=1.0))
    mst = jnp.asarray(dynamics.max_steps or default_max_steps(transient * T_max, dynamics.dt), jnp.int32)
    return valid, T_max, mst


def transient_speed(chain: Chain, *, transient: int, last: int, dynamics: Exact, contact: str = "strict",
                    start: str = "relaxed", guarded: bool = True) -> np.ndarray:  # fmt: skip
    """The centre of mass's mean speed over periods `transient - last` to `transient` of the
    actuation from the start at rest `start`: the end of [`steady_gait`][]'s transient, whose first
    `transient - last` periods this runs with the same compiled program. A host array of the batch
    shape, NaN where the run stopped (invalid, unresolved, a strict lift-off, a collision, the step
    cap). Over `last = 12` periods it is the mean speed of a converged gait of any period
    $k \\le 4$ (12 periods are whole gait periods); the chain optimiser's screen compares it
    with the required speed before solving the gait. `guarded`: as [`bodies_problem`][]'s."""
    if not (isinstance(last, int) and 1 <= last < transient):
        raise ValueError(f"transient_speed: need 1 <= last < transient, got last={last!r}, transient={transient!r}.")
    pb = bodies_problem(chain, dynamics, contact, start, None, guarded)  # the steady gait's configurations and guard
    omega = np.broadcast_to(pb.omega, pb.valid.shape)
    valid, _, mst = _transient_setup(pb.valid, omega, pb.shape, transient, dynamics)
    real = lambda v: jnp.asarray(v, pb.dtype)
    C, physics_of, dt = pb.configs, pb.physics_of, dynamics.dt
    y, st1, _, _ = _transient_batch(C, physics_of, valid, contact, start, dt, real(transient - last), mst)
    _, st2, _, dX = _transient_batch(C, physics_of, valid, contact, "paper", dt, real(last), mst, y)
    ok = (np.asarray(st1) == Status.OK) & (np.asarray(st2) == Status.OK)
    if pb.unresolved is not None:
        ok &= ~np.asarray(pb.unresolved)
    speed = np.where(ok, np.asarray(dX, np.float64) * omega / (2 * np.pi * last), np.nan)
    return speed.reshape(pb.shape)


def solve(C, physics_of, valid, unresolved, shape, omega, *, periods, transient, tol, max_iter, dynamics: Exact,
          contact, start, y_start=None, say=lambda message: None, compact: bool = False,
          patience: int | None = None) -> dict:  # fmt: skip
    """The steady gaits of the flat batch `C` of configurations (physics `physics_of(c)`; `valid`,
    the resolution guard's `unresolved` mask or `None`, batch `shape`, forcing frequencies `omega`):
    the transient, then Newton's method for each gait period in turn ([`steady_gait`][]). Returns the
    host results of [`_select.judge`][] of the best period per configuration, and `omega`.
    `compact`, `patience`: see [`newton`][]; `say` reports each stage (`steady_gait(verbose=True)`)."""
    omega = np.broadcast_to(omega, valid.shape)
    dtype_ = jax.tree_util.tree_leaves(C)[0].dtype
    f32 = jnp.finfo(dtype_).bits < 64
    tol = (1e-5 if f32 else 1e-11) if tol is None else float(tol)
    ks = select.check(periods, transient, tol, max_iter)
    valid, T_max, mst = _transient_setup(valid, omega, shape, transient, dynamics)
    real = lambda v: jnp.asarray(v, dtype_)
    say(f"transient: {transient} periods")
    y0, trans, trans_lift, _ = _transient_batch(C, physics_of, valid, contact, start, dynamics.dt, real(transient), mst,
                                             y_start)  # fmt: skip
    trans = np.asarray(trans)
    # -1: to be solved; else the final status (invalid, a strict lift-off, a collision, a step that
    # did not resolve a kink, the step cap).
    base = np.select(
        [
            trans == Status.INVALID,
            trans == Status.LIFTOFF,
            trans == Status.COLLISION,
            trans == Status.UNRESOLVED,
            trans != Status.OK,
        ],
        [GaitStatus.INVALID, GaitStatus.LIFTOFF, GaitStatus.COLLISION, GaitStatus.UNRESOLVED, GaitStatus.NOT_CONVERGED],
        -1,
    )
    base = select.unresolved(base, unresolved)
    with np.errstate(divide="ignore"):
        key = 1 / omega.ravel()  # the batches' order: a row of omega = 0 (undriven or invalid) goes last
    best = None
    for k in ks:
        msp = dynamics.max_steps or default_max_steps(k * T_max, dynamics.dt)
        go = (base < 0) & (True if best is None else select.still_open(best))
        say(f"gait period {k}: Newton on {int(np.sum(go))} configuration(s)")
        r = newton(C, physics_of, contact, dynamics.dt, y0, go, k, tol, max_iter, msp, compact, patience, key)
        r = select.judge(r, base, k, (base != GaitStatus.INVALID) & (np.asarray(trans_lift) | r["out"].lifted))
        best = select.better(best, r)
        if not np.any(select.still_open(best)):
            break
    assert best is not None
    return dict(best, omega=omega)


def as_gait(r: dict, dtype: Any, contact: str, names: str = BODIES) -> Gait:
    """The solver's host results `r` (of [`solve`][], its forcing frequencies `r["omega"]` included) as a
    [`Gait`][] (NaN where not converged)."""
    ok, omega = r["status"] == GaitStatus.CONVERGED, r["omega"]
    nan = lambda x: jnp.asarray(np.where(select.expand(ok, x), x, np.nan), dtype)
    out: _Period = r["out"]
    kT = np.where(ok, r["k"] * 2 * np.pi / np.where(ok, omega, 1), np.nan)
    dX = out.dX
    ssl = np.max(out.stuck, axis=-1) > STICK_TOL
    return Gait(
        status=jnp.asarray(r["status"]),
        converged=jnp.asarray(ok),
        k=jnp.asarray(r["k"], jnp.int32),
        period=jnp.asarray(kT, dtype),
        mean_speed=nan(dX / np.where(ok, kT, 1)),
        e_d=nan(out.ed),
        work=nan(out.w),
        cost_of_transport=nan(select.ratio(out.ed, np.abs(dX), ok)),
        stick_fraction=nan(out.stuck / np.where(ok, kT, 1)[:, None]),
        regime=jnp.asarray(np.where(ok, np.where(ssl, Regime.SSL, Regime.SL), Regime.UNDETERMINED), jnp.int32),
        n_switch=jnp.asarray(np.where(ok, out.n_switch, 0), jnp.int32),
        n_land=jnp.asarray(np.where(ok, out.n_land, 0), jnp.int32),
        state=nan(r["y"]),
        monodromy=nan(r["M"]),
        multipliers=jnp.asarray(r["multipliers"]),
        stable=jnp.asarray(r["stable"]),
        residual=jnp.asarray(r["residual"], dtype),
        n_iter=jnp.asarray(r["it"]),
        liftoff=jnp.asarray(r["lifted"]),
        slip_margin=nan(out.margin),
        min_normal=nan(out.n_min),
        contact=contact,
        names=names,
    )
