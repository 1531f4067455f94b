"""Smoothed dynamics (SPEC §3), integrated with diffrax; differentiable.

The friction law is documented in [`Smoothed`][]. Lift-off under the strict
reading is a terminating diffrax event located by a root finder.

Sticking has no exact meaning for a smooth law: below the static limit a mass
creeps at $|v| = \\varepsilon\\,\\mathrm{artanh}(|F|/\\mu_s n)$, a few
$\\varepsilon$ at most. A sample counts as stuck when $|v_i| < 3\\varepsilon$; the
regime is SSL when such samples run contiguously for longer than `MIN_STICK`
(a velocity merely passing through zero is shorter). The exact engine is the
reference for the regime; this one is approximate near the SSL/SL boundary.
"""

from typing import TYPE_CHECKING

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx

from .._custom_types import Array, Contact
from .._status import mode_code, Regime, Status
from ..model import _two_mass as model
from ..model._friction import Coulomb
from ..model._params import Params, safe_params
from ..model._waveform import AbstractWaveform


if TYPE_CHECKING:  # the class runs this engine: imported for annotations only
    from ._smoothed_dynamics import Smoothed


STICK_SPEED = 3.0  # in units of eps
MIN_STICK = 0.05  # shortest stuck interval (time units) that makes SSL
WINDOW_SAMPLES = 2501


def friction_coefficient(v: Array, params: Params, eps: Array) -> Array:
    """The paper's law smoothed ([`AbstractFriction.smoothed`][locomotion_jax.AbstractFriction.smoothed]
    of [`Coulomb`][]) with $v_s = \\sqrt{\\varepsilon}$:
    $[\\mu_k + (\\mu_s - \\mu_k) e^{-(v/v_s)^2}]\\tanh(v/\\varepsilon)$."""
    return Coulomb(params.mu_s, params.mu_k).smoothed(v, eps, jnp.sqrt(eps))


def smooth_rates(params: Params, wave: AbstractWaveform, contact: Contact, eps: Array, t, y) -> Array:
    """Right-hand side of the smoothed model; state `(x1, v1, x2, v2, e_d, w)`."""
    f = model.forces(params, wave, t, y[0], y[2], contact)
    a1, a2, p_d = model.smoothed_rates(params, f, y[1], y[3], lambda v: friction_coefficient(v, params, eps))
    return jnp.stack([y[1], a1, y[3], a2, p_d, model.actuator_power(f)])


def _solver(dyn: "Smoothed"):
    return diffrax.Tsit5() if dyn.solver == "tsit5" else diffrax.Kvaerno5()


def _liftoff_fn(params, wave, contact):
    def cond(t, y, args, **kwargs):
        f = model.forces(params, wave, t, y[0], y[2], contact)
        return jnp.minimum(f.N1, f.N2)

    return cond


def solve(params, wave, contact, dyn: "Smoothed", t0, t1, y0, saveat, extra_events=()):
    """One diffrax solve; a strict-contact lift-off, the masses meeting (the gap $x_2 - x_1$
    reaching zero, event `met_index`) and any `extra_events` terminate it."""
    term = diffrax.ODETerm(lambda t, y, args: smooth_rates(params, wave, contact, dyn.eps, t, y))
    conds = list(extra_events)
    if contact == "strict":
        conds.append(_liftoff_fn(params, wave, contact))
    conds.append(lambda t, y, args, **kwargs: y[2] - y[0])
    event = None
    if conds:
        event = diffrax.Event(conds, root_finder=optx.Newton(rtol=1e-10, atol=1e-12))
    return diffrax.diffeqsolve(
        term,
        _solver(dyn),
        t0,
        t1,
        None,
        y0,
        saveat=saveat,
        stepsize_controller=diffrax.PIDController(rtol=dyn.rtol, atol=dyn.atol, dtmin=None),
        max_steps=dyn.max_steps,
        event=event,
        throw=False,
    )


def _y0(params, start):
    dtype = params.dtype
    gap = model.initial_gap(params, start)
    return jnp.stack([0 * gap, 0 * gap, gap, 0 * gap, 0 * gap, 0 * gap]).astype(dtype)


def _longest_run(flags: Array) -> Array:
    """Longest run of consecutive True samples, over both masses (`flags`: (n, 2))."""

    def body(run, f):
        run = jnp.where(f, run + 1, 0)
        return run, run

    _, runs = jax.lax.scan(body, jnp.zeros(flags.shape[1:], jnp.int32), flags)
    return jnp.max(runs)


def _saved(sol: diffrax.Solution) -> tuple[Array, Array]:
    """`(sol.ts, sol.ys)`, which every `SaveAt` here requests (diffrax types them optional)."""
    assert sol.ts is not None and sol.ys is not None
    return sol.ts, sol.ys


