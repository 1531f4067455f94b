"""The exact two-mass engine's trajectories: states saved at requested times.

The batch runs through the work queue ([`_saves.run_saves`][]), so memory grows
with the saves, not with the number of steps; the derived fields (energy, normal
forces, $F_{ex}$) are computed from the saved states afterwards.
"""

import equinox as eqx
import jax
import jax.numpy as jnp

from .._custom_types import Array, Contact
from .._status import mode_code, Status
from ..model import _two_mass as model
from ..model._params import Params, safe_params
from ..model._waveform import AbstractWaveform
from . import _exact as exact
from ._compile import engine_jit
from ._margins import switch_gap
from ._runs import default_lanes, initial_state
from ._saves import BUFFER, run_saves


def derived_fields(params: Params, wave: AbstractWaveform, contact: Contact, t, y, stuck, sdir) -> dict:
    """Energy (eq. 10), normal forces (eq. 5) and $F_{ex}$ (eq. 17) at saved states."""
    f = model.forces(params, wave, t, y[0], y[2], contact)
    r = exact.rates(params, f, y, stuck, sdir)
    return {
        "e": model.total_energy(params, f.l0, y[0], y[1], y[2], y[3]),
        "l0": f.l0,
        "N1": f.N1,
        "N2": f.N2,
        "f_ex": params.m1 * r[1] + params.m2 * r[3],
        "X": model.centre_of_mass(params, y[0], y[2]),
    }


def _row(s: exact.Hybrid) -> Array:
    dtype = s.t.dtype
    return jnp.stack([*s.y, s.stuck1.astype(dtype), s.stuck2.astype(dtype), s.s1, s.s2, s.cross, s.near, s.t_switch])


def _init(params, wave, contact, start, initial=None) -> tuple[tuple, exact.Hybrid]:
    params, valid = safe_params(params, wave)
    st, ok = initial_state(params, wave, contact, start, initial)
    valid = valid & ok
    st = eqx.tree_at(lambda s: s.status, st, jnp.where(valid, st.status, Status.INVALID).astype(jnp.int32))
    return (params, wave, exact.consts(params, wave)), st


def _exact_batch(
    params,
    wave,
    wave_axes,
    save_at,
    contact,
    start,
    dt,
    max_steps,
    lanes: int | None = None,
    buffer: int = BUFFER,
    initial: Array | None = None,
):
    """The saved rows of a flat batch ([`_saves.run_saves`][]: a work queue over `lanes` lanes).

    `lanes=None` takes `_runs.default_lanes` (on a CPU a multiple of `LANE_QUANTUM`), else the whole batch. The
    queue takes the highest frequencies first, as in `measure`. A row is the state
    $(x_1, v_1, x_2, v_2, e_d, w)$, the stick flags, the slip directions and the records of
    the margins. `initial`: per-configuration states at $t = 0$ (`(n, 4)`), or `None`.
    """
    n = params.omega.shape[0]
    if lanes is None:
        lanes = default_lanes(n)
    take = lambda i: jax.tree_util.tree_map(lambda x: x[i], params)
    pick_wave = (lambda i: wave) if wave_axes is None else (lambda i: jax.tree_util.tree_map(lambda x: x[i], wave))
    init = lambda i: _init(take(i), pick_wave(i), contact, start, None if initial is None else initial[i])
    step = lambda f, s, t_stop: exact.step(f[0], f[1], contact, dt, s, t_stop, None, f[2])[0]
    order = jnp.argsort(-jnp.where(jnp.isfinite(params.omega), params.omega, -jnp.inf))
    return run_saves(init, step, _row, n, save_at, max_steps, lanes, order, buffer)


_exact_batch = engine_jit(_exact_batch, ("wave_axes", "contact", "start", "dt", "lanes", "buffer"))


def _trajectory(params, wave, wave_axes, contact, start, save_at, rows, valid, status, t_lift, n_switch):
    y = jnp.moveaxis(rows[..., :6], -1, 0)  # (6, B, n)
    stuck = jnp.moveaxis(rows[..., 6:8] > 0.5, -1, 0)
    sdir = jnp.moveaxis(rows[..., 8:10], -1, 0)
    t = jnp.broadcast_to(save_at, rows.shape[:-1])

    def one(p, w, t, y, stuck, sdir):
        return jax.vmap(lambda t, y, s, d: derived_fields(p, w, contact, t, y, s, d), in_axes=(0, 1, 1, 1))(
            t, y, stuck, sdir
        )

    der = jax.vmap(one, in_axes=(0, wave_axes, 0, 1, 1, 1))(params, wave, t, y, stuck, sdir)
    omega = jnp.broadcast_to(wave.omega, rows.shape[:1])
    return dict(
        t=t,
        x1=y[0],
        v1=y[1],
        x2=y[2],
        v2=y[3],
        e_d=y[4],
        w=y[5],
        mode=mode_code(stuck[0], stuck[1]),
        valid=valid,
        status=status,
        liftoff=jnp.isfinite(t_lift),
        t_liftoff=t_lift,
        n_switch=n_switch,
        transversality=jnp.sqrt(rows[..., 10]),
        near_miss=jnp.sqrt(rows[..., 11]),
        switch_gap=switch_gap(omega, t, rows[..., 12]),
        **der,
    )


# One compiled computation rather than dozens of small ones run op by op: each of
# those is a compilation (or a compilation-cache read) of its own in a new process.
_trajectory = jax.jit(_trajectory, static_argnames=("wave_axes", "contact", "start"))


def simulate_batch(params, wave, wave_axes, save_at, contact, start, dt, max_steps: int, initial=None) -> dict:
    """The fields of a [`Trajectory`][locomotion_jax.Trajectory] of a flat batch (leading axis: the
    configurations); `max_steps` caps each configuration's iterations, saves included."""
    rows, valid, status, t_lift, n_switch = _exact_batch(
        params, wave, wave_axes, save_at, contact, start, dt, jnp.asarray(max_steps, jnp.int32), initial=initial
    )
    return _trajectory(params, wave, wave_axes, contact, start, save_at, rows, valid, status, t_lift, n_switch)
