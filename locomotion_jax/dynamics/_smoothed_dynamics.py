"""`Smoothed`: smoothed friction integrated by diffrax (SPEC §3), as an `AbstractDynamics`.

`eps` is an array (traced: a continuation in `eps` does not recompile); the solver's
settings are static. Every mechanism runs on one engine (`_smoothed`), written against the
physics interface: the paper's model as its two-body physics (`params_physics`), with the
N-body fields mapped to a `Trajectory`'s and a `Measurement`'s here; a `Chain` and a
`Mechanism` with their own, a chain in its layout (`_chain_array.engine_physics`: the array
layout's one entry over the masses keeps the program's size independent of N). Each run is
diffrax's `diffeqsolve` under `vmap`: one loop of diffrax's own, which the exact engine's work
queue cannot take step by step.
"""

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.sharding import Mesh

from .._custom_types import Array, ArrayLike
from ..model._chain import Chain
from ..model._chain_array import engine_physics
from ..model._params import Params, safe_params
from ..model._physics import AbstractPhysics
from ..model._two_mass import initial_gap
from ..model._waveform import AbstractWaveform
from . import _smoothed as smoothed
from ._base import AbstractDynamics
from ._flat import FlatBatch


class Smoothed(AbstractDynamics):
    """Smoothed friction integrated by diffrax (SPEC §3); differentiable. Runs every mechanism
    (the paper's model, a `Chain`, a `Mechanism`) on one engine written against its physics,
    with both starts, `initial=` states and `t_start`; `contact="strict"` or `"paper"`.

    Friction on a body with normal force $n$ and velocity $v$ (the paper's Coulomb law; any
    other law is smoothed the same way, `AbstractFriction.smoothed`):

    $$f(v) = -n\\,\\big[\\mu_k + (\\mu_s - \\mu_k)\\, e^{-(v/v_s)^2}\\big] \\tanh(v/\\varepsilon),
    \\qquad v_s = \\sqrt{\\varepsilon},$$

    a regularised sign with a Stribeck-like static bump. As $\\varepsilon \\to 0$,
    $v_s \\to 0$ and $v_s / \\varepsilon \\to \\infty$, so the peak friction tends to
    $\\mu_s n$ and the sliding friction to $\\mu_k n$: the exact law.

    **Arguments:**

    - `eps`: regularisation velocity $\\varepsilon > 0$ (traced).
    - `rtol`, `atol`: tolerances of diffrax's PID step-size controller.
    - `max_steps`: diffrax's step cap.
    - `solver`: `"tsit5"` (explicit, default) or `"kvaerno5"` (implicit, for very small `eps`).
    """

    eps: Array
    rtol: float = eqx.field(static=True, default=1e-7)
    atol: float = eqx.field(static=True, default=1e-9)
    max_steps: int = eqx.field(static=True, default=2_000_000)
    solver: str = eqx.field(static=True, default="tsit5")

    def __init__(
        self,
        eps: ArrayLike = 1e-3,
        rtol: float = 1e-7,
        atol: float = 1e-9,
        max_steps: int = 2_000_000,
        solver: str = "tsit5",
    ):
        self.eps = jnp.asarray(eps)
        self.rtol, self.atol, self.max_steps, self.solver = rtol, atol, max_steps, solver
        if solver not in ("tsit5", "kvaerno5"):
            raise ValueError(f"Smoothed.solver must be 'tsit5' or 'kvaerno5', got {solver!r}.")
        if not (rtol > 0 and atol > 0):
            raise ValueError(f"Smoothed.rtol and atol must be > 0, got {rtol!r}, {atol!r}.")
        try:
            bad = bool(jnp.any(~(self.eps > 0)))
        except Exception:  # traced eps: checked by the caller's status instead
            bad = False
        if bad:
            raise ValueError(f"Smoothed.eps must be > 0, got {eps!r}.")

    def simulate(self, batch: FlatBatch, save_at: Array, t_end: float, contact: str, start: str) -> dict[str, Array]:
        dyn = self.astype(batch.dtype)
        if batch.wave is not None:  # the paper's model: its physics from parameters and waveform
            args = (batch.mechanism, batch.wave, batch.wave_axes, save_at, contact, start, batch.initial, dyn)
            return two_mass_trajectory(_simulate_two_mass(*args))
        return _simulate_bodies(batch.mechanism, batch.valid, save_at, contact, start, batch.initial, dyn)

    def measure(
        self, batch: FlatBatch, z: ArrayLike, horizon: ArrayLike, window: ArrayLike, contact: str, start: str
    ) -> dict[str, Array]:
        z_, h_, w_ = (jnp.asarray(v, batch.dtype) for v in (z, horizon, window))
        dyn = self.astype(batch.dtype)
        if batch.wave is not None:  # the paper's model: its physics from parameters and waveform
            p, wave, axes = batch.mechanism, batch.wave, batch.wave_axes
            return _measure_two_mass(p, wave, axes, z_, h_, w_, contact, start, batch.t_start, batch.initial, dyn)
        # The default start (eigenvalues of the linearised chain) outside the program, as the exact
        # engine's: a batched eigensolver inside it can deadlock XLA's CPU thread pool (seen at N = 16,
        # batch 64).
        ts = jnp.asarray(batch.mechanism.t_start if batch.t_start is None else batch.t_start, batch.dtype)
        return _measure_bodies(batch.mechanism, batch.valid, ts, z_, h_, w_, contact, start, batch.initial, dyn)

    def measure_chunk(
        self,
        batch: FlatBatch,
        zhw: Array,
        contact: str,
        start: str,
        max_steps: Array,
        mesh: Mesh,
        lanes: int | None,
    ) -> dict[str, Array]:
        # diffrax's closure conversion rejects shard_map's per-device types, so the
        # smoothed model is left to jit's automatic partitioning of the sharded batch
        # (correct, but every device iterates until the slowest configuration is done).
        z, horizon, window = zhw[0], zhw[1], zhw[2]
        if batch.wave is None or batch.wave_axes is None:  # a mechanism with its own actuation, or one shared
            return self.measure(batch, z, horizon, window, contact, start)
        params, wave = batch.mechanism, batch.wave
        one = lambda q, w: _measure_params(q, w, z, horizon, window, contact, start, None, None, self)
        if not lanes or lanes >= batch.size:
            return jax.vmap(one)(params, wave)
        # Sub-batches in sequence, each vmapped: a sub-batch's while_loop stops with
        # its own slowest configuration, and its state stays in cache.
        return jax.lax.map(lambda args: one(*args), (params, wave), batch_size=lanes)

    def step_cap(self, t_total: float) -> int:
        return 0  # each diffrax solve is capped by `max_steps`

    def nominal_step(self) -> float | None:
        return None  # adaptive steps

    def describe(self) -> dict[str, Any]:
        return {
            "dynamics": "smoothed",
            "eps": float(jnp.max(self.eps)),
            "rtol": self.rtol,
            "atol": self.atol,
            "solver": self.solver,
        }

    def spec(self) -> dict[str, Any]:
        return self.describe()


