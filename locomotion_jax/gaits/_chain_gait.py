"""Steady gaits of chains of N masses as periodic orbits (the N-mass counterpart of `_gait`).

Every waveform of a [`Chain`][] shares the base frequency $\\omega$, so the forcing is
$T$-periodic ($T = 2\\pi/\\omega$), and the loads depend on the positions only through the
gaps $u_j = x_{j+1} - x_j$ (SPEC §8). A steady gait is then a fixed point of the $k$-period
map $\\Phi_k$ of the reduced state $y = (u_1, \\dots, u_{N-1}, v_1, \\dots, v_N)$ at the phase
$\\omega t \\equiv 0$, while the centre of mass drifts by $\\Delta X$ per gait period $kT$.
As for two masses: a transient from the start, then Newton's method on $\\Phi_k(y) = y$ with
the monodromy matrix $M = \\partial\\Phi_k/\\partial y$ from forward-mode differentiation through
the N-mass exact engine (located events enter with their implicit-function times, so $M$
includes the saltation of every switch); the Floquet multipliers are the eigenvalues of $M$.

A mass at rest at the section sticks where its static limits hold, so its velocity carries
no tangent there (its column of $M$ is zero), as in the two-mass model.

A [`Mechanism`][locomotion_jax.Mechanism] (SPEC §9) runs on the same solver through its physics.
Its forces depend on the positions only through the springs' extensions; where no spring ties a
body to the wall they are invariant under a common translation, and the reduced state is the
chain's, $(u_1, \\dots, u_{N-1}, v_1, \\dots, v_N)$ with $u_j = x_{j+1} - x_j$ the positions relative
to body 0 (of any sign: a carried mass passes its carrier). A mechanism with a spring to the wall
(an anchored one) is not: its section state holds the absolute positions,
$(x_1, \\dots, x_N, v_1, \\dots, v_N)$, and its centre of mass returns to where it was over a period.
"""

from collections.abc import Sequence
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array, ArrayLike, Contact
from .._status import Regime, Status
from ..dynamics import _chain_exact as engine
from ..dynamics._compile import engine_jit
from ..dynamics._exact_dynamics import Exact
from ..dynamics._runs import chain_initial_state, default_max_steps, STICK_TOL
from ..model._bodies import Mechanism
from ..model._chain import Chain
from ..model._elements import WALL
from ..model._mechanism_physics import MechanismPhysics
from ..model._physics import AbstractPhysics
from ..run._batch import check_contact_start, prepare_chain, unflatten
from ..run._resolution import guard_chain
from . import _select as select
from ._select import GaitStatus


class ChainGait(eqx.Module):
    """Steady gaits of chains, per configuration (compare [`Gait`][], whose fields these are).

    - `status` ([`GaitStatus`][]), `converged`, `k`, `period`, `mean_speed`, `e_d`, `work`,
      `cost_of_transport`, `regime`, `n_switch`, `multipliers`, `stable`, `residual`, `n_iter`,
      `liftoff`: as in [`Gait`][].
    - `stick_fraction`: fraction of the gait period each mass is stuck, shape `batch + (N,)`.
    - `state`: the orbit's reduced state at the section $\\omega t \\equiv 0$, shape
      `batch + (2N - 1,)` (under `contact="hop"`: `batch + (4N - 1,)`, the heights and vertical
      velocities $(y_1, \\dots, y_N, w_1, \\dots, w_N)$ appended), order
      $(u_1, \\dots, u_{N-1}, v_1, \\dots, v_N)$ (a mechanism anchored to
      the wall: `batch + (2N,)`, $(x_1, \\dots, x_N, v_1, \\dots, v_N)$);
      `monodromy`: $M$ in that order, shape `batch + (2N - 1, 2N - 1)` (anchored: `(2N, 2N)`).
    """

    status: Array
    converged: Array
    k: Array
    period: Array
    mean_speed: Array
    e_d: Array
    work: Array
    cost_of_transport: Array
    stick_fraction: Array
    regime: Array
    n_switch: Array
    state: Array
    monodromy: Array
    multipliers: Array
    stable: Array
    residual: Array
    n_iter: Array
    liftoff: Array
    contact: str = eqx.field(static=True)


class _Period(NamedTuple):
    """One application of the period map: the end state and what the period accumulated."""

    y: Array
    dX: Array
    ed: Array
    w: Array
    stuck: Array  # time each mass was stuck, shape (N,)
    n_switch: Array
    status: Array
    lifted: Array


