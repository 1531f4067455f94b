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
  free linearised chain for a `Chain` (by eigenvalue interlacing, no higher than any
  frequency of `Chain.natural_frequencies` with one mass held);
- the damping: the decay time $m_i / c_i$ of each mass;
- a `Stribeck` law: the time $v_s / \\mu_s$ over which friction alone (normal force
  $m_i g$, $g = 1$) changes a speed by the law's own scale $v_s$.

A period needs `STEPS_PER_PERIOD` steps, a decay or Stribeck time `STEPS_PER_TIME`. A
configuration whose step is longer is refused with a `ValueError` naming the parameter
and the largest step that resolves it (one configuration whose values are known), or
flagged `Status.UNRESOLVED` in its own result and never run (a batch, or under `jit`).
Only [`Exact`][locomotion_jax.Exact] dynamics are guarded: the smoothed dynamics choose
their steps by error control (a scale they cannot resolve ends as `MAX_STEPS` or
`SOLVER_FAILED`), and a dynamics of one's own states its own needs.
"""

import dataclasses
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
from ..model._chain import Chain
from ..model._checks import is_concrete
from ..model._friction import Stribeck
from ..model._params import Params
from ..model._springwaves import SpringFourier
from ..model._waveform import AbstractWaveform, Fourier, Sinusoid, Spline


STEPS_PER_PERIOD = 4
"""Least steps per forcing or natural period: $\\omega\\,\\Delta t \\le \\pi/2$, inside RK4's
stability interval ($|\\omega \\Delta t| < 2\\sqrt 2$) with a margin of 1.8, and twice the
sampling theorem's two points per period. The paper's figures take at least 8.8 steps per
period (Fig. 12, quick size: $\\omega_{n1} = 35.7$ at $\\hat m = 0.02$ with `dt = 0.02`),
so none of them is affected."""

STEPS_PER_TIME = 1
"""Least steps per damping time $m_i/c_i$ or Stribeck time $v_s/\\mu_s$ (not periods:
RK4 is stable for a decay rate up to $2.78/\\Delta t$)."""


@dataclasses.dataclass(frozen=True)
class Scale:
    """One time scale of every configuration of a flat batch, and what sets it."""

    name: str  # the parameter a message names
    what: str  # e.g. "forcing period 2*pi/(K*omega)"
    time: jax.Array  # shape (size,)
    steps: int
    unit: str  # "period" or "time": what `steps` counts per
    shown: Mapping[str, jax.Array]  # values a message shows, each shape (size,)

    def limit(self) -> jax.Array:
        """The longest step that resolves it."""
        return self.time / self.steps


def harmonics(wave: AbstractWaveform | SpringFourier) -> int:
    """$K$: the forcing's shortest period is $2\\pi/(K\\omega)$ (a spline's knot spacing for a `Spline`)."""
    if isinstance(wave, (Fourier, SpringFourier)):
        return int(wave.harmonics)
    if isinstance(wave, Spline):
        return int(wave.knots)
    return 1


def _flat(x, size: int) -> jax.Array:
    x = jnp.asarray(x)
    return jnp.broadcast_to(x.reshape((-1,)) if x.size == size else x.reshape(()), (size,))


def _forcing(wave: AbstractWaveform | SpringFourier, omega: jax.Array) -> Scale:
    K = harmonics(wave)
    what = f"forcing period 2*pi/(K*omega) (K = {K})"
    return Scale("omega", what, 2 * math.pi / (K * omega), STEPS_PER_PERIOD, "period", {"omega": omega})


def two_mass_scales(params: Params, wave: AbstractWaveform) -> list[Scale]:
    """The scales of a flat batch of the paper's model (`params` of shape `(size,)`)."""
    omega = _flat(wave.omega, params.batch_shape[0])
    m_min = jnp.minimum(params.m1, params.m2)
    natural = 2 * math.pi / params.wn1
    return [
        _forcing(wave, omega),
        Scale("k", "natural period 2*pi/wn1 (eq. 11)", natural, STEPS_PER_PERIOD, "period",
              {"k": params.k, "mhat": params.mhat}),
        Scale("c", "damping time min(m1, m2)/c", m_min / params.c, STEPS_PER_TIME, "damping time",
              {"c": params.c, "mhat": params.mhat}),
    ]  # fmt: skip


def _free_frequency(chain: Chain) -> jax.Array:
    """Highest natural frequency of the free linearised chain (no mass held), batch shape."""
    n = chain.n_masses
    j = jnp.arange(n - 1)
    K = jnp.zeros(chain.k.shape[:-1] + (n, n), chain.k.dtype)
    K = K.at[..., j, j].add(chain.k).at[..., j + 1, j + 1].add(chain.k)
    K = K.at[..., j, j + 1].add(-chain.k).at[..., j + 1, j].add(-chain.k)
    s = 1 / jnp.sqrt(chain.m)
    return jnp.sqrt(jnp.clip(jnp.linalg.eigvalsh(K * s[..., :, None] * s[..., None, :])[..., -1], 0))


