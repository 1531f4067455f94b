"""Settings and result of the actuation optimiser (SPEC §7), and what every optimiser's result has."""

import abc
import dataclasses
import math
from collections.abc import Mapping
from typing import Any, ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._json import dumps, jsonable
from ..model._waveform import AbstractWaveform, Fourier, Spline
from ._search_settings import count, SearchSettings, tension


class Settings(eqx.Module):
    """Static settings of [`optimise`][locomotion_jax.optimisation._optimise.optimise] (Python numbers; changing
    them recompiles).

    - `starts`: number of starts optimised together under `vmap`.
    - `start_frequencies`: base frequencies the starts are spread over when
      `omega` is free (the cheapest feasible sinusoids' frequencies, at least
      20 % apart and within a factor `omega_range` of the best).
    - `eps_schedule`: continuation in the smoothing scale $\\varepsilon$.
    - `outer`, `inner`: augmented-Lagrangian blocks per stage and Adam steps per block.
    - `learning_rate`: Adam's step (decision variables are O(1): coefficients
      in units of $a_\\max$, $\\log\\omega$); `lr_decay`: its factor per stage.
    - `rho0`, `rho_growth`, `rho_max`: penalty parameter schedule.
    - `speed_slack`: the smoothed model targets $v_\\min (1 + \\text{slack})$.
    - `phase1_threshold`: a start whose speed falls short by more than this
      fraction of the target optimises feasibility alone (cost weight 0) until it is closer.
    - `margin`: required normal-force margin (in units of weight; $m_1 + m_2 = 2$).
    - `margin_step`: added to a start's margin when it lifts off on the exact model.
    - `temperature`: of the soft minimum of the normal forces.
    - `transient`, `measured`: smoothed rollout lengths (time units; whole periods).
    - `backprop`: differentiate only this many time units at the end of the
      transient (truncated backpropagation, approximate); `None`: all.
    - `omega_range`: a free $\\omega$ stays within this factor of its starts.
    - `corrections`, `correction_outer`: exact-feedback rounds and their blocks.
    - `verify_dt`: the exact engine's step of the verification (steady gaits, whole periods).
    - `refine_baseline`: refine the best sinusoids of the sweep by a zooming local grid
      search (`_pareto.refine_sinusoid`: 3 levels, each 4x finer, to 1/64 of the coarse
      grid's step), so the optimum is compared with a well-resolved sinusoid.
    - `seed`: for the random starts. `verbose`: print progress per block.
    """

    starts: int = 8
    start_frequencies: int = 2
    eps_schedule: tuple[float, ...] = (1e-2, 3e-3, 1e-3)
    outer: int = 3
    inner: int = 30
    learning_rate: float = 0.03
    lr_decay: float = 0.6
    rho0: float = 10.0
    rho_growth: float = 4.0
    rho_max: float = 1e4
    speed_slack: float = 0.02
    phase1_threshold: float = 0.5
    margin: float = 0.05
    margin_step: float = 0.05
    temperature: float = 0.005
    transient: float = 12.0
    measured: float = 6.0
    backprop: float | None = None
    omega_range: float = 1.3
    corrections: int = 1
    correction_outer: int = 2
    verify_dt: float = 0.01
    refine_baseline: bool = True
    seed: int = 0
    verbose: bool = False

    def __check_init__(self):
        if self.starts < 1 or self.outer < 1 or self.inner < 1:
            raise ValueError("Settings: starts, outer and inner must be >= 1.")
        if not self.eps_schedule or any(not (e > 0) for e in self.eps_schedule):
            raise ValueError(f"Settings.eps_schedule must be non-empty and positive, got {self.eps_schedule!r}.")
        for name in ("transient", "measured"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"Settings.{name} must be a finite time > 0, got {value!r}.")


