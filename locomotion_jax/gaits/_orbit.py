"""Periodic gaits of a parametrised actuation and their exact sensitivities: the exact
optimisers' oracle, for the paper's model and for chains and mechanisms alike.

A decision vector $\\theta$ sets a model's actuation: for the paper's model, the stroke's
shape in units of $a_\\max$ and $\\log\\omega$ (a family of `_shapes`: a [`Fourier`][] series or
a periodic [`Spline`][]; [`ShapeActuation`][locomotion_jax.gaits._orbit.ShapeActuation]); for a
chain or a mechanism, one such signal per actuated element (`_element_orbit`). Either way the
actuated model is a physics ([`AbstractPhysics`][locomotion_jax.AbstractPhysics]) and the
period map is the N-body exact engine's (`dynamics._engine`): the paper's model is the
two-mass chain of `Params.physics`.

For a given $\\theta$ the steady gait is the fixed point $y^*$ of the $k$-period map
$\\Phi_k(y, \\theta)$ of the reduced state $y = (u_1, \\dots, u_{N-1}, v_1, \\dots, v_N)$ at the
phase $\\omega t \\equiv 0$ (for the paper's model $(u, v_1, v_2)$, as in [`steady_gait`][]),
found by Newton's method from a warm start with the monodromy $M = \\partial\\Phi/\\partial y$ by
forward mode through the engine. Over the $k$ periods the engine also accumulates the drift of
the centre of mass $\\Delta X$ (eq. 4), the dissipated energy $e_d$ (eq. 15, SPEC §8) and the
smallest normal force $\\min_{i,t} N_i$ (eq. 5 generalised, at the step ends). Their total
derivatives follow from the implicit function theorem,

$$\\frac{dy^*}{d\\theta} = (I - M)^{-1}\\frac{\\partial\\Phi}{\\partial\\theta},\\qquad
\\frac{dF}{d\\theta} = \\frac{\\partial F}{\\partial\\theta} + \\frac{\\partial F}{\\partial y}\\frac{dy^*}{d\\theta},$$

so one forward-mode pass over the gait period in the $\\dim y + p$ directions $(y, \\theta)$ at
the converged orbit gives every gradient (with `monodromy_only`, Newton's iterations before it
push the directions of $y$ alone: [`newton_orbit`][locomotion_jax.gaits._orbit.newton_orbit]);
located events enter with their implicit-function times (the saltation of each switch).
Whole-period averages of the orbit are exact: no transient, no window.
"""

import abc
from collections import Counter
from typing import Any, ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from .._custom_types import Array, Contact
from .._loops import lane_while_loop
from .._status import Status
from ..dynamics import _engine as engine
from ..dynamics._compile import engine_jit
from ..model._params import Params
from ..model._physics import AbstractPhysics, least_contact_load
from ..model._two_mass import initial_gap
from ..optimisation._shapes import AbstractShape
from ._shooting import _reduced, _section_state, displacement


TRACES: Counter = Counter()
"""Python-level traces of the compiled functions for the paper's model (keys `"evaluate"`,
`"relax"`); a test checks that a whole optimisation traces each once."""


PATIENCE = 3
"""Newton iterations without halving the smallest residual before an orbit is given up
([`newton_orbit`][locomotion_jax.gaits._orbit.newton_orbit]'s `patience`, and the steady-gait
corrector's): in the exact optimisers' oracles, the steady gaits of the paper's sinusoid baseline
and of its verification, and the chain optimiser's screen. A converging solve halves it at nearly
every iteration; one without an orbit near its start cycles (from a point past a jump of the
objective, where a line search often probes, or a wave with no gait of that period), and a batch
runs in lockstep."""


class Period(NamedTuple):
    """`k` periods from a section state: the end's reduced state, $(\\Delta X, e_d, \\min N)$, success."""

    y: Array
    figures: Array
    ok: Array


def period(
    P: AbstractPhysics, contact: Contact, dt: float | Array, max_steps: Array, y: Array, k: Array, loop=lane_while_loop
) -> Period:
    """The `k`-period map $\\Phi_k$ of the physics `P` from the reduced state `y`, with the figures
    the optimisers need (`max_steps` per actuation period). `loop`: the time loop, with
    `lax.while_loop`'s signature (default `_loops.lane_while_loop`;
    `gaits._adjoint` passes one that reverse mode traverses)."""
    t_end = k.astype(y.dtype) * 2 * jnp.pi / P.omega
    st0 = _section_state(P, contact, y)

    def normal(s):
        # Eq. (5) generalised (SPEC §8), at a step's end: N_i = m_i - fy_i + fy_{i-1}; the bodies on the ground.
        return least_contact_load(P, P.loads(P.drive(s.cph, s.sph), s.y.x).N, s.t)

    def cond(c):
        s, _, n = c
        return (s.t < t_end) & (s.status == Status.OK) & (n < k * max_steps)

    def body(c):
        s, low, n = c
        s, _ = engine.step(P, contact, dt, s, t_end)
        return s, jnp.minimum(low, normal(s)), n + 1

    st, low, _ = loop(cond, body, (st0, normal(st0), jnp.zeros((), jnp.int32)))
    ok = (st.status == Status.OK) & (st.t >= t_end)
    return Period(_reduced(st, P), jnp.stack([displacement(P, st0, st), st.y.ed, low]), ok)


