"""The paper's model under `contact="hop"` (SPEC §10): its runs on the N-body engine.

Each configuration's physics is [`Params.physics`][locomotion_jax.Params.physics] (the two-mass chain,
SPEC §8 at $N = 2$, the same as `Chain.from_params`), built for the whole flat batch before the
engine's loop; the loops are the N-body engine's (`_chain_measure.measure_batch`, and
`_saves.run_saves` over `_chain_exact.step`). This module only translates: the paper's parameters,
waveform and states $(x_1, v_1, x_2, v_2)$ in, the fields of [`Measurement`][locomotion_jax.Measurement]
and [`Trajectory`][locomotion_jax.Trajectory] out, with the hopping fields (heights, flight fractions,
landings) per mass. A configuration lands plastically (restitution 0, SPEC's default) and starts on
the ground at rest vertically (`ChainPhysics.hop`).
"""

from typing import Any

import jax
import jax.numpy as jnp

from .._custom_types import Array
from .._status import mode_code
from ..model._params import Params, safe_params
from ..model._physics import loads_at
from ..model._waveform import AbstractWaveform
from . import _chain_exact as engine, _chain_measure
from ._chain_motion import Mode, rates, State
from ._chain_simulate import _row as chain_row
from ._compile import engine_jit
from ._margins import switch_gap
from ._paper import _measurement, _TO_CHAIN
from ._runs import chain_initial_state, default_lanes
from ._saves import BUFFER, run_saves


CONTACT = "hop"


def physics_batch(params: Params, wave: AbstractWaveform, wave_axes: int | None) -> tuple[Any, Params, Array]:
    """`(P, safe, valid)` of a flat batch: the physics of each configuration (leading axis: the
    configurations), its parameters with an invalid set replaced by the defaults (`safe_params`),
    and the validity of parameters and waveform (an invalid configuration is not advanced)."""

    def one(p: Params, w: AbstractWaveform):
        safe, valid = safe_params(p, w)
        # A sinusoid's Fourier coefficients come out in the default float: cast to the configuration's.
        cast = lambda x: x.astype(safe.dtype) if jnp.issubdtype(x.dtype, jnp.floating) else x
        return jax.tree_util.tree_map(cast, safe.physics(w)), safe, valid

    return jax.vmap(one, in_axes=(0, wave_axes))(params, wave)


def measure_batch(
    params: Params,
    wave: AbstractWaveform,
    wave_axes: int | None,
    z,
    horizon,
    window,
    start: str,
    dt: float,
    max_steps,
    t_start: Array | None = None,
    initial: Array | None = None,
) -> dict[str, Array]:
    """The fields of a [`Measurement`][locomotion_jax.Measurement] under `contact="hop"` of a flat batch
    (leading axis: the configurations), hopping fields included.

    `t_start`: per-configuration measurement starts (`None`: the paper's `Params.t_start`);
    `initial`: per-configuration states $(x_1, v_1, x_2, v_2)$ at $t = 0$, shape `(n, 4)`, or `None`;
    `max_steps`: an explicit cap on each configuration's iterations, or 0 for each one's own default.
    """
    P, safe, valid = physics_batch(params, wave, wave_axes)
    ts = safe.t_start if t_start is None else t_start
    row = None if initial is None else initial[:, jnp.asarray(_TO_CHAIN)]
    out = _chain_measure.measure_batch(P, valid, ts, z, horizon, window, CONTACT, start, dt, max_steps, row)
    return _measurement(out)


def _row(s: engine.Hybrid) -> Array:
    """A saved row: the N-body engine's (`_chain_simulate._row`), then the in-flight flags."""
    assert s.fly is not None
    return jnp.concatenate([chain_row(s), jnp.stack([f.astype(s.t.dtype) for f in s.fly])])


def _simulate_rows(P, valid, save_at, start, dt, max_steps, lanes, buffer=BUFFER, initial=None):
    take = lambda i: jax.tree_util.tree_map(lambda x: x[i], P)

    def init(i):
        Pi = take(i)
        return Pi, chain_initial_state(Pi, valid[i], CONTACT, start, None if initial is None else initial[i])

    step = lambda Pi, s, t_stop: engine.step(Pi, CONTACT, dt, s, t_stop, hop=Pi.hop()[2:])[0]
    order = jnp.argsort(-jnp.where(jnp.isfinite(P.omega), P.omega, -jnp.inf))
    return run_saves(init, step, _row, valid.shape[0], save_at, max_steps, lanes, order, buffer)