def _event_hit(sol, k) -> Array:
    if sol.event_mask is None:
        return jnp.asarray(False)
    return jnp.asarray(sol.event_mask[k])


def met_index(contact: Contact, n_extra: int = 0) -> int:
    """The index of the event "the masses met" in a `solve` with `n_extra` extra events."""
    return n_extra + (1 if contact == "strict" else 0)


def _failed(sol) -> Array:
    ok = (sol.result == diffrax.RESULTS.successful) | (sol.result == diffrax.RESULTS.event_occurred)
    return ~ok


def simulate_one(params, wave, save, contact, start, dyn):
    params, valid = safe_params(params, wave)
    y0 = _y0(params, start)
    # The motion starts at t = 0 whatever the first save time.
    sol = solve(params, wave, contact, dyn, jnp.zeros_like(save[0]), save[-1], y0, diffrax.SaveAt(ts=save, t1=True))
    sol_ts, sol_ys = _saved(sol)
    ys = sol_ys[:-1]  # (n, 6); inf after a terminating event
    t_final = sol_ts[-1]
    ok_rows = jnp.all(jnp.isfinite(ys), axis=-1) & valid
    last = jnp.max(jnp.where(ok_rows, jnp.arange(ys.shape[0]), 0))
    ys = jnp.where(ok_rows[:, None], ys, ys[last][None, :])
    lift = _event_hit(sol, 0) if contact == "strict" else jnp.asarray(False)
    met = _event_hit(sol, met_index(contact))  # the masses met (outside the model): the run stops there
    status = jnp.where(lift, Status.LIFTOFF, jnp.where(_failed(sol), Status.SOLVER_FAILED, Status.OK))
    status = jnp.where(met, Status.COLLISION, status)
    status = jnp.where(valid, status, Status.INVALID).astype(jnp.int32)
    t_lift = jnp.where(lift, t_final, jnp.inf)

    def derived(t, y):
        f = model.forces(params, wave, t, y[0], y[2], contact)
        r = smooth_rates(params, wave, contact, dyn.eps, t, y)
        stuck = jnp.abs(jnp.stack([y[1], y[3]])) < STICK_SPEED * dyn.eps
        return dict(
            e=model.total_energy(params, f.l0, y[0], y[1], y[2], y[3]),
            l0=f.l0,
            N1=f.N1,
            N2=f.N2,
            f_ex=params.m1 * r[1] + params.m2 * r[3],
            X=model.centre_of_mass(params, y[0], y[2]),
            stuck1=stuck[0],
            stuck2=stuck[1],
        )

    der = jax.vmap(derived)(save, ys)
    if contact == "paper":
        lifted = (der["N1"] <= 0) | (der["N2"] <= 0)
        t_lift = jnp.where(jnp.any(lifted), save[jnp.argmax(lifted)], jnp.inf)

    mode = mode_code(der.pop("stuck1"), der.pop("stuck2"))
    return dict(
        t=save,
        x1=ys[:, 0],
        v1=ys[:, 1],
        x2=ys[:, 2],
        v2=ys[:, 3],
        e_d=ys[:, 4],
        w=ys[:, 5],
        mode=mode,
        valid=ok_rows,
        status=status,
        liftoff=jnp.isfinite(t_lift),
        t_liftoff=jnp.asarray(t_lift, ys.dtype),
        n_switch=jnp.sum(mode[1:] != mode[:-1]).astype(jnp.int32),
        # A smooth model has no switching structure to change.
        transversality=jnp.full_like(save, jnp.inf),
        near_miss=jnp.full_like(save, jnp.inf),
        switch_gap=jnp.full_like(save, jnp.inf),
        **der,
    )


@eqx.filter_jit
def simulate_smoothed(flat, wave, axes, save, contact, start, dyn):
    fn = lambda p, w: simulate_one(p, w, save, contact, start, dyn)
    return jax.vmap(fn, in_axes=(0, axes))(flat, wave)


