"""The paper's two-mass model on the N-body engine (`_chain_exact`): `measure` and `simulate` runs.

Each configuration's physics is [`Params.physics`][locomotion_jax.Params.physics] (the two-mass
chain, SPEC §8 at $N = 2$), built inside the work queue when a lane takes the configuration;
the loops are the N-body engine's (`_chain_measure`, `_chain_simulate`'s rows). This module
only translates: the paper's parameters, waveform and states $(x_1, v_1, x_2, v_2)$ in, the
fields of [`Measurement`][locomotion_jax.Measurement] and [`Trajectory`][locomotion_jax.Trajectory] out.
"""

import jax
import jax.numpy as jnp

from .._custom_types import Array
from ..model._params import Params, safe_params
from ..model._waveform import AbstractWaveform
from . import _chain_measure as chain_measure
from ._compile import engine_jit
from ._queue import run_queue
from ._runs import default_lanes


# A two-mass state (x1, v1, x2, v2) as the N-body engine's (x1, x2, v1, v2).
_TO_CHAIN = (0, 2, 1, 3)


def _picker(params: Params, wave: AbstractWaveform, wave_axes: int | None, t_start, initial):
    """`take(i)`: configuration `i`'s `(physics, valid, t_start, initial row)` (for the engine)."""
    wave_at = (lambda i: wave) if wave_axes is None else (lambda i: jax.tree_util.tree_map(lambda x: x[i], wave))

    def take(i):
        p, w = jax.tree_util.tree_map(lambda x: x[i], params), wave_at(i)
        safe, valid = safe_params(p, w)
        row = None if initial is None else initial[i][jnp.asarray(_TO_CHAIN)]
        ts = None if t_start is None else jnp.where(jnp.isnan(t_start[i]), safe.t_start, t_start[i])
        return safe.physics(w), valid, ts if ts is not None else safe.t_start, row

    return take


def _order(params: Params) -> Array:
    """The queue's order: the highest frequencies (most mode switches per time unit) first."""
    return jnp.argsort(-jnp.where(jnp.isfinite(params.omega), params.omega, -jnp.inf))


def _measurement(out: dict) -> dict:
    """The N-body engine's fields as a two-mass `Measurement`'s (`stick_fraction` per mass)."""
    frac = out.pop("stick_fraction")
    return out | {"stick_fraction1": frac[..., 0], "stick_fraction2": frac[..., 1]}


def measure_batch(
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
    lanes: int | None = None,
    t_start: Array | None = None,
    initial: Array | None = None,
) -> dict[str, Array]:
    """`measure` of the paper's model on a flat batch (not jitted): a work queue over `lanes`
    lanes ([`_queue.run_queue`][]), highest frequencies first.

    `lanes=None` takes `_runs.default_lanes`. `t_start`: per-configuration measurement starts
    (NaN: the paper's `Params.t_start`), default all the paper's. `initial`: per-configuration
    states $(x_1, v_1, x_2, v_2)$ at $t = 0$, shape `(n, 4)` (default: at rest in the `start`
    position). `max_steps`: an explicit cap on each configuration's iterations, or 0 for each
    one's own default from its span (`_runs.step_cap`).
    """
    n = params.omega.shape[0]
    lanes = default_lanes(n) if lanes is None else lanes
    take = _picker(params, wave, wave_axes, t_start, initial)
    setup = lambda i: chain_measure._setup(*take(i), z, horizon, window, contact, start, dt, max_steps)
    advance = lambda f, d: chain_measure._advance(f, d, contact, dt)
    results = lambda f, d: chain_measure._results(f, d, contact)
    return _measurement(run_queue(setup, chain_measure._running, advance, results, n, lanes, _order(params)))


_measure_batch = engine_jit(measure_batch, ("wave_axes", "contact", "start", "dt", "lanes"))


def measure_one(params: Params, wave: AbstractWaveform, z, horizon, window, contact, start, dt, max_steps) -> dict:
    """One configuration in a plain loop of its own (no queue): what the queue must reproduce."""
    add = lambda tree: jax.tree_util.tree_map(lambda x: x[None], tree)
    take = _picker(add(params), add(wave), 0, None, None)
    f, d = chain_measure._setup(*take(0), z, horizon, window, contact, start, dt, max_steps)
    advance = lambda d: chain_measure._advance(f, d, contact, dt)
    d = jax.lax.while_loop(lambda d: chain_measure._running(f, d), advance, d)
    return _measurement(chain_measure._results(f, d, contact))