_simulate_rows = engine_jit(_simulate_rows, ("start", "dt", "lanes", "buffer"))


def _derived(P, t, x, v, y, vy, stuck, sdir, fly) -> dict:
    """At one saved state of one configuration: energy with gravity $m_i y_i$ and the vertical kinetic
    energy, signed normal forces, rest length, centre of mass and $F_{ex}$ (the horizontal friction plus
    damping on the system, $\\sum_i m_i \\dot v_i$: zero from a body in flight but for its damping)."""
    tup = lambda a: tuple(a[i] for i in range(2))
    dr = P.drive(jnp.cos(P.omega * t), jnp.sin(P.omega * t))
    L = loads_at(P, dr, tup(x), y=tup(y))
    m = jnp.stack(P.m)
    e = P.energy(L, tup(v)) + jnp.sum(m * (y + 0.5 * vy * vy))
    zero = jnp.zeros_like(t)
    mode = Mode(stuck=tup(stuck), sdir=tup(sdir), side=(zero + 1, zero + 1), fly=tup(fly))
    acc = rates(P, CONTACT, mode, dr, State(tup(x), tup(v), zero, zero, tup(y), tup(vy))).v
    return dict(
        e=e, l0=dr.l0[0], N1=L.N[0], N2=L.N[1], f_ex=P.m[0] * acc[0] + P.m[1] * acc[1],
        X=P.centre_of_mass(tup(x)),
    )  # fmt: skip


def _trajectory(P, save_at, rows, ok, status, t_lift, n_switch) -> dict:
    t = jnp.broadcast_to(save_at, rows.shape[:-1])
    x, v = rows[..., 0:2], rows[..., 2:4]
    stuck, sdir = rows[..., 6:8] > 0.5, rows[..., 8:10]
    y, vy, fly = rows[..., 13:15], rows[..., 15:17], rows[..., 19:21] > 0.5
    one = lambda Pi, *a: jax.vmap(lambda *b: _derived(Pi, *b))(*a)
    der = jax.vmap(one)(P, t, x, v, y, vy, stuck, sdir, fly)
    return dict(
        t=t, x1=x[..., 0], v1=v[..., 0], x2=x[..., 1], v2=v[..., 1], e_d=rows[..., 4], w=rows[..., 5],
        mode=mode_code(stuck[..., 0], stuck[..., 1]), valid=ok, status=status, liftoff=jnp.isfinite(t_lift),
        t_liftoff=t_lift, n_switch=n_switch, transversality=jnp.sqrt(rows[..., 10]), near_miss=jnp.sqrt(rows[..., 11]),
        switch_gap=switch_gap(P.omega, t, rows[..., 12]), y=y, vy=vy, n_land=rows[..., -1, 17].astype(jnp.int32),
        zeno=rows[..., -1, 18] > 0.5, **der,
    )  # fmt: skip


_trajectory = jax.jit(_trajectory)


def simulate_batch(
    params: Params,
    wave: AbstractWaveform,
    wave_axes: int | None,
    save_at: Array,
    start: str,
    dt: float,
    max_steps: int,
    initial: Array | None = None,
) -> dict[str, Array]:
    """The fields of a [`Trajectory`][locomotion_jax.Trajectory] under `contact="hop"` of a flat batch
    (leading axis: the configurations), heights included; `max_steps` caps each configuration's
    iterations, saves included; `initial`: states $(x_1, v_1, x_2, v_2)$ at $t = 0$, shape `(n, 4)`."""
    P, _, valid = physics_batch(params, wave, wave_axes)
    row = None if initial is None else initial[:, jnp.asarray(_TO_CHAIN)]
    lanes = default_lanes(valid.shape[0])
    rows, ok, status, t_lift, n_switch = _simulate_rows(
        P, valid, save_at, start, dt, jnp.asarray(max_steps, jnp.int32), lanes, initial=row
    )
    return _trajectory(P, save_at, rows, ok, status, t_lift, n_switch)
