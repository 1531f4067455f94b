"""Reverse mode (`jax.grad`, `jax.vjp`, `jax.jacrev`) through `measure` and `simulate` of the exact
engine: equal to forward mode (`jax.jacfwd`, an independent code path through the work queue) to
1e-8 relative, and to central differences of the scipy references (`tests/reference.py`,
`tests/reference_chain.py`) to the accuracy those allow; float32 runs; the refusals that remain."""

import logging
import sys
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from locomotion_jax.dynamics._forward import forward_only, VMAP_REVERSE_MESSAGE


sys.path.insert(0, str(Path(__file__).parent))
from reference import DEFAULTS, reference_measure  # noqa: E402


pytestmark = pytest.mark.xdist_group("reverse_mode")

# SSL and SL (tests/test_measure_gradients.py's CI pair), z = 1 measured from t = 30.
PAIR = dict(omega=[5.79, 6.79], a=[0.032, 0.068], d=[0.5, -0.4], mu_s=[0.6, 0.7], mu_k=[0.5, 0.4])
SAVE = np.array([4.1, 8.3, 12.0])


def _close(got, want, rtol: float) -> None:
    got, want = np.asarray(got), np.asarray(want)
    assert np.all(np.isfinite(got)), got
    assert np.max(np.abs(got - want)) <= rtol * np.max(np.abs(want)), (got, want)


def _reverse_equals_forward(run, x, floor: float) -> None:
    """jacrev of `run` at `x` equals its jacfwd to 1e-8 (relative to the largest entry, at least `floor`)."""
    J = np.asarray(jax.jacfwd(run)(x))
    R = np.asarray(jax.jacrev(run)(x))
    assert np.all(np.isfinite(J)) and np.max(np.abs(J)) > floor
    np.testing.assert_allclose(R, J, rtol=1e-8, atol=1e-8 * np.max(np.abs(J)))


def _measure_pair(dtype=jnp.float64):
    base = {k: jnp.asarray(v, dtype) for k, v in PAIR.items()}

    def run(delta):
        p = lj.Params(omega=base["omega"] + delta[0], a=base["a"] + delta[1], d=base["d"] + delta[2],
                      mu_s=base["mu_s"], mu_k=base["mu_k"] + delta[3])  # fmt: skip
        m = lj.measure(p, z=1.0, t_start=30.0, horizon=100.0)
        return jnp.stack([m.tau_z, m.e_z, m.mean_speed])

    return run


def test_measure_jacrev_equals_jacfwd():
    _reverse_equals_forward(_measure_pair(), jnp.zeros(4), floor=1.0)


def test_measure_grad_matches_reference_differences():
    # d tau_1 / d omega of the SSL configuration against the reference's central differences.
    run = _measure_pair()
    g = jax.grad(lambda d: run(d)[0, 0])(jnp.zeros(4))
    c = {**DEFAULTS, **{k: v[0] for k, v in PAIR.items()}}
    h = 1e-5 * c["omega"]
    tau = [reference_measure({**c, "omega": c["omega"] + s}, z=1.0, t_start=30.0, horizon=100.0)["tau_z"]
           for s in (h, -h)]  # fmt: skip
    fd = (tau[0] - tau[1]) / (2 * h)
    assert abs(float(g[0]) - fd) <= 1e-3 * abs(fd), (float(g[0]), fd)


def test_measure_float32():
    run = _measure_pair(jnp.float32)
    zero = jnp.zeros(4, jnp.float32)
    R = np.asarray(jax.jacrev(run)(zero))
    J = np.asarray(jax.jacfwd(run)(zero))
    assert R.dtype == np.float32
    _close(R, J, 1e-3)


def _chain():
    from chain_cases import ANISO
    from reference_chain import chain_config
    from test_against_reference import to_chain

    kw: dict[str, Any] = dict(masses=[1.0] * 3, omega=3.0, a=0.08, phi=2 * np.pi / 3, **ANISO)
    return kw, to_chain(chain_config(**kw))


