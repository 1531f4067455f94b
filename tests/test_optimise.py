"""The actuation optimiser (SPEC §7): both methods' gradients, constraints, verification, inputs, CLI.

Problems are tiny (few harmonics, few iterations, one coarse smoothing stage) so the
file stays well under the test budget; the real runs are in
`experiments/optimal_actuation.py`. Every reported exact figure is checked against the
independent reference (`tests/reference.py`) over whole periods of the steady gait.
"""

import json
import math
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from locomotion_jax.cli._optimise import register
from locomotion_jax.gaits import _orbit
from locomotion_jax.optimisation import _constraints, _exact as _exact_optimise, _objective, _optimise, _pareto, _shapes
from locomotion_jax.optimisation._optimum import ExactSettings, Settings
from plugin_app import plugin_app
from reference import reference_simulate
from typer.testing import CliRunner


TINY = Settings(
    starts=2,
    eps_schedule=(1e-2,),
    outer=1,
    inner=4,
    corrections=0,
    transient=4.0,
    measured=3.0,
    refine_baseline=False,
)


def _reference_figures(cos, sin, omega, a=None, rho=0.9):
    """`(mean speed, cost of transport, lift-off)` of a waveform's steady gait on the independent
    reference (`tests/reference.py`): the defaults, strict contact, relaxed start, averaged over
    10 whole periods after a transient long enough for a gait whose largest Floquet multiplier
    has modulus `rho` to settle to 1e-7; `a` instead of `cos, sin`: eq. (13); `cos` may be
    `("spline", control)` instead (a periodic spline, `sin` unused)."""
    T = 2 * math.pi / omega
    settle = int(min(300, max(40, math.ceil(math.log(1e-7) / math.log(max(rho, 1e-3))))))
    t0, t1 = settle * T, (settle + 10) * T
    wave = cos if isinstance(cos, tuple) else (cos, sin)  # ("spline", control) or Fourier coefficients
    kw: dict[str, Any] = dict(wave=wave) if a is None else {}
    params = dict(omega=omega) if a is None else dict(omega=omega, a=a)
    r = reference_simulate(params, t1, save_at=[t0, t1], start="relaxed", **kw)
    dX = r["X"][1] - r["X"][0]
    return dX / (t1 - t0), (r["e_d"][1] - r["e_d"][0]) / abs(dX), r["liftoff"]


pytestmark = pytest.mark.xdist_group("optimise")  # the module's sweep and optimisations are run once, on one worker


@pytest.fixture(scope="module")
def tiny_sweep():
    # Two amplitudes x three frequencies around omega = 4, exact model, short horizon.
    return _pareto.sinusoid_sweep(lj.Params(), 0.05, omegas=np.array([2.0, 4.0, 6.0]), amplitudes=2, transient=20)


def _problem(eps, free_omega=True, detach=None):
    p = lj.Params()
    plan = _objective.make_plan(p, 4.0, 4.0, eps, 3.0, 3.0, detach)
    return _optimise._Problem(
        p,
        jnp.asarray(0.05),
        jnp.asarray(1.0),
        jnp.asarray(math.log(2.0)),
        jnp.asarray(math.log(8.0)),
        plan,
        0.005,
        free_omega,
    )


def test_gradient_matches_finite_differences():
    # Reverse mode through the checkpointed RK4 rollout vs central differences (float64),
    # for the cost of transport and both constraints, along a random direction.
    prob = _problem(1e-2)
    theta = {"cos": jnp.array([0.1, -0.2]), "sin": jnp.array([0.8, 0.15]), "log_omega": jnp.asarray(math.log(4.0))}
    eps, v_t, margin = jnp.asarray(1e-2), jnp.asarray(0.03), jnp.asarray(0.05)
    rng = np.random.default_rng(1)
    direction = jax.tree_util.tree_map(lambda x: jnp.asarray(rng.normal(size=x.shape)), theta)

    @jax.jit
    def f(th):  # cost, speed constraint, normal-force constraint
        cost, g, _ = _optimise.terms(th, prob, eps, v_t, margin)
        return jnp.concatenate([cost[None], g])

    jac = jax.jit(jax.jacrev(f))(theta)
    ad = sum(jnp.tensordot(jac[k], direction[k], axes=direction[k].ndim) for k in theta)
    h = 1e-5
    plus = jax.tree_util.tree_map(lambda x, d: x + h * d, theta, direction)
    minus = jax.tree_util.tree_map(lambda x, d: x - h * d, theta, direction)
    fd = (f(plus) - f(minus)) / (2 * h)
    np.testing.assert_allclose(ad, fd, rtol=1e-5, atol=1e-8)
    assert np.all(np.abs(np.asarray(ad)) > 1e-3)  # a real check: no vanishing derivative


