"""Forward-mode derivatives of the exact engine against finite differences of the reference.

The package differentiates through its located events: each event time by the
implicit function theorem (`_numerics.root`), and the state committed at the event
moves with it (the saltation of the switch). The reference (`tests/reference.py`,
event-driven DOP853 at rtol 1e-11) knows nothing of derivatives; its central
differences are the truth here. Step study (README, "Gradients"): with relative steps
1e-4 a switch can move across a saved time inside the stencil (a kink of the
reference's own curve, up to 6x off); with 1e-5 every case below agrees to 8e-4.
"""

import functools
import sys
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest


sys.path.insert(0, str(Path(__file__).parent))
from reference import DEFAULTS, reference_measure, reference_simulate  # noqa: E402


NAMES = ("omega", "a", "d", "mu_s", "mu_k")
FIELDS = ("x1", "x2", "e_d", "w")
SAVE = np.array([4.1, 8.3, 12.0])
T_END = 12.0
H_REL = 1e-5  # the reference's central-difference step, relative to max(1, |value|)
RTOL = 1e-3

# Over the steady regimes of tests/test_against_reference.py: six SSL, four SL.
CONFIGS = [
    dict(omega=1.0, a=0.08),
    dict(omega=2.0),
    dict(omega=2.5, mu_s=0.6),
    dict(omega=4.0, a=0.04),
    dict(omega=5.0, d=0.3),
    dict(omega=3.0, mu_k=0.3, mu_s=0.5),
    dict(omega=6.0),
    dict(omega=6.0, d=-0.5),
    dict(omega=7.0, a=0.03),
    dict(omega=12.0, a=0.03),
]
FULL = [{**DEFAULTS, **c} for c in CONFIGS]

# One worker runs this module (pyproject.toml: --dist loadgroup), so the batch's
# Jacobian (a module fixture) is computed once.
pytestmark = pytest.mark.xdist_group("gradients")


def _batch(configs: list[dict]) -> dict:
    return {n: jnp.asarray([c[n] for c in configs]) for n in DEFAULTS}


def _fields(traj) -> jax.Array:
    return jnp.stack([getattr(traj, k) for k in FIELDS], -2)  # (..., fields, times)


@functools.cache
def _jacobian() -> np.ndarray:
    """d(fields at SAVE)/d(NAMES) for every configuration: one `jacfwd` of one batch, once
    per process (a module fixture would be rebuilt whenever xdist interleaves modules)."""
    base = _batch(FULL)

    def run(delta):
        shifted = {n: base[n] + (delta[NAMES.index(n)] if n in NAMES else 0.0) for n in base}
        return _fields(lj.simulate(lj.Params(**shifted), t_end=T_END, save_at=SAVE))

    return np.asarray(jax.jacfwd(run)(jnp.zeros(len(NAMES))))  # (B, fields, times, names)


def _reference_fd(config: dict, name: str, wave=None, value: float = 0.0) -> np.ndarray:
    """Central difference in `config[name]`, or with `wave(v)` the waveform at `v = value`."""

    def at(v):
        if wave is None:
            r = reference_simulate({**config, name: v}, T_END, SAVE)
        else:
            r = reference_simulate(config, T_END, SAVE, wave=wave(v))
        return np.stack([r[k] for k in FIELDS])

    v = config[name] if wave is None else value
    h = H_REL * max(1.0, abs(v))
    return (at(v + h) - at(v - h)) / (2 * h)


def _assert_close(got: np.ndarray, fd: np.ndarray, what: str) -> None:
    # Relative to each entry, with a floor of RTOL x the largest entry (a derivative
    # that crosses zero at a saved time has no relative accuracy to check).
    floor = RTOL * np.max(np.abs(fd))
    bad = np.abs(got - fd) > RTOL * np.abs(fd) + floor + 1e-12
    assert not np.any(bad), f"{what}: package {got[bad]} vs reference {fd[bad]}"


