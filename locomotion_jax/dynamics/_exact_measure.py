"""The exact two-mass engine's measurements (Sects. 3-5; SPEC §5), accumulated on the fly.

Nothing is saved per step: the carry holds running sums (stick times in the
window, energies at the measurement start), so memory is independent of the
number of steps. $|X - X_0| = z$ is an event of the integrator (`_numerics.Target`),
located like a mode switch, so `tau_z` and `e_z` share the integrator's order.
"""

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from .._status import Regime, Status
from ..model import _two_mass as model
from ..model._params import Params, safe_params
from ..model._waveform import AbstractWaveform
from . import _exact as exact
from ._compile import engine_jit
from ._margins import margin_fields
from ._numerics import Target, target_margin
from ._queue import run_queue
from ._runs import default_lanes, initial_state, step_cap, STICK_TOL


def _energy(params, wave, t, y):
    l0, _ = wave(t)
    return model.total_energy(params, l0, y.x1, y.v1, y.x2, y.v2)


class _Acc(eqx.Module):
    started: jax.Array
    X0: jax.Array
    ed0: jax.Array
    w0: jax.Array
    e0: jax.Array
    reached: jax.Array
    t_z: jax.Array
    y_z: exact.State
    stuck1: jax.Array
    stuck2: jax.Array
    steps: jax.Array
    before_z: jax.Array  # time from the last switch to t_z


class _Fixed(NamedTuple):
    """What stays constant during one configuration's run."""

    params: Params
    wave: AbstractWaveform
    P: exact.Consts
    ws: jax.Array  # measurement start (t_start)
    we: jax.Array  # end of the regime window
    te: jax.Array  # horizon
    z: jax.Array
    cap: jax.Array  # the step cap of this configuration (`_runs.step_cap`)


def _setup(params, wave, z, horizon, window, contact, start, dt, max_steps, t_start, initial=None):
    """`(fixed, dyn)` of one configuration: its constants, and the loop state `(Hybrid, _Acc)`.

    `t_start` is the measurement's start, or NaN for the paper's (`Params.t_start`);
    `initial` the state $(x_1, v_1, x_2, v_2)$ at $t = 0$, or `None` for `start`'s.
    `max_steps`: an explicit step cap, or 0 for the default from the configuration's own
    span $t_\\text{start}$ + `horizon` (`_runs.step_cap`)."""
    params, valid = safe_params(params, wave)
    dtype = params.dtype
    P = exact.consts(params, wave)
    st, ok = initial_state(params, wave, contact, start, initial)
    valid = valid & ok
    st = eqx.tree_at(lambda s: s.status, st, jnp.where(valid, st.status, Status.INVALID).astype(jnp.int32))
    ws = jnp.where(jnp.isnan(t_start), params.t_start, t_start).astype(dtype)
    zero = jnp.zeros((), dtype)
    no = jnp.asarray(False)
    acc = _Acc(
        started=no,
        X0=zero,
        ed0=zero,
        w0=zero,
        e0=zero,
        reached=no,
        t_z=jnp.asarray(jnp.inf, dtype),
        y_z=exact.State(*(zero,) * 6),
        stuck1=zero,
        stuck2=zero,
        steps=jnp.zeros((), jnp.int32),
        before_z=jnp.asarray(jnp.inf, dtype),
    )
    te = ws + horizon
    fixed = _Fixed(params, wave, P, ws, ws + window, te, jnp.asarray(z, dtype), step_cap(te, dt, max_steps))
    return fixed, (st, acc)


def _com(P, y):
    return P.mhat * y.x1 + (1 - P.mhat) * y.x2


def _finished(f: _Fixed, s, a):
    return (s.t >= f.te) | (a.reached & (s.t >= f.we))


def _running(f: _Fixed, dyn):
    s, a = dyn
    return (s.status == Status.OK) & ~_finished(f, s, a) & (a.steps < f.cap)