class ExactSettings(SearchSettings):
    """Settings of the exact method of [`optimise`][locomotion_jax.optimisation._optimise.optimise]
    for the paper's model (`method="exact"`, module `_exact_optimise`): the fields of
    [`SearchSettings`][locomotion_jax.optimisation._search_settings.SearchSettings] with other
    defaults, and the starts' own. Python numbers: changing `local`, `dt`, `search_dt`,
    `newton_iter` or the harmonics recompiles; the others do not.

    Where the paper's model reads a field otherwise:

    - `shape`: `"spline"` by default (of 64 `knots`), which represents step-like strokes without
      overshoot; `"fourier"`: `optimise`'s `harmonics`, default 16.
    - `local`: the best starts are refined; `max_iter`: over `stages` runs with required speeds
      rising geometrically from the start's speed to $v_\\min$ (for a start that is too slow; the
      last run has half the iterations). `local_method`: also scipy's `"trust-constr"` and
      `"SLSQP"`; with `"sqp"` at the default problem, fewer evaluations for a slightly costlier
      optimum (`benchmarks/NOTES.md`). `stall_rtol`: 1e-6 by default (in the default problem 210
      lockstep rounds instead of 393 for an optimum 1.6e-8 costlier, `benchmarks/NOTES.md`).
    - `margin`: on $\\min_t N_{1,2}$ over the orbit.
    - `omega_min`, `omega_max`: in units of the smallest natural frequency and of $\\omega_{n1}$.
    - `dt`: also the step of the sinusoid baseline. A coarser `search_dt` differs from `dt` by the
      RK4 error (fourth order in `search_dt`; at `2 dt` 6.7e-6 relative in the speed at the
      default problem's optimum, inside `speed_slack`) and moves the descent's path: over the
      required speeds 0.01 to 0.06, `search_dt = 0.02` took 0.70 of the time in all, 0.39 to 0.75
      at five of the six but 1.5 times at 0.06, its optima within 2.2e-4 either way
      (`benchmarks/NOTES.md`).
    - `transient`: from the relaxed spring (also the verification's, [`steady_gait`][]); 0 is
      allowed.
    - The direct simulation runs from the relaxed spring.

    Its own fields:

    - `tension_periods`, `tension_levels`: the tension-wave starts (`_starts`: idealised
      inchworm gaits whose spring tension alternates in sign), over `tension_periods` periods
      from 0.7 to 4 times the slowest natural period and these levels between the two masses'
      break-away forces; 0 periods: none.
    - `start_frequencies`: base frequencies of the starts, log-spaced over the range.
    - `random_shapes`: random waveforms among the start shapes (with sinusoids of five
      strokes, sinusoids with a third harmonic and saw-tooth ramps of both senses).
    - `stages`: the local runs of a start too slow for $v_\\min$.
    - `retry`: in which of those runs a trial point whose orbit Newton's method does not find from
      the lane's last orbit is retried (after a transient of `transient` periods from rest,
      as a period-1 and then a period-2 gait): `"last"` (default) or `"every"`. In the others the
      point is rejected and the descent backtracks. Over the required speeds 0.01 to 0.06 `"last"`
      took 0.70 of `"every"`'s time, for optima within 5e-4 (`benchmarks/NOTES.md`).
    - `refine_baseline`: refine the best sinusoids of the sweep (`_pareto.refine_sinusoid`).
    - `seed`: for the random shapes.
    """

    shape: str = "spline"
    knots: int = 64
    local: int = 4
    max_iter: int = 600
    stall_rtol: float = 1e-6
    omega_min: float = 0.06
    omega_max: float = 1.2
    tension_periods: int = 10
    tension_levels: tuple[float, ...] = (0.3, 0.55, 0.8)
    start_frequencies: int = 8
    random_shapes: int = 2
    stages: int = 3
    retry: str = "last"
    refine_baseline: bool = True
    seed: int = 0

    local_methods: ClassVar[tuple[str, ...]] = ("descent", "sqp", "trust-constr", "SLSQP")
    least_transient: ClassVar[int] = 0

    def __check_init__(self):
        for field in ("start_frequencies", "stages"):
            count(self, field, 1)
        tension(self)
        if self.retry not in ("last", "every"):
            raise ValueError(f"ExactSettings.retry must be 'last' or 'every', got {self.retry!r}.")


def fmt(v: Any) -> str:
    """A figure of a summary: four significant digits, `n/a` for `None` or a non-finite number."""
    return "n/a" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{v:.4g}"


