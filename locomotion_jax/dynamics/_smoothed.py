"""The smoothed engine (SPEC §3): any mechanism's physics with its friction smoothed, integrated by diffrax.

Written once against [`AbstractPhysics`][locomotion_jax.AbstractPhysics], the interface the
exact engine integrates: the paper's model (a two-mass physics), a
[`Chain`][locomotion_jax.Chain] and a [`Mechanism`][locomotion_jax.Mechanism] (SPEC §9) all
run through it. Each body's friction is the smooth law of its friction class,
[`AbstractFriction.smoothed`][locomotion_jax.AbstractFriction.smoothed] with the static bump
width $v_s = \\sqrt{\\varepsilon}$ of [`Smoothed`][locomotion_jax.Smoothed]:

$$m_i \\dot v_i = F_i + G_i(v) - c_i v_i - n_i\\,\\mu_i(v_i), \\qquad
\\dot e_d = \\sum_i n_i\\,\\mu_i(v_i)\\,v_i + c_i v_i^2 + \\sum_\\text{dampers} c\\,(v_b - v_a)^2,$$

with $F_i$ and $N_i$ the physics' loads, $n_i = N_i$ (strict) or $|N_i|$ (paper), $G_i$ its
forces linear in the velocities (relative dampers) and $\\dot w$ the actuators' power, so that
$w = e_d + \\Delta e$ (eq. 16) stays a check of the integration. The state is the flat array
$y = (x_0..x_{N-1}, v_0..v_{N-1}, e_d, w)$. A body without ground contact (a `Mechanism`'s
carried or free body) has a law whose smoothed coefficient is zero.

Sticking has no exact meaning for a smooth law: below the static limit a body creeps at
$|v| = \\varepsilon\\,\\mathrm{artanh}(|F|/\\mu_s n)$, a few $\\varepsilon$ at most. A sample
counts as stuck when $|v_i| < 3\\varepsilon$ (`STICK_SPEED`); the regime is SSL when such
samples of one body run contiguously for longer than `MIN_STICK` (a velocity merely passing
through zero is shorter). The exact engine is the reference for the regime; this one is
approximate near the SSL/SL boundary.

Terminating events, located by a root finder: lift-off under the strict reading (the
smallest normal force reaching zero), two bodies meeting (the smallest of the physics'
[`gaps`][locomotion_jax.AbstractPhysics.gaps] reaching zero; only where the physics has
gaps), and a measurement's first passage $|X - X_0| = z$.
"""

from typing import Any, TYPE_CHECKING

import diffrax
import jax
import jax.numpy as jnp
import optimistix as optx

from .._custom_types import Array, ArrayLike, Contact
from .._status import Regime, Status
from ..model._physics import AbstractPhysics, least_contact_load, Loads, Scalars
from ._numerics import least, total


if TYPE_CHECKING:  # the class runs this engine: imported for annotations only
    from ._smoothed_dynamics import Smoothed


STICK_SPEED = 3.0  # in units of eps
MIN_STICK = 0.05  # shortest stuck interval (time units) that makes SSL
WINDOW_SAMPLES = 2501


def _stack(P: AbstractPhysics, a: Scalars, like: Array) -> Array:
    """A per-body or per-spring tuple of the physics' entries as an array (an empty tuple: an empty
    last axis)."""
    return P.stacked(a) if a else jnp.zeros(jnp.shape(like) + (0,), like.dtype)


def normal(contact: Contact, N: Scalars) -> Scalars:
    """The normal forces entering friction: $N_i$ (strict) or $|N_i|$ (paper's reading, SPEC §1)."""
    return N if contact != "paper" else tuple(jnp.abs(q) for q in N)


def loads(P: AbstractPhysics, t: ArrayLike, x: Array) -> tuple[Any, Loads]:
    """The actuation and the loads at time `t` and positions `x` (shape `(N,)`)."""
    dr = P.drive(jnp.cos(P.omega * t), jnp.sin(P.omega * t))
    return dr, P.loads(dr, P.bodies(x))


def friction(P: AbstractPhysics, contact: Contact, eps: Array, L: Loads, v: Scalars,
             v_s: Array | None = None) -> Scalars:  # fmt: skip
    """Each body's smoothed friction force magnitude $n_i\\,\\mu_i(v_i)$ (against the motion), with the
    static bump's width `v_s` (default $\\sqrt{\\varepsilon}$)."""
    n = normal(contact, L.N)
    v_s = jnp.sqrt(eps) if v_s is None else v_s
    return tuple(ni * law.smoothed(vi, eps, v_s) for ni, law, vi in zip(n, P.friction, v))


