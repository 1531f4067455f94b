"""The mechanisms that the front ends run: the paper's two-mass model and chains of N masses."""

import abc
from typing import Any, ClassVar, TypeVar

import equinox as eqx
import jax
import jax.numpy as jnp


M = TypeVar("M", bound="AbstractMechanism")


class AbstractMechanism(eqx.Module):
    """Base class of [`Params`][locomotion_jax.Params] (the paper's two-mass model),
    [`Chain`][locomotion_jax.Chain] (N masses) and [`Mechanism`][locomotion_jax.Mechanism].

    The front ends (`simulate`, `measure`, `sweep`) do not test which they were given: the
    mechanism flattens itself into a `FlatBatch` (`flat_batch`, `own_batch`: what differs between
    mechanisms, their actuation, starts and initial states, travels in it; their physics is
    `physics()`), and the dynamics' `simulate` and `measure` take it whatever the mechanism.
    The solvers ask it for their problem the same way: `gait_problem` (`steady_gait`),
    `branch_setup` (`continuation`) and `optimum` (`optimise`, whose method depends on the kind of
    mechanism), and `animate` for its `animation`; their defaults serve any mechanism that carries
    its own actuation.
    """

    kind: ClassVar[str]
    """The kind of mechanism, as its file's `kind` and the command line's records name it:
    `"paper"`, `"chain"` or `"mechanism"`."""

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

    def check_hop(self) -> None:
        """Raise a `NotImplementedError` naming what this mechanism has that flight and landing
        (`contact="hop"`, SPEC §10) do not support; this default: nothing."""

    def check_section(self, y: Any) -> None:
        """Raise a `ValueError` where one configuration's given section state `y` (a host array: the
        reduced positions, then the velocities; [`steady_gait`][locomotion_jax.steady_gait]'s `start`)
        puts bodies where they cannot be; this default: nothing (`Chain` requires its gaps positive)."""

    def describe(self) -> str:
        """A short label of this mechanism (the command line's first line on a mechanism file)."""
        return f"{type(self).__name__} of {self.kind} kind"

    def attributes(self) -> dict[str, str]:
        """This mechanism's laws and elements by name, for a sweep's record (its `attrs`); this default:
        its `kind`."""
        return {"kind": self.kind}

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

    def gait_problem(self, dynamics: Any, *, waveform: Any = None, contact: str = "strict", start: Any = "paper",
                     dtype: Any = None) -> Any:  # fmt: skip
        """The steady gaits of this mechanism as the one solver takes them (a `GaitProblem` of
        `gaits._shooting`: flat configurations, the physics of each, validity, starts and names), for
        [`steady_gait`][locomotion_jax.steady_gait]'s arguments. Raises `ValueError`,
        `NotImplementedError` on bad input, before any computation.

        This default serves a mechanism that carries its own actuation ([`Chain`][locomotion_jax.Chain],
        [`Mechanism`][locomotion_jax.Mechanism]); `Params` has its own."""
        from ..gaits._shooting import bodies_problem

        if waveform is not None:
            name = type(self).__name__
            raise ValueError(f"waveform= applies to Params; a {name} carries its own waveforms (in its elements).")
        return bodies_problem(self, dynamics, contact, start, dtype)

    def branch_setup(self, parameter: str, stops_of: Any, dynamics: Any, waveform: Any, dtype: Any,
                     contact: str) -> Any:  # fmt: skip
        """The branches of [`continuation`][locomotion_jax.continuation] in `parameter` as its corrector
        takes them (a `BranchSetup` of `gaits._continuation`); `stops_of(shape, start_values)` checks
        and returns the end values. This default serves a mechanism that carries its own actuation
        (`parameter` a leaf named by its attribute); `Params` has its own."""
        from ..gaits._continuation import bodies_setup

        return bodies_setup(self, parameter, stops_of, dynamics, waveform, dtype, contact)

    def animation(self, traj: Any, **options: Any) -> Any:
        """[`animate`][locomotion_jax.run._animation.animate] of this mechanism's trajectory `traj`, with its
        options. This default draws the bodies on their line (`run._mechanism_animation`, the
        mechanism's `drawing()`); `Params` draws the paper's two masses and tilted spring."""
        from ..run._mechanism_animation import animate_bodies

        return animate_bodies(traj, self, **options)

    def optimum(self, v_min: Any, a_max: Any, method: str, direction: int | None, omega: Any, harmonics: Any,
                settings: Any, sweep: Any, start: Any) -> Any:  # fmt: skip
        """[`optimise`][locomotion_jax.optimise] of this mechanism (one configuration), with its
        arguments: each kind of mechanism names its optimiser. This default: the method of
        `optimisation._mechanism` (a signal per actuated element); `Chain` and `Params` have their own."""
        from ..optimisation._optimise import mechanism_optimum

        return mechanism_optimum(self, v_min, a_max, method, direction, omega, harmonics, settings, sweep, start)
