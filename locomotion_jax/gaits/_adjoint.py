"""Reverse-mode derivatives of a chain's steady gait by the implicit function theorem (an adjoint solve).

The steady gait of a decision vector $\\theta$ (the chain optimiser's, `_element_orbit`) is the fixed
point $y^* = \\Phi(y^*, \\theta)$ of the $k$-period map, with figures $F = f(y^*, \\theta)$
($\\Delta X$, $e_d$, $\\min N$ over the $k$ periods). [`steady_gait`][] solves it by Newton's
method with $M = \\partial\\Phi/\\partial y$ by forward mode in the $n_y = 2N - 1$ directions of
$y$ only (the last iterate's linearisation, at the fixed point returned, gives $M$ and $f_y$),
and defines its reverse-mode derivative: for output cotangents $(\\bar y, \\bar F)$,

$$\\lambda = (I - M)^{-T}(\\bar y + f_y^T \\bar F), \\qquad
\\bar\\theta = \\Phi_\\theta^T \\lambda + f_\\theta^T \\bar F,$$

one transposed linear solve of size $n_y$ and one vector-Jacobian product of $(\\Phi, f)$ over the
gait's $k$ periods at $(y^*, \\theta)$. That product runs the same engine step in a
checkpointed loop (`equinox.internal.while_loop(kind="checkpointed")`), so its cost does not grow
with the number of parameters. By default it stores the state after every step (memory: the step
cap times one engine state per gait), so that the backward pass recomputes no step; fewer
checkpoints trade memory for recomputation (binomial checkpointing). Located events enter as in
forward mode: their times by the implicit function theorem (`_numerics.root`'s derivative, linear
in the tangents, transposed here), which gives the saltation of each switch.

So `jax.grad` of a scalar function of the gait (cost of transport, speed) with respect to all
$p$ coefficients costs one gait solve and one reverse pass, against $n_y + p$ directions for
the forward-mode oracle ([`ChainOracle.orbits`][locomotion_jax.gaits._element_orbit.ChainOracle.orbits]).

Only reverse mode is defined (a `custom_vjp`): `jax.jvp`/`jax.jacfwd` of [`steady_gait`][] raise
JAX's error for a `custom_vjp` function; forward-mode sensitivities come from the oracle's
`Orbit.gradient`.
"""

from typing import NamedTuple

import equinox as eqx
import equinox.internal as eqxi
import jax
import jax.numpy as jnp

from .._custom_types import Array
from ._element_orbit import ChainOracle, period, with_waves
from ._orbit import newton_orbit


class AdjointGait(NamedTuple):
    """A steady gait, differentiable in reverse mode with respect to the decision vector.

    - `y`: the fixed point of the $k$-period map (the reduced state at phase 0);
    - `figures`: $(\\Delta X, e_d, \\min N)$ over the gait's $k$ actuation periods;
    - `ok`: Newton's method converged and the periods completed (not differentiable).
    """

    y: Array
    figures: Array
    ok: Array


def _run(oracle: ChainOracle, theta: Array, k: Array, loop=jax.lax.while_loop):
    """`z = (y, theta)` -> (`(Phi, figures)`, ok): the oracle's period map at `theta`."""

    def run(y, th):
        C = with_waves(oracle.chain, th, oracle.a_max, oracle.harmonics, oracle.knots)
        out = period(C, oracle.contact, oracle.dt, oracle.max_steps, y, k, loop)
        return jnp.concatenate([out.y, out.figures]), out.ok

    return run


@eqx.filter_jit
def _solve(theta: Array, oracle: ChainOracle, y0: Array, k: Array):
    """Newton's method on $y$ alone ($\\theta$ a constant of the period map): the orbit, whose
    last iterate's linearisation is at the returned fixed point (its $M$ and $f_y$)."""
    run = _run(oracle, theta, k)
    empty = jnp.zeros((0,), theta.dtype)
    return newton_orbit(lambda z: run(z, theta), y0, empty, oracle.tol, oracle.max_iter)


