"""The exact optimiser: least cost of transport over steady gaits of the exact model (SPEC §7).

Problem, for a required speed $v_\\min$ in the direction $\\sigma = \\pm 1$ and a stroke limit
$a_\\max$, over a family of stroke shapes (`_shapes`: a periodic cubic spline of $M$ control
values, the default, or a Fourier series of $N$ harmonics) and a free (or fixed) base frequency:

$$\\min_\\theta\\ \\frac{e_d}{\\sigma\\Delta X}\\quad\\text{s.t.}\\quad
\\frac{\\sigma\\Delta X}{T} \\ge v_\\min,\\quad \\min_t N_{1,2} \\ge \\text{margin},\\quad
\\max_t |\\ell_0(t) - \\bar\\ell| \\le a_\\max,$$

where $\\Delta X$, $e_d$ and $\\min N$ are those of one period $T = 2\\pi/\\omega$ of the
periodic orbit (the steady gait), with their gradients by the implicit function theorem
(`_orbit`): no smoothing, no transient inside the optimisation, whole periods.

Method:

- **Starts** (`_starts`), each fitted by the shape family: sinusoids of several amplitudes,
  sinusoids with a third harmonic, saw-tooth ramps of both senses and random waveforms, over
  log-spaced base frequencies; the rest lengths of idealised inchworm gaits whose spring
  tension alternates in sign (the fast gaits near the quasi-static floor, which a sinusoid
  cannot drive); the best sinusoid of the baseline; and an optional given start
  (continuation in $v_\\min$: the optimum of a nearby requirement), which is always refined.
  Each is run from the relaxed spring for a transient, its orbit solved, and the starts are
  ranked by cost of transport with a penalty on the constraint violations; the best few
  are refined.
- **Local refinement** by a monotone descent on an exact penalty (`_descent`: L-BFGS
  directions, a backtracking line search that accepts only a decrease, so that an iterate
  never walks into a costlier gait or a failed orbit; the first step is bounded so that
  it stays within the reach of the warm-started Newton solve of the orbit), or by
  `scipy.optimize.minimize` (`trust-constr`, `SLSQP`): exact values, exact gradients.
  The stroke is a convex set: the descent keeps it by the family's projection (clipping the
  spline's control values, radial rescaling of a Fourier series), the scipy methods take it
  as constraints (the control values, or the Fourier series' maxima within fixed phase
  windows, `_shapes.StrokePeaks`). The local solvers run in lockstep, so that each of their
  evaluations is one batched (vmapped) call of the engine.
- **Verification.** Every refined waveform (and the best and the given start) is solved again by
  [`steady_gait`][] under the strict contact reading from the relaxed spring (periods 1 to 4
  tried, a period given up where Newton's iterations cycle, stability from the Floquet
  multipliers); the reported optimum is the cheapest one that is converged, stable, without
  lift-off, at least as fast as required and within the stroke. The runners-up of each local run (earlier points of its
  descent) are solved in a second batch, only where their run's waveform fails or where the
  descent found them cheaper than the cheapest that passed.
- **Two steps** (optional): the screen and the local runs may step the exact engine at a coarser
  `search_dt` than the sinusoid baseline and the verification (`dt`): the search's figures only
  rank and steer, and every figure reported is the verification's.
- **Compilation** of the orbit oracle's and the verification's programs starts in a background
  thread before the sinusoid baseline ([`Precompile`][]), so that on a machine of two cores or
  more it overlaps the baseline's and the local runs' work.
"""

import dataclasses
import math
import threading
import time
from functools import partial
from typing import Any, cast

import jax
import jax.numpy as jnp
import numpy as np
import scipy.optimize

