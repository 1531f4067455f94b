"""Optimal actuation (SPEC §7): waveforms that minimise the cost of transport.

Problem, for one configuration `params`, a required speed $v_\\min$ in a
direction $\\sigma = \\pm 1$ and a stroke limit $a_\\max$:

$$\\min_{A, B, \\omega}\\ \\frac{e_d}{\\sigma\\Delta X}
\\quad\\text{s.t.}\\quad \\sigma\\bar v \\ge v_\\min,\\quad
\\max_t |\\ell_0(t) - \\bar\\ell| \\le a_\\max,\\quad \\min_t N_{1,2}(t) \\ge \\text{margin},$$

with $\\ell_0(t) = \\bar\\ell + \\sum_{n \\le N} A_n \\cos n\\omega t + B_n \\sin n\\omega t$
([`Fourier`][]) and $e_d$, $\\Delta X$ over whole periods in steady state (eqs. 4, 15).

Method:

- **Objective and gradients** on the smoothed model by reverse mode through a
  checkpointed fixed-step rollout (`_objective.rollout`), with a continuation
  in $\\varepsilon$ (default $10^{-2} \\to 3\\cdot10^{-3} \\to 10^{-3}$). The step
  count, set by $\\varepsilon$, is traced, so every stage runs the same compiled
  block (one compilation per optimisation; coarse stages skip the surplus steps).
- **Constraints.** The stroke is convex in $(A, B)$ and cheap: iterates are kept
  inside it by radial rescaling (`_constraints.project_stroke`), so it holds
  exactly at every iterate. Speed and no-lift-off depend on the dynamics and are
  handled by an augmented Lagrangian (Powell-Hestenes-Rockafellar for $g \\le 0$):
  $L = f + \\sum_j \\big(\\max(0, \\lambda_j + \\rho_j g_j)^2 - \\lambda_j^2\\big)/(2\\rho_j)$,
  minimised by `optax.chain(clip_by_global_norm, adam)` for a block of steps,
  then $\\lambda_j \\leftarrow \\max(0, \\lambda_j + \\rho_j g_j)$ and $\\rho_j$ grows
  where the violation did not shrink fourfold. Unlike a fixed penalty, the
  multipliers converge to values that make the constraint hold.
- **Many starts** (sinusoids, saw-tooth and square-ish shapes, random
  harmonics, at a few base frequencies) run at once under `vmap`; each keeps the
  best iterate that is feasible on the smoothed model.
- **Verification on the exact model** (`_pareto.exact_figures`). Smoothing
  leaves a bias of a few per cent, so a start whose exact speed falls short gets
  its target speed raised by the shortfall (and a start that lifts off a larger
  margin), and is re-optimised at the finest $\\varepsilon$ (defect correction).
  The reported optimum is the cheapest candidate that meets every constraint on
  the exact model; the initial guesses are candidates too, so the result is never
  worse than the best start.
"""

import dataclasses
import math
import sys
import time
from collections import Counter
from collections.abc import Callable, Mapping
from typing import Any, cast, overload

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

from ..model._bodies import Mechanism
from ..model._chain import Chain
from ..model._params import Params
from ..model._waveform import Fourier
from ..run._batch import mechanism_arg
from ..run._resolution import refuse_search
from . import _constraints as cons, _objective, _pareto as pareto
from ._element_optimum import ChainOptimiseSettings, ChainOptimum, MechanismOptimiseSettings, MechanismOptimum
from ._objective import make_plan, Plan, Rollout, rollout
from ._optimum import along, ExactSettings, Optimum, Settings, start_waveform, verified
from ._shapes import FourierShape, SplineShape


# -- decision variables -------------------------------------------------------


def to_waveform(theta: dict, a_max: Any, lbar: Any, free_omega: bool) -> Fourier:
    """Decision variables -> waveform. Coefficients are in units of $a_\\max$ and the
    frequency is $\\omega = e^{\\theta_\\omega}$, so Adam sees O(1) variables."""
    omega = jnp.exp(theta["log_omega"])
    if not free_omega:
        omega = jax.lax.stop_gradient(omega)
    return Fourier(a_max * theta["cos"], a_max * theta["sin"], omega, lbar)


def project(theta: dict, log_lo: Any, log_hi: Any) -> dict:
    """Feasible set of the simple constraints: stroke <= 1 (in units of $a_\\max$; every signal's,
    for coefficients of shape `(S, H)`), $\\omega$ in range."""
    stroke = cons.project_stroke if theta["cos"].ndim == 1 else jax.vmap(cons.project_stroke, in_axes=(0, 0, None))
    c, s = stroke(theta["cos"], theta["sin"], 1.0)
    return {"cos": c, "sin": s, "log_omega": jnp.clip(theta["log_omega"], log_lo, log_hi)}