def measure_one(params, wave, z, horizon, window, contact, start, dyn: "Smoothed"):
    """Measurements of SPEC §5 on the smoothed model, in three solves:
    `[0, t_start]`, the regime window (sampled), and `[t_start, t_start + horizon]`
    terminated by the first passage $|X - X_0| = z$ (located by a root finder)."""
    params, valid = safe_params(params, wave)
    dtype = params.dtype
    y0 = _y0(params, start)
    ws = params.t_start.astype(dtype)
    com = lambda y: model.centre_of_mass(params, y[0], y[2])
    solA = solve(params, wave, contact, dyn, jnp.zeros((), dtype), ws, y0, diffrax.SaveAt(t1=True))
    tsA, ysA = _saved(solA)
    yA = ysA[-1]
    liftA = _event_hit(solA, 0) if contact == "strict" else jnp.asarray(False)
    metA = _event_hit(solA, met_index(contact))
    okA = ~liftA & ~metA & ~_failed(solA) & valid
    yA = jnp.where(okA, yA, y0)
    X0 = com(yA)
    ts = ws + jnp.linspace(0, 1, WINDOW_SAMPLES, dtype=dtype) * window
    solB = solve(params, wave, contact, dyn, ws, ws + window, yA, diffrax.SaveAt(ts=ts))
    vB = _saved(solB)[1][:, jnp.array([1, 3])]
    finite = jnp.all(jnp.isfinite(vB), axis=-1)
    stuckB = (jnp.abs(vB) < STICK_SPEED * dyn.eps) & finite[:, None]
    frac = jnp.sum(stuckB, axis=0) / jnp.maximum(jnp.sum(finite), 1)
    window_ok = jnp.all(finite) & okA & ~_failed(solB)
    ssl = _longest_run(stuckB) * (window / (WINDOW_SAMPLES - 1)) > MIN_STICK
    regime = jnp.where(window_ok, jnp.where(ssl, Regime.SSL, Regime.SL), Regime.UNDETERMINED)

    reach = lambda t, y, args, **kw: z - jnp.abs(com(y) - X0)
    solC = solve(params, wave, contact, dyn, ws, ws + horizon, yA, diffrax.SaveAt(t1=True), (reach,))
    tsC, ysC = _saved(solC)
    yC = ysC[-1]
    reached = _event_hit(solC, 0) & okA
    liftC = _event_hit(solC, 1) if contact == "strict" else jnp.asarray(False)
    met = metA | _event_hit(solC, met_index(contact, 1))
    tC = tsC[-1]
    nan = jnp.asarray(jnp.nan, dtype)
    inf = jnp.asarray(jnp.inf, dtype)
    tau = jnp.where(reached, tC - ws, inf)
    e_d = jnp.where(okA, yC[4] - yA[4], nan)
    work = jnp.where(okA, yC[5] - yA[5], nan)
    energy = lambda t, y: model.total_energy(params, wave(t)[0], y[0], y[1], y[2], y[3])
    delta_e = jnp.where(okA, energy(tC, yC) - energy(ws, yA), nan)
    lift = liftA | liftC
    failed = _failed(solA) | _failed(solC)
    status = jnp.where(lift, Status.LIFTOFF, jnp.where(failed, Status.SOLVER_FAILED, Status.OK))
    status = jnp.where(met & ~lift, Status.COLLISION, status)
    status = jnp.where(valid, status, Status.INVALID).astype(jnp.int32)
    t_lift = jnp.where(liftA, tsA[-1], jnp.where(liftC, tC, inf))
    elapsed = tC - ws
    e_z = jnp.where(reached, e_d, inf)
    return dict(
        tau_z=tau,
        e_z=e_z,
        reached=reached,
        regime=regime.astype(jnp.int32),
        mean_speed=jnp.where(okA & (elapsed > 0), (com(yC) - X0) / jnp.where(elapsed > 0, elapsed, 1), nan),
        cost_of_transport=e_z / z,
        stick_fraction1=jnp.where(window_ok, frac[0], nan),
        stick_fraction2=jnp.where(window_ok, frac[1], nan),
        e_d=e_d,
        work=work,
        delta_e=delta_e,
        balance=work - e_d - delta_e,
        liftoff=lift,
        t_liftoff=t_lift,
        status=status,
        t_start=ws,
        X_start=jnp.where(okA, X0, nan),
        n_steps=(solA.stats["num_steps"] + solC.stats["num_steps"]).astype(jnp.int32),
        n_switch=jnp.zeros((), jnp.int32),
        # A smooth model has no switching structure to change.
        transversality=jnp.asarray(jnp.inf, ws.dtype),
        near_miss=jnp.asarray(jnp.inf, ws.dtype),
        margin_z=jnp.asarray(jnp.inf, ws.dtype),
    )


def measure_smoothed(flat, wave, axes, z, horizon, window, contact, start, dyn):
    z, horizon, window = (jnp.asarray(v, flat.dtype) for v in (z, horizon, window))
    return _measure_smoothed_batch(flat, wave, axes, z, horizon, window, contact, start, dyn)


@eqx.filter_jit
def _measure_smoothed_batch(flat, wave, axes, z, horizon, window, contact, start, dyn):
    fn = lambda p, w: measure_one(p, w, z, horizon, window, contact, start, dyn)
    return jax.vmap(fn, in_axes=(0, axes))(flat, wave)