def anchored(P: AbstractPhysics) -> bool:
    """Whether a spring ties a body of the mechanism to the wall (its forces then depend on the
    absolute positions, and its section state holds them; module docstring). A chain: never."""
    return isinstance(P, MechanismPhysics) and any(WALL in (s.a, s.b) for s in P.springs)


def reduced_size(P: AbstractPhysics) -> int:
    """Length of the section state: $2N - 1$, or $2N$ for an anchored mechanism."""
    return 2 * P.n_bodies - (0 if anchored(P) else 1)


def _reduced(st: engine.Hybrid, P: AbstractPhysics | None = None) -> Array:
    """The section state of a hybrid state; under `contact="hop"` followed by the heights and
    vertical velocities $(y_1, \\dots, y_N, w_1, \\dots, w_N)$."""
    x, v = st.y.x, st.y.v
    vert = [] if st.y.y is None or st.y.vy is None else list(st.y.y) + list(st.y.vy)
    if P is not None and anchored(P):
        return jnp.stack(list(x) + list(v) + vert)
    return jnp.stack([b - a for a, b in zip(x[:-1], x[1:])] + list(v) + vert)


def _positions(P: AbstractPhysics, y: Array) -> Array:
    """The positions of a section state: $x_1 = 0$ and the gaps' sums, or the anchored state's own."""
    n = P.n_bodies
    if anchored(P):
        return y[:n]
    return jnp.concatenate([jnp.zeros((1,), y.dtype), jnp.cumsum(y[: n - 1])])


def _section_state(P: AbstractPhysics, contact: Contact, y: Array) -> engine.Hybrid:
    """The hybrid state at phase 0 for a reduced state `y` (with $x_1 = 0$ unless anchored): a mass
    at rest sticks where its static limits hold (eq. 7 generalised), a moving one slips along $v_i$."""
    n, base = P.n_bodies, reduced_size(P)
    if contact != "hop":
        return engine.init(P, contact, _positions(P, y), y[base - n : base])
    # A body on the ground (y_i = 0, not rising) has no vertical tangent: its height and vertical
    # velocity are set to the constant 0 there (`where`), so a grounded body adds a zero multiplier.
    h, w = y[base : base + n], y[base + n : base + 2 * n]
    up = (h > 0) | (w > 0)
    h, w = jnp.where(up, h, 0), jnp.where(up, w, 0)
    return engine.init(P, contact, _positions(P, y), y[base - n : base], h, w)


def _step(P, contact, dt, st, t_end):
    """One engine step (under `contact="hop"` with the physics' restitution and Zeno speed)."""
    return engine.step(P, contact, dt, st, t_end, hop=P.hop()[2:] if contact == "hop" else None)


def _advance(P, contact, dt, st, t_end, max_steps):
    """Integrate to `t_end` (or a strict lift-off, or the step cap); also the time each mass was stuck."""

    def cond(c):
        s, _, n = c
        return (s.t < t_end) & (s.status == Status.OK) & (n < max_steps)

    def body(c):
        s, stuck, n = c
        new, info = _step(P, contact, dt, s, t_end)
        span = jnp.where(info.commit, info.t1 - info.t0, 0)
        return new, tuple(a + jnp.where(b, span, 0) for a, b in zip(stuck, info.stuck)), n + 1

    zero = tuple(jnp.zeros_like(a) for a in st.y.x)
    st, stuck, _ = jax.lax.while_loop(cond, body, (st, zero, jnp.zeros((), jnp.int32)))
    return st, jnp.stack(stuck)


def _period_map(P, contact, dt, max_steps, k, y) -> _Period:
    """$\\Phi_k(y)$ and what the $k$ periods accumulate."""
    t_end = k * (2 * jnp.pi) / P.omega
    st0 = _section_state(P, contact, y)
    st, stuck = _advance(P, contact, dt, st0, t_end, max_steps)
    ok = (st.status == Status.OK) & (st.t >= t_end)
    status = jnp.where(ok, Status.OK, jnp.where(st.status == Status.OK, Status.MAX_STEPS, st.status))
    return _Period(
        y=_reduced(st, P),
        dX=P.centre_of_mass(st.y.x) - P.centre_of_mass(st0.y.x),
        ed=st.y.ed,
        w=st.y.w,
        stuck=stuck,
        n_switch=st.n_switch,
        status=status.astype(jnp.int32),
        lifted=jnp.isfinite(st.t_liftoff),
    )


