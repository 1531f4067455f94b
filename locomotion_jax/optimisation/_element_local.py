"""The stages that the chain and mechanism optimisers share, after each one's own baseline (travelling
waves of a chain, sinusoids of a mechanism): the local refinement, the verification of the
candidates on their steady gaits (`verify`; the choice among them, `_optimum.choose`, is every
exact optimiser's) and the direct-simulation check of the optimum. A signal per actuated element:
`gaits._element_orbit`.

The refinement (`refine`) runs a monotone descent on an exact penalty per start (`_local.local_run`),
the starts in lockstep (`_lockstep.run_lockstep`): each start runs in its own thread and their
evaluations are batched into one call of the oracle (`_element_orbit.ChainOracle`: periodic
orbit, figures and their exact gradients). The descent takes L-BFGS directions and a backtracking line search that
accepts only a decrease of the merit, so that an iterate never walks into a costlier gait or a
failed orbit. The bound on every signal is kept by radial rescaling of its Fourier coefficients
onto its exact limit (the set $\\{\\max_t |s_j(t)| \\le a_\\max\\}$ is convex and contains 0), or by
clipping a spline's control values (a box); $\\log\\omega$ by clipping.

Both optimisers check the mechanism-free part of their requirement here too (`check_requirement`).
"""

import dataclasses
import math
import time
from collections.abc import Callable, Mapping
from typing import Any, NamedTuple

import jax.numpy as jnp
import numpy as np

from ..dynamics._exact_dynamics import Exact
from ..gaits import _element_orbit as orbit
from ..gaits._orbit import PATIENCE
from ..gaits._select import ratio
from ..model._waveform import Spline
from ..run._resolution import refuse_search, resolved_step
from ._descent import local_step
from ._evaluator import Evaluator
from ._figures import Figures, PENALTY
from ._local import local_run
from ._lockstep import run_lockstep
from ._optimum import choose, steady_at_half_step
from ._shapes import normalise_phase, spline_stroke, SplineShape


def strokes(cos: np.ndarray, sin: np.ndarray) -> np.ndarray:
    """Exact $\\max_\\phi |s_j(\\phi)|$ per spring (`cos`, `sin`: `(S, H)`): the largest value on a
    grid of $64H + 64$ phases, polished by Newton's method on $s_j' = 0$ within its grid cell
    (as [`_constraints.stroke`][locomotion_jax.optimisation._constraints.stroke], on the host)."""
    S, H = cos.shape
    m = 64 * H + 64
    h = 2 * np.pi / m
    n = np.arange(1, H + 1)
    grid = np.arange(m) * h
    vals = cos @ np.cos(np.outer(n, grid)) + sin @ np.sin(np.outer(n, grid))
    j = np.argmax(np.abs(vals), axis=1)
    phi = grid[j]
    best = np.abs(vals[np.arange(S), j])
    for _ in range(4):
        c, s = np.cos(np.outer(phi, n)), np.sin(np.outer(phi, n))  # one phase per spring
        d1 = (n * (sin * c - cos * s)).sum(1)
        d2 = -(n * n * (cos * c + sin * s)).sum(1)
        phi = phi + np.clip(np.where(d2 != 0, -d1 / np.where(d2 != 0, d2, 1), 0), -h, h)
        best = np.maximum(best, np.abs((cos * np.cos(np.outer(phi, n)) + sin * np.sin(np.outer(phi, n))).sum(1)))
    return best


def unpack(theta: np.ndarray, springs: int, harmonics: int) -> tuple[np.ndarray, np.ndarray, float]:
    """Decision vector -> `(cos, sin)` in units of $a_\\max$ and $\\omega$."""
    c, s = orbit.coefficients(jnp.asarray(theta), springs, harmonics)
    return np.asarray(c), np.asarray(s), float(np.exp(theta[-1]))


def pack(cos: np.ndarray, sin: np.ndarray, omega: float) -> np.ndarray:
    """`(cos, sin)` (units of $a_\\max$, $A_{0,1} = 0$) and $\\omega$ -> decision vector."""
    return np.concatenate([np.ravel(cos)[1:], np.ravel(sin), [math.log(omega)]])


