"""The actuation optimiser (SPEC §7): gradients, constraint handling, verification, inputs, CLI.

Problems are tiny (few harmonics, one coarse smoothing stage, a few Adam steps,
short exact verification) so the file stays well under the test budget; the
real runs are in `experiments/optimal_actuation.py`.
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
from locomotion_jax import _constraints, _objective, _optimise, _pareto
from locomotion_jax._optimise_cli import register
from locomotion_jax._optimum import Settings
from plugin_app import plugin_app
from reference import reference_natural_frequencies, reference_simulate
from typer.testing import CliRunner


TINY = Settings(
    starts=2,
    eps_schedule=(1e-2,),
    outer=1,
    inner=4,
    corrections=0,
    verify_horizon=10.0,
    transient=4.0,
    measured=3.0,
    refine_baseline=False,
)


def _reference_figures(cos, sin, omega, horizon=TINY.verify_horizon, a=None):
    """`(mean speed, cost of transport, lift-off)` of a waveform on the independent reference
    (`tests/reference.py`), as the optimiser defines them on the exact model: the defaults, strict
    contact, relaxed start, from t_start over `horizon`; `a` instead of `cos, sin`: eq. (13)."""
    ts = 80 * 2 * math.pi / min(reference_natural_frequencies({}))
    kw: dict[str, Any] = dict(wave=(cos, sin)) if a is None else {}
    params = dict(omega=omega) if a is None else dict(omega=omega, a=a)
    r = reference_simulate(params, ts + horizon, save_at=[ts, ts + horizon], start="relaxed", **kw)
    dX = r["X"][1] - r["X"][0]
    return dX / horizon, (r["e_d"][1] - r["e_d"][0]) / abs(dX), r["liftoff"]


@pytest.fixture(scope="module")
def tiny_sweep():
    # Two amplitudes x three frequencies around omega = 4, exact model, short horizon.
    return _pareto.sinusoid_sweep(
        lj.Params(), 0.05, omegas=np.array([2.0, 4.0, 6.0]), amplitudes=2, horizon=TINY.verify_horizon
    )


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


def test_d0_equal_masses_cannot_move():
    # With d = 0 and m1 = m2 the model is symmetric under x -> -x with the masses swapped,
    # so no waveform moves the centre of mass; use a time-asymmetric, even-harmonic one.
    p = lj.Params(d=0.0, mhat=0.5)
    wave = lj.Fourier(np.array([0.01, -0.012, 0.004]), np.array([0.03, 0.015, -0.006]), 3.0, 3.0)
    fig = _pareto.exact_figures(p, wave, TINY.verify_horizon)  # shapes shared with other tests: one compile
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
    return _optimise.optimise(lj.Params(), 0.01, 0.05, omega=4.0, harmonics=2, settings=TINY, sweep=tiny_sweep)


def test_compilations_per_optimisation(tiny_sweep):
    # One trace of the Adam block per optimisation: not per smoothing stage (the step
    # count is traced, under a loop of the finest stage's length), outer iteration,
    # start or call. `_evaluate` runs on the starts and once on all candidates
    # (another batch size): two traces.
    settings = eqx.tree_at(lambda s: (s.eps_schedule, s.outer), TINY, ((1e-2, 5e-3), 2))
    jax.clear_caches()
    run = lambda v: _optimise.optimise(
        lj.Params(), v, 0.05, omega=4.0, harmonics=2, settings=settings, sweep=tiny_sweep
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


def test_optimum_verified_on_the_reference(tiny_optimum):
    # The reported exact figures of the optimum and of the best sinusoid are those of the
    # independent reference solver for the returned waveforms (measured 2e-6 apart).
    opt = tiny_optimum
    speed, cost, lifted = _reference_figures(opt.cos, opt.sin, opt.omega)
    assert not lifted and not opt.liftoff_exact
    assert opt.mean_speed_exact == pytest.approx(speed, rel=1e-4)
    assert opt.cost_of_transport_exact == pytest.approx(cost, rel=1e-4)
    assert opt.feasible_exact == (speed >= 0.01) and all(opt.constraints_exact.values()) == opt.feasible_exact
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


def test_cli_infeasible_requirement_is_reported_infeasible():
    # Nothing reaches a mean speed of 0.5 with a stroke of 0.03: the result must say so.
    # Same shapes and static settings as TINY, so the compiled functions are reused.
    args = [
        "optimize",
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
        "--horizon",
        "10",
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