def initial_guesses(
    n_starts: int, harmonics: int, omegas: list[float], seed: int
) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """Starting shapes (unit stroke scaled to 0.9), cycled over the base frequencies.

    Shapes: the sinusoid of eq. (13); saw-tooth ramps of both senses (even and
    odd harmonics, time-asymmetric); a square-ish wave (odd harmonics); then
    sinusoids with random higher harmonics.
    """
    rng = np.random.default_rng(seed)
    n = np.arange(1, harmonics + 1)
    saw = (-1.0) ** (n + 1) / n  # slow rise, fast fall; -saw is its time reversal
    shapes = [np.eye(1, harmonics, 0)[0], saw, -saw, np.where(n % 2 == 1, 1.0 / n, 0.0)]
    out = []
    for i in range(n_starts):
        omega = omegas[i % len(omegas)]
        k = i // len(omegas)
        if k < len(shapes) and (harmonics > 1 or k == 0):
            cos, sin = np.zeros(harmonics), shapes[k].astype(float)
        else:
            cos = 0.3 * rng.normal(size=harmonics) / n
            sin = np.eye(1, harmonics, 0)[0] + 0.3 * rng.normal(size=harmonics) / n
        scale = 0.9 / float(cons.stroke(jnp.asarray(cos), jnp.asarray(sin)))
        out.append((cos * scale, sin * scale, float(omega)))
    return out


# -- augmented Lagrangian ---------------------------------------------------------


def paper_rollout(theta: dict, prob: "_Problem", eps: jax.Array) -> Rollout:
    """The paper's model's smoothed rollout (`_objective.rollout`) at the decision variables `theta`."""
    wave = to_waveform(theta, prob.a_max, prob.params.lbar, prob.free_omega)
    return rollout(prob.params, wave, eps, prob.plan, prob.temperature)


def element_rollout(theta: dict, prob: "_Problem", eps: jax.Array) -> Rollout:
    """A chain's or a mechanism's smoothed rollout (`_objective.element_rollout`) at the decision
    variables `theta` (`cos`, `sin` of shape `(S, H)`, in units of $a_\\max$)."""
    omega = jnp.exp(theta["log_omega"])
    if not prob.free_omega:
        omega = jax.lax.stop_gradient(omega)
    cos, sin = prob.a_max * theta["cos"], prob.a_max * theta["sin"]
    return _objective.element_rollout(prob.params, cos, sin, omega, eps, prob.plan, prob.temperature)


class _Problem(eqx.Module):
    """Traced data of the problem (one start), and the static choices: `params`, the paper's
    model or the chain or mechanism driven; `roll`, its rollout ([`paper_rollout`][] or
    [`element_rollout`][])."""

    params: Any
    a_max: jax.Array
    direction: jax.Array
    log_lo: jax.Array
    log_hi: jax.Array
    plan: Plan
    temperature: float = eqx.field(static=True)
    free_omega: bool = eqx.field(static=True)
    roll: Callable = eqx.field(static=True, default=paper_rollout)


def terms(theta: dict, prob: _Problem, eps: jax.Array, v_target: jax.Array, margin: jax.Array):
    """Objective $f$ (cost of transport) and constraints $g \\le 0$ on the smoothed model.

    $g_0 = 1 - \\sigma\\Delta X / (v_\\text{target} T)$ (speed), $g_1 = \\text{margin} - \\min N$.
    The denominator of $f$ is $\\sigma\\Delta X$ floored smoothly at a quarter of
    the required distance, so $f$ stays finite and differentiable when an iterate
    stands still or moves backwards (it equals $\\sigma \\Delta X$ whenever the
    speed constraint holds).
    """
    r = prob.roll(theta, prob, eps)
    dist = prob.direction * r.distance
    need = v_target * r.duration
    floor, width = 0.25 * need, 0.05 * need
    cost = r.dissipated / (floor + width * jax.nn.softplus((dist - floor) / width))
    g = jnp.stack([1 - dist / need, margin - r.min_normal])
    return cost, g, r


def _lagrangian(theta, prob, eps, v_target, margin, lam, rho, weight):
    cost, g, r = terms(theta, prob, eps, v_target, margin)
    penalty = jnp.sum((jnp.maximum(0, lam + rho * g) ** 2 - lam**2) / (2 * rho))
    return weight * cost + penalty, (cost, g, r)