def project(theta: np.ndarray, springs: int, harmonics: int, log_lo: float, log_hi: float) -> np.ndarray:
    """Every spring's coefficients rescaled radially onto stroke <= 1 (units of $a_\\max$), $\\log\\omega$ clipped."""
    c, s, w = unpack(theta, springs, harmonics)
    scale = 1 / np.maximum(strokes(c, s), 1.0)
    return pack(c * scale[:, None], s * scale[:, None], math.exp(float(np.clip(math.log(w), log_lo, log_hi))))


def on_bound(x: np.ndarray, S: int, H: int, a_max: float) -> tuple[np.ndarray, np.ndarray, float]:
    """A refined point's coefficients and frequency, each spring's stroke rescaled onto the bound
    `a_max` where it exceeds it (what the line search's tolerance let through)."""
    c, s, w = unpack(x, S, H)
    scale = 1 / np.maximum(strokes(c, s), 1.0)
    return a_max * c * scale[:, None], a_max * s * scale[:, None], w


# -- splines: decision vectors (each element's control values in units of a_max, then log omega) --


def spline_start(cos: np.ndarray, sin: np.ndarray, omega: float, a_max: float, knots: int) -> np.ndarray:
    """The decision vector of the splines that interpolate each element's Fourier signal (`cos`,
    `sin`: `(S, H)`, absolute units) at the knots ([`SplineShape.fit`][]), control values clipped
    to the bound."""
    grid = 64 * knots
    phase = np.arange(grid) * 2 * np.pi / grid
    n = np.arange(1, cos.shape[1] + 1)
    values = (cos @ np.cos(np.outer(n, phase)) + sin @ np.sin(np.outer(n, phase))) / a_max
    shape = SplineShape(knots=knots)
    return np.concatenate([*(shape.fit(v, omega)[:-1] for v in values), [math.log(omega)]])


def spline_project(theta: np.ndarray, log_lo: float, log_hi: float) -> np.ndarray:
    """Control values clipped to the box $|c| \\le 1$ (units of $a_\\max$), $\\log\\omega$ to its range."""
    out = np.array(theta, float)
    out[:-1] = np.clip(out[:-1], -1.0, 1.0)
    out[-1] = np.clip(out[-1], log_lo, log_hi)
    return out


def spline_strokes(control: np.ndarray) -> np.ndarray:
    """Exact $\\max_\\phi |s_j - \\bar s_j|$ per element of the control values `(S, M)`."""
    return np.array([spline_stroke(row) for row in control])


def refuse_steps(mechanism: Any, settings: Any, what: str) -> None:
    """Refuse `settings.dt` and `settings.search_dt` (where given) where either does not resolve
    `mechanism` (one configuration, the one the search must resolve), the error ending with `what`
    and the field's name."""
    for name in ("dt", "search_dt"):
        step = getattr(settings, name)
        if step is not None:
            refuse_search(mechanism, None, step, f"({what}; the step is {type(settings).__name__}.{name}.)")


def resolved(fastest: Any, settings: Any) -> Any:
    """The verification's settings of a spline search: `settings`, with `dt` refined where it does
    not resolve `fastest` (one configuration driven by splines of the search's knots at the
    highest of the candidates' frequencies; the step the resolution guard suggests, `resolved_step`).
    The search steps at `search_dt` or `dt` whatever its knots' spacing: its figures only steer."""
    dt = resolved_step(fastest, None, settings.dt)
    return settings if dt == settings.dt else dataclasses.replace(settings, dt=dt, search_dt=None)


def half_step(settings: Any) -> Any:
    """`settings` at half its `dt` (the verification's convergence check, [`verify`][])."""
    return dataclasses.replace(settings, dt=settings.dt / 2, search_dt=None)


