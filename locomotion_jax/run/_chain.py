"""`simulate` and `measure` for chains of N masses (SPEC §5 and §8) on the N-mass exact engine.

The same loops as the two-mass front ends (`_simulate`, `_measure`): a flat batch
through the work queue (`_queue.run_queue`), each configuration stopping on its own;
`simulate` saves states at the requested times (`_saves.run_saves`), `measure` keeps
running sums only, so memory does not grow with the number of steps.
"""

import math
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._results import ChainMeasurement, ChainTrajectory
from .._status import Regime, Status
from ..dynamics import _chain_exact as engine, _chain_forces as forces, _chain_smooth as smooth
from ..dynamics._base import Exact, Smoothed
from ..dynamics._compile import engine_jit
from ..dynamics._exact import Target, target_margin
from ..dynamics._margins import margin_fields, switch_gap
from ..model._chain import Chain
from ._batch import default_max_steps, MICRO_BATCH_CPU
from ._queue import run_queue
from ._saves import BUFFER, run_saves


STICK_TOL = 1e-6
"""A mass counts as stuck in the window (SSL) only for a total stuck time above this."""


# -- batch preparation ------------------------------------------------------------------


def prepare_chain(chain: Chain, dtype: Any) -> tuple[Chain, jax.Array, tuple[int, ...]]:
    """Cast, broadcast and flatten; returns `(flat_chain, valid, batch_shape)`.

    An invalid configuration is replaced by a valid one of the batch (so nothing
    turns into NaN) and flagged in `valid`; its result says `Status.INVALID`.
    """
    if not isinstance(chain, Chain):
        raise TypeError(f"expected a locomotion_jax.Chain, got {type(chain).__name__}.")
    if dtype is not None:
        chain = chain.astype(dtype)
    chain = chain.broadcast()
    shape = chain.batch_shape
    size = math.prod(shape)
    if size == 0:
        raise ValueError("the chain batch is empty (a zero-length axis).")
    nb = len(shape)
    flat = jax.tree_util.tree_map(lambda x: x.reshape((size,) + x.shape[nb:]), chain)
    valid = flat.is_valid()
    try:
        ok = np.asarray(valid)
        fallback = int(np.argmax(ok)) if ok.any() else 0
    except jax.errors.ConcretizationTypeError:
        fallback = 0
    pick = lambda x: jnp.where(valid.reshape((size,) + (1,) * (x.ndim - 1)), x, x[fallback])
    return jax.tree_util.tree_map(pick, flat), valid, shape


def _unflatten(tree: Any, shape: tuple[int, ...]) -> Any:
    return jax.tree_util.tree_map(lambda x: x.reshape(shape + x.shape[1:]), tree)


def _check(contact: str, start: str) -> None:
    if contact not in ("strict", "paper"):
        raise ValueError(f"contact must be 'strict' or 'paper', got {contact!r}.")
    if start not in ("paper", "relaxed"):
        raise ValueError(f"start must be 'paper' (eq. 14) or 'relaxed', got {start!r}.")


def _initial(C: Chain, valid, contact, start, P: forces.Consts | None = None) -> engine.Hybrid:
    st = engine.init(C, contact, engine.initial_positions(C, start), P)
    return eqx.tree_at(lambda s: s.status, st, jnp.where(valid, st.status, Status.INVALID).astype(jnp.int32))


def _com(C: Chain, x: jax.Array) -> jax.Array:
    """Centre of mass $\\sum_i m_i x_i / \\sum_i m_i$ of one configuration (`x`: `(..., N)`)."""
    return jnp.matmul(x, C.m) / C.m.sum()


def chain_dynamics(dynamics: Any, waveform: Any) -> Exact | Smoothed:
    """A chain runs on the N-mass exact or smoothed engine and carries its own actuation."""
    if waveform is not None:
        raise ValueError("waveform= applies to Params; a Chain carries its own waveforms (Chain(waveforms=...)).")
    if not isinstance(dynamics, (Exact, Smoothed)):
        raise ValueError(f"a Chain runs with Exact or Smoothed dynamics; got {type(dynamics).__name__}.")
    return dynamics


# -- simulate -------------------------------------------------------------------------------


def _row(s: engine.Hybrid) -> jax.Array:
    dt = s.t.dtype
    stuck = (b.astype(dt) for b in s.stuck)
    return jnp.stack([*s.y.x, *s.y.v, s.y.ed, s.y.w, *stuck, *s.sdir, s.cross, s.near, s.t_switch])