def _optimizer() -> optax.GradientTransformation:
    """Adam on clipped gradients; the step size is applied by the caller, so that the
    continuation can shrink it per stage without resetting Adam's moments."""
    return optax.chain(optax.clip_by_global_norm(1.0), optax.scale_by_adam())


TRACES: Counter = Counter()
"""Python-level traces of the jitted blocks (keys `"block"`, `"evaluate"`): a test
checks that a whole optimisation (every start, smoothing stage and outer
iteration) traces the Adam block once."""


class _Best(eqx.Module):
    theta: dict
    cost: jax.Array


@eqx.filter_jit
def _block(theta, opt_state, best, prob, eps, v_target, margin, lam, rho, weight, lr, steps: int):
    """`steps` Adam steps of size `lr` on the augmented Lagrangian for every start (vmapped)."""
    TRACES["block"] += 1  # runs only while tracing
    opt = _optimizer()
    grad_fn = jax.value_and_grad(_lagrangian, has_aux=True)

    def one(theta, opt_state, best, v_target, margin, lam, rho, weight):
        def body(carry, _):
            theta, opt_state, best = carry
            (_, (cost, g, _)), grad = grad_fn(theta, prob, eps, v_target, margin, lam, rho, weight)
            better = (g[0] <= 0) & (g[1] <= 0) & (cost < best.cost)
            best = jax.tree_util.tree_map(lambda a, b: jnp.where(better, a, b), _Best(theta, cost), best)
            updates, opt_state = opt.update(grad, opt_state, theta)
            updates = jax.tree_util.tree_map(lambda u: -lr * u, updates)
            # `apply_updates` returns the structure of `theta` (a dict); its stubs say `optax.Params`.
            theta = project(cast(dict, optax.apply_updates(theta, updates)), prob.log_lo, prob.log_hi)
            return (theta, opt_state, best), jnp.concatenate([cost[None], g])

        (theta, opt_state, best), hist = jax.lax.scan(body, (theta, opt_state, best), None, length=steps)
        cost, g, r = terms(theta, prob, eps, v_target, margin)
        better = (g[0] <= 0) & (g[1] <= 0) & (cost < best.cost)
        best = jax.tree_util.tree_map(lambda a, b: jnp.where(better, a, b), _Best(theta, cost), best)
        return theta, opt_state, best, cost, g, hist

    return jax.vmap(one)(theta, opt_state, best, v_target, margin, lam, rho, weight)


@eqx.filter_jit
def _evaluate(theta, prob, eps, v_target, margin):
    TRACES["evaluate"] += 1
    fn = lambda th, v, m: terms(th, prob, eps, v, m)
    return jax.vmap(fn)(theta, v_target, margin)


def _stack(guesses, dtype) -> dict:
    return {
        "cos": jnp.asarray(np.stack([g[0] for g in guesses]), dtype),
        "sin": jnp.asarray(np.stack([g[1] for g in guesses]), dtype),
        "log_omega": jnp.asarray(np.log([g[2] for g in guesses]), dtype),
    }


def _fourier_batch(theta: dict, a_max: float, lbar) -> Fourier:
    omega = jnp.exp(theta["log_omega"])
    return Fourier(a_max * theta["cos"], a_max * theta["sin"], omega, jnp.broadcast_to(lbar, omega.shape))


