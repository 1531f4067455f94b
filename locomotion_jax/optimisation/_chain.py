"""Optimal actuation of a chain of N masses (SPEC §7 and §8): least cost of transport over steady gaits.

Problem, for one [`Chain`][], a required speed $v_\\min > 0$ in the direction $\\sigma = \\pm 1$ and
a stroke limit $a_\\max$, over per-spring Fourier actuations of $H$ harmonics ([`SpringFourier`][])
or per-spring periodic cubic B-splines of $M$ control values ([`Spline`][]) and a common base
frequency, $\\ell_{0,j}(t) = \\bar\\ell_j + s_j(t)$ (the rest-length actuator; under [`InternalForce`][]
$s_j$ is the force between masses $j$ and $j + 1$, and $a_\\max$ bounds it):

$$\\min\\ \\frac{e_d}{\\sigma\\Delta X}\\quad\\text{s.t.}\\quad \\frac{\\sigma\\Delta X}{kT} \\ge v_\\min,\\quad
\\max_t |s_j(t)| \\le a_\\max\\ \\forall j,\\quad \\min_{i,t} N_i \\ge \\text{margin},\\quad\\text{a stable gait},$$

with $\\Delta X$ (the centre of mass, eq. 4 generalised) and $e_d$ (eq. 15 generalised) over the
gait period $kT$ of the periodic orbit of the exact model: whole periods, no window.

Method:

1. **Travelling waves** $a\\sin(\\omega t - j\\varphi)$ (`_chain_screen`): a grid over
   $(a, \\omega, \\varphi)$ solved as steady gaits in batches of one compiled shape, and a zooming
   refinement of the best that meets the requirement. The best one found is the baseline.
   Beside them (rest-length actuators), idealised inchworms (`_starts.tension_waves`: each
   spring's tension a square wave alternating in sign, lagged as the best wave), their steady
   gaits solved as the waves' are: the gaits near the quasi-static floor that no sinusoid
   drives (on the paper's model, the optimum's start).
2. **Local refinement of per-spring harmonics** (`_element_local`, shared with the mechanism
   optimiser; with `ChainOptimiseSettings(shape="spline")` of per-spring periodic splines, started
   from each wave's interpolating spline) from the best distinct starts
   (`_chain_screen.best_distinct`: feasible gaits by cost, then stable ones by speed) among
   the waves and the inchworms that beat the best wave (else the waves keep every lane): a
   monotone L-BFGS descent on an exact penalty, with exact gradients through the periodic orbit
   by the implicit function theorem (`gaits._element_orbit`), the starts in lockstep (one
   batched evaluation per step).
3. **Verification.** Every refined actuation and the baseline wave are solved again by
   [`steady_gait`][] (strict contact, from the relaxed springs, periods 1 to 4); the reported
   optimum is the cheapest that is converged, stable, without lift-off, fast enough and within
   the stroke, so it is never costlier than the baseline. It is cross-checked by a direct
   [`simulate`][] run averaged over whole gait periods once its transient has decayed (as its
   largest Floquet multiplier says). If no candidate is feasible the result says so
   (`feasible_exact = False`).
"""

import math
import time
from typing import Any

import jax.numpy as jnp
import numpy as np

from ..gaits._progress import reporter
from ..model._chain import Chain
from ..model._springwaves import SpringFourier
from . import _chain_screen as screen, _element_local as local
from ._element_optimum import ChainOptimiseSettings, ChainOptimum