def test_stroke_is_exact_and_projection_lands_on_the_limit():
    rng = np.random.default_rng(0)
    for _ in range(3):
        cos, sin = rng.normal(size=4), rng.normal(size=4)
        t = np.linspace(0, 2 * np.pi, 100_001)
        dense = np.max(np.abs(np.asarray(lj.Fourier(cos, sin, 1.0, 0.0)(t)[0])))
        exact = float(_constraints.stroke(jnp.asarray(cos), jnp.asarray(sin)))
        assert dense <= exact <= dense * (1 + 1e-8)
        c2, s2 = _constraints.project_stroke(jnp.asarray(cos), jnp.asarray(sin), 0.05)
        assert float(_constraints.stroke(c2, s2)) == pytest.approx(0.05, rel=1e-12)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(v_min=-0.02, a_max=0.05), "v_min"),
        (dict(v_min=-0.02, a_max=0.05, direction=1), "v_min"),
        (dict(v_min=0.02, a_max=0.13), "a_max"),  # 1 - k a |d| / lbar < 0 at a = 0.13
        (dict(v_min=0.02, a_max=0.05, harmonics=0), "harmonics"),
        (dict(v_min=0.02, a_max=0.05, direction=2), "direction"),
        (dict(v_min=0.0, a_max=0.05), "v_min"),
    ],
)
def test_bad_inputs(kwargs, match):
    with pytest.raises(ValueError, match=match):
        _optimise.optimise(lj.Params(), **kwargs)


@pytest.mark.slow
def test_d0_equal_masses_cannot_move():
    # With d = 0 and m1 = m2 the model is symmetric under x -> -x with the masses swapped,
    # so no waveform moves the centre of mass; use a time-asymmetric, even-harmonic one.
    p = lj.Params(d=0.0, mhat=0.5)
    wave = lj.Fourier(np.array([0.01, -0.012, 0.004]), np.array([0.03, 0.015, -0.006]), 3.0, 3.0)
    fig = _pareto.exact_figures(p, wave)
    assert bool(fig.ok) and abs(float(fig.speed)) < 1e-10
    tr = lj.simulate(
        _pareto.with_waveform_frequency(p, wave), 30.0, np.linspace(0, 30, 61), waveform=wave, start="relaxed"
    )
    np.testing.assert_allclose(tr.X, tr.X[0], atol=1e-10)
    # The smoothed rollout of the optimiser keeps the symmetry too.
    plan = _objective.make_plan(p, 3.0, 3.0, 1e-2, 4.0, 4.0)
    r = _objective.rollout(p, wave, jnp.asarray(1e-2), plan, 0.005)
    assert abs(float(r.distance)) < 1e-10 and float(r.dissipated) > 0


@pytest.fixture(scope="module")
def tiny_optimum(tiny_sweep):
    return _optimise.optimise(
        lj.Params(), 0.01, 0.05, method="smoothed", omega=4.0, harmonics=2, settings=TINY, sweep=tiny_sweep
    )


@pytest.mark.slow
def test_compilations_per_optimisation(tiny_sweep):
    # One trace of the Adam block per optimisation: not per smoothing stage (the step
    # count is traced, under a loop of the finest stage's length), outer iteration,
    # start or call. `_evaluate` runs on the starts and once on all candidates
    # (another batch size): two traces.
    settings = eqx.tree_at(lambda s: (s.eps_schedule, s.outer), TINY, ((1e-2, 5e-3), 2))
    jax.clear_caches()
    run = lambda v: _optimise.optimise(
        lj.Params(), v, 0.05, method="smoothed", omega=4.0, harmonics=2, settings=settings, sweep=tiny_sweep
    )
    before = dict(_optimise.TRACES)
    run(0.01)
    grew = {k: _optimise.TRACES[k] - before.get(k, 0) for k in ("block", "evaluate")}
    assert grew == {"block": 1, "evaluate": 2}
    # Another requirement of the same problem size: nothing is traced again.
    before = dict(_optimise.TRACES)
    run(0.012)
    assert dict(_optimise.TRACES) == before


