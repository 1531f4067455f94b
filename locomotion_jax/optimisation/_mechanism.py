"""Optimal actuation of a [`Mechanism`][locomotion_jax.Mechanism] (SPEC §9): the chain optimiser's
method over the waveforms of the mechanism's actuated elements.

Problem, for one mechanism, a required speed $v_\\min > 0$ in the direction $\\sigma = \\pm 1$ and a
bound $a_\\max$ on every actuated signal: over periodic signals of a common base frequency for each
element driven by a waveform (a spring's rest length, an internal force, an external force;
`Mechanism.actuated`), each about the element's own mean $\\bar s_j$, of one of the two
families of the exact optimiser (`_shapes`, [`MechanismOptimiseSettings`][]`.shape`):

- `"fourier"` (default): Fourier series of $H$ harmonics, $s_j(t) = \\bar s_j + \\sum_n A_{jn}\\cos
  n\\omega t + B_{jn}\\sin n\\omega t$;
- `"spline"`: periodic cubic B-splines of $M$ = `knots` control values $c_{jm}$ in the phase
  ([`Spline`][]), whose excursion is bounded by $\\max_m |c_{jm}|$, so that the bound is a box.

$$\\min\\ \\frac{e_d}{\\sigma\\Delta X}\\quad\\text{s.t.}\\quad \\frac{\\sigma\\Delta X}{kT} \\ge v_\\min,\\quad
\\max_t |s_j(t) - \\bar s_j| \\le a_\\max\\ \\forall j,\\quad\\text{a stable gait},$$

on the periodic orbits of the exact model ([`steady_gait`][] of a mechanism).

Method (as `optimisation._chain`, with sinusoids in place of travelling waves):

1. **Sinusoids**: actuated element $j$ driven by $a\\sin(\\omega t + \\varphi - j\\lambda)$ about its
   mean, on a grid of `amplitudes` $\\times$ `frequencies` $\\times$ `phases` $\\times$ `lags`
   ([`MechanismOptimiseSettings`][]; the lag $\\lambda$ with two or more actuated elements only),
   solved in one batched [`steady_gait`][]; the cheapest that meets the speed is the baseline. The
   phase matters where the ground is symmetric: a sinusoid's steady gait then has a mirror image
   (x -> -x, t -> t + T/2) going the other way, and the phase of the start picks one. The lag
   makes a travelling wave along the elements (a worm's springs, as a chain's screen has them),
   or sets an internal force's phase against an external one's.
2. **Local refinement** of every element's harmonics (or control values, started from the
   sinusoid's interpolating spline) from the best `local` sinusoids and, in a spline search,
   the idealised inchworms that beat the best of them (`_starts.mechanism_tension_waves`: each
   actuated element's tension a square wave alternating in sign, lagged as the best sinusoid;
   where none beats it, the sinusoids keep every lane): the chain's monotone L-BFGS
   descent on an exact penalty (`_element_local`), with exact gradients through the periodic orbit
   (`gaits._element_orbit.ChainOracle`, which takes a mechanism). The bound is kept by radial
   rescaling of each element's Fourier coefficients onto its exact stroke, or by clipping the
   control values.
3. **Verification**: the refined actuations (on the exact bound) and the baseline are solved
   again by [`steady_gait`][] (a spline's baseline: its row of the screen); the reported optimum
   is the cheapest converged, stable and fast enough one, so never costlier than the baseline,
   and it is checked by a direct [`simulate`][] averaged over whole gait periods once its
   transient has decayed.

The frequency range, for a free `omega`, is `omega_min` to `omega_max` times the highest natural
frequency of the mechanism's free bodies and springs (its resolution guard's scale), or the
mechanism's own base frequency where it has no spring between bodies.
"""

import math
import time
from collections.abc import Mapping
from typing import Any, cast

import jax.numpy as jnp
import numpy as np

