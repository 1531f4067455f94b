"""The paper's two-mass model on the N-body engine (`_engine`): `measure` and `simulate` runs.

Each configuration's physics is [`Params.physics`][locomotion_jax.Params.physics] (the two-mass
chain, SPEC §8 at $N = 2$), built inside the work queue when a lane takes the configuration;
the loops are the N-body engine's (`_measure`, `_simulate`'s rows). This module
only translates: the paper's parameters, waveform and states $(x_1, v_1, x_2, v_2)$ in, the
fields of [`Measurement`][locomotion_jax.Measurement] and [`Trajectory`][locomotion_jax.Trajectory] out.
Under `contact="hop"` (SPEC §10) the same runs carry the hopping fields (heights, flight fractions,
landings) per mass; a configuration lands plastically (restitution 0, SPEC's default) and starts on
the ground at rest vertically (`ChainPhysics.hop`).
"""

from typing import Any

import jax
import jax.numpy as jnp

from .._custom_types import Array, Contact
from ..model import _two_mass as model
from ..model._params import Params, safe_params
from ..model._physics import loads_at
from ..model._waveform import AbstractWaveform
from . import _engine as engine, _measure as runs
from ._compile import engine_jit
from ._margins import switch_gap
from ._motion import Mode, rates, State
from ._queue import run_queue
from ._runs import BatchRows, chain_initial_state, default_lanes, overflow_failed, start_code
from ._saves import BUFFER, run_saves
from ._simulate import _row


# The N-body engine's saved columns (x1, x2, v1, v2) in the order (x1, v1, x2, v2).
_TO_CHAIN = (0, 2, 1, 3)


def physics(params: Params, wave: AbstractWaveform) -> tuple[Params, Any, Array]:
    """`(safe, P, valid)` of one configuration: its parameters with an invalid set replaced by the
    defaults (`safe_params`), their physics (`Params.physics`) in the parameters' dtype, and the
    validity of parameters and waveform."""
    safe, valid = safe_params(params, wave)
    # A sinusoid's Fourier coefficients come out in the default float: cast to the configuration's.
    cast = lambda x: x.astype(safe.dtype) if jnp.issubdtype(x.dtype, jnp.floating) else x
    return safe, jax.tree_util.tree_map(cast, safe.physics(wave)), valid


def _picker(params: Params, wave: AbstractWaveform, wave_axes: int | None, t_start, initial):
    """`take(i)`: configuration `i`'s `(physics, valid, t_start, initial row)` (for the engine)."""
    wave_at = (lambda i: wave) if wave_axes is None else (lambda i: jax.tree_util.tree_map(lambda x: x[i], wave))

    def take(i):
        p, w = jax.tree_util.tree_map(lambda x: x[i], params), wave_at(i)
        safe, P, valid = physics(p, w)
        row = None if initial is None else initial[i]
        ts = safe.t_start if t_start is None else jnp.where(jnp.isnan(t_start[i]), safe.t_start, t_start[i])
        return P, valid, ts, row

    return take


def _order(params: Params) -> Array:
    """The queue's order: the highest frequencies (most mode switches per time unit) first."""
    return jnp.argsort(-jnp.where(jnp.isfinite(params.omega), params.omega, -jnp.inf))


def measure_batch(
    params: Params,
    wave: AbstractWaveform,
    wave_axes: int | None,
    z,
    horizon,
    window,
    contact: str,
    start: str | Array,
    dt: float | Array,
    max_steps,
    lanes: int | None = None,
    t_start: Array | None = None,
    initial: Array | None = None,
    count: Array | None = None,
) -> dict[str, Array]:
    """`measure` of the paper's model on a flat batch (not jitted): a work queue over `lanes`
    lanes ([`_queue.run_queue`][]; the first `count` configurations), highest frequencies first.

    `lanes=None` takes `_runs.default_lanes`. `t_start`: per-configuration measurement starts
    (NaN: the paper's `Params.t_start`), default all the paper's. `initial`: per-configuration
    states $(x_1, x_2, v_1, v_2)$ at $t = 0$ (positions, then velocities, as the N-body engine's),
    shape `(n, 4)` (default: at rest in the `start` position). `max_steps`: an explicit cap on
    each configuration's iterations, or 0 for each one's own default from its span (`_runs.step_cap`).
    """
    n = params.omega.shape[0]
    lanes = default_lanes(n) if lanes is None else lanes
    take = _picker(params, wave, wave_axes, t_start, initial)
    setup = lambda i: runs._setup(*take(i), z, horizon, window, contact, start, dt, max_steps)
    advance = lambda f, d: runs._advance(f, d, contact, dt)
    results = lambda f, d: runs._results(f, d, contact)
    return run_queue(setup, runs._running, advance, results, n, lanes, _order(params), count=count)


_measure_batch = engine_jit(measure_batch, ("wave_axes", "contact", "lanes"), reverse=True)


