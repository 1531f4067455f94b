"""Differentiable steady-state objective for the actuation optimiser (SPEC §7).

A fixed-step RK4 rollout of the smoothed model, from the relaxed spring, over a
transient of whole periods followed by whole measured periods. Everything is a
pure function of one configuration; the optimiser `vmap`s it over its starts.

**Why a fixed-step integrator, not diffrax.** The smoothed friction is stiff
(slope $\\mu_s n / (m\\varepsilon)$ at $v = 0$), so an adaptive solve takes about
$1/\\varepsilon$ steps per time unit anyway, and its adjoint is much slower than
reverse mode through a `lax.scan` of RK4 steps with `jax.checkpoint` on every
period (memory: one period of residuals plus one state per period). With
$\\Delta t \\le 1.4\\,\\varepsilon$ RK4 stays inside its stability interval
($\\lambda \\Delta t \\le 2.78$) for normal forces up to twice the weight.

**Why not the law of `Smoothed` as is.** Its static bump has width
$v_s = \\sqrt{\\varepsilon}$: at $\\varepsilon = 10^{-3}$ that is 0.03, as large as
the sliding speeds, and the measured speed of a sinusoid is 25 % off the exact
model (omega = 6, a = 0.035). The law below is the same family with a narrower
bump, $v_s = \\sqrt{\\varepsilon_\\text{ref}\\,\\varepsilon}$, $\\varepsilon_\\text{ref} = 0.1$;
it still satisfies $v_s \\to 0$ and $v_s / \\varepsilon \\to \\infty$ as
$\\varepsilon \\to 0$, so it converges to the exact law, and at
$\\varepsilon = 10^{-4}$ speed and cost of transport agree with the exact engine
to about 1 % (omega = 1, 3, 6: a one-off check, not a test; every optimum is
verified on the exact engine, `_optimise`).
"""

import math
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from .._custom_types import Array
from ..model import _two_mass as model
from ..model._chain_array import engine_physics, GAIT_ARRAY_FROM
from ..model._friction import Coulomb
from ..model._params import Params
from ..model._waveform import Fourier


EPS_REF = 0.1
"""Reference velocity of the static bump: $v_s = \\sqrt{\\varepsilon_\\text{ref}\\,\\varepsilon}$."""

STABILITY = 1.4
"""Largest RK4 step in units of $\\varepsilon$ (see the module docstring)."""


def friction_coefficient(v: Array, params: Params, eps: Array) -> Array:
    """The paper's law smoothed ([`AbstractFriction.smoothed`][locomotion_jax.AbstractFriction.smoothed] of
    [`Coulomb`][]), with a narrower static bump than `Smoothed` (module docstring):

    $$\\mu(v) = \\big[\\mu_k + (\\mu_s - \\mu_k) e^{-(v/v_s)^2}\\big] \\tanh(v/\\varepsilon),
    \\qquad v_s = \\sqrt{\\varepsilon_\\text{ref}\\,\\varepsilon}.$$
    """
    return Coulomb(params.mu_s, params.mu_k).smoothed(v, eps, jnp.sqrt(EPS_REF * eps))


def rates(params: Params, wave: Fourier, eps: Array, t: Array, y: Array) -> tuple[Array, Array]:
    """Right-hand side on `y = (x1, v1, x2, v2, e_d)`; also returns $\\min(N_1, N_2)$.

    Forces, eqs. (2, 5, 8) via `_two_mass.forces` with the paper's $n_i = |N_i|$
    (so that an infeasible iterate that lifts off stays bounded; the signed
    $N_i$ enter the no-lift-off constraint). Eq. (9) with smoothed friction (`_two_mass.smoothed_rates`);
    the last rate is the integrand of eq. (15).
    """
    f = model.forces(params, wave, t, y[0], y[2], "paper")
    a1, a2, p_d = model.smoothed_rates(params, f, y[1], y[3], lambda v: friction_coefficient(v, params, eps))
    return jnp.stack([y[1], a1, y[3], a2, p_d]), jnp.minimum(f.N1, f.N2)


class Plan(eqx.Module):
    """Step counts of one rollout.

    - `steps_per_period`: RK4 steps per actuation period (a traced integer, so that
      the stages of an $\\varepsilon$ continuation share one compilation).
    - `max_steps_per_period`: the compiled length of a period's loop; steps past
      `steps_per_period` are skipped by a `lax.cond`.
    - `transient_periods`: periods discarded before measuring.
    - `measured_periods`: periods over which speed and cost are measured.
    - `detached_periods`: leading transient periods integrated without gradient
      (truncated backpropagation, see [`rollout`][]); 0 differentiates everything.
    """

    steps_per_period: Array
    max_steps_per_period: int = eqx.field(static=True)
    transient_periods: int = eqx.field(static=True)
    measured_periods: int = eqx.field(static=True)
    detached_periods: int = eqx.field(static=True, default=0)

    @property
    def periods(self) -> int:
        return self.transient_periods + self.measured_periods


