"""Exact hybrid stick/slip dynamics (eqs. 7, 9; corrected per SPEC §2).

One configuration, one iteration at a time: callers run [`step`][] inside a
`lax.while_loop` and batch with `vmap`.

**Scheme.** Inside a mode the dynamics is a smooth ODE, integrated with classical
RK4 at a nominal step `dt`. Mode switches are events, located by treating the
step length itself as the unknown: a trial step that ends past an event (an event
function changed sign) is not committed; the next iteration retries with the
Illinois (modified regula falsi) estimate of the crossing, committing every trial
that stays before it. A switch is applied once the bracket is narrower than a few
ulps of `t`. The switching state is therefore an RK4 state, not an interpolant,
and the results converge at fourth order in `dt` (tests/test_convergence.py).
Every iteration costs the same (under `vmap` there is no cheap branch), so the
search adds iterations only where there are events.

**Events** (each fires when its function goes from $\\ge 0$ to $< 0$):

- a slipping mass $i$ with slip direction $\\sigma_i$: $\\sigma_i v_i$ (velocity zero);
- a stuck mass $i$: $\\mu_s n_i - |F_i|$ (static friction exceeded, eq. 7);
- strict contact only: $N_1$, $N_2$ (lift-off, eq. 5), which stops the run.

After any switch both masses are re-checked at the switching state (SPEC §2):
the forces depend only on positions and time, never on the other mass's mode, so
each mass's stick condition can be decided on its own, and exactly simultaneous
events (by symmetry when $d = 0$, $m_1 = m_2$) fire together.

Limitation: a sign change that starts and ends inside one step (a grazing
excursion shorter than `dt`) is not seen; only grazing contacts are affected.
"""

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from . import _model as model
from ._actuation import AbstractWaveform
from ._custom_types import Array, Bool, Contact, Float, FloatScalar, IntScalar
from ._params import Params
from ._status import Status


MAX_SEARCH = 60
"""Hard cap on Illinois iterations for one event (guards against any Zeno stall)."""


class Hybrid(eqx.Module):
    """Integrator state of one configuration (a pytree of arrays).

    `y = (x1, v1, x2, v2, e_d, w)`. `k1` caches the rates at `(t, y)` in the
    current mode (first same as last). `search`/`hi`/`g0`/`ghi`/`side` hold the
    event bracket `[t, t + hi]` while an event is being located.
    """

    t: FloatScalar
    y: Float[Array, "6"]
    stuck: Bool[Array, "2"]
    sdir: Float[Array, "2"]
    k1: Float[Array, "6"]
    comp: Float[Array, "6"]
    g0: FloatScalar
    search: Array
    hi: FloatScalar
    ghi: FloatScalar
    side: IntScalar
    n_search: IntScalar
    status: IntScalar
    t_liftoff: FloatScalar
    n_switch: IntScalar


class StepInfo(NamedTuple):
    """What one iteration did, for measurements: the committed interval
    `[t0, t1]` with the end states and rates needed for cubic Hermite dense output
    (before any switch at `t1`)."""

    commit: Array
    switch: Array
    t0: Array
    t1: Array
    y0: Array
    f0: Array
    y1: Array
    f1: Array
    stuck0: Array


def rates(params: Params, f: model.Forces, y: Array, stuck: Array, sdir: Array) -> Array:
    """Right-hand side in a fixed mode: eq. (9) corrected per SPEC §2.

    Slipping: $m_i \\dot v_i = F_i - c v_i - \\mu_k n_i \\sigma_i$ with $F_1 = f_x$,
    $F_2 = -f_x$. Stuck: $\\dot x_i = \\dot v_i = 0$. The last two entries are the
    integrands of $e_d$ (eq. 15; $|v_i| = \\sigma_i v_i$ inside a slip segment, which
    keeps the integrand smooth there) and of $w$ (eq. 16).
    """
    v1, v2 = y[1], y[3]
    a1 = (f.fx - params.c * v1 - params.mu_k * f.n1 * sdir[0]) / params.m1
    a2 = (-f.fx - params.c * v2 - params.mu_k * f.n2 * sdir[1]) / params.m2
    zero = jnp.zeros_like(v1)
    dx1 = jnp.where(stuck[0], zero, v1)
    dx2 = jnp.where(stuck[1], zero, v2)
    a1 = jnp.where(stuck[0], zero, a1)
    a2 = jnp.where(stuck[1], zero, a2)
    p_d = params.mu_k * (f.n1 * sdir[0] * dx1 + f.n2 * sdir[1] * dx2) + params.c * (dx1 * dx1 + dx2 * dx2)
    p_w = model.actuator_power(f)
    return jnp.stack([dx1, a1, dx2, a2, p_d, p_w])