class AbstractOptimum(abc.ABC):
    """What every result of [`optimise`][locomotion_jax.optimisation._optimise.optimise] has, whatever the
    mechanism ([`Optimum`][] of the paper's model, [`ChainOptimum`][] of a chain,
    [`MechanismOptimum`][] of a mechanism; frozen dataclasses): the requirement (`v_min`, `direction`,
    `a_max`), the base frequency `omega`, the optimum's steady gait on the exact model
    (`mean_speed_exact`, `cost_of_transport_exact`, `feasible_exact`), the candidates verified
    (`candidates`) and `runtime_s`; `to_dict`, `to_json` and a human-readable `summary`.

    The exact optimisers check their optimum by a direct [`simulate`][] run as well:
    `mean_speed_simulated`, `cost_of_transport_simulated`, averaged over 12 gait periods after
    `simulated_periods` gait periods (enough for the slowest Floquet mode to decay to the settings'
    `check_tol`); `simulation_agreement`, the larger relative difference of the two from the steady
    gait's; `simulated_recurrence`, the smallest $p \\le 4$ such that the simulated state (gaps and
    velocities) at the gait's sections recurs every $p$ gait periods (to
    $\\sqrt{\\text{check\\_tol}}$ relative, or 100 machine epsilons where larger: float32), 0 if
    none does. Where it is not 1, the run settled on another motion than the optimum's gait (a
    second attractor: the gait is stable, but this start does not lead to it), and the simulated
    figures are that motion's, averaged over whole periods of it. NaN and 0 where nothing was
    simulated (an unstable gait; the smoothed method).
    """

    v_min: float
    direction: int
    a_max: float
    omega: float
    mean_speed_exact: float
    cost_of_transport_exact: float
    feasible_exact: bool
    candidates: list
    runtime_s: float
    mean_speed_simulated: float
    cost_of_transport_simulated: float
    simulation_agreement: float
    simulated_periods: int
    simulated_recurrence: int
    harmonics: int
    control: np.ndarray | None

    objects: ClassVar[tuple[str, ...]] = ()
    """Fields that hold objects, not figures (the mechanism driven): left out of `to_dict`."""

    @abc.abstractmethod
    def signals(self, t: np.ndarray) -> np.ndarray:
        """Each actuated signal about its mean at the times `t`: shape `(S, len(t))`, a row per
        actuated element (the paper's model: one row, $\\ell_0(t) - \\bar\\ell$)."""

    @abc.abstractmethod
    def signal_labels(self) -> list[str]:
        """A name per actuated signal, in the order of `signals`."""

    @abc.abstractmethod
    def baseline_signals(self, phase: np.ndarray) -> tuple[str, np.ndarray] | None:
        """The baseline (the best sinusoid or travelling wave that meets the requirement) at the
        phases `phase` (radians) of its own period: its description and its signals, shape
        `(S, len(phase))`; `None` where none meets the requirement."""

    @abc.abstractmethod
    def driven(self, params: Any = None) -> tuple[Any, dict[str, Any]]:
        """The mechanism driven by the optimum's signals, and [`simulate`][]'s keyword arguments
        for a run of it from the start of the optimiser's direct simulation (`params`: the
        paper's model's [`Params`][], which its optimum does not keep; `None` for the others).

        **Raises:** `ValueError` where `params` is missing or not wanted."""

    def baseline_screen(self) -> tuple[str, np.ndarray, np.ndarray, np.ndarray] | None:
        """The baseline screen the optimum keeps: what its signals are (e.g. `"travelling waves"`),
        and the mean speed, cost of transport and `ok` (a stable gait without lift-off) of each;
        `None` (this default) where it keeps none."""
        return None

    def family(self) -> str:
        """The signals' family: `"H harmonics"` or `"spline of M knots"`."""
        return (
            f"{self.harmonics} harmonics" if self.control is None else f"spline of {np.shape(self.control)[-1]} knots"
        )

    def to_dict(self, full: bool = False) -> dict[str, Any]:
        """JSON-ready dict (`nan` and `inf` become `None`); `full` adds the candidates, the history and
        a chain's or a mechanism's `screen`."""
        skip = self.objects + (() if full else ("candidates", "history", "screen"))
        fields = dataclasses.fields(self)  # pyright: ignore[reportArgumentType]
        return jsonable({f.name: getattr(self, f.name) for f in fields if f.name not in skip} | self.extra())

    def extra(self) -> dict[str, Any]:
        """Figures of `to_dict` that are not fields."""
        return {}

    def to_json(self, full: bool = False, **kwargs: Any) -> str:
        """`to_dict` as JSON (`kwargs`: `json.dumps`'s)."""
        return dumps(self.to_dict(full), **kwargs)

    @abc.abstractmethod
    def summary(self) -> str:
        """Human-readable report."""

    def simulation_line(self) -> str:
        """The summary's line of the direct simulation."""
        p, ran = self.simulated_recurrence, math.isfinite(self.simulation_agreement)
        motion = ("" if p == 1 or not ran else f"; it settled on another motion, recurring every {p} gait periods "
                  "(a second attractor: this start does not lead to the optimum's gait)" if p
                  else "; its state did not recur within 4 gait periods")  # fmt: skip
        return (f"direct simulation ({self.simulated_periods} gait periods, then 12 averaged): mean speed "
                f"{fmt(self.mean_speed_simulated)}, cost of transport {fmt(self.cost_of_transport_simulated)} "
                f"(relative difference {fmt(self.simulation_agreement)}){motion}")  # fmt: skip


