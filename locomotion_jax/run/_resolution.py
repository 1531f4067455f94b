"""Resolution guards: a fixed step must resolve the time scales a configuration sets.

The exact engines take RK4 steps of a fixed nominal length `Exact.dt` between located
switches. A forcing or a natural period shorter than a few steps is not integrated but
aliased: the run still ends and reports numbers (issue 29: `Params(omega=1e4)` at
`dt = 0.01` gave status OK with a mean speed 700 times too large). The front ends compare
each configuration's shortest time scales with its step before anything runs:

- the forcing: the period of the highest harmonic, $2\\pi / (K\\omega)$ ($K = 1$ for a
  `Sinusoid` or `TravellingWave`, the number of harmonics of a `Fourier` or
  `SpringFourier`, the number of knots of a `Spline`, whose pieces span $2\\pi/(M\\omega)$);
- the mechanism: its highest natural period, $2\\pi/\\omega_{n1}$ for the paper's model
  (eq. 11; $\\omega_{n1} \\ge \\omega_{n2}, \\omega_{n3}$) and $2\\pi/\\omega_\\max$ of the
  free linearised bodies for a `Chain` or a `Mechanism` (every spring, wall springs included;
  by eigenvalue interlacing no higher than any frequency with one mass held);
- the damping: the decay time $m_i / c_i$ of each mass;
- a `Stribeck` law: the time $v_s / \\mu_s$ over which friction alone (normal force
  $m_i g$, $g = 1$) changes a speed by the law's own scale $v_s$.

Each mechanism reports these itself (`AbstractMechanism.time_scales`, `model._scales`), so
the guards do not ask which kind of mechanism they hold. A period needs `STEPS_PER_PERIOD`
steps, a decay or Stribeck time `STEPS_PER_TIME`. A configuration whose step is longer is
refused with a `ValueError` naming the parameter and the largest step that resolves it (one
configuration whose values are known), or flagged `Status.UNRESOLVED` in its own result and
never run (a batch, or under `jit`).

A measurement's default start (`t_start` not given: 80 periods of the lowest natural
frequency, `AbstractMechanism.start_scale`) may take at most `MAX_START_STEPS` steps: a valid
but very soft spring would otherwise set a start of ages. Such a configuration is refused
naming `t_start` and the spring, or flagged `UNRESOLVED` in a batch; an explicit `t_start`
is not limited.
Every dynamics with a fixed step is guarded, at its `nominal_step()` ([`Exact`][locomotion_jax.Exact]'s
`dt`, and a dynamics of one's own that states one): the smoothed dynamics choose their steps by
error control (`nominal_step()` is `None`; a scale they cannot resolve ends as `MAX_STEPS` or
`SOLVER_FAILED`).
"""

import math
from collections.abc import Mapping
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._status import Status
from ..dynamics._base import AbstractDynamics
from ..dynamics._exact_dynamics import Exact
from ..model._checks import is_concrete
from ..model._mechanism import AbstractMechanism
from ..model._params import Params
from ..model._scales import (  # noqa: F401 (re-exported: the tests and sweeps read them here)
    harmonics,
    MAX_START_STEPS,
    STEPS_PER_PERIOD,
    STEPS_PER_TIME,
    TimeScale as Scale,
)
from ..model._waveform import AbstractWaveform, Sinusoid


def _flat(x, size: int) -> jax.Array:
    x = jnp.asarray(x)
    return jnp.broadcast_to(x.reshape((-1,)) if x.size == size else x.reshape(()), (size,))


def two_mass_scales(params: Params, wave: AbstractWaveform) -> list[Scale]:
    """The scales of a flat batch of the paper's model (`params` of shape `(size,)`)."""
    return params.time_scales(wave)


def chain_scales(mechanism: AbstractMechanism) -> list[Scale]:
    """The scales of a flat, broadcast batch of a mechanism of the N-body path (a chain or a
    `Mechanism`; batch shape `(size,)`)."""
    return mechanism.time_scales()


def unresolved(scales: list[Scale], dt: float, valid: jax.Array) -> jax.Array:
    """Mask of the valid configurations whose step `dt` does not serve one of their scales."""
    bad = jnp.zeros_like(valid)
    for s in scales:
        bad = bad | s.exceeded(dt)  # False for NaN: an invalid configuration stays INVALID
    return valid & bad


def refuse(scales: list[Scale], dt: float) -> None:
    """Raise the `ValueError` for one configuration whose values are known (index 0)."""
    for s in scales:
        if not bool(np.asarray(s.exceeded(dt))[0]):
            continue
        shown = ", ".join(f"{n}={float(np.asarray(v)[0]):.6g}" for n, v in s.shown.items())
        time = float(np.asarray(s.time)[0])
        if s.unit == "span":
            raise ValueError(
                f"Invalid parameter 't_start': the {s.what} = {time:.6g} ({shown}) would take {time / dt:.3g} steps "
                f"of Exact(dt={dt!r}), more than {s.steps:.3g}. Give an explicit t_start= (e.g. a few periods of "
                "the forcing), or stiffer springs."
            )
        limit = float(np.asarray(s.limit())[0])
        raise ValueError(
            f"Invalid parameter {s.name!r}: Exact(dt={dt!r}) does not resolve the {s.what} = "
            f"{time:.6g} ({shown}); it needs dt <= {limit:.3g} ({s.steps} steps per "
            f"{s.unit}). Give Exact(dt={_round_down(limit)!r}) "
            "or smaller, or change the parameter."
        )