def make_plan(
    masses: Sequence[Any],
    omega_lo: float,
    omega_hi: float,
    eps: float,
    transient: float,
    measured: float,
    backprop: float | None = None,
    eps_min: float | None = None,
) -> Plan:
    """Step counts for base frequencies in `[omega_lo, omega_hi]`, for bodies of masses `masses`.

    The step $\\Delta t = (2\\pi/\\omega)/s$ must stay below the stability limit at
    the slowest frequency (`STABILITY` times the ratio of the lightest to the heaviest mass); the
    transient must last `transient` time units and the
    measurement `measured` time units (and at least two periods) at the fastest.
    `backprop`: time units of the transient's end that are differentiated
    (`None`: all of it). `eps_min`: the finest $\\varepsilon$ the compiled loop must
    serve (default `eps`); plans made for any `eps >= eps_min` have the same static
    shape, and differ only in the traced step count.
    """
    eps_min = eps if eps_min is None else eps_min
    if not eps_min <= eps:
        raise ValueError(f"eps_min must be <= eps, got eps_min={eps_min} and eps={eps}")
    m = [float(x) for x in masses]
    period_lo, period_hi = 2 * math.pi / omega_hi, 2 * math.pi / omega_lo

    def steps(e: float) -> int:
        # Stability: lambda = mu_s n / (m eps), n up to about twice the heaviest weight.
        dt_max = STABILITY * e * min(m) / max(m)
        return max(16, math.ceil(period_hi / dt_max))

    transient_periods = max(1, math.ceil(transient / period_lo))
    kept = transient_periods if backprop is None else min(transient_periods, max(1, math.ceil(backprop / period_lo)))
    return Plan(
        steps_per_period=jnp.asarray(steps(eps), jnp.int32),
        max_steps_per_period=steps(eps_min),
        transient_periods=transient_periods,
        measured_periods=max(2, math.ceil(measured / period_lo)),
        detached_periods=transient_periods - kept,
    )


class Rollout(NamedTuple):
    """Steady-state figures of one smoothed rollout (all scalars).

    - `distance`: $\\Delta X$ over the measured periods (eq. 4), signed.
    - `dissipated`: $e_d$ over the measured periods (eq. 15).
    - `duration`: length of the measured interval.
    - `min_normal`: soft minimum of $N_1, N_2$ over the whole run (transient
      included), a lower bound of the sampled minimum (see [`rollout`][]).
    - `drift`: relative change of $\\Delta X$ per period between the last two
      periods (0 in a periodic steady state; a diagnostic of the transient).
    """

    distance: Array
    dissipated: Array
    duration: Array
    min_normal: Array
    drift: Array


def rollout(params: Params, wave: Fourier, eps: Array, plan: Plan, temperature: float) -> Rollout:
    """Integrate the paper's smoothed model from the relaxed spring and measure the steady state
    ([`integrate`][] of [`rates`][]).

    Start: $x_1 = 0$, $x_2 = \\sqrt{\\bar\\ell^2 - d^2}$ (spring at rest, SPEC §1
    "relaxed"), at rest."""
    dtype = params.dtype
    gap = model.initial_gap(params, "relaxed")
    zero = jnp.zeros_like(gap)
    y0 = jnp.stack([zero, zero, gap, zero, zero]).astype(dtype)
    return integrate(
        (params, wave),
        lambda inputs: lambda t, y: rates(inputs[0], inputs[1], eps, t, y),
        lambda inputs, y: jnp.stack([model.centre_of_mass(inputs[0], y[0], y[2]), y[4]]),
        lambda inputs: 2 * jnp.pi / inputs[1].omega,
        y0,
        plan,
        temperature,
    )


def element_rollout(mechanism: Any, cos: Array, sin: Array, omega: Array, eps: Array, plan: Plan,
                    temperature: float) -> Rollout:  # fmt: skip
    """Integrate a chain or a mechanism (`mechanism`, one configuration) with its actuated signals
    driven by the Fourier series `cos`, `sin` (shape `(S, H)`, absolute units) of base frequency
    `omega` (its `with_fourier`), its friction
    smoothed as [`friction_coefficient`][]'s (each body's law's `smoothed`, the static bump of width
    $\\sqrt{\\varepsilon_\\text{ref}\\,\\varepsilon}$; the paper's reading $n_i = |N_i|$, as [`rates`][]), from
    the start of the optimisers' direct simulation (a chain's relaxed springs, a mechanism's own
    start), and measure the steady state ([`integrate`][]; `min_normal` over the bodies on the ground)."""
    from ..dynamics import _smoothed as smoothed

    def physics(inputs):
        model, cos, sin, omega = inputs
        # A chain in the layout of its steady gaits: the array layout keeps the differentiated
        # rollout's program the same size at any N.
        return engine_physics(model.with_fourier(cos, sin, omega), GAIT_ARRAY_FROM)

    def rates_of(inputs):
        P = physics(inputs)
        return lambda t, y: smoothed.rates_and_normal(P, "paper", eps, t, y, jnp.sqrt(EPS_REF * eps))

    def figures_of(inputs, y):
        P = physics(inputs)
        return jnp.stack([smoothed.centre_of_mass(P, y), y[2 * P.n_bodies]])

    inputs = (mechanism, cos, sin, omega)
    y0 = smoothed.initial_state(physics(inputs), "relaxed", None)
    return integrate(inputs, rates_of, figures_of, lambda inputs: 2 * jnp.pi / inputs[3], y0, plan, temperature)