def constraints_line(constraints: dict, feasible: bool) -> str:
    """A summary's line of the constraints checked on the exact model."""
    held = ", ".join(f"{k} {'holds' if v else 'VIOLATED'}" for k, v in constraints.items())
    return f"constraints on the exact model: {held} -> {'FEASIBLE' if feasible else 'INFEASIBLE'}"


def waveform_of(fields: dict, omega: float, lbar: float) -> AbstractWaveform:
    """The waveform of an optimum's `fields` (`cos`, `sin` and `control`, as `AbstractShape.fields`
    gives them): a [`Spline`][] of the `control` values, or a [`Fourier`][] series where it is `None`."""
    if fields["control"] is not None:
        return Spline(fields["control"], omega, lbar)
    return Fourier(fields["cos"], fields["sin"], omega, lbar)


def start_waveform(start: Any) -> Any:
    """The waveform of the paper's model's `start=`: an [`Optimum`][]'s, that of its `to_dict()`
    (e.g. read back from the JSON of `optimize --json`), or `start` itself (any waveform).

    **Raises:** `ValueError` for a dict that is not an optimum of the paper's model (one signal:
    `cos` and `sin` of shape `(H,)`, `control` `(M,)` or `None`, `omega`, `lbar`)."""
    if isinstance(start, Optimum):
        return start.waveform
    if not isinstance(start, Mapping):
        return start
    if not {"cos", "sin", "control", "omega"} <= set(start):
        raise ValueError("start: a dict must be an optimum's to_dict(), with cos, sin, control, omega and lbar.")
    cos, sin = np.asarray(start["cos"], np.float64), np.asarray(start["sin"], np.float64)
    control = None if start["control"] is None else np.asarray(start["control"], np.float64)
    lbar = start.get("lbar")
    if cos.ndim != 1 or sin.shape != cos.shape or (control is not None and control.ndim != 1):
        raise ValueError(f"start: not a result of the paper's model (cos of shape {cos.shape}): a chain's or a "
                         "mechanism's result has a row per actuated signal.")  # fmt: skip
    if lbar is None or np.ndim(lbar) != 0:
        raise ValueError(f"start: a dict must be an optimum's to_dict(), with a scalar lbar (got {lbar!r}).")
    return waveform_of(dict(cos=cos, sin=sin, control=control), float(start["omega"]), float(lbar))