def _run_stage(state, prob, eps, lr, settings: Settings, outer: int, log):
    """One continuation stage: `outer` blocks of Adam steps with multiplier updates."""
    theta, opt_state, lam, rho, v_target, margin = state
    dtype = theta["cos"].dtype
    n = theta["cos"].shape[0]
    best = _Best(theta, jnp.full((n,), jnp.inf, dtype))
    eps_a = jnp.asarray(eps, dtype)
    viol_prev = np.full((n, 2), np.inf)
    # Feasibility first: a start far from the required speed optimises the constraint
    # terms alone (weight 0 on the cost). Otherwise the cost, which a standing robot
    # makes small, can shrink the stroke below the static-friction threshold, where
    # nothing moves and every gradient vanishes.
    _, g0, _ = _evaluate(theta, prob, eps_a, v_target, margin)
    weight = jnp.where(g0[:, 0] > settings.phase1_threshold, 0.0, 1.0).astype(dtype)
    for it in range(outer):
        theta, opt_state, best, cost, g, hist = _block(
            theta,
            opt_state,
            best,
            prob,
            eps_a,
            v_target,
            margin,
            lam,
            rho,
            weight,
            jnp.asarray(lr, dtype),
            settings.inner,
        )
        phase1 = np.asarray(weight == 0)
        weight = jnp.where(g[:, 0] > settings.phase1_threshold, 0.0, 1.0).astype(dtype)
        g_np = np.asarray(g)
        lam = jnp.maximum(0, lam + rho * g)
        viol = np.maximum(g_np, 0)
        grow = viol > 0.25 * viol_prev
        rho = jnp.where(jnp.asarray(grow), jnp.minimum(rho * settings.rho_growth, settings.rho_max), rho)
        viol_prev = viol
        log.append(
            {
                "eps": eps,
                "outer": it,
                "cost": np.asarray(cost).tolist(),
                "phase1": phase1.tolist(),
                "g_speed": g_np[:, 0].tolist(),
                "g_normal": g_np[:, 1].tolist(),
            }
        )
        if settings.verbose:
            print(
                f"  eps={eps:.0e} outer {it}: cost {np.round(np.asarray(cost), 3)} "
                f"speed-violation {np.round(g_np[:, 0], 3)}",
                file=sys.stderr,
                flush=True,
            )
    # Starts with no feasible iterate in this stage continue from their last one.
    found = jnp.isfinite(best.cost)
    best_theta = jax.tree_util.tree_map(
        lambda a, b: jnp.where(found.reshape((-1,) + (1,) * (a.ndim - 1)), a, b), best.theta, theta
    )
    return (theta, opt_state, lam, rho, v_target, margin), best_theta


@overload
def optimise(
    params: Params, v_min: float, a_max: float, *, method: str = ..., direction: int | None = ...,
    omega: float | None = ..., harmonics: int | None = ..., settings: "Settings | ExactSettings | None" = ...,
    sweep: "pareto.SinusoidSweep | Mapping[str, Any] | None" = ..., start: Any = ...,
) -> Optimum: ...  # fmt: skip


@overload
def optimise(
    params: Chain, v_min: float, a_max: float, *, method: str = ..., direction: int | None = ...,
    omega: float | None = ..., harmonics: int | None = ..., settings: "ChainOptimiseSettings | None" = ...,
    sweep: Mapping[str, Any] | None = ..., start: Any = ...,
) -> ChainOptimum: ...  # fmt: skip


@overload
def optimise(
    params: Mechanism, v_min: float, a_max: float, *, method: str = ..., direction: int | None = ...,
    omega: float | None = ..., harmonics: int | None = ...,
    settings: "MechanismOptimiseSettings | ChainOptimiseSettings | None" = ...,
    sweep: Mapping[str, Any] | None = ..., start: Any = ...,
) -> MechanismOptimum: ...  # fmt: skip


