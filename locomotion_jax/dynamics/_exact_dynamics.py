"""`Exact`: the hybrid stick/slip dynamics with located switches, as an `AbstractDynamics`.

Its settings are Python numbers, static under `jit` (changing them recompiles). The
paper's model runs on the N-body engine (`_paper`), as the chains do (`_simulate`,
`_measure`): each a flat batch through the work queue (`_queue`).
"""

import dataclasses
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.sharding import Mesh, PartitionSpec

from .._custom_types import Array, ArrayLike
from ..model._chain_array import engine_physics
from . import _measure, _paper, _simulate
from ._base import AbstractDynamics
from ._flat import FlatBatch
from ._forward import check_static
from ._runs import default_lanes, default_max_steps


class Exact(AbstractDynamics):
    """Exact hybrid stick/slip dynamics (eqs. 7, 9) with located switches.

    **Arguments:**

    - `dt`: nominal RK4 step (fourth order; see README for accuracy vs `dt`).
    - `max_steps`: hard cap on each configuration's integrator iterations (steps cut
      at events included); `None` picks one per configuration from its own simulated
      time (`measure`: its $t_\\text{start}$ + horizon; `simulate`: `t_end`, plus the
      saves), so a configuration stops at the same step alone and in a batch.
    """

    dt: float = eqx.field(static=True, default=0.01)
    max_steps: int | None = eqx.field(static=True, default=None)

    def __check_init__(self):
        check_static("Exact.dt", self.dt)
        if not (isinstance(self.dt, (int, float)) and 0 < self.dt <= 0.1):
            raise ValueError(f"Exact.dt must be a number in (0, 0.1], got {self.dt!r}.")
        if self.max_steps is not None and not (isinstance(self.max_steps, int) and self.max_steps > 0):
            raise ValueError(f"Exact.max_steps must be a positive int or None, got {self.max_steps!r}.")

    def simulate(self, batch: FlatBatch, save_at: Array, t_end: float, contact: str, start: str) -> dict[str, Array]:
        # Room for the steps to t_end, plus the iterations that save a state.
        max_steps = self.max_steps or default_max_steps(t_end, self.dt) + 4 * save_at.shape[0]
        if batch.wave is not None:  # the paper's model: its physics from parameters and waveform (`_paper`)
            args = (batch.mechanism, batch.wave, batch.wave_axes, save_at, contact, start, self.dt, max_steps)
            return _paper.simulate_batch(*args, batch.initial)
        args = (batch.mechanism, batch.valid, save_at, contact, start, self.dt, max_steps)
        return _simulate.simulate_batch(*args, batch.initial)

    def measure(
        self, batch: FlatBatch, z: ArrayLike, horizon: ArrayLike, window: ArrayLike, contact: str, start: str
    ) -> dict[str, Array]:
        return self._measure(batch, z, horizon, window, contact, start, None)

    def _measure(
        self,
        batch: FlatBatch,
        z,
        horizon,
        window,
        contact: str,
        start: str,
        lanes: int | None,
        cap: Array | None = None,
    ):
        """`measure`, over `lanes` lanes of the work queue (`None`: the engine's choice), each
        configuration's loop capped at `cap` (`None`: [`_own_cap`][])."""
        cap = self._own_cap() if cap is None else cap
        if batch.wave is not None:  # the paper's model: its physics from parameters and waveform (`_paper`)
            z_, h_, w_ = (jnp.asarray(v, batch.dtype) for v in (z, horizon, window))
            p, wave, axes = batch.mechanism, batch.wave, batch.wave_axes
            if lanes:
                return _paper.measure_batch(
                    p, wave, axes, z_, h_, w_, contact, start, self.dt, cap, lanes, batch.t_start, batch.initial
                )
            return _paper.measure(
                p, wave, axes, z_, h_, w_, contact, start, self.dt, cap, t_start=batch.t_start, initial=batch.initial
            )
        # The default start (eigenvalues of the linearised chain) outside the engine's program: a
        # batched eigensolver inside it can deadlock XLA's CPU thread pool (seen at N = 8, batch 1024).
        chain = batch.mechanism
        ts = chain.t_start if batch.t_start is None else batch.t_start
        P = engine_physics(chain)  # the chain's layout (`_chain_array`)
        return _measure.measure_batch(
            P, batch.valid, ts, z, horizon, window, contact, start, self.dt, cap, batch.initial
        )

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
        def local(b: FlatBatch, zhw: Array, dyn: Exact, cap: Array) -> dict[str, Array]:
            # A work queue over `lanes` lanes (`_queue`): a lane whose configuration is
            # done takes the next one. `cap` is the sweep's `max_steps` (`chunk_program`) or 0,
            # each configuration's own from its span, as in a `measure` of that configuration
            # alone; a dynamics that kept its `max_steps` (called by another's `measure_chunk`) caps by it.
            own = cap if dyn.max_steps is None else None
            return dyn._measure(b, zhw[0], zhw[1], zhw[2], contact, start, lanes or default_lanes(b.size), own)

        # shard_map, not jit's partitioning of a sharded batch: each device's loop ends
        # with its own slowest configuration, not with the slowest of all devices.
        # check_vma=False: the integrator's while_loop carries mix per-shard and
        # replicated values, which the varying-manual-axes checker rejects.
        spec = PartitionSpec(mesh.axis_names[0])
        replicated = PartitionSpec()
        sharded = jax.shard_map(
            local, mesh=mesh, in_specs=(spec, replicated, replicated, replicated), out_specs=spec, check_vma=False
        )
        return sharded(batch, zhw, self, max_steps)

    def chunk_program(self) -> tuple["Exact", int]:
        return dataclasses.replace(self, max_steps=None), self.max_steps or 0

    def step_cap(self, t_total: float) -> int:
        return self.max_steps or default_max_steps(t_total, self.dt)

    def _own_cap(self) -> Array:
        """The measurement loops' `max_steps`: the explicit cap, or 0 for each configuration's
        own default from its span (`_runs.step_cap`)."""
        return jnp.asarray(self.max_steps or 0, jnp.int32)

    def nominal_step(self) -> float | None:
        return self.dt

    def describe(self) -> dict[str, Any]:
        return {"dynamics": "exact", "dt": self.dt}

    def spec(self) -> dict[str, Any]:
        return self.describe() | {"max_steps": self.max_steps}