from ..dynamics._exact_dynamics import Exact
from ..gaits._progress import reporter
from ..model._bodies import Mechanism
from . import _chain_screen as screen, _element_local as local
from ._element_optimum import ChainOptimiseSettings, MechanismOptimiseSettings, MechanismOptimum
from ._optimum import along
from ._starts import mechanism_tension_waves, tension_starts


def _stiffness(mech: Mechanism) -> np.ndarray:
    """The mass-normalised stiffness matrix $M^{-1/2} K M^{-1/2}$ of the bodies and springs (wall
    springs included; a tilted spring's geometry ignored, as in eqs. 11-12)."""
    m = np.asarray(mech.m, np.float64)
    K = np.zeros((m.size, m.size))
    for el in mech.links:
        k = el.values().get("k")  # a spring's stiffness (other elements have none)
        if k is None:
            continue
        ends = [e for e in el.bodies() if isinstance(e, int)]
        for a in ends:
            K[a, a] += float(k)
        if len(ends) == 2:
            K[ends[0], ends[1]] -= float(k)
            K[ends[1], ends[0]] -= float(k)
    s = 1 / np.sqrt(m)
    return K * s[:, None] * s[None, :]


def _natural(mech: Mechanism) -> float:
    """The highest natural frequency of the free bodies and springs (wall springs included)."""
    return float(np.sqrt(max(np.linalg.eigvalsh(_stiffness(mech)).max(), 0.0)))


def _held(mech: Mechanism) -> float:
    """The lowest natural frequency with one body in ground contact held, over which body (a
    chain's [`Chain.omega_min`][locomotion_jax.Chain.omega_min]); 0 where no such mode exists."""
    Kn, lowest = _stiffness(mech), math.inf
    for i, law in enumerate(mech.friction):
        keep = [j for j in range(len(Kn)) if j != i]
        if law is None or not keep:
            continue
        w = np.linalg.eigvalsh(Kn[np.ix_(keep, keep)])
        w = w[w > 1e-12 * max(w.max(), 0.0)]
        lowest = min([lowest, *np.sqrt(w)])
    return 0.0 if math.isinf(lowest) else float(lowest)


def _inchworms(base: Mechanism, lag: float, a_max: float, lo: float, hi: float, harmonics: int, knots: int,
               state: np.ndarray, settings: MechanismOptimiseSettings, say: Any,
               ) -> screen.Inchworms | None:  # fmt: skip
    """The idealised inchworms' starts of a mechanism (`_starts.mechanism_tension_waves`: each
    actuated element's tension a square wave, element $j$'s lagged by $j$ `lag`) over
    `settings.tension_periods` periods (`None`: 10 for a spline search, none for a Fourier series)
    from 0.7 to 4 times the slowest natural period with one body held ([`_held`][]) and
    `settings.tension_levels`, in the search's family, their frequencies clipped to `[lo, hi]`,
    and their steady gaits at `settings`' step; `None` where there are none (no periods, no such
    mode, an actuated external force)."""
    count = settings.tension_periods if settings.tension_periods is not None else (10 if knots else 0)
    w = _held(base)
    if not count or not w:
        return None
    periods = 2 * math.pi / w * np.geomspace(0.7, 4.0, count)
    waves = tension_starts(lambda pp, ll: mechanism_tension_waves(base, pp, ll, lag), a_max, periods,
                           settings.tension_levels)  # fmt: skip
    if not waves:
        return None
    starts = [local.sampled_start(a_max * v, om, harmonics, knots, a_max, lo, hi, state) for v, om, _ in waves]
    omega = np.array([st.omega for st in starts])
    say(f"solving the steady gaits of {len(starts)} idealised inchworms (lag {lag:.4g})...")
    if knots:
        g = _gaits(_spline(base, np.stack([cast(np.ndarray, st.control) for st in starts]), omega), settings, False)
    else:
        g = _gaits(_fourier(base, np.stack([st.cos for st in starts]), np.stack([st.sin for st in starts]), omega),
                   settings)  # fmt: skip
    starts = [st._replace(y=g["y"][i], k=int(g["k"][i]), cost=float(g["cost"][i]), fresh=False)
              for i, st in enumerate(starts)]  # fmt: skip
    period, level = np.array([2 * math.pi / q for _, q, _ in waves]), np.array([q for _, _, q in waves])
    return screen.Inchworms(starts, period, level, screen.Gaits(**g))


