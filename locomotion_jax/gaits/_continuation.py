"""Continuation of steady gaits along one parameter (pseudo-arclength on the period map).

A steady gait of period $kT$ is a fixed point of $\\Phi_k(\\,\\cdot\\,; \\lambda)$ ([`steady_gait`][]). As the
parameter $\\lambda$ varies, the fixed points form a curve in $(y, \\lambda)$ (the section state $y$:
$(u, v_1, v_2)$ for the paper's model, a chain's gaps and velocities); it is followed
by pseudo-arclength continuation, which passes folds: from a point $z$ with unit tangent $t$ the
predictor is $z + h\\,t$, and the corrector ([`_corrector`][]) solves the fixed point on the
hyperplane through it normal to $t$. The new tangent is the null vector of
$[\\,M - I,\\ \\partial\\Phi_k/\\partial\\lambda\\,]$ oriented like the old one. The step $h$ grows
after quick corrections and halves after a failed or too distant one, or a turn of the tangent by
more than `MAX_TURN`. Arclength is measured with $\\lambda$ in units of the range
$|\\lambda_\\text{stop} - \\lambda_\\text{start}|$.

The period map and the corrector are the same for every mechanism (the N-body engine; [`_corrector`][]):
[`Params`][], a [`Chain`][] or a [`Mechanism`][locomotion_jax.Mechanism]. Every configuration of the
batch is a branch; all of them advance together, one batched corrector
call per step (one compilation for the whole continuation), and each ends on its own
([`BranchStatus`][]). Along each branch, [`_bifurcation`][] then finds and locates folds, period
doublings, torus bifurcations, and the changes of switching structure (SSL/SL, lift-off).
"""

import math
from collections.abc import Sequence
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array, ArrayLike
from .._results import BODIES, PAPER
from .._status import Regime, Status
from ..dynamics._base import AbstractDynamics
from ..dynamics._exact_dynamics import Exact
from ..dynamics._runs import default_max_steps, STICK_TOL
from ..model._bodies import Mechanism
from ..model._chain import Chain
from ..model._params import Params
from ..model._waveform import AbstractWaveform
from ..run._batch import mechanism_arg, prepare, prepare_chain
from ..run._resolution import guard_chain, guard_two_mass
from . import _corrector as corrector, _progress as progress, _shooting as shooting
from ._bifurcation import BranchEvents, complex_radius, find_events, kinds, torus_function
from ._gait import configs, GaitStatus, steady_gait
from ._result import PaperNames


MAX_TURN = 0.5
"""Largest angle (radians) between consecutive tangents of an accepted step, above the smallest steps
(a change of switching structure is a corner of the branch, passed at the smallest step)."""


class BranchStatus:
    """Why a branch ended.

    - `REACHED`: the parameter reached `stop` (the last point is solved there exactly).
    - `LEFT_RANGE`: the branch turned back at a fold and left the range between start and stop.
    - `MAX_POINTS`: `max_points` points were computed first.
    - `FAILED`: the corrector failed at the smallest step (no periodic orbit continues the branch:
      e.g. it meets a switching structure it cannot cross, or the step cap).
    - `LIFTOFF`: strict reading: a normal force of the orbit reaches zero ahead.
    - `INVALID`: the parameter left its valid range ahead, or the start's parameters are invalid.
    - `NO_START`: no gait converged at the start (the start's `Gait.status` says why).
    - `UNRESOLVED`: the step of `Exact` dynamics does not resolve a time scale of the start or of
      the configuration at `stop` (`Status.UNRESOLVED`; the scales are monotonic in every
      parameter between them or, for `mhat`, largest at the ends); nothing was continued. One
      configuration alone is refused with a `ValueError` instead.
    """

    REACHED = 0
    LEFT_RANGE = 1
    MAX_POINTS = 2
    FAILED = 3
    LIFTOFF = 4
    INVALID = 5
    NO_START = 6
    UNRESOLVED = 7