@dataclasses.dataclass(frozen=True)
class Optimum(AbstractOptimum):
    """Result of [`optimise`][locomotion_jax.optimisation._optimise.optimise]; every figure called `*_exact` is from
    the exact hybrid model.

    - `cos`, `sin`, `omega`, `lbar`: the waveform ([`Fourier`][], `waveform`); for a spline
      (`shape == "spline"`) `cos` and `sin` are empty, `harmonics` is 0 and `control` holds
      the [`Spline`][]'s control values.
    - `mean_speed_exact`, `cost_of_transport_exact`: signed mean speed and
      $e_d / |\\Delta X|$ after the paper's transient, from the relaxed spring.
    - `constraints_exact`: `{"speed", "stroke", "no_liftoff"}` each True when it
      holds on the exact model; `feasible_exact`: all three.
    - `stroke_exact`: $\\max_t |\\ell_0 - \\bar\\ell|$ (located exactly).
    - `mean_speed_smoothed`, `cost_of_transport_smoothed`, `min_normal_smoothed`:
      the smoothed model at the last $\\varepsilon$ (`eps`).
    - `sinusoid`: the best sinusoid for the same requirement (exact model) or
      `None`; `sinusoid_cost_of_transport`; `improvement_vs_sinusoid`
      $= 1 - \\text{cost}/\\text{cost}_\\text{sin}$ (negative when the sinusoid is
      better; `nan` when either is infeasible).
    - `initial_cost_of_transport_exact`: exact cost of the best feasible initial guess.
    - `source`: which candidate won; `candidates`: every verified candidate's figures.
    - `history`: per block costs and constraint values; `runtime_s`.
    - `method`: `"exact"` or `"smoothed"`. Exact method only (else `None`/NaN):
      `stable_exact` (a converged steady gait without lift-off whose Floquet multipliers all lie
      inside the unit circle, and which is the same with half the engine's step: its speed
      and cost of transport within 1e-3),
      `spectral_radius_exact` (their largest modulus), `gait_period_exact`,
      `evaluations` (batched orbit evaluations), and the direct simulation's figures
      ([`AbstractOptimum`][]: from the relaxed spring). With the exact method the
      `*_smoothed` figures and `eps` are NaN, and the `*_exact` figures are those of the
      steady gait ([`steady_gait`][]: whole periods).
    - `screen`: the sinusoid sweep of the baseline (its `a`, `omega`, `speed`, `cost`, `ok`,
      [`sinusoid_sweep`][locomotion_jax.optimisation._pareto.sinusoid_sweep]'s), which
      `to_dict(full=True)` includes and `optimise(params, ..., sweep=opt.screen)` takes again.
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
    lbar: float
    mean_speed_exact: float
    cost_of_transport_exact: float
    stroke_exact: float
    liftoff_exact: bool
    constraints_exact: dict
    feasible_exact: bool
    mean_speed_smoothed: float
    cost_of_transport_smoothed: float
    min_normal_smoothed: float
    eps: float
    sinusoid: dict | None
    sinusoid_cost_of_transport: float
    improvement_vs_sinusoid: float
    initial_cost_of_transport_exact: float
    source: str
    candidates: list
    history: list
    runtime_s: float
    method: str = "smoothed"
    stable_exact: bool | None = None
    spectral_radius_exact: float = math.nan
    gait_period_exact: float = math.nan
    evaluations: int = 0
    shape: str = "fourier"
    control: np.ndarray | None = None
    mean_speed_simulated: float = math.nan
    cost_of_transport_simulated: float = math.nan
    simulation_agreement: float = math.nan
    simulated_periods: int = 0
    simulated_recurrence: int = 0
    screen: dict | None = dataclasses.field(default=None, repr=False)

    def baseline_screen(self) -> tuple[str, np.ndarray, np.ndarray, np.ndarray] | None:
        """The sinusoids of the `screen` sweep, where it keeps one."""
        s = self.screen
        if s is None:
            return None
        return "sinusoids", np.asarray(s["speed"]), np.asarray(s["cost"]), np.asarray(s["ok"], bool)

    @property
    def waveform(self) -> AbstractWaveform:
        return waveform_of(dict(cos=self.cos, sin=self.sin, control=self.control), self.omega, self.lbar)

    def signals(self, t: np.ndarray) -> np.ndarray:
        """$\\ell_0(t) - \\bar\\ell$ at the times `t`, shape `(1, len(t))`."""
        return np.asarray(self.waveform(jnp.asarray(t))[0], np.float64)[None] - self.lbar

    def signal_labels(self) -> list[str]:
        return ["$\\ell_0 - \\bar\\ell$"]

    def baseline_signals(self, phase: np.ndarray) -> tuple[str, np.ndarray] | None:
        """The best sinusoid $a \\sin\\varphi$."""
        w = self.sinusoid
        if w is None:
            return None
        return f"best sinusoid, a = {w['a']:.3g}, $\\omega$ = {w['omega']:.3g}", w["a"] * np.sin(phase)[None]

    def driven(self, params: Any = None) -> tuple[Any, dict[str, Any]]:
        """`params` at the waveform's frequency, and the waveform, from the relaxed spring."""
        from ..model._params import Params
        from ._pareto import with_waveform_frequency

        if not isinstance(params, Params):
            raise ValueError("params: the paper's model's optimum keeps no Params; pass the Params it was optimised "
                             f"for, got {type(params).__name__}.")  # fmt: skip
        wave = self.waveform
        return with_waveform_frequency(params, wave), dict(waveform=wave, start="relaxed")

    def summary(self) -> str:
        """Human-readable report."""
        exact = self.method == "exact"
        lines = [
            f"requirement: mean speed >= {self.v_min:g} in direction {self.direction:+d}, stroke <= {self.a_max:g}, "
            + (
                f"normal forces >= {self.margin:g} on the orbit, stable steady gait (exact)"
                if exact
                else f"normal forces >= {self.margin:g} (smoothed), no lift-off (exact)"
            ),
            f"method: {self.method}; base frequency omega = {self.omega:.6g} "
            f"({'optimised' if self.free_omega else 'fixed'}), lbar = {self.lbar:g}, " + self.family(),
        ]
        if self.control is None:
            lines += [
                "cos coefficients: " + " ".join(f"{c:+.6f}" for c in self.cos),
                "sin coefficients: " + " ".join(f"{s:+.6f}" for s in self.sin),
            ]
        else:
            lines.append("control values: " + " ".join(f"{c:+.5f}" for c in self.control))
        if exact:
            lines += [
                f"steady gait (exact, whole periods): mean speed {fmt(self.mean_speed_exact)}, cost of transport "
                f"{fmt(self.cost_of_transport_exact)}, period {fmt(self.gait_period_exact)}, stable "
                f"{self.stable_exact} (largest multiplier modulus {fmt(self.spectral_radius_exact)})",
                f"stroke {fmt(self.stroke_exact)} (limit {self.a_max:g}); lift-off: {self.liftoff_exact}",
                self.simulation_line(),
            ]
        else:
            lines += [
                f"mean speed:        exact {fmt(self.mean_speed_exact)}   smoothed {fmt(self.mean_speed_smoothed)}",
                f"cost of transport: exact {fmt(self.cost_of_transport_exact)}   smoothed "
                f"{fmt(self.cost_of_transport_smoothed)} (eps = {self.eps:g})",
                f"stroke {fmt(self.stroke_exact)} (limit {self.a_max:g}); min normal force (smoothed) "
                f"{fmt(self.min_normal_smoothed)}; lift-off on the exact model: {self.liftoff_exact}",
            ]
        lines.append(constraints_line(self.constraints_exact, self.feasible_exact))
        if self.sinusoid is None:
            lines.append("best sinusoid: none meets the requirement on the exact model")
        else:
            s = self.sinusoid
            lines.append(
                f"best sinusoid: a = {s['a']:.4g}, omega = {s['omega']:.4g}: mean speed {s['mean_speed']:.4g}, "
                f"cost of transport {s['cost_of_transport']:.4g}"
            )
        lines.append(
            f"improvement vs sinusoid: {fmt(100 * self.improvement_vs_sinusoid)} %  "
            f"(winner: {self.source}; {self.runtime_s:.0f} s)"
        )
        return "\n".join(lines)