def test_chain_measure_grad_equals_jacfwd():
    # A 3-mass worm with anisotropic friction (stick/slip events), d(tau_z, e_z) / d(omega, mu_k_fwd).
    _, chain = _chain()

    def run(x):
        c = eqx.tree_at(lambda c: c.waves.omega, chain, chain.waves.omega + x[0])
        c = eqx.tree_at(lambda c: c.friction.mu_k_fwd, c, c.friction.mu_k_fwd + x[1])
        m = lj.measure(c, z=0.5, t_start=10.0, horizon=60.0, start="relaxed")
        return jnp.stack([m.tau_z, m.e_z]).reshape(-1)

    _reverse_equals_forward(run, jnp.zeros(2), floor=0.1)


def test_chain_simulate_vjp_equals_jacfwd_and_reference():
    from reference_chain import chain_config, reference_chain_simulate

    kw, chain = _chain()

    def run(dw):
        c = eqx.tree_at(lambda c: c.waves.omega, chain, chain.waves.omega + dw)
        traj = lj.simulate(c, t_end=12.0, save_at=SAVE, start="relaxed")
        return jnp.concatenate([traj.x.reshape(-1), traj.e_d.reshape(-1)])

    J = np.asarray(jax.jacfwd(run)(0.0))
    out, vjp = jax.vjp(run, 0.0)
    rng = np.random.default_rng(0)
    cot = jnp.asarray(rng.standard_normal(out.shape))
    (got,) = vjp(cot)
    want = float(np.dot(np.asarray(cot), J))
    assert abs(float(got) - want) <= 1e-8 * np.sum(np.abs(np.asarray(cot) * J))
    # Every saved coordinate's derivative (jacrev: one reverse pass per row) against the reference.
    R = np.asarray(jax.jacrev(run)(0.0))
    np.testing.assert_allclose(R, J, rtol=1e-8, atol=1e-8 * np.max(np.abs(J)))
    h = 1e-5 * kw["omega"]
    runs = [reference_chain_simulate(chain_config(**{**kw, "omega": kw["omega"] + s}), 12.0, SAVE, start="relaxed")
            for s in (h, -h)]  # fmt: skip
    fd = np.concatenate([(runs[0]["x"] - runs[1]["x"]).reshape(-1), runs[0]["e_d"] - runs[1]["e_d"]]) / (2 * h)
    assert np.max(np.abs(R - fd)) <= 1e-3 * np.max(np.abs(fd)) + 1e-9


def test_params_simulate_grad_equals_jacfwd():
    def run(w):
        traj = lj.simulate(lj.Params(omega=w), t_end=12.0, save_at=SAVE)
        return jnp.concatenate([traj.x1.reshape(-1), traj.x2.reshape(-1)])

    _reverse_equals_forward(run, 2.0, floor=0.01)


def test_reverse_mode_under_vmap_is_refused():
    f = lambda w: lj.measure(lj.Params(omega=w), z=0.1, horizon=20.0).tau_z
    with pytest.raises(TypeError, match="jax.vmap is not supported"):
        jax.vmap(jax.grad(f))(jnp.asarray([2.0, 3.0]))
    assert "one batch" in VMAP_REVERSE_MESSAGE


def test_forward_only_computations_still_refuse_reverse_mode():
    # Steady gaits' Newton loops and sweeps' chunks pass their outputs through forward_only.
    with pytest.raises(TypeError, match="jax.jacfwd"):
        jax.grad(lambda x: forward_only(x * x))(2.0)
    assert float(jax.jvp(lambda x: forward_only(x * x), (2.0,), (1.0,))[1]) == 4.0


def test_a_second_grad_compiles_nothing(caplog):
    """The backward pass is one cached program: a second eager `jax.grad` of the same run reuses it
    (a transposition traced anew would compile the checkpointed loops on every call)."""

    def run(d):
        return lj.measure(lj.Params(omega=2.0 + d[0], a=0.08 + d[1]), z=1.0, t_start=30.0, horizon=100.0).tau_z

    grad = jax.grad(run)
    first = np.asarray(grad(jnp.zeros(2)))
    with jax.log_compiles(True), caplog.at_level(logging.WARNING):
        second = np.asarray(grad(jnp.zeros(2)))
    compiles = [r.getMessage() for r in caplog.records if "ompil" in r.getMessage()]
    assert compiles == [], compiles[:3]
    np.testing.assert_array_equal(second, first)