def _advance(f: _Fixed, dyn, contact, dt):
    """One integrator iteration, with the measurement's running sums."""
    s, a = dyn
    ws, we = f.ws, f.we
    t_stop = jnp.where(s.t < ws, ws, jnp.where(s.t < we, we, f.te))
    # Measurement start: the iteration that starts on t_start (a step lands there).
    begin = ~a.started & (s.t >= ws)
    started = a.started | begin
    X0 = jnp.where(begin, _com(f.P, s.y), a.X0)
    target = Target(active=started & ~a.reached, X0=X0, z=f.z)
    # The margins cover the measured interval: they restart at t_start.
    s = eqx.tree_at(lambda s: (s.cross, s.near), s, tuple(jnp.where(begin, jnp.inf, m) for m in (s.cross, s.near)))
    s_new, info = exact.step(f.params, f.wave, contact, dt, s, t_stop, target, f.P)
    # Stick time inside the window (steps never straddle ws or we).
    inside = info.commit & started & (info.t1 <= we)
    dur = jnp.where(inside, info.t1 - info.t0, 0)
    # First passage |X - X0| = z: an event of the integrator (located like a switch).
    hit = info.target_fired
    a_new = _Acc(
        started=started,
        X0=X0,
        ed0=jnp.where(begin, info.y0.ed, a.ed0),
        w0=jnp.where(begin, info.y0.w, a.w0),
        e0=jnp.where(begin, exact.energy(f.P, info.y0, info.tension0), a.e0),
        reached=a.reached | hit,
        t_z=jnp.where(hit, info.t_target, a.t_z),
        y_z=info.y_target.map(lambda n, o: jnp.where(hit, n, o), a.y_z),
        stuck1=a.stuck1 + jnp.where(info.stuck1, dur, 0),
        stuck2=a.stuck2 + jnp.where(info.stuck2, dur, 0),
        steps=a.steps + 1,
        before_z=jnp.where(hit, jax.lax.stop_gradient(info.t_target - s.t_switch), a.before_z),
    )
    return s_new, a_new


def _margin_z(f: _Fixed, a: _Acc, contact) -> jax.Array:
    """The time from $t_z$ to the nearest change of the target's structure (`_numerics.target_margin`)."""
    target = Target(active=jnp.asarray(True), X0=a.X0, z=f.z)
    t_z = jnp.where(a.reached, a.t_z, f.ws)
    events = exact.probe(f.params, f.wave, contact, t_z, a.y_z, target)
    return target_margin(a.before_z, *events)


def _results(f: _Fixed, dyn, contact) -> dict:
    """The `Measurement` fields of one finished run (SPEC §5)."""
    s, a = dyn
    params, wave, ws, we, z = f.params, f.wave, f.ws, f.we, f.z
    dtype = ws.dtype
    status = jnp.where((s.status == Status.OK) & ~_finished(f, s, a), Status.MAX_STEPS, s.status).astype(jnp.int32)
    nan = jnp.asarray(jnp.nan, dtype)
    window_done = s.t >= we
    stuck_time = jnp.stack([a.stuck1, a.stuck2])
    ssl = jnp.max(stuck_time) > STICK_TOL
    regime = jnp.where(window_done, jnp.where(ssl, Regime.SSL, Regime.SL), Regime.UNDETERMINED)
    # End of the measured interval: the crossing if reached, else where the run is.
    t_end = jnp.where(a.reached, a.t_z, s.t)
    y_end = a.y_z.map(lambda zv, sv: jnp.where(a.reached, zv, sv), s.y)
    elapsed = t_end - ws
    measured = a.started & (elapsed > 0)
    mean_speed = jnp.where(measured, (_com(f.P, y_end) - a.X0) / jnp.where(measured, elapsed, 1), nan)
    e_d = jnp.where(a.started, y_end.ed - a.ed0, nan)
    work = jnp.where(a.started, y_end.w - a.w0, nan)
    delta_e = jnp.where(a.started, _energy(params, wave, t_end, y_end) - a.e0, nan)
    inf = jnp.asarray(jnp.inf, dtype)
    e_z = jnp.where(a.reached, y_end.ed - a.ed0, inf)
    covered = jnp.clip(jnp.minimum(s.t, we) - ws, 0, None)
    frac = jnp.where(covered > 0, stuck_time / jnp.where(covered > 0, covered, 1), nan)
    return dict(
        tau_z=jnp.where(a.reached, a.t_z - ws, inf),
        e_z=e_z,
        reached=a.reached,
        regime=regime.astype(jnp.int32),
        mean_speed=mean_speed,
        cost_of_transport=e_z / z,
        stick_fraction1=frac[0],
        stick_fraction2=frac[1],
        e_d=e_d,
        work=work,
        delta_e=delta_e,
        balance=work - e_d - delta_e,
        liftoff=jnp.isfinite(s.t_liftoff),
        t_liftoff=s.t_liftoff,
        status=status,
        t_start=ws,
        X_start=jnp.where(a.started, a.X0, nan),
        n_steps=a.steps,
        n_switch=s.n_switch,
        **margin_fields(a.started, a.reached, s.cross, s.near, _margin_z(f, a, contact), a.t_z - ws, nan),
    )


