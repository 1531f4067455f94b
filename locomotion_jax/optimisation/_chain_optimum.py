"""Settings and result of the chain optimiser (`optimise(chain, ...)`, module `optimisation._chain`)."""

import dataclasses
from typing import Any, ClassVar

import equinox as eqx
import numpy as np

from ..model._chain import Chain
from ..model._springwaves import SpringFourier
from ..model._waveform import Spline
from ._element_local import check_search_settings
from ._optimum import AbstractOptimum, constraints_line, fmt


class ChainOptimiseSettings(eqx.Module):
    """Settings of [`optimise`][locomotion_jax.optimisation._optimise.optimise] for a [`Chain`][]
    (module `optimisation._chain`). Python numbers: changing `local`, `chunk`, `dt`,
    `newton_iter`, `shape` or `knots` (or the harmonics) recompiles; the others do not.

    - `shape`: the family of the springs' signals searched by the local refinement: `"fourier"`
      (default), a Fourier series of `optimise`'s `harmonics` (default 3) per spring; or
      `"spline"`, a periodic cubic B-spline of `knots` control values per spring (then
      `harmonics` is not taken; the screen's travelling waves are single harmonics), whose
      stroke bound is a box on the control values, so that a step-like stroke carries no
      overshoot.
    - `knots`: control values per spring of a spline (>= 4; default 16: every control value is a
      forward-mode direction of the orbit's gradient, so the refinement's cost grows with
      `knots` times the springs).

    - `amplitudes`, `frequencies`, `phases`: the travelling-wave screen, $a$ on
      `amplitudes` equal steps up to $a_\\max$, $\\omega$ log-spaced over its range, the phase
      lag $\\varphi$ on `phases` equal steps of $[-\\pi, \\pi)$ (one phase for $N = 2$).
    - `screen_speed`: the screen solves the steady gaits only of the waves whose speed over the
      last 12 periods of their transient reaches this fraction of $v_\\min$ (and of the `chunk`
      fastest, so that an infeasible requirement still has candidates); 0: of every wave. A
      wave far slower than required where its transient ends is no start for the optimum, and
      the slowest waves (the longest periods) cost the screen most.
    - `zoom_levels`, `zoom_points`: the zooming refinement of the best travelling wave: per
      level a grid of `zoom_points` per variable over one step either side, the step halved
      per level.
    - `local`: starts refined locally in lockstep (the refined best wave and the next best
      distinct waves of the screen); `max_iter`: iterations of each local descent;
      `trust_radius`: the largest first step of a line search (coefficients in units of
      $a_\\max$, $\\log\\omega$); `local_method`: `"descent"` (default) or `"sqp"`, and
      `stall_rtol` (as [`ExactSettings`][locomotion_jax.optimisation._optimum.ExactSettings]'s;
      0 by default: on the README's 4-mass worm, 1e-6 stopped the descent at a speed 10 % above
      `v_min`, 0.09 % costlier, `benchmarks/NOTES.md`).
    - `margin`: required $\\min_{i,t} N_i$ on the orbit during the refinement (units of weight).
    - `speed_slack`: the refinement targets $v_\\min (1 + \\text{slack})$.
    - `omega_min`, `omega_max`: range of a free base frequency, in units of the lowest
      natural frequency with one mass held ([`Chain.omega_min`][locomotion_jax.Chain.omega_min])
      and of the highest natural frequency of the free chain.
    - `dt`: the exact engine's step; `transient`: actuation periods from the relaxed springs
      before an orbit is solved (screen, refinement, verification); `newton_tol`, `newton_iter`:
      the periodic-orbit solve; `chunk`: configurations per compiled `steady_gait` call.
    - `check_tol`, `check_periods`: the direct simulation of the optimum runs until the
      largest Floquet multiplier's modulus to the power of the periods run falls below
      `check_tol` (at most `check_periods[1]` gait periods, at least `check_periods[0]`), then
      averages over 10 gait periods.
    - `verbose`: progress on stderr.
    """

    amplitudes: int = 3
    frequencies: int = 12
    phases: int = 8
    screen_speed: float = 0.5
    zoom_levels: int = 2
    zoom_points: int = 5
    local: int = 4
    max_iter: int = 60
    trust_radius: float = 0.1
    local_method: str = "descent"
    stall_rtol: float = 0.0
    margin: float = 0.05
    speed_slack: float = 1e-3
    omega_min: float = 0.06
    omega_max: float = 1.2
    dt: float = 0.01
    transient: int = 30
    newton_tol: float = 1e-10
    newton_iter: int = 12
    chunk: int = 32
    check_tol: float = 1e-12
    check_periods: tuple[int, int] = (40, 1500)
    shape: str = "fourier"
    knots: int = 16
    verbose: bool = False

    def __check_init__(self):
        check_search_settings(self, ("zoom_points", "chunk"))
        if isinstance(self.zoom_levels, bool) or not (isinstance(self.zoom_levels, int) and self.zoom_levels >= 0):
            raise ValueError(f"ChainOptimiseSettings.zoom_levels must be an int >= 0, got {self.zoom_levels!r}.")
        if not (0 <= self.screen_speed <= 1):
            raise ValueError(f"ChainOptimiseSettings.screen_speed must be in [0, 1], got {self.screen_speed!r}.")