class Branch(PaperNames):
    """Branches of steady gaits, one per configuration; per point, arrays of shape `batch + (n,)`
    with NaN (or the sentinels below) past each branch's `n_points`.

    - `lam`: the parameter; `state`: the orbit's section state, `batch + (n, S)` (as [`Gait`][]'s
      `(u, v1, v2)` for the paper's model, `Gait.state` for a chain or a mechanism; under
      `contact="hop"` followed by the heights and vertical velocities).
    - `mean_speed`, `cost_of_transport`, `e_d`, `work`, `n_switch`, `slip_margin`, `min_normal`: as in
      [`Gait`][], of each point's orbit; `stick_fraction`: per mass, `batch + (n, N)`; `regime`:
      [`Regime`][] (UNDETERMINED past the end).
    - `multipliers`: Floquet multipliers, `batch + (n, S)`, by decreasing modulus; `stable`: all inside
      the unit circle.
    - `n_land`: landings per gait period (0 but under `contact="hop"`).
    - `liftoff`: a normal force of the orbit reaches zero (`min_normal <= 0`; under the paper
      reading and `contact="hop"`, where the orbit has a flight).
    - `tangent`: $d\\lambda/ds$ of the unit tangent (sign change: a fold).
    - `det_minus`, `det_plus`: $\\det(M - I)$ and $\\det(M + I)$ (test functions of a real multiplier
      at $+1$ and $-1$); `det_torus`: $\\det(M^{(2)} - I)$ (of a complex pair on the unit circle,
      [`EventKind`][]`.TORUS`).
    - `n_points`, `status` ([`BranchStatus`][]), `k` (the gait period followed, in actuation
      periods), `start_status` (the start's [`GaitStatus`][]): per branch.
    - `events`: [`BranchEvents`][], the located bifurcations and switching changes.
    - `names`: `"paper"` for the paper's model, else `"bodies"`. The paper's names of two bodies are
      properties, as on [`Gait`][]: `u`, `v1`, `v2` (the columns of `state`) and `stick_fraction1`,
      `stick_fraction2` (those of `stick_fraction`); they raise a `ValueError` for other than two bodies.
    """

    lam: Array
    state: Array
    mean_speed: Array
    cost_of_transport: Array
    e_d: Array
    work: Array
    stick_fraction: Array
    regime: Array
    n_switch: Array
    n_land: Array
    slip_margin: Array
    min_normal: Array
    multipliers: Array
    stable: Array
    liftoff: Array
    tangent: Array
    det_minus: Array
    det_plus: Array
    det_torus: Array
    n_points: Array
    status: Array
    k: Array
    start_status: Array
    events: BranchEvents
    parameter: str = eqx.field(static=True)
    contact: str = eqx.field(static=True)
    names: str = eqx.field(static=True, default=BODIES)


class Solver:
    """The batched corrector with everything but the unknowns fixed; calls return numpy arrays."""

    def __init__(self, C, physics_of, sel, contact, dt, k, lam0, scale, tol, max_iter, max_steps, omega, sets_omega):
        self.args = (C, physics_of, sel, contact, dt)
        dtype = jax.tree_util.tree_leaves(C)[0].dtype
        self.dtype = dtype
        self.const = tuple(jnp.asarray(x, dtype) for x in (lam0, scale))
        self.k = jnp.asarray(k, dtype)
        self.tol, self.max_iter, self.max_steps = jnp.asarray(tol, dtype), max_iter, jnp.asarray(max_steps, jnp.int32)
        self.lam0, self.scale, self.sets_omega = np.asarray(lam0), np.asarray(scale), sets_omega
        self.omega = np.broadcast_to(np.asarray(omega, np.float64), np.shape(lam0))

    def __call__(self, z0, zref, c, go, max_iter: int | None = None) -> corrector.Solved:
        arr = lambda x: jnp.asarray(x, self.dtype)
        it = jnp.asarray(self.max_iter if max_iter is None else max_iter, jnp.int32)
        # `patience` = `max_iter`: no point of a branch is stopped before `max_iter` iterations.
        r = corrector.correct_batch(*self.args, self.k, *self.const, arr(z0), arr(zref), arr(c),
                                    jnp.asarray(go), self.tol, it, self.max_steps, it)  # fmt: skip
        return jax.tree_util.tree_map(np.asarray, r)

    def lam(self, zeta):
        return self.lam0 + self.scale * zeta

    def period(self, zeta, k):
        """The gait period $kT$ at `zeta` (shape `(B, n)`)."""
        omega = self.lam(zeta.T).T if self.sets_omega else self.omega[:, None] + 0 * zeta
        return k[:, None] * 2 * np.pi / omega