class Orbit(NamedTuple):
    """The steady gait of one decision vector and its sensitivities.

    - `y`: the fixed point of $\\Phi_k$ (the reduced state); `figures`: $(\\Delta X, e_d, \\min N)$
      over the gait's `k` actuation periods;
    - `gradient`: $d\\,\\text{figures}/d\\theta$, shape `(3, p)`;
    - `monodromy`: $M$ at the fixed point; `ok`: Newton converged and the period completed;
    - `n_iter`, `residual`: Newton iterations and $\\|\\Phi(y) - y\\|_\\infty$;
    - `figures_y`: $\\partial\\,\\text{figures}/\\partial y$ at the fixed point, shape `(3, dim y)`
      (with $M$, what an adjoint solve needs: `gaits._adjoint`).
    """

    y: Array
    figures: Array
    gradient: Array
    monodromy: Array
    ok: Array
    n_iter: Array
    residual: Array
    figures_y: Array


DIVERGED = 1e3
"""An iterate of Newton's method larger than this times its start's scale (`1 + max|y0|`) has
diverged: its convergence test does not grow with it (`tolerance_scale`)."""


def tolerance_scale(y: Array, y0: Array) -> Array:
    """The scale of Newton's convergence test $|\\Phi(y) - y| \\le \\text{tol}\\,(1 + \\text{scale})$:
    the iterate's largest component, but no more than `DIVERGED` times the start's scale. A
    relative test alone accepts an iterate that ran off to a huge velocity (a capsule's orbit at
    $|v| \\approx 10^{16}$ had residual 64, within $10^{-11}$ of its size), which no
    friction-driven gait has; an iterate of an orbit near its start is judged as before."""
    return jnp.minimum(jnp.max(jnp.abs(y)), DIVERGED * (1 + jnp.max(jnp.abs(y0))))