def _round_down(x: float) -> float:
    """A step at most `x` with two significant digits (what a message suggests)."""
    if not (0 < x < math.inf):
        return x
    q = 10.0 ** (math.floor(math.log10(x)) - 1)
    return float(f"{math.floor(x / q) * q:.2g}")


def guard(dynamics: AbstractDynamics, scales_fn, valid: jax.Array, scalar: bool, concrete: bool):
    """`None` where nothing needs flagging (a dynamics without a fixed step, whose
    `nominal_step()` is `None`, or every known configuration resolved); else the mask of the
    configurations to flag. Raises for one known configuration."""
    dt = dynamics.nominal_step()
    if dt is None:
        return None
    scales = scales_fn()
    mask = unresolved(scales, dt, valid)
    if not concrete:
        return mask
    if not np.asarray(mask).any():
        return None
    if scalar:
        refuse(scales, dt)
    return mask


def guard_two_mass(dynamics: AbstractDynamics, flat: Params, wave: AbstractWaveform, shape: tuple[int, ...],
                   default_start: bool = False):  # fmt: skip
    """`(flat, mask)`: the flat params with the unresolved configurations marked invalid (the
    engines then skip them; `flag` turns their status into `UNRESOLVED`), and the mask or `None`.
    `default_start`: the run starts its measurement at `Params.t_start` (its span is guarded)."""
    size = flat.batch_shape[0]
    valid = flat.is_valid() & _flat(wave.is_valid(), size)
    scales = lambda: flat.time_scales(wave) + ([flat.start_scale()] if default_start else [])
    mask = guard(dynamics, scales, valid, shape == (), is_concrete((flat, wave)))
    if mask is None:
        return flat, None
    # An invalid configuration is never advanced by the engines (`safe_params`): that is how a
    # front end keeps an unresolved one from running without a path of its own through them.
    return eqx.tree_at(lambda p: p.mhat, flat, jnp.where(mask, jnp.nan, flat.mhat)), mask


def guard_chain(dynamics: AbstractDynamics, flat: AbstractMechanism, valid: jax.Array, shape: tuple[int, ...],
                default_start: bool = False):  # fmt: skip
    """`(valid, mask)`: `valid` without the unresolved configurations of a flat mechanism of the
    N-body path (a [`Chain`][] or a [`Mechanism`][locomotion_jax.Mechanism]), and the mask or
    `None`; `default_start` as in `guard_two_mass`."""
    scales = lambda: flat.time_scales() + ([flat.start_scale()] if default_start else [])
    mask = guard(dynamics, scales, valid, shape == (), is_concrete((flat, valid)))
    return (valid, None) if mask is None else (valid & ~mask, mask)


def guard_values(values: Mapping[str, np.ndarray], dtype, dynamics: AbstractDynamics, default_start: bool = False):
    """A sweep chunk's host values with the unresolved configurations made invalid (NaN), and
    their mask (host) or `None` (the sweeps then set their status with `flag`)."""
    if dynamics.nominal_step() is None:
        return values, None
    with np.errstate(all="ignore"):
        flat = Params(**{n: jnp.asarray(v, dtype) for n, v in values.items()}, check=False)
        scales = lambda: flat.time_scales(Sinusoid.from_params(flat)) + ([flat.start_scale()] if default_start else [])
        mask = guard(dynamics, scales, flat.is_valid(), False, True)
    if mask is None:
        return values, None
    mask = np.asarray(mask)
    return {**values, "mhat": np.where(mask, np.nan, values["mhat"])}, mask


def _single(mechanism: AbstractMechanism) -> AbstractMechanism:
    """One configuration (batch shape `()`) as a flat batch of one."""
    return jax.tree_util.tree_map(lambda x: jnp.reshape(x, (1,) + jnp.shape(x)), mechanism)


def refuse_search(mechanism: AbstractMechanism, waveform: Any, dt: float, what: str, skip: tuple[str, ...] = ()
                  ) -> None:  # fmt: skip
    """Raise the `ValueError` of `refuse`, with `what` appended, where the step `dt` does not
    resolve one configuration (`mechanism` of batch shape `()`, at the fastest forcing a search
    such as an optimiser's may reach; `waveform` for the paper's model, else `None`). The scales
    named in `skip` are not checked (a search that verifies them by a convergence study)."""
    one = _single(mechanism)
    scales = lambda: [s for s in one.time_scales(waveform) if s.name not in skip]
    try:
        guard(Exact(dt), scales, one.is_valid().reshape(1), True, True)
    except ValueError as err:
        raise ValueError(f"{err} {what}") from None


def resolved_step(mechanism: AbstractMechanism, waveform: Any, dt: float) -> float:
    """`dt`, or the step the resolution guard's message would suggest where `dt` does not resolve
    one configuration (`mechanism` of batch shape `()`; `waveform` for the paper's model, else
    `None`): the longest step of two significant digits that serves every scale."""
    one = _single(mechanism)
    limits = [float(np.asarray(s.limit())[0]) for s in one.time_scales(waveform) if s.unit != "span"]
    return min([dt] + [_round_down(limit) for limit in limits if limit < dt])


def flag(out: dict, mask) -> dict:
    """`out` with the status of the masked configurations `Status.UNRESOLVED` (`mask` `None`: unchanged)."""
    if mask is None:
        return out
    status = out["status"]
    xp = np if isinstance(status, np.ndarray) else jnp
    return {**out, "status": xp.where(mask, Status.UNRESOLVED, status).astype(status.dtype)}