@pytest.mark.parametrize("index", range(len(CONFIGS)), ids=[str(c) for c in CONFIGS])
def test_state_derivatives_match_reference(index):
    jacobian = _jacobian()
    config = FULL[index]
    for j, name in enumerate(NAMES):
        _assert_close(jacobian[index, :, :, j], _reference_fd(config, name), f"{CONFIGS[index]} d/d{name}")


def test_fourier_coefficient_derivative_matches_reference():
    # l0 = lbar + a sin(wt) + B2 sin(2wt): the derivative in B2 at B2 = 0.01.
    configs = [FULL[1], FULL[3], FULL[6]]
    base = _batch(configs)
    params = lj.Params(**base)

    def run(b2):
        sin = jnp.stack([base["a"], jnp.full_like(base["a"], b2)], -1)
        wave = lj.Fourier(jnp.zeros_like(sin), sin, base["omega"], base["lbar"])
        return _fields(lj.simulate(params, t_end=T_END, save_at=SAVE, waveform=wave))

    _, tangent = jax.jvp(run, (jnp.asarray(0.01),), (jnp.asarray(1.0),))
    for i, config in enumerate(configs):
        wave = lambda b2, a=config["a"]: ([0.0, 0.0], [a, b2])
        fd = _reference_fd(config, "B2", wave=wave, value=0.01)
        _assert_close(np.asarray(tangent[i]), fd, f"{config} d/dB2")


def test_derivative_converges_in_dt():
    # The derivative is the derivative of the discrete solution: it converges at the
    # integrator's order (4) to the reference's finite difference.
    config = FULL[1]
    fd = _reference_fd(config, "omega")

    def error(dt):
        run = lambda w: _fields(lj.simulate(lj.Params(omega=w), t_end=T_END, save_at=SAVE, dynamics=lj.Exact(dt=dt)))
        return np.max(np.abs(np.asarray(jax.jvp(run, (jnp.asarray(2.0),), (jnp.asarray(1.0),))[1]) - fd))

    errs = [error(dt) for dt in (0.04, 0.02)]
    order = np.log2(errs[0] / errs[1])
    assert 3.0 < order < 5.5, (errs, order)


def test_lift_off_in_a_batch_is_flagged_and_isolated():
    # The middle configuration of the first batch lifts off (strict reading: the run
    # stops there); its derivative stays finite, and the others' are those they have
    # beside a configuration that does not lift off (same batch size: one compilation).
    def run(omegas):
        def fields(a):
            traj = lj.simulate(lj.Params(omega=jnp.asarray(omegas), a=a), t_end=8.0, save_at=np.array([3.0, 8.0]))
            return _fields(traj), traj.status

        (_, status), (tangent, _) = jax.jvp(fields, (jnp.asarray(0.05),), (jnp.asarray(1.0),))
        return [int(s) for s in status], np.asarray(tangent)

    status, tangent = run([2.0, 9.0, 6.0])
    assert status == [lj.Status.OK, lj.Status.LIFTOFF, lj.Status.OK]
    assert np.all(np.isfinite(tangent))
    status, other = run([2.0, 4.0, 6.0])
    assert status == [lj.Status.OK] * 3
    np.testing.assert_allclose(tangent[[0, 2]], other[[0, 2]], rtol=1e-12, atol=1e-14)


def test_reverse_mode_equals_forward_mode():
    # Reverse mode through simulate (a checkpointed loop per configuration; tests/test_reverse_mode.py).
    f = lambda w: lj.simulate(lj.Params(omega=w), t_end=5.0, save_at=np.array([5.0])).x1[0]
    g = float(jax.grad(f)(2.0))
    t = float(jax.jvp(f, (2.0,), (1.0,))[1])
    assert g == pytest.approx(t, rel=1e-10) and t != 0