def check_requirement(v_min: Any, direction: Any, harmonics: Any, omega: Any) -> None:
    """The checks of a chain's and a mechanism's requirement that do not depend on the mechanism:
    `harmonics` an integer >= 1, `direction` +1 or -1, `v_min` a finite speed > 0 in `direction`,
    `omega` `None` (optimised) or a finite frequency > 0.

    **Raises:** `ValueError` naming the argument and its valid range."""
    if isinstance(harmonics, bool) or not isinstance(harmonics, (int, np.integer)) or harmonics < 1:
        raise ValueError(f"harmonics must be an integer >= 1, got {harmonics!r}.")
    if direction not in (1, -1):
        raise ValueError(f"direction must be +1 (forward) or -1 (backward), got {direction!r}.")
    if not (isinstance(v_min, (int, float, np.floating, np.integer)) and np.isfinite(v_min) and v_min > 0):
        raise ValueError(f"v_min must be a finite speed > 0 (the required mean speed in `direction`), got {v_min!r}.")
    if omega is not None and not (np.isfinite(omega) and omega > 0):
        raise ValueError(f"omega must be a finite number > 0 (or None to optimise it), got {omega!r}.")


def family_harmonics(settings: Any, harmonics: int | None, default: int) -> int:
    """The harmonics of a chain's or a mechanism's search: `harmonics` (`default` if `None`) for a
    Fourier search; 1 for a spline search (`settings.shape == "spline"`: its baseline screens single
    harmonics), which refuses a given `harmonics`.

    **Raises:** `ValueError` naming `harmonics` and the settings' `knots`."""
    if settings.shape != "spline":
        return default if harmonics is None else harmonics
    if harmonics is not None:
        name = type(settings).__name__
        raise ValueError(f"harmonics applies to Fourier series; {name}(shape='spline') searches splines of "
                         f"{name}.knots control values (got harmonics={harmonics!r}).")  # fmt: skip
    return 1


class Start(NamedTuple):
    """A start of the refinement: the Fourier coefficients `(S, H)` of every actuated signal
    (absolute units) and the base frequency of a baseline actuation, and its steady gait (the
    section state `y`, the gait period `k` in actuation periods, the cost of transport).

    A spline search starts from `control` `(S, knots)` (absolute units) where one is given, else
    from the splines that interpolate the Fourier signals. `fresh`: the steady gait is not known
    (`y` only gives the state's shape); the lane's first warm start is the state after a transient
    of `settings.transient` periods from rest."""

    cos: np.ndarray
    sin: np.ndarray
    omega: float
    y: np.ndarray
    k: int
    cost: float
    control: np.ndarray | None = None
    fresh: bool = False


def decision(start: Start, a_max: float, knots: int) -> np.ndarray:
    """The decision vector of `start` in a search of Fourier series (`knots` 0) or of splines of
    `knots` control values."""
    if not knots:
        return pack(start.cos / a_max, start.sin / a_max, start.omega)
    if start.control is not None:
        return spline_project(np.r_[np.ravel(start.control) / a_max, math.log(start.omega)], -np.inf, np.inf)
    return spline_start(start.cos, start.sin, start.omega, a_max, knots)


def signals_of(start: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, float]:
    """`(cos, sin, control, omega)` of a chain's or a mechanism's `start=`: its optimum, or that
    optimum's `to_dict()` (e.g. read back from the JSON of `optimize --json`).

    **Raises:** `TypeError` for anything else; `ValueError` for a dict whose signals are not
    `(S, H)` coefficients or `(S, M)` control values."""
    from ._element_optimum import ElementOptimum

    if isinstance(start, ElementOptimum):
        return start.cos, start.sin, start.control, float(start.omega)
    if isinstance(start, Mapping) and {"cos", "sin", "control", "omega"} <= set(start):
        cos, sin = np.asarray(start["cos"], np.float64), np.asarray(start["sin"], np.float64)
        control = None if start["control"] is None else np.asarray(start["control"], np.float64)
        if cos.ndim != 2 or sin.shape != cos.shape or (control is not None and control.ndim != 2):
            raise ValueError(
                "start: a chain's or a mechanism's optimum has per-signal rows, cos and sin of shape (S, H) and "
                f"control of shape (S, M) or None; got cos {cos.shape}, sin {sin.shape}, control "
                f"{None if control is None else control.shape} (a result of the paper's model takes its own start=)."
            )
        if control is not None and control.shape[0] != cos.shape[0]:
            raise ValueError(f"start: control has {control.shape[0]} rows and cos {cos.shape[0]}.")
        return cos, sin, control, float(start["omega"])
    raise TypeError(
        "start must be the result of an earlier optimise call of a Chain or a Mechanism (a ChainOptimum or "
        f"MechanismOptimum, or its to_dict()) with the same actuated elements, got {type(start).__name__}."
    )


