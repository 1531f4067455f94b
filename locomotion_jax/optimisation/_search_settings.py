"""What the exact optimisers' settings share ([`SearchSettings`][]): the signals' family, the local
runs, the periodic-orbit solve, the engine's steps and the direct simulation of the optimum,
declared and checked once for the paper's model's [`ExactSettings`][locomotion_jax.optimisation._optimum.ExactSettings]
and a mechanism's or a chain's settings."""

import dataclasses
import math
from typing import Any, ClassVar, TypeVar

import equinox as eqx
import numpy as np

from ._descent import METHODS


def count(s: Any, field: str, least: int) -> None:
    """Refuse a count that is not an int >= `least`, naming the class and the field."""
    v = getattr(s, field)
    if isinstance(v, bool) or not (isinstance(v, int) and v >= least):
        raise ValueError(f"{type(s).__name__}.{field} must be an int >= {least}, got {v!r}.")


def tension(s: Any, optional: bool = False) -> None:
    """Refuse the tension-wave starts' fields (`tension_periods` a count >= 0, or `None` where
    `optional`; `tension_levels` within [0, 1]), naming the class and the field."""
    if not (optional and s.tension_periods is None):
        count(s, "tension_periods", 0)
    if any(not (0 <= x <= 1) for x in s.tension_levels):
        raise ValueError(f"{type(s).__name__}.tension_levels must lie within [0, 1], got {s.tension_levels!r}.")


def _step(s: Any, field: str, optional: bool) -> None:
    """Refuse a step that is not finite and > 0 (`optional`: or `None`), naming the class and the field."""
    v = getattr(s, field)
    if optional and v is None:
        return
    if not (isinstance(v, (int, float, np.number)) and not isinstance(v, bool) and math.isfinite(v) and v > 0):
        either = "None or " if optional else ""
        raise ValueError(f"{type(s).__name__}.{field} must be {either}a finite step > 0, got {v!r}.")


_Settings = TypeVar("_Settings", bound="SearchSettings")