def _simulate_batch(C, valid, save_at, contact, start, dt, max_steps, lanes, buffer=BUFFER):
    """The saved rows of a flat batch: the work queue of [`_saves.run_saves`][], highest frequencies first."""
    take = lambda i: jax.tree_util.tree_map(lambda x: x[i], C)

    def init(i):
        P = forces.consts(take(i))
        return P, _initial(take(i), valid[i], contact, start, P)

    step = lambda P, s, t_stop: engine.step(None, contact, dt, s, t_stop, P=P)[0]
    order = jnp.argsort(-jnp.where(jnp.isfinite(C.waves.omega), C.waves.omega, -jnp.inf))
    return run_saves(init, step, _row, valid.shape[0], save_at, max_steps, lanes, order, buffer)


_simulate_batch = engine_jit(_simulate_batch, ("contact", "start", "dt", "lanes", "buffer"))


def _derived(C: Chain, contact, t, x, v):
    """Energy, normal forces, rest lengths and tensions at one saved state."""
    P = forces.consts(C)
    dr = forces.drive(P, jnp.cos(P.omega * t), jnp.sin(P.omega * t))
    sp = forces.springs(P, dr.l0, forces.unstack(x))
    _, N = forces.loads(P, sp.fx, sp.fy, dr.f)
    e = forces.energy(P, forces.unstack(v), sp.tension)
    return dict(e=e, N=jnp.stack(N, -1), l0=jnp.stack(dr.l0, -1), tension=jnp.stack(sp.tension, -1))


def simulate_chain(chain: Chain, t_end: float, save_at, *, dynamics: Exact | Smoothed, contact: str, start: str,
                   dtype: Any) -> ChainTrajectory:  # fmt: skip
    """`simulate` for a [`Chain`][] on the N-mass exact or smoothed engine (arguments as in `simulate`)."""
    _check(contact, start)
    flat, valid, shape = prepare_chain(chain, dtype)
    save = jnp.asarray(save_at, flat.dtype)
    if isinstance(dynamics, Smoothed):
        out = _simulate_smoothed(flat, valid, save, contact, start, _cast_eps(dynamics, flat.dtype))
        return ChainTrajectory(**_unflatten(out, shape), start=start, contact=contact)
    dt, max_steps = dynamics.dt, dynamics.max_steps
    N = flat.n_masses
    steps = max_steps or default_max_steps(float(t_end), dt) + 4 * save.shape[0]
    n = valid.shape[0]
    lanes = min(n, MICRO_BATCH_CPU) if jax.default_backend() == "cpu" else n
    rows, ok, status, t_lift, n_switch = _simulate_batch(
        flat, valid, save, contact, start, dt, jnp.asarray(steps, jnp.int32), lanes
    )
    x, v = rows[..., :N], rows[..., N : 2 * N]
    t = jnp.broadcast_to(save, rows.shape[:-1])
    der = jax.vmap(lambda C, t, x, v: jax.vmap(lambda *a: _derived(C, contact, *a))(t, x, v))(flat, t, x, v)
    out = dict(
        t=t, x=x, v=v, stuck=rows[..., 2 * N + 2 : 3 * N + 2] > 0.5, X=jax.vmap(_com)(flat, x),
        e_d=rows[..., 2 * N], w=rows[..., 2 * N + 1], valid=ok, status=status, liftoff=jnp.isfinite(t_lift),
        t_liftoff=t_lift, n_switch=n_switch, transversality=jnp.sqrt(rows[..., 4 * N + 2]),
        near_miss=jnp.sqrt(rows[..., 4 * N + 3]), switch_gap=switch_gap(flat.waves.omega, t, rows[..., 4 * N + 4]),
        **der,
    )  # fmt: skip
    return ChainTrajectory(**_unflatten(out, shape), start=start, contact=contact)


# -- measure ----------------------------------------------------------------------------------


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


class _Fixed(NamedTuple):
    C: Chain
    P: forces.Consts
    ws: jax.Array
    we: jax.Array
    te: jax.Array
    z: jax.Array


def _setup(C, valid, t_start, z, horizon, window, contact, start):
    P = forces.consts(C)
    st = _initial(C, valid, contact, start, P)
    dtype = st.t.dtype
    ws = t_start.astype(dtype)
    zero = jnp.zeros((), dtype)
    no = jnp.asarray(False)
    acc = _Acc(
        started=no, X0=zero, ed0=zero, w0=zero, e0=zero, reached=no, t_z=jnp.asarray(jnp.inf, dtype),
        y_z=st.y.map(jnp.zeros_like), stuck=tuple(map(jnp.zeros_like, st.y.x)), steps=jnp.zeros((), jnp.int32),
        before_z=jnp.asarray(jnp.inf, dtype),
    )  # fmt: skip
    return _Fixed(C, P, ws, ws + window, ws + horizon, jnp.asarray(z, dtype)), (st, acc)