def accelerations(P: AbstractPhysics, contact: Contact, eps: Array, L: Loads, v: Scalars,
                  v_s: Array | None = None) -> tuple[Scalars, Array]:  # fmt: skip
    """The accelerations $\\dot v_i$ and the dissipated power $\\dot e_d$ (module docstring; `v_s` as
    in [`friction`][])."""
    fr = friction(P, contact, eps, L, v, v_s)
    G = P.velocity_forces(v)
    F = L.F if G is None else tuple(f + g for f, g in zip(L.F, G))
    a = tuple((f - c * vi - q) * im for f, c, vi, q, im in zip(F, P.c, v, fr, P.im))
    p_d = total([q * vi + c * vi * vi for q, c, vi in zip(fr, P.c, v)])
    relative = P.velocity_power(v, v)
    return a, p_d if relative is None else p_d + relative


def rates(P: AbstractPhysics, contact: Contact, eps: Array, t: ArrayLike, y: Array) -> Array:
    """Right-hand side on the flat state $y = (x, v, e_d, w)$."""
    return rates_and_normal(P, contact, eps, t, y)[0]


def rates_and_normal(P: AbstractPhysics, contact: Contact, eps: Array, t: ArrayLike, y: Array,
                     v_s: Array | None = None) -> tuple[Array, Array]:  # fmt: skip
    """[`rates`][] (the static bump's width `v_s` as in [`friction`][]) and the smallest signed
    normal force $\\min_i N_i$ of the bodies on the ground (`inf` where none is)."""
    n = P.n_bodies
    x, v = y[:n], P.bodies(y[n : 2 * n])
    dr, L = loads(P, t, x)
    a, p_d = accelerations(P, contact, eps, L, v, v_s)
    p_w = P.power(dr, L, v)
    dy = jnp.concatenate([y[n : 2 * n], P.stacked(a), jnp.stack([p_d, jnp.asarray(p_w, y.dtype)])])
    return dy, least_contact_load(P, L.N, y)


def energy(P: AbstractPhysics, t: Array, y: Array) -> Array:
    n = P.n_bodies
    _, L = loads(P, t, y[:n])
    return P.energy(L, P.bodies(y[n : 2 * n]))


def centre_of_mass(P: AbstractPhysics, y: Array) -> Array:
    return P.centre_of_mass(P.bodies(y[: P.n_bodies]))


class Events:
    """The terminating events of a solve, in the order diffrax reports them: `extra` first, then a
    strict-contact lift-off (if `contact == "strict"`), then two bodies meeting (if the physics has gaps)."""

    def __init__(self, P: AbstractPhysics, contact: Contact, n_extra: int):
        n = P.n_bodies
        self.conds: list = []
        self.lift: int | None = None
        self.met: int | None = None
        if contact == "strict":
            self.lift = n_extra
            self.conds.append(lambda t, y, args, **kw: least(loads(P, t, y[:n])[1].N))
        if P.gaps(P.bodies(jnp.zeros((n,)))):
            self.met = n_extra + len(self.conds)
            self.conds.append(lambda t, y, args, **kw: least(P.gaps(P.bodies(y[:n]))))


def _hit(sol: diffrax.Solution, k: int | None) -> Array:
    if k is None or sol.event_mask is None:
        return jnp.asarray(False)
    return jnp.asarray(sol.event_mask[k])


def solve(
    P: AbstractPhysics, contact: Contact, dyn: "Smoothed", t0, t1, y0, saveat, extra_events=()
) -> tuple[diffrax.Solution, Events]:
    """One diffrax solve from `t0` to `t1`, terminated by the events of [`Events`][]."""
    term = diffrax.ODETerm(lambda t, y, args: rates(P, contact, dyn.eps, t, y))
    ev = Events(P, contact, len(extra_events))
    # diffrax evaluates an event not yet armed as the default float (its `0.0`): each condition
    # returns that dtype too, so that a float32 run under jax_enable_x64 traces.
    conds = [lambda t, y, args, c=c, **kw: jnp.asarray(c(t, y, args, **kw), float) for c in (*extra_events, *ev.conds)]
    # The event times to 1e-10 (relative) in float64; float32 resolves a time to ~1e-7 only.
    eps = float(jnp.finfo(y0.dtype).eps)
    finder = optx.Newton(rtol=max(1e-10, 10 * eps), atol=max(1e-12, 10 * eps))
    event = diffrax.Event(conds, root_finder=finder) if conds else None
    solver = diffrax.Tsit5() if dyn.solver == "tsit5" else diffrax.Kvaerno5()
    sol = diffrax.diffeqsolve(
        term, solver, t0, t1, None, y0, saveat=saveat,
        stepsize_controller=diffrax.PIDController(rtol=dyn.rtol, atol=dyn.atol, dtmin=None),
        max_steps=dyn.max_steps, event=event, throw=False,
    )  # fmt: skip
    return sol, ev


