"""Settings and results of the optimisers of a [`Mechanism`][locomotion_jax.Mechanism] and of a
[`Chain`][] (`optimisation._mechanism`, `optimisation._chain`): one signal per actuated element, a
baseline screen, the shared local refinement and verification (`_element_local`).

A chain's settings and a mechanism's share a base (`ElementSettings`), a mechanism's adding the
lags between its elements and a chain's its travelling-wave screen's own fields, and both results
share the figures of the optimum's steady gait and of its direct simulation.
"""

import dataclasses
from typing import Any, ClassVar

import jax.numpy as jnp
import numpy as np

from ..model._bodies import Mechanism
from ..model._chain import Chain
from ..model._springwaves import SpringFourier
from ..model._waveform import Spline
from ._optimum import AbstractOptimum, constraints_line, fmt, Settings
from ._search_settings import count, SearchSettings, tension


class ElementSettings(SearchSettings):
    """What the settings of a mechanism's and of a chain's optimiser share: the fields of
    `SearchSettings`, the sinusoid screen's grid (`amplitudes`, `frequencies`, `phases`) and the
    smoothed local stage's `smoothed` and the idealised inchworms' starts (`tension_periods`,
    `tension_levels`), each class with its own defaults and docstring."""

    amplitudes: int = 4
    frequencies: int = 8
    phases: int = 1
    smoothed: Settings = Settings()
    tension_periods: int | None = None
    tension_levels: tuple[float, ...] = (0.3, 0.55, 0.8)

    def __check_init__(self):
        tension(self, optional=True)
        for field in ("amplitudes", "frequencies", "phases"):
            count(self, field, 1)
        if not isinstance(self.smoothed, Settings):
            raise TypeError(f"{type(self).__name__}.smoothed must be a Settings, got {type(self.smoothed).__name__}.")


class MechanismOptimiseSettings(ElementSettings):
    """Settings of [`optimise`][locomotion_jax.optimisation._optimise.optimise] for a
    [`Mechanism`][locomotion_jax.Mechanism] (module `optimisation._mechanism`): the fields of
    [`SearchSettings`][] with its defaults (`optimise`'s `harmonics` default 2), and the sinusoid
    screen's. Python numbers: changing `local`, `dt`, `search_dt`, `newton_iter`, `shape` or `knots`
    (or the harmonics) recompiles; the others do not.

    The actuators are the mechanism's elements driven by a waveform (a spring's rest length, an
    internal `Force`, an `ExternalForce`); `optimise`'s `a_max` bounds each one's excursion about its
    mean, in the element's own units: a length for a spring's rest, a force for a force (the force
    bound).

    - `amplitudes`, `frequencies`, `phases`, `lags`: the sinusoid screen, actuated element $j$
      driven by $a \\sin(\\omega t + \\varphi - j\\lambda)$: $a$ on `amplitudes` equal steps up to
      $a_\\max$, $\\omega$ log-spaced over its range (one value for a fixed `omega`), the phase
      $\\varphi$ on `phases` equal steps of $[0, 2\\pi)$, and with two or more actuated elements the
      lag $\\lambda$ from one to the next on `lags` equal steps of $[-\\pi, \\pi)$, 0 among them
      (a travelling wave along the elements, as a chain's; 1: every element in phase). A worm of
      three bodies on bristles built as a `Mechanism` reaches cost of transport 0.900 with the
      default 8 lags, the chain optimiser's optimum; 0.934 with its elements in phase, 0.982 with
      4 lags (`benchmarks/NOTES.md`).
    - `local`: the best sinusoids of the screen are refined.
    - `stall_rtol`: 0 by default: on the README's 4-mass worm, 1e-6 stopped the descent at a speed
      10 % above `v_min`, 0.09 % costlier (`benchmarks/NOTES.md`).
    - `omega_min`, `omega_max`: in units of the highest natural frequency of the mechanism's bodies
      and springs (or of its own base frequency where it has no spring).
    - `dt`: every figure of the result is at this step. With a `search_dt` the
      baseline is solved again at `dt` by the verification, which reports its figures.
    - `smoothed`: the settings ([`Settings`][]) of the local stage of `optimise(...,
      method="smoothed")` (module `optimisation._element_smoothed`, which names the fields it reads).
    - `tension_periods`, `tension_levels`: the idealised inchworms' starts
      (`optimisation._starts.mechanism_tension_waves`), as a chain's (`ChainOptimiseSettings`):
      each actuated element's tension a square wave alternating in sign, lagged from element to
      element as the best sinusoid, over `tension_periods` periods from 0.7 to 4 times the slowest
      natural period with one body held, its magnitudes these levels between the break-away forces
      of the element's two ends; those that beat the best sinusoid compete with the sinusoids for
      the local runs. `None` (default): 10 for a spline search, none for a Fourier series.

    A [`ChainOptimiseSettings`][] is accepted in its place: its fields of these names are used, one
    phase, and its `phases` (its travelling waves' lags) as the `lags`.
    """

    lags: int = 8

    def __check_init__(self):
        count(self, "lags", 1)

    @classmethod
    def from_chain(cls, s: "ChainOptimiseSettings") -> "MechanismOptimiseSettings":
        """A chain's settings' fields of these names, one phase, and the chain's `phases` (its
        travelling waves' lags) as the `lags`."""
        own = {f.name: getattr(s, f.name) for f in dataclasses.fields(cls) if f.name not in ("phases", "lags")}
        return cls(**own, lags=s.phases)