def test_coarse_stage_in_a_finer_loop_matches_its_own_plan():
    # A stage run inside the finest stage's loop (skipped steps) is the same rollout
    # as the one compiled at its own step count.
    p = lj.Params()
    wave = lj.Fourier(jnp.array([0.0]), jnp.array([0.04]), jnp.asarray(3.0), p.lbar)
    eps = jnp.asarray(1e-2)
    own = _objective.make_plan(p, 3.0, 3.0, 1e-2, 4.0, 4.0)
    shared = _objective.make_plan(p, 3.0, 3.0, 1e-2, 4.0, 4.0, eps_min=2.5e-3)
    assert shared.max_steps_per_period > int(shared.steps_per_period) == own.max_steps_per_period
    a = _objective.rollout(p, wave, eps, own, 0.005)
    b = _objective.rollout(p, wave, eps, shared, 0.005)
    for x, y in zip(a, b):
        assert float(y) == pytest.approx(float(x), rel=1e-12, abs=1e-15)
    with pytest.raises(ValueError, match="eps_min"):
        _objective.make_plan(p, 3.0, 3.0, 1e-3, 4.0, 4.0, eps_min=1e-2)


@pytest.mark.slow  # the smoothed method end to end; its parts are tested above, the exact method below
def test_optimum_verified_on_the_reference(tiny_optimum):
    # The reported exact figures of the optimum and of the best sinusoid are those of the
    # independent reference solver for the returned waveforms, over whole periods.
    opt = tiny_optimum
    speed, cost, lifted = _reference_figures(opt.cos, opt.sin, opt.omega)
    assert not lifted and not opt.liftoff_exact
    assert opt.mean_speed_exact == pytest.approx(speed, rel=1e-4)
    assert opt.cost_of_transport_exact == pytest.approx(cost, rel=1e-4)
    assert opt.feasible_exact == (speed >= 0.01) and all(opt.constraints_exact.values()) == opt.feasible_exact
    assert opt.method == "smoothed"
    assert opt.stroke_exact <= 0.05 * (1 + 1e-12)
    sin = opt.sinusoid
    s_speed, s_cost, s_lifted = _reference_figures(None, None, sin["omega"], a=sin["a"])
    assert not s_lifted and s_speed >= 0.01
    assert sin["mean_speed"] == pytest.approx(s_speed, rel=1e-4)
    assert sin["cost_of_transport"] == pytest.approx(s_cost, rel=1e-4)
    assert opt.improvement_vs_sinusoid == pytest.approx(1 - cost / s_cost, rel=1e-3, abs=1e-4)
    names = {c["candidate"].split()[0] for c in opt.candidates}
    assert names == {"initial", "optimised"}
    json.dumps(opt.to_dict())


@pytest.mark.slow
def test_cli_infeasible_requirement_is_reported_infeasible():
    # Nothing reaches a mean speed of 0.5 with a stroke of 0.03: the result must say so.
    # Same shapes and static settings as TINY, so the compiled functions are reused.
    args = [
        "optimize",
        "--method",
        "smoothed",
        "--v-min",
        "0.5",
        "--a-max",
        "0.03",
        "--omega",
        "4",
        "--harmonics",
        "2",
        "--json",
        "--starts",
        "2",
        "--outer",
        "1",
        "--inner",
        "4",
        "--eps",
        "1e-2",
        "--transient",
        "4",
        "--measured",
        "3",
        "--corrections",
        "0",
        "--sweep-omegas",
        "3",
        "--sweep-amplitudes",
        "2",
    ]
    res = CliRunner().invoke(plugin_app(register), args)
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    # The printed figures are the reference's for the printed waveform, which is too slow.
    speed, cost, lifted = _reference_figures(out["cos"], out["sin"], out["omega"])
    assert out["mean_speed_exact"] == pytest.approx(speed, rel=1e-4) and speed < 0.5
    assert out["cost_of_transport_exact"] == pytest.approx(cost, rel=1e-4)
    assert out["liftoff_exact"] is lifted is False and out["a_max"] == 0.03 and out["v_min"] == 0.5
    assert out["stroke_exact"] <= 0.03 * (1 + 1e-12)
    assert out["feasible_exact"] is False
    assert out["constraints_exact"]["speed"] is False
    assert out["sinusoid"] is None and out["improvement_vs_sinusoid"] is None