from ..gaits import _orbit as orbit
from ..gaits._gait import GaitStatus, paper_gait
from ..gaits._progress import reporter
from ..model._chain import Chain
from ..model._params import Params
from ..model._waveform import AbstractWaveform
from . import _element_local as local, _pareto as pareto
from ._descent import local_step, METHODS
from ._evaluator import Evaluator
from ._figures import Figures, PENALTY
from ._local import local_run
from ._lockstep import run_lockstep
from ._optimum import choose, ExactSettings, Optimum, start_waveform, steady_at_half_step, verified, waveform_of
from ._shapes import AbstractShape
from ._starts import start_shapes, tension_starts, tension_waves


class _Bad:
    """A point where the orbit could not be solved: a cost far above the last good one, so
    that the trust region shrinks, and the last good gradients, so that the quasi-Newton
    update skips it (a zero difference of gradients) instead of learning from it."""

    def __init__(self, theta, last: "Figures | None"):
        self.ok = False
        self.cot = math.inf
        self.f = (last.f if last is not None else 0.0) + 1e3
        self.df = last.df if last is not None else np.zeros_like(theta)
        self.c = last.c - 1.0 if last is not None else np.array([-1.0, -1.0])
        self.dc = last.dc if last is not None else np.zeros((2, len(theta)))


def _descent(x0, shape: AbstractShape, bounds, settings: ExactSettings, max_iter: int, at) -> None:
    """[`descent`][locomotion_jax.optimisation._descent.descent] (`local_method="descent"`) or
    [`sqp_descent`][locomotion_jax.optimisation._descent.sqp_descent] (`"sqp"`) on the exact
    penalty $\\phi = f + \\rho\\,(\\max(0, -c_v) + \\max(0, -c_N))$, the stroke kept by the
    shape family's projection onto its exact limit and $\\omega$ clipped to its bounds."""

    def project(x):
        x = shape.project(x)
        x[-1] = np.clip(x[-1], bounds.lb[-1], bounds.ub[-1])
        return x

    local_step(settings.local_method, x0, at, project, max_iter, settings.trust_radius, PENALTY,
               stall_rtol=settings.stall_rtol)  # fmt: skip


def _local_solver(x0, shape: AbstractShape, bounds, settings: ExactSettings, log: list, max_iter: int):
    """One local run (`settings.local_method`) from `x0`, with its runners-up
    ([`local_run`][locomotion_jax.optimisation._local.local_run]): a descent, or a scipy method on
    the exact values and gradients with the stroke as constraints (`shape.constraint`)."""

    def search(at, x):
        if settings.local_method in METHODS:
            _descent(x, shape, bounds, settings, max_iter, at)
            return {"message": settings.local_method}
        if settings.local_method == "SLSQP":
            res = scipy.optimize.minimize(
                lambda x: at(x).f,
                x,
                jac=lambda x: at(x).df,
                method="SLSQP",
                constraints=[
                    {"type": "ineq", "fun": lambda x: at(x).c, "jac": lambda x: at(x).dc},
                    {"type": "ineq", "fun": lambda x: shape.constraint(x)[0], "jac": lambda x: shape.constraint(x)[1]},
                ],
                bounds=bounds,
                options={"maxiter": max_iter, "ftol": 1e-10},
            )
        else:
            res = scipy.optimize.minimize(
                lambda x: at(x).f,
                x,
                jac=lambda x: at(x).df,
                method="trust-constr",
                constraints=[
                    scipy.optimize.NonlinearConstraint(
                        lambda x: at(x).c, 0.0, np.inf, jac=cast(Any, lambda x: at(x).dc), hess=_zero_hessian
                    ),
                    scipy.optimize.NonlinearConstraint(
                        lambda x: shape.constraint(x)[0],
                        0.0,
                        np.inf,
                        jac=cast(Any, lambda x: shape.constraint(x)[1]),
                        hess=_zero_hessian,
                    ),
                ],
                bounds=bounds,
                options={"maxiter": max_iter, "initial_tr_radius": settings.trust_radius, "verbose": 0},
            )
        return {"message": str(res.message), "nit": int(res.nit)}

    stroke_ok = lambda x: shape.stroke(np.asarray(x)) <= 1 + 1e-9
    return local_run(x0, search, stroke_ok, log, runners_up=True)