def measure(
    params: Params,
    wave: AbstractWaveform,
    wave_axes: int | None,
    z,
    horizon,
    window,
    contact: str,
    start: str,
    dt: float,
    max_steps,
    t_start: Array | None = None,
    initial: Array | None = None,
) -> dict[str, Array]:
    """[`measure_batch`][locomotion_jax.dynamics._paper.measure_batch], compiled for the batch's
    bucket (`_runs.BatchRows`) with the engine's lanes."""
    n = params.omega.shape[0]
    rows = BatchRows.of(n, params, wave, t_start, initial, z, horizon, window, max_steps)
    params, t_start, initial = rows.pad((params, t_start, initial))
    wave = wave if wave_axes is None else rows.pad(wave)
    code = start_code(start)
    dt_ = jnp.asarray(dt, params.omega.dtype)
    args = (params, wave, wave_axes, z, horizon, window, contact, code, dt_, max_steps, default_lanes(rows.m))
    return rows.cut(_measure_batch(*args, t_start=t_start, initial=initial, count=rows.queue_count))


def measure_one(params: Params, wave: AbstractWaveform, z, horizon, window, contact, start, dt, max_steps) -> dict:
    """One configuration in a plain loop of its own (no queue): what the queue must reproduce."""
    add = lambda tree: jax.tree_util.tree_map(lambda x: x[None], tree)
    take = _picker(add(params), add(wave), 0, None, None)
    f, d = runs._setup(*take(0), z, horizon, window, contact, start, dt, max_steps)
    advance = lambda d: runs._advance(f, d, contact, dt)
    d = jax.lax.while_loop(lambda d: runs._running(f, d), advance, d)
    return runs._results(f, d, contact)


def _hop_row(s: engine.Hybrid) -> Array:
    """A saved row under `contact="hop"`: the N-body engine's (`_simulate._row`: heights,
    vertical velocities, landings and the Zeno flag included), then the in-flight flags."""
    assert s.fly is not None
    return jnp.concatenate([_row(s), jnp.stack([f.astype(s.t.dtype) for f in s.fly])])


def _simulate_rows(
    params, wave, wave_axes, save_at, contact, start, dt, max_steps, lanes, buffer=BUFFER, initial=None, count=None,
    saves=None,
):  # fmt: skip
    """The saved rows of a flat batch ([`_saves.run_saves`][]: a work queue over `lanes` lanes,
    highest frequencies first): the N-body engine's rows (`_simulate._row`), reordered to
    $(x_1, v_1, x_2, v_2, e_d, w)$, the stick flags, the slip directions and the margins' records
    (columns 0 to 12); under `contact="hop"` then $(y_1, y_2, \\dot y_1, \\dot y_2)$, the landings,
    the Zeno flag and the in-flight flags (columns 13 to 20)."""
    take = _picker(params, wave, wave_axes, None, initial)

    def init(i):
        P, valid, _, row = take(i)
        return P, chain_initial_state(P, valid, contact, start, row)

    hop = (lambda P: P.hop()[2:]) if contact == "hop" else (lambda P: None)
    step = lambda P, s, t_stop: engine.step(P, contact, dt, s, t_stop, hop=hop(P))[0]
    row = _hop_row if contact == "hop" else _row
    n = params.omega.shape[0]
    rows, *rest = run_saves(init, step, row, n, save_at, max_steps, lanes, _order(params), buffer, count, saves)
    return (rows[..., jnp.asarray(_TO_CHAIN + tuple(range(4, rows.shape[-1])))], *rest)


_simulate_rows = engine_jit(_simulate_rows, ("wave_axes", "contact", "lanes", "buffer"), reverse=True)


def derived_fields(params: Params, wave: AbstractWaveform, contact: Contact, t, y, stuck, sdir) -> dict:
    """Energy (eq. 10), normal forces (eq. 5) and $F_{ex}$ (eq. 17) at saved states."""
    f = model.forces(params, wave, t, y[0], y[2], contact)
    # The accelerations in the saved mode (eq. 9 corrected per SPEC §2; zero while stuck).
    a1 = (f.fx - params.c * y[1] - params.mu_k * f.n1 * sdir[0]) / params.m1
    a2 = (-f.fx - params.c * y[3] - params.mu_k * f.n2 * sdir[1]) / params.m2
    zero = jnp.zeros_like(a1)
    a1, a2 = jnp.where(stuck[0], zero, a1), jnp.where(stuck[1], zero, a2)
    return {
        "e": model.total_energy(params, f.l0, y[0], y[1], y[2], y[3]),
        "l0": f.l0,
        "N1": f.N1,
        "N2": f.N2,
        "f_ex": params.m1 * a1 + params.m2 * a2,
        "X": model.centre_of_mass(params, y[0], y[2]),
    }