def _finished(f: _Fixed, s, a):
    return (s.t >= f.te) | (a.reached & (s.t >= f.we))


def _running(f: _Fixed, dyn, max_steps):
    s, a = dyn
    return (s.status == Status.OK) & ~_finished(f, s, a) & (a.steps < max_steps)


def _advance(f: _Fixed, dyn, contact, dt):
    s, a = dyn
    t_stop = jnp.where(s.t < f.ws, f.ws, jnp.where(s.t < f.we, f.we, f.te))
    begin = ~a.started & (s.t >= f.ws)
    started = a.started | begin
    X0 = jnp.where(begin, forces.centre_of_mass(f.P, s.y.x), a.X0)
    target = Target(active=started & ~a.reached, X0=X0, z=f.z)
    # The margins cover the measured interval: they restart at t_start.
    s = eqx.tree_at(lambda s: (s.cross, s.near), s, tuple(jnp.where(begin, jnp.inf, m) for m in (s.cross, s.near)))
    s_new, info = engine.step(f.C, contact, dt, s, t_stop, target, f.P)
    inside = info.commit & started & (info.t1 <= f.we)
    dur = jnp.where(inside, info.t1 - info.t0, 0)
    hit = info.target_fired
    a_new = _Acc(
        started=started, X0=X0, ed0=jnp.where(begin, info.y0.ed, a.ed0), w0=jnp.where(begin, info.y0.w, a.w0),
        e0=jnp.where(begin, engine.energy(f.P, info.y0, info.tension0), a.e0), reached=a.reached | hit,
        t_z=jnp.where(hit, info.t_target, a.t_z), y_z=info.y_target.map(lambda n, o: jnp.where(hit, n, o), a.y_z),
        stuck=tuple(q + jnp.where(b, dur, 0) for q, b in zip(a.stuck, info.stuck)), steps=a.steps + 1,
        before_z=jnp.where(hit, jax.lax.stop_gradient(info.t_target - s.t_switch), a.before_z),
    )  # fmt: skip
    return s_new, a_new


def _energy_at(P: forces.Consts, t, y):
    dr = forces.drive(P, jnp.cos(P.omega * t), jnp.sin(P.omega * t))
    return engine.energy(P, y, forces.springs(P, dr.l0, y.x).tension)


def _margin_z(f: _Fixed, a: _Acc, contact) -> jax.Array:
    """The time from $t_z$ to the nearest change of the target's structure (`_exact.target_margin`)."""
    t_z = jnp.where(a.reached, a.t_z, f.ws)
    g, d, e = engine.probe(f.C, contact, t_z, a.y_z, Target(active=jnp.asarray(True), X0=a.X0, z=f.z), f.P)
    return target_margin(a.before_z, g, d, e)


def _results(f: _Fixed, dyn, contact) -> dict:
    s, a = dyn
    ws, we, z = f.ws, f.we, f.z
    dtype = ws.dtype
    status = jnp.where((s.status == Status.OK) & ~_finished(f, s, a), Status.MAX_STEPS, s.status).astype(jnp.int32)
    nan, inf = jnp.asarray(jnp.nan, dtype), jnp.asarray(jnp.inf, dtype)
    stuck = jnp.stack(a.stuck)
    regime = jnp.where(s.t >= we, jnp.where(jnp.max(stuck) > STICK_TOL, Regime.SSL, Regime.SL), Regime.UNDETERMINED)
    t_end = jnp.where(a.reached, a.t_z, s.t)
    y_end = a.y_z.map(lambda zv, sv: jnp.where(a.reached, zv, sv), s.y)
    elapsed = t_end - ws
    measured = a.started & (elapsed > 0)
    mean_speed = jnp.where(
        measured, (forces.centre_of_mass(f.P, y_end.x) - a.X0) / jnp.where(measured, elapsed, 1), nan
    )
    e_d = jnp.where(a.started, y_end.ed - a.ed0, nan)
    work = jnp.where(a.started, y_end.w - a.w0, nan)
    delta_e = jnp.where(a.started, _energy_at(f.P, t_end, y_end) - a.e0, nan)
    e_z = jnp.where(a.reached, y_end.ed - a.ed0, inf)
    covered = jnp.clip(jnp.minimum(s.t, we) - ws, 0, None)
    frac = jnp.where(covered > 0, stuck / jnp.where(covered > 0, covered, 1), nan)
    return dict(
        tau_z=jnp.where(a.reached, a.t_z - ws, inf), e_z=e_z, reached=a.reached, regime=regime.astype(jnp.int32),
        mean_speed=mean_speed, cost_of_transport=e_z / z, stick_fraction=frac, e_d=e_d, work=work,
        delta_e=delta_e, balance=work - e_d - delta_e, liftoff=jnp.isfinite(s.t_liftoff), t_liftoff=s.t_liftoff,
        status=status, t_start=ws, X_start=jnp.where(a.started, a.X0, nan), n_steps=a.steps, n_switch=s.n_switch,
        **margin_fields(a.started, a.reached, s.cross, s.near, _margin_z(f, a, contact), a.t_z - ws, nan),
    )  # fmt: skip