def newton_orbit(
    run,
    y0: Array,
    theta: Array,
    tol: Array | float,
    max_iter: Array | int,
    *,
    monodromy_only: bool = False,
    gradient: Array | bool = True,
    patience: Array | int | None = None,
) -> Orbit:
    """The fixed point of a period map and the figures' implicit-function gradient.

    `run(z)`, with `z` the section state `y` followed by the decision vector `theta`, returns
    the state after the gait's periods followed by its figures, and whether the period
    completed. Newton's method on $\\Phi(y) - y$ from `y0`, each iterate linearised by
    forward mode; the Jacobian at the last iterate gives the monodromy
    $M = \\partial\\Phi/\\partial y$ and, by the implicit function theorem,
    $d\\,\\text{figures}/d\\theta = J_{f\\theta} + J_{fy} (I - M)^{-1} J_{y\\theta}$.

    Newton's steps need only the `ny` directions of `y`. With `monodromy_only`, each iterate
    pushes those alone and one pass in all `ny + p` directions follows at the last iterate:
    `(iterations + 1) ny + (ny + p)` directions in all instead of `(iterations + 1)(ny + p)`,
    for a second differentiated copy of `run` in the compiled program (its compile time).
    Without it, every iterate pushes all `ny + p` directions (one differentiated copy).

    `gradient` (with `monodromy_only`; a bool, or a traced boolean scalar that is not batched):
    where false, the pass in all directions is skipped and the gradient returned is zero, the
    rest as with it (a screen that ranks orbits by their figures alone). Traced, it picks the
    branch at run time (`lax.cond`; under `vmap` an unbatched predicate runs one branch), so
    both uses share one compiled program.

    `patience` (`None`: `max_iter`, never early): Newton's method stops, unconverged, once
    `patience` iterations in a row have not halved the smallest residual reached so far. Where
    the period map has no fixed point near the start (a jump of the gait's contact sequence),
    the iterates cycle instead of converging, and in a vmapped batch such a row would hold the
    others for `max_iter` iterations."""
    ny = y0.shape[0]
    eye = jnp.eye(ny, dtype=theta.dtype)

    def linearise(y):
        # One forward pass in all ny + p directions (the gradient needs all of J).
        J, (val, ok) = jax.jacfwd(lambda z: (lambda r: (r[0], r))(run(z)), has_aux=True)(jnp.concatenate([y, theta]))
        return val, J, ok & jnp.all(jnp.isfinite(val)) & jnp.all(jnp.isfinite(J))

    def linearise_y(y):
        # One forward pass in the ny directions of y: (Phi, figures) and their y-Jacobian.
        J, (val, ok) = jax.jacfwd(lambda u: (lambda r: (r[0], r))(run(jnp.concatenate([u, theta]))), has_aux=True)(y)
        return val, J, ok & jnp.all(jnp.isfinite(val)) & jnp.all(jnp.isfinite(J))

    step_pass = linearise_y if monodromy_only else linearise
    patience = max_iter if patience is None else patience

    def residual(y, val):
        return jnp.max(jnp.abs(val[:ny] - y))

    def small(y, val):
        return residual(y, val) <= tol * (1 + tolerance_scale(y, y0))

    def cond(c):
        _, _, _, ok, it, done, _, since, started = c
        return ~started | (~done & ok & (it < max_iter) & (since < patience))

    def body(c):
        # The first pass linearises the start; each later one takes a Newton step first. One
        # call site of the differentiated period map: it is traced and compiled once.
        y, val, J, _, it, _, best, since, started = c
        y1 = jnp.where(started, y + jnp.linalg.solve(J[:ny, :ny] - eye, y - val[:ny]), y)
        val1, J1, ok1 = step(y1)
        r1 = residual(y1, val1)
        since1 = jnp.where(started, jnp.where(r1 <= best / 2, 0, since + 1), 0)
        it1 = jnp.where(started, it + 1, it)
        return y1, val1, J1, ok1, it1, small(y1, val1), jnp.minimum(best, r1), since1, jnp.asarray(True)

    step = jax.jit(step_pass)  # traced once: `eval_shape` below and the loop's body share its trace
    val0, J0, ok0 = jax.tree_util.tree_map(lambda a: jnp.zeros(a.shape, a.dtype), jax.eval_shape(step, y0))
    zero = jnp.zeros((), jnp.int32)
    init = (y0, val0, J0, ok0, zero, jnp.asarray(False), jnp.asarray(jnp.inf, y0.dtype), zero, jnp.asarray(False))
    y, val, J, ok, it, done, _, _, _ = lane_while_loop(cond, body, init)
    if monodromy_only:
        # The full Jacobian once, at the last iterate (the same point: the same values).
        full = lambda y, val, J: linearise(y)
        # Or none: the y-columns alone, the theta-columns zero.
        skip = lambda y, val, J: (val, jnp.pad(J, ((0, 0), (0, theta.shape[0]))), jnp.asarray(True))
        if isinstance(gradient, bool):
            val, J, ok_full = (full if gradient else skip)(y, val, J)
        else:
            val, J, ok_full = jax.lax.cond(gradient, full, skip, y, val, J)
        ok = ok & ok_full
    M = J[:ny, :ny]
    dy = jnp.linalg.solve(eye - M, J[:ny, ny:])
    grad = J[ny:, ny:] + J[ny:, :ny] @ dy
    good = ok & done & jnp.all(jnp.isfinite(grad))
    return Orbit(y, val[ny:], grad, M, good, it, jnp.max(jnp.abs(val[:ny] - y)), J[ny:, :ny])


class AbstractActuation(eqx.Module):
    """How a decision vector actuates a model (static: hashed into the compiled oracle).

    `physics(model, theta, a_max)` is the model driven by the actuation of `theta` (one
    configuration, traced); `rest(model, P)` the positions at rest with relaxed springs, from
    which a fresh transient starts; `traces` the counter of the compiled functions' traces."""

    traces: ClassVar[Counter]

    @abc.abstractmethod
    def physics(self, model: Any, theta: Array, a_max: Array) -> AbstractPhysics:
        """The physics of `model` under the actuation of `theta`."""

    @abc.abstractmethod
    def rest(self, model: Any, P: AbstractPhysics) -> Array:
        """Positions at $t = 0$, shape `(N,)`, at rest with relaxed springs."""


class ShapeActuation(AbstractActuation):
    """The paper's model ([`Params`][locomotion_jax.Params]) with its rest length $\\ell_0(t)$ the
    waveform of a shape family's decision vector (`_shapes`), about $\\bar\\ell$."""

    shape: AbstractShape
    traces: ClassVar[Counter] = TRACES

    def physics(self, model: Params, theta: Array, a_max: Array) -> AbstractPhysics:
        P = model.physics(self.shape.waveform(theta, a_max, model.lbar))
        # Coefficients built in the default float (a zero sinusoid's) take the decision vector's.
        cast = lambda x: x.astype(theta.dtype) if jnp.issubdtype(x.dtype, jnp.floating) else x
        return jax.tree_util.tree_map(cast, P)

    def rest(self, model: Params, P: AbstractPhysics) -> Array:
        # The relaxed spring at its mean rest length, eq. (14) with x2 - x1 = sqrt(lbar^2 - d^2).
        gap = initial_gap(model, "relaxed")
        return jnp.stack([jnp.zeros_like(gap), gap])