def check_inputs(chain: Any, v_min: Any, a_max: Any, direction: Any, harmonics: Any, omega: Any,
                 settings: ChainOptimiseSettings) -> tuple[float, int]:  # fmt: skip
    """Validate a chain requirement; return `(v_min, direction)`.

    **Raises:** `ValueError` naming the argument and its valid range.
    """
    if not isinstance(chain, Chain):
        raise TypeError(f"chain must be a locomotion_jax.Chain, got {type(chain).__name__}.")
    if chain.batch_shape != ():
        raise ValueError(
            f"chain must be a single configuration (batch shape ()), got batch shape {chain.batch_shape}; "
            "optimise one chain at a time (index the batch: chain[i])."
        )
    chain.validate()
    local.check_requirement(v_min, direction, harmonics, omega)
    c = chain.broadcast()
    lbar = np.asarray(c.lbar, np.float64)
    length = chain.actuator.varies_rest_length
    bound = lbar.min() if length else math.inf  # a rest length stays positive; a force has no such bound
    if not (isinstance(a_max, (int, float, np.floating, np.integer)) and np.isfinite(a_max) and 0 < a_max < bound):
        what = f"0 < a_max < min(lbar) = {lbar.min():g}" if length else "0 < a_max < inf (a force bound)"
        raise ValueError(f"a_max must satisfy {what}, got {a_max!r}.")
    m = np.asarray(c.m, np.float64)
    if not (np.isfinite(settings.margin) and 0 <= settings.margin < m.min()):
        raise ValueError(f"margin must satisfy 0 <= margin < min(masses) = {m.min():g}, got {settings.margin!r}.")
    # At rest at the relaxed gaps (l_j = lbar_j) the rest lengths l0_j = lbar_j + s_j with
    # |s_j| <= a_max give f_y,j = -k_j d_j s_j / lbar_j: the worst normal force of mass i has
    # both neighbouring springs' terms against it. A stroke that lifts a mass quasi-statically
    # cannot be run at any frequency. An internal force leaves the rest lengths, and so these
    # loads, alone (the actuator's own split says which signal moves a rest length); its
    # lift-off, a dynamic one, is the gait's normal-force constraint's.
    dl0 = np.asarray(chain.actuator.split(jnp.zeros(lbar.shape), jnp.ones(lbar.shape))[0], np.float64)
    g = np.abs(np.asarray(c.k, np.float64) * dl0 * np.asarray(c.d, np.float64)) / lbar
    load = np.concatenate([g, [0.0]]) + np.concatenate([[0.0], g])
    if np.any(m - a_max * load <= 0):
        a_lift = float(np.min(m / np.where(load > 0, load, np.inf)))
        raise ValueError(
            f"a_max={a_max!r} lifts a mass off at rest (at the relaxed gaps, with every rest length in "
            f"[lbar_j - a_max, lbar_j + a_max]); a_max must be below {a_lift:.4g} (min_i m_i / sum of "
            "k_j |d_j| / lbar_j over the springs of mass i) for this chain."
        )
    return float(v_min), int(direction)