def integrate(inputs: Any, rates_of: Callable, figures_of: Callable, period_of: Callable, y0: Array, plan: Plan,
              temperature: float) -> Rollout:  # fmt: skip
    """Integrate a smoothed model from `y0` and measure its steady state: the rollout of
    [`rollout`][] and [`element_rollout`][], written once.

    `inputs` is the pytree differentiated through (what truncated backpropagation detaches);
    `rates_of(inputs)` the right-hand side `(t, y) -> (dy/dt, smallest normal force)`,
    `figures_of(inputs, y)` the centre of mass and the dissipated energy $e_d$ of a state, and
    `period_of(inputs)` the actuation period.

    Classical RK4 with $\\Delta t = T/s$ in a `lax.scan`; every period is a `jax.checkpoint`ed
    inner scan, so reverse mode stores one state per period and recomputes the steps of one
    period at a time. The inner scan has `plan.max_steps_per_period` iterations and runs the
    first `plan.steps_per_period` of them, so one compiled rollout serves every $\\varepsilon$ of
    a continuation (see [`make_plan`][]).
    With `plan.detached_periods > 0` the first transient periods run without
    gradient (truncated backpropagation; off by default). It is only an
    approximation: with the light damping c = 0.01 the memory of the state is
    long, and at omega = 4 with 3 differentiated transient periods the gradient
    was 10-30 % off (more for omega) for a 1.5x saving, so the optimiser
    differentiates the whole run unless asked (`Settings.backprop`).

    The soft minimum of the normal forces is the streaming log-sum-exp
    $m - T \\log \\sum_j e^{-(N_j - m)/T}$ over all step starts ($m$ the running
    minimum): smooth, and never above the sampled minimum, so the constraint
    `min_normal >= margin` is conservative (by at most $T \\log(\\#\\text{steps})$).
    """
    dtype = y0.dtype
    s = plan.steps_per_period
    period = period_of(inputs)

    def make_step(inputs):
        dt = period_of(inputs) / s.astype(dtype)
        f = rates_of(inputs)

        def rk4(carry):
            t, y, m, acc = carry
            k1, n_min = f(t, y)
            k2, _ = f(t + 0.5 * dt, y + (0.5 * dt) * k1)
            k3, _ = f(t + 0.5 * dt, y + (0.5 * dt) * k2)
            k4, _ = f(t + dt, y + dt * k3)
            y = y + (dt / 6) * (k1 + 2 * k2 + 2 * k3 + k4)
            m_new = jnp.minimum(m, n_min)
            acc = acc * jnp.exp((m_new - m) / temperature) + jnp.exp((m_new - n_min) / temperature)
            return t + dt, y, m_new, acc

        def step(carry, i):
            # The loop has the finest stage's length; a coarser stage skips the rest. The
            # predicate is the same for every start, so under vmap this stays a branch.
            return jax.lax.cond(i < s, rk4, lambda c: c, carry), None

        return step

    def periods(inputs, carry, count, checkpoint):
        # Checkpointing each step as well as each period halves the cost of reverse mode:
        # the inner backward pass then stores only carries instead of every RK4 stage.
        step = make_step(inputs)
        step = jax.checkpoint(step) if checkpoint else step

        def one_period(carry, _):
            carry, _ = jax.lax.scan(step, carry, jnp.arange(plan.max_steps_per_period))
            return carry, figures_of(inputs, carry[1])

        one_period = jax.checkpoint(one_period) if checkpoint else one_period
        return jax.lax.scan(one_period, carry, None, length=count)

    # The running minimum starts at N(0) with an empty sum; the first step adds N(0).
    t0 = jnp.zeros((), dtype)
    carry = (t0, y0, rates_of(inputs)(t0, y0)[1], jnp.zeros((), dtype))
    if plan.detached_periods:
        # Truncated backpropagation: the start of the transient only has to forget the
        # initial state; the steady state does not depend on it, so it runs without gradient.
        detach = jax.lax.stop_gradient
        carry, _ = periods(detach(inputs), carry, plan.detached_periods, False)
        # Time restarts on a period boundary as a function of omega, so that the phase
        # omega * t stays exactly 2 pi k under differentiation.
        carry = (plan.detached_periods * period,) + detach(carry[1:])
    (_, _, m, acc), ends = periods(inputs, carry, plan.periods - plan.detached_periods, True)
    k0 = plan.transient_periods - plan.detached_periods - 1
    distance = ends[-1, 0] - ends[k0, 0]
    dissipated = ends[-1, 1] - ends[k0, 1]
    last, before = ends[-1, 0] - ends[-2, 0], ends[-2, 0] - ends[-3, 0]
    drift = (last - before) / jnp.maximum(jnp.abs(last), jnp.finfo(dtype).tiny)
    return Rollout(
        distance=distance,
        dissipated=dissipated,
        duration=plan.measured_periods * period,
        min_normal=m - temperature * jnp.log(acc),
        drift=drift,
    )