def check_start(start: Any, S: int) -> None:
    """Check a chain's or a mechanism's `start=` (`None`, or an optimum of `S` actuated signals).

    **Raises:** as [`signals_of`][]; `ValueError` where its number of signals is not `S`."""
    if start is not None:
        _checked_signals(start, S)


def _checked_signals(start: Any, S: int) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, float]:
    """[`signals_of`][] `start`, refused where its number of signals is not `S`."""
    signals = signals_of(start)
    if signals[0].shape[0] != S:
        raise ValueError(f"start: an optimum of {signals[0].shape[0]} actuated signals; this search has {S}.")
    return signals


def given_start(start: Any, S: int, harmonics: int, knots: int, a_max: float, lo: float, hi: float,
                state: np.ndarray) -> Start:  # fmt: skip
    """The [`Start`][] of `start` (continuation: an earlier chain's or mechanism's optimum or its
    `to_dict()`, at a nearby requirement or of a nearby mechanism), `fresh` (`state`: a section state of the search's
    shape), its signals in this search's family, within its bounds:

    - `cos`, `sin` `(S, harmonics)`, absolute units: the first `harmonics` harmonics of its signals
      (exact for a Fourier series of at most as many), the time origin moved so that the first
      signal's first cosine coefficient is 0 (the decision vector leaves it out; the gait is the
      same), each signal rescaled radially onto the stroke bound `a_max` where it exceeds it;
    - `control` `(S, knots)` for a spline search (`knots > 0`): the splines that interpolate its
      signals at the knots (the same control values for a spline of as many knots), clipped to
      the bound; `None` for a Fourier search;
    - its base frequency clipped to `[lo, hi]`.

    **Raises:** as [`check_start`][]."""
    given_cos, given_sin, given_control, given_omega = _checked_signals(start, S)
    grid = 64 * max(knots, 16, 0 if given_control is None else given_control.shape[-1])
    phase = np.arange(grid) * 2 * np.pi / grid
    if given_control is None:
        n = np.arange(1, given_cos.shape[-1] + 1)
        values = given_cos @ np.cos(np.outer(n, phase)) + given_sin @ np.sin(np.outer(n, phase))
    else:
        spline = SplineShape(knots=given_control.shape[-1])
        values = np.stack([spline.sample(Spline(jnp.asarray(c), 1.0, 0.0), grid) for c in given_control])
    return sampled_start(values, given_omega, harmonics, knots, a_max, lo, hi, np.zeros_like(state))


def sampled_start(values: np.ndarray, omega: float, harmonics: int, knots: int, a_max: float, lo: float, hi: float,
                  state: np.ndarray) -> Start:  # fmt: skip
    """The `fresh` [`Start`][] of signals sampled at equal phases over one period (`values` `(S, G)`,
    absolute units, about their means) and base frequency `omega`, in a search's family as
    [`given_start`][] describes (`cos`, `sin` of `harmonics` harmonics, rescaled onto `a_max`;
    `control` of `knots` values for a spline search; `omega` clipped to `[lo, hi]`); `state`: a
    section state of the search's shape."""
    omega = float(np.clip(omega, lo, hi))
    grid = values.shape[-1]
    c = np.fft.rfft(values, axis=-1) / grid
    cos, sin = 2 * c.real[:, 1 : harmonics + 1], -2 * c.imag[:, 1 : harmonics + 1]
    cos, sin = normalise_phase(cos, sin)
    scale = 1 / np.maximum(strokes(cos, sin) / a_max, 1.0)
    cos, sin = cos * scale[:, None], sin * scale[:, None]
    control = None
    if knots:
        fit = SplineShape(knots=knots)
        control = a_max * np.stack([fit.fit(v / a_max, omega)[:-1] for v in values])
    return Start(cos, sin, omega, state, 1, math.nan, control, fresh=True)


