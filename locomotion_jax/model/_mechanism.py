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
    """Base class of [`Params`][locomotion_jax.Params] (the paper's two-mass model) and
    [`Chain`][locomotion_jax.Chain] (N masses).

    The front ends (`simulate`, `measure`, `steady_gait`) do not test which of the two
    they were given: they pass one function per kind of mechanism to `dispatch`, and the
    mechanism calls its own with itself (double dispatch). Each function then runs the
    dynamics' method for that kind (`AbstractDynamics.simulate_two_mass` or
    `simulate_chain`, and so on), so that neither the front ends nor the dynamics test a class.
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
    def dispatch(self, *, two_mass: Callable[[Any], R], chain: Callable[[Any], R]) -> R:
        """`two_mass(self)` for a `Params`, `chain(self)` for a `Chain`."""