def event_values(params: Params, f: model.Forces, y: Array, stuck: Array, sdir: Array, contact: Contact) -> Array:
    """The four event functions (module docstring); an event fires below zero."""
    F = jnp.stack([f.fx, -f.fx])
    n = jnp.stack([f.n1, f.n2])
    v = jnp.stack([y[1], y[3]])
    g_mass = jnp.where(stuck, params.mu_s * n - jnp.abs(F), sdir * v)
    if contact == "strict":
        g_lift = jnp.stack([f.N1, f.N2])
    else:  # the paper's reading integrates through lift-off; flagged, not located
        g_lift = jnp.full((2,), jnp.inf, dtype=v.dtype)
    return jnp.concatenate([g_mass, g_lift])


def _forces_at(params, wave, contact, t, y):
    return model.forces(params, wave, t, y[0], y[2], contact)


def resolve_modes(params: Params, f: model.Forces, y: Array, stuck: Array, sdir: Array, fired: Array):
    """Apply the switches of the fired events at one state (SPEC §2).

    A fired stuck mass starts to slip in the direction of $F_i$. A fired slipping
    mass has reached $v_i = 0$: it sticks if $|F_i| \\le \\mu_s n_i$ (eq. 7), otherwise
    the friction reverses ($\\sigma_i = \\operatorname{sgn} F_i$).
    """
    F = jnp.stack([f.fx, -f.fx])
    n = jnp.stack([f.n1, f.n2])
    can_stick = jnp.abs(F) <= params.mu_s * n
    to_dir = jnp.where(F >= 0, 1.0, -1.0).astype(sdir.dtype)
    vel_fired = fired[:2] & ~stuck
    stat_fired = fired[:2] & stuck
    new_stuck = jnp.where(vel_fired, can_stick, jnp.where(stat_fired, False, stuck))
    new_sdir = jnp.where(vel_fired | stat_fired, to_dir, sdir)
    zero = jnp.zeros_like(y[1])
    y = y.at[1].set(jnp.where(vel_fired[0], zero, y[1]))
    y = y.at[3].set(jnp.where(vel_fired[1], zero, y[3]))
    return y, new_stuck, new_sdir


def init(params: Params, wave: AbstractWaveform, contact: Contact, x1: Array, x2: Array) -> Hybrid:
    """State at $t = 0$ with both masses at rest; each mass sticks if eq. (7) allows."""
    dtype = params.dtype
    t = jnp.zeros((), dtype)
    y = jnp.stack([x1, 0 * x1, x2, 0 * x2, 0 * x1, 0 * x1]).astype(dtype)
    f = _forces_at(params, wave, contact, t, y)
    F = jnp.stack([f.fx, -f.fx])
    n = jnp.stack([f.n1, f.n2])
    stuck = jnp.abs(F) <= params.mu_s * n
    sdir = jnp.where(F >= 0, 1.0, -1.0).astype(dtype)
    k1 = rates(params, f, y, stuck, sdir)
    g0 = jnp.min(event_values(params, f, y, stuck, sdir, contact))
    lifted = (f.N1 <= 0) | (f.N2 <= 0) if contact == "strict" else jnp.asarray(False)
    status = jnp.where(lifted, Status.LIFTOFF, Status.OK).astype(jnp.int32)
    t_lift = jnp.where(lifted, t, jnp.inf)
    if contact == "paper":
        t_lift = jnp.where((f.N1 <= 0) | (f.N2 <= 0), t, jnp.inf)
    zi = jnp.zeros((), jnp.int32)
    return Hybrid(
        t=t, y=y, stuck=stuck, sdir=sdir, k1=k1, comp=jnp.zeros_like(y), g0=jnp.maximum(g0, 0).astype(dtype),
        search=jnp.asarray(False), hi=jnp.zeros((), dtype), ghi=jnp.zeros((), dtype),
        side=zi, n_search=zi, status=status, t_liftoff=t_lift.astype(dtype), n_switch=zi,
    )