OptimiseSettings = Settings
"""Public name of [`Settings`][] (exported as `locomotion_jax.OptimiseSettings`)."""


ExactOptimiseSettings = ExactSettings
"""Public name of [`ExactSettings`][] (exported as `locomotion_jax.ExactOptimiseSettings`)."""


def verified(fig: Any, strokes: np.ndarray, speed: float, direction: int, a_max: float, eps: float,
             baseline: dict | None) -> tuple[int, np.ndarray, dict]:  # fmt: skip
    """Choose the reported candidate from the exact check of every candidate (`fig`: steady-gait
    figures with `speed`, `cost`, `ok` (a stable gait), `liftoff`; `strokes`: true strokes) by
    [`choose`][]. Returns its index, the feasibility of every candidate, and the chosen one's
    [`Optimum`][] fields of the exact check and the comparison with the best sinusoid `baseline`."""
    k, feasible, ok_speed, ok_stroke = choose(fig.ok, fig.speed, fig.cost, strokes, speed, direction, a_max, eps)
    sin_cost = baseline["cost_of_transport"] if baseline else math.nan
    fields = dict(
        mean_speed_exact=float(fig.speed[k]),
        cost_of_transport_exact=float(fig.cost[k]),
        stroke_exact=float(strokes[k]),
        liftoff_exact=bool(fig.liftoff[k]),
        constraints_exact={
            "speed": bool(ok_speed[k]),
            "stroke": bool(ok_stroke[k]),
            "no_liftoff": bool(~fig.liftoff[k]),
            "stable": bool(fig.ok[k]),
        },
        feasible_exact=bool(feasible[k]),
        sinusoid=baseline,
        sinusoid_cost_of_transport=sin_cost,
        improvement_vs_sinusoid=1 - float(fig.cost[k]) / sin_cost if (feasible[k] and baseline) else math.nan,
    )
    return k, feasible, fields