def optimise(
    params: Params | Chain | Mechanism,
    v_min: float,
    a_max: float,
    *,
    method: str = "exact",
    direction: int | None = None,
    omega: float | None = None,
    harmonics: int | None = None,
    settings: "Settings | ExactSettings | ChainOptimiseSettings | MechanismOptimiseSettings | None" = None,
    sweep: "pareto.SinusoidSweep | Mapping[str, Any] | None" = None,
    start: Any = None,
) -> Optimum | ChainOptimum | MechanismOptimum:
    """Find the periodic actuation of least cost of transport that meets a speed (SPEC §7).

    `params` may be a [`Chain`][] of N masses (SPEC §8): then the actuation is per spring
    (travelling waves screened, then per-spring harmonics refined on the exact steady gaits;
    module `optimisation._chain`, [`ChainOptimiseSettings`][], default 3 harmonics) and the
    result a [`ChainOptimum`][]; a [`Mechanism`][locomotion_jax.Mechanism] (SPEC §9): the same method
    over the Fourier coefficients (default 2 harmonics) or, with
    `MechanismOptimiseSettings(shape="spline")`, the spline control values (`knots`) of its actuated
    elements' waveforms (sinusoids screened; module `optimisation._mechanism`,
    [`MechanismOptimiseSettings`][]; `a_max` bounds each actuated element's excursion in its own
    units, a force bound for a force), the result a `MechanismOptimum`.

    Two methods:

    - `"exact"` (default, `_exact_optimise`): on the steady gaits of the exact hybrid
      model, with gradients by forward mode and the implicit function theorem, over a
      periodic cubic spline stroke of 64 knots (or a Fourier series: `ExactSettings.shape`),
      starts screened and the best refined by a monotone descent in lockstep, every
      candidate verified by [`steady_gait`][].
    - `"smoothed"` (this module's docstring): Adam on an augmented Lagrangian of a
      smoothed friction model (default 3 harmonics), verified on the exact model. For a `Chain`
      or a `Mechanism` it replaces the local stage alone (module `optimisation._element_smoothed`,
      its settings the `smoothed` field of the chain's or mechanism's settings): the screen's best
      starts refined on the smoothed model, then verified on their steady gaits as the exact
      method's candidates; Fourier series only.

    **Arguments:**

    - `params`: one configuration ([`Params`][]; `a` and `omega` are ignored), or one [`Chain`][] (its
      waveforms are ignored; `v_min > 0`, `0 < a_max < min(lbar)` for the rest-length actuator or
      `a_max > 0` for [`InternalForce`][], `settings` a [`ChainOptimiseSettings`][]).
    - `v_min`: required mean speed (> 0) in `direction`; see `_constraints.check_inputs`.
    - `a_max`: stroke bound, $\\max_t |\\ell_0(t) - \\bar\\ell| \\le a_\\max$ (a chain's force bound
      under [`InternalForce`][]).
    - `method`: `"exact"` or `"smoothed"`, for every mechanism.
    - `direction`: +1 (forward, default) or -1 (backward).
    - `omega`: fix the base frequency; `None` optimises it.
    - `harmonics`: number $N$ of Fourier harmonics: the smoothed method (default 3) and the
      exact method with `ExactSettings(shape="fourier")` (default 16); the exact method's
      default spline takes `ExactSettings.knots` instead.
    - `settings`: [`ExactSettings`][locomotion_jax.optimisation._optimum.ExactSettings] (exact) or
      [`Settings`][] (smoothed); defaults if `None`.
    - `sweep`: a precomputed [`sinusoid_sweep`][locomotion_jax.optimisation._pareto.sinusoid_sweep] for the same
      `params` and `a_max` (the baseline), or an earlier optimum's `screen` (which is that sweep);
      computed if `None`. For a `Chain` or a `Mechanism`: an
      earlier optimum's `screen` of the same mechanism, screened with the same settings (`opt.screen`,
      or `to_dict(full=True)["screen"]` read back from `optimum.json`), which is then the screen:
      its signals are not solved again, those above `a_max` or outside the frequency range are left
      out, and a wave that the earlier screen left unsolved (slower than `screen_speed` of its
      `v_min`) is no start. Optimising one mechanism at several speeds (its cost-speed front)
      screens it once.
    - `start`: exact method: a waveform to start from besides the built-in starts (an
      [`Optimum`][], its `to_dict()` or any waveform, e.g. the optimum at a nearby `v_min`:
      continuation); it is always refined, and is a candidate itself. For a `Chain` or a
      `Mechanism`: an earlier [`ChainOptimum`][] or [`MechanismOptimum`][] (or its `to_dict()`,
      e.g. read back from the JSON of `optimize --json`) with as many actuated signals (at a nearby
      requirement, or of a nearby mechanism; either family, refitted to this search's), refined
      in the last local lane from its own transient and a candidate itself. With `local=1` it is
      the only local run.

    **Returns:** an [`Optimum`][]: coefficients, exact figures (whole periods of the steady
    gait), constraint checks on the exact model and the best sinusoid for comparison.

    **Raises:** `ValueError` for a bad requirement (see `_constraints.check_inputs`) or
    method; `TypeError` for settings of the other method.

    **Compilation.** A first call in a process compiles the engine's programs (the sinusoid
    baseline's steady gaits, the orbit oracle, the verification: most of a cold call's time);
    later calls with the same settings, in the same process, reuse them. Across processes,
    [`enable_compilation_cache`][locomotion_jax.enable_compilation_cache] (once, at start-up)
    keeps them on disk: a later process reads them back instead of compiling. The library
    leaves that switch (JAX's process-wide `jax_compilation_cache_dir`) to the caller; the
    command line turns it on by default.

    !!! Example

        ```python
        enable_compilation_cache()  # optional: compiled programs kept across processes
        opt = optimise(Params(), v_min=0.05, a_max=0.05)
        opt.cost_of_transport_exact, opt.improvement_vs_sinusoid
        ```
    """
    # The mechanism names its optimiser (`AbstractMechanism.optimum`).
    return mechanism_arg(params).optimum(v_min, a_max, method, direction, omega, harmonics, settings, sweep, start)