def tangent(J: np.ndarray, prev: np.ndarray) -> np.ndarray:
    """Unit null vectors of $[M - I, \\partial\\Phi/\\partial\\zeta]$ (the last right singular
    vector), oriented along `prev`; NaN where the Jacobian is not finite."""
    n = J.shape[-1] - 1
    A = J[:, :n].copy()
    A[:, :, :n] -= np.eye(n)
    bad = ~np.all(np.isfinite(A), axis=(1, 2))
    A[bad] = 0
    t = np.linalg.svd(A)[2][:, -1]
    t = np.where((np.sum(t * prev, axis=-1) < 0)[:, None], -t, t)
    t[bad] = np.nan
    return t


class BranchSetup(NamedTuple):
    """A mechanism's branches as the corrector (`_corrector`) takes them
    ([`AbstractMechanism.branch_setup`][locomotion_jax.model._mechanism.AbstractMechanism.branch_setup]):
    the flat configurations `C` and the physics of each, the parameter's selector `sel`, the batch
    `shape`, the parameter's `label`, which branches' far end the step does not resolve (`far`), the
    forcing frequencies, whether the parameter sets them, and whether the results take the paper's
    names."""

    C: Any
    physics_of: Any
    sel: Any
    shape: tuple
    label: str
    far: np.ndarray  # the configuration at `stop` is not resolved
    omega: np.ndarray
    sets_omega: bool
    paper: bool


def paper_setup(params: Params, parameter, stops_of, dynamics, waveform, dtype) -> BranchSetup:
    """The paper's model's [`BranchSetup`][]: `parameter` a field or a waveform's coefficient."""
    spec = corrector.parse(parameter, waveform)
    flat, wave, axes, shape = prepare(params, waveform, dtype)
    C = configs(flat, wave, axes)
    sel = corrector.paper_selector(spec, C)
    B = math.prod(shape)
    stops = stops_of(shape, corrector.value(C, sel, parameter))
    # The far end of the range must be resolved too (the start is checked by `steady_gait`).
    # (A Fourier coefficient sets no time scale: the forcing's harmonics are counted, not weighed.)
    far = None
    if spec.harmonic < 0:
        end, end_wave = jax.vmap(lambda c, lam: corrector.with_value(c, sel, lam))(C, jnp.asarray(stops, flat.dtype))
        _, far = guard_two_mass(dynamics, end, end_wave, shape)
    omega = np.broadcast_to(np.asarray(wave.omega, np.float64), (B,))
    return BranchSetup(C, shooting.paper_physics, sel, shape, spec.label, _mask(far, B), omega,
                       spec.name == "omega" and spec.harmonic < 0, True)  # fmt: skip