class ChainOptimiseSettings(ElementSettings):
    """Settings of [`optimise`][locomotion_jax.optimisation._optimise.optimise] for a [`Chain`][]
    (module `optimisation._chain`): those of [`MechanismOptimiseSettings`][] but its `lags` (the actuated elements
    are the springs, `a_max` bounds each spring's signal $\\max_t |s_j(t)|$: its stroke, or its force
    under [`InternalForce`][]; default 3 harmonics),
    with other defaults and the travelling-wave screen's own fields. Python numbers: changing
    `local`, `chunk`, `dt`, `search_dt`, `newton_iter`, `shape` or `knots` (or the harmonics)
    recompiles; the others do not.

    Where a chain reads a field otherwise:

    - `amplitudes`, `frequencies`, `phases`: the travelling-wave screen, $a$ on `amplitudes` equal
      steps up to $a_\\max$, $\\omega$ log-spaced over its range, the phase lag $\\varphi$ on
      `phases` equal steps of $[-\\pi, \\pi)$ (one phase for $N = 2$); with `shape="spline"` the
      screen's travelling waves are single harmonics (a chain's `phases` are what a mechanism's
      settings call `lags`; it has no field of that name).
    - `local`: the refined best wave and the next best distinct waves of the screen.
    - `omega_min`, `omega_max`: in units of the lowest natural frequency with one mass held
      ([`Chain.omega_min`][locomotion_jax.Chain.omega_min]) and of the highest natural frequency of
      the free chain.
    - `transient`: actuation periods from the relaxed springs (screen, refinement, verification).

    The screen's own fields:

    - `screen_speed`: the screen solves the steady gaits only of the waves whose speed over the
      last 12 periods of their transient reaches this fraction of $v_\\min$ (and of the `chunk`
      fastest, so that an infeasible requirement still has candidates); 0: of every wave. A
      wave far slower than required where its transient ends is no start for the optimum, and
      the slowest waves (the longest periods) cost the screen most.
    - `zoom_levels`, `zoom_points`: the zooming refinement of the best travelling wave: per
      level a grid of `zoom_points` per variable over one step either side, the step halved
      per level.
    - `chunk`: configurations per compiled `steady_gait` call.

    The idealised inchworms' starts (`optimisation._starts.tension_waves`, rest-length actuators):

    - `tension_periods`, `tension_levels`: each spring's tension a square wave alternating in sign,
      lagged from spring to spring as the best travelling wave, over `tension_periods` periods from
      0.7 to 4 times the slowest natural period with one mass held and these levels between the
      break-away forces of each spring's two masses; their steady gaits are solved beside the
      screen's, and those that beat the best wave compete with the waves for the local runs.
      0 periods: none; `None` (default): 10 for a spline search, none for a Fourier series, whose
      few harmonics cannot draw the inchworm's jumps (on the README's 4-mass worm they cost 41 s
      of the screen's 88 and no start better than the best wave; `benchmarks/NOTES.md`).
    """

    amplitudes: int = 3
    frequencies: int = 12
    phases: int = 8
    local: int = 4
    max_iter: int = 60
    omega_min: float = 0.06
    omega_max: float = 1.2
    screen_speed: float = 0.5
    zoom_levels: int = 2
    zoom_points: int = 5
    chunk: int = 32

    def __check_init__(self):
        count(self, "zoom_points", 1)
        count(self, "chunk", 1)
        count(self, "zoom_levels", 0)
        if not (0 <= self.screen_speed <= 1):
            raise ValueError(f"ChainOptimiseSettings.screen_speed must be in [0, 1], got {self.screen_speed!r}.")