def _zero_hessian(x, v):
    return np.zeros((len(x), len(x)))


def _omega_bounds(params: Params, omega: float | None, settings: ExactSettings) -> tuple[float, float]:
    if omega is not None:
        return float(omega), float(omega)
    wmin = float(min(params.wn1, params.wn2, params.wn3))
    return settings.omega_min * wmin, settings.omega_max * float(params.wn1)


GRID = 256
"""Phase samples per period of a start's stroke, before a shape family fits it."""


def _starts(params, a_max, shape: AbstractShape, lo, hi, baseline, start, settings: ExactSettings) -> np.ndarray:
    """Decision vectors of the starts (module docstring); the given `start` last."""
    omegas = [lo] if lo == hi else list(np.geomspace(max(lo, 0.1 * hi), hi / 1.5, settings.start_frequencies))
    shapes = start_shapes(GRID, settings.seed, settings.random_shapes)
    out = [shape.fit(v, w) for w in omegas for v in shapes]
    phase = np.arange(GRID) * 2 * np.pi / GRID
    if baseline is not None and lo != hi:
        out.append(shape.fit(baseline["a"] / a_max * np.sin(phase), baseline["omega"]))
    if settings.tension_periods:
        slowest = 2 * math.pi / float(min(params.wn1, params.wn2, params.wn3))
        periods = slowest * np.geomspace(0.7, 4.0, settings.tension_periods)
        for values, w, _ in tension_starts(
            partial(tension_waves, Chain.from_params(params)), a_max, periods, settings.tension_levels
        ):
            out.append(shape.fit(values[0], w if lo != hi else lo))
    if start is not None:
        wave = start_waveform(start)
        out.append(shape.fit(shape.sample(wave, GRID) / a_max, float(np.asarray(wave.omega)) if lo != hi else lo))
    theta = np.stack(out)
    theta[:, -1] = np.clip(theta[:, -1], math.log(lo), math.log(hi))
    return theta


def _merit(fig: "Figures | _Bad") -> float:
    """Ranking of the starts: the true cost of transport, penalised by the constraint violations
    (the objective's floored distance would favour a waveform that barely moves). A speed
    deficit is penalised mildly: the local solver closes it more easily than it lowers a cost."""
    if not fig.ok:
        return math.inf
    return fig.cot * (1 + 3 * max(0.0, -fig.c[0])) + 10 * max(0.0, -fig.c[1])


def search_step(settings: ExactSettings) -> float:
    """The exact engine's step in the screen and the local runs: `settings.search_dt`, `None` for `dt`."""
    return settings.dt if settings.search_dt is None else settings.search_dt


def _oracle(params: Params, a_max: float, lo: float, shape: AbstractShape, settings: ExactSettings) -> orbit.Oracle:
    """The orbit oracle of the screen and the local runs (step cap: three periods at the lowest frequency)."""
    dtype = params.dtype
    dt = search_step(settings)
    max_steps = int(math.ceil(2 * math.pi / lo / dt)) * 3 + 200
    return orbit.Oracle(
        params=params,
        a_max=jnp.asarray(a_max, dtype),
        max_steps=jnp.asarray(max_steps, jnp.int32),
        tol=jnp.asarray(settings.newton_tol if jnp.finfo(dtype).bits == 64 else 1e-5, dtype),
        shape=shape,
        contact="paper",  # iterates past a lift-off stay defined; the margin constraint keeps N > 0
        dt=dt,
        max_iter=settings.newton_iter,
        patience=jnp.asarray(orbit.PATIENCE, jnp.int32),
    )