def bodies_setup(mech, parameter, stops_of, dynamics, waveform, dtype, contact) -> BranchSetup:
    """The [`BranchSetup`][] of a chain or a mechanism: `parameter` a leaf named by its attribute."""
    if waveform is not None:
        raise ValueError(f"waveform= applies to Params; a {type(mech).__name__} carries its own waveforms.")
    flat, valid, shape = prepare_chain(mech, dtype)
    sel = corrector.parse_leaf(parameter, flat, type(mech).__name__)
    stops = stops_of(shape, corrector.value(flat, sel, parameter))
    end = jax.vmap(lambda c, lam: corrector.with_value(c, sel, lam))(flat, jnp.asarray(stops, flat.m.dtype))
    _, far = guard_chain(dynamics, end, valid & end.is_valid(), shape)
    B = math.prod(shape)
    omega = np.broadcast_to(np.asarray(flat.omega, np.float64), (B,))
    sets_omega = any(bool(np.any(np.asarray(m))) and corrector._leaf_names(p).endswith(".omega")
                     for p, m in jax.tree_util.tree_flatten_with_path(sel)[0])  # fmt: skip
    physics_of = shooting.physics_for(flat)
    return BranchSetup(flat, physics_of, sel, shape, parameter, _mask(far, B), omega, sets_omega, False)


def _mask(far, B: int) -> np.ndarray:
    return np.zeros(B, bool) if far is None else np.asarray(far).reshape(B)