def _exact_one(params, wave, z, horizon, window, contact, start, dt, max_steps, t_start=jnp.nan, initial=None):
    """One configuration, in its own loop (under `vmap`: a loop of lanes that idle once done).

    `t_start`: the measurement's start, NaN for the paper's; `initial`: as in `_setup`."""
    fixed, dyn = _setup(params, wave, z, horizon, window, contact, start, dt, max_steps, t_start, initial)
    dyn = jax.lax.while_loop(lambda d: _running(fixed, d), lambda d: _advance(fixed, d, contact, dt), dyn)
    return _results(fixed, dyn, contact)


def exact_batch(
    params,
    wave,
    wave_axes,
    z,
    horizon,
    window,
    contact,
    start,
    dt,
    max_steps,
    lanes: int | None = None,
    t_start: jax.Array | None = None,
    initial: jax.Array | None = None,
) -> dict[str, jax.Array]:
    """`measure` on a flat batch (not jitted): a work queue over `lanes` lanes ([`_queue.run_queue`][]).

    `lanes=None` takes `_runs.default_lanes` (on a CPU at most `MICRO_BATCH_CPU`: wider kernels
    are split over threads and run slower, benchmarks/NOTES.md; a multiple of `LANE_QUANTUM`, so
    that a configuration's result does not depend on its batch), else the whole batch in one
    `vmap`. On a CPU the queue runs even where the lanes hold the whole batch.
    The queue takes the highest frequencies (most mode switches per time unit) first,
    so that the last configurations, run while lanes run out of work, are short.
    `t_start`: per-configuration measurement starts (NaN: the paper's), default all the paper's.
    `initial`: per-configuration states $(x_1, v_1, x_2, v_2)$ at $t = 0$, shape `(n, 4)`
    (default: at rest in the `start` position).
    `max_steps`: an explicit cap on each configuration's iterations, or 0: each
    configuration's own default from its span (`_runs.step_cap`), so that a
    configuration's status and step count do not depend on its batch-mates.
    """
    n = params.omega.shape[0]
    if t_start is None:
        t_start = jnp.full((n,), jnp.nan, params.dtype)
    if lanes is None:
        lanes = default_lanes(n)
    if lanes == n and jax.default_backend() != "cpu":
        fn = lambda p, w, ts, y0: _exact_one(p, w, z, horizon, window, contact, start, dt, max_steps, ts, y0)
        return jax.vmap(fn, in_axes=(0, wave_axes, 0, None if initial is None else 0))(params, wave, t_start, initial)
    take = lambda i: jax.tree_util.tree_map(lambda x: x[i], params)
    pick_wave = (lambda i: wave) if wave_axes is None else (lambda i: jax.tree_util.tree_map(lambda x: x[i], wave))
    pick_initial = (lambda i: None) if initial is None else (lambda i: initial[i])
    setup = lambda i: _setup(
        take(i), pick_wave(i), z, horizon, window, contact, start, dt, max_steps, t_start[i], pick_initial(i)
    )
    advance = lambda f, d: _advance(f, d, contact, dt)
    order = jnp.argsort(-jnp.where(jnp.isfinite(params.omega), params.omega, -jnp.inf))
    results = lambda f, d: _results(f, d, contact)
    return run_queue(setup, _running, advance, results, n, lanes, order)


_exact_batch = engine_jit(exact_batch, ("wave_axes", "contact", "start", "dt", "lanes"))
