"""The N-mass exact engine's measurements (SPEC §5 and §8), accumulated on the fly.

A flat batch through the work queue (`_queue.run_queue`; the paper's model too, through
`_paper`), each configuration stopping on its own, with running sums only, so memory does
not grow with the number of steps.

Under `contact="hop"` (SPEC §10) also, over the window like the stick fractions: each body's
time in flight, the landings, and the highest height (each step's top in flight from the
cubic Hermite interpolant of $y$ through its ends' heights and vertical velocities).
"""

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from .._custom_types import Array
from .._status import Regime, Status
from ..model._physics import AbstractPhysics, loads_at
from . import _engine as engine
from ._compile import engine_jit
from ._margins import margin_fields
from ._numerics import Target, target_margin
from ._queue import run_queue
from ._runs import BatchRows, chain_initial_state, default_lanes, start_code, step_cap, STICK_TOL


class _Acc(eqx.Module):
    started: jax.Array
    X0: jax.Array
    ed0: jax.Array
    w0: jax.Array
    e0: jax.Array
    reached: jax.Array
    t_z: jax.Array
    y_z: engine.State
    stuck: tuple[jax.Array, ...]  # stuck time per mass
    steps: jax.Array
    before_z: jax.Array  # time from the last switch to t_z
    # contact="hop" only (else None): flight time and highest height per body, landings
    flight: tuple[jax.Array, ...] | None = None
    top: tuple[jax.Array, ...] | None = None
    landings: jax.Array | None = None


class _Fixed(NamedTuple):
    P: AbstractPhysics
    ws: jax.Array
    we: jax.Array
    te: jax.Array
    z: jax.Array
    cap: jax.Array  # the step cap of this configuration (`_runs.step_cap`)


def _setup(P: AbstractPhysics, valid, t_start, row, z, horizon, window, contact, start, dt, max_steps):
    """`(fixed, dyn)` of one configuration; `row` its initial state or `None`; `max_steps` an
    explicit step cap, or 0 for the default from its own span $t_\\text{start}$ + `horizon`
    (`_runs.step_cap`)."""
    st = chain_initial_state(P, valid, contact, start, row)
    dtype = st.t.dtype
    ws = t_start.astype(dtype)
    zero = jnp.zeros((), dtype)
    no = jnp.asarray(False)
    acc = _Acc(
        started=no, X0=zero, ed0=zero, w0=zero, e0=zero, reached=no, t_z=jnp.asarray(jnp.inf, dtype),
        y_z=st.y.map(jnp.zeros_like), stuck=tuple(map(jnp.zeros_like, st.y.x)), steps=jnp.zeros((), jnp.int32),
        before_z=jnp.asarray(jnp.inf, dtype),
    )  # fmt: skip
    if contact == "hop":
        acc = eqx.tree_at(
            lambda a: (a.flight, a.top, a.landings), acc,
            (tuple(map(jnp.zeros_like, st.y.x)), tuple(map(jnp.zeros_like, st.y.x)), jnp.zeros((), jnp.int32)),
            is_leaf=lambda q: q is None,
        )  # fmt: skip
    te = ws + horizon
    return _Fixed(P, ws, ws + window, te, jnp.asarray(z, dtype), step_cap(te, dt, max_steps)), (st, acc)


def _finished(f: _Fixed, s, a):
    return (s.t >= f.te) | (a.reached & (s.t >= f.we))


def _running(f: _Fixed, dyn):
    s, a = dyn
    return (s.status == Status.OK) & ~_finished(f, s, a) & (a.steps < f.cap)