def continuation(
    params: Params | Chain | Mechanism,
    parameter: str,
    stop: float | Sequence[float] | np.ndarray | Array,
    *,
    periods: int | Sequence[int] = (1, 2, 3, 4),
    max_points: int = 200,
    step: float = 0.01,
    max_step: float = 0.04,
    min_step: float = 1e-6,
    locate: bool | Sequence[str] = True,
    tol: float | None = None,
    max_iter: int = 8,
    transient: int = 30,
    dynamics: AbstractDynamics | None = None,
    waveform: AbstractWaveform | None = None,
    contact: str = "strict",
    start: str | ArrayLike = "paper",
    dtype: Any = None,
    verbose: bool = False,
) -> Branch:
    """Follow the steady gait of each configuration as `parameter` goes from its value to `stop`.

    The start is [`steady_gait`][]`(params, periods=periods, ...)`; its gait (of period `k`, stable or
    not) is continued (module docstring), and with `locate` its folds, period doublings, torus
    bifurcations, SSL/SL boundaries and lift-offs are located ([`BranchEvents`][]).

    **Arguments:**

    - `params`: [`Params`][], a [`Chain`][] or a [`Mechanism`][locomotion_jax.Mechanism] (any batch
      shape: one branch per configuration).
    - `parameter`: for [`Params`][], a field (`"omega"`, `"a"`, `"d"`, `"mhat"`, `"mu_s"`, ...), or
      `"cosN"`/`"sinN"`, the coefficient of harmonic `N` of a [`Fourier`][] `waveform`; for a chain or a
      mechanism, a leaf named by its attribute (`"omega"`, `"mu_s"`, `"c"`), every entry of it (they
      must be equal at the start), or one entry with an index (`"m[1]"`, `"mu_s_fwd[0]"`); a
      mechanism's element or friction law by its path (`"links[0].k"`, `"friction[0].mu_s_fwd"`).
    - `stop`: the parameter's end value (a number, or one per configuration).
    - `periods`: as in [`steady_gait`][], for the start.
    - `max_points`: points per branch, the start included.
    - `step`, `max_step`, `min_step`: first, largest and smallest arclength step, with the
      parameter in units of $|$`stop` $-$ start$|$.
    - `locate`: locate the branch's events (all kinds, none, or the kinds named, e.g. `("SSL_SL",)`);
      the others are reported between the two points that bracket them.
    - `tol`, `max_iter`: the corrector's Newton tolerance (as [`steady_gait`][]'s) and iterations.
    - `transient`, `dynamics`, `waveform`, `contact`, `start`, `dtype`: as in [`steady_gait`][].
      Under `contact="hop"` (SPEC §10) the orbits fly and land; a change of their sequence of
      flights and landings is a change of switching structure like a new stick interval.
    - `verbose`: print progress to stderr from the start: the start gait's stages (as
      [`steady_gait`][]'s), then the corrector's compilation, the walk and the event location.

    **Returns:** a [`Branch`][] with batch shape `params.batch_shape`. A configuration without a start
    gait or with invalid parameters has an empty branch and its status; the others are unaffected.

    !!! Example

        ```python
        b = continuation(Params(omega=4.0), "omega", 6.0)
        b.lam, b.mean_speed, b.stable, b.events.kind, b.events.lam
        ```
    """
    dynamics = Exact() if dynamics is None else dynamics
    if not isinstance(dynamics, Exact):
        raise TypeError(f"continuation needs Exact dynamics, got {type(dynamics).__name__}.")
    _check(max_points, step, max_step, min_step, max_iter)
    to_locate = kinds(locate)

    def stops_of(shape, lam0):
        B = math.prod(shape)
        try:
            stops = np.broadcast_to(np.asarray(stop, np.float64), shape).reshape(B)
        except ValueError:
            raise ValueError(f"stop must be a number or broadcast to the batch shape {shape}.") from None
        if not np.all(np.isfinite(stops)) or np.any(stops == lam0):
            raise ValueError(f"stop must be finite and differ from the start value of {parameter!r}, got {stop!r}.")
        return stops

    setup: BranchSetup = mechanism_arg(params).branch_setup(parameter, stops_of, dynamics, waveform, dtype, contact)
    C, shape = setup.C, setup.shape
    B = math.prod(shape)
    lam0 = corrector.value(C, setup.sel, parameter)
    stops = stops_of(shape, lam0)
    dtype_ = jax.tree_util.tree_leaves(C)[0].dtype
    f32 = jnp.finfo(dtype_).bits < 64
    tol = (1e-5 if f32 else 1e-11) if tol is None else float(tol)

    say = progress.reporter(verbose, "continuation")
    say(f"{B} branch(es) in {parameter!r}: the start gaits first")
    g = steady_gait(params, periods=periods, transient=transient, tol=tol, dynamics=dynamics,
                    waveform=waveform, contact=contact, start=start, dtype=dtype, verbose=verbose)  # fmt: skip
    fl = lambda x: np.asarray(x).reshape(B, *np.shape(x)[len(shape) :])
    unresolved = setup.far | (fl(g.status) == GaitStatus.UNRESOLVED)
    ok = fl(g.converged) & ~unresolved
    k = np.where(ok, fl(g.k), 1)
    scale = stops - lam0
    omega = setup.omega
    if setup.sets_omega:
        omega = np.minimum(lam0, stops)
    omega_min = float(np.min(omega[ok & (omega > 0)], initial=np.inf))
    T_max = 2 * np.pi / omega_min if np.isfinite(omega_min) else 1.0
    max_steps = dynamics.max_steps or default_max_steps(float(np.max(k)) * T_max, dynamics.dt)
    solve = Solver(C, setup.physics_of, setup.sel, contact, dynamics.dt, k, lam0, scale, tol, max_iter, max_steps,
                   setup.omega, setup.sets_omega)  # fmt: skip

    y = fl(g.state)
    n = y.shape[-1]
    z = np.concatenate([y, np.zeros((B, 1))], axis=-1)
    z = np.where(ok[:, None], z, 0.0)
    e = _last(n + 1)
    say("the corrector: compiling (first call only) and correcting the start points")
    r = solve(z, z, e[None].repeat(B, 0), ok)
    ok = ok & r.done
    status = np.where(ok, BranchStatus.MAX_POINTS, np.where(fl(g.status) == GaitStatus.INVALID,
                      BranchStatus.INVALID, BranchStatus.NO_START))  # fmt: skip
    status = np.where(unresolved, BranchStatus.UNRESOLVED, status)
    walk = _Walk(solve, r, ok, step, max_step, min_step, max_points)
    say(f"walking up to {max_points} points per branch")
    walk.run(status)
    data = _pack(walk.points, solve, k)
    say(f"{sum(len(p) for p in walk.points)} points; locating the events")
    events = find_events(data, status, walk.failed_at, solve, contact, to_locate, setup.paper)
    say("done")
    return _branch(data, status, k, fl(g.status), events, shape, dtype_, setup.label, contact, setup.paper)