def _verify_gaits(params: Params, shape: AbstractShape, a_max: float, settings: ExactSettings, theta: np.ndarray,
                  dt: float) -> Any:  # fmt: skip
    """The verification's steady gaits of the decision vectors `theta` (strict contact, relaxed start)."""
    dtype = params.dtype
    wave = shape.waveform(jnp.asarray(theta, dtype), jnp.asarray(a_max, dtype), jnp.asarray(params.lbar, dtype))
    batch = pareto.with_waveform_frequency(params, wave)
    # Unguarded: a spline's knot spacing is finer than the guard's 4 steps at the default
    # settings, and this verification checks the resolution itself (a solve at dt/2 must agree).
    # Newton's patience: a row that cycles would hold the batch for every iteration of each period.
    return paper_gait(batch, dynamics=_exact_dynamics(dt), transient=settings.transient, waveform=wave,
                      start="relaxed", guarded=False, patience=orbit.PATIENCE)  # fmt: skip


class Precompile:
    """The exact optimiser's own programs compiled in a background thread, started before the
    sinusoid baseline: the orbit oracle's (the screen's and the local runs': `oracle` is set once
    they are compiled), then the verification's and the direct-simulation check's. Each is
    compiled by a call on placeholder decision vectors (zero strokes at the highest frequency, no
    transient periods, the verification at 4 times the step, the check over one gait period: the
    step and the periods are traced, so the programs are those of the real calls). The baseline
    and the optimiser's stages compile and run in the calling thread meanwhile: XLA compiles a
    program on mostly one core, so on a machine of two cores or more the two overlap. The
    optimiser waits for `oracle` before its screen, for `verification` before its verification
    and for the thread ([`wait`][locomotion_jax.optimisation._exact.Precompile.wait]) before its
    check, so that no program is compiled twice at once. The thread compiles for the caller's default
    device (`jax.default_device` is set per thread): a program compiled for another device would
    not be the real calls'.

    A placeholder call that fails is left to the real call, which raises its error there."""

    def __init__(self, params: Params, a_max: float, omega: float | None, shape: AbstractShape,
                 settings: ExactSettings):  # fmt: skip
        self.oracle = threading.Event()
        self.verification = threading.Event()
        self.device = jax.config.jax_default_device  # pyright: ignore[reportAttributeAccessIssue]
        self.thread = threading.Thread(target=self._run, args=(params, a_max, omega, shape, settings), daemon=True)
        self.thread.start()

    def _run(self, params, a_max, omega, shape, settings) -> None:
        try:
            with jax.default_device(self.device):
                self._compile(params, a_max, omega, shape, settings)
        finally:
            self.oracle.set()  # never left waiting
            self.verification.set()

    def _compile(self, params, a_max, omega, shape, settings) -> None:
        dtype = params.dtype
        try:
            lo, hi = _omega_bounds(params, omega, settings)
            lanes = settings.local
            th = np.zeros((lanes, shape.size))
            th[:, -1] = math.log(hi)
            oracle = _oracle(params, a_max, lo, shape, settings)
            rest = oracle.transient(jnp.asarray(th, dtype), jnp.zeros((lanes, 3), dtype), jnp.ones(lanes, bool),
                                    jnp.asarray(0, jnp.int32))  # fmt: skip
            y, k = jnp.asarray(np.asarray(rest), dtype), jnp.asarray(np.ones(lanes, int), jnp.int32)
            jax.block_until_ready(oracle.orbits(jnp.asarray(th, dtype), y, k, gradient=False))
            th = np.zeros(((2 + settings.local) * len(shape.origins), shape.size))
            th[:, -1] = math.log(hi)
            self.oracle.set()
            _verify_gaits(params, shape, a_max, settings, th, 4 * settings.dt)
            self.verification.set()
            # The direct-simulation check's program (its step is traced too), over one gait period.
            wave = waveform_of(shape.fields(th[0], a_max), float(hi), float(params.lbar))
            _simulated(params, wave, (True, 1.0, 1.0, 0.5, 2 * math.pi / hi), settings, periods=1)
        except Exception:  # the real call raises it
            pass

    def wait(self) -> None:
        """Until the direct-simulation check's program is compiled too (the last)."""
        self.thread.join()