def chain_scales(chain: Chain) -> list[Scale]:
    """The scales of a flat, broadcast batch of chains (batch shape `(size,)`)."""
    natural = 2 * math.pi / _free_frequency(chain)
    decay = jnp.min(chain.m / chain.c, -1)
    scales = [
        _forcing(chain.waves, chain.waves.omega),
        Scale("k", "natural period 2*pi/w_max of the free chain", natural, STEPS_PER_PERIOD, "period",
              {"k (largest)": chain.k.max(-1), "masses (smallest)": chain.m.min(-1)}),
        Scale("c", "damping time min_i m_i/c_i", decay, STEPS_PER_TIME, "damping time",
              {"c (largest)": chain.c.max(-1)}),
    ]  # fmt: skip
    fr = chain.friction
    if isinstance(fr, Stribeck):
        t = jnp.min(fr.v_s / jnp.maximum(jnp.maximum(fr.mu_s, fr.mu_s_bwd), 1e-300), -1)
        scales.append(Scale("v_s", "Stribeck time v_s/mu_s", t, STEPS_PER_TIME, "Stribeck time",
                            {"v_s (smallest)": fr.v_s.min(-1)}))  # fmt: skip
    return scales


def unresolved(scales: list[Scale], dt: float, valid: jax.Array) -> jax.Array:
    """Mask of the valid configurations whose step `dt` is longer than one of their scales allows."""
    bad = jnp.zeros_like(valid)
    for s in scales:
        bad = bad | (dt > s.limit())  # False for NaN: an invalid configuration stays INVALID
    return valid & bad


def refuse(scales: list[Scale], dt: float) -> None:
    """Raise the `ValueError` for one configuration whose values are known (index 0)."""
    for s in scales:
        limit = float(np.asarray(s.limit())[0])
        if dt > limit:
            shown = ", ".join(f"{n}={float(np.asarray(v)[0]):.6g}" for n, v in s.shown.items())
            raise ValueError(
                f"Invalid parameter {s.name!r}: Exact(dt={dt!r}) does not resolve the {s.what} = "
                f"{float(np.asarray(s.time)[0]):.6g} ({shown}); it needs dt <= {limit:.3g} ({s.steps} steps per "
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
    """`None` where nothing needs flagging (no `Exact` dynamics, or every known configuration
    resolved); else the mask of the configurations to flag. Raises for one known configuration."""
    if not isinstance(dynamics, Exact):
        return None
    scales = scales_fn()
    mask = unresolved(scales, dynamics.dt, valid)
    if not concrete:
        return mask
    if not np.asarray(mask).any():
        return None
    if scalar:
        refuse(scales, dynamics.dt)
    return mask


def guard_two_mass(dynamics: AbstractDynamics, flat: Params, wave: AbstractWaveform, shape: tuple[int, ...]):
    """`(flat, mask)`: the flat params with the unresolved configurations marked invalid (the
    engines then skip them; `flag` turns their status into `UNRESOLVED`), and the mask or `None`."""
    size = flat.batch_shape[0]
    valid = flat.is_valid() & _flat(wave.is_valid(), size)
    mask = guard(dynamics, lambda: two_mass_scales(flat, wave), valid, shape == (), is_concrete((flat, wave)))
    if mask is None:
        return flat, None
    # An invalid configuration is never advanced by the engines (`safe_params`): that is how a
    # front end keeps an unresolved one from running without a path of its own through them.
    return eqx.tree_at(lambda p: p.mhat, flat, jnp.where(mask, jnp.nan, flat.mhat)), mask


def guard_chain(dynamics: AbstractDynamics, flat: Any, valid: jax.Array, shape: tuple[int, ...]):
    """`(valid, mask)`: `valid` without the unresolved chains, and the mask or `None`. A
    [`Mechanism`][locomotion_jax.Mechanism]'s time scales are not guarded yet (`None`)."""
    if not isinstance(flat, Chain):
        return valid, None
    mask = guard(dynamics, lambda: chain_scales(flat), valid, shape == (), is_concrete((flat, valid)))
    return (valid, None) if mask is None else (valid & ~mask, mask)


def guard_values(values: Mapping[str, np.ndarray], dtype, dynamics: AbstractDynamics):
    """A sweep chunk's host values with the unresolved configurations made invalid (NaN), and
    their mask (host) or `None` (the sweeps then set their status with `flag`)."""
    if not isinstance(dynamics, Exact):
        return values, None
    with np.errstate(all="ignore"):
        flat = Params(**{n: jnp.asarray(v, dtype) for n, v in values.items()}, check=False)
        mask = guard(dynamics, lambda: two_mass_scales(flat, Sinusoid.from_params(flat)), flat.is_valid(), False, True)
    if mask is None:
        return values, None
    mask = np.asarray(mask)
    return {**values, "mhat": np.where(mask, np.nan, values["mhat"])}, mask


def flag(out: dict, mask) -> dict:
    """`out` with the status of the masked configurations `Status.UNRESOLVED` (`mask` `None`: unchanged)."""
    if mask is None:
        return out
    status = out["status"]
    xp = np if isinstance(status, np.ndarray) else jnp
    return {**out, "status": xp.where(mask, Status.UNRESOLVED, status).astype(status.dtype)}