def _saved(sol: diffrax.Solution) -> tuple[Array, Array]:
    """`(sol.ts, sol.ys)`, which every `SaveAt` here requests (diffrax types them optional)."""
    assert sol.ts is not None and sol.ys is not None
    return sol.ts, sol.ys


def _failed(sol: diffrax.Solution) -> Array:
    return ~((sol.result == diffrax.RESULTS.successful) | (sol.result == diffrax.RESULTS.event_occurred))


def initial_state(P: AbstractPhysics, start: str, initial: Array | None) -> Array:
    """$y_0 = (x, v, 0, 0)$: `initial` (positions, then velocities, shape `(2N,)`) or the physics' start."""
    if initial is None:
        x = P.initial_positions(start)
        v = P.initial_velocities(start)
        v = jnp.zeros_like(x) if v is None else v.astype(x.dtype)
        state = jnp.concatenate([x, v])
    else:
        state = initial
    return jnp.concatenate([state, jnp.zeros((2,), state.dtype)])


def admissible(P: AbstractPhysics, y0: Array) -> Array:
    """Whether a start is inside the model: finite, and every gap of the physics positive. An
    `initial=` state past the front end's checks (as under `jit`) that is not is flagged
    `INVALID`, and the run goes from the physics' own start instead (nothing becomes NaN)."""
    gaps = P.gaps(P.bodies(y0[: P.n_bodies]))
    ok = jnp.all(jnp.isfinite(y0))
    return ok & (least(gaps) > 0) if gaps else ok


def _longest_run(flags: Array) -> Array:
    """Longest run of consecutive True samples of any one body (`flags`: (samples, N))."""

    def body(run, f):
        run = jnp.where(f, run + 1, 0)
        return run, run

    _, runs = jax.lax.scan(body, jnp.zeros(flags.shape[1:], jnp.int32), flags)
    return jnp.max(runs)


def simulate_one(
    P: AbstractPhysics, valid: Array, save: Array, contact: Contact, y0: Array, dyn: "Smoothed"
) -> dict[str, Array]:
    """The states at the times `save` of one configuration, with the N-body fields `x`, `v`,
    `stuck`, `X`, `e_d`, `w`, `e`, `N`, `l0`, `tension`, `f_ex` (eq. 17: $\\sum_i m_i \\dot v_i$,
    the friction and damping force on the whole), the status and the lift-off fields."""
    n = P.n_bodies
    ok = admissible(P, y0)
    y0, valid = jnp.where(ok, y0, initial_state(P, "paper", None).astype(y0.dtype)), valid & ok
    # The motion starts at t = 0 whatever the first save time.
    sol, ev = solve(P, contact, dyn, jnp.zeros_like(save[0]), save[-1], y0, diffrax.SaveAt(ts=save, t1=True))
    sol_ts, sol_ys = _saved(sol)
    ys = sol_ys[:-1]  # (samples, 2N + 2); inf after a terminating event
    ok_rows = jnp.all(jnp.isfinite(ys), axis=-1) & valid
    last = jnp.max(jnp.where(ok_rows, jnp.arange(ys.shape[0]), 0))
    ys = jnp.where(ok_rows[:, None], ys, ys[last][None, :])
    lift = _hit(sol, ev.lift)
    met = _hit(sol, ev.met)  # two bodies met (outside the model): the run stops there
    status = jnp.where(lift, Status.LIFTOFF, jnp.where(_failed(sol), Status.SOLVER_FAILED, Status.OK))
    status = jnp.where(met, Status.COLLISION, status)
    status = jnp.where(valid, status, Status.INVALID).astype(jnp.int32)
    t_lift = jnp.where(lift, sol_ts[-1], jnp.inf)
    x, v = ys[:, :n], ys[:, n : 2 * n]

    def derived(t, y):
        dr, L = loads(P, t, y[:n])
        vs = P.bodies(y[n : 2 * n])
        a, _ = accelerations(P, contact, dyn.eps, L, vs)
        e = P.energy(L, vs)
        return dict(
            e=e, N=P.stacked(L.N), l0=_stack(P, dr.l0, e), tension=_stack(P, L.aux.tension, e),
            f_ex=total([m * ai for m, ai in zip(P.m, a)]), X=centre_of_mass(P, y),
        )  # fmt: skip

    der = jax.vmap(derived)(save, ys)
    if contact == "paper":
        lifted = jnp.any(der["N"] <= 0, axis=-1)
        t_lift = jnp.where(jnp.any(lifted), save[jnp.argmax(lifted)], jnp.inf)
    stuck = jnp.abs(v) < STICK_SPEED * dyn.eps
    changes = jnp.any(stuck[1:] != stuck[:-1], axis=-1)
    return dict(
        t=save, x=x, v=v, stuck=stuck, e_d=ys[:, 2 * n], w=ys[:, 2 * n + 1], valid=ok_rows, status=status,
        liftoff=jnp.isfinite(t_lift), t_liftoff=jnp.asarray(t_lift, ys.dtype),
        n_switch=jnp.sum(changes).astype(jnp.int32),
        # A smooth model has no switching structure to change.
        transversality=jnp.full_like(save, jnp.inf), near_miss=jnp.full_like(save, jnp.inf),
        switch_gap=jnp.full_like(save, jnp.inf), **der,
    )  # fmt: skip


