"""Smoothed dynamics of a chain of N masses (SPEC §3 and §8), integrated with diffrax.

The chain's loads (its physics, `ChainPhysics`: tensions,
horizontal loads $F_i$, normal forces) with each mass's friction replaced by the smooth law of its friction class,
[`AbstractFriction.smoothed`][locomotion_jax.AbstractFriction.smoothed] with the
static bump width $v_s = \\sqrt{\\varepsilon}$ of [`Smoothed`][locomotion_jax.Smoothed]:

$$m_i \\dot v_i = F_i - c_i v_i - n_i\\,\\mu_i(v_i), \\qquad
\\dot e_d = \\sum_i n_i\\,\\mu_i(v_i)\\,v_i + c_i v_i^2,$$

and $\\dot w$ the actuator's power, so that $w = e_d + \\Delta e$ (eq. 16) stays a check
of the integration. For N = 2 with [`Coulomb`][locomotion_jax.Coulomb] friction these
are the equations of the two-mass smoothed model (`_smooth`).

Sticking has no exact meaning for a smooth law: as in `_smooth`, a sample counts as
stuck when $|v_i| < 3\\varepsilon$ and the regime is SSL when such samples of one mass
run contiguously for longer than `_smooth.MIN_STICK`. Lift-off under the strict reading
(a normal force reaching zero) is a terminating event located by a root finder.
"""

from typing import Any, TYPE_CHECKING

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx

from .._custom_types import Array, ArrayLike, Contact
from .._status import Regime, Status
from ..model._chain import Chain
from . import _chain_motion as motion
from ._smooth import MIN_STICK, STICK_SPEED, WINDOW_SAMPLES


if TYPE_CHECKING:  # the class runs this engine: imported for annotations only
    from ._smoothed_dynamics import Smoothed


def _loads(C: Chain, contact: Contact, t: ArrayLike, x: Array):
    """The physics, actuation, loads, horizontal loads $F_i$, signed normal forces $N_i$ and the
    normal forces $n_i$ entering friction at time `t` and positions `x` (arrays over the bodies)."""
    P = C.physics()
    dr = P.drive(jnp.cos(P.omega * t), jnp.sin(P.omega * t))
    L = P.loads(dr, _unstack(x))
    n = _stack(motion.normal(contact, L.N))
    return P, dr, L, _stack(L.F), _stack(L.N), n


def _unstack(a: Array) -> tuple[Array, ...]:
    return tuple(a[..., i] for i in range(a.shape[-1]))


def _stack(a) -> Array:
    return jnp.stack(a, -1)


def rates(C: Chain, contact: Contact, eps: Array, t: ArrayLike, y: Array) -> Array:
    """Right-hand side on the flat state $y = (x_1..x_N, v_1..v_N, e_d, w)$."""
    n_mass = C.m.shape[-1]
    x, v = y[:n_mass], y[n_mass : 2 * n_mass]
    P, dr, L, F, _, n = _loads(C, contact, t, x)
    friction = n * C.friction.smoothed(v, eps, jnp.sqrt(eps))
    a = (F - C.c * v - friction) / C.m
    p_d = (friction * v + C.c * v * v).sum()
    p_w = P.power(dr, L, _unstack(v))
    return jnp.concatenate([v, a, p_d[None], jnp.asarray(p_w)[None]])


def _normal_min(C: Chain, contact: Contact, t: Array, y: Array) -> Array:
    return _loads(C, contact, t, y[: C.m.shape[-1]])[4].min()


def _gap_min(C: Chain, y: Array) -> Array:
    n = C.m.shape[-1]
    gaps = C.physics().gaps(tuple(y[i] for i in range(n)))
    return jnp.min(jnp.stack(gaps)) if gaps else jnp.asarray(jnp.inf, y.dtype)


def met_index(contact: Contact, n_extra: int = 0) -> int:
    """The index of the event "two bodies met" in a `solve` with `n_extra` extra events."""
    return n_extra + (1 if contact == "strict" else 0)


def solve(C: Chain, contact: Contact, dyn: "Smoothed", t0, t1, y0, saveat, extra_events=()) -> diffrax.Solution:
    """One diffrax solve; a strict-contact lift-off, two bodies meeting (the smallest gap
    `AbstractPhysics.gaps` reaching zero, event `met_index`) and any `extra_events` terminate it."""
    term = diffrax.ODETerm(lambda t, y, args: rates(C, contact, dyn.eps, t, y))
    conds = list(extra_events)
    if contact == "strict":
        conds.append(lambda t, y, args, **kw: _normal_min(C, contact, t, y))
    conds.append(lambda t, y, args, **kw: _gap_min(C, y))
    event = diffrax.Event(conds, root_finder=optx.Newton(rtol=1e-10, atol=1e-12)) if conds else None
    solver = diffrax.Tsit5() if dyn.solver == "tsit5" else diffrax.Kvaerno5()
    return diffrax.diffeqsolve(
        term, solver, t0, t1, None, y0, saveat=saveat,
        stepsize_controller=diffrax.PIDController(rtol=dyn.rtol, atol=dyn.atol, dtmin=None),
        max_steps=dyn.max_steps, event=event, throw=False,
    )  # fmt: skip