def _orbit_one(
    model, a_max, theta, y0, k, actuation, contact, dt, max_steps, tol, max_iter, monodromy_only, gradient, patience
) -> Orbit:
    ny = y0.shape[0]

    def run(z):
        P = actuation.physics(model, z[ny:], a_max)
        out = period(P, contact, dt, max_steps, z[:ny], k)
        return jnp.concatenate([out.y, out.figures]), out.ok

    return newton_orbit(run, y0, theta, tol, max_iter, monodromy_only=monodromy_only, gradient=gradient,
                        patience=patience)  # fmt: skip


def _evaluate(model, a_max, theta, y0, k, actuation, contact, dt, max_steps, tol, max_iter, monodromy_only, gradient,
              patience=None):  # fmt: skip
    actuation.traces["evaluate"] += 1  # runs only while tracing
    # `gradient` stays outside the vmap: one branch runs for the whole batch.
    one = lambda th, y, kk: _orbit_one(
        model, a_max, th, y, kk, actuation, contact, dt, max_steps, tol, max_iter, monodromy_only, gradient, patience
    )
    return jax.vmap(one)(theta, y0, k)


def _relax(model, a_max, theta, y0, fresh, periods, actuation, contact, dt, max_steps):
    """`periods` actuation periods from the section state `y0`, or from rest with relaxed
    springs where `fresh`: the reduced state at the end (a start for Newton's method)."""
    actuation.traces["relax"] += 1

    def one(th, y, new):
        P = actuation.physics(model, th, a_max)
        rest = engine.init(P, contact, actuation.rest(model, P))
        sec = _section_state(P, contact, y)
        st = jax.tree_util.tree_map(lambda a, b: jnp.where(new, a, b), rest, sec)
        t_end = periods.astype(y.dtype) * 2 * jnp.pi / P.omega

        def cond(c):
            s, n = c
            return (s.t < t_end) & (n < periods * max_steps)

        def body(c):
            s, n = c
            return engine.step(P, contact, dt, s, t_end)[0], n + 1

        st, _ = lane_while_loop(cond, body, (st, jnp.zeros((), jnp.int32)))
        return _reduced(st, P)

    return jax.vmap(one)(theta, y0, fresh)


# The step and the iteration cap are data: oracles of any step share a compiled program.
evaluate = engine_jit(_evaluate, ("actuation", "contact", "monodromy_only"))
relax = engine_jit(_relax, ("actuation", "contact"))


class Oracle(eqx.Module):
    """The compiled evaluations of one problem of the paper's model (static: the shape family and
    contact; the step `dt` and Newton's `max_iter` reach the program as data; `patience`:
    [`newton_orbit`][locomotion_jax.gaits._orbit.newton_orbit]'s, traced, `None` for `max_iter`)."""

    params: Params
    a_max: Array
    max_steps: Array
    tol: Array
    shape: AbstractShape = eqx.field(static=True)
    contact: Contact = eqx.field(static=True)
    dt: float = eqx.field(static=True)
    max_iter: int = eqx.field(static=True)
    patience: Array | None = None

    @property
    def dtype(self) -> Any:
        return self.params.dtype

    def orbits(self, theta: Array, y0: Array, k: Array, gradient: bool = True) -> Orbit:
        """Steady gaits of period `k` actuation periods (int32, per row) and their sensitivities,
        for a batch of decision vectors, from warm starts `y0`; without `gradient`, the same orbits
        with a zero gradient, at a fraction of the cost (the same compiled program)."""
        dt, max_iter = jnp.asarray(self.dt, self.dtype), jnp.asarray(self.max_iter, jnp.int32)
        return evaluate(self.params, self.a_max, theta, y0, k, ShapeActuation(self.shape), self.contact, dt,
                        self.max_steps, self.tol, max_iter, True, jnp.asarray(gradient), self.patience)  # fmt: skip

    def transient(self, theta: Array, y0: Array, fresh: Array, periods: Array) -> Array:
        """The reduced state after `periods` periods (from `y0`, or from rest where `fresh`)."""
        return relax(self.params, self.a_max, theta, y0, fresh, periods, ShapeActuation(self.shape), self.contact,
                     jnp.asarray(self.dt, self.dtype), self.max_steps)  # fmt: skip