class SearchSettings(eqx.Module):
    """The fields of every exact optimiser's settings, with a mechanism's defaults: the paper's
    model's [`ExactSettings`][locomotion_jax.optimisation._optimum.ExactSettings], a mechanism's
    [`MechanismOptimiseSettings`][] and a chain's [`ChainOptimiseSettings`][] derive from it, each
    with its own defaults and fields, and each says where it reads one of these otherwise.

    - `shape`: the family of signals searched, `"fourier"`, a Fourier series of `optimise`'s
      `harmonics` per actuated element, or `"spline"`, a periodic cubic B-spline of `knots` control
      values per element, whose bound is a box on the control values, so that a step-like signal
      carries no overshoot. `knots` (>= 4): every control value is a forward-mode direction of the
      orbit's gradient, so the local runs' cost grows with `knots` times the elements actuated.
    - `local`: starts refined locally, in lockstep (one batched engine call per step);
      `max_iter`: iterations of each local run; `trust_radius`: the largest first step of a line
      search, or the initial trust region (decision variables: coefficients in units of
      $a_\\max$, $\\log\\omega$); `local_method`, one of the class's `local_methods`:
      `"descent"` (a monotone L-BFGS descent on an exact penalty, `_descent.descent`) or `"sqp"`
      (the same penalty and line search with SQP steps on the linearised constraints, which
      follow an active speed constraint instead of crossing it, and a stop where the merit stalls
      at 1e-5, `_descent.sqp_descent`: fewer evaluations, a slightly costlier optimum);
      `stall_rtol`: the descent stops where its merit fell by at most this (relative) over its
      last 20 evaluations, 0 for never, and by at most 1e-4 where it misses a constraint by more
      than 1e-2 (`_descent.FAR_STALL_RTOL`).
    - `margin`: the smallest normal force required on the orbit (units of weight);
      `speed_slack`: the local runs target $v_\\min (1 + \\text{slack})$.
    - `omega_min`, `omega_max`: the range of a free base frequency, in units of natural
      frequencies of the mechanism (each class says which).
    - `dt`: the exact engine's step of the verification, and so of every figure reported;
      `search_dt`: its step in the search (the screen and the local runs), whose figures only
      rank and steer (`None`: `dt`). `transient`: actuation periods from the start before an
      orbit is first solved (at least `least_transient`); `newton_tol`, `newton_iter`: the
      periodic-orbit solve.
    - `check_tol`, `check_periods`: the direct simulation of the optimum runs until the largest
      Floquet multiplier's modulus to the power of the periods run falls below `check_tol` (at
      least `check_periods[0]`, at most `check_periods[1]` gait periods), then averages over 12
      ([`AbstractOptimum`][locomotion_jax.optimisation._optimum.AbstractOptimum]'s
      `simulated_recurrence`).
    - `verbose`: progress on stderr.
    """

    shape: str = "fourier"
    knots: int = 16
    local: int = 2
    max_iter: int = 40
    trust_radius: float = 0.1
    local_method: str = "descent"
    stall_rtol: float = 0.0
    margin: float = 0.05
    speed_slack: float = 1e-3
    omega_min: float = 0.15
    omega_max: float = 2.0
    dt: float = 0.01
    search_dt: float | None = None
    transient: int = 30
    newton_tol: float = 1e-10
    newton_iter: int = 12
    check_tol: float = 1e-12
    check_periods: tuple[int, int] = (40, 1500)
    verbose: bool = False

    local_methods: ClassVar[tuple[str, ...]] = METHODS
    """The local steps the class's optimiser offers."""

    least_transient: ClassVar[int] = 1
    """The fewest actuation periods of `transient`."""

    def __check_init__(self):
        # Each error names the class (a subclass runs these checks too) and the field.
        name = type(self).__name__
        for field in ("local", "max_iter", "newton_iter"):
            count(self, field, 1)
        count(self, "knots", 4)
        count(self, "transient", self.least_transient)
        if self.shape not in ("fourier", "spline"):
            raise ValueError(f"{name}.shape must be 'fourier' or 'spline', got {self.shape!r}.")
        if self.local_method not in self.local_methods:
            methods = ", ".join(repr(m) for m in self.local_methods[:-1]) + f" or {self.local_methods[-1]!r}"
            raise ValueError(f"{name}.local_method must be {methods}, got {self.local_method!r}.")
        if not (0 <= self.stall_rtol < 1):
            raise ValueError(f"{name}.stall_rtol must be in [0, 1), got {self.stall_rtol!r}.")
        if not (0 < self.omega_min < self.omega_max):
            raise ValueError(f"{name}: need 0 < omega_min < omega_max, got {self.omega_min!r}, {self.omega_max!r}.")
        _step(self, "dt", False)
        _step(self, "search_dt", True)
        if not (self.trust_radius > 0 and self.newton_tol > 0):
            raise ValueError(f"{name}: trust_radius and newton_tol must be > 0, got {self.trust_radius!r}, "
                             f"{self.newton_tol!r}.")  # fmt: skip
        if not (self.margin >= 0 and self.speed_slack >= 0):
            raise ValueError(f"{name}: margin and speed_slack must be >= 0, got {self.margin!r}, {self.speed_slack!r}.")
        if not (isinstance(self.check_tol, (int, float, np.number)) and 0 < self.check_tol < 1):
            raise ValueError(f"{name}.check_tol must be in (0, 1), got {self.check_tol!r}.")
        lo, hi = self.check_periods
        if not (1 <= lo <= hi):
            raise ValueError(f"{name}.check_periods must be (lo, hi), 1 <= lo <= hi, got {lo, hi}.")

    def searching(self: _Settings) -> _Settings:
        """The settings of the search (the screen and the local runs): these, with `dt` =
        `search_dt` where one is given."""
        return self if self.search_dt is None else dataclasses.replace(self, dt=self.search_dt, search_dt=None)
