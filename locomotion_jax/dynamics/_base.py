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

from .._custom_types import Array
from ..model._bodies import Mechanism
from ..model._chain import Chain
from ..model._params import Params
from ..model._waveform import AbstractWaveform


class AbstractDynamics(eqx.Module):
    """How the equations of motion are integrated: the engine behind [`simulate`][locomotion_jax.simulate],
    [`measure`][locomotion_jax.measure] and [`sweep`][locomotion_jax.sweep].

    [`Exact`][locomotion_jax.Exact] and [`Smoothed`][locomotion_jax.Smoothed] are final subclasses; a
    new integrator is one more, implementing the methods below (none has a default). The front ends
    call only these methods. They check the arguments first, then cast, broadcast and flatten the
    mechanism, so every run method gets a *flat* batch (one leading axis of `n` configurations) and
    returns a dict of arrays with that leading axis, one per array field of the result
    ([`Trajectory`][locomotion_jax.Trajectory], [`Measurement`][locomotion_jax.Measurement],
    [`ChainTrajectory`][locomotion_jax.ChainTrajectory] or [`ChainMeasurement`][locomotion_jax.ChainMeasurement]);
    the front end restores the batch shape. The mechanism chooses between the two-mass and the chain
    methods: a [`Params`][locomotion_jax.Params] runs on `*_two_mass`, a [`Chain`][locomotion_jax.Chain] on `*_chain`.

    A configuration that fails (invalid parameters, lift-off, the step cap) is flagged in its own
    `status`, never raised; an option a dynamics does not support raises `ValueError`.

    !!! Example

        ```python
        class HalfStep(lj.AbstractDynamics):  # the exact engine at half its step
            inner: lj.Exact = lj.Exact(dt=0.005)

            def simulate_two_mass(self, *args):
                return self.inner.simulate_two_mass(*args)

            ...  # and so on for every method
        ```
    """

    # -- the paper's two-mass model -------------------------------------------------------------

    @abc.abstractmethod
    def simulate_two_mass(
        self,
        params: Params,
        wave: AbstractWaveform,
        wave_axes: int | None,
        save_at: Array,
        t_end: float,
        contact: str,
        start: str,
        initial: Array | None,
    ) -> dict[str, Array]:
        """The states of the two-mass model at the times `save_at` (the fields of a `Trajectory`).

        - `params`: a flat batch of `n` configurations (invalid ones are flagged `INVALID`).
        - `wave`: the actuation $\\ell_0(t)$, batched along its leading axis if `wave_axes == 0`,
          shared by every configuration if `None`.
        - `save_at`: increasing times in $[0, t_\\text{end}]$, in the parameters' dtype.
        - `contact`, `start`: as in `simulate`; `initial`: states $(x_1, v_1, x_2, v_2)$ at
          $t = 0$, shape `(n, 4)`, or `None` for `start`'s.
        """

    @abc.abstractmethod
    def measure_two_mass(
        self,
        params: Params,
        wave: AbstractWaveform,
        wave_axes: int | None,
        z: float,
        horizon: float,
        window: float,
        contact: str,
        start: str,
        t_start: Array | None,
        initial: Array | None,
    ) -> dict[str, Array]:
        """The measurements of SPEC §5 on the two-mass model (the fields of a `Measurement`).

        `z`, `horizon`, `window`: as in `measure`; `t_start`: the measurement's start per
        configuration, shape `(n,)`, or `None` for `Params.t_start`; the rest as in
        `simulate_two_mass`.
        """

    # -- chains of N masses ---------------------------------------------------------------------

    @abc.abstractmethod
    def simulate_chain(
        self,
        chain: Chain | Mechanism,
        valid: Array,
        save_at: Array,
        t_end: float,
        contact: str,
        start: str,
        initial: Array | None = None,
    ) -> dict[str, Array]:
        """The states of a flat batch of chains at the times `save_at` (the fields of a `ChainTrajectory`).

        `valid`: which configurations are valid, shape `(n,)` (the front end has replaced the
        invalid ones by a valid one of the batch; flag them `INVALID`). `initial`: the states
        at $t = 0$, shape `(n, 2N)` (positions, then velocities), or `None` for `start`'s.
        """

    @abc.abstractmethod
    def measure_chain(
        self,
        chain: Chain | Mechanism,
        valid: Array,
        t_start: Array,
        z: float,
        horizon: float,
        window: float,
        contact: str,
        start: str,
        initial: Array | None = None,
    ) -> dict[str, Array]:
        """The measurements of SPEC §5 on a flat batch of chains (the fields of a `ChainMeasurement`).

        `t_start`: the measurement's start per configuration, shape `(n,)`, `inf` for the
        chain's own (`Chain.t_start`); `valid` and `initial` as in `simulate_chain`.
        """

    # -- sweeps ---------------------------------------------------------------------------------

    @abc.abstractmethod
    def measure_chunk(
        self,
        params: Params,
        zhw: Array,
        contact: str,
        start: str,
        max_steps: int,
        mesh: Mesh,
        lanes: int | None,
    ) -> dict[str, Array]:
        """One chunk of a sweep of the two-mass model, split over the devices of `mesh`.

        Called while the sweep traces its chunk program (once per sweep, inside `jax.jit`),
        so it must be traceable. `params`: the chunk, sharded along the mesh's one axis, with
        the sinusoid of eq. (13); `zhw`: the array $(z, \\text{horizon}, \\text{window})$;
        `max_steps`: `step_cap` of the sweep's longest run (recorded with its results; a
        dynamics may cap each configuration by its own span instead, as `Exact` does, so that
        a configuration's result does not depend on its chunk); `lanes`: configurations that
        each device runs together (`None`: the dynamics' own choice).
        """

    @abc.abstractmethod
    def step_cap(self, t_total: float) -> int:
        """The cap on the engine's loop iterations for runs to the time `t_total`.

        A sweep records it for its longest run (`max_steps` of `measure_chunk`, a static of
        the compilation fixed once, so that every chunk shares one compilation). `0` where
        the dynamics caps its loops by a setting of its own.
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