def params_optimum(params: Params, v_min, a_max, method, direction, omega, harmonics, settings, sweep, start):
    """[`optimise`][] of the paper's two-mass model: the exact method (the default) or the smoothed one."""
    if method not in ("exact", "smoothed"):
        raise ValueError(f"method must be 'exact' or 'smoothed', got {method!r}.")
    sweep = None if sweep is None else pareto.sweep_of(sweep)
    exact = method == "exact"
    kind = ExactSettings if exact else Settings
    settings = kind() if settings is None else settings
    if not isinstance(settings, kind):
        raise TypeError(f"settings for method={method!r} must be a {kind.__name__}, got {type(settings).__name__}.")
    spline = exact and cast(ExactSettings, settings).shape == "spline"
    if spline and harmonics is not None:
        raise ValueError(
            "harmonics applies to Fourier strokes; the exact method's default stroke is a spline "
            "(ExactSettings.knots). Pass settings=ExactSettings(shape='fourier') to optimise harmonics."
        )
    if harmonics is None:
        harmonics = 16 if exact else 3
    if start is not None and not exact:
        raise ValueError("start= is only used by method='exact'.")
    start_waveform(start)  # a start that is not the paper's model's is refused before the baseline
    if exact and harmonics < 2:
        raise ValueError(f"harmonics must be an integer >= 2 for method='exact', got {harmonics!r}.")
    speed, direction = cons.check_inputs(params, v_min, a_max, direction, harmonics, omega, settings.margin)
    shape = SplineShape(knots=cast(ExactSettings, settings).knots) if spline else FourierShape(harmonics=harmonics)
    precompiled = None
    if exact:
        _guard_search(params, omega, shape, cast(ExactSettings, settings))
        from ._exact import Precompile

        precompiled = Precompile(params, a_max, omega, shape, cast(ExactSettings, settings))
    if settings.verbose:  # the baseline compiles and solves before the optimiser's own progress
        what = "sweeping the sinusoids, then " if sweep is None else ""
        refine = "refining " if settings.refine_baseline else "picking "
        print(f"the sinusoid baseline: {what}{refine}the best one (compiles on the first call)...",
              file=sys.stderr, flush=True)  # fmt: skip
    if sweep is None:
        dt = cast(ExactSettings, settings).dt if exact else cast(Settings, settings).verify_dt
        sweep = pareto.sinusoid_sweep(params, a_max, dt=dt)
    if not exact:
        opt = _optimise_smoothed(params, speed, direction, a_max, omega, harmonics, cast(Settings, settings), sweep)
    else:
        s = cast(ExactSettings, settings)
        baseline = _baseline(params, a_max, speed, direction, sweep, s.refine_baseline, s.dt)
        from ._exact import optimise_exact

        opt, _ = optimise_exact(params, speed, direction, a_max, omega, shape, s, baseline, start, precompiled)
    return dataclasses.replace(opt, screen=sweep._asdict())  # the baseline's sweep, kept for `sweep=` and its figure


def _guard_search(params: Params, omega: float | None, shape: Any, settings: ExactSettings) -> None:
    """Refuse a search whose steps (`settings.dt`, and `settings.search_dt` where given) do not
    resolve the mechanism's own scales (natural period, damping; `run._resolution`). The stroke's
    harmonics or knots at the highest frequency the search reaches are not guarded here: the
    verification solves each candidate at `dt` and `dt/2` and keeps only those that agree
    (`HALF_STEP_RTOL`), a convergence check."""
    from ._exact import _omega_bounds, GRID

    _, hi = _omega_bounds(params, omega, settings)
    one = jnp.asarray(1.0, params.dtype)
    wave = shape.waveform(jnp.asarray(shape.fit(np.zeros(GRID), hi), params.dtype), one, jnp.asarray(params.lbar))
    what = "given" if omega is not None else "ExactSettings.omega_max * wn1, the highest the search reaches"
    for name in ("dt", "search_dt"):
        dt = getattr(settings, name)
        if dt is not None:
            refuse_search(params, wave, dt, f"(optimise: omega = {hi:.6g}, {what}; the step is ExactSettings.{name}.)",
                          skip=("omega",))  # fmt: skip


def mechanism_optimum(mech: Any, v_min, a_max, method, direction, omega, harmonics, settings, sweep, start):
    """[`optimise`][] of a [`Mechanism`][locomotion_jax.Mechanism]: the method of `optimisation._mechanism`
    (sinusoids per actuated element, then their harmonics or splines refined on the exact model or,
    with `method="smoothed"`, their harmonics on the smoothed one)."""
    from ._mechanism import optimise_mechanism

    if not isinstance(mech, Mechanism):
        raise NotImplementedError(f"optimise takes Params, a Chain or a Mechanism, got {type(mech).__name__}.")
    return optimise_mechanism(mech, v_min, a_max, direction=1 if direction is None else direction, omega=omega,
                              harmonics=harmonics, settings=settings, start=start, method=method,
                              sweep=sweep)  # fmt: skip