def _y0(C: Chain, start: str) -> Array:
    x = C.physics().initial_positions(start)
    zero = jnp.zeros((1,), x.dtype)
    return jnp.concatenate([x, jnp.zeros_like(x), zero, zero])


def _saved(sol: diffrax.Solution) -> tuple[Array, Array]:
    assert sol.ts is not None and sol.ys is not None
    return sol.ts, sol.ys


def _event_hit(sol: diffrax.Solution, k: int) -> Array:
    return jnp.asarray(False) if sol.event_mask is None else jnp.asarray(sol.event_mask[k])


def _failed(sol: diffrax.Solution) -> Array:
    return ~((sol.result == diffrax.RESULTS.successful) | (sol.result == diffrax.RESULTS.event_occurred))


def _com(C: Chain, x: Array) -> Array:
    return jnp.matmul(x, C.m) / C.m.sum()


def _energy(C: Chain, contact: Contact, t: Array, y: Array) -> Array:
    n_mass = C.m.shape[-1]
    P, _, L, _, _, _ = _loads(C, contact, t, y[:n_mass])
    return P.energy(L, _unstack(y[n_mass : 2 * n_mass]))


def _longest_run(flags: Array) -> Array:
    """Longest run of consecutive True samples of any one mass (`flags`: (samples, N))."""

    def body(run, f):
        run = jnp.where(f, run + 1, 0)
        return run, run

    _, runs = jax.lax.scan(body, jnp.zeros(flags.shape[1:], jnp.int32), flags)
    return jnp.max(runs)


def simulate_one(C: Chain, valid: Array, save: Array, contact: Contact, start: str, dyn: "Smoothed") -> dict[str, Any]:
    """The states at the times `save` of one chain (fields of `ChainTrajectory`)."""
    n_mass = C.m.shape[-1]
    y0 = _y0(C, start)
    # The motion starts at t = 0 whatever the first save time.
    sol = solve(C, contact, dyn, jnp.zeros_like(save[0]), save[-1], y0, diffrax.SaveAt(ts=save, t1=True))
    sol_ts, sol_ys = _saved(sol)
    ys = sol_ys[:-1]  # (n, 2N + 2); inf after a terminating event
    ok_rows = jnp.all(jnp.isfinite(ys), axis=-1) & valid
    last = jnp.max(jnp.where(ok_rows, jnp.arange(ys.shape[0]), 0))
    ys = jnp.where(ok_rows[:, None], ys, ys[last][None, :])
    lift = _event_hit(sol, 0) if contact == "strict" else jnp.asarray(False)
    met = _event_hit(sol, met_index(contact))  # two bodies met (outside the model): the run stops there
    status = jnp.where(lift, Status.LIFTOFF, jnp.where(_failed(sol), Status.SOLVER_FAILED, Status.OK))
    status = jnp.where(met, Status.COLLISION, status)
    status = jnp.where(valid, status, Status.INVALID).astype(jnp.int32)
    t_lift = jnp.where(lift, sol_ts[-1], jnp.inf)
    x, v = ys[:, :n_mass], ys[:, n_mass : 2 * n_mass]

    def derived(t, y):
        _, dr, L, _, N, _ = _loads(C, contact, t, y[:n_mass])
        return dict(e=_energy(C, contact, t, y), N=N, l0=_stack(dr.l0), tension=_stack(L.aux.tension))

    der = jax.vmap(derived)(save, ys)
    if contact == "paper":
        lifted = jnp.any(der["N"] <= 0, axis=-1)
        t_lift = jnp.where(jnp.any(lifted), save[jnp.argmax(lifted)], jnp.inf)
    stuck = jnp.abs(v) < STICK_SPEED * dyn.eps
    changes = jnp.any(stuck[1:] != stuck[:-1], axis=-1)
    return dict(
        t=save, x=x, v=v, stuck=stuck, X=jax.vmap(lambda xi: _com(C, xi))(x), e_d=ys[:, 2 * n_mass],
        w=ys[:, 2 * n_mass + 1], valid=ok_rows, status=status, liftoff=jnp.isfinite(t_lift),
        t_liftoff=jnp.asarray(t_lift, ys.dtype), n_switch=jnp.sum(changes).astype(jnp.int32), **der,
        # A smooth model has no switching structure to change.
        transversality=jnp.full_like(save, jnp.inf), near_miss=jnp.full_like(save, jnp.inf),
        switch_gap=jnp.full_like(save, jnp.inf),
    )  # fmt: skip