def hop_derived_fields(P: Any, t, x, v, y, vy, stuck, sdir, fly) -> dict:
    """Under `contact="hop"`, at one saved state of one configuration (`P`: its physics; per-mass pairs
    `x`, `v`, heights `y`, vertical velocities `vy`, flags): energy with gravity $m_i y_i$ and the
    vertical kinetic energy, signed normal forces, rest length, centre of mass and $F_{ex}$ (the
    horizontal friction plus damping on the system, $\\sum_i m_i \\dot v_i$: zero from a body in flight
    but for its damping)."""
    tup = lambda a: tuple(a[i] for i in range(2))
    dr = P.drive(jnp.cos(P.omega * t), jnp.sin(P.omega * t))
    L = loads_at(P, dr, tup(x), y=tup(y))
    e = P.energy(L, tup(v)) + jnp.sum(jnp.stack(P.m) * (y + 0.5 * vy * vy))
    zero = jnp.zeros_like(t)
    mode = Mode(stuck=tup(stuck), sdir=tup(sdir), side=(zero + 1, zero + 1), fly=tup(fly))
    acc = rates(P, "hop", mode, dr, State(tup(x), tup(v), zero, zero, tup(y), tup(vy))).v
    return dict(
        e=e, l0=dr.l0[0], N1=L.N[0], N2=L.N[1], f_ex=P.m[0] * acc[0] + P.m[1] * acc[1],
        X=P.centre_of_mass(tup(x)),
    )  # fmt: skip


def _trajectory(params, wave, wave_axes, contact, save_at, rows, valid, status, t_lift, n_switch):
    y = jnp.moveaxis(rows[..., :6], -1, 0)  # (6, B, n)
    stuck = jnp.moveaxis(rows[..., 6:8] > 0.5, -1, 0)
    sdir = jnp.moveaxis(rows[..., 8:10], -1, 0)
    t = jnp.broadcast_to(save_at, rows.shape[:-1])

    if contact == "hop":
        P = jax.vmap(lambda p, w: physics(p, w)[1], in_axes=(0, wave_axes))(params, wave)
        x, v, hy, hvy = rows[..., (0, 2)], rows[..., (1, 3)], rows[..., 13:15], rows[..., 15:17]
        fly = rows[..., 19:21] > 0.5
        one_hop = lambda Pi, *a: jax.vmap(lambda *b: hop_derived_fields(Pi, *b))(*a)
        der = jax.vmap(one_hop)(P, t, x, v, hy, hvy, rows[..., 6:8] > 0.5, rows[..., 8:10], fly)
        der |= dict(y=hy, vy=hvy, n_land=rows[..., -1, 17].astype(jnp.int32), zeno=rows[..., -1, 18] > 0.5)
        omega = P.omega
    else:

        def one(p, w, t, y, stuck, sdir):
            return jax.vmap(lambda t, y, s, d: derived_fields(p, w, contact, t, y, s, d), in_axes=(0, 1, 1, 1))(
                t, y, stuck, sdir
            )

        der = jax.vmap(one, in_axes=(0, wave_axes, 0, 1, 1, 1))(params, wave, t, y, stuck, sdir)
        omega = jnp.broadcast_to(wave.omega, rows.shape[:1])
    N, l0 = jnp.stack([der.pop("N1"), der.pop("N2")], -1), der.pop("l0")
    status, valid = overflow_failed(status, valid, jnp.isfinite(jnp.sum(rows[..., :6], -1) + der["e"]))
    return dict(
        t=t, x=rows[..., (0, 2)], v=rows[..., (1, 3)], stuck=rows[..., 6:8] > 0.5, N=N, rest_length=l0[..., None],
        e_d=y[4], w=y[5], valid=valid, status=status, liftoff=jnp.isfinite(t_lift), t_liftoff=t_lift, n_switch=n_switch,
        transversality=jnp.sqrt(rows[..., 10]), near_miss=jnp.sqrt(rows[..., 11]),
        switch_gap=switch_gap(omega, t, rows[..., 12]), **der,
    )  # fmt: skip


# One compiled computation rather than dozens of small ones run op by op: each of
# those is a compilation (or a compilation-cache read) of its own in a new process.
_trajectory = jax.jit(_trajectory, static_argnames=("wave_axes", "contact"))


def simulate_batch(params, wave, wave_axes, save_at, contact, start, dt, max_steps: int, initial=None) -> dict:
    """The fields of a [`Trajectory`][locomotion_jax.Trajectory] of a flat batch (leading axis: the
    configurations); `max_steps` caps each configuration's iterations, saves included. Compiled for
    the batch's bucket and its save times' (`_runs.BatchRows`)."""
    batch = BatchRows.of(params.omega.shape[0], params, wave, save_at, initial)
    times = BatchRows.of(save_at.shape[0], params, wave, save_at, initial)  # the save times, padded as the rows are
    p, init = batch.pad((params, initial))
    w = wave if wave_axes is None else batch.pad(wave)
    cap = jnp.asarray(max_steps, jnp.int32)
    dt_ = jnp.asarray(dt, params.omega.dtype)
    args = (p, w, wave_axes, times.pad(save_at), contact, start_code(start), dt_, cap, default_lanes(batch.m))
    out = _simulate_rows(*args, initial=init, count=batch.queue_count, saves=times.queue_count)
    rows, valid, status, t_lift, n_switch = batch.cut(out)
    rows, valid = rows[:, : times.n], valid[:, : times.n]
    return _trajectory(params, wave, wave_axes, contact, save_at, rows, valid, status, t_lift, n_switch)