def _measure_batch(C, valid, t_start, z, horizon, window, contact, start, dt, max_steps, lanes):
    n = valid.shape[0]
    take = lambda i: (jax.tree_util.tree_map(lambda x: x[i], C), valid[i], t_start[i])
    setup = lambda i: _setup(*take(i), z, horizon, window, contact, start)
    running = lambda f, d: _running(f, d, max_steps)
    advance = lambda f, d: _advance(f, d, contact, dt)
    results = lambda f, d: _results(f, d, contact)
    order = jnp.argsort(-jnp.where(jnp.isfinite(C.waves.omega), C.waves.omega, -jnp.inf))
    return run_queue(setup, running, advance, results, n, lanes, order)


_measure_batch = engine_jit(_measure_batch, ("contact", "start", "dt", "lanes"))


def measure_chain(chain: Chain, z: float, *, t_start: Any, horizon: float, window: float,
                  dynamics: Exact | Smoothed, contact: str, start: str, dtype: Any) -> ChainMeasurement:  # fmt: skip
    """`measure` for a [`Chain`][] on the N-mass exact or smoothed engine (arguments as in `measure`)."""
    _check(contact, start)
    flat, valid, shape = prepare_chain(chain, dtype)
    n = valid.shape[0]
    if t_start is None:
        ts = jnp.full((n,), jnp.inf, flat.dtype)
    else:
        ts = jnp.broadcast_to(jnp.asarray(t_start, flat.dtype), shape).reshape((n,))
        if not np.all(np.isfinite(np.asarray(ts))) or np.any(np.asarray(ts) < 0):
            raise ValueError(f"t_start must be finite and >= 0, got {t_start!r}.")
    z_, h_, w_ = (jnp.asarray(v, flat.dtype) for v in (z, horizon, window))
    if isinstance(dynamics, Smoothed):
        out = _measure_smoothed(flat, valid, ts, z_, h_, w_, contact, start, _cast_eps(dynamics, flat.dtype))
        return ChainMeasurement(**_unflatten(out, shape), z=float(z), start=start, contact=contact)
    # The default start (eigenvalues of the linearised chain) outside the engine's program: a
    # batched eigensolver inside it can deadlock XLA's CPU thread pool (seen at N = 8, batch 1024).
    ts = jnp.where(jnp.isfinite(ts), ts, flat.t_start)
    steps = dynamics.max_steps or default_max_steps(float(np.max(np.asarray(ts))) + horizon, dynamics.dt)
    lanes = min(n, MICRO_BATCH_CPU) if jax.default_backend() == "cpu" else n
    out = _measure_batch(flat, valid, ts, z_, h_, w_, contact, start, dynamics.dt, jnp.asarray(steps, jnp.int32), lanes)
    return ChainMeasurement(**_unflatten(out, shape), z=float(z), start=start, contact=contact)


# -- the smoothed engine ----------------------------------------------------------------------


def _cast_eps(dynamics: Smoothed, dtype: Any) -> Smoothed:
    return eqx.tree_at(lambda d: d.eps, dynamics, jnp.asarray(dynamics.eps, dtype))


@eqx.filter_jit
def _simulate_smoothed(C, valid, save, contact, start, dyn):
    return jax.vmap(lambda C, ok: smooth.simulate_one(C, ok, save, contact, start, dyn))(C, valid)


@eqx.filter_jit
def _measure_smoothed(C, valid, t_start, z, horizon, window, contact, start, dyn):
    one = lambda C, ok, ts: smooth.measure_one(C, ok, ts, z, horizon, window, contact, start, dyn)
    return jax.vmap(one)(C, valid, t_start)