def optimise_exact(
    params: Params,
    speed: float,
    direction: int,
    a_max: float,
    omega: float | None,
    shape: AbstractShape,
    settings: ExactSettings,
    baseline: dict | None,
    start: Any,
    precompiled: Precompile | None = None,
) -> tuple[Optimum, dict]:
    """The exact method (module docstring); inputs already checked by `optimise`. `precompiled`:
    the programs compiling in the background since before the baseline ([`Precompile`][])."""
    t0 = time.perf_counter()
    dtype = params.dtype
    lo, hi = _omega_bounds(params, omega, settings)
    free = lo != hi
    oracle = _oracle(params, a_max, lo, shape, settings)
    v_target = speed * (1 + settings.speed_slack)
    make = lambda th, orb, v, k: Figures(th, orb, v, k, direction, settings.margin, free)
    lanes = settings.local
    say = reporter(settings.verbose)
    targets: dict[int, float] = {}  # each lane's required speed, per stage of the continuation
    last: dict[int, Figures] = {}  # each lane's last figures, for a point where no orbit is found

    def figures(lane, th, orb, k):
        fig = last[lane] = make(th, orb, targets[lane], k)
        return fig

    def report(calls, figs):
        if calls % 25 == 0:
            say(f"  evaluation {calls}: cost " + " ".join(f"{f.f:.4f}" for f in figs) + " speed constraint "
                + " ".join(f"{f.c[0]:+.4f}" for f in figs))  # fmt: skip

    ev = Evaluator(oracle, lanes, settings.transient, figures, lambda lane, th: _Bad(th, last.get(lane)), report)
    log: dict[str, Any] = {}

    # -- starts, screened in batches of the same size as the local solves (one compilation).
    theta0 = _starts(params, a_max, shape, lo, hi, baseline, start, settings)
    n0 = len(theta0)
    given = n0 - 1 if start is not None else None
    pad = (-n0) % lanes
    theta0 = np.concatenate([theta0, theta0[:pad]])
    periods = jnp.asarray(settings.transient, jnp.int32)

    say(f"screening {n0} starts in batches of {lanes} (the first batch compiles the orbit solver: first call only)...")

    def screen(theta):
        figs, ys = [], []
        for b in range(0, len(theta), lanes):
            if b:
                say(f"  {b} of {len(theta)} starts screened ({time.perf_counter() - t0:.0f} s)")
            th = theta[b : b + lanes]
            rest = oracle.transient(
                jnp.asarray(th, dtype), jnp.zeros((lanes, 3), dtype), jnp.ones(lanes, bool), periods
            )
            # The screen ranks by the figures alone: no gradients (the local runs compute their own).
            orb, kk = ev.solve(th, np.asarray(rest), np.ones(lanes, int), rested=True, gradient=False)
            for k in range(lanes):
                one = jax.tree_util.tree_map(lambda x: x[k], orb)
                figs.append(make(th[k], one, v_target, int(kk[k])) if one.ok else _Bad(th[k], None))
                ys.append((one.y, int(kk[k])))
        return figs, ys

    if precompiled is not None:
        precompiled.oracle.wait()
    figs, ys = screen(theta0)
    if free:
        # A good shape at too low a frequency: the same shape run faster, in proportion to
        # its speed deficit, for the best starts that fall short.
        best = np.argsort([_merit(f) for f in figs[:n0]])[: 2 * lanes]
        short = [int(i) for i in best if figs[i].ok and figs[i].c[0] < 0]
        if short:
            extra = theta0[short].copy()
            ratio = np.array([1.02 / max(1 + figs[i].c[0], 0.1) for i in short])
            extra[:, -1] = np.clip(extra[:, -1] + np.log(ratio), math.log(lo), math.log(hi))
            extra = np.concatenate([extra, extra[: (-len(extra)) % lanes]])
            f2, y2 = screen(extra)
            theta0 = np.concatenate([theta0[:n0], extra[: len(short)]])
            figs, ys = figs[:n0] + f2[: len(short)], ys[:n0] + y2[: len(short)]
            n0 = len(theta0)
    merit = np.array([_merit(f) for f in figs[:n0]])
    order: list[int] = []
    for i in np.argsort(merit):
        # Distinct gaits only: shapes that are time shifts or mirror images of each other
        # give the same gait, and the same merit to rounding.
        if np.isfinite(merit[i]) and all(abs(merit[i] - merit[j]) > 1e-9 * merit[j] for j in order):
            order.append(int(i))
        if len(order) == lanes:
            break
    if given is not None and given not in order and np.isfinite(merit[given]):
        # The given start (continuation: the optimum of a nearby requirement) is always refined.
        order = order[: lanes - 1] + [given]
    log["starts"] = [{"omega": float(np.exp(theta0[i, -1])), "merit": float(merit[i])} for i in range(n0)]
    if not order:
        order = [0]
    order += order[:1] * (lanes - len(order))
    say(
        f"{n0} starts screened ({time.perf_counter() - t0:.0f} s); refining: "
        + ", ".join(f"omega {np.exp(theta0[i, -1]):.3g} merit {merit[i]:.3g}" for i in order)
    )

    # -- local refinement in lockstep.
    bounds = scipy.optimize.Bounds(
        np.r_[np.full(shape.size - 1, -np.inf), math.log(lo) if free else -np.inf],
        np.r_[np.full(shape.size - 1, np.inf), math.log(hi) if free else np.inf],
    )
    ev.y = {k: ys[i][0] for k, i in enumerate(order)}
    ev.k = {k: ys[i][1] for k, i in enumerate(order)}
    log["local"] = []
    # Continuation in the required speed: a lane that starts too slow is led to v_min in
    # `stages` steps (geometric in speed); the last step has half the iterations.
    v0 = [v_target * max(0.1, 1 + min(0.0, figs[i].c[0])) for i in order]
    n = settings.stages
    iters = (
        [settings.max_iter // (2 * (n - 1))] * (n - 1)
        + [settings.max_iter - (n - 1) * (settings.max_iter // (2 * (n - 1)))]
        if n > 1
        else [settings.max_iter]
    )
    x = [theta0[i].copy() for i in order]
    runners: Any = [[] for _ in range(lanes)]
    for j, it in enumerate(iters):
        targets.update({k: v0[k] * (v_target / v0[k]) ** ((j + 1) / len(iters)) for k in range(lanes)})
        # Before the last stage a trial point whose orbit is not found from the lane's last one is
        # rejected (the descent backtracks) rather than retried after a transient (`retry`).
        ev.retry = settings.retry == "every" or j == len(iters) - 1
        solvers = [_local_solver(x[k], shape, bounds, settings, log["local"], it) for k in range(lanes)]
        x, runners = zip(*run_lockstep(solvers, ev))
    say(
        f"local runs done ({time.perf_counter() - t0:.0f} s); stroke / a_max "
        + " ".join(f"{shape.stroke(xi):.8f}" for xi in x)
    )
    # The exact stroke limit: what the constraint tolerance let through, moved onto it.
    x = [shape.project(xi) for xi in x]
    candidates = [("start", theta0[order[0]])]
    if given is not None:
        candidates.append(("given start", theta0[given]))
    candidates += [(f"local {k}", x[k]) for k in range(lanes)]
    fallbacks = [
        (f"local {k} runner-up {j}", shape.project(r), cot, len(candidates) - lanes + k)
        for k in range(lanes)
        for j, (cot, r) in enumerate(runners[k])
    ]
    if precompiled is not None:
        precompiled.verification.wait()
    ready = None if precompiled is None else precompiled.wait
    return _verify(params, speed, direction, a_max, shape, free, settings, candidates, fallbacks, baseline, log, t0, ev,
                   ready)  # fmt: skip


FALLBACK_RTOL = 1e-6
"""A runner-up of a local run whose candidate passed the verification is verified too only if
its cost of transport in the descent is below the cheapest feasible candidate's by more than
this (relative; `_verify`). A runner-up is an earlier point of the same descent, so it costs
at least the run's candidate there; it can be the cheaper in the verification only if the
verification found another gait than the descent did, not by the figures' rounding."""


def _verify(params, speed, direction, a_max, shape, free, settings, candidates, fallbacks, baseline, log, t0, ev,
            ready=None):  # fmt: skip
    """Solve each candidate's steady gait (strict contact, relaxed start) and keep the cheapest feasible one.

    A candidate counts as feasible only if its gait is also converged, stable and without
    lift-off with half the engine's step, with the same speed and cost of transport to
    `HALF_STEP_RTOL` (the figures reported are those at the full step). `candidates` (the
    start, a given start and the local runs' points) are verified first; the `fallbacks`
    (the local runs' runners-up: name, point, cost of transport in the descent and the index
    of their run's candidate) then where their run's candidate is not feasible, or where the
    descent found them cheaper than the cheapest feasible candidate (`FALLBACK_RTOL`). The
    optimum's direct-simulation check follows once `ready()` returns (`Precompile.wait`; `None`: at once)."""
    dtype = params.dtype
    # Batches of a fixed number of rows (padded with their first candidate), so that every
    # optimisation with the same settings runs the same compiled verification.
    rows = 2 + settings.local
    origins = shape.origins
    eps = float(jnp.finfo(dtype).eps)
    gaits = lambda theta, dt: _verify_gaits(params, shape, a_max, settings, theta, dt)

    def check(thetas):
        """The gaits of up to `rows` candidates at the better of their time origins, with the
        figures at `dt` (`ok` only if `dt/2` agrees) and at `dt/2`."""
        m = len(thetas)
        padded = list(thetas) + [thetas[0]] * (rows - m)
        # Every candidate at each time origin the family offers, candidate-major.
        theta = np.stack([shape.shift(th, o) for th in padded for o in origins])
        gait = gaits(theta, settings.dt)
        # Every section again at dt/2: the same shapes, so the same compiled program (dt is traced).
        half = gaits(theta, settings.dt / 2)
        pick = _best_sections(gait, rows, len(origins))[:m]
        gait, half = (jax.tree_util.tree_map(lambda x: x[pick] if np.ndim(x) else x, g) for g in (gait, half))
        fig, half = pareto.gait_figures(gait), pareto.gait_figures(half)
        steady = steady_at_half_step(fig.ok, fig.speed, fig.cost, half.ok, half.speed, half.cost)
        return theta[pick], gait, fig._replace(ok=steady), half

    names = [name for name, _ in candidates]
    parts = [check([th for _, th in candidates])]
    theta, _, fig, _ = parts[0]
    strokes = np.array([a_max * shape.stroke(th) for th in theta])
    held = choose(fig.ok, fig.speed, fig.cost, strokes, speed, direction, a_max, eps)[1]
    cheapest = float(np.min(np.where(held, fig.cost, np.inf)))
    go = [not held[f[3]] or f[2] < cheapest * (1 - FALLBACK_RTOL) for f in fallbacks]
    wanted = [f for f, g in zip(fallbacks, go) if g]
    log["unverified"] = [f[0] for f, g in zip(fallbacks, go) if not g]
    for b in range(0, len(wanted), rows):
        parts.append(check([f[1] for f in wanted[b : b + rows]]))
        names += [f[0] for f in wanted[b : b + rows]]
    # The batches' rows in order: every array of each part (theta, gait, figures, half-step figures).
    join = lambda *xs: np.concatenate([np.asarray(x) for x in xs]) if np.ndim(xs[0]) else xs[0]
    theta, gait, fig, half = (jax.tree_util.tree_map(join, *column) for column in zip(*parts))
    n = len(names)
    strokes = np.array([a_max * shape.stroke(th) for th in theta])
    k, feasible, exact = verified(fig, strokes, speed, direction, a_max, eps, baseline)
    table = [
        {
            "candidate": names[i],
            "omega": float(np.exp(theta[i, -1])),
            "mean_speed_exact": float(fig.speed[i]),
            "cost_of_transport_exact": float(fig.cost[i]),
            "stable_exact": bool(fig.ok[i]),
            "half_step_speed": float(half.speed[i]),
            "half_step_cost": float(half.cost[i]),
            "liftoff_exact": bool(fig.liftoff[i]),
            "stroke": float(strokes[i]),
            "feasible_exact": bool(feasible[i]),
        }
        for i in range(n)
    ]
    rho = np.abs(np.asarray(gait.multipliers[k]))
    radius = float(np.max(rho)) if np.all(np.isfinite(rho)) else math.nan
    opt = Optimum(
        v_min=speed,
        direction=direction,
        a_max=float(a_max),
        margin=settings.margin,
        free_omega=free,
        **shape.fields(theta[k], a_max),
        omega=float(np.exp(theta[k, -1])),
        lbar=float(params.lbar),
        **exact,
        mean_speed_smoothed=math.nan,
        cost_of_transport_smoothed=math.nan,
        min_normal_smoothed=math.nan,
        eps=math.nan,
        initial_cost_of_transport_exact=float(fig.cost[0]) if feasible[0] else math.nan,
        source=names[k],
        candidates=table,
        history=[log],
        runtime_s=time.perf_counter() - t0,
        method="exact",
        stable_exact=bool(fig.ok[k]),
        spectral_radius_exact=radius,
        gait_period_exact=float(gait.period[k]),
        evaluations=ev.calls,
    )
    steady = (bool(fig.ok[k]), float(fig.speed[k]), float(fig.cost[k]), radius, float(gait.period[k]))
    if ready is not None:
        ready()
    sim = _simulated(params, opt.waveform, steady, settings)
    return dataclasses.replace(opt, **sim, runtime_s=time.perf_counter() - t0), log


def _simulated(params: Params, wave: AbstractWaveform, steady: tuple, settings: ExactSettings,
               periods: int | None = None) -> dict:  # fmt: skip
    """The optimum's direct-simulation check ([`_element_local.simulated`][]; strict contact, relaxed start)."""
    model = pareto.with_waveform_frequency(params, wave)
    return local.simulated(model, steady, settings, periods=periods, start="relaxed", waveform=wave)


def _best_sections(gait: Any, n: int, m: int) -> np.ndarray:
    """Per candidate, the index of the time origin (of `m`) whose steady gait to report.

    The section of [`steady_gait`][] is the phase $\\omega t \\equiv 0$. Where a slipping mass's
    velocity is about to reach zero there, the period map of the reduced state is nearly
    discontinuous (a Newton iterate on the other side of $v_i = 0$ starts with the mass
    stuck or sliding back), so that Newton's method may stall and the monodromy, hence the
    stability verdict, depends on the last iterate. The same gait seen from another time
    origin has its section elsewhere: we take the origin whose orbit converged with the
    largest clearance $\\min |v_i|$ over the masses slipping at the section (a stuck mass has
    none to lose)."""
    status = np.asarray(gait.status).reshape(n, m)
    v = np.abs(np.stack([np.asarray(gait.v1), np.asarray(gait.v2)], axis=-1)).reshape(n, m, 2)
    clearance = np.min(np.where(v > 0, v, np.inf), axis=-1)
    score = np.where(status == GaitStatus.CONVERGED, np.nan_to_num(clearance, nan=-1.0), -np.inf)
    return np.arange(n) * m + np.argmax(score, axis=1)


def _exact_dynamics(dt: float):
    from ..dynamics._exact_dynamics import Exact

    return Exact(dt=dt)