# -- the paper's model: its two-mass physics, and the N-body fields as the two-mass ones --------


def params_physics(params: Params, wave: AbstractWaveform) -> AbstractPhysics:
    """The physics of one configuration of the paper's model actuated by `wave`: the two-mass
    chain of `Chain.from_params`, its rest length $\\ell_0(t)$ the waveform's own (its mean
    `wave.lbar`, which may differ from `params.lbar`, the start's gap)."""
    p = eqx.tree_at(lambda q: q.lbar, params, jnp.broadcast_to(jnp.asarray(wave.lbar, params.dtype), params.lbar.shape))
    return Chain.from_params(p, wave).astype(params.dtype).physics()  # the chain's own fields in the params' dtype


def params_state(params: Params, start: str, initial: Array | None) -> Array:
    """The flat state $(x_1, x_2, v_1, v_2, e_d, w)$ at $t = 0$: `initial` $(x_1, x_2, v_1, v_2)$, or
    $x_1 = 0$ and the gap of eq. (14) or of the relaxed spring (`initial_gap`), at rest."""
    if initial is not None:
        return jnp.concatenate([initial, jnp.zeros((2,), initial.dtype)])
    gap = initial_gap(params, start)
    zero = 0 * gap
    return jnp.stack([zero, gap, zero, zero, zero, zero]).astype(params.dtype)


def _simulate_params(p, w, save, contact, start, initial, dyn):
    p, valid = safe_params(p, w)
    P = params_physics(p, w)
    return smoothed.simulate_one(P, valid, save, contact, params_state(p, start, initial), dyn)


def _measure_params(p, w, z, horizon, window, contact, start, t_start, initial, dyn):
    p, valid = safe_params(p, w)
    ws = p.t_start if t_start is None else jnp.asarray(t_start, p.dtype)
    P = params_physics(p, w)
    return smoothed.measure_one(P, valid, ws, z, horizon, window, contact, params_state(p, start, initial), dyn)


@eqx.filter_jit
def _simulate_two_mass(flat, wave, axes, save, contact, start, initial, dyn):
    one = lambda p, w, y: _simulate_params(p, w, save, contact, start, y, dyn)
    return jax.vmap(one, in_axes=(0, axes, 0))(flat, wave, initial)


@eqx.filter_jit
def _measure_two_mass(flat, wave, axes, z, horizon, window, contact, start, t_start, initial, dyn):
    one = lambda p, w, ts, y: _measure_params(p, w, z, horizon, window, contact, start, ts, y, dyn)
    return jax.vmap(one, in_axes=(0, axes, 0, 0))(flat, wave, t_start, initial)


def two_mass_trajectory(out: dict[str, Array]) -> dict[str, Array]:
    """The engine's N-body trajectory fields as the paper's model's `Trajectory`: the rest lengths
    as `rest_length`, no `tension` (the exact engine's paper runs have none)."""
    out = dict(out)
    del out["tension"]
    out["rest_length"] = out.pop("l0")
    return out


# -- chains and mechanisms: their own physics ---------------------------------------------------


@eqx.filter_jit
def _simulate_bodies(M, valid, save, contact, start, initial, dyn):
    def one(M, ok, y):
        P = engine_physics(M)  # a chain's layout (`_chain_array`)
        return smoothed.simulate_one(P, ok, save, contact, smoothed.initial_state(P, start, y), dyn)

    out = jax.vmap(one)(M, valid, initial)
    del out["f_ex"]  # the paper's model's only
    out["rest_length"] = out.pop("l0")
    return out


@eqx.filter_jit
def _measure_bodies(M, valid, ws, z, horizon, window, contact, start, initial, dyn):
    def one(M, ok, ws, y):
        P = engine_physics(M)  # a chain's layout (`_chain_array`)
        return smoothed.measure_one(P, ok, ws, z, horizon, window, contact, smoothed.initial_state(P, start, y), dyn)

    return jax.vmap(one)(M, valid, ws, initial)
