"""The mechanisms that the front ends run: the paper's two-mass model and chains of N masses."""

import abc
from collections.abc import Callable
from typing import Any, TypeVar

import equinox as eqx
import jax
import jax.numpy as jnp


R = TypeVar("R")
M = TypeVar("M", bound="AbstractMechanism")


class AbstractMechanism(eqx.Module):
    """Base class of [`Params`][locomotion_jax.Params] (the paper's two-mass model),
    [`Chain`][locomotion_jax.Chain] (N masses) and [`Mechanism`][locomotion_jax.Mechanism].

    The front ends (`simulate`, `measure`, `sweep`) do not test which they were given: the
    mechanism flattens itself into a `FlatBatch` (`flat_batch`, `own_batch`: what differs between
    mechanisms, their actuation, starts and initial states, travels in it; their physics is
    `physics()`), and the dynamics' `simulate` and `measure` take it whatever the mechanism.
    (`steady_gait` and `optimise` still choose their solver by `dispatch`.)
    """

    @property
    @abc.abstractmethod
    def batch_shape(self) -> tuple[int, ...]:
        """The batch axes of the configurations (`()` for one)."""

    @property
    @abc.abstractmethod
    def dtype(self) -> Any:
        """The floating dtype of the configurations' fields."""

    def astype(self: M, dtype: Any) -> M:
        """Every field cast to `dtype`; `float64` needs `jax.config.update("jax_enable_x64", True)`."""
        dtype = jnp.dtype(dtype)
        if dtype == jnp.float64 and not jax.config.read("jax_enable_x64"):
            raise ValueError(
                "dtype=float64 requested but JAX runs in 32-bit mode; enable it with "
                'jax.config.update("jax_enable_x64", True) at start-up (or the CLI flag --x64).'
            )
        return jax.tree_util.tree_map(lambda x: x.astype(dtype), self)

    @abc.abstractmethod
    def physics(self) -> Any:
        """The [`AbstractPhysics`][locomotion_jax.AbstractPhysics] of one configuration: what the
        N-body engine integrates this mechanism with."""

    @abc.abstractmethod
    def time_scales(self, waveform: Any = None) -> list[Any]:
        """The time scales (`TimeScale`s of `model._scales`) of a flat batch of this
        mechanism (batch shape `(size,)`) that a fixed step must resolve: the forcing's highest
        harmonic, the highest natural period, the damping times and a friction law's own time
        (`waveform`: the paper's model's actuation, `None` for its sinusoid; other mechanisms
        carry their own). The resolution guards (`run._resolution`) read them."""

    @abc.abstractmethod
    def start_scale(self) -> Any:
        """The default measurement start (`t_start`) of a flat batch as a span
        `TimeScale` (`model._scales`): it may take at most
        `MAX_START_STEPS` steps."""

    @abc.abstractmethod
    def is_valid(self) -> Any:
        """Per configuration, whether its values are in their valid ranges (the others run flagged
        `Status.INVALID`)."""

    def flat_batch(
        self,
        dynamics: Any,
        *,
        waveform: Any = None,
        dtype: Any = None,
        t_start: Any = None,
        initial: Any = None,
        measuring: bool = False,
        contact: str = "strict",
        start: str = "paper",
    ) -> tuple[Any, Any, tuple[int, ...]]:
        """`(batch, unresolved, shape)`: this mechanism cast to `dtype`, broadcast and flattened into
        a `FlatBatch` for `dynamics` (`dynamics._flat`), the mask of the configurations whose step
        does not resolve their forcing (flagged `UNRESOLVED` by the front end; `None`: none), and the
        batch shape. The arguments are the front ends' (`simulate`, `measure`: `waveform` for the
        paper's model only, `initial` in the mechanism's own form); `measuring`: the run measures
        from the default start, whose span is guarded too. Raises `ValueError` or `TypeError` on
        bad input, before any computation.

        This default serves a mechanism that carries its own actuation ([`Chain`][locomotion_jax.Chain],
        [`Mechanism`][locomotion_jax.Mechanism]): `waveform` must be `None`, `initial` a tuple `(x, v)`
        of positions and velocities per body. `Params` has its own."""
        from ..run._batch import bodies_batch

        return bodies_batch(self, dynamics, waveform, dtype, t_start, initial, measuring, contact, start)

    def own_batch(self) -> Any:
        """This flat batch (batch shape `(n,)`) as a `FlatBatch` as it stands, with its own actuation,
        starts and validity and no front-end checks: what a sweep's chunk hands `measure_chunk`.
        The default: a mechanism that carries its own actuation; `Params` has its own."""
        from ..dynamics._flat import FlatBatch

        return FlatBatch(self, self.is_valid())

    @abc.abstractmethod
    def dispatch(self, *, two_mass: Callable[[Any], R], chain: Callable[[Any], R]) -> R:
        """`two_mass(self)` for a `Params`, `chain(self)` for a `Chain` (the solvers of
        `steady_gait` and `optimise`; the front ends of `simulate`, `measure` and `sweep` use none)."""