def _rk4(params, wave, contact, t, y, k1, stuck, sdir, h):
    """Classical RK4 in a fixed mode; returns the increment of the state."""
    # k2 and k3 share t + h/2: evaluate the actuation there once.
    l0m, dl0m = wave(t + 0.5 * h)
    y2 = y + 0.5 * h * k1
    k2 = rates(params, model.spring_forces(params, l0m, dl0m, y2[0], y2[2], contact), y2, stuck, sdir)
    y3 = y + 0.5 * h * k2
    k3 = rates(params, model.spring_forces(params, l0m, dl0m, y3[0], y3[2], contact), y3, stuck, sdir)
    y4 = y + h * k3
    k4 = rates(params, _forces_at(params, wave, contact, t + h, y4), y4, stuck, sdir)
    return (h / 6) * (k1 + 2 * k2 + 2 * k3 + k4)


def _kahan_add(y: Array, comp: Array, incr: Array) -> tuple[Array, Array]:
    corrected = incr - comp
    total = y + corrected
    return total, (total - y) - corrected


def step(
    params: Params, wave: AbstractWaveform, contact: Contact, dt: float, st: Hybrid, t_stop: Array
) -> tuple[Hybrid, StepInfo]:
    """One iteration: a trial RK4 step, committed unless it passes an event.

    The step never passes `t_stop` (a measurement boundary or save time) and
    lands on it exactly.
    """
    dtype = st.y.dtype
    eps = jnp.finfo(dtype).eps
    tol = 4 * eps * jnp.maximum(jnp.abs(st.t), 1)
    span = t_stop - st.t
    lands = span <= dt
    h_nom = jnp.minimum(jnp.asarray(dt, dtype), span)
    # Illinois estimate of the crossing inside the bracket [0, hi] (g0 >= 0 > ghi).
    secant = st.hi * st.g0 / (st.g0 - st.ghi)
    secant = jnp.where(jnp.isfinite(secant) & (secant > 0) & (secant < st.hi), secant, 0.5 * st.hi)
    trial = jnp.where(st.hi <= tol, st.hi, secant)
    h = jnp.where(st.search, trial, h_nom)
    t1 = jnp.where(~st.search & lands, t_stop, st.t + h)
    # Step by the representable difference so that time and state stay consistent
    # (in float32 at t ~ 1e3, t + h rounds h by up to 1e-3 relative).
    h = t1 - st.t

    incr = _rk4(params, wave, contact, st.t, st.y, st.k1, st.stuck, st.sdir, h)
    # Compensated (Kahan) update: positions and energies grow to O(10-100) while
    # increments are O(1e-4); plain float32 sums would lose ~1e-3 over 1e5 steps.
    y1, comp1 = _kahan_add(st.y, st.comp, incr)
    f_end = _forces_at(params, wave, contact, t1, y1)
    k_end = rates(params, f_end, y1, st.stuck, st.sdir)
    g_end = event_values(params, f_end, y1, st.stuck, st.sdir, contact)
    G1 = jnp.min(g_end)
    crossed = G1 < 0
    converged = (h <= tol) | (st.n_search >= MAX_SEARCH)
    commit = ~crossed | converged
    switch = crossed & converged

    # Switch (if any) at the committed end state.
    fired = g_end < 0
    y_sw, stuck_sw, sdir_sw = resolve_modes(params, f_end, y1, st.stuck, st.sdir, fired)
    lift = switch & (fired[2] | fired[3])
    k_sw = rates(params, f_end, y_sw, stuck_sw, sdir_sw)
    g_sw = jnp.maximum(jnp.min(event_values(params, f_end, y_sw, stuck_sw, sdir_sw, contact)), 0)

    y_new = jnp.where(switch, y_sw, y1)
    stuck_new = jnp.where(switch, stuck_sw, st.stuck)
    sdir_new = jnp.where(switch, sdir_sw, st.sdir)
    k_new = jnp.where(switch, k_sw, k_end)
    # Bracket bookkeeping (Illinois: halve the stale end's value on a repeated side).
    remaining = st.hi - h
    keep_search = st.search & ~crossed & (remaining > 0)
    start_or_shrink = crossed & ~converged
    g0_commit = jnp.where(switch, g_sw, jnp.maximum(G1, 0))
    g0_new = jnp.where(commit, g0_commit, jnp.where(st.side == -1, 0.5 * st.g0, st.g0))
    ghi_new = jnp.where(
        start_or_shrink, G1, jnp.where(keep_search & (st.side == 1), 0.5 * st.ghi, st.ghi)
    )
    hi_new = jnp.where(start_or_shrink, h, jnp.where(keep_search, remaining, 0))
    side_new = jnp.where(start_or_shrink, -1, jnp.where(keep_search, 1, 0)).astype(jnp.int32)
    search_new = start_or_shrink | keep_search
    n_search_new = jnp.where(search_new, st.n_search + 1, 0).astype(jnp.int32)

    status = jnp.where(lift, Status.LIFTOFF, st.status).astype(jnp.int32)
    t_lift = jnp.where(lift & ~jnp.isfinite(st.t_liftoff), t1, st.t_liftoff)
    if contact == "paper":  # flagged only (at committed step ends), never stops
        touched = commit & ((f_end.N1 <= 0) | (f_end.N2 <= 0))
        t_lift = jnp.where(touched & ~jnp.isfinite(st.t_liftoff), t1, t_lift)

    new = Hybrid(
        t=jnp.where(commit, t1, st.t),
        y=jnp.where(commit, y_new, st.y),
        stuck=jnp.where(commit, stuck_new, st.stuck),
        sdir=jnp.where(commit, sdir_new, st.sdir),
        k1=jnp.where(commit, k_new, st.k1),
        # A switch sets velocities exactly (to 0): drop their pending compensation.
        comp=jnp.where(commit, jnp.where(switch & (y_new != y1), 0, comp1), st.comp),
        g0=g0_new.astype(dtype),
        search=search_new,
        hi=hi_new.astype(dtype),
        ghi=ghi_new.astype(dtype),
        side=side_new,
        n_search=n_search_new,
        status=status,
        t_liftoff=t_lift.astype(dtype),
        n_switch=st.n_switch + switch.astype(jnp.int32),
    )
    info = StepInfo(commit, switch, st.t, t1, st.y, st.k1, y1, k_end, st.stuck)
    return new, info


