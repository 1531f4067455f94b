"""Periodic gaits of a parametrised actuation and their exact sensitivities (the exact optimiser's oracle).

The decision vector $\\theta$ holds the stroke's shape in units of $a_\\max$ and $\\log\\omega$
(a family of `_shapes`: a [`Fourier`][] series or a periodic [`Spline`][]); the family maps it
to the waveform $\\ell_0(t)$.

For a given $\\theta$ the steady gait is the fixed point $y^*$ of the period map
$\\Phi(y, \\theta)$ of the reduced state $y = (u, v_1, v_2)$ at the phase
$\\omega t \\equiv 0$ (as in [`steady_gait`][]), found by Newton's method from a warm
start with the monodromy $M = \\partial\\Phi/\\partial y$ by forward mode through the
exact engine. Over one period the engine also accumulates the drift of the centre of
mass $\\Delta X$ (eq. 4), the dissipated energy $e_d$ (eq. 15) and the smallest normal
force $\\min(N_1, N_2)$ (eq. 5, at the step ends). Their total derivatives follow
from the implicit function theorem,

$$\\frac{dy^*}{d\\theta} = (I - M)^{-1}\\frac{\\partial\\Phi}{\\partial\\theta},\\qquad
\\frac{dF}{d\\theta} = \\frac{\\partial F}{\\partial\\theta} + \\frac{\\partial F}{\\partial y}\\frac{dy^*}{d\\theta},$$

so one forward-mode pass over one period in the $3 + p$ directions $(y, \\theta)$ at the
converged orbit gives every gradient (Newton's iterations before it push the 3 directions
of $y$ alone: `newton_orbit(monodromy_only=True)`); located events enter with their
implicit-function times (the saltation of each switch). Whole-period averages of the orbit
are exact: no transient, no window.
"""

from collections import Counter
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from .._custom_types import Array, Contact
from .._status import Status
from ..dynamics import _exact as exact
from ..dynamics._compile import engine_jit
from ..model._params import Params
from ..model._two_mass import initial_gap
from ..model._waveform import AbstractWaveform
from ..optimisation._shapes import AbstractShape
from ._period import reduced as _reduced, section_state as _section_state


TRACES: Counter = Counter()
"""Python-level traces of the compiled functions (keys `"evaluate"`, `"relax"`); a test
checks that a whole optimisation traces each once."""


class Period(NamedTuple):
    """`k` periods from a section state: the end's reduced state, $(\\Delta X, e_d, \\min N)$, success."""

    y: Array
    figures: Array
    ok: Array


def period(
    params: Params, wave: AbstractWaveform, contact: Contact, dt: float, max_steps: Array, y: Array, k: Array
) -> Period:
    """The `k`-period map $\\Phi_k$ from the reduced state `y`, with the figures the optimiser needs
    (`max_steps` per actuation period)."""
    P = exact.consts(params, wave)
    t_end = k.astype(y.dtype) * 2 * jnp.pi / wave.omega
    st0 = _section_state(params, wave, contact, y)

    def normal(s):
        # Eq. (5) at a step's end: N1 = m1 - fy, N2 = m2 + fy, fy = T d / l.
        l0, _, _ = wave.at_phase(s.cph, s.sph)
        u = s.y.x2 - s.y.x1
        length = jnp.sqrt(u * u + P.dd)
        fy = P.k * (length - l0) / length * P.d
        return jnp.minimum(P.m1 - fy, P.m2 + fy)

    def cond(c):
        s, _, n = c
        return (s.t < t_end) & (s.status == Status.OK) & (n < k * max_steps)

    def body(c):
        s, low, n = c
        s, _ = exact.step(params, wave, contact, dt, s, t_end, None, P)
        return s, jnp.minimum(low, normal(s)), n + 1

    st, low, _ = jax.lax.while_loop(cond, body, (st0, normal(st0), jnp.zeros((), jnp.int32)))
    com = lambda s: P.mhat * s.y.x1 + (1 - P.mhat) * s.y.x2
    ok = (st.status == Status.OK) & (st.t >= t_end)
    return Period(_reduced(st), jnp.stack([com(st) - com(st0), st.y.ed, low]), ok)


class Orbit(NamedTuple):
    """The steady gait of one decision vector and its sensitivities.

    - `y`: the fixed point $(u, v_1, v_2)$ of $\\Phi_k$; `figures`: $(\\Delta X, e_d, \\min N)$ over
      the gait's `k` actuation periods;
    - `gradient`: $d\\,\\text{figures}/d\\theta$, shape `(3, p)`;
    - `monodromy`: $M$ at the fixed point; `ok`: Newton converged and the period completed;
    - `n_iter`, `residual`: Newton iterations and $\\|\\Phi(y) - y\\|_\\infty$.
    """

    y: Array
    figures: Array
    gradient: Array
    monodromy: Array
    ok: Array
    n_iter: Array
    residual: Array