def along(speed: Any, direction: int) -> np.ndarray:
    """Speeds in the required `direction` ($\\sigma \\bar v$), a NaN (no gait, a stopped run) as $-\\infty$:
    never fast enough, and the slowest in either direction."""
    return np.nan_to_num(direction * np.asarray(speed), nan=-np.inf)


HALF_STEP_RTOL = 1e-3
"""Largest relative change of a candidate's mean speed or cost of transport with half the step: the
exact optimisers' verification counts a candidate stable only where its steady gait at half the
step agrees to this ([`steady_at_half_step`][locomotion_jax.optimisation._optimum.steady_at_half_step]),
a convergence check of every figure they report (those at the full step)."""


def steady_at_half_step(ok: np.ndarray, speed: np.ndarray, cost: np.ndarray, half_ok: np.ndarray,
                        half_speed: np.ndarray, half_cost: np.ndarray) -> np.ndarray:  # fmt: skip
    """`ok` where the gaits at half the step are `ok` too, with the same mean speed and cost of
    transport to [`HALF_STEP_RTOL`][locomotion_jax.optimisation._optimum.HALF_STEP_RTOL] (an infinite
    cost, a gait that does not move, agrees with itself)."""
    with np.errstate(invalid="ignore"):
        agree = lambda a, b: (a == b) | (np.abs(a - b) <= HALF_STEP_RTOL * np.abs(a))
        return np.asarray(ok & half_ok & agree(speed, half_speed) & agree(cost, half_cost), bool)


TIE_RTOL = 1e-9
"""Feasible candidates whose costs of transport lie within this of the cheapest's (relative) tie:
[`choose`][] reports the most stable of them, where it is given their spectral radii."""


def choose(ok: np.ndarray, speed: np.ndarray, cost: np.ndarray, strokes: np.ndarray, v_min: float, direction: int,
           a_max: float, eps: float, radius: np.ndarray | None = None,
           ) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """The reported candidate among the verified ones (`ok`: a converged, stable gait without
    lift-off; `strokes`: each one's largest exact stroke): the cheapest feasible one (speed
    `>= v_min` in `direction`, stroke within `a_max` up to 8 `eps` relative), else the closest
    miss, the fastest stable gait. With `radius` (each gait's largest Floquet multiplier modulus),
    of the feasible ones as cheap as the cheapest to [`TIE_RTOL`][] the most stable: where many
    gaits reach a floor of the cost (a capsule sliding at its kinetic friction), their costs
    differ by rounding, and the gait whose perturbations decay fastest is the one a robot keeps.
    Returns its index, and per candidate whether it is feasible, fast enough and within the stroke."""
    ok_speed = ok & (along(speed, direction) >= v_min)
    ok_stroke = strokes <= a_max * (1 + 8 * eps)
    feasible = ok_speed & ok_stroke & ok
    if feasible.any():
        k = int(np.argmin(np.where(feasible, cost, np.inf)))
        if radius is not None:
            tied = feasible & (cost <= cost[k] * (1 + TIE_RTOL))
            k = int(np.argmin(np.where(tied, radius, np.inf)))
    else:
        k = int(np.argmax(np.where(ok, along(speed, direction), -np.inf))) if ok.any() else 0
    return k, feasible, ok_speed, ok_stroke
