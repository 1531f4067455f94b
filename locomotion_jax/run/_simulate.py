"""`simulate`: trajectories saved at requested times (memory grows with the saves only)."""

from typing import Any, overload

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array, ArrayLike, Contact
from .._results import ChainTrajectory, Trajectory
from .._status import mode_code, Status
from ..dynamics import _exact as exact
from ..dynamics._base import AbstractDynamics, Exact, Smoothed
from ..dynamics._compile import engine_jit
from ..dynamics._forward import check_static
from ..dynamics._margins import switch_gap
from ..model import _two_mass as model
from ..model._chain import Chain
from ..model._params import Params, safe_params
from ..model._waveform import AbstractWaveform
from ._batch import default_max_steps, initial_state, MICRO_BATCH_CPU, prepare, prepare_initial, unflatten
from ._chain import chain_dynamics, simulate_chain
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
    params, valid = safe_params(params)
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

    `lanes=None` takes `_batch.MICRO_BATCH_CPU` on a CPU, else the whole batch. The
    queue takes the highest frequencies first, as in `measure`. A row is the state
    $(x_1, v_1, x_2, v_2, e_d, w)$, the stick flags, the slip directions and the records of
    the margins. `initial`: per-configuration states at $t = 0$ (`(n, 4)`), or `None`.
    """
    n = params.omega.shape[0]
    if lanes is None:
        lanes = MICRO_BATCH_CPU if jax.default_backend() == "cpu" else n
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


@overload
def simulate(
    params: Params,
    t_end: float,
    save_at: ArrayLike | None = None,
    *,
    dynamics: AbstractDynamics | None = None,
    waveform: AbstractWaveform | None = None,
    contact: str = "strict",
    start: str = "paper",
    initial: tuple | None = None,
    dtype: Any = None,
) -> Trajectory: ...


@overload
def simulate(
    params: Chain,
    t_end: float,
    save_at: ArrayLike | None = None,
    *,
    dynamics: AbstractDynamics | None = None,
    waveform: AbstractWaveform | None = None,
    contact: str = "strict",
    start: str = "paper",
    initial: tuple | None = None,
    dtype: Any = None,
) -> ChainTrajectory: ...


def simulate(
    params: "Params | Chain",
    t_end: float,
    save_at: ArrayLike | None = None,
    *,
    dynamics: AbstractDynamics | None = None,
    waveform: AbstractWaveform | None = None,
    contact: str = "strict",
    start: str = "paper",
    initial: tuple | None = None,
    dtype: Any = None,
) -> "Trajectory | ChainTrajectory":
    """Integrate the two-mass model or a chain from $t = 0$ to `t_end`, saving at `save_at`.

    **Arguments:**

    - `params`: the mechanism, one configuration or a batch: [`Params`][] (the paper's
      two-mass model) or a [`Chain`][] of N masses (which carries its own waveforms).
    - `t_end`: final time (> 0).
    - `save_at`: increasing times in `[0, t_end]`; default 1001 equally spaced
      times. Memory grows with `len(save_at)`, not with the number of steps.
    - `dynamics`: [`Exact`][] (default) or [`Smoothed`][].
    - `waveform`: actuation $\\ell_0(t)$; default the sinusoid of eq. (13) from `params`.
    - `contact`: `"strict"` (default: stop at lift-off) or `"paper"` ($n_i = |N_i|$,
      flagged). `start`: `"paper"` (eq. 14, default) or `"relaxed"`.
    - `initial`: instead of `start`, the state at $t = 0$: a tuple `(x1, v1, x2, v2)` of
      arrays broadcastable to the batch shape, with $x_1 < x_2$ (a mass at rest sticks if
      eq. (7) allows). Forward-mode derivatives with respect to it work as with respect
      to a parameter. Two-mass model only.
    - `dtype`: cast parameters to this floating dtype (default: theirs).

    **Returns:** a [`Trajectory`][] with batch shape `params.batch_shape`, or a
    [`ChainTrajectory`][] for a chain.

    With [`Exact`][] dynamics (both engines) the batch runs through the work queue of
    `measure` (`_saves.run_saves`), at about `measure`'s cost over the same run plus
    one iteration per save (benchmarks/simulate_vs_measure.py). [`Smoothed`][] dynamics
    run diffrax's `diffeqsolve` under `vmap`, as `measure` does with them: the solve is
    one loop of diffrax's own, which a work queue cannot take step by step.

    **Raises:** `ValueError` for invalid arguments (before any computation); an invalid
    `initial` state is refused where its values are known, and flagged `INVALID` in its
    own result under `jit`.

    !!! Example

        ```python
        traj = simulate(Params(omega=2.0), t_end=20.0)
        traj.X[-1], traj.mode[:10]
        ```
    """
    dynamics = Exact() if dynamics is None else dynamics
    model.check_contact(contact)
    model.initial_gap(Params(), start)  # validates `start`
    check_static("t_end", t_end)
    check_static("save_at", save_at)
    if not np.isfinite(t_end) or t_end <= 0:
        raise ValueError(f"t_end must be a finite number > 0, got {t_end!r}.")
    if save_at is None:
        save_at = np.linspace(0.0, float(t_end), 1001)
    save_np = np.asarray(save_at, dtype=float)
    if save_np.ndim != 1 or save_np.size == 0:
        raise ValueError(f"save_at must be a non-empty 1-D array, got shape {save_np.shape}.")
    if np.any(np.diff(save_np) < 0) or save_np[0] < 0 or save_np[-1] > t_end or not np.all(np.isfinite(save_np)):
        raise ValueError("save_at must be finite, non-decreasing and inside [0, t_end].")
    if isinstance(params, Chain):
        if initial is not None:
            raise ValueError("initial= is supported for Params (the two-mass model), not for a Chain.")
        dyn = chain_dynamics(dynamics, waveform)
        return simulate_chain(params, float(t_end), save_np, dynamics=dyn, contact=contact, start=start, dtype=dtype)
    flat, wave, axes, shape = prepare(params, waveform, dtype)
    y0 = prepare_initial(initial, shape, flat.dtype)
    save = jnp.asarray(save_np, flat.dtype)
    if isinstance(dynamics, Exact):
        max_steps = dynamics.max_steps or default_max_steps(float(t_end), dynamics.dt) + 4 * save_np.size
        rows, valid, status, t_lift, n_switch = _exact_batch(
            flat, wave, axes, save, contact, start, dynamics.dt, jnp.asarray(max_steps, jnp.int32), initial=y0
        )
        out = _trajectory(flat, wave, axes, contact, start, save, rows, valid, status, t_lift, n_switch)
    elif isinstance(dynamics, Smoothed):
        from ..dynamics._smooth import simulate_smoothed

        if initial is not None:
            raise ValueError("initial= is supported by the Exact dynamics only.")

        out = simulate_smoothed(flat, wave, axes, save, contact, start, dynamics)
    else:
        raise TypeError(f"dynamics must be Exact or Smoothed, got {type(dynamics).__name__}.")
    out = unflatten(out, shape)
    return Trajectory(**out, start="initial" if initial is not None else start, contact=contact)