def optimise_chain(chain: Chain, v_min: float, a_max: float, *, direction: int = 1, omega: float | None = None,
                   harmonics: int | None = None, settings: ChainOptimiseSettings | None = None,
                   start: Any = None, method: str = "exact", sweep: Any = None) -> ChainOptimum:  # fmt: skip
    """`optimise(chain, v_min, a_max, ...)`: the method of the module docstring (arguments as there;
    `harmonics`: the Fourier series' length, default 3; a spline search refuses one). `start`: an
    earlier chain optimum ([`_element_local.given_start`][]) that takes the last local lane and is
    a candidate itself. `method="smoothed"`: the local stage on the smoothed model
    (`_element_smoothed`; Fourier series only), verified as the exact method's. `sweep`: an earlier
    optimum's `screen` of this chain (`_chain_screen.from_record`), which then is the screen: its
    waves are not solved again."""
    settings = ChainOptimiseSettings() if settings is None else settings
    if not isinstance(settings, ChainOptimiseSettings):
        raise TypeError(f"settings for a Chain must be a ChainOptimiseSettings, got {type(settings).__name__}.")
    local.check_method(method, settings)
    spline = settings.shape == "spline"
    H = local.family_harmonics(settings, harmonics, 3)  # a spline search screens single-harmonic waves
    speed, direction = check_inputs(chain, v_min, a_max, direction, H, omega, settings)
    t0 = time.perf_counter()
    say = reporter(settings.verbose)
    base = chain.broadcast()
    S, H, M = base.n_masses - 1, int(H), settings.knots
    local.check_start(start, S)
    lo, hi = screen.frequency_range(base, omega, settings)
    free = hi > lo
    # A spline search's knots are resolved in the verification (`local.resolved`), not in the search.
    fastest = base.with_waves(SpringFourier(np.zeros((S, H)), np.zeros((S, H)), hi))
    family = f"the screen's single harmonics ({M} knots are verified at a step that resolves them)" if spline else (
        f"{H} harmonics")  # fmt: skip
    what = "given" if omega is not None else "ChainOptimiseSettings.omega_max times the highest natural frequency"
    local.refuse_steps(fastest, settings, f"optimise: omega = {hi:.6g} with {family}, {what}")
    search = settings.searching()  # the screen's and the local runs' step; the verification's is dt

    # 1. Travelling waves. Progress from the first second: compiling the screen alone takes minutes.
    if sweep is None:
        size = settings.amplitudes * settings.frequencies * settings.phases
        say(f"screening {size} travelling waves, then {settings.zoom_levels} zoom level(s) (compiling the screen: "
            "first call only)...")  # fmt: skip
        sc, best, steps = screen.screen(base, speed, direction, a_max, lo, hi, H, search, say)
        say(f"{len(sc.a)} travelling waves solved ({time.perf_counter() - t0:.0f} s)")
    else:
        sc = screen.from_record(sweep, 2 * S + 1, a_max, lo, hi)
        best, steps = int(screen.rank(sc.gaits, speed, direction)[0]), screen.grid_steps(S, a_max, lo, hi, settings)
        say(f"the given screen: {len(sc.a)} travelling waves, not solved again")
    feas = screen.feasible(sc.gaits, speed, direction)
    baseline = screen.as_dict(sc, best) if feas[best] else None

    # 2. Local refinement of per-spring harmonics (or control values), from the best distinct
    # waves and, where they beat the best wave, the best idealised inchworms, lagged as it is.
    rows = screen.distinct_starts(sc, best, settings.local, speed, direction, steps)
    keys = [screen.preference(sc.gaits, speed, direction)[rows]]
    starts, records = [], [screen.as_dict(sc, i) for i in rows]
    for i in rows:
        cos, sin = screen.wave_coefficients(sc.a[i : i + 1], sc.phi[i : i + 1], S, H)
        starts.append(local.Start(cos[0], sin[0], float(sc.omega[i]), sc.gaits.y[i], int(sc.gaits.k[i]),
                                  float(sc.gaits.cost[i])))  # fmt: skip
    lag = float(sc.phi[best])
    worms = screen.inchworms(base, lag, a_max, lo, hi, H, M if spline else 0, search, say, (speed, direction))
    if worms is not None:
        # Only where one beats the best wave: the waves' lanes are otherwise kept.
        worm_keys = screen.preference(worms.gaits, speed, direction)
        better = np.flatnonzero(screen.preferred(worm_keys, keys[0][0]))
        keys.append(worm_keys[better])
        starts += [worms.starts[i] for i in better]
        records += [screen.as_inchworm(worms, int(i), lag) for i in better]
    lanes = screen.best_distinct(np.concatenate(keys), settings.local)
    starts, records = [starts[i] for i in lanes], [records[i] for i in lanes]
    if start is not None:
        starts[-1] = local.given_start(start, S, H, M if spline else 0, a_max, lo, hi, sc.gaits.y[best])
        records.pop()
    xs, ev, log = local.local_stage(method, base, starts, a_max, speed, direction, lo, hi, M if spline else 0, search,
                                    say)  # fmt: skip

    # 3. Verification of the candidates: the refined actuations, rescaled onto the exact
    # stroke limit (what the line search's tolerance let through), and the baseline wave.
    # A given start is a candidate itself, as its lane's result is.
    given = [] if start is None else [local.decision(starts[-1], a_max, M if spline else 0)]
    stage = "smoothed" if method == "smoothed" else "local"
    names = ["travelling wave"] + [f"{stage} {lane}" for lane in range(len(xs))] + ["given start"] * len(given)
    cos_b, sin_b = screen.wave_coefficients(sc.a[best : best + 1], sc.phi[best : best + 1], S, H)
    checked = settings
    if spline:  # the search's step need not resolve the knots; every figure reported does
        fastest = max([float(sc.omega[best])] + [math.exp(float(x[-1])) for x in xs + given])
        checked = local.resolved(base.with_spline(jnp.zeros((S, M), base.dtype), jnp.asarray(fastest, base.dtype)),
                                 settings)  # fmt: skip
    say(f"verifying {len(names)} candidates on their steady gaits (dt = {checked.dt:g})...")
    solve = lambda cos, sin, om, control=None: screen.solve(base, cos, sin, om, checked, control=control)._asdict()
    half = local.half_step(checked)
    halved = lambda cos, sin, om, control=None: screen.solve(base, cos, sin, om, half, control=control)._asdict()
    row = {name: x[best : best + 1] for name, x in sc.gaits._asdict().items()}
    if spline and search.dt != checked.dt:  # the screen's row is at the search step
        row = solve(cos_b, sin_b, sc.omega[best : best + 1])
    eps = float(jnp.finfo(base.dtype).eps)
    v = local.verify(xs + given, (cos_b[0], sin_b[0], float(sc.omega[best])), row, names, solve, halved, a_max,
                     speed, direction, H, M if spline else 0, eps)  # fmt: skip
    g, om, strokes, k, feasible, table = screen.Gaits(**v.gaits), v.omega, v.strokes, v.k, v.feasible, v.table
    ok_speed, ok_stroke = v.ok_speed, v.ok_stroke
    if search.dt != checked.dt:
        baseline = local.verified_baseline(screen.as_dict(sc, best), v)
    cos_k, sin_k, control_k = v.waves[k]
    if control_k is None:
        chosen = screen.with_actuation(base, cos_k[None], sin_k[None], om[k : k + 1])[0]
    else:
        chosen = base.with_spline(jnp.asarray(control_k, base.dtype), jnp.asarray(om[k], base.dtype))
    gait = (bool(g.ok[k]), float(g.speed[k]), float(g.cost[k]), float(g.radius[k]), float(g.period[k]))
    sim = local.simulated(chosen, gait, checked, start="relaxed")
    say(f"verified ({time.perf_counter() - t0:.0f} s): {names[k]}, cost of transport {g.cost[k]:.6g}")
    wave_cost = baseline["cost_of_transport"] if baseline else math.nan
    return ChainOptimum(
        v_min=speed, direction=direction, a_max=float(a_max), margin=settings.margin,
        harmonics=H if control_k is None else 0, free_omega=free, cos=cos_k, sin=sin_k, omega=float(om[k]),
        lbar=np.asarray(base.lbar, np.float64),
        mean_speed_exact=float(g.speed[k]), cost_of_transport_exact=float(g.cost[k]),
        gait_period_exact=float(g.period[k]), stable_exact=bool(g.ok[k]), spectral_radius_exact=float(g.radius[k]),
        liftoff_exact=bool(g.liftoff[k]), stroke_exact=strokes[k], min_normal=float(g.min_normal[k]),
        constraints_exact=dict(speed=bool(ok_speed[k]), stroke=bool(ok_stroke[k]), no_liftoff=bool(~g.liftoff[k]),
                               stable=bool(g.ok[k])),
        feasible_exact=bool(feasible[k]), travelling_wave=baseline, travelling_wave_cost_of_transport=wave_cost,
        improvement_vs_travelling_wave=1 - float(g.cost[k]) / wave_cost if (feasible[k] and baseline) else math.nan,
        **sim, source=names[k], candidates=table,
        history=[{"starts": records, "local": log}], screened=len(sc.a),
        evaluations=0 if ev is None else ev.calls,
        runtime_s=time.perf_counter() - t0, dt_exact=checked.dt, shape="fourier" if control_k is None else "spline",
        control=control_k, chain=chosen,
        screen=screen.record(sc),
    )  # fmt: skip