def measure_one(
    P: AbstractPhysics, valid: Array, ws: Array, z: Array, horizon: Array, window: Array, contact: Contact,
    y0: Array, dyn: "Smoothed",
) -> dict[str, Array]:  # fmt: skip
    """The measurements of SPEC §5 for one configuration from $t_\\text{start} = $ `ws`, in three
    solves: $[0, t_\\text{start}]$, the regime window (sampled), and $[t_\\text{start},
    t_\\text{start} + \\text{horizon}]$ terminated by the first passage $|X - X_0| = z$ (located by a
    root finder). `stick_fraction` has one entry per body."""
    n = P.n_bodies
    ok = admissible(P, y0)
    y0, valid = jnp.where(ok, y0, initial_state(P, "paper", None).astype(y0.dtype)), valid & ok
    dtype = y0.dtype
    com = lambda y: centre_of_mass(P, y)
    solA, evA = solve(P, contact, dyn, jnp.zeros((), dtype), ws, y0, diffrax.SaveAt(t1=True))
    tsA, ysA = _saved(solA)
    liftA, metA = _hit(solA, evA.lift), _hit(solA, evA.met)
    okA = ~liftA & ~metA & ~_failed(solA) & valid
    yA = jnp.where(okA, ysA[-1], y0)
    X0 = com(yA)
    ts = ws + jnp.linspace(0, 1, WINDOW_SAMPLES, dtype=dtype) * window
    solB, _ = solve(P, contact, dyn, ws, ws + window, yA, diffrax.SaveAt(ts=ts))
    vB = _saved(solB)[1][:, n : 2 * n]
    finite = jnp.all(jnp.isfinite(vB), axis=-1)
    stuckB = (jnp.abs(vB) < STICK_SPEED * dyn.eps) & finite[:, None]
    frac = jnp.sum(stuckB, axis=0) / jnp.maximum(jnp.sum(finite), 1)
    window_ok = jnp.all(finite) & okA & ~_failed(solB)
    ssl = _longest_run(stuckB) * (window / (WINDOW_SAMPLES - 1)) > MIN_STICK
    regime = jnp.where(window_ok, jnp.where(ssl, Regime.SSL, Regime.SL), Regime.UNDETERMINED)

    reach = lambda t, y, args, **kw: z - jnp.abs(com(y) - X0)
    solC, evC = solve(P, contact, dyn, ws, ws + horizon, yA, diffrax.SaveAt(t1=True), (reach,))
    tsC, ysC = _saved(solC)
    yC, tC = ysC[-1], tsC[-1]
    reached = _hit(solC, 0) & okA
    liftC = _hit(solC, evC.lift)
    met = metA | _hit(solC, evC.met)
    nan, inf = jnp.asarray(jnp.nan, dtype), jnp.asarray(jnp.inf, dtype)
    i_ed, i_w = 2 * n, 2 * n + 1
    e_d = jnp.where(okA, yC[i_ed] - yA[i_ed], nan)
    work = jnp.where(okA, yC[i_w] - yA[i_w], nan)
    delta_e = jnp.where(okA, energy(P, tC, yC) - energy(P, ws, yA), nan)
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