def _last(n: int) -> np.ndarray:
    """The unit vector along $\\zeta$ (the last unknown) of `n` unknowns."""
    return np.eye(n)[n - 1]


SWITCH_STEP = 1e-3
"""Largest step across a change of switching structure (switch or landing count, the order of the
bodies' mode changes, or the sign of the slip margin or of the smallest normal force): a step that
changes it is retried shorter down to this, so that the corrector cannot jump to another branch with
another structure (past a fold two stable gaits coexist, their section states a few 1e-3 apart)."""

CORNER_STEP = 1e-4
"""First step onto the other piece of the branch after a corner (see `_Walk.cross`)."""

CORNER_PROBE = 1e-5
"""How far past the last point (along its tangent) the Jacobian of the other piece is evaluated."""

MAX_CORNERS = 32
"""Corners crossed per branch at most."""


def _signature(out) -> tuple:
    return (np.asarray(out.n_switch), np.asarray(out.n_land), np.asarray(out.sequence), np.asarray(out.margin) > 0,
            np.asarray(out.n_min) > 0)  # fmt: skip


class _Walk:
    """The predictor-corrector loop of all branches (module docstring), on the host."""

    def __init__(self, solve, r0, ok, step, max_step, min_step, max_points):
        B = len(ok)
        self.solve, self.B = solve, B
        self.step, self.max_step, self.min_step, self.max_points = step, max_step, min_step, max_points
        self.z, self.J = r0.z.copy(), r0.J.copy()
        self.t = tangent(r0.J, np.broadcast_to(_last(r0.z.shape[-1]), r0.z.shape))
        self.sig = _signature(r0.out)
        self.active = ok.copy()
        self.h = np.full(B, float(step))
        self.corners = np.zeros(B, int)
        self.failed_at = np.full(r0.z.shape, np.nan)
        self.points: list[list[dict]] = [[] for _ in range(B)]
        for i in np.flatnonzero(ok):
            self.points[i].append(_record(r0, self.t, int(i)))

    def accept(self, r, tn, good):
        for i in np.flatnonzero(good):
            self.points[i].append(_record(r, tn, int(i)))
        self.z = np.where(good[:, None], r.z, self.z)
        self.J = np.where(good[:, None, None], r.J, self.J)
        self.t = np.where(good[:, None], tn, self.t)
        self.sig = tuple(np.where(good, new, old) for new, old in zip(_signature(r.out), self.sig))

    def run(self, status):
        solve, small = self.solve, 16 * self.min_step
        e4 = np.broadcast_to(_last(self.z.shape[-1]), self.z.shape)
        while np.any(self.active):
            z, t, h, active = self.z, self.t, self.h, self.active
            zp = z + h[:, None] * t
            land = active & (zp[:, -1] >= 1)
            with np.errstate(all="ignore"):
                hl = (1 - z[:, -1]) / t[:, -1]
            zp = np.where(land[:, None], z + hl[:, None] * t, zp)
            r = solve(zp, zp, np.where(land[:, None], e4, t), active)
            tn = tangent(r.J, t)
            dist = np.linalg.norm(r.z - zp, axis=-1)
            turn = np.arccos(np.clip(np.sum(tn * t, axis=-1), -1, 1))
            same = np.all([a == b for a, b in zip(_signature(r.out), self.sig)], axis=0)
            good = active & r.done & (dist <= np.maximum(h / 2, small))
            good &= ((turn <= MAX_TURN) | (h <= small)) & (same | (h <= SWITCH_STEP))
            self.accept(r, tn, good)
            grow = np.where(r.it <= 2, 2.0, np.where(r.it <= 4, 1.2, 0.7))
            self.h = np.where(good, np.minimum(grow * h, self.max_step), h / 2)
            counts = np.array([len(p) for p in self.points])
            reached = good & land
            left = good & ~land & ((self.z[:, -1] < 0) | (self.z[:, -1] > 1))
            full = good & (counts >= self.max_points)
            dead = active & ~good & (self.h < self.min_step)
            lifted = dead & (r.out.status == Status.LIFTOFF)
            invalid = dead & ~r.valid & np.all(np.isfinite(zp), axis=-1)
            self.failed_at = np.where(dead[:, None], zp, self.failed_at)
            crossed = self.cross(dead & ~lifted & ~invalid & (self.corners < MAX_CORNERS))
            dead &= ~crossed
            full |= crossed & (np.array([len(p) for p in self.points]) >= self.max_points)
            status[:] = np.select(
                [reached, left, full & ~reached & ~left, lifted, invalid, dead],
                [BranchStatus.REACHED, BranchStatus.LEFT_RANGE, BranchStatus.MAX_POINTS, BranchStatus.LIFTOFF,
                 BranchStatus.INVALID, BranchStatus.FAILED],
                status,
            )  # fmt: skip
            self.active = active & ~(reached | left | full | dead)

    def cross(self, lanes: np.ndarray) -> np.ndarray:
        """Continue past a corner of the branch, where the step fails at the last point: a switching
        structure changes there (the corrector's Jacobian differs on the two sides, so that the
        branch has a corner, and may turn back: a non-smooth fold). The other side's piece has
        the null vector of the Jacobian just past the corner (along the tangent) as its tangent;
        of its two orientations, the one whose corrected point has another switching structure
        than the last point is taken."""
        if not np.any(lanes):
            return lanes
        solve, B = self.solve, self.B
        e4 = np.broadcast_to(_last(self.z.shape[-1]), self.z.shape)
        zq = self.z + CORNER_PROBE * self.t
        rq = solve(zq, zq, e4, lanes, max_iter=0)
        tq = tangent(rq.J, self.t)
        done = np.zeros(B, bool)
        for sign in (1.0, -1.0):
            go = lanes & ~done & np.all(np.isfinite(tq), axis=-1)
            if not np.any(go):
                break
            d = sign * tq
            zp = self.z + CORNER_STEP * d
            r = solve(zp, zp, d, go)
            other = ~np.all([a == b for a, b in zip(_signature(r.out), self.sig)], axis=0)
            good = go & r.done & other & (np.linalg.norm(r.z - zp, axis=-1) <= CORNER_STEP / 2)
            self.accept(r, tangent(r.J, d), good)
            done |= good
        self.h = np.where(done, CORNER_STEP, self.h)
        self.corners += done
        return done