def measure_one(
    C: Chain, valid: Array, t_start: Array, z: Array, horizon: Array, window: Array, contact: Contact, start: str,
    dyn: "Smoothed",
) -> dict[str, Any]:  # fmt: skip
    """The measurements of SPEC §5 for one chain (fields of `ChainMeasurement`), in three solves:
    $[0, t_\\text{start}]$, the regime window (sampled), and $[t_\\text{start}, t_\\text{start} + \\text{horizon}]$
    terminated by the first passage $|X - X_0| = z$ (located by a root finder)."""
    n_mass = C.m.shape[-1]
    y0 = _y0(C, start)
    dtype = y0.dtype
    ws = jnp.where(jnp.isfinite(t_start), t_start, C.t_start).astype(dtype)
    com = lambda y: _com(C, y[:n_mass])
    solA = solve(C, contact, dyn, jnp.zeros((), dtype), ws, y0, diffrax.SaveAt(t1=True))
    tsA, ysA = _saved(solA)
    liftA = _event_hit(solA, 0) if contact == "strict" else jnp.asarray(False)
    metA = _event_hit(solA, met_index(contact))
    okA = ~liftA & ~metA & ~_failed(solA) & valid
    yA = jnp.where(okA, ysA[-1], y0)
    X0 = com(yA)
    ts = ws + jnp.linspace(0, 1, WINDOW_SAMPLES, dtype=dtype) * window
    solB = solve(C, contact, dyn, ws, ws + window, yA, diffrax.SaveAt(ts=ts))
    vB = _saved(solB)[1][:, n_mass : 2 * n_mass]
    finite = jnp.all(jnp.isfinite(vB), axis=-1)
    stuckB = (jnp.abs(vB) < STICK_SPEED * dyn.eps) & finite[:, None]
    frac = jnp.sum(stuckB, axis=0) / jnp.maximum(jnp.sum(finite), 1)
    window_ok = jnp.all(finite) & okA & ~_failed(solB)
    ssl = _longest_run(stuckB) * (window / (WINDOW_SAMPLES - 1)) > MIN_STICK
    regime = jnp.where(window_ok, jnp.where(ssl, Regime.SSL, Regime.SL), Regime.UNDETERMINED)

    reach = lambda t, y, args, **kw: z - jnp.abs(com(y) - X0)
    solC = solve(C, contact, dyn, ws, ws + horizon, yA, diffrax.SaveAt(t1=True), (reach,))
    tsC, ysC = _saved(solC)
    yC, tC = ysC[-1], tsC[-1]
    reached = _event_hit(solC, 0) & okA
    liftC = _event_hit(solC, 1) if contact == "strict" else jnp.asarray(False)
    met = metA | _event_hit(solC, met_index(contact, 1))
    nan, inf = jnp.asarray(jnp.nan, dtype), jnp.asarray(jnp.inf, dtype)
    i_ed, i_w = 2 * n_mass, 2 * n_mass + 1
    e_d = jnp.where(okA, yC[i_ed] - yA[i_ed], nan)
    work = jnp.where(okA, yC[i_w] - yA[i_w], nan)
    delta_e = jnp.where(okA, _energy(C, contact, tC, yC) - _energy(C, contact, ws, yA), nan)
    lift = liftA | liftC
    failed = _failed(solA) | _failed(solC)
    status = jnp.where(lift, Status.LIFTOFF, jnp.where(failed, Status.SOLVER_FAILED, Status.OK))
    status = jnp.where(met & ~lift, Status.COLLISION, status)
    status = jnp.where(valid, status, Status.INVALID).astype(jnp.int32)
    elapsed = tC - ws
    e_z = jnp.where(reached, e_d, inf)
    return dict(
        tau_z=jnp.where(reached, elapsed, inf), e_z=e_z, reached=reached, regime=regime.astype(jnp.int32),
        mean_speed=jnp.where(okA & (elapsed > 0), (com(yC) - X0) / jnp.where(elapsed > 0, elapsed, 1), nan),
        cost_of_transport=e_z / z, stick_fraction=jnp.where(window_ok, frac, nan), e_d=e_d, work=work,
        delta_e=delta_e, balance=work - e_d - delta_e, liftoff=lift,
        t_liftoff=jnp.where(liftA, tsA[-1], jnp.where(liftC, tC, inf)), status=status, t_start=ws,
        X_start=jnp.where(okA, X0, nan), n_steps=(solA.stats["num_steps"] + solC.stats["num_steps"]).astype(jnp.int32),
        n_switch=jnp.zeros((), jnp.int32),
        # A smooth model has no switching structure to change.
        transversality=inf, near_miss=inf, margin_z=inf,
    )  # fmt: skip


@eqx.filter_jit
def simulate_batch(C, valid, save, contact, start, dyn):
    """[`simulate_one`][] over a flat batch of chains (`vmap`)."""
    return jax.vmap(lambda C, ok: simulate_one(C, ok, save, contact, start, dyn))(C, valid)


@eqx.filter_jit
def measure_batch(C, valid, t_start, z, horizon, window, contact, start, dyn):
    """[`measure_one`][] over a flat batch of chains (`vmap`)."""
    one = lambda C, ok, ts: measure_one(C, ok, ts, z, horizon, window, contact, start, dyn)
    return jax.vmap(one)(C, valid, t_start)