def test_cli_bad_input_names_the_parameter():
    res = CliRunner().invoke(plugin_app(register), ["optimize", "--v-min", "-0.02", "--a-max", "0.05"])
    assert res.exit_code == 2
    assert "v_min" in res.output and "direction" in res.output
    res = CliRunner().invoke(plugin_app(register), ["optimize", "--v-min", "0.02", "--a-max", "0.2"])
    assert res.exit_code == 2 and "a_max" in res.output


# -- the exact method ---------------------------------------------------------------

EXACT_TINY = ExactSettings(
    knots=8,
    tension_periods=3,
    local=2,
    start_frequencies=3,
    random_shapes=0,
    max_iter=20,
    stages=1,
    transient=20,
    refine_baseline=False,
)
EXACT_SHAPE = _shapes.SplineShape(knots=EXACT_TINY.knots)


def _oracle() -> _orbit.Oracle:
    # The same static choices and batch size as the optimisations below: one compilation.
    p = lj.Params()
    return _orbit.Oracle(
        params=p,
        a_max=jnp.asarray(0.05),
        max_steps=jnp.asarray(4000, jnp.int32),
        tol=jnp.asarray(1e-12),
        shape=EXACT_SHAPE,
        contact="paper",
        dt=EXACT_TINY.dt,
        max_iter=EXACT_TINY.newton_iter,
    )


def test_orbit_gradients_match_finite_differences():
    # The implicit-function gradients of (Delta X, e_d, min N) over one period of the orbit
    # against central differences of orbits solved again at theta +- h d (float64).
    oracle = _oracle()
    a_max = 0.05
    phase = np.arange(256) * 2 * np.pi / 256
    theta = np.stack(
        [
            EXACT_SHAPE.fit(
                (0.03 * np.sin(phase) + 0.004 * np.cos(2 * phase) + 0.005 * np.sin(3 * phase)) / a_max, 2.0
            ),
            EXACT_SHAPE.fit(
                (0.016 * np.sin(phase) - 0.003 * np.cos(2 * phase) + 0.002 * np.cos(3 * phase)) / a_max, 4.8
            ),
        ]
    )
    y = oracle.transient(jnp.asarray(theta), jnp.zeros((2, 3)), jnp.ones(2, bool), jnp.asarray(40, jnp.int32))
    one = jnp.ones(2, jnp.int32)
    orb = oracle.orbits(jnp.asarray(theta), y, one)
    assert np.all(np.asarray(orb.ok))
    d = np.random.default_rng(3).normal(size=theta.shape)
    h = 1e-6
    plus = oracle.orbits(jnp.asarray(theta + h * d), orb.y, one)
    minus = oracle.orbits(jnp.asarray(theta - h * d), orb.y, one)
    fd = (np.asarray(plus.figures) - np.asarray(minus.figures)) / (2 * h)
    ad = np.einsum("bkp,bp->bk", np.asarray(orb.gradient), d)
    np.testing.assert_allclose(ad, fd, rtol=2e-4, atol=1e-6)
    assert np.all(np.abs(ad[:, :2]) > 1e-3)  # not a vanishing derivative
    # The orbit is a fixed point of the period map, which the dynamics alone decide.
    assert np.all(np.asarray(orb.residual) < 1e-10)
    # Without the gradient (the screen's call, the same compiled program): the same orbits.
    bare = oracle.orbits(jnp.asarray(theta), y, one, gradient=False)
    for name in ("y", "figures", "monodromy", "ok", "n_iter", "residual"):
        np.testing.assert_array_equal(np.asarray(getattr(bare, name)), np.asarray(getattr(orb, name)), err_msg=name)
    assert np.all(np.asarray(bare.gradient) == 0)


