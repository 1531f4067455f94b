"""Reverse mode through a chain's steady gait (gaits/_adjoint.py): the adjoint solve's gradients
against the forward-mode oracle's implicit-function gradients (`ChainOracle.orbits`, jacfwd through
the period map in all directions), on a 3-mass worm with anisotropic friction (stick/slip events)."""

import math

import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from locomotion_jax.gaits import _adjoint as adj
from locomotion_jax.gaits._element_orbit import ChainOracle


pytestmark = pytest.mark.xdist_group("adjoint_gait")

N, H, OMEGA, DT = 3, 2, 3.0, 0.05


def _theta(dtype) -> jax.Array:
    """A two-harmonic wave travelling along the 3-mass worm (the oracle's layout, A_{0,1} dropped)."""
    phi = 2 * math.pi / 3
    A, B = np.zeros((N - 1, H)), np.zeros((N - 1, H))
    for j in range(N - 1):
        A[j] = -0.8 * math.sin(j * phi), 0.2 * math.sin(1 - 2 * j * phi)
        B[j] = 0.8 * math.cos(j * phi), 0.2 * math.cos(1 - 2 * j * phi)
    return jnp.asarray(np.concatenate([A.ravel()[1:], B.ravel(), [math.log(OMEGA)]]), dtype)


def _oracle(dtype) -> ChainOracle:
    chain = lj.Chain(masses=[1.0] * N, d=0.0, friction=lj.AnisotropicCoulomb(0.5, 0.9, 0.3, 0.7)).broadcast()
    if dtype == jnp.float32:
        chain = jax.tree_util.tree_map(lambda x: x.astype(dtype) if jnp.issubdtype(x.dtype, jnp.floating) else x, chain)
    steps = int(math.ceil(2 * math.pi / OMEGA / DT)) * 3 + 200
    tol = 1e-11 if dtype == jnp.float64 else 1e-5
    return ChainOracle(chain=chain, a_max=jnp.asarray(0.1, dtype), max_steps=jnp.asarray(steps, jnp.int32),
                       tol=jnp.asarray(tol, dtype), harmonics=H, contact="paper", dt=DT, max_iter=30)  # fmt: skip


def _forward(oracle, theta):
    """The oracle's steady gait (forward mode) from a relaxed start."""
    ny = 2 * N - 1
    y0 = oracle.transient(theta[None], jnp.zeros((1, ny), theta.dtype), jnp.ones(1, bool), jnp.asarray(30))
    orb = oracle.orbits(theta[None], y0, jnp.ones(1, jnp.int32))
    return jax.tree_util.tree_map(lambda x: x[0], orb)


def test_grad_of_cost_of_transport_equals_forward_mode():
    oracle, theta = _oracle(jnp.float64), _theta(jnp.float64)
    orb = _forward(oracle, theta)
    assert bool(orb.ok)
    gait = adj.steady_gait(oracle, theta, orb.y)
    assert bool(gait.ok)
    np.testing.assert_allclose(gait.figures, orb.figures, rtol=1e-10)
    # Every figure's gradient by one reverse pass each (jacrev), against the forward-mode gradient.
    jac = jax.jacrev(lambda th: adj.steady_gait(oracle, th, orb.y).figures[:2])(theta)
    scale = np.max(np.abs(orb.gradient[:2]), axis=1, keepdims=True)
    assert np.max(np.abs(jac - orb.gradient[:2]) / scale) <= 1e-8
    # The cost of transport e_d / |dX|: grad against the chain rule on the forward-mode gradients.
    dX, ed = orb.figures[0], orb.figures[1]
    expect = orb.gradient[1] / abs(dX) - ed * np.sign(dX) * orb.gradient[0] / dX**2
    grad = jax.grad(lambda th: adj.cost_of_transport(adj.steady_gait(oracle, th, orb.y)))(theta)
    assert np.max(np.abs(grad - expect)) <= 1e-8 * np.max(np.abs(expect))
    assert np.max(np.abs(expect)) > 0.1  # a gradient that can fail
    # From a start off the fixed point Newton iterates: the adjoint's M and f_y are its last
    # linearisation, which must be at the fixed point returned, not at the iterate before.
    y_off = orb.y + 1e-3
    grad = jax.grad(lambda th: adj.cost_of_transport(adj.steady_gait(oracle, th, y_off)))(theta)
    assert np.max(np.abs(grad - expect)) <= 1e-8 * np.max(np.abs(expect))
    # Few checkpoints (the backward pass recomputes steps from them): the same gradient.
    grad = jax.grad(lambda th: adj.cost_of_transport(adj.steady_gait(oracle, th, orb.y, checkpoints=8)))(theta)
    assert np.max(np.abs(grad - expect)) <= 1e-8 * np.max(np.abs(expect))


def test_grad_float32():
    oracle, theta = _oracle(jnp.float32), _theta(jnp.float32)
    orb = _forward(oracle, theta)
    assert bool(orb.ok)
    dX, ed = orb.figures[0], orb.figures[1]
    expect = orb.gradient[1] / abs(dX) - ed * np.sign(dX) * orb.gradient[0] / dX**2
    grad = jax.grad(lambda th: adj.cost_of_transport(adj.steady_gait(oracle, th, orb.y)))(theta)
    assert grad.dtype == jnp.float32
    assert np.max(np.abs(grad - expect)) <= 1e-3 * np.max(np.abs(expect))


def test_bad_k_and_checkpoints_are_refused():
    with pytest.raises(ValueError, match="k \\(actuation periods\\)"):
        adj.steady_gait(_oracle(jnp.float64), _theta(jnp.float64), jnp.zeros(2 * N - 1), k=0)
    with pytest.raises(ValueError, match="checkpoints must be an int >= 1"):
        adj.steady_gait(_oracle(jnp.float64), _theta(jnp.float64), jnp.zeros(2 * N - 1), checkpoints=0)