@eqx.filter_jit
def _pullback(theta: Array, oracle: ChainOracle, y: Array, k: Array, cot: Array, step_cap: int, checkpoints: int):
    """$(\\Phi, f)_\\theta^T$ `cot` at `(y, theta)`: one reverse pass through the periods."""

    def loop(cond, body, init):
        return eqxi.while_loop(cond, body, init, max_steps=step_cap, kind="checkpointed", checkpoints=checkpoints)

    run = _run(oracle, theta, k, loop)
    _, vjp = jax.vjp(lambda th: run(y, th)[0], theta)
    return vjp(cot)[0]


@eqx.filter_custom_vjp
def _gait(theta: Array, oracle: ChainOracle, y0: Array, k: Array, step_cap: int, checkpoints: int):
    orb = _solve(theta, oracle, y0, k)
    return orb.y, orb.figures, orb.ok


@_gait.def_fwd
def _gait_fwd(perturbed, theta, oracle, y0, k, step_cap, checkpoints):
    del perturbed
    orb = _solve(theta, oracle, y0, k)
    # Newton's last linearisation is at the fixed point it returns: no second forward pass.
    return (orb.y, orb.figures, orb.ok), (orb.y, orb.monodromy, orb.figures_y)


@_gait.def_bwd
def _gait_bwd(residuals, grad_obj, perturbed, theta, oracle, y0, k, step_cap, checkpoints):
    del perturbed, y0
    y, M, f_y = residuals
    ny = y.shape[0]
    y_bar, f_bar, _ = grad_obj
    y_bar = jnp.zeros_like(y) if y_bar is None else y_bar
    f_bar = jnp.zeros((f_y.shape[0],), y.dtype) if f_bar is None else f_bar
    lam = jnp.linalg.solve((jnp.eye(ny, dtype=y.dtype) - M).T, y_bar + f_y.T @ f_bar)
    return _pullback(theta, oracle, y, k, jnp.concatenate([lam, f_bar]), step_cap, checkpoints)


def _backward_cap(oracle: ChainOracle, k: int) -> int:
    """The checkpointed loop's bound: the oracle's step cap per period times `k` periods (concrete)."""
    return int(oracle.max_steps) * k


def steady_gait(
    oracle: ChainOracle, theta: Array, y0: Array, k: int = 1, cap: int | None = None, checkpoints: int | None = None
) -> AdjointGait:
    """The steady gait of one decision vector `theta` (shape `(p,)`; the oracle's layout) from the
    warm start `y0` (a reduced state, shape `(2N - 1,)`) over `k` actuation periods, with a
    reverse-mode derivative by the adjoint method (module docstring): `jax.grad` and `jax.vjp` of
    any function of its `y` and `figures` with respect to `theta`. Its value at a gait whose Newton
    iteration failed (`ok` false) is the last iterate's and its derivative is meaningless there.

    `cap`: the backward pass's bound on engine steps (static; default `oracle.max_steps * k`, which
    needs `oracle.max_steps` concrete). `checkpoints`: the engine states the backward pass stores
    (static; default `cap`, every step: no step recomputed; fewer save memory and recompute steps).
    Several decision vectors: `jax.vmap` over `theta` and `y0`.
    """
    if not isinstance(k, int) or k < 1:
        raise ValueError(f"k (actuation periods) must be an int >= 1, got {k!r}")
    if cap is None:
        try:
            cap = _backward_cap(oracle, k)
        except jax.errors.ConcretizationTypeError:
            raise TypeError(
                "steady_gait: oracle.max_steps is traced; pass cap= (an int bound on engine steps over the k periods)"
            ) from None
    checkpoints = cap if checkpoints is None else checkpoints
    if not isinstance(checkpoints, int) or checkpoints < 1:
        raise ValueError(f"checkpoints must be an int >= 1, got {checkpoints!r}")
    theta = jnp.asarray(theta)
    y, figures, ok = _gait(
        theta, oracle, jnp.asarray(y0, theta.dtype), jnp.asarray(k, jnp.int32), int(cap), checkpoints
    )
    return AdjointGait(y, figures, ok)


def cost_of_transport(gait: AdjointGait) -> Array:
    """$e_d / |\\Delta X|$ over the gait's periods (as the chain optimiser's)."""
    return gait.figures[1] / jnp.abs(gait.figures[0])