def chain_optimum(chain: Chain, v_min, a_max, method, direction, omega, harmonics, settings, sweep, start):
    """[`optimise`][] of a [`Chain`][]: the method of `optimisation._chain` (travelling waves, then
    harmonics refined on the exact model or, with `method="smoothed"`, on the smoothed one)."""
    from ._chain import optimise_chain

    return optimise_chain(chain, v_min, a_max, direction=1 if direction is None else direction, omega=omega,
                          harmonics=harmonics, settings=settings, start=start, method=method, sweep=sweep)  # fmt: skip


def _baseline(params, a_max, speed, direction, sweep, refine: bool, dt: float) -> dict | None:
    if refine:
        return pareto.refine_sinusoid(params, a_max, speed, direction, sweep, dt=dt)
    return pareto.best_sinusoid(sweep, speed, direction)


def _optimise_smoothed(params, speed, direction, a_max, omega, harmonics, settings: Settings, sweep) -> Optimum:
    """The smoothed method (module docstring); inputs checked by `optimise`."""
    t0 = time.perf_counter()
    dtype = params.dtype
    baseline = _baseline(params, a_max, speed, direction, sweep, settings.refine_baseline, settings.verify_dt)
    omegas = _start_omegas(params, sweep, speed, direction, a_max, omega, settings)
    free = omega is None
    lo, hi = (min(omegas) / settings.omega_range, max(omegas) * settings.omega_range) if free else (omega, omega)
    guesses = initial_guesses(settings.starts, harmonics, omegas, settings.seed)
    theta = _stack(guesses, dtype)
    n = len(guesses)
    opt_state = jax.vmap(_optimizer().init)(theta)
    lam = jnp.zeros((n, 2), dtype)
    rho = jnp.full((n, 2), settings.rho0, dtype)
    v_target = jnp.full((n,), speed * (1 + settings.speed_slack), dtype)
    margin = jnp.full((n,), settings.margin, dtype)
    state = (theta, opt_state, lam, rho, v_target, margin)
    log: list[dict] = []

    centre = math.exp(np.mean(np.log(omegas)))

    def problem(eps):
        # Stability needs the step at the slowest admissible frequency; the transient and the
        # measurement are sized at the starts' centre (a drift to the range's end shortens
        # them by a factor of at most `omega_range` squared).
        # Every stage shares the finest stage's compiled loop (one compilation per optimisation).
        plan = make_plan(
            (params.m1, params.m2),
            lo,
            centre,
            eps,
            settings.transient,
            settings.measured,
            settings.backprop,
            eps_min=min(settings.eps_schedule),
        )
        return _Problem(
            params,
            jnp.asarray(a_max, dtype),
            jnp.asarray(direction, dtype),
            jnp.asarray(math.log(lo), dtype),
            jnp.asarray(math.log(hi), dtype),
            plan,
            settings.temperature,
            free,
        )

    lr = settings.learning_rate
    best_theta = theta  # replaced by the first stage (`eps_schedule` is never empty)
    for stage, eps in enumerate(settings.eps_schedule):
        lr = settings.learning_rate * settings.lr_decay**stage
        state, best_theta = _run_stage(state, problem(eps), eps, lr, settings, settings.outer, log)
    candidates = [("initial", theta), ("optimised", best_theta)]
    eps_f = settings.eps_schedule[-1]
    for round_ in range(settings.corrections):
        fig = pareto.exact_figures(
            _batched(params, n), _fourier_batch(best_theta, a_max, params.lbar), dt=settings.verify_dt
        )
        v_dir = direction * np.nan_to_num(fig.speed, nan=0.0)
        short = fig.ok & (v_dir < speed)
        if not (short.any() or (~fig.ok).any()):
            break
        # Defect correction: raise the smoothed target by the exact shortfall (at most 1.5x),
        # and the normal-force margin of starts that lift off.
        ratio = np.clip(speed / np.maximum(v_dir, 1e-12), 1.0, 1.5) * 1.02
        v_t = np.asarray(state[4]) * np.where(short, ratio, 1.0)
        m_t = np.asarray(state[5]) + np.where(fig.ok, 0.0, settings.margin_step)
        _, os_, lam_, rho_, _, _ = state
        state = (best_theta, os_, lam_, rho_, jnp.asarray(v_t, dtype), jnp.asarray(m_t, dtype))
        state, best_theta = _run_stage(state, problem(eps_f), eps_f, lr, settings, settings.correction_outer, log)
        candidates.append((f"corrected{round_ + 1}", best_theta))
    return _select(
        params, speed, direction, a_max, harmonics, free, settings, candidates, problem(eps_f), baseline, log, t0
    )