@pytest.mark.parametrize("monodromy_only", [False, True])
def test_newton_orbit_on_an_affine_map(monodromy_only):
    # Phi(y, theta) = A y + B theta**2 + c has the fixed point y* = (I - A)^-1 (B theta**2 + c);
    # the figures F = (w . y + theta . theta) give dF/dtheta = w^T (I - A)^-1 B diag(2 theta) + 2 theta.
    # Newton from far off takes several iterations; with monodromy_only they push the y directions
    # alone and the full Jacobian comes from one pass at the last iterate: the same result.
    rng = np.random.default_rng(5)
    A = 0.3 * rng.normal(size=(3, 3))
    B = rng.normal(size=(3, 4))
    c, w = rng.normal(size=3), rng.normal(size=3)
    theta = rng.normal(size=4)

    def run(z):
        y, th = z[:3], z[3:]
        phi = jnp.asarray(A) @ y + jnp.asarray(B) @ th**2 + jnp.asarray(c)
        # A mildly nonlinear term: Newton needs more than one step.
        phi = phi + 0.05 * jnp.sin(y)
        return jnp.concatenate([phi, (jnp.asarray(w) @ y + th @ th)[None]]), jnp.asarray(True)

    orb = jax.jit(lambda y0, th: _orbit.newton_orbit(run, y0, th, 1e-13, 30, monodromy_only=monodromy_only))(
        jnp.full(3, 10.0), jnp.asarray(theta)
    )
    assert bool(orb.ok) and int(orb.n_iter) >= 3
    y = np.asarray(orb.y)
    np.testing.assert_allclose(A @ y + B @ theta**2 + c + 0.05 * np.sin(y), y, rtol=0, atol=1e-12)
    M = A + 0.05 * np.diag(np.cos(y))
    np.testing.assert_allclose(np.asarray(orb.monodromy), M, rtol=1e-12, atol=1e-14)
    grad = w @ np.linalg.solve(np.eye(3) - M, B * (2 * theta)) + 2 * theta
    np.testing.assert_allclose(np.asarray(orb.gradient)[0], grad, rtol=1e-10)
    np.testing.assert_allclose(np.asarray(orb.figures)[0], w @ y + theta @ theta, rtol=1e-12)


@pytest.fixture(scope="module")
def exact_run(tiny_sweep):
    jax.clear_caches()
    before = dict(_orbit.TRACES)
    opt = _optimise.optimise(lj.Params(), 0.02, 0.05, settings=EXACT_TINY, sweep=tiny_sweep)
    grew = {k: _orbit.TRACES[k] - before.get(k, 0) for k in ("evaluate", "relax")}
    return opt, grew


def test_exact_optimum_verified_on_the_reference(exact_run):
    # The reported figures are those of the optimum's steady gait on the independent
    # reference, over whole periods; the constraints it reports as holding hold there.
    opt, _ = exact_run
    assert opt.method == "exact" and opt.feasible_exact and opt.stable_exact
    assert opt.spectral_radius_exact < 1
    assert opt.shape == "spline" and opt.control is not None and len(opt.control) == EXACT_TINY.knots
    assert isinstance(opt.waveform, lj.Spline)
    speed, cost, lifted = _reference_figures(("spline", opt.control), None, opt.omega, rho=opt.spectral_radius_exact)
    assert not lifted and speed >= 0.02
    assert opt.mean_speed_exact == pytest.approx(speed, rel=5e-4)
    assert opt.cost_of_transport_exact == pytest.approx(cost, rel=5e-4)
    t = np.linspace(0, 2 * np.pi / opt.omega, 200_001)
    dense = np.max(np.abs(np.asarray(opt.waveform(jnp.asarray(t))[0]) - 3.0))
    assert dense <= 0.05 * (1 + 1e-9) and opt.stroke_exact == pytest.approx(dense, rel=1e-8)
    # Far cheaper than any sinusoid of the sweep at this speed (the quasi-static floor is ~0.92).
    assert opt.sinusoid is not None and opt.cost_of_transport_exact < 0.8 * opt.sinusoid_cost_of_transport
    json.dumps(opt.to_dict())