def check_method(method: Any, settings: Any) -> None:
    """Refuse a `method` of `optimise` other than `"exact"` and `"smoothed"`, and the smoothed method
    with a spline search (it optimises Fourier series).

    **Raises:** `ValueError` naming `method` (or the settings' `shape`) and the valid values."""
    if method not in ("exact", "smoothed"):
        raise ValueError(f"method must be 'exact' or 'smoothed', got {method!r}.")
    if method == "smoothed" and settings.shape != "fourier":
        raise ValueError(f"method='smoothed' refines Fourier series: {type(settings).__name__}.shape must be "
                         f"'fourier', got {settings.shape!r}.")  # fmt: skip


def local_stage(method: str, base: Any, starts: list[Start], a_max: float, v_min: float, direction: int, lo: float,
                hi: float, knots: int, settings: Any, say: Callable[[str], None],
                ) -> tuple[list[np.ndarray], Evaluator | None, list[dict]]:  # fmt: skip
    """The local stage of `method`: [`refine`][] on the exact model (`"exact"`), or on the smoothed
    model (`"smoothed"`, `_element_smoothed.refine`, which has no orbit oracle: `None` in its place)."""
    if method == "smoothed":
        from ._element_smoothed import refine as refine_smoothed

        xs, log = refine_smoothed(base, starts, a_max, v_min, direction, lo, hi, settings, say)
        return xs, None, log
    return refine(base, starts, a_max, v_min, direction, lo, hi, knots, settings, say)


def refine(base: Any, starts: list[Start], a_max: float, v_min: float, direction: int, lo: float, hi: float,
           knots: int, settings: Any, say: Callable[[str], None],
           ) -> tuple[list[np.ndarray], Evaluator, list[dict]]:  # fmt: skip
    """Refine `starts` (one per lane, `settings.local` of them) locally in lockstep: Fourier series
    of the starts' harmonics, or with `knots > 0` splines of `knots` control values per signal
    (started from each start's interpolating spline), base frequency in `[lo, hi]`. `settings`:
    a chain's or a mechanism's optimiser settings (the fields of the refinement and the orbit
    solve). Returns each lane's result (the cheapest point that met every constraint, else
    the one with the smallest violation), the evaluator (its oracle and warm starts) and the
    descent's log."""
    S, H = starts[0].cos.shape
    dtype = base.dtype
    steps = int(math.ceil(2 * math.pi / lo / settings.dt)) * 3 + 200
    oracle = orbit.ChainOracle(
        chain=base, a_max=jnp.asarray(a_max, dtype), max_steps=jnp.asarray(steps, jnp.int32),
        tol=jnp.asarray(settings.newton_tol if jnp.finfo(dtype).bits == 64 else 1e-5, dtype), harmonics=H,
        contact="paper",  # iterates past a lift-off stay defined; the margin keeps N > 0
        dt=settings.dt, max_iter=settings.newton_iter, knots=knots, patience=jnp.asarray(PATIENCE, jnp.int32),
    )  # fmt: skip
    v_target = v_min * (1 + settings.speed_slack)
    free = hi > lo
    make = lambda lane, th, orb, k: Figures(th, orb, v_target, k, direction, settings.margin, free)
    ev = Evaluator(oracle, settings.local, settings.transient, make)
    x0 = [decision(st, a_max, knots) for st in starts]
    for lane, st in enumerate(starts):
        ev.y[lane], ev.k[lane] = st.y, int(max(st.k, 1))
    fresh = np.array([st.fresh for st in starts])
    if fresh.any():
        y = oracle.transient(jnp.asarray(np.stack(x0), dtype), jnp.asarray(np.stack([st.y for st in starts]), dtype),
                             jnp.asarray(fresh), jnp.asarray(settings.transient, jnp.int32))  # fmt: skip
        for lane in np.flatnonzero(fresh):
            ev.y[int(lane)], ev.k[int(lane)] = np.asarray(y[lane]), 1
    bounds = (math.log(lo), math.log(hi))
    if knots:
        proj = lambda x: spline_project(x, *bounds)
        stroke_ok = lambda x: float(np.max(spline_strokes(x[:-1].reshape(S, knots)))) <= 1 + 1e-9
    else:
        proj = lambda x: project(x, S, H, *bounds)
        stroke_ok = lambda x: float(np.max(strokes(*unpack(x, S, H)[:2]))) <= 1 + 1e-9
    costs = [st.cost for st in starts if np.isfinite(st.cost)]
    rho = PENALTY * max(1.0, max(costs, default=1.0))
    log: list[dict] = []

    def search(at, x):
        local_step(settings.local_method, x, at, proj, settings.max_iter, settings.trust_radius, rho, True,
                   settings.stall_rtol)  # fmt: skip
        return {"message": settings.local_method}

    solvers = [local_run(x, search, stroke_ok, log) for x in x0]
    say(f"refining {len(solvers)} starts locally, in lockstep (compiling the orbit solver: first call only)...")
    t0 = time.perf_counter()
    xs = run_lockstep(solvers, ev)
    say(f"local refinement done ({time.perf_counter() - t0:.0f} s, {ev.calls} batched evaluations)")
    return xs, ev, log