def _advance(f: _Fixed, dyn, contact, dt):
    s, a = dyn
    # Steps end at the start, at the window's end and at the horizon, whichever comes first.
    t_stop = jnp.where(s.t < f.ws, f.ws, jnp.where(s.t < f.we, jnp.minimum(f.we, f.te), f.te))
    begin = ~a.started & (s.t >= f.ws)
    started = a.started | begin
    X0 = jnp.where(begin, f.P.centre_of_mass(s.y.x), a.X0)
    target = Target(active=started & ~a.reached, X0=X0, z=f.z)
    # The margins cover the measured interval: they restart at t_start.
    s = eqx.tree_at(lambda s: (s.cross, s.near), s, tuple(jnp.where(begin, jnp.inf, m) for m in (s.cross, s.near)))
    hop = f.P.hop()[2:] if contact == "hop" else None
    s_new, info = engine.step(f.P, contact, dt, s, t_stop, target, hop=hop)
    inside = info.commit & started & (info.t1 <= f.we)
    dur = jnp.where(inside, info.t1 - info.t0, 0)
    hit = info.target_fired
    a_new = _Acc(
        started=started, X0=X0, ed0=jnp.where(begin, info.y0.ed, a.ed0), w0=jnp.where(begin, info.y0.w, a.w0),
        e0=jnp.where(begin, engine.energy(f.P, info.y0, info.loads0), a.e0), reached=a.reached | hit,
        t_z=jnp.where(hit, info.t_target, a.t_z), y_z=info.y_target.map(lambda n, o: jnp.where(hit, n, o), a.y_z),
        stuck=tuple(q + jnp.where(b, dur, 0) for q, b in zip(a.stuck, info.stuck)), steps=a.steps + 1,
        before_z=jnp.where(hit, jax.lax.stop_gradient(info.t_target - s.t_switch), a.before_z),
    )  # fmt: skip
    if a.flight is not None and a.top is not None and a.landings is not None:
        assert s_new.fly is not None and s.n_land is not None and s_new.n_land is not None
        assert info.y0.y is not None and info.y0.vy is not None and info.y1.y is not None and info.y1.vy is not None
        # The landings applied at this step's start (time t0), counted inside [t_start, t_start + window).
        at_start = started & (info.t0 < f.we)
        landed = jnp.where(at_start, s_new.n_land - s.n_land, 0)
        h = info.t1 - info.t0
        tops = [_top(y0, w0, y1, w1, h) for y0, w0, y1, w1 in zip(info.y0.y, info.y0.vy, info.y1.y, info.y1.vy)]
        a_new = eqx.tree_at(
            lambda q: (q.flight, q.top, q.landings), a_new,
            (tuple(q + jnp.where(fl, dur, 0) for q, fl in zip(a.flight, s_new.fly)),
             tuple(jnp.where(inside & fl, jnp.maximum(q, p), q) for q, p, fl in zip(a.top, tops, s_new.fly)),
             a.landings + landed),
            is_leaf=lambda q: q is None,
        )  # fmt: skip
    return s_new, a_new


def _top(y0, w0, y1, w1, h):
    """The highest value over a step of length `h` of the cubic Hermite interpolant through heights
    `y0`, `y1` with rates `w0`, `w1` at its ends: the ends and the roots in $[0, 1]$ of its
    derivative $A\theta^2 + B\theta + C$ (stable quadratic roots; no root: the ends)."""
    dy = y0 - y1
    A = 6 * dy + 3 * h * (w0 + w1)
    B = -6 * dy - h * (4 * w0 + 2 * w1)
    C = h * w0
    disc = B * B - 4 * A * C
    ok = disc >= 0
    sq = jnp.sqrt(jnp.where(ok, disc, 0))
    q = -0.5 * (B + jnp.where(B >= 0, sq, -sq))
    safe = lambda num, den: jnp.where(ok & (den != 0), num / jnp.where(den != 0, den, 1), 0)
    best = jnp.maximum(y0, y1)
    for th in (safe(q, A), safe(C, q)):
        th = jnp.clip(th, 0, 1)
        p = (2 * th**3 - 3 * th**2 + 1) * y0 + (th**3 - 2 * th**2 + th) * h * w0
        p = p + (3 * th**2 - 2 * th**3) * y1 + (th**3 - th**2) * h * w1
        best = jnp.maximum(best, p)
    return best


def _energy_at(P: AbstractPhysics, t, y):
    dr = P.drive(jnp.cos(P.omega * t), jnp.sin(P.omega * t))
    return engine.energy(P, y, loads_at(P, dr, y.x, y=y.y))


def _margin_z(f: _Fixed, a: _Acc, contact) -> jax.Array:
    """The time from $t_z$ to the nearest change of the target's structure (`_numerics.target_margin`)."""
    t_z = jnp.where(a.reached, a.t_z, f.ws)
    g, d, e = engine.probe(f.P, contact, t_z, a.y_z, Target(active=jnp.asarray(True), X0=a.X0, z=f.z))
    return target_margin(a.before_z, g, d, e)