def _gaits(batch: Mechanism, settings: MechanismOptimiseSettings, guarded: bool = True) -> dict[str, np.ndarray]:
    """Steady gaits (periods 1 and 2; [`steady_gait`][]'s problem and solver) of a batch of
    mechanisms, as host arrays. `guarded=False`: the search's splines, at a step that need not
    resolve their knots (`gaits._shooting.bodies_problem`)."""
    from ..gaits._shooting import bodies_problem, steady_gaits

    dynamics = Exact(dt=settings.dt)
    problem = bodies_problem(batch, dynamics, "strict", "paper", None, guarded)
    g = steady_gaits(problem, periods=(1, 2), transient=settings.transient, dynamics=dynamics, contact="strict",
                     bucket=True)  # fmt: skip
    radius = np.max(np.abs(np.asarray(g.multipliers)), axis=-1)
    liftoff = np.asarray(g.liftoff)
    ok = np.asarray(g.converged) & np.asarray(g.stable) & ~liftoff
    return dict(speed=np.asarray(g.mean_speed, np.float64), cost=np.asarray(g.cost_of_transport, np.float64), ok=ok,
                liftoff=liftoff, k=np.asarray(g.k), period=np.asarray(g.period, np.float64), radius=radius,
                min_normal=np.asarray(g.min_normal, np.float64), y=np.asarray(g.state, np.float64))  # fmt: skip


GAIT_FIELDS = ("speed", "cost", "ok", "liftoff", "k", "period", "radius", "min_normal", "y")
"""The figures of each sinusoid's gait that [`_gaits`][] gives and the optimum's `screen` keeps."""


def _from_record(given: Any, n_red: int, a_max: float, lo: float, hi: float) -> tuple[Any, ...]:
    """`(a, omega, phase, lag, gaits)` of an earlier optimum's `screen` (`sweep=`): its sinusoids
    within the bound and the frequency range (`_element_local.screen_rows`, which raises a
    `ValueError` naming `sweep` for a record of another kind or mechanism); a record without lags
    drove every element in phase."""
    if isinstance(given, Mapping) and "lag" not in given and "a" in given:
        given = {**given, "lag": np.zeros(np.shape(given["a"]))}
    rows = local.screen_rows(given, ("a", "omega", "phase", "lag", *GAIT_FIELDS), n_red, a_max, lo, hi,
                             ("mechanism", "sinusoid"), "this mechanism's section state")  # fmt: skip
    return rows["a"], rows["omega"], rows["phase"], rows["lag"], {key: rows[key] for key in GAIT_FIELDS}