class Verified(NamedTuple):
    """The candidates' steady gaits (the baseline first, then one per local run; [`verify`][]) and
    the choice among them (`_optimum.choose`)."""

    gaits: dict[str, np.ndarray]  # each figure of the gait solver, one row per candidate
    omega: np.ndarray
    strokes: np.ndarray  # (candidates, S): each signal's exact largest excursion
    waves: list[tuple[np.ndarray, np.ndarray, np.ndarray | None]]  # cos, sin (absolute units), control or None
    k: int  # the reported candidate
    feasible: np.ndarray
    ok_speed: np.ndarray
    ok_stroke: np.ndarray
    table: list[dict]  # each candidate's figures, as the optimum's `candidates`


def verify(xs: list[np.ndarray], baseline: tuple[np.ndarray, np.ndarray, float], baseline_gait: dict[str, np.ndarray],
           names: list[str], solve: Callable[..., dict[str, np.ndarray]], halved: Callable[..., dict[str, np.ndarray]],
           a_max: float, v_min: float, direction: int, harmonics: int, knots: int, eps: float) -> Verified:  # fmt: skip
    """The verification of a chain's or a mechanism's candidates: the baseline (`baseline`: its
    Fourier coefficients `(S, H)` in absolute units and its frequency; `baseline_gait`: its steady
    gait's row, each figure of shape `(1, ...)`) and the local runs' points `xs`, rescaled onto the
    exact bound (what the line search's tolerance let through). `solve(cos, sin, omega, control=None)`:
    the steady gaits (strict contact, relaxed start) of a batch of Fourier series, or of splines of
    `knots` control values (absolute units), as host arrays with at least `ok` (converged, stable,
    no lift-off), `speed`, `cost` and `radius` (the largest Floquet multiplier modulus: of the
    feasible candidates as cheap as the cheapest, `_optimum.choose` reports the most stable); a
    `liftoff` figure goes into the table too. The baseline's gait
    is not solved again in a spline search (its row is the screen's). `halved`: `solve` at half the
    step; every candidate's gait is solved there too, and counts as `ok` only where it agrees
    (`_optimum.steady_at_half_step`, as the paper's optimiser's verification)."""
    cos_b, sin_b, om_b = baseline
    S = cos_b.shape[0]
    waves: list[tuple[np.ndarray, np.ndarray, np.ndarray | None]]
    if knots:
        control = np.stack([a_max * spline_project(x, -np.inf, np.inf)[:-1].reshape(S, knots) for x in xs])
        om = np.array([om_b] + [math.exp(float(x[-1])) for x in xs])
        refined = solve(None, None, om[1:], control=control)
        g = {name: np.concatenate([baseline_gait[name], refined[name]]) for name in refined}
        half_b, half_r = halved(cos_b[None], sin_b[None], om[:1]), halved(None, None, om[1:], control=control)
        half = {name: np.concatenate([half_b[name], half_r[name]]) for name in ("ok", "speed", "cost")}
        strokes_ = np.concatenate([strokes(cos_b, sin_b)[None], [spline_strokes(c) for c in control]])
        empty = np.zeros((S, 0))
        waves = [(cos_b, sin_b, None), *((empty, empty, c) for c in control)]
    else:
        coefs = [(cos_b, sin_b, om_b)] + [on_bound(x, S, harmonics, a_max) for x in xs]
        om = np.array([w for _, _, w in coefs])
        cos, sin = np.stack([c for c, _, _ in coefs]), np.stack([s for _, s, _ in coefs])
        g, half = solve(cos, sin, om), halved(cos, sin, om)
        strokes_ = np.stack([strokes(c, s) for c, s in zip(cos, sin)])
        waves = [(c, s, None) for c, s in zip(cos, sin)]
    full_ok, full_v, full_c = (np.asarray(g[n], float) for n in ("ok", "speed", "cost"))
    half_ok, half_v, half_c = (np.asarray(half[n], float) for n in ("ok", "speed", "cost"))
    g = dict(g, ok=steady_at_half_step(full_ok > 0, full_v, full_c, half_ok > 0, half_v, half_c))
    ok = g["ok"]
    k, feasible, ok_speed, ok_stroke = choose(ok, g["speed"], g["cost"], strokes_.max(axis=1), v_min, direction,
                                              a_max, eps, np.asarray(g["radius"], np.float64))  # fmt: skip
    lift = lambda i: {"liftoff_exact": bool(g["liftoff"][i])} if "liftoff" in g else {}
    table = [dict(candidate=names[i], omega=float(om[i]), mean_speed_exact=float(g["speed"][i]),
                  cost_of_transport_exact=float(g["cost"][i]), stable_exact=bool(ok[i]),
                  half_step_speed=float(half["speed"][i]), half_step_cost=float(half["cost"][i]), **lift(i),
                  stroke=float(strokes_[i].max()), feasible_exact=bool(feasible[i]))
             for i in range(len(names))]  # fmt: skip
    return Verified(g, om, strokes_, waves, k, feasible, ok_speed, ok_stroke, table)