def _check(max_points, step, max_step, min_step, max_iter) -> None:
    if not (isinstance(max_points, int) and max_points >= 2):
        raise ValueError(f"max_points must be an int >= 2, got {max_points!r}.")
    if not (isinstance(max_iter, int) and max_iter >= 1):
        raise ValueError(f"max_iter must be an int >= 1, got {max_iter!r}.")
    if not (0 < min_step <= step <= max_step and np.isfinite(max_step)):
        raise ValueError(f"need 0 < min_step <= step <= max_step (finite), got {min_step!r}, {step!r}, {max_step!r}.")


_FIELDS = ("dX", "ed", "w", "stuck", "margin", "n_min", "n_switch", "n_land", "sequence", "lifted")


def _record(r: corrector.Solved, t: np.ndarray, i: int) -> dict:
    rec = {name: getattr(r.out, name)[i] for name in _FIELDS}
    return dict(rec, z=r.z[i], J=r.J[i], t=t[i])


def _pack(points: list[list[dict]], solve: Solver, k: np.ndarray) -> dict[str, np.ndarray]:
    """Per-point arrays `(B, n)` padded with NaN; derived quantities per point."""
    B = len(points)
    n = max(2, max(len(p) for p in points))
    like = next(p[0] for p in points if p) if any(points) else None
    S = like["z"].shape[0] - 1 if like is not None else 3
    N = like["stuck"].shape[0] if like is not None else 2
    out: dict[str, np.ndarray] = {}
    template = {"z": np.zeros(S + 1), "J": np.zeros((S + 2, S + 1)), "t": np.zeros(S + 1), "stuck": np.zeros(N),
                **{f: 0.0 for f in _FIELDS if f != "stuck"}}  # fmt: skip
    for name, shape_of in template.items():
        arr = np.full((B, n) + np.shape(shape_of), np.nan)
        for i, p in enumerate(points):
            for j, rec in enumerate(p):
                arr[i, j] = rec[name]
        out[name] = arr
    count = np.array([len(p) for p in points])
    valid = np.arange(n)[None, :] < count[:, None]
    out["valid"], out["count"] = valid, count
    zeta = out["z"][..., S]
    out["lam"] = solve.lam0[:, None] + solve.scale[:, None] * zeta
    out["period"] = solve.period(zeta, k)
    M = np.where(valid[..., None, None], out["J"][..., :S, :S], 0.0)
    ev = np.linalg.eigvals(M)
    ev = np.take_along_axis(ev, np.argsort(-np.abs(ev), axis=-1), -1)
    out["multipliers"] = np.where(valid[..., None], ev, np.nan)
    out["det_minus"] = np.where(valid, np.linalg.det(M - np.eye(S)), np.nan)
    out["det_plus"] = np.where(valid, np.linalg.det(M + np.eye(S)), np.nan)
    out["det_torus"] = np.where(valid, torus_function(M), np.nan)
    out["complex_radius"] = np.where(valid, complex_radius(ev), np.nan)
    return out


