"""The interface of an integrator: what `simulate`, `measure` and `sweep` ask of the dynamics.

Abstract/final pattern (equinox; diffrax's `AbstractSolver`): the front ends call only
the methods of [`AbstractDynamics`][], which the final classes `Exact` (`_exact_dynamics`)
and `Smoothed` (`_smoothed_dynamics`) implement; nothing tests which class it was given,
so a new integrator is one new subclass.
"""

import abc
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.sharding import Mesh

from .._custom_types import Array, ArrayLike
from ._flat import FlatBatch


class AbstractDynamics(eqx.Module):
    """How the equations of motion are integrated: the engine behind [`simulate`][locomotion_jax.simulate],
    [`measure`][locomotion_jax.measure] and [`sweep`][locomotion_jax.sweep].

    [`Exact`][locomotion_jax.Exact] and [`Smoothed`][locomotion_jax.Smoothed] are final subclasses; a
    new integrator is one more, implementing the methods below (none has a default). The front ends
    call only these methods, with any mechanism: they check the arguments first, then the mechanism
    casts, broadcasts and flattens itself into a `FlatBatch`
    (one leading axis of `n` configurations, with its validity, its actuation where it is given apart,
    its starts and initial states). Each run method returns a dict of arrays with that leading axis,
    one per array field of the result ([`Trajectory`][locomotion_jax.Trajectory] or
    [`Measurement`][locomotion_jax.Measurement]: per-body fields with a trailing body axis); the front
    end restores the batch shape.

    A configuration that fails (invalid parameters, lift-off, the step cap) is flagged in its own
    `status`, never raised; an option a dynamics does not support raises `ValueError`.

    !!! Example

        ```python
        class HalfStep(lj.AbstractDynamics):  # the exact engine at half its step
            inner: lj.Exact = lj.Exact(dt=0.005)

            def simulate(self, *args, **kwargs):
                return self.inner.simulate(*args, **kwargs)

            ...  # and so on for every method
        ```
    """

    @abc.abstractmethod
    def simulate(self, batch: FlatBatch, save_at: Array, t_end: float, contact: str, start: str) -> dict[str, Array]:
        """The states at the times `save_at` (the fields of a `Trajectory`) of a flat batch of any mechanism.

        - `batch`: the configurations (`FlatBatch`; flag
          the invalid ones `INVALID`).
        - `save_at`: increasing times in $[0, t_\\text{end}]$, in the batch's dtype.
        - `contact`, `start`: as in `simulate`; `batch.initial` replaces `start`'s states where given.
        """

    @abc.abstractmethod
    def measure(
        self, batch: FlatBatch, z: ArrayLike, horizon: ArrayLike, window: ArrayLike, contact: str, start: str
    ) -> dict[str, Array]:
        """The measurements of SPEC §5 (the fields of a `Measurement`) of a flat batch of any mechanism.

        `z`, `horizon`, `window`: as in `measure`; the measurement starts at `batch.t_start`, or
        where `None` at each configuration's own (`Params.t_start`, `Chain.t_start`); the rest as
        in `simulate`.
        """

    # -- sweeps ---------------------------------------------------------------------------------

    @abc.abstractmethod
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
        """`measure` of one chunk of a sweep, split over the devices of `mesh`.

        Called while the sweep traces its chunk program (once per sweep, inside `jax.jit`),
        so it must be traceable. `batch`: the chunk, sharded along the mesh's one axis (a
        sweep of the paper's model: `Params` with the sinusoid of eq. (13)); `zhw`: the array
        $(z, \\text{horizon}, \\text{window})$; `max_steps`: the cap of [`chunk_program`][], an
        int32 scalar traced as data; `lanes`: configurations that each device runs together
        (`None`: the dynamics' own choice).
        """

    def chunk_program(self) -> tuple["AbstractDynamics", int]:
        """The dynamics a sweep compiles its chunk program for, and the cap on each configuration's
        loop iterations that it hands to `measure_chunk` as data (`0`: each configuration's own).

        A dynamics whose loop cap is one of its static settings returns itself without it, and
        the cap: sweeps of any cap then share one program (`Exact(max_steps=...)`). This default
        keeps every setting in the program.
        """
        return self, 0

    @abc.abstractmethod
    def step_cap(self, t_total: float) -> int:
        """The cap on the engine's loop iterations for runs to the time `t_total`.

        A sweep records it for its longest run with its results. `0` where the dynamics caps
        its loops by a setting of its own.
        """

    @abc.abstractmethod
    def nominal_step(self) -> float | None:
        """The step by which a sweep's cost model predicts each configuration's iterations.

        `sweep(order="cost")` sorts the configurations by the duration a pilot run of the exact
        engine predicts, at $1/\\text{step}$ iterations per time unit. `None` where iterations
        do not follow from a step (an adaptive solver): `order="auto"` then keeps grid order.
        """

    # -- provenance -----------------------------------------------------------------------------

    @abc.abstractmethod
    def describe(self) -> dict[str, Any]:
        """Attributes recorded with every sweep's results (for provenance)."""

    @abc.abstractmethod
    def spec(self) -> dict[str, Any]:
        """The settings that identify a sweep's results: a stored sweep resumes only with the same."""

    def astype(self, dtype: Any) -> "AbstractDynamics":
        """A copy with every floating array field cast to `dtype` (settings that are arrays,
        such as `Smoothed.eps`, follow the computation's dtype)."""

        def cast(x):
            return jnp.asarray(x, dtype) if jnp.issubdtype(jnp.result_type(x), jnp.inexact) else x

        return jax.tree_util.tree_map(cast, self)