def verified_baseline(found: dict[str, Any], v: Verified) -> dict[str, Any] | None:
    """The baseline `found` by a screen at a coarser search step, with the figures the verification
    solved at `dt` (its row 0; and the gait's period multiple `k` where `found` has one), or `None`
    where it is not feasible there."""
    if not v.feasible[0]:
        return None
    g = v.gaits
    return (
        found
        | dict(mean_speed=float(g["speed"][0]), cost_of_transport=float(g["cost"][0]))
        | ({"k": int(g["k"][0])} if "k" in found else {})
    )


def screen_rows(given: Any, fields: tuple[str, ...], n_red: int, a_max: float, lo: float, hi: float,
                kind: tuple[str, str], state: str) -> dict[str, np.ndarray]:  # fmt: skip
    """The rows of an earlier optimum's `screen` (`optimise(..., sweep=)`; read back from JSON, NaN
    as `None`) that keep within the bound `a_max` and the frequency range `[lo, hi]` (to 1e-12
    relative): each of `fields` (`a`, `omega`, ... and the gait's figures, `y` the section state of
    `n_red` numbers, described as `state`) as an array over them. `kind`: the screen's mechanism and
    signal, e.g. `("chain", "wave")`, for the messages.

    **Raises:** `ValueError` naming `sweep` where a field is missing or of another shape, or where
    no row is left."""
    mechanism, signal = kind
    if not isinstance(given, Mapping) or not set(fields) <= set(given):
        raise ValueError(
            f"sweep: an earlier {mechanism} optimum's screen (opt.screen), a dict with {', '.join(fields)}."
        )
    kinds = dict(ok=bool, liftoff=bool, k=np.int32)
    rows = {key: np.array(given[key], dtype=kinds.get(key, np.float64)) for key in fields}
    n = rows["a"].shape
    if len(n) != 1 or any(rows[key].shape[:1] != n for key in fields) or rows["y"].shape != n + (n_red,):
        raise ValueError(f"sweep: the screen's fields must have one row per {signal}, and y {n_red} numbers per row "
                         f"({state}); got y of shape {rows['y'].shape}.")  # fmt: skip
    tol = 1 + 1e-12
    keep = (rows["a"] <= a_max * tol) & (rows["omega"] >= lo / tol) & (rows["omega"] <= hi * tol)
    if not keep.any():
        raise ValueError(f"sweep: no {signal} of the screen has a <= a_max = {a_max:g} and omega in "
                         f"[{lo:.6g}, {hi:.6g}].")  # fmt: skip
    return {key: value[keep] for key, value in rows.items()}