@pytest.mark.parametrize("option", ["t_end", "dt", "z"])
def test_options_cannot_be_differentiated(option):
    p = lj.Params(omega=2.0)
    runs = {
        "t_end": lambda v: lj.simulate(p, t_end=v).x1,
        "dt": lambda v: lj.simulate(p, t_end=1.0, dynamics=lj.Exact(dt=v)).x1,
        "z": lambda v: lj.measure(p, z=v).tau_z,
    }
    # The package's message; under the test suite's run-time type checker (pyproject.toml)
    # an argument annotated `float` may be refused first, also naming it.
    name = {"dt": "Exact.dt"}.get(option, option)
    with pytest.raises(TypeError, match=f"{name} is an option of the run|parameter '{option}'"):
        jax.jvp(runs[option], (jnp.asarray(0.01),), (jnp.asarray(1.0),))


def test_chain_derivatives_match_reference():
    # N = 3, anisotropic friction, a travelling wave: d(positions, e_d)/d(omega, mu_k_fwd)
    # at the saved times, against tests/reference_chain.py.
    from chain_cases import ANISO
    from reference_chain import chain_config, reference_chain_simulate
    from test_against_reference import to_chain

    kw: dict[str, Any] = dict(masses=[1.0] * 3, omega=3.0, a=0.08, phi=2 * np.pi / 3, **ANISO)
    chain = to_chain(chain_config(**kw))

    def run(dw, dmu):
        c = eqx.tree_at(lambda c: c.waves.omega, chain, chain.waves.omega + dw)
        c = eqx.tree_at(lambda c: c.friction.mu_k_fwd, c, c.friction.mu_k_fwd + dmu)
        traj = lj.simulate(c, t_end=T_END, save_at=SAVE, start="relaxed")
        return jnp.concatenate([traj.x.reshape(-1), traj.e_d])

    jac = np.asarray(jax.jacfwd(run, argnums=(0, 1))(0.0, 0.0))
    for j, name in enumerate(("omega", "mu_k_fwd")):
        h = H_REL * max(1.0, kw[name])
        runs = [reference_chain_simulate(chain_config(**{**kw, name: kw[name] + s}), T_END, SAVE, start="relaxed")
                for s in (h, -h)]  # fmt: skip
        fd = np.concatenate([(runs[0]["x"] - runs[1]["x"]).reshape(-1), runs[0]["e_d"] - runs[1]["e_d"]]) / (2 * h)
        _assert_close(jac[j], fd, f"chain d/d{name}")


INITIAL = np.array([0.1, 0.05, 3.0, -0.02])  # (x1, v1, x2, v2) at t = 0


def test_initial_state_derivatives_match_reference():
    # d(fields at SAVE)/d(x1, v1, x2, v2 at t = 0), SSL and SL, against the reference
    # started from the same state.
    omegas = [2.0, 6.0]

    def run(y):
        batch = tuple(jnp.full(2, v) for v in y)
        return _fields(lj.simulate(lj.Params(omega=jnp.asarray(omegas)), t_end=T_END, save_at=SAVE, initial=batch))

    jac = np.asarray(jax.jacfwd(run)(jnp.asarray(INITIAL)))  # (B, fields, times, 4)
    h = 1e-5
    for i, omega in enumerate(omegas):
        config = {**DEFAULTS, "omega": omega}
        for j, name in enumerate(("x1", "v1", "x2", "v2")):
            rp, rm = (reference_simulate(config, T_END, SAVE, start=tuple(INITIAL + s * h * np.eye(4)[j]))
                      for s in (1, -1))  # fmt: skip
            fd = np.stack([(rp[k] - rm[k]) / (2 * h) for k in FIELDS])
            _assert_close(jac[i, :, :, j], fd, f"omega = {omega} d/d{name}(0)")


def test_initial_state_in_measure_matches_reference():
    # tau_z, e_z early in the run (t_start = 1, z = 0.1) depend on the initial state.
    def run(y):
        m = lj.measure(lj.Params(omega=2.0), z=0.1, t_start=1.0, horizon=20.0, initial=tuple(y))
        return jnp.stack([m.tau_z, m.e_z])

    jac = np.asarray(jax.jacfwd(run)(jnp.asarray(INITIAL)))
    h = 1e-5
    for j in range(4):
        rp, rm = (reference_measure({**DEFAULTS, "omega": 2.0}, z=0.1, t_start=1.0, horizon=20.0,
                                    start=tuple(INITIAL + s * h * np.eye(4)[j])) for s in (1, -1))  # fmt: skip
        fd = np.array([(rp[k] - rm[k]) / (2 * h) for k in ("tau_z", "e_z")])
        np.testing.assert_allclose(jac[:, j], fd, rtol=RTOL, atol=RTOL * np.max(np.abs(jac)), err_msg=str(j))


