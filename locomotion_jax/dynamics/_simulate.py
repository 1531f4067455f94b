"""The N-mass exact engine's trajectories (SPEC §8): states saved at requested times.

A flat batch through the work queue ([`_saves.run_saves`][]), highest frequencies first
(the paper's model too, through `_paper`), so memory grows with the saves only; energy,
normal forces, rest lengths and tensions follow from the saved states.
"""

from typing import Any

import jax
import jax.numpy as jnp

from ..model._bodies import Mechanism
from ..model._chain import Chain
from ..model._chain_array import engine_physics, uses_array
from ..model._physics import loads_at
from . import _engine as engine
from ._compile import engine_jit
from ._margins import switch_gap
from ._runs import BatchRows, chain_initial_state, default_lanes, overflow_failed, start_code
from ._saves import BUFFER, run_saves


def _com(C: Chain | Mechanism, x: jax.Array) -> jax.Array:
    """Centre of mass $\\sum_i m_i x_i / \\sum_i m_i$ of one configuration (`x`: `(..., N)`)."""
    return jnp.matmul(x, C.m) / C.m.sum()


def _row(s: engine.Hybrid) -> jax.Array:
    dt = s.t.dtype
    stuck = (b.astype(dt) for b in s.stuck)
    hop = []
    if s.y.y is not None and s.y.vy is not None and s.n_land is not None and s.zeno is not None:
        hop = [*s.y.y, *s.y.vy, s.n_land.astype(dt), s.zeno.astype(dt)]
    parts = [*s.y.x, *s.y.v, s.y.ed, s.y.w, *stuck, *s.sdir, s.cross, s.near, s.t_switch, *hop]
    if all(jnp.ndim(q) == 0 for q in parts):
        return jnp.stack(parts)
    return jnp.concatenate([jnp.atleast_1d(q) for q in parts])  # the array layout: entries over the bodies


def _simulate_batch(C, valid, save_at, contact, start, dt, max_steps, lanes, buffer=BUFFER, initial=None, count=None,
                    saves=None):  # fmt: skip
    """The saved rows of a flat batch: the work queue of [`_saves.run_saves`][], highest frequencies first."""
    take = lambda i: jax.tree_util.tree_map(lambda x: x[i], C)

    def init(i):
        P = engine_physics(take(i))
        return P, chain_initial_state(P, valid[i], contact, start, None if initial is None else initial[i])

    hop = (lambda P: P.hop()[2:]) if contact == "hop" else (lambda P: None)
    step = lambda P, s, t_stop: engine.step(P, contact, dt, s, t_stop, hop=hop(P))[0]
    order = jnp.argsort(-jnp.where(jnp.isfinite(C.omega), C.omega, -jnp.inf))
    return run_saves(init, step, _row, valid.shape[0], save_at, max_steps, lanes, order, buffer, count, saves)


_simulate_batch = engine_jit(_simulate_batch, ("contact", "lanes", "buffer"), reverse=True)


def _stack(P: Any, a: tuple, like: jax.Array) -> jax.Array:
    """A per-spring tuple as an array (a mechanism without springs: an empty last axis)."""
    return P.stacked(a) if a else jnp.zeros(jnp.shape(like) + (0,), like.dtype)


def _derived(C: Chain | Mechanism, contact, t, x, v, y=None, vy=None):
    """Energy, normal forces, rest lengths and tensions (per spring) at one saved state (under
    `contact="hop"`, the energy with each body's gravity $m_i y_i$ and vertical kinetic energy)."""
    P: Any = engine_physics(C)  # a chain's or a mechanism's: both have `l0` per spring and `tension`
    dr = P.drive(jnp.cos(P.omega * t), jnp.sin(P.omega * t))
    heights = None if y is None else P.bodies(y)
    L = loads_at(P, dr, P.bodies(x), y=heights)
    e = P.energy(L, P.bodies(v))
    if y is not None and vy is not None:
        e = e + jnp.sum(C.m * (y + 0.5 * vy * vy), -1)
    return dict(e=e, N=P.stacked(L.N), rest_length=_stack(P, dr.l0, e), tension=_stack(P, L.aux.tension, e))


def simulate_batch(flat: Chain | Mechanism, valid, save, contact, start, dt, max_steps: int, initial=None) -> dict:
    """The fields of a [`Trajectory`][locomotion_jax.Trajectory] of a flat batch of chains
    (leading axis: the configurations); `max_steps` caps each one's iterations, saves included;
    `initial`: the states at $t = 0$, shape `(n, 2N)`, or `None` for `start`'s. Compiled for the
    batch's bucket and its save times' (`_runs.BatchRows`)."""
    N = flat.n_masses
    batch = BatchRows.of(valid.shape[0], flat, valid, save, initial)
    times = BatchRows.of(save.shape[0], flat, valid, save, initial)  # the save times, padded as the rows are
    lanes = default_lanes(batch.m, N if uses_array(flat) else 1)
    C, ok, init = batch.pad((flat, valid, initial))
    cap = jnp.asarray(max_steps, jnp.int32)
    code = start_code(start)
    dt_ = jnp.asarray(dt, flat.m.dtype)
    out = _simulate_batch(C, ok, times.pad(save), contact, code, dt_, cap, lanes, initial=init,
                          count=batch.queue_count, saves=times.queue_count)  # fmt: skip
    rows, ok, status, t_lift, n_switch = batch.cut(out)
    rows, ok = rows[:, : times.n], ok[:, : times.n]
    x, v = rows[..., :N], rows[..., N : 2 * N]
    t = jnp.broadcast_to(save, rows.shape[:-1])
    if contact == "hop":
        hy, hvy = rows[..., 4 * N + 5 : 5 * N + 5], rows[..., 5 * N + 5 : 6 * N + 5]
        der = jax.vmap(lambda C, *a: jax.vmap(lambda *b: _derived(C, contact, *b))(*a))(flat, t, x, v, hy, hvy)
        der.update(y=hy, vy=hvy, n_land=rows[..., -1, 6 * N + 5].astype(jnp.int32), zeno=rows[..., -1, 6 * N + 6] > 0.5)
    else:
        der = jax.vmap(lambda C, t, x, v: jax.vmap(lambda *a: _derived(C, contact, *a))(t, x, v))(flat, t, x, v)
    status, ok = overflow_failed(status, ok, jnp.isfinite(jnp.sum(rows[..., : 2 * N + 2], -1) + der["e"]))
    out = dict(
        t=t, x=x, v=v, stuck=rows[..., 2 * N + 2 : 3 * N + 2] > 0.5, X=jax.vmap(_com)(flat, x),
        e_d=rows[..., 2 * N], w=rows[..., 2 * N + 1], valid=ok, status=status, liftoff=jnp.isfinite(t_lift),
        t_liftoff=t_lift, n_switch=n_switch, transversality=jnp.sqrt(rows[..., 4 * N + 2]),
        near_miss=jnp.sqrt(rows[..., 4 * N + 3]), switch_gap=switch_gap(flat.omega, t, rows[..., 4 * N + 4]),
        **der,
    )  # fmt: skip
    return out