def _select(params, speed, direction, a_max, harmonics, free, settings, candidates, prob, baseline, log, t0):
    """Verify every candidate on the exact model and keep the cheapest feasible one."""
    dtype = params.dtype
    names = [f"{name} start {i}" for name, th in candidates for i in range(th["cos"].shape[0])]
    theta = jax.tree_util.tree_map(lambda *xs: jnp.concatenate(xs), *(th for _, th in candidates))
    n = theta["cos"].shape[0]
    eps_f = settings.eps_schedule[-1]
    cost_s, g_s, r_s = _evaluate(
        theta, prob, jnp.asarray(eps_f, dtype), jnp.full((n,), speed, dtype), jnp.full((n,), settings.margin, dtype)
    )
    fig = pareto.exact_figures(_batched(params, n), _fourier_batch(theta, a_max, params.lbar), dt=settings.verify_dt)
    strokes = a_max * np.asarray(jax.vmap(cons.stroke)(theta["cos"], theta["sin"]))
    k, feasible, exact = verified(fig, strokes, speed, direction, a_max, float(jnp.finfo(dtype).eps), baseline)
    v_s = np.asarray(r_s.distance / r_s.duration)
    with np.errstate(divide="ignore", invalid="ignore"):
        cost_s = np.asarray(r_s.dissipated) / np.abs(np.asarray(r_s.distance))
    table = [
        {
            "candidate": names[i],
            "omega": float(np.exp(theta["log_omega"][i])),
            "mean_speed_exact": float(fig.speed[i]),
            "cost_of_transport_exact": float(fig.cost[i]),
            "liftoff_exact": bool(fig.liftoff[i]),
            "stroke": float(strokes[i]),
            "feasible_exact": bool(feasible[i]),
            "mean_speed_smoothed": float(v_s[i]),
            "cost_of_transport_smoothed": float(cost_s[i]),
        }
        for i in range(n)
    ]
    init = [i for i in range(n) if names[i].startswith("initial") and feasible[i]]
    init_cost = min((float(fig.cost[i]) for i in init), default=math.nan)
    c = a_max * np.asarray(theta["cos"][k], float)
    s = a_max * np.asarray(theta["sin"][k], float)
    return Optimum(
        v_min=speed,
        direction=direction,
        a_max=float(a_max),
        margin=settings.margin,
        harmonics=harmonics,
        free_omega=free,
        cos=c,
        sin=s,
        omega=float(np.exp(theta["log_omega"][k])),
        lbar=float(params.lbar),
        **exact,
        mean_speed_smoothed=float(v_s[k]),
        cost_of_transport_smoothed=float(cost_s[k]),
        min_normal_smoothed=float(r_s.min_normal[k]),
        eps=eps_f,
        initial_cost_of_transport_exact=init_cost,
        source=names[k],
        candidates=table,
        history=log,
        runtime_s=time.perf_counter() - t0,
    )


def _batched(params: Params, n: int) -> Params:
    return jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (n,)), params.broadcast())


def _start_omegas(params, sweep, speed, direction, a_max, omega, settings: Settings) -> list[float]:
    """Base frequencies of the starts: the given one, else the best feasible sinusoids' frequencies."""
    if omega is not None:
        return [float(omega)]
    v = along(sweep.speed, direction)
    feasible = sweep.ok & (v >= speed)
    if feasible.any():
        order = np.argsort(np.where(feasible, sweep.cost, np.inf))
        picked: list[float] = []
        for i in order[: int(feasible.sum())]:
            w = float(sweep.omega[i])
            near = not picked or abs(math.log(w / picked[0])) <= math.log(settings.omega_range)
            if near and all(abs(math.log(w / p)) > math.log(1.2) for p in picked):
                picked.append(w)
            if len(picked) == settings.start_frequencies:
                break
        return picked
    # No sinusoid is fast enough: start where sinusoids are fastest.
    i = int(np.argmax(np.where(sweep.ok, v, -np.inf)))
    return [float(sweep.omega[i])]


optimize = optimise
"""The same function under its US spelling (the CLI's command is `optimize`)."""