def hermite(info: StepInfo, theta: Array) -> Array:
    """Cubic Hermite dense output on the committed interval, $\\theta \\in [0, 1]$."""
    h = info.t1 - info.t0
    t2 = theta * theta
    t3 = t2 * theta
    h00 = 2 * t3 - 3 * t2 + 1
    h10 = t3 - 2 * t2 + theta
    h01 = -2 * t3 + 3 * t2
    h11 = t3 - t2
    return h00 * info.y0 + (h10 * h) * info.f0 + h01 * info.y1 + (h11 * h) * info.f1


def illinois(fn, lo: Array, hi: Array, flo: Array, fhi: Array, iters: int) -> tuple[Array, Array]:
    """Bracketed root of a scalar function with `flo >= 0 > fhi`; returns `(lo, hi)`."""

    def body(_, carry):
        lo, hi, flo, fhi, side = carry
        m = (lo * fhi - hi * flo) / (fhi - flo)
        m = jnp.where(jnp.isfinite(m) & (m > lo) & (m < hi), m, 0.5 * (lo + hi))
        fm = fn(m)
        left = fm >= 0
        new_lo, new_flo = jnp.where(left, m, lo), jnp.where(left, fm, flo)
        new_hi, new_fhi = jnp.where(left, hi, m), jnp.where(left, fhi, fm)
        new_fhi = jnp.where(left & (side == 1), 0.5 * new_fhi, new_fhi)
        new_flo = jnp.where(~left & (side == -1), 0.5 * new_flo, new_flo)
        return new_lo, new_hi, new_flo, new_fhi, jnp.where(left, 1, -1).astype(jnp.int32)

    lo, hi, *_ = jax.lax.fori_loop(0, iters, body, (lo, hi, flo, fhi, jnp.zeros((), jnp.int32)))
    return lo, hi