def test_initial_state_is_validated():
    p = lj.Params(omega=jnp.array([2.0, 6.0]))
    with pytest.raises(ValueError, match="x1 < x2"):
        lj.simulate(p, t_end=1.0, initial=(3.0, 0.0, 1.0, 0.0))
    with pytest.raises(ValueError, match="finite"):
        lj.measure(p, z=0.1, horizon=5.0, initial=(0.0, np.nan, 3.0, 0.0))
    with pytest.raises(ValueError, match="broadcast"):
        lj.simulate(p, t_end=1.0, initial=(np.zeros(3), 0.0, 3.0, 0.0))
    with pytest.raises(TypeError, match="initial"):  # the package's, or the test suite's type checker
        lj.simulate(p, t_end=1.0, initial=np.array([0.0, 0.0, 3.0, 0.0]))  # pyright: ignore[reportArgumentType, reportCallIssue]
    # The smoothed dynamics take the same states, and flag the same bad one under jit.
    smooth = jax.jit(lambda x2: lj.simulate(p, t_end=1.0, save_at=np.array([1.0]), initial=(0.0, 0.0, x2, 0.0),
                                            dynamics=lj.Smoothed()))  # fmt: skip
    assert [int(s) for s in smooth(jnp.array([3.0, -1.0])).status] == [lj.Status.OK, lj.Status.INVALID]
    # Under jit the values are not known: the bad configuration is flagged in its own result.
    run = jax.jit(lambda x2: lj.simulate(p, t_end=1.0, save_at=np.array([1.0]), initial=(0.0, 0.0, x2, 0.0)))
    tr = run(jnp.array([3.0, -1.0]))
    assert [int(s) for s in tr.status] == [lj.Status.OK, lj.Status.INVALID]
    np.testing.assert_array_equal(tr.x1[0], lj.simulate(p[0], t_end=1.0, save_at=np.array([1.0]),
                                                        initial=(0.0, 0.0, 3.0, 0.0)).x1)  # fmt: skip


def test_measure_failures_are_flagged_with_finite_derivatives():
    # In one batch: a lift-off before t_start (strict reading), a run that never reaches z,
    # and two that do. The failures' derivatives are finite and flagged (`smooth` False),
    # and the others' are those they have in a batch without failures.
    def run(omegas):
        def fields(a):
            m = lj.measure(lj.Params(omega=jnp.asarray(omegas), a=a), z=0.5, t_start=10.0, horizon=30.0)
            return jnp.stack([m.tau_z, m.e_z, m.mean_speed]), m

        (_, m), (tangent, _) = jax.jvp(fields, (jnp.asarray(0.05),), (jnp.asarray(1.0),))
        return m, np.asarray(tangent)

    m, tangent = run([6.0, 9.0, 0.5, 7.0])
    assert [int(s) for s in m.status] == [lj.Status.OK, lj.Status.LIFTOFF, lj.Status.OK, lj.Status.OK]
    assert not bool(m.reached[2])
    assert [bool(s) for s in m.smooth] == [True, False, False, True]
    assert np.all(np.isfinite(tangent))
    _, other = run([6.0, 7.0, 7.0, 7.0])
    np.testing.assert_allclose(tangent[:, [0, 3]], other[:, [0, 3]], rtol=1e-12)


def test_integers_cannot_be_differentiated():
    with pytest.raises(TypeError, match="jacfwd requires real"):
        jax.jacfwd(lambda w: lj.simulate(lj.Params(omega=w), t_end=1.0).x1)(2)