AVERAGED = 12
"""Gait periods the direct simulation check averages over: a multiple of every period from 1 to
`RECUR` gait periods, so that a motion of any of them is averaged over whole periods of its own."""

RECUR = 4
"""The longest recurrence, in gait periods, that the direct simulation check looks for."""


def recurrence(states: np.ndarray, tol: float) -> int:
    """The smallest `p <= RECUR` such that the section states `states` (one row per gait period)
    recur every `p` rows to `tol` relative to their largest value; 0 if none does."""
    scale = 1.0 + float(np.abs(states).max())
    for p in range(1, RECUR + 1):
        if float(np.abs(states[p:] - states[:-p]).max()) <= tol * scale:
            return p
    return 0


def simulated(model: Any, gait: tuple[bool, float, float, float, float], settings: Any, periods: int | None = None,
              **run: Any) -> dict:  # fmt: skip
    """The optimum's fields of a direct simulation of `model` (`run`: `simulate`'s `start`,
    `initial` or `waveform`), whose steady gait `gait` is `(stable, mean speed, cost of transport,
    largest multiplier modulus, period)`.

    It runs for enough gait periods `n` for the slowest Floquet mode to decay to `settings.check_tol`
    (within `settings.check_periods`; `periods` where given), then `AVERAGED` more: the mean speed
    and cost of transport over those, their larger relative difference from the gait's, and the
    recurrence of the states at the gait-period sections ([`recurrence`][]) to
    $\\sqrt{\\text{check\\_tol}}$, or to 100 machine epsilons where that is larger (float32:
    1.2e-5). A recurrence other than 1 is a motion other than the gait: a second attractor, reached
    from this start. NaN and 0 where the gait is not stable or the run stopped. A run that dissipates
    nothing does not move (its distance is rounding: `gaits._select.ratio`): its cost is infinite,
    and the agreement with a gait that does not move either is NaN.

    It steps at `settings.dt`, or finer where the resolution guard asks for it (`resolved_step`; the
    verification of a spline whose knots lie closer than 4 steps checks its resolution by a
    convergence study instead, and is not guarded): its agreement then includes that change of step."""
    from ..run._simulate import simulate

    ok, speed, cost, rho, period = gait
    lo, hi = settings.check_periods
    n = hi if not (0 < rho < 1) else int(np.clip(math.ceil(math.log(settings.check_tol) / math.log(rho)), lo, hi))
    n = n if periods is None else periods
    out = dict(mean_speed_simulated=math.nan, cost_of_transport_simulated=math.nan, simulation_agreement=math.nan,
               simulated_periods=n, simulated_recurrence=0)  # fmt: skip
    if not ok:
        return out | dict(simulated_periods=0)
    t = (n + np.arange(AVERAGED + 1)) * period
    dt = resolved_step(model, run.get("waveform"), settings.dt)
    traj = simulate(model, float(t[-1]), t, dynamics=Exact(dt=dt), contact="strict", **run)
    if not np.all(np.asarray(traj.valid)):
        return out
    X, ed = np.asarray(traj.X, np.float64), np.asarray(traj.e_d, np.float64)
    eps = float(np.finfo(np.asarray(traj.x).dtype).eps)
    x, v = np.asarray(traj.x, np.float64), np.asarray(traj.v, np.float64)
    dX = X[-1] - X[0]
    # A run or a gait that does not move: an infinite (or NaN) cost, and an agreement of NaN.
    with np.errstate(divide="ignore", invalid="ignore"):
        speed_s, cost_s = np.float64(dX / (t[-1] - t[0])), np.float64(ratio(ed[-1] - ed[0], abs(dX), np.array(True)))
        agreement = float(np.maximum(abs(speed_s / speed - 1), abs(cost_s / cost - 1)))
    states = np.concatenate([x[:, 1:] - x[:, :1], v], axis=1)  # gaps and velocities: invariant under travel
    tol = max(math.sqrt(settings.check_tol), 100 * eps)
    return out | dict(mean_speed_simulated=float(speed_s), cost_of_transport_simulated=float(cost_s),
                      simulation_agreement=agreement, simulated_recurrence=recurrence(states, tol))  # fmt: skip