def _transient_batch(C, valid, contact, start, dt, transient, max_steps, y_start=None):
    """The reduced states after `transient` actuation periods from the start at rest `start`, or
    from the section states `y_start` (flat, `(n, 2N - 1)`) where given."""

    def one(c, ok, y):
        P = c.physics()
        row = None if y is None else jnp.concatenate([_positions(P, y), y[y.shape[-1] - P.n_bodies :]])
        st = chain_initial_state(P, ok, contact, start, row)
        st, _ = _advance(P, contact, dt, st, transient * (2 * jnp.pi) / P.omega, max_steps)
        return _reduced(st, P), st.status, jnp.isfinite(st.t_liftoff)

    return jax.vmap(one)(C, valid, y_start)


_transient_batch = engine_jit(_transient_batch, ("contact", "start", "dt"))


def _solve_batch(C, contact, dt, k, y0, go, tol, max_iter, max_steps):
    """Newton's method on $\\Phi_k(y) = y$ from `y0` where `go` (elsewhere nothing is integrated)."""

    def one(c, y_start, g):
        P = c.physics()
        kk = jnp.where(g, k, 0)
        eye = jnp.eye(y_start.shape[0], dtype=y_start.dtype)

        def phi(y):
            out = _period_map(P, contact, dt, max_steps, kk, y)
            return out.y, out

        def evaluate(y):
            J, out = jax.jacfwd(phi, has_aux=True)(y)
            bad = (out.status != Status.OK) | ~jnp.all(jnp.isfinite(y)) | ~jnp.all(jnp.isfinite(J))
            return J, out, bad

        def small(y, out):
            return jnp.max(jnp.abs(out.y - y)) <= tol * (1 + jnp.max(jnp.abs(y)))

        def cond(s):
            _, _, _, it, done, failed = s
            return ~done & ~failed & (it < max_iter)

        def body(s):
            y, J, out, it, _, _ = s
            y1 = y - jnp.linalg.solve(J - eye, out.y - y)
            J1, out1, bad = evaluate(y1)
            return y1, J1, out1, it + 1, small(y1, out1) & ~bad, bad

        J0, out0, bad0 = evaluate(y_start)
        init = (y_start, J0, out0, jnp.zeros((), jnp.int32), g & small(y_start, out0) & ~bad0, ~g | bad0)
        y, J, out, it, done, _ = jax.lax.while_loop(cond, body, init)
        return y, J, out, it, done & g

    return jax.vmap(one)(C, y0, go)


_solve_batch = engine_jit(_solve_batch, ("contact", "dt"))