@dataclasses.dataclass(frozen=True)
class ElementOptimum(AbstractOptimum):
    """What the results of the chain's and the mechanism's optimisers share; every figure called
    `*_exact` is the steady gait's ([`steady_gait`][]: whole periods, exact model, strict contact).

    - The requirement: `v_min`, `direction`, `a_max`; `margin`, the smallest normal force required
      on the orbit during the refinement; `free_omega`, whether the base frequency was searched.
    - The signals: `shape`, their family, `"fourier"` or `"spline"` (a spline search reports its
      baseline, `"fourier"`, where no refined spline is cheaper); `cos`, `sin`, shape `(S, H)` over
      the `S` actuated elements, their Fourier coefficients about the elements' means (absolute
      units; `(S, 0)` and `harmonics` 0 for a spline); `control`, shape `(S, M)`, a spline's control
      values about the means (absolute units; `None` for a Fourier series); `omega`, the base
      frequency.
    - The optimum's steady gait: `mean_speed_exact`, `cost_of_transport_exact` ($e_d / |\\Delta X|$
      over the gait period), `gait_period_exact`, `stable_exact`, `spectral_radius_exact` (the
      largest Floquet multiplier's modulus), `stroke_exact` (per element, the largest excursion of
      its signal about its mean, located exactly), `liftoff_exact`, `min_normal` (the smallest
      normal force on the orbit, `Gait.min_normal`; not a constraint of the verification, which
      requires no lift-off: `margin` bounds it in the refinement only).
    - `constraints_exact` (`speed`, `stroke`, `no_liftoff`, `stable`), `feasible_exact`: all hold.
      An infeasible requirement gives `feasible_exact = False` and the closest candidate (the
      fastest stable gait), never an optimum.
    - The direct simulation's `mean_speed_simulated`, `cost_of_transport_simulated`,
      `simulation_agreement`, `simulated_periods` and `simulated_recurrence`, as
      [`AbstractOptimum`][locomotion_jax.optimisation._optimum.AbstractOptimum]'s.
    - `source`, the winning candidate; `candidates`, every verified candidate's figures;
      `history`, the local starts (the baseline screen's rows; a chain's idealised inchworms with
      their `inchworm` period, level and lag) and the local runs' log;
      `screened`, the baseline signals solved; `evaluations`, batched orbit evaluations;
      `runtime_s`; `dt_exact`, the engine's step of every `*_exact` figure and of the direct
      simulation (the settings' `dt`, or finer where a spline search needs it to resolve its
      candidates' knots).
    - `screen`: every baseline signal of the screen, as arrays over them: its grid coordinates (a
      chain's travelling waves `a`, `omega`, `phi`; a mechanism's sinusoids `a`, `omega`,
      `phase`, `lag`), and its steady gait at the search step (`search_dt`, else `dt`): `speed`, `cost`,
      `ok` (converged, stable, no lift-off), `liftoff`, `k`, `period`, `radius`, `min_normal` and
      `y`, the section state (the local runs' warm start); NaN and not `ok` where the screen left a
      signal unsolved. `to_dict(full=True)` includes it; `optimize --out` draws it (`pareto.png`);
      `optimise(..., sweep=opt.screen)` takes it as its screen at another requirement.
    """

    v_min: float
    direction: int
    a_max: float
    margin: float
    free_omega: bool
    harmonics: int
    shape: str
    cos: np.ndarray
    sin: np.ndarray
    control: np.ndarray | None
    omega: float
    mean_speed_exact: float
    cost_of_transport_exact: float
    gait_period_exact: float
    stable_exact: bool
    spectral_radius_exact: float
    stroke_exact: np.ndarray
    liftoff_exact: bool
    min_normal: float
    constraints_exact: dict
    feasible_exact: bool
    mean_speed_simulated: float
    cost_of_transport_simulated: float
    simulation_agreement: float
    simulated_periods: int
    simulated_recurrence: int
    source: str
    candidates: list
    history: list
    screened: int
    evaluations: int
    runtime_s: float
    dt_exact: float
    screen: dict = dataclasses.field(repr=False)

    screen_label: ClassVar[str] = "baseline signals"
    """What the screen's signals are, for its figure."""

    def baseline_screen(self) -> tuple[str, np.ndarray, np.ndarray, np.ndarray] | None:
        """The `screen` field's signals, speeds, costs of transport and `ok`."""
        s = self.screen
        return self.screen_label, np.asarray(s["speed"]), np.asarray(s["cost"]), np.asarray(s["ok"], bool)

    def signals(self, t: np.ndarray) -> np.ndarray:
        """$s_j(t)$ about the element's mean at the times `t`, shape `(S, len(t))`."""
        t = np.asarray(t, np.float64)
        if self.control is None:
            wt = np.outer(np.arange(1, self.cos.shape[1] + 1), self.omega * t)
            return self.cos @ np.cos(wt) + self.sin @ np.sin(wt)
        times = jnp.asarray(t)
        return np.stack([np.asarray(Spline(c, self.omega, 0.0)(times)[0], np.float64) for c in self.control])

    def signal_lines(self, labels: list[str]) -> list[str]:
        """One line per actuated element, `labels[j]` first: its coefficients or control values."""
        if self.control is None:
            return [f"{label}: cos " + " ".join(f"{c:+.5f}" for c in cj) + "  sin " + " ".join(f"{s:+.5f}" for s in sj)
                    for label, cj, sj in zip(labels, self.cos, self.sin)]  # fmt: skip
        return [f"{label}: control " + " ".join(f"{c:+.5f}" for c in cj) for label, cj in zip(labels, self.control)]

    def gait_line(self) -> str:
        """The summary's line of the optimum's steady gait."""
        return (f"steady gait (exact, whole periods): mean speed {fmt(self.mean_speed_exact)}, cost of transport "
                f"{fmt(self.cost_of_transport_exact)}, period {fmt(self.gait_period_exact)}, stable "
                f"{self.stable_exact} (largest multiplier modulus {fmt(self.spectral_radius_exact)})")  # fmt: skip