def _results(f: _Fixed, dyn, contact) -> dict:
    s, a = dyn
    ws, we, z = f.ws, f.we, f.z
    dtype = ws.dtype
    status = jnp.where((s.status == Status.OK) & ~_finished(f, s, a), Status.MAX_STEPS, s.status).astype(jnp.int32)
    nan, inf = jnp.asarray(jnp.nan, dtype), jnp.asarray(jnp.inf, dtype)
    stuck = f.P.stacked(a.stuck)
    regime = jnp.where(s.t >= we, jnp.where(jnp.max(stuck) > STICK_TOL, Regime.SSL, Regime.SL), Regime.UNDETERMINED)
    t_end = jnp.where(a.reached, a.t_z, s.t)
    y_end = a.y_z.map(lambda zv, sv: jnp.where(a.reached, zv, sv), s.y)
    elapsed = t_end - ws
    measured = a.started & (elapsed > 0)
    mean_speed = jnp.where(measured, (f.P.centre_of_mass(y_end.x) - a.X0) / jnp.where(measured, elapsed, 1), nan)
    e_d = jnp.where(a.started, y_end.ed - a.ed0, nan)
    work = jnp.where(a.started, y_end.w - a.w0, nan)
    delta_e = jnp.where(a.started, _energy_at(f.P, t_end, y_end) - a.e0, nan)
    # A state that left the floating-point range (a spring stretched by 1e300: its energy overflows)
    # is the integration's failure, never an OK run with NaN figures.
    overflow = a.started & ~jnp.isfinite(mean_speed + e_d + work + delta_e)
    status = jnp.where((status == Status.OK) & overflow, Status.SOLVER_FAILED, status).astype(jnp.int32)
    e_z = jnp.where(a.reached, y_end.ed - a.ed0, inf)
    covered = jnp.clip(jnp.minimum(s.t, we) - ws, 0, None)
    frac = jnp.where(covered > 0, stuck / jnp.where(covered > 0, covered, 1), nan)
    hop = {}
    if a.flight is not None and a.top is not None and a.landings is not None:
        periods = covered * f.P.omega / (2 * jnp.pi)
        hop = dict(
            flight_fraction=jnp.where(covered > 0, f.P.stacked(a.flight) / jnp.where(covered > 0, covered, 1), nan),
            landings_per_period=jnp.where(periods > 0, a.landings / jnp.where(periods > 0, periods, 1), nan),
            highest_hop=jnp.where(a.started, f.P.stacked(a.top), nan),
            zeno=jnp.asarray(s.zeno),
        )
    return dict(
        tau_z=jnp.where(a.reached, a.t_z - ws, inf), e_z=e_z, reached=a.reached, regime=regime.astype(jnp.int32),
        mean_speed=mean_speed, cost_of_transport=e_z / z, stick_fraction=frac, e_d=e_d, work=work,
        delta_e=delta_e, balance=work - e_d - delta_e, liftoff=jnp.isfinite(s.t_liftoff), t_liftoff=s.t_liftoff,
        status=status, t_start=ws, X_start=jnp.where(a.started, a.X0, nan), n_steps=a.steps, n_switch=s.n_switch,
        **margin_fields(a.started, a.reached, s.cross, s.near, _margin_z(f, a, contact), a.t_z - ws, nan),
        **hop,
    )  # fmt: skip


def _measure_batch(P, valid, t_start, initial, z, horizon, window, contact, start, dt, max_steps, lanes, count=None):
    n = valid.shape[0]
    row = lambda i: None if initial is None else initial[i]
    take = lambda i: (jax.tree_util.tree_map(lambda x: x[i], P), valid[i], t_start[i], row(i))
    setup = lambda i: _setup(*take(i), z, horizon, window, contact, start, dt, max_steps)
    advance = lambda f, d: _advance(f, d, contact, dt)
    results = lambda f, d: _results(f, d, contact)
    order = jnp.argsort(-jnp.where(jnp.isfinite(P.omega), P.omega, -jnp.inf))
    return run_queue(setup, _running, advance, results, n, lanes, order, count=count)


_measure_batch = engine_jit(_measure_batch, ("contact", "lanes"), reverse=True)


def measure_batch(
    physics: AbstractPhysics,
    valid,
    t_start,
    z,
    horizon,
    window,
    contact,
    start,
    dt,
    max_steps: Array | int,
    initial=None,
) -> dict:
    """The fields of a [`ChainMeasurement`][locomotion_jax.ChainMeasurement] of a flat batch of
    mechanisms given by their physics (every array field with the batch's leading axis: a flat
    chain's `physics()`, or the paper's model's), measured from `t_start` (one per
    configuration); `max_steps` caps each one's iterations (0: each one's own default from its
    span, `_runs.step_cap`); `initial`: the states at $t = 0$, shape `(n, 2N)` (positions, then
    velocities), or `None` for `start`'s. Compiled for the batch's bucket (`_runs.BatchRows`)."""
    dtype = physics.one.dtype
    z_, h_, w_ = (jnp.asarray(v, dtype) for v in (z, horizon, window))
    rows = BatchRows.of(valid.shape[0], physics, valid, t_start, initial, z_, h_, w_)
    P, valid, t_start, initial = rows.pad((physics, valid, t_start, initial))
    lanes = default_lanes(rows.m, physics.lane_width)
    cap = jnp.asarray(max_steps, jnp.int32)
    code = start_code(start)
    dt_ = jnp.asarray(dt, dtype)
    out = _measure_batch(P, valid, t_start, initial, z_, h_, w_, contact, code, dt_, cap, lanes, rows.queue_count)
    return rows.cut(out)