def steady_gait_chain(
    chain: Chain | Mechanism,
    *,
    periods: int | Sequence[int] = (1, 2, 3, 4),
    transient: int = 30,
    tol: float | None = None,
    max_iter: int = 12,
    dynamics: Exact,
    contact: str = "strict",
    start: str | ArrayLike = "paper",
    dtype: Any = None,
) -> ChainGait:
    """[`steady_gait`][] for a [`Chain`][] or a [`Mechanism`][locomotion_jax.Mechanism] (its
    arguments; `start` names a start at rest (a mechanism: its own `x0`, `v0`), or gives section
    states at phase 0: gaps then velocities $(u_0, \\dots, u_{N-2}, v_0, \\dots, v_{N-1})$, shape
    `batch + (2N - 1,)`, or for an anchored mechanism positions then velocities, `batch + (2N,)`)."""
    check_contact_start(contact, start if isinstance(start, str) else "paper", chain)
    if contact == "hop" and not isinstance(start, str):
        raise NotImplementedError(
            "steady_gait with contact='hop' starts at rest ('paper' or 'relaxed'), not from given section states."
        )
    flat, valid, shape = prepare_chain(chain, dtype)
    valid, unresolved = guard_chain(dynamics, flat, valid, shape)  # refused alone, skipped in a batch
    y_start = None
    if not isinstance(start, str):
        P = flat.physics()
        n_red = reduced_size(P)
        what = "positions x_0..x_N-1" if anchored(P) else "gaps u_0..u_N-2"
        y = np.asarray(start, np.float64)
        if y.shape != shape + (n_red,) or not np.all(np.isfinite(y)):
            raise ValueError(
                f"start must be 'paper', 'relaxed' or finite section states ({what}, velocities "
                f"v_0..v_N-1) of shape {shape + (n_red,)}, got shape {y.shape}."
            )
        if isinstance(chain, Chain) and shape == () and np.any(y[: flat.n_masses - 1] <= 0):  # refused alone
            raise ValueError(
                f"start: the gaps u_j must be > 0 (the masses in order along the chain), got {y[: flat.n_masses - 1]}."
            )
        y_start = jnp.asarray(y.reshape(-1, n_red), flat.m.dtype)
        start = "paper"
    valid = valid & jnp.asarray(select.periodic(np.asarray(flat.omega, np.float64), shape))
    dtype_ = flat.m.dtype
    f32 = jnp.finfo(dtype_).bits < 64
    tol = (1e-5 if f32 else 1e-11) if tol is None else float(tol)
    ks = select.check(periods, transient, tol, max_iter)
    omega = np.asarray(flat.omega, np.float64)
    T_max = float(np.max(2 * np.pi / omega[np.isfinite(omega) & (omega > 0)], initial=1.0))
    real = lambda v: jnp.asarray(v, dtype_)
    mst = jnp.asarray(dynamics.max_steps or default_max_steps(transient * T_max, dynamics.dt), jnp.int32)
    y0, trans, trans_lift = _transient_batch(flat, valid, contact, start, dynamics.dt, real(transient), mst, y_start)
    trans = np.asarray(trans)
    base = np.select(
        [trans == Status.INVALID, trans == Status.LIFTOFF, trans == Status.COLLISION, trans != Status.OK],
        [GaitStatus.INVALID, GaitStatus.LIFTOFF, GaitStatus.COLLISION, GaitStatus.NOT_CONVERGED],
        -1,
    )
    base = select.unresolved(base, unresolved)
    best = None
    for k in ks:
        msp = jnp.asarray(dynamics.max_steps or default_max_steps(k * T_max, dynamics.dt), jnp.int32)
        go = jnp.asarray((base < 0) & (True if best is None else select.still_open(best)))
        y, M, out, it, done = jax.tree_util.tree_map(
            np.asarray,
            _solve_batch(flat, contact, dynamics.dt, real(k), y0, go, real(tol), jnp.asarray(max_iter, jnp.int32), msp),
        )
        r = dict(y=y, M=M, out=out, it=it, done=done, residual=np.max(np.abs(out.y - y), axis=1))
        r = select.judge(r, base, k, (base != GaitStatus.INVALID) & (np.asarray(trans_lift) | out.lifted))
        best = select.better(best, r)
        if not np.any(select.still_open(best)):
            break
    assert best is not None
    return unflatten(_chain_gait(best, omega, dtype_, contact), shape)


def _chain_gait(r: dict, omega: np.ndarray, dtype: Any, contact: str) -> ChainGait:
    ok = r["status"] == GaitStatus.CONVERGED
    nan = lambda x: jnp.asarray(np.where(select.expand(ok, x), x, np.nan), dtype)
    out: _Period = r["out"]
    kT = np.where(ok, r["k"] * 2 * np.pi / np.where(ok, omega, 1), np.nan)
    dX = out.dX
    ssl = np.max(out.stuck, axis=-1) > STICK_TOL
    return ChainGait(
        status=jnp.asarray(r["status"]),
        converged=jnp.asarray(ok),
        k=jnp.asarray(r["k"], jnp.int32),
        period=jnp.asarray(kT, dtype),
        mean_speed=nan(dX / np.where(ok, kT, 1)),
        e_d=nan(out.ed),
        work=nan(out.w),
        cost_of_transport=nan(select.ratio(out.ed, np.abs(dX), ok)),
        stick_fraction=nan(out.stuck / np.where(ok, kT, 1)[:, None]),
        regime=jnp.asarray(np.where(ok, np.where(ssl, Regime.SSL, Regime.SL), Regime.UNDETERMINED), jnp.int32),
        n_switch=jnp.asarray(np.where(ok, out.n_switch, 0), jnp.int32),
        state=nan(r["y"]),
        monodromy=nan(r["M"]),
        multipliers=jnp.asarray(r["multipliers"]),
        stable=jnp.asarray(r["stable"]),
        residual=jnp.asarray(r["residual"], dtype),
        n_iter=jnp.asarray(r["it"]),
        liftoff=jnp.asarray(r["lifted"]),
        contact=contact,
    )