@dataclasses.dataclass(frozen=True)
class ChainOptimum(ElementOptimum):
    """Result of [`optimise`][locomotion_jax.optimisation._optimise.optimise] for a [`Chain`][]: the
    fields of [`ElementOptimum`][locomotion_jax.optimisation._element_optimum.ElementOptimum] (the
    actuated elements are the springs, $s_j(t) = \\ell_{0,j}(t) - \\bar\\ell_j$ under the rest-length
    actuator, the force $f_j(t)$ under [`InternalForce`][]; `waveforms`: a
    [`SpringFourier`][] or one [`Spline`][] per spring; `chain`: the input chain driven by them;
    the direct simulation runs from the relaxed springs), and:

    - `lbar` (per spring);
    - `travelling_wave`: the best travelling wave $a\\sin(\\omega t - j\\varphi)$ of the screen and
      its zoom that meets the requirement (`a`, `omega`, `phi`, `mean_speed`,
      `cost_of_transport`), or `None`; `travelling_wave_cost_of_transport`;
      `improvement_vs_travelling_wave` $= 1 - \\text{cost}/\\text{cost}_\\text{wave}$ (NaN when either
      is infeasible).
    """

    lbar: np.ndarray
    travelling_wave: dict | None
    travelling_wave_cost_of_transport: float
    improvement_vs_travelling_wave: float
    chain: Chain = dataclasses.field(repr=False)

    objects: ClassVar[tuple[str, ...]] = ("chain",)
    screen_label: ClassVar[str] = "travelling waves"

    @property
    def waveforms(self) -> SpringFourier | list[Spline]:
        """The actuation: a [`SpringFourier`][] of `cos`, `sin`, or one [`Spline`][] per spring."""
        if self.control is None:
            return SpringFourier(self.cos, self.sin, self.omega)
        return [Spline(c, self.omega, lb) for c, lb in zip(self.control, self.lbar)]

    def signal_labels(self) -> list[str]:
        return [f"spring {j}" for j in range(self.cos.shape[0])]

    def baseline_signals(self, phase: np.ndarray) -> tuple[str, np.ndarray] | None:
        """The best travelling wave $a \\sin(\\varphi - j\\phi)$."""
        w = self.travelling_wave
        if w is None:
            return None
        signals = w["a"] * np.sin(phase[None] - np.arange(self.cos.shape[0])[:, None] * w["phi"])
        return (
            f"best travelling wave, a = {w['a']:.3g}, $\\omega$ = {w['omega']:.3g}, $\\phi$ = {w['phi']:.3g}",
            signals,
        )

    def driven(self, params: Any = None) -> tuple[Any, dict[str, Any]]:
        """`chain`, from the relaxed springs."""
        _no_params(params)
        return self.chain, dict(start="relaxed")

    def extra(self) -> dict[str, Any]:
        """`n_masses`."""
        return {"n_masses": int(self.cos.shape[0]) + 1}

    def summary(self) -> str:
        """Human-readable report."""
        S = self.cos.shape[0]
        bound = "stroke" if self.chain.actuator.varies_rest_length else "force"  # what the signal is
        lines = [
            f"chain of {S + 1} masses: mean speed >= {self.v_min:g} in direction {self.direction:+d}, {bound} <= "
            f"{self.a_max:g} per spring, normal forces >= {self.margin:g} on the orbit, stable steady gait (exact)",
            f"base frequency omega = {self.omega:.6g} ({'optimised' if self.free_omega else 'fixed'}), "
            f"{self.family()} per spring",
            *self.signal_lines([f"spring {j}" for j in range(S)]),
            self.gait_line(),
            f"{bound} per spring "
            + " ".join(fmt(float(s)) for s in self.stroke_exact)
            + f" (limit {self.a_max:g}); min normal force {fmt(self.min_normal)}; lift-off: {self.liftoff_exact}",
            self.simulation_line(),
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


@dataclasses.dataclass(frozen=True)
class MechanismOptimum(ElementOptimum):
    """Result of [`optimise`][locomotion_jax.optimisation._optimise.optimise] for a
    [`Mechanism`][locomotion_jax.Mechanism]: the fields of
    [`ElementOptimum`][locomotion_jax.optimisation._element_optimum.ElementOptimum] (the actuated
    elements in the order of `elements`, indices into `links`; `mechanism`: the mechanism driven
    by the signals; the direct simulation runs from the mechanism's own start), and `sinusoid`, the
    best sinusoid of the screen (a dict: `a`, `omega`, `phase`, `lag`, `mean_speed`, `cost_of_transport`;
    `None` if none meets the speed); `improvement_vs_sinusoid`: $1 -$ the ratio of the costs of
    transport.
    """

    elements: list[int]
    sinusoid: dict | None
    improvement_vs_sinusoid: float
    mechanism: Mechanism = dataclasses.field(repr=False)

    objects: ClassVar[tuple[str, ...]] = ("mechanism",)
    screen_label: ClassVar[str] = "sinusoids"

    def signal_labels(self) -> list[str]:
        return [f"link {e}" for e in self.elements]

    def baseline_signals(self, phase: np.ndarray) -> tuple[str, np.ndarray] | None:
        """The best sinusoid $a \\sin(\\varphi + \\varphi_0 - j\\lambda)$ of element $j$."""
        w = self.sinusoid
        if w is None:
            return None
        lag = w.get("lag", 0.0)  # a result of before the lags: every element in phase
        signals = w["a"] * np.sin(phase[None] + w["phase"] - np.arange(len(self.elements))[:, None] * lag)
        label = f"best sinusoid, a = {w['a']:.3g}, $\\omega$ = {w['omega']:.3g}, phase {w['phase']:.3g}, lag {lag:.3g}"
        return label, signals

    def driven(self, params: Any = None) -> tuple[Any, dict[str, Any]]:
        """`mechanism`, from its own start."""
        _no_params(params)
        return self.mechanism, {}

    def summary(self) -> str:
        """Human-readable report."""
        lines = [
            f"mechanism of {self.mechanism.n_bodies} bodies: mean speed >= {self.v_min:g} in direction "
            f"{self.direction:+d}, excursion <= {self.a_max:g} per actuated link, stable steady gait (exact)",
            f"base frequency omega = {self.omega:.6g}; links {self.elements} actuated by {self.family()}",
            *self.signal_lines([f"link {e}" for e in self.elements]),
            self.gait_line(),
            "excursion per link " + " ".join(fmt(float(s)) for s in np.ravel(self.stroke_exact))
            + f" (limit {self.a_max:g}); min normal force {fmt(self.min_normal)}; lift-off: {self.liftoff_exact}",
            self.simulation_line(),
            constraints_line(self.constraints_exact, self.feasible_exact),
        ]  # fmt: skip
        w = self.sinusoid
        if w is None:
            lines.append("best sinusoid: none meets the requirement on the exact model")
        else:
            lines.append(f"best sinusoid: a = {w['a']:.4g}, omega = {w['omega']:.4g}, phase = {w['phase']:.4g}, "
                         f"lag = {w.get('lag', 0.0):.4g}: mean speed {w['mean_speed']:.4g}, cost of transport "
                         f"{w['cost_of_transport']:.4g}")  # fmt: skip
        lines.append(
            f"improvement vs sinusoid: {fmt(100 * self.improvement_vs_sinusoid)} %  (winner: {self.source}; "
            f"{self.screened} sinusoids screened, {self.evaluations} batched evaluations, {self.runtime_s:.0f} s)"
        )
        return "\n".join(lines)


def _no_params(params: Any) -> None:
    if params is not None:
        raise ValueError(f"params: a chain's or a mechanism's optimum drives its own (pass none), got {params!r}.")