def test_exact_compilations(exact_run, tiny_sweep):
    # One optimisation traces the orbit evaluation and the transient once each (every
    # start, local iteration and batch shares them); another requirement traces nothing.
    _, grew = exact_run
    assert grew == {"evaluate": 1, "relax": 1}
    settings = eqx.tree_at(lambda s: s.max_iter, EXACT_TINY, 3)
    before = dict(_orbit.TRACES)
    _optimise.optimise(lj.Params(), 0.025, 0.05, settings=settings, sweep=tiny_sweep)
    assert dict(_orbit.TRACES) == before


def test_method_choice_is_checked():
    with pytest.raises(ValueError, match="method"):
        _optimise.optimise(lj.Params(), 0.02, 0.05, method="adam")
    with pytest.raises(TypeError, match="ExactSettings"):
        _optimise.optimise(lj.Params(), 0.02, 0.05, settings=TINY)
    with pytest.raises(ValueError, match="harmonics"):
        _optimise.optimise(lj.Params(), 0.02, 0.05, harmonics=8)
    with pytest.raises(ValueError, match="shape"):
        ExactSettings(shape="chebyshev")
    with pytest.raises(ValueError, match="start"):
        _optimise.optimise(
            lj.Params(), 0.02, 0.05, method="smoothed", start=lj.Fourier(np.zeros(1), np.full(1, 0.05), 2.0, 3.0)
        )


def test_objective_and_constraint_gradients_compose():
    # The driver's objective (cost of transport with a floored distance and a penalty on
    # the speed deficit) and constraints, built from an orbit's figures and gradients,
    # differentiated by hand: against central differences, on a fast and a slow point.
    rng = np.random.default_rng(5)
    p = 5
    W = rng.normal(size=(3, p)) * 0.01

    def orbit_at(theta):
        # Smooth stand-ins for (Delta X, e_d, min N) and their exact gradients.
        base = np.array([0.05, 0.05, 0.5]) + W @ np.sin(theta)
        grad = W * np.cos(theta)[None, :]
        a = jnp.asarray
        return _orbit.Orbit(a(np.zeros(3)), a(base), a(grad), a(np.zeros((3, 3))), a(True), a(0), a(0.0))

    for speed in (0.01, 0.2):  # feasible, then short of the speed (deficit penalised)
        theta = rng.normal(size=p)
        fig = lambda th: _exact_optimise._Figures(th, orbit_at(th), speed, 1, 1, 0.05, True)
        f0 = fig(theta)
        h = 1e-6
        fd = np.array([(fig(theta + h * e).f - fig(theta - h * e).f) / (2 * h) for e in np.eye(p)])
        fdc = np.array([(fig(theta + h * e).c - fig(theta - h * e).c) / (2 * h) for e in np.eye(p)]).T
        np.testing.assert_allclose(f0.df, fd, rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose(f0.dc, fdc, rtol=1e-6, atol=1e-9)
    assert f0.c[0] < 0 and f0.f > 1  # the slow point is penalised above any physical cost


def test_stroke_windows_bound_the_true_stroke():
    # The exact method's stroke constraint: the largest window maximum is the true stroke
    # (against a dense evaluation of the series), and the Jacobian is that of the values.
    n_h = 16
    peaks = _shapes.StrokePeaks(n_h)
    rng = np.random.default_rng(2)
    n = np.arange(1, n_h + 1)
    phase = np.linspace(0, 2 * np.pi, 400_001)
    for _ in range(3):
        theta = np.r_[rng.normal(size=2 * n_h - 1) / np.r_[n[1:], n], 0.3]
        values, jac = peaks(theta)
        cos, sin = np.r_[0.0, theta[: n_h - 1]], theta[n_h - 1 : -1]
        dense = np.max(np.abs(np.cos(np.outer(phase, n)) @ cos + np.sin(np.outer(phase, n)) @ sin))
        assert 1 - values.min() == pytest.approx(dense, rel=1e-8)
        d = rng.normal(size=theta.shape)
        h = 1e-6
        fd = (peaks(theta + h * d)[0] - peaks(theta - h * d)[0]) / (2 * h)
        np.testing.assert_allclose(jac @ d, fd, atol=1e-6)