def _branch(d, status, k, start_status, events, shape, dtype, label, contact, paper: bool) -> Branch:
    valid = d["valid"]
    dX = d["dX"]
    with np.errstate(divide="ignore", invalid="ignore"):
        cot = np.where(valid & (dX == 0), np.inf, d["ed"] / np.abs(dX))
        stuck = d["stuck"] / d["period"][..., None]
    ssl = np.max(d["stuck"], axis=-1) > STICK_TOL
    regime = np.where(valid, np.where(ssl, Regime.SSL, Regime.SL), Regime.UNDETERMINED)
    n = valid.shape[1]
    re = lambda x, dt=dtype: jnp.asarray(x, dt).reshape(shape + (n,) + np.shape(x)[2:])
    mult = np.abs(np.nan_to_num(d["multipliers"], nan=np.inf))
    S = d["z"].shape[-1] - 1
    state = d["z"][..., :S]
    return Branch(
        lam=re(d["lam"]),
        state=re(state),
        mean_speed=re(dX / d["period"]),
        cost_of_transport=re(cot),
        e_d=re(d["ed"]),
        work=re(d["w"]),
        stick_fraction=re(stuck),
        regime=re(regime, jnp.int32),
        n_switch=re(np.nan_to_num(d["n_switch"]), jnp.int32),
        n_land=re(np.nan_to_num(d["n_land"]), jnp.int32),
        slip_margin=re(d["margin"]),
        min_normal=re(d["n_min"]),
        multipliers=jnp.asarray(d["multipliers"]).reshape(shape + (n, S)),
        stable=re(valid & (np.max(mult, axis=-1) < 1), bool),
        liftoff=re(valid & (d["n_min"] <= 0), bool),
        tangent=re(d["t"][..., S]),
        det_minus=re(d["det_minus"]),
        det_plus=re(d["det_plus"]),
        det_torus=re(d["det_torus"]),
        n_points=jnp.asarray(d["count"], jnp.int32).reshape(shape),
        status=jnp.asarray(status, jnp.int32).reshape(shape),
        k=jnp.asarray(k, jnp.int32).reshape(shape),
        start_status=jnp.asarray(start_status, jnp.int32).reshape(shape),
        events=jax.tree_util.tree_map(lambda x: x.reshape(shape + x.shape[1:]), events),
        parameter=label,
        contact=contact,
        names=PAPER if paper else BODIES,
    )