def sinusoids(a_max: float, lo: float, hi: float, S: int, settings: MechanismOptimiseSettings,
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """The screen's sinusoids for `S` actuated elements, as flat arrays `(a, omega, phase, lag)`
    over the grid of [`MechanismOptimiseSettings`][]: `omega` log-spaced over `[lo, hi]` (`lo`
    alone where they are equal), the lags `settings.lags` equal steps of $[-\\pi, \\pi)$ with 0
    among them, or 0 alone for one element (a lag needs two)."""
    amps = a_max * np.arange(1, settings.amplitudes + 1) / settings.amplitudes
    oms = np.geomspace(lo, hi, settings.frequencies) if hi > lo else np.array([lo])
    phis = 2 * np.pi * np.arange(settings.phases) / settings.phases
    n = settings.lags if S > 1 else 1
    lags = np.sort((2 * np.pi * np.arange(n) / n + np.pi) % (2 * np.pi) - np.pi)
    A, W, PHI, LAG = (x.ravel() for x in np.meshgrid(amps, oms, phis, lags, indexing="ij"))
    return A, W, PHI, LAG


def sinusoid_signals(a: np.ndarray, phase: np.ndarray, lag: np.ndarray, S: int, H: int,
                     ) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """`(cos, sin)` `(B, S, H)` of the sinusoids $a \\sin(\\omega t + \\varphi - j\\lambda)$ of elements
    $j < S$ (`a`, `phase`, `lag`: `(B,)`), in a Fourier series of `H` harmonics."""
    cos, sin = np.zeros((a.size, S, H)), np.zeros((a.size, S, H))
    shift = phase[:, None] - np.arange(S)[None] * lag[:, None]
    cos[:, :, 0], sin[:, :, 0] = a[:, None] * np.sin(shift), a[:, None] * np.cos(shift)
    return cos, sin


def _fourier(mech: Mechanism, cos: np.ndarray, sin: np.ndarray, omega: Any) -> Mechanism:
    """`mech` driven by Fourier series (absolute units; leading axes: a batch)."""
    dtype = mech.dtype
    return mech.with_fourier(jnp.asarray(cos, dtype), jnp.asarray(sin, dtype), jnp.asarray(omega, dtype))


def _spline(mech: Mechanism, control: np.ndarray, omega: Any) -> Mechanism:
    """`mech` driven by splines of these control values (absolute units; leading axes: a batch)."""
    return mech.with_spline(jnp.asarray(control, mech.dtype), jnp.asarray(omega, mech.dtype))


def check_inputs(mech: Any, v_min: Any, a_max: Any, direction: Any, harmonics: Any, omega: Any) -> list[int]:
    """Validate a mechanism requirement; return the actuated elements' indices.

    **Raises:** `ValueError` naming the argument and its valid range."""
    if mech.batch_shape != ():
        raise ValueError(f"mechanism must be a single configuration (batch shape ()), got {mech.batch_shape}.")
    mech.validate()
    elements = mech.actuated()
    if not elements:
        raise ValueError(
            "optimise: the mechanism has no element driven by a waveform (a Spring's rest, a Force or an "
            "ExternalForce with a Sinusoid, Fourier or Spline) whose waveform it could design."
        )
    local.check_requirement(v_min, direction, harmonics, omega)
    if not (isinstance(a_max, (int, float, np.floating, np.integer)) and np.isfinite(a_max) and a_max > 0):
        raise ValueError(f"a_max must be a finite bound > 0 on every actuated signal's excursion, got {a_max!r}.")
    return elements


def optimise_mechanism(mech: Mechanism, v_min: float, a_max: float, *, direction: int = 1,
                       omega: float | None = None, harmonics: int | None = None, settings: Any = None,
                       start: Any = None, method: str = "exact", sweep: Any = None) -> MechanismOptimum:  # fmt: skip
    """`optimise(mechanism, v_min, a_max, ...)`: the method of the module docstring. `settings`: a
    `MechanismOptimiseSettings`, a `ChainOptimiseSettings` (its shared fields) or `None` (the defaults);
    anything else is refused here with a `TypeError` naming both. `harmonics`: the Fourier series'
    length (default 2); a spline search (`settings.shape == "spline"`) refuses one. `start`: an
    earlier mechanism optimum ([`_element_local.given_start`][]) that takes the last local lane and
    is a candidate itself. `method="smoothed"`: the local stage on the smoothed model
    (`_element_smoothed`; Fourier series only), verified as the exact method's. `sweep`: an earlier
    optimum's `screen` of this mechanism (`_from_record`), which then is the screen: its sinusoids
    are not solved again."""
    if isinstance(settings, ChainOptimiseSettings):
        settings = MechanismOptimiseSettings.from_chain(settings)
    settings = MechanismOptimiseSettings() if settings is None else settings
    if not isinstance(settings, MechanismOptimiseSettings):
        raise TypeError(f"settings for a Mechanism must be a MechanismOptimiseSettings, got {type(settings).__name__}.")
    local.check_method(method, settings)
    spline = settings.shape == "spline"
    search = settings.searching()  # the screen's and the local runs' step; the verification's is dt
    H = local.family_harmonics(settings, harmonics, 2)  # a spline search screens plain sinusoids
    elements = check_inputs(mech, v_min, a_max, direction, H, omega)
    t0 = time.perf_counter()
    say = reporter(settings.verbose)
    base = mech.broadcast()
    S, H, M = len(elements), int(H), settings.knots
    local.check_start(start, S)
    if omega is not None:
        lo = hi = float(omega)
    else:
        w = _natural(base) or float(base.omega)
        lo, hi = settings.omega_min * w, settings.omega_max * w
    free = hi > lo
    # A step that does not resolve even the slowest sinusoid of the screen (the mechanism's own
    # time scales, the forcing at the lowest frequency) resolves no candidate: refused, named.
    slowest = _fourier(base, np.zeros((S, 1)), np.zeros((S, 1)), lo)
    local.refuse_steps(slowest, settings, f"optimise: the screen's slowest sinusoid, omega = {lo:.6g}")

    # 1. Sinusoids a sin(omega t + phi - j lag) on actuated element j (or the given screen's).
    sc: dict[str, np.ndarray] | None = None
    if sweep is None:
        A, W, PHI, LAG = sinusoids(a_max, lo, hi, S, settings)
    else:
        n_red = 2 * base.n_bodies - (0 if base.physics().anchored else 1)
        A, W, PHI, LAG, sc = _from_record(sweep, n_red, a_max, lo, hi)
    cos, sin = sinusoid_signals(A, PHI, LAG, S, H)
    if sc is None:
        say(f"screening {A.size} sinusoids (compiling the steady-gait solver: first call only)...")
        sc = _gaits(_fourier(base, cos, sin, W), search)
    else:
        say(f"the given screen: {A.size} sinusoids, not solved again")
    fast = np.asarray(sc["ok"], bool) & (along(sc["speed"], direction) >= v_min)
    order = np.lexsort((-along(sc["speed"], direction), np.where(fast, sc["cost"], np.inf),
                        ~fast))  # fmt: skip
    best = int(order[0])
    row_of = lambda i: dict(a=float(A[i]), omega=float(W[i]), phase=float(PHI[i]), lag=float(LAG[i]),
                            mean_speed=float(sc["speed"][i]), cost_of_transport=float(sc["cost"][i]))  # fmt: skip
    sinusoid = row_of(best) if fast[best] else None

    # 2. Local refinement of every element's harmonics (or control values) from the best sinusoids
    # and, where they beat the best of them, the best idealised inchworms, lagged as it is.
    rows = [int(i) for i in order if sc["ok"][i]][: settings.local] or [best]
    rows += rows[:1] * (settings.local - len(rows))
    starts = [local.Start(cos[i], sin[i], float(W[i]), sc["y"][i], int(sc["k"][i]), float(sc["cost"][i])) for i in rows]
    records = [row_of(i) for i in rows]
    worms = _inchworms(base, float(LAG[best]), a_max, lo, hi, H, M if spline else 0, np.zeros_like(sc["y"][best]),
                       search, say)  # fmt: skip
    if worms is not None:
        keys = screen.preference(screen.Gaits(**{f: sc[f] for f in GAIT_FIELDS}), v_min, direction)[rows]
        worm_keys = screen.preference(worms.gaits, v_min, direction)
        better = np.flatnonzero(screen.preferred(worm_keys, keys[0]))
        if better.size:  # else the sinusoids keep every lane
            lanes = screen.best_distinct(np.concatenate([keys, worm_keys[better]]), settings.local)
            starts += [worms.starts[i] for i in better]
            records += [screen.as_inchworm(worms, int(i), float(LAG[best])) for i in better]
            starts, records = [starts[i] for i in lanes], [records[i] for i in lanes]
    if start is not None:
        starts[-1] = local.given_start(start, S, H, M if spline else 0, a_max, lo, hi, sc["y"][rows[-1]])
        records.pop()
    xs, ev, log = local.local_stage(method, base, starts, a_max, v_min, direction, lo, hi, M if spline else 0, search,
                                    say)  # fmt: skip

    # 3. Verification: the baseline, the refined actuations (on the exact bound) and a given start.
    given = [] if start is None else [local.decision(starts[-1], a_max, M if spline else 0)]
    stage = "smoothed" if method == "smoothed" else "local"
    names = ["sinusoid"] + [f"{stage} {lane}" for lane in range(len(xs))] + ["given start"] * len(given)
    checked = settings
    if spline:  # the search's step need not resolve the knots; every figure reported does
        fastest = max([float(W[best])] + [math.exp(float(x[-1])) for x in xs + given])
        checked = local.resolved(_spline(base, np.zeros((S, M)), fastest), settings)
    say(f"verifying {len(names)} candidates on their steady gaits (dt = {checked.dt:g})...")

    def solve(cos, sin, om, control=None, at=checked):
        return _gaits(_fourier(base, cos, sin, om) if control is None else _spline(base, control, om), at)

    half = local.half_step(checked)
    halved = lambda cos, sin, om, control=None: solve(cos, sin, om, control, at=half)

    row = {name: x[best : best + 1] for name, x in sc.items()}
    if spline and search.dt != checked.dt:  # the screen's row is at the search step
        row = solve(cos[best : best + 1], sin[best : best + 1], W[best : best + 1])
    eps = float(jnp.finfo(base.dtype).eps)
    v = local.verify(xs + given, (cos[best], sin[best], float(W[best])), row, names, solve, halved, a_max, v_min,
                     direction, H, M if spline else 0, eps)  # fmt: skip
    g, om_c, strokes, k, feasible, table = v.gaits, v.omega, v.strokes, v.k, v.feasible, v.table
    if search.dt != checked.dt:
        sinusoid = local.verified_baseline(row_of(best), v)
    cos_k, sin_k, control_k = v.waves[k]
    chosen = _fourier(base, cos_k, sin_k, om_c[k]) if control_k is None else _spline(base, control_k, om_c[k])
    gait = (bool(g["ok"][k]), float(g["speed"][k]), float(g["cost"][k]), float(g["radius"][k]), float(g["period"][k]))
    sim = local.simulated(chosen, gait, checked)
    cost_sin = sinusoid["cost_of_transport"] if sinusoid else math.nan
    say(f"verified ({time.perf_counter() - t0:.0f} s): {names[k]}, cost of transport {g['cost'][k]:.6g}")
    return MechanismOptimum(
        v_min=float(v_min), direction=int(direction), a_max=float(a_max), margin=settings.margin, free_omega=free,
        elements=elements, shape="fourier" if control_k is None else "spline", harmonics=H if control_k is None else 0,
        cos=cos_k,
        sin=sin_k, control=control_k, omega=float(om_c[k]), mean_speed_exact=float(g["speed"][k]),
        cost_of_transport_exact=float(g["cost"][k]), gait_period_exact=float(g["period"][k]),
        stable_exact=bool(g["ok"][k]), spectral_radius_exact=float(g["radius"][k]), stroke_exact=strokes[k],
        liftoff_exact=bool(g["liftoff"][k]), min_normal=float(g["min_normal"][k]),
        constraints_exact=dict(speed=bool(v.ok_speed[k]), stroke=bool(v.ok_stroke[k]),
                               no_liftoff=bool(~g["liftoff"][k]), stable=bool(g["ok"][k])),
        feasible_exact=bool(feasible[k]), sinusoid=sinusoid,
        improvement_vs_sinusoid=1 - float(g["cost"][k]) / cost_sin if (feasible[k] and sinusoid) else math.nan,
        **sim, source=names[k], candidates=table,
        history=[{"starts": records, "local": log}], screened=int(A.size),
        evaluations=0 if ev is None else ev.calls,
        runtime_s=time.perf_counter() - t0, dt_exact=checked.dt, mechanism=chosen,
        screen=dict(a=A, omega=W, phase=PHI, lag=LAG, **sc),
    )  # fmt: skip