@dataclasses.dataclass(frozen=True)
class ChainOptimum(AbstractOptimum):
    """Result of [`optimise`][locomotion_jax.optimisation._optimise.optimise] for a [`Chain`][]; every
    figure called `*_exact` is the steady gait's ([`steady_gait`][]: whole periods, exact model,
    strict contact, from the relaxed springs).

    - `shape`: the family of the reported signals, `"fourier"` or `"spline"` (a spline search
      reports its travelling wave, `"fourier"`, where no refined spline is cheaper).
    - `cos`, `sin` (shape `(S, H)`: springs, harmonics), `omega`, `lbar` (per spring): the
      actuation $s_j(t) = \\sum_n A_{jn}\\cos n\\omega t + B_{jn}\\sin n\\omega t$
      ([`SpringFourier`][], `waveforms`; `chain`: the input chain with it); shape `(S, 0)` and
      `harmonics` 0 for a spline. `control`: shape `(S, M)`, a spline's control values about
      `lbar` (absolute units; `waveforms`: one [`Spline`][] per spring), `None` for a Fourier series.
    - `mean_speed_exact`, `cost_of_transport_exact` ($e_d / |\\Delta X|$ over the gait period),
      `gait_period_exact`, `stable_exact`, `spectral_radius_exact` (largest Floquet multiplier
      modulus), `liftoff_exact`, `stroke_exact` (per spring, $\\max_t |s_j(t)|$ located exactly),
      `min_normal` (smallest normal force on the orbit, at the step ends; NaN where the travelling
      wave wins a spline search: the refinement's orbit oracle solves splines only).
    - `constraints_exact` (`speed`, `stroke`, `no_liftoff`, `stable`), `feasible_exact`: all hold.
      An infeasible requirement gives `feasible_exact = False` and the closest candidate (the
      fastest stable gait), never an optimum.
    - `travelling_wave`: the best travelling wave $a\\sin(\\omega t - j\\varphi)$ of the screen and
      its zoom that meets the requirement (`a`, `omega`, `phi`, `mean_speed`,
      `cost_of_transport`), or `None`; `travelling_wave_cost_of_transport`;
      `improvement_vs_travelling_wave` $= 1 - \\text{cost}/\\text{cost}_\\text{wave}$ (NaN when either
      is infeasible).
    - `mean_speed_simulated`, `cost_of_transport_simulated`: a direct [`simulate`][] run from
      the relaxed springs, averaged over whole gait periods after `simulated_periods` gait
      periods; `simulation_agreement`: the larger relative difference of the two from the
      steady gait's.
    - `source`, `candidates`, `history`, `screened` (travelling waves solved),
      `evaluations` (batched orbit evaluations), `runtime_s`.
    """

    v_min: float
    direction: int
    a_max: float
    margin: float
    harmonics: int
    free_omega: bool
    cos: np.ndarray
    sin: np.ndarray
    omega: float
    lbar: np.ndarray
    mean_speed_exact: float
    cost_of_transport_exact: float
    gait_period_exact: float
    stable_exact: bool
    spectral_radius_exact: float
    liftoff_exact: bool
    stroke_exact: np.ndarray
    min_normal: float
    constraints_exact: dict
    feasible_exact: bool
    travelling_wave: dict | None
    travelling_wave_cost_of_transport: float
    improvement_vs_travelling_wave: float
    mean_speed_simulated: float
    cost_of_transport_simulated: float
    simulation_agreement: float
    simulated_periods: int
    source: str
    candidates: list
    history: list
    screened: int
    evaluations: int
    runtime_s: float
    shape: str
    control: np.ndarray | None
    chain: Chain = dataclasses.field(repr=False)

    @property
    def waveforms(self) -> SpringFourier | list[Spline]:
        """The actuation: a [`SpringFourier`][] of `cos`, `sin`, or one [`Spline`][] per spring."""
        if self.control is None:
            return SpringFourier(self.cos, self.sin, self.omega)
        return [Spline(c, self.omega, lb) for c, lb in zip(self.control, self.lbar)]

    objects: ClassVar[tuple[str, ...]] = ("chain",)

    def extra(self) -> dict[str, Any]:
        """`n_masses`."""
        return {"n_masses": int(self.cos.shape[0]) + 1}

    def summary(self) -> str:
        """Human-readable report."""
        S, H = self.cos.shape
        family = f"{H} harmonics" if self.control is None else f"a spline of {self.control.shape[-1]} knots"
        lines = [
            f"chain of {S + 1} masses: mean speed >= {self.v_min:g} in direction {self.direction:+d}, stroke <= "
            f"{self.a_max:g} per spring, normal forces >= {self.margin:g} on the orbit, stable steady gait (exact)",
            f"base frequency omega = {self.omega:.6g} ({'optimised' if self.free_omega else 'fixed'}), "
            f"{family} per spring",
        ]
        for j in range(S):
            if self.control is None:
                lines.append(f"spring {j}: cos " + " ".join(f"{c:+.5f}" for c in self.cos[j])
                             + "  sin " + " ".join(f"{s:+.5f}" for s in self.sin[j]))  # fmt: skip
            else:
                lines.append(f"spring {j}: control " + " ".join(f"{c:+.5f}" for c in self.control[j]))
        lines += [
            f"steady gait (exact, whole periods): mean speed {fmt(self.mean_speed_exact)}, cost of transport "
            f"{fmt(self.cost_of_transport_exact)}, period {fmt(self.gait_period_exact)}, stable {self.stable_exact} "
            f"(largest multiplier modulus {fmt(self.spectral_radius_exact)})",
            "stroke per spring "
            + " ".join(fmt(float(s)) for s in self.stroke_exact)
            + f" (limit {self.a_max:g}); min normal force {fmt(self.min_normal)}; lift-off: {self.liftoff_exact}",
            f"direct simulation ({self.simulated_periods} gait periods, then 10 averaged): mean speed "
            f"{fmt(self.mean_speed_simulated)}, cost of transport {fmt(self.cost_of_transport_simulated)} "
            f"(relative difference {fmt(self.simulation_agreement)})",
            constraints_line(self.constraints_exact, self.feasible_exact),
        ]
        w = self.travelling_wave
        if w is None:
            lines.append("best travelling wave: none meets the requirement on the exact model")
        else:
            lines.append(
                f"best travelling wave: a = {w['a']:.4g}, omega = {w['omega']:.4g}, phi = {w['phi']:.4g}: mean speed "
                f"{w['mean_speed']:.4g}, cost of transport {w['cost_of_transport']:.4g}"
            )
        lines.append(
            f"improvement vs travelling wave: {fmt(100 * self.improvement_vs_travelling_wave)} %  (winner: "
            f"{self.source}; {self.screened} waves screened, {self.evaluations} batched evaluations, "
            f"{self.runtime_s:.0f} s)"
        )
        return "\n".join(lines)