def newton_orbit(
    run, y0: Array, theta: Array, tol: Array | float, max_iter: Array | int, *, monodromy_only: bool = False
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
    Without it, every iterate pushes all `ny + p` directions (one differentiated copy)."""
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

    def small(y, val):
        return jnp.max(jnp.abs(val[:ny] - y)) <= tol * (1 + jnp.max(jnp.abs(y)))

    def cond(c):
        _, _, _, ok, it, done = c
        return ~done & ok & (it < max_iter)

    def body(c):
        y, val, J, _, it, _ = c
        y1 = y + jnp.linalg.solve(J[:ny, :ny] - eye, y - val[:ny])
        val1, J1, ok1 = step_pass(y1)
        return y1, val1, J1, ok1, it + 1, small(y1, val1)

    val0, J0, ok0 = step_pass(y0)
    init = (y0, val0, J0, ok0, jnp.zeros((), jnp.int32), small(y0, val0))
    y, val, J, ok, it, done = jax.lax.while_loop(cond, body, init)
    if monodromy_only:
        # The full Jacobian once, at the last iterate (the same point: the same values).
        val, J, ok_full = linearise(y)
        ok = ok & ok_full
    M = J[:ny, :ny]
    dy = jnp.linalg.solve(eye - M, J[:ny, ny:])
    grad = J[ny:, ny:] + J[ny:, :ny] @ dy
    good = ok & done & jnp.all(jnp.isfinite(grad))
    return Orbit(y, val[ny:], grad, M, good, it, jnp.max(jnp.abs(val[:ny] - y)))


def _orbit_one(params, a_max, theta, y0, k, shape, contact, dt, max_steps, tol, max_iter) -> Orbit:
    def run(z):
        out = period(params, shape.waveform(z[3:], a_max, params.lbar), contact, dt, max_steps, z[:3], k)
        return jnp.concatenate([out.y, out.figures]), out.ok

    return newton_orbit(run, y0, theta, tol, max_iter, monodromy_only=True)


def _evaluate(params, a_max, theta, y0, k, shape, contact, dt, max_steps, tol, max_iter):
    TRACES["evaluate"] += 1  # runs only while tracing
    one = lambda th, y, kk: _orbit_one(params, a_max, th, y, kk, shape, contact, dt, max_steps, tol, max_iter)
    return jax.vmap(one)(theta, y0, k)


def _relax(params, a_max, theta, y0, fresh, periods, shape, contact, dt, max_steps):
    """`periods` actuation periods from the section state `y0`, or from the relaxed spring
    at rest where `fresh`: the reduced state at the end (a start for Newton's method)."""
    TRACES["relax"] += 1

    def one(th, y, new):
        wave = shape.waveform(th, a_max, params.lbar)
        P = exact.consts(params, wave)
        gap = initial_gap(params, "relaxed")
        rest = exact.init(params, wave, contact, jnp.zeros_like(gap), gap)
        sec = _section_state(params, wave, contact, y)
        st = jax.tree_util.tree_map(lambda a, b: jnp.where(new, a, b), rest, sec)
        t_end = periods.astype(gap.dtype) * 2 * jnp.pi / wave.omega
        steps = periods * max_steps

        def cond(c):
            s, n = c
            return (s.t < t_end) & (n < steps)

        def body(c):
            s, n = c
            return exact.step(params, wave, contact, dt, s, t_end, None, P)[0], n + 1

        st, _ = jax.lax.while_loop(cond, body, (st, jnp.zeros((), jnp.int32)))
        return _reduced(st)

    return jax.vmap(one)(theta, y0, fresh)


evaluate = engine_jit(_evaluate, ("shape", "contact", "dt", "max_iter"))
relax = engine_jit(_relax, ("shape", "contact", "dt"))


class Oracle(eqx.Module):
    """The compiled evaluations of one problem (static: the shape family, contact, step, iterations)."""

    params: Params
    a_max: Array
    max_steps: Array
    tol: Array
    shape: AbstractShape = eqx.field(static=True)
    contact: Contact = eqx.field(static=True)
    dt: float = eqx.field(static=True)
    max_iter: int = eqx.field(static=True)

    def orbits(self, theta: Array, y0: Array, k: Array) -> Orbit:
        """Steady gaits of period `k` actuation periods (int32, per row) and their sensitivities,
        for a batch of decision vectors, from warm starts `y0`."""
        return evaluate(self.params, self.a_max, theta, y0, k, self.shape, self.contact, self.dt,
                        self.max_steps, self.tol, self.max_iter)  # fmt: skip

    def transient(self, theta: Array, y0: Array, fresh: Array, periods: Array) -> Array:
        """The reduced state after `periods` periods (from `y0`, or from rest where `fresh`)."""
        return relax(self.params, self.a_max, theta, y0, fresh, periods, self.shape, self.contact, self.dt,
                     self.max_steps)  # fmt: skip
