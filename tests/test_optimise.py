"""The actuation optimisers: gradients, constraints, verification, inputs and CLI, for the paper's
model, chains and mechanisms.

The paper's model (SPEC §7): problems are tiny (few harmonics, few iterations, one coarse
smoothing stage) so the tests stay well under the test budget; the real runs are in
`experiments/optimal_actuation.py`. Every reported exact figure is checked against the
independent reference (`tests/reference.py`) over whole periods of the steady gait.

Chains (`optimise(chain, ...)` and `locomotion-jax chain-optimize`): small problems (N = 3 and
N = 2, a short transient, coarse screens, few iterations) whose fixtures share every compilation
(the screen's and the verification's steady-gait solver, the orbit oracle, the direct
simulation), in one xdist group.

Mechanisms (`optimisation._mechanism`, `lj.MechanismOptimiseSettings`; slow, about 2 to 5 minutes
each):

1. A capsule whose internal mass sits on a spring and a damper, driven by an internal force, on
   anisotropic ground, backwards: the optimum's gait is checked by a direct `simulate` and by the
   independent reference (`tests/reference_mechanism.py`, with the optimum's Fourier force; within
   the step's truncation error, which shrinks with the step), and it beats the best sinusoid of a
   small batched sweep of the test's own.
2. The capsule of `experiments/capsule.py` on isotropic Coulomb ground at a fixed frequency,
   forward, under a force bound the optimum does not reach: its cost of transport is the physical
   floor mu_k (M + m) g (a body that never slides backward dissipates exactly mu_k N per distance;
   any backward slide costs more), checked by a direct simulation from rest (`lj.measure`), and no
   sinusoid under the same bound is as fast (a batched sweep of amplitudes and phases).
3. The same capsule with splines (`MechanismOptimiseSettings(shape="spline")`) under a force bound
   at which no sinusoid of the screen moves it: the optimum's control values are within the bound,
   its exact stroke matches a dense sampling, its cost is at or above the physical floor, and its
   gait from rest agrees with the independent reference (which has its own B-spline).
4. float32: the optimiser keeps the mechanism's dtype, and the float32 optimum's gait agrees with
   the float64 reference to float32's resolution.
"""

import dataclasses
import json
import math
import types
from pathlib import Path
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
import scipy.optimize
from locomotion_jax.cli import _main as _cli, _optimise as _cli_optimise
from locomotion_jax.cli._optimise import register
from locomotion_jax.dynamics import _paper
from locomotion_jax.gaits import _element_orbit, _orbit, _shooting
from locomotion_jax.optimisation import (
    _chain_screen as screen,
    _constraints,
    _element_local,
    _evaluator,
    _exact as _exact_optimise,
    _objective,
    _optimise,
    _pareto,
    _plots,
    _shapes,
)
from locomotion_jax.optimisation._optimum import ExactSettings, Settings, waveform_of
from plugin_app import plugin_app
from reference import reference_simulate
from reference_mechanism import Body, run, Sig, System
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
    plan = _objective.make_plan((p.m1, p.m2), 4.0, 4.0, eps, 3.0, 3.0, detach)
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


def _gradient_matches_finite_differences(prob, theta: dict, speed: float, seed: int) -> None:
    """Reverse mode through the checkpointed RK4 rollout of `prob` vs central differences
    (float64), for the cost of transport and both constraints, along a random direction."""
    eps, v_t, margin = jnp.asarray(1e-2), jnp.asarray(speed), jnp.asarray(0.05)
    rng = np.random.default_rng(seed)
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


def test_gradient_matches_finite_differences():
    theta = {"cos": jnp.array([0.1, -0.2]), "sin": jnp.array([0.8, 0.15]), "log_omega": jnp.asarray(math.log(4.0))}
    _gradient_matches_finite_differences(_problem(1e-2), theta, 0.03, 1)


def test_element_rollout_is_the_papers_on_its_two_mass_chain():
    """`_objective.element_rollout` (any mechanism's physics through `_smoothed.rates_and_normal`) on
    the paper's model as a two-mass chain (`Chain.from_params`) is the paper's own rollout
    (`_two_mass.forces`): the same smoothed model and start, to rounding. (The cosine coefficients
    sum to 0, so that $\\ell_0(0) = \\bar\\ell$: the paper's rollout starts at the gap of $\\bar\\ell$,
    a chain's relaxed start at that of $\\ell_0(0)$.)"""
    p = lj.Params()
    cos, sin, omega = jnp.array([0.012, -0.012]), jnp.array([0.03, 0.015]), jnp.asarray(3.0)
    plan = _objective.make_plan((p.m1, p.m2), 3.0, 3.0, 1e-2, 4.0, 4.0)
    eps = jnp.asarray(1e-2)
    a = _objective.rollout(p, lj.Fourier(cos, sin, omega, p.lbar), eps, plan, 0.005)
    b = _objective.element_rollout(lj.Chain.from_params(p), cos[None], sin[None], omega, eps, plan, 0.005)
    assert abs(float(a.distance)) > 1e-3 and float(a.min_normal) > 0.5
    for name, x, y in zip(a._fields, a, b):
        assert float(y) == pytest.approx(float(x), rel=1e-11, abs=1e-14), name


def test_element_gradient_matches_finite_differences():
    """Reverse mode through a chain's smoothed rollout (`_optimise.element_rollout`, the smoothed
    local stage's objective and constraints) against central differences along a random direction:
    the paper's Coulomb law on tilted springs (so that the normal forces depend on the actuation)."""
    chain = lj.Chain(masses=[1.0] * 3).broadcast()
    plan = _objective.make_plan((1.0, 1.0, 1.0), 3.0, 3.0, 1e-2, 4.0, 4.0)
    log_lo, log_hi = jnp.asarray(math.log(2.0)), jnp.asarray(math.log(5.0))
    prob = _optimise._Problem(chain, jnp.asarray(A_MAX), jnp.asarray(1.0), log_lo, log_hi, plan, 0.005, True,
                              _optimise.element_rollout)  # fmt: skip
    theta = {"cos": jnp.array([[0.0, 0.1], [-0.3, 0.05]]), "sin": jnp.array([[0.8, -0.1], [0.4, 0.2]]),
             "log_omega": jnp.asarray(math.log(3.0))}  # fmt: skip
    _gradient_matches_finite_differences(prob, theta, 0.05, 2)


def test_element_rollout_in_either_layout(monkeypatch):
    """A chain's smoothed rollout (`_objective.element_rollout`) runs in the layout of its steady gaits:
    a 4-mass worm on bristles in the array layout (one entry over the masses, `layout="auto"` from
    `GAIT_ARRAY_FROM` masses) gives the unrolled layout's figures and reverse-mode gradients to
    rounding (the same fixed RK4 steps; sums over masses in another order)."""
    plan = _objective.make_plan((1.0,) * 4, 3.0, 3.0, 1e-2, 4.0, 4.0)
    eps = jnp.asarray(1e-2)
    cos = jnp.array([[0.01, -0.02], [0.03, 0.0], [-0.01, 0.02]])
    sin = jnp.array([[0.04, 0.01], [0.02, -0.01], [0.03, 0.02]])

    def run(layout, cos):
        worm = lj.Chain(masses=[1.0, 1.1, 0.9, 1.0], k=50.0, d=0.3, lbar=3.0, c=0.01, layout=layout,
                        friction=lj.AnisotropicCoulomb(0.7, 0.9, 0.5, 0.7)).broadcast()  # fmt: skip
        return _objective.element_rollout(worm, cos, sin, jnp.asarray(3.0), eps, plan, 0.005)

    seen = []  # the physics each rollout integrates
    real = _objective.engine_physics
    monkeypatch.setattr(_objective, "engine_physics", lambda *a: seen.append(type(P := real(*a)).__name__) or P)
    got, ref = run("auto", cos), run("unrolled", cos)
    assert set(seen) == {"ArrayChainPhysics", "ChainPhysics"}
    assert abs(float(ref.distance)) > 1e-3 and float(ref.min_normal) > 0.1
    for name, x, y in zip(ref._fields, ref, got):
        assert float(y) == pytest.approx(float(x), rel=1e-11, abs=1e-14), name
    grads = [jax.grad(lambda c, layout=layout: run(layout, c).distance)(cos) for layout in ("auto", "unrolled")]
    assert float(jnp.max(jnp.abs(grads[1]))) > 1e-3
    np.testing.assert_allclose(np.asarray(grads[0]), np.asarray(grads[1]), rtol=1e-9, atol=1e-12)


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


def test_projection_of_several_signals_rescales_each_one():
    """`_optimise.project` of `(S, H)` coefficients (the smoothed local stage of a chain or a
    mechanism): each signal above the unit stroke lands on it, one inside is kept, and the
    frequency is clipped."""
    cos = jnp.array([[0.9, 0.4], [0.1, 0.0], [0.0, -2.0]])
    sin = jnp.array([[0.5, 0.0], [0.2, 0.1], [1.0, 0.3]])
    out = _optimise.project({"cos": cos, "sin": sin, "log_omega": jnp.asarray(3.0)}, 0.0, 1.0)
    strokes = [float(_constraints.stroke(c, s)) for c, s in zip(out["cos"], out["sin"])]
    assert strokes[0] == pytest.approx(1.0, rel=1e-12) and strokes[2] == pytest.approx(1.0, rel=1e-12)
    assert np.array_equal(out["cos"][1], cos[1]) and np.array_equal(out["sin"][1], sin[1])
    assert float(out["log_omega"]) == 1.0


def test_a_candidate_is_stable_only_where_half_the_step_agrees():
    """`_optimum.steady_at_half_step`, and the chain's and the mechanism's verification that applies
    it (`_element_local.verify`, on gaits given here): of two fast enough candidates the cheaper one's
    cost moves by 2e-3 at half the step, so the other is reported; the table has both steps' figures."""
    from locomotion_jax.optimisation._element_local import pack, verify
    from locomotion_jax.optimisation._optimum import steady_at_half_step

    ok, speed, cost = np.array([True, True, True, True, False]), np.full(5, 0.1), np.array([1.0, 1.0, 1.0, np.inf, 1.0])
    half = np.array([1.0 + 9e-4, 1.0 + 2e-3, 1.0, np.inf, 1.0])
    half_ok = np.array([True, True, False, True, True])
    assert steady_at_half_step(ok, speed, cost, half_ok, speed, half).tolist() == [True, False, False, True, False]
    assert not steady_at_half_step(ok, speed, cost, half_ok, speed * (1 + 2e-3), cost)[0]

    S, H = 1, 1
    baseline = (np.zeros((S, H)), np.full((S, H), 0.05), 2.0)
    xs = [pack(np.zeros((S, H)), np.full((S, H), 1.0), math.log(2.0)) for _ in range(2)]

    def gaits(costs):
        def solve(cos, sin, om, control=None):
            n = len(om)
            return dict(ok=np.ones(n, bool), speed=np.full(n, 0.1), cost=np.asarray(costs[:n], float),
                        radius=np.full(n, 0.5), liftoff=np.zeros(n, bool))  # fmt: skip

        return solve

    at_dt, at_half = gaits([1.0, 0.8, 0.9]), gaits([1.0, 0.8 * (1 + 2e-3), 0.9 * (1 + 5e-4)])
    v = verify(xs, baseline, {}, ["wave", "local 0", "local 1"], at_dt, at_half, 0.05, 0.05, 1, H, 0, 1e-16)
    assert v.k == 2 and v.feasible.tolist() == [True, False, True]
    assert [c["stable_exact"] for c in v.table] == [True, False, True]
    assert [c["half_step_cost"] for c in v.table] == pytest.approx([1.0, 0.8016, 0.90045])
    v = verify(xs, baseline, {}, ["wave", "local 0", "local 1"], at_dt, at_dt, 0.05, 0.05, 1, H, 0, 1e-16)
    assert v.k == 1  # agreeing: the cheapest


def test_choose_takes_the_cheapest_feasible_else_the_fastest_stable_gait():
    """The choice every exact optimiser makes among its verified candidates (`_optimum.choose`); the
    chain's and the mechanism's break a tie of costs by the spectral radius."""
    from locomotion_jax.optimisation._optimum import choose

    eps = float(np.finfo(np.float64).eps)
    ok = np.array([True, True, True, False, True])
    speed = np.array([0.06, 0.05, 0.07, 0.09, np.nan])
    cost = np.array([1.0, 0.8, 0.9, 0.1, 0.1])
    strokes = np.array([0.05, 0.05, 0.05 * (1 + 4 * eps), 0.05, 0.05])
    # Row 1 is the cheapest fast enough; row 3 is cheaper but not a stable gait, row 4 has no speed.
    k, feasible, ok_speed, ok_stroke = choose(ok, speed, cost, strokes, 0.05, 1, 0.05, eps)
    assert k == 1 and feasible.tolist() == [True, True, True, False, False]
    assert ok_speed.tolist() == [True, True, True, False, False] and ok_stroke.all()
    # A stroke over the limit by more than 8 eps is infeasible, whatever its cost.
    k, feasible, _, ok_stroke = choose(ok, speed, cost, strokes * np.array([1, 1 + 1e-9, 1, 1, 1]), 0.05, 1, 0.05, eps)
    assert k == 2 and not ok_stroke[1] and not feasible[1]
    # None fast enough: the fastest stable gait, in the required direction.
    k, feasible, _, _ = choose(ok, speed, cost, strokes, 0.5, 1, 0.05, eps)
    assert k == 2 and not feasible.any()
    k, _, _, _ = choose(ok, -speed, cost, strokes, 0.5, -1, 0.05, eps)
    assert k == 2
    # No stable gait at all: the first candidate.
    assert choose(~ok & False, speed, cost, strokes, 0.05, 1, 0.05, eps)[0] == 0
    # With the spectral radii: of the feasible rows as cheap as the cheapest to 1e-9 (a floor of the
    # cost, reached by rounding), the most stable; a cheaper one by more than that wins alone.
    tie = np.array([0.8 * (1 + 2e-10), 0.8, 0.8 * (1 + 5e-10), 0.1, 0.1])
    radius = np.array([0.3, 0.999, 0.5, 0.1, 0.1])
    assert choose(ok, speed, tie, strokes, 0.05, 1, 0.05, eps, radius)[0] == 0
    assert choose(ok, speed, tie, strokes, 0.05, 1, 0.05, eps)[0] == 1
    apart = np.array([0.8 * (1 + 2e-9), 0.8, 0.8 * (1 + 5e-10), 0.1, 0.1])
    assert choose(ok, speed, apart, strokes, 0.05, 1, 0.05, eps, radius)[0] == 2


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
    plan = _objective.make_plan((p.m1, p.m2), 3.0, 3.0, 1e-2, 4.0, 4.0)
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
    own = _objective.make_plan((p.m1, p.m2), 3.0, 3.0, 1e-2, 4.0, 4.0)
    shared = _objective.make_plan((p.m1, p.m2), 3.0, 3.0, 1e-2, 4.0, 4.0, eps_min=2.5e-3)
    assert shared.max_steps_per_period > int(shared.steps_per_period) == own.max_steps_per_period
    a = _objective.rollout(p, wave, eps, own, 0.005)
    b = _objective.rollout(p, wave, eps, shared, 0.005)
    for x, y in zip(a, b):
        assert float(y) == pytest.approx(float(x), rel=1e-12, abs=1e-15)
    with pytest.raises(ValueError, match="eps_min"):
        _objective.make_plan((p.m1, p.m2), 3.0, 3.0, 1e-3, 4.0, 4.0, eps_min=1e-2)


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
    for model in ([], ["--masses", "1,1,1"]):
        args = ["optimize", "--v-min", "0.02", "--a-max", "0.05", "--local-method", "bfgs", *model]
        res = CliRunner().invoke(plugin_app(register), args)
        assert res.exit_code == 2 and "local_method must be 'descent'" in res.output, res.output


CAPSULE_FILE = str(Path(__file__).resolve().parents[1] / "examples" / "capsule.toml")


def test_cli_local_method_reaches_the_settings(monkeypatch):
    """`--local-method sqp`, `--dt`, `--search-dt` and `--tension-periods` reach the settings, for the
    paper's model, a chain and a mechanism's file; without them the settings keep their defaults."""
    seen = []

    def stop(mech, v_min, a_max, **kw):
        seen.append(kw["settings"])
        raise ValueError("stopped by the test")

    # `lj` first: its lazy attribute resolves to `_optimise`'s, which must still be the real one
    # when monkeypatch records what to restore.
    monkeypatch.setattr(lj, "optimise", stop)  # a chain's path
    monkeypatch.setattr(_optimise, "optimise", stop)  # the paper's model's
    monkeypatch.setattr(_pareto, "sinusoid_sweep", lambda *a, **k: None)
    for model in ([], ["--masses", "1,1,1"]):
        for steps in ([], ["--dt", "0.005", "--search-dt", "0.01", "--tension-periods", "0"]):
            args = ["optimize", "--v-min", "0.02", "--a-max", "0.05", "--local-method", "sqp", *steps, *model]
            res = CliRunner().invoke(plugin_app(register), args)
            assert "stopped by the test" in res.output, res.output
    assert [s.local_method for s in seen] == ["sqp"] * 4
    assert [(s.dt, s.search_dt, s.tension_periods) for s in seen] == [(0.01, None, 10), (0.005, 0.01, 0),
                                                                      (0.01, None, None), (0.005, 0.01, 0)]  # fmt: skip
    # A mechanism's file: its idealised inchworms too.
    res = CliRunner().invoke(plugin_app(register), ["optimize", CAPSULE_FILE, "--v-min", "0.02", "--a-max",
                                                    "0.5", "--tension-periods", "3"])  # fmt: skip
    assert "stopped by the test" in res.output and seen[-1].tension_periods == 3, res.output
    for extra in (["--search-dt", "0.02"], ["--tension-periods", "3"]):
        res = CliRunner().invoke(plugin_app(register), ["optimize", "--v-min", "0.02", "--a-max", "0.05", "--method",
                                                        "smoothed", *extra])  # fmt: skip
        assert res.exit_code == 2 and extra[0] in res.output, res.output


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


def _oracle(dt: float = EXACT_TINY.dt, max_iter: int = EXACT_TINY.newton_iter) -> _orbit.Oracle:
    # The same static choices and batch size as the optimisations below: one compilation.
    p = lj.Params()
    return _orbit.Oracle(
        params=p,
        a_max=jnp.asarray(0.05),
        max_steps=jnp.asarray(4000, jnp.int32),
        tol=jnp.asarray(1e-12),
        shape=EXACT_SHAPE,
        contact="paper",
        dt=dt,
        max_iter=max_iter,
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


def test_oracles_of_any_step_and_iteration_cap_share_their_programs():
    # The step and Newton's iteration cap are data of the oracle's programs: an oracle at half the
    # step and with one iteration runs `_oracle()`'s programs, and both settings reach them.
    phase = np.arange(256) * 2 * np.pi / 256
    theta = jnp.asarray(np.stack([EXACT_SHAPE.fit(0.6 * np.sin(phase), w) for w in (2.0, 4.8)]))
    start, fresh, one = jnp.zeros((2, 3)), jnp.ones(2, bool), jnp.ones(2, jnp.int32)
    periods = jnp.asarray(3, jnp.int32)
    first = _oracle()
    y = first.transient(theta, start, fresh, periods)
    orb = first.orbits(theta, y, one)
    before = dict(_orbit.TRACES)
    other = _oracle(dt=first.dt / 2, max_iter=1)
    y_half = other.transient(theta, start, fresh, periods)
    orb_one = other.orbits(theta, y, one)
    assert dict(_orbit.TRACES) == before  # no new program
    assert not np.array_equal(y_half, y)  # the step reached the engine: within RK4's error
    np.testing.assert_allclose(y_half, y, rtol=1e-5, atol=1e-5)
    assert np.all(np.asarray(orb.n_iter) > 1) and np.all(np.asarray(orb.ok))
    np.testing.assert_array_equal(orb_one.n_iter, 1)  # the cap reached Newton's loop
    assert not np.any(np.asarray(orb_one.ok))


@pytest.mark.parametrize("monodromy_only, patience", [(False, None), (True, None), (True, 3)])
def test_newton_orbit_on_an_affine_map(monodromy_only, patience):
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

    solve = lambda y0, th: _orbit.newton_orbit(run, y0, th, 1e-13, 30, monodromy_only=monodromy_only, patience=patience)
    orb = jax.jit(solve)(jnp.full(3, 10.0), jnp.asarray(theta))
    assert bool(orb.ok) and int(orb.n_iter) >= 3
    y = np.asarray(orb.y)
    np.testing.assert_allclose(A @ y + B @ theta**2 + c + 0.05 * np.sin(y), y, rtol=0, atol=1e-12)
    M = A + 0.05 * np.diag(np.cos(y))
    np.testing.assert_allclose(np.asarray(orb.monodromy), M, rtol=1e-12, atol=1e-14)
    grad = w @ np.linalg.solve(np.eye(3) - M, B * (2 * theta)) + 2 * theta
    np.testing.assert_allclose(np.asarray(orb.gradient)[0], grad, rtol=1e-10)
    np.testing.assert_allclose(np.asarray(orb.figures)[0], w @ y + theta @ theta, rtol=1e-12)


def test_newton_orbit_gives_up_a_cycle():
    # Newton's method on f(y) = y^3 - 2y + 2 from y = 0 cycles 0, 1, 0, ... (residuals 2, 1, 2, 1):
    # the period map y + f(y) has no fixed point near the start. With `patience` 3 it stops,
    # unconverged, at the third iteration in a row that did not halve the smallest residual (1);
    # without, at max_iter.
    def run(z):
        y = z[:1]
        return jnp.concatenate([y + y**3 - 2 * y + 2, z[1:]]), jnp.asarray(True)

    def solve(patience):
        fn = jax.jit(lambda y0, th: _orbit.newton_orbit(run, y0, th, 1e-12, 30, patience=patience))
        return fn(jnp.zeros(1), jnp.ones(1))

    stopped, held = solve(3), solve(None)
    assert not bool(stopped.ok) and int(stopped.n_iter) == 4
    assert not bool(held.ok) and int(held.n_iter) == 30


class _LadderOrbit(NamedTuple):
    y: np.ndarray
    ok: np.ndarray


class _LadderOracle:
    """An orbit oracle whose outcome is a function of its inputs alone: the transient from rest
    settles at 10 + theta, one from a warm start adds 1; an orbit converges from a settled state
    as a period-1 gait where theta > 0, as a period-2 gait where theta > -1. Records its calls."""

    dtype = jnp.float64

    def __init__(self):
        self.calls: list[tuple] = []

    def orbits(self, theta, y0, k, gradient=True):
        self.calls.append(("orbits", np.asarray(k).tolist()))
        settled = np.asarray(y0)[:, 0] == 10 + np.asarray(theta)[:, 0]
        ok = settled & (np.asarray(theta)[:, 0] > np.where(np.asarray(k) == 1, 0.0, -1.0))
        return _LadderOrbit(y=np.asarray(y0) + 100 * np.asarray(k)[:, None], ok=ok)

    def transient(self, theta, y0, fresh, periods):
        self.calls.append(("transient", np.asarray(fresh).tolist()))
        return np.where(np.asarray(fresh)[:, None], 10 + np.asarray(theta), np.asarray(y0) + 1)


def test_a_rested_batch_retries_its_failures_as_period_2_gaits_alone():
    # The exact optimiser's screen solves period-1 gaits from the transient from rest. Where one
    # fails, the retry's transient from rest and period-1 solve would repeat that attempt bit for
    # bit: `rested=True` goes straight to the period-2 gait, with the same outcome.
    theta = np.array([[0.5], [-0.5], [-2.0], [1.0]])
    rest = 10 + theta
    plain, rested = _LadderOracle(), _LadderOracle()
    ev_plain = _evaluator.Evaluator(plain, 4, 30, make=lambda *a: None)
    ev_rested = _evaluator.Evaluator(rested, 4, 30, make=lambda *a: None)
    orb_p, k_p = ev_plain.solve(theta, rest, np.ones(4, int), np.zeros(4, bool))
    orb_r, k_r = ev_rested.solve(theta, rest, np.ones(4, int), rested=True)
    assert orb_r.ok.tolist() == [True, True, False, True] and k_r.tolist() == [1, 2, 1, 1]
    np.testing.assert_array_equal(k_p, k_r)
    np.testing.assert_array_equal(orb_p.ok, orb_r.ok)
    np.testing.assert_array_equal(orb_p.y, orb_r.y)
    assert [c[0] for c in plain.calls] == ["orbits", "transient", "orbits", "orbits"]
    assert rested.calls == [("orbits", [1, 1, 1, 1]), ("orbits", [2, 2, 2, 2])]


def test_a_batch_without_retry_leaves_its_failures_unsolved():
    # With `retry` off (the exact optimiser's local runs before the last stage) a lane whose orbit is
    # not found from its warm start gets `bad` at once: one oracle call, no transient.
    theta = np.array([[0.5], [-0.5], [-2.0], [1.0]])
    warm = {0: 10 + theta[0], 1: 11 + theta[1], 2: 11 + theta[2], 3: 10 + theta[3]}  # 1, 2: not settled
    outcomes = []
    for retry in (False, True):
        oracle = _LadderOracle()
        ev = _evaluator.Evaluator(oracle, 4, 30, make=lambda lane, th, orb, k: k, bad=lambda lane, th: "bad")
        ev.y, ev.k, ev.retry = dict(warm), dict.fromkeys(range(4), 1), retry
        outcomes.append((ev([0, 1, 2, 3], list(theta)), [c[0] for c in oracle.calls]))
    assert outcomes[0] == ([1, "bad", "bad", 1], ["orbits"])
    # Retried: after the transient from rest lane 1 has a period-2 gait (lane 2 has none at all).
    assert outcomes[1] == ([1, 2, "bad", 1], ["orbits", "transient", "orbits", "orbits"])


@pytest.mark.parametrize("retry", ["last", "every"])
def test_the_exact_local_runs_retry_in_their_last_stage_only(tiny_sweep, monkeypatch, retry):
    # `ExactSettings.retry`: "last" retries a failed orbit in the last stage of the local runs only,
    # "every" in each. Two short stages of the tiny problem (its programs: no new compilation).
    stages: list[bool] = []
    lockstep = _exact_optimise.run_lockstep
    monkeypatch.setattr(
        _exact_optimise, "run_lockstep", lambda solvers, ev: stages.append(ev.retry) or lockstep(solvers, ev)
    )
    settings = dataclasses.replace(EXACT_TINY, stages=2, max_iter=4, retry=retry)
    _optimise.optimise(lj.Params(), 0.02, 0.05, settings=settings, sweep=tiny_sweep)
    assert stages == ([False, True] if retry == "last" else [True, True])


@pytest.fixture(scope="module")
def exact_run(tiny_sweep):
    jax.clear_caches()
    before = dict(_orbit.TRACES)
    opt = _optimise.optimise(lj.Params(), 0.02, 0.05, settings=EXACT_TINY, sweep=tiny_sweep)
    grew = {k: _orbit.TRACES[k] - before.get(k, 0) for k in ("evaluate", "relax")}
    return opt, grew


def test_the_papers_optimum_keeps_its_sweep(exact_run, tiny_sweep):
    """`Optimum.screen`: the baseline's sinusoid sweep, which `to_dict(full=True)` carries and
    `sweep=` takes back (read from JSON, NaN as null) as the same sweep; a record of other shapes is
    refused naming `sweep`."""
    opt, _ = exact_run
    back = _pareto.sweep_of(json.loads(opt.to_json(full=True))["screen"])
    for key, value in tiny_sweep._asdict().items():
        np.testing.assert_array_equal(opt.screen[key], value)
        np.testing.assert_array_equal(getattr(back, key), value)
    assert "screen" not in opt.to_dict() and _pareto.sweep_of(tiny_sweep) is tiny_sweep
    name, speed, cost, ok = opt.baseline_screen()
    assert name == "sinusoids" and np.array_equal(speed, tiny_sweep.speed, equal_nan=True)
    with pytest.raises(TypeError, match="sweep: an optimum's screen has one row per sinusoid"):
        _pareto.sweep_of(dict(a=[1.0], omega=[1.0, 2.0], speed=[0.1], cost=[1.0], ok=[True]))


def test_the_papers_start_may_be_an_optimums_dict(exact_run, monkeypatch):
    """`start=` of the paper's model: an optimum's `to_dict()`, read back from JSON, is its waveform;
    a chain's is refused, naming what it is."""
    from locomotion_jax.optimisation._optimum import start_waveform

    opt, _ = exact_run
    wave = start_waveform(json.loads(opt.to_json()))
    assert type(wave) is type(opt.waveform)
    for a, b in zip(jax.tree_util.tree_leaves(wave), jax.tree_util.tree_leaves(opt.waveform)):
        assert np.array_equal(np.asarray(a), np.asarray(b))
    assert start_waveform(opt) is not None and start_waveform(wave) is wave
    chain = dict(cos=[[0.0, 0.01]], sin=[[0.02, 0.0]], control=None, omega=2.0, lbar=[3.0])
    monkeypatch.setattr(_pareto, "sinusoid_sweep", lambda *args, **kwargs: pytest.fail("swept before the check"))
    with pytest.raises(ValueError, match="start: not a result of the paper's model"):
        _optimise.optimise(lj.Params(), 0.02, 0.05, settings=EXACT_TINY, start=chain)
    with pytest.raises(ValueError, match="with cos, sin, control, omega and lbar"):
        start_waveform({"cos": [0.0]})
    with pytest.raises(ValueError, match="with a scalar lbar"):
        start_waveform(dict(cos=[0.0], sin=[0.01], control=None, omega=2.0))


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
    # Its direct simulation from the relaxed spring settles on its gait, as the reference's does.
    assert opt.simulated_recurrence == 1 and opt.simulation_agreement < 1e-6
    assert opt.mean_speed_simulated == pytest.approx(speed, rel=5e-4)
    assert "direct simulation" in opt.summary() and opt.to_dict()["simulated_recurrence"] == 1
    t = np.linspace(0, 2 * np.pi / opt.omega, 200_001)
    dense = np.max(np.abs(np.asarray(opt.waveform(jnp.asarray(t))[0]) - 3.0))
    assert dense <= 0.05 * (1 + 1e-9) and opt.stroke_exact == pytest.approx(dense, rel=1e-8)
    # Far cheaper than any sinusoid of the sweep at this speed (the quasi-static floor is ~0.92).
    assert opt.sinusoid is not None and opt.cost_of_transport_exact < 0.8 * opt.sinusoid_cost_of_transport
    json.dumps(opt.to_dict())


def test_the_verification_steps_at_dt_whatever_the_search_step(exact_run):
    """The screen and the local runs may step at `ExactSettings.search_dt`; the verification, and
    so every figure reported, steps at `dt`: given a search step of `2 dt`, `_exact._verify`
    reports the optimum's figures at `dt` (to Newton's tolerance), which differ from those at
    `2 dt` by the search's RK4 error."""
    opt, _ = exact_run
    best = np.r_[opt.control / 0.05, math.log(opt.omega)]
    settings = dataclasses.replace(EXACT_TINY, search_dt=2 * EXACT_TINY.dt)
    found, _ = _exact_optimise._verify(lj.Params(), 0.02, 1, 0.05, EXACT_SHAPE, True, settings, [("start", best)], [],
                                       None, {}, 0.0, types.SimpleNamespace(calls=0))  # fmt: skip
    assert found.cost_of_transport_exact == pytest.approx(opt.cost_of_transport_exact, rel=1e-7)
    rows = (2 + EXACT_TINY.local) * len(EXACT_SHAPE.origins)  # the verification's batch: its program
    coarse = _exact_optimise._verify_gaits(lj.Params(), EXACT_SHAPE, 0.05, EXACT_TINY, np.tile(best, (rows, 1)),
                                           2 * EXACT_TINY.dt)  # fmt: skip
    assert abs(float(np.asarray(coarse.cost_of_transport)[0]) / opt.cost_of_transport_exact - 1) > 1e-8


def test_the_search_steps_at_search_dt_which_the_guard_checks():
    """`ExactSettings.search_dt` is the orbit oracle's step (the screen's and the local runs'),
    `None` for `dt`; `optimise` refuses one that does not resolve the model, naming it (at
    mhat = 0.001 the natural period 0.0397 needs dt <= 0.0099)."""
    assert _exact_optimise._oracle(lj.Params(), 0.05, 1.0, EXACT_SHAPE, EXACT_TINY).dt == EXACT_TINY.dt
    assert _exact_optimise._oracle(lj.Params(), 0.05, 1.0, EXACT_SHAPE, ExactSettings(search_dt=0.015)).dt == 0.015
    stiff = lj.Params(mhat=0.001)
    _optimise._guard_search(stiff, None, EXACT_SHAPE, ExactSettings(dt=0.008, margin=0.001))
    with pytest.raises(ValueError, match=r"natural period.*\(optimise: .*ExactSettings.search_dt"):
        _optimise._guard_search(stiff, None, EXACT_SHAPE, ExactSettings(dt=0.008, search_dt=0.016, margin=0.001))
    with pytest.raises(ValueError, match=r"ExactSettings.search_dt must be None or a finite step > 0, got 0.0"):
        ExactSettings(search_dt=0.0)


def test_sqp_local_method_reaches_a_verified_optimum(exact_run, tiny_sweep):
    """`local_method="sqp"` on the same problem and compiled programs: an optimum that holds
    on the independent reference, within 1 % of the default descent's cost of transport."""
    opt_d, _ = exact_run
    before = dict(_orbit.TRACES)
    settings = eqx.tree_at(lambda s: s.local_method, EXACT_TINY, "sqp")
    opt = _optimise.optimise(lj.Params(), 0.02, 0.05, settings=settings, sweep=tiny_sweep)
    assert dict(_orbit.TRACES) == before  # no new compilation
    assert opt.feasible_exact and opt.stable_exact
    speed, cost, lifted = _reference_figures(("spline", opt.control), None, opt.omega, rho=opt.spectral_radius_exact)
    assert not lifted and speed >= 0.02
    assert opt.mean_speed_exact == pytest.approx(speed, rel=5e-4)
    assert opt.cost_of_transport_exact == pytest.approx(cost, rel=5e-4)
    assert opt.cost_of_transport_exact <= 1.01 * opt_d.cost_of_transport_exact


def test_runners_up_are_verified_where_their_run_fails_or_might_be_cheaper(exact_run, monkeypatch):
    """`_exact._verify`: the candidates first, then only the runners-up of a run whose candidate
    is not feasible or whose cost in the descent is below the cheapest feasible candidate's by
    more than `FALLBACK_RTOL`; those of the later batch get the figures they get in the first.
    Its steady gaits give up a cycling Newton solve (`PATIENCE`)."""
    opt, _ = exact_run
    patience = []
    real = _exact_optimise.paper_gait

    def spy(*args, **options):
        patience.append(options["patience"])
        return real(*args, **options)

    monkeypatch.setattr(_exact_optimise, "paper_gait", spy)
    best = np.r_[opt.control / 0.05, math.log(opt.omega)]
    slow = np.r_[best[:-1], best[-1] - math.log(2)]  # half the frequency: too slow
    c, rtol = opt.cost_of_transport_exact, _exact_optimise.FALLBACK_RTOL
    candidates = [("start", best), ("local 0", slow), ("local 1", EXACT_SHAPE.shift(best, 1 / EXACT_TINY.knots))]
    fallbacks = [
        ("local 0 runner-up 0", best, 0.99 * c, 1),  # its run failed: verified
        ("local 1 runner-up 0", np.r_[0.8 * best[:-1], best[-1]], (1 - 0.5 * rtol) * c, 2),  # not verified
        ("local 1 runner-up 1", slow, (1 - 2 * rtol) * c, 2),  # cheaper in the descent: verified
    ]
    log: dict = {}
    found, _ = _exact_optimise._verify(lj.Params(), 0.02, 1, 0.05, EXACT_SHAPE, True, EXACT_TINY, candidates, fallbacks,
                              None, log, 0.0, types.SimpleNamespace(calls=0))  # fmt: skip
    table = {row["candidate"]: row for row in found.candidates}
    assert list(table) == ["start", "local 0", "local 1", "local 0 runner-up 0", "local 1 runner-up 1"]
    assert log["unverified"] == ["local 1 runner-up 0"]
    assert table["start"]["feasible_exact"] and table["local 1"]["feasible_exact"]
    assert not table["local 0"]["feasible_exact"]
    assert table["start"]["cost_of_transport_exact"] == pytest.approx(c, rel=1e-8)
    # The second batch's rows: the figures of the same waveforms in the first.
    for again, first in (("local 0 runner-up 0", "start"), ("local 1 runner-up 1", "local 0")):
        for key in ("omega", "mean_speed_exact", "cost_of_transport_exact", "half_step_cost", "feasible_exact"):
            assert table[again][key] == pytest.approx(table[first][key], rel=1e-12), (again, key)
    cheapest = min(r["cost_of_transport_exact"] for r in table.values() if r["feasible_exact"])
    assert found.feasible_exact and found.cost_of_transport_exact == cheapest
    assert patience == [_orbit.PATIENCE] * 4  # two batches, each at dt and dt/2


def test_exact_compilations(exact_run, tiny_sweep):
    # One optimisation traces the orbit evaluation and the transient once each (every
    # start, local iteration and batch shares them); another requirement traces nothing.
    _, grew = exact_run
    assert grew == {"evaluate": 1, "relax": 1}
    settings = eqx.tree_at(lambda s: s.max_iter, EXACT_TINY, 3)
    before = dict(_orbit.TRACES)
    _optimise.optimise(lj.Params(), 0.025, 0.05, settings=settings, sweep=tiny_sweep)
    assert dict(_orbit.TRACES) == before


@pytest.mark.parametrize("method", ["SLSQP", "trust-constr"])
def test_scipy_local_methods_report_their_cheapest_point(method):
    """The exact optimiser's scipy local methods (`_exact._local_solver`) on a quadratic with a known
    minimum inside the stroke limit: they reach it, and their log holds scipy's iterations and
    every evaluation."""
    settings = eqx.tree_at(lambda s: s.local_method, EXACT_TINY, method)
    n = EXACT_SHAPE.size
    target = np.r_[np.full(n - 1, 0.1), 0.3]

    def ask(x):
        d = x - target
        return types.SimpleNamespace(f=float(d @ d), df=2 * d, c=np.ones(2), dc=np.zeros((2, n)), ok=True,
                                     cot=float(d @ d))  # fmt: skip

    bounds = scipy.optimize.Bounds(-np.inf, np.inf)
    log: list = []
    best, _ = _exact_optimise._local_solver(np.zeros(n), EXACT_SHAPE, bounds, settings, log, 100)(ask)
    np.testing.assert_allclose(best, target, atol=1e-4)
    assert log[0]["nit"] >= 1 and log[0]["evaluations"] == len(log[0]["trace"]) >= 2


def test_precompiled_verification_is_the_verifications_program():
    """`_exact.Precompile` compiles the verification's steady-gait programs on placeholders at 4
    times the step (traced): the verification's own first call at the step compiles no new
    transient program; and the direct-simulation check's over one gait period: the optimum's
    check, at another frequency and step, compiles no new simulation program. (The oracle's
    programs: `test_exact_compilations`, one trace each.)"""
    pre = _exact_optimise.Precompile(lj.Params(), 0.05, None, EXACT_SHAPE, EXACT_TINY)
    pre.wait()
    assert pre.oracle.is_set() and pre.verification.is_set() and not pre.thread.is_alive()
    programs = (_shooting._transient_batch, _paper._simulate_rows, _paper._trajectory)
    # The `jax.jit` wrappers have `_cache_size` (pyright sees the functions they wrap).
    sizes = lambda: [f._cache_size() for f in programs]  # pyright: ignore[reportFunctionMemberAccess]
    before = sizes()
    phase = np.arange(256) * 2 * np.pi / 256
    rows = (2 + EXACT_TINY.local) * len(EXACT_SHAPE.origins)  # the verification's batch (`_exact._verify`)
    theta = np.stack([EXACT_SHAPE.fit(np.sin(phase + j), 4.0) for j in range(rows)])
    gait = _exact_optimise._verify_gaits(lj.Params(), EXACT_SHAPE, 0.05, EXACT_TINY, theta, EXACT_TINY.dt)
    wave = waveform_of(EXACT_SHAPE.fields(theta[0], 0.05), 4.0, float(lj.Params().lbar))
    steady = (True, 0.02, 1.0, 0.5, 2 * np.pi / 4.0)
    sim = _exact_optimise._simulated(lj.Params(), wave, steady, dataclasses.replace(EXACT_TINY, dt=0.005), periods=2)
    assert sizes() == before
    assert np.asarray(gait.converged).any()
    assert sim["simulated_periods"] == 2 and np.isfinite(sim["mean_speed_simulated"])


def test_precompile_compiles_for_the_callers_default_device(monkeypatch):
    """`_exact.Precompile`'s thread compiles under the caller's `jax.default_device` (a per-thread
    setting: a thread of its own would compile for the process's default device, not the one the
    optimiser's own calls run on)."""
    seen = []
    record = lambda self, *args: seen.append(jax.config.jax_default_device)  # pyright: ignore[reportAttributeAccessIssue]
    monkeypatch.setattr(_exact_optimise.Precompile, "_compile", record)
    cpu = jax.devices("cpu")[0]
    with jax.default_device(cpu):
        _exact_optimise.Precompile(lj.Params(), 0.05, None, EXACT_SHAPE, EXACT_TINY).wait()
    _exact_optimise.Precompile(lj.Params(), 0.05, None, EXACT_SHAPE, EXACT_TINY).wait()
    assert seen == [cpu, None]


def test_stall_rtol_reaches_the_descent(exact_run, tiny_sweep, monkeypatch):
    """`ExactSettings.stall_rtol` is the local descent's (`_descent.local_step`), in every local run."""
    seen = []
    real = _exact_optimise.local_step

    def spy(method, *args, **options):
        seen.append((method, options["stall_rtol"]))
        return real(method, *args, **options)

    monkeypatch.setattr(_exact_optimise, "local_step", spy)
    settings = eqx.tree_at(lambda s: (s.max_iter, s.stall_rtol), EXACT_TINY, (3, 3e-6))
    _optimise.optimise(lj.Params(), 0.025, 0.05, settings=settings, sweep=tiny_sweep)
    assert seen and set(seen) == {("descent", 3e-6)}


def test_period_plot_of_a_spline_the_default_step_does_not_resolve(exact_run, tmp_path):
    """`_plots.plot_period` (the CLI's `optimize --plot`, the experiment's figures) simulates an
    optimum whose spline the default step does not resolve (the guard would refuse it) at a step
    that does."""
    opt, _ = exact_run
    fast = dataclasses.replace(opt, omega=40.0)  # knots 2*pi/(8*40) = 0.0196 apart: dt <= 0.0049
    with pytest.raises(ValueError, match="does not resolve"):
        lj.simulate(lj.Params(omega=40.0), 1.0, waveform=fast.waveform)
    path = _plots.plot_period(fast, lj.Params(), tmp_path / "period.png", periods=20)
    assert path.exists() and path.stat().st_size > 0


def test_figures_of_the_papers_optimum(exact_run):
    """`_plots.waveform_figure` and `period_figure` of the paper's model's spline optimum: its
    stroke against the reference's own B-spline, the best sinusoid dotted, and each mass moving
    over the last of 200 periods by the steady gait's mean speed times the period (a gait of one
    actuation period)."""
    opt, _ = exact_run
    phase = np.linspace(0, 2 * np.pi, 1201)
    ref = [Sig(opt.lbar, w=opt.omega, control=tuple(opt.control)).at(t)[0] - opt.lbar for t in phase / opt.omega]
    lines = _plots.waveform_figure(opt).axes[0].lines
    assert np.abs(lines[0].get_ydata() - np.array(ref)).max() < 1e-12
    assert np.abs(lines[1].get_ydata() - opt.sinusoid["a"] * np.sin(phase)).max() < 1e-15
    T = 2 * np.pi / opt.omega
    assert opt.gait_period_exact == pytest.approx(T, rel=1e-12)
    ax, _ = _plots.period_figure(opt, lj.Params(), periods=200).axes
    moved = np.array([np.asarray(line.get_ydata())[-1] for line in ax.lines])
    np.testing.assert_allclose(moved, opt.mean_speed_exact * T, rtol=1e-6)


def test_method_choice_is_checked():
    with pytest.raises(ValueError, match="method"):
        _optimise.optimise(lj.Params(), 0.02, 0.05, method="adam")
    with pytest.raises(ValueError, match="local_method must be 'descent', 'sqp', 'trust-constr' or 'SLSQP'"):
        ExactSettings(local_method="bfgs")
    with pytest.raises(ValueError, match=r"ExactSettings.stall_rtol must be in \[0, 1\), got -1e-06"):
        ExactSettings(stall_rtol=-1e-6)
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
        zero = a(np.zeros((3, 3)))
        return _orbit.Orbit(a(np.zeros(3)), a(base), a(grad), zero, a(True), a(0), a(0.0), zero)

    for speed in (0.01, 0.2):  # feasible, then short of the speed (deficit penalised)
        theta = rng.normal(size=p)
        fig = lambda th: _exact_optimise.Figures(th, orbit_at(th), speed, 1, 1, 0.05, True)
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


# Chains of N masses.

CHAIN_OPTIMISE = pytest.mark.xdist_group("chain_optimise")  # the fixtures' compilations are shared on one worker

SMALL: dict[str, Any] = dict(amplitudes=2, frequencies=4, phases=4, zoom_levels=1, zoom_points=3, local=2, transient=10)
# The screen's slowest waves take most of the steps (a period at omega_min is ~60 of the
# fastest): the frequency range starts at 0.4 instead of 0.06 of the lowest natural frequency.
SETTINGS = lj.ChainOptimiseSettings(**SMALL, max_iter=8, omega_min=0.4)
CHAIN_SPLINE = lj.ChainOptimiseSettings(**SMALL, max_iter=8, omega_min=0.4, shape="spline", knots=8)
A_MAX = 0.1


def worm(n: int = 3) -> lj.Chain:
    return lj.Chain(masses=[1.0] * n, d=0.0, friction=lj.AnisotropicCoulomb(0.5, 0.9, 0.3, 0.7))


def force_worm() -> lj.Chain:
    """The 3-mass worm driven by internal forces between its masses (an inchworm's motor)."""
    return lj.Chain(masses=[1.0] * 3, d=0.0, friction=lj.AnisotropicCoulomb(0.5, 0.9, 0.3, 0.7),
                    actuator=lj.InternalForce())  # fmt: skip


def _first(tree):
    """Row 0 of a batched result."""
    return jax.tree_util.tree_map(lambda x: x[0], tree)


@pytest.fixture(scope="module")
def opt3() -> lj.ChainOptimum:
    return lj.optimise(worm(), 0.05, A_MAX, harmonics=2, settings=SETTINGS)


@pytest.fixture(scope="module")
def infeasible() -> lj.ChainOptimum:
    quick: dict[str, Any] = SMALL | dict(zoom_levels=0, max_iter=1)
    settings = lj.ChainOptimiseSettings(**quick)
    return lj.optimise(worm(), 5.0, A_MAX, harmonics=2, settings=settings)


@CHAIN_OPTIMISE
def test_beats_its_best_travelling_wave(opt3):
    wave = opt3.travelling_wave
    assert opt3.feasible_exact and wave is not None
    assert all(opt3.constraints_exact.values())
    assert opt3.cost_of_transport_exact <= wave["cost_of_transport"] * (1 + 1e-12)
    assert opt3.improvement_vs_travelling_wave >= 0
    # The baseline is the best feasible wave the screen solved, and a candidate of the verification.
    (cand,) = [c for c in opt3.candidates if c["candidate"] == "travelling wave"]
    assert cand["cost_of_transport_exact"] == pytest.approx(wave["cost_of_transport"], rel=1e-10)
    assert opt3.mean_speed_exact >= opt3.v_min


SMOOTHED = lj.OptimiseSettings(eps_schedule=(1e-2, 3e-3), outer=2, inner=15, transient=8.0, measured=6.0)


@CHAIN_OPTIMISE
def test_smoothed_method_on_a_chain(opt3):
    """`method="smoothed"` on the same worm and screen: the local stage on the smoothed model, its
    candidates verified on their steady gaits. A feasible optimum, no costlier than its travelling
    wave, within the stroke bound, whose direct simulation and the independent reference's (from
    the relaxed springs, over whole gait periods) agree with its steady gait. On this worm it is
    cheaper than the exact method's 8 descent steps (`opt3`)."""
    settings = eqx.tree_at(lambda s: s.smoothed, SETTINGS, SMOOTHED)
    opt = lj.optimise(worm(), 0.05, A_MAX, harmonics=2, method="smoothed", settings=settings)
    print(opt.summary())
    assert [c["candidate"] for c in opt.candidates] == ["travelling wave", "smoothed 0", "smoothed 1"]
    assert opt.feasible_exact and all(opt.constraints_exact.values()) and opt.mean_speed_exact >= opt.v_min
    assert opt.cost_of_transport_exact <= opt.travelling_wave["cost_of_transport"] * (1 + 1e-12)
    assert opt.cost_of_transport_exact < opt3.cost_of_transport_exact
    assert np.all(opt.stroke_exact <= A_MAX * (1 + 1e-12))
    # d = 0: every normal force is its unit mass's weight, on the gait as on the direct simulation.
    assert opt.evaluations == 0 and opt.min_normal == pytest.approx(1.0, rel=1e-12)
    assert opt.simulation_agreement < 1e-6
    assert _worm_reference_error(opt, wave_A=opt.cos, wave_B=opt.sin) < 1e-4


@CHAIN_OPTIMISE
def test_a_force_driven_chain_against_the_reference():
    """A chain driven by internal forces (`InternalForce`): `a_max` bounds each spring's force (here
    1, above the masses' kinetic friction). A feasible
    optimum, no costlier than its travelling wave, within the force bound, whose direct simulation
    and the independent reference's, driven by the forces $f_j = s_j$ from the relaxed springs,
    agree with its steady gait."""
    opt = lj.optimise(force_worm(), 0.05, 1.0, harmonics=2, settings=SETTINGS)
    print(opt.summary())
    assert opt.feasible_exact and all(opt.constraints_exact.values()) and opt.mean_speed_exact >= opt.v_min
    assert opt.travelling_wave is not None
    assert opt.cost_of_transport_exact <= opt.travelling_wave["cost_of_transport"] * (1 + 1e-12)
    assert np.all(opt.stroke_exact <= 1.0 * (1 + 1e-12)) and "force <= 1 per spring" in opt.summary()
    assert isinstance(opt.chain.actuator, lj.InternalForce)
    assert opt.simulation_agreement < 1e-6
    assert _worm_reference_error(opt, wave_A=opt.cos, wave_B=opt.sin, actuator="force") < 1e-4


def test_the_smoothed_stage_moves_each_lanes_time_origin():
    """The smoothed stage's candidates (`_element_smoothed.decisions`): each lane's decision vector,
    decoded (`_element_local.unpack`), drives every signal as the lane's iterate does, read from
    one time origin for all its signals, the one at which the first signal's A_1 is 0. The
    decision vector leaves that coefficient out: without the move, a lane's candidate is another
    gait. The shift is found by sampling the iterate's first harmonic (as in `tests/test_shapes.py`)."""
    from locomotion_jax.optimisation import _element_smoothed

    rng = np.random.default_rng(5)
    n, S, H = 3, 2, 3
    best = dict(cos=rng.normal(size=(n, S, H)), sin=rng.normal(size=(n, S, H)), log_omega=rng.normal(size=n))
    xs = _element_smoothed.decisions(best)
    phase = np.linspace(0.0, 2 * np.pi, 361)
    fine = np.linspace(0.0, 2 * np.pi, 2_000_001)

    def signals(c: np.ndarray, s: np.ndarray, at: np.ndarray) -> np.ndarray:
        k = np.arange(1, c.shape[-1] + 1)[:, None]
        return c @ np.cos(k * at) + s @ np.sin(k * at)

    for lane, x in enumerate(xs):
        cos, sin, omega = _element_local.unpack(x, S, H)
        assert omega == pytest.approx(math.exp(best["log_omega"][lane]), rel=1e-12)
        c0, s0 = best["cos"][lane], best["sin"][lane]
        shift = fine[np.argmax(c0[0, 0] * np.cos(fine) + s0[0, 0] * np.sin(fine))] - np.pi / 2
        np.testing.assert_allclose(signals(cos, sin, phase), signals(c0, s0, phase + shift), atol=2e-4)
        assert np.abs(signals(cos, sin, phase) - signals(c0, s0, phase)).max() > 0.1


def _worm_reference_error(opt: lj.ChainOptimum, **actuation: Any) -> float:
    """The larger relative difference of the 3-mass worm optimum's mean speed and cost of
    transport from the independent reference's, driven by `actuation` (`chain_config`'s), from
    the relaxed springs over 10 gait periods after the package's settling time."""
    from reference_chain import chain_config, reference_chain_simulate

    cfg = chain_config([1.0] * 3, k=50.0, d=0.0, lbar=float(opt.lbar[0]), c=0.01, omega=opt.omega, mu_s_fwd=0.5,
                       mu_s_bwd=0.9, mu_k_fwd=0.3, mu_k_bwd=0.7, **actuation)  # fmt: skip
    n, Tg = opt.simulated_periods, opt.gait_period_exact
    ref = reference_chain_simulate(cfg, (n + 10) * Tg, np.array([n * Tg, (n + 10) * Tg]), start="relaxed")
    assert ref["status"] == "ok"
    dX, ed = np.diff(ref["X"])[0], np.diff(ref["e_d"])[0]
    err = max(abs(dX / (10 * Tg) / opt.mean_speed_exact - 1), abs(ed / abs(dX) / opt.cost_of_transport_exact - 1))
    print(f"{opt.shape} worm optimum: speed {opt.mean_speed_exact:.10f} (reference {dX / (10 * Tg):.10f}), cost "
          f"{opt.cost_of_transport_exact:.10f} (reference {ed / abs(dX):.10f}); diff {err:.1e}")  # fmt: skip
    return err


@CHAIN_OPTIMISE
def test_sqp_local_method_on_a_chain(opt3):
    """`local_method="sqp"` on the same worm and compiled programs: a feasible optimum whose direct
    simulation agrees with its steady gait, at least as cheap as its best travelling wave and
    within 2 % of the default descent's."""
    opt = lj.optimise(worm(), 0.05, A_MAX, harmonics=2, settings=eqx.tree_at(lambda s: s.local_method, SETTINGS, "sqp"))
    assert opt.feasible_exact and all(opt.constraints_exact.values())
    assert opt.cost_of_transport_exact <= opt.travelling_wave["cost_of_transport"] * (1 + 1e-12)
    assert opt.cost_of_transport_exact <= 1.02 * opt3.cost_of_transport_exact
    assert opt.simulation_agreement < 1e-6


# A 4-mass worm on bristles driven by a search-step optimum (`search_dt = 0.02`): its period-1 gait
# is stable, but a run from the relaxed springs settles on a period-3 motion instead.
TWO_ATTRACTORS = dict(
    cos=[[0.0, 0.005580194924211564, 0.0018104765503970353],
         [-8.442330971078528e-06, 0.00043484013046266316, -0.0010741909456851585],
         [0.0008198890088653098, -0.006273408287086314, 0.001972302880862292]],
    sin=[[0.014403123551934363, -0.002639619987766826, -0.001064008009380295],
         [0.016742174087284664, -0.00015955712447476996, 0.0005036983051365296],
         [0.014599579408770639, 0.0027983139441682507, -0.0009042487738005032]],
    omega=4.405695792563269,
)  # fmt: skip


def test_recurrence_is_the_shortest_period_to_the_tolerance():
    """`_element_local.recurrence`: the smallest p <= 4 with every state equal to the one p rows
    before, to `tol` relative to the largest value; 0 for none (a period of 5, or noise above tol)."""
    from locomotion_jax.optimisation._element_local import recurrence

    rng = np.random.default_rng(0)
    cycle = rng.normal(size=(5, 7))
    for p in (1, 2, 3, 4, 5):
        states = np.tile(cycle[:p], (13 // p + 1, 1))[:13]
        assert recurrence(states, 1e-12) == (p if p <= 4 else 0)
        noisy = states + 1e-7 * rng.normal(size=states.shape)
        assert recurrence(noisy, 1e-9) == 0 and recurrence(noisy, 1e-5) == (p if p <= 4 else 0)


def test_the_direct_simulation_names_a_second_attractor():
    """The optimum's direct simulation check (`_element_local.simulated`) on a gait with a second
    attractor: from the relaxed springs it settles on a period-3 motion, whose figures it reports
    averaged over whole periods of it (equal to the period-3 gait's and to the reference's) with
    recurrence 3; from the period-1 orbit's own state it stays there, recurrence 1."""
    from reference_chain import chain_config, reference_chain_simulate

    worm = lj.Chain(masses=[1.0] * 4, d=0.0, friction=lj.AnisotropicCoulomb(0.5, 0.9, 0.3, 0.7))
    w = {key: np.asarray(value) for key, value in TWO_ATTRACTORS.items()}
    chain = screen.with_actuation(worm, w["cos"][None], w["sin"][None], w["omega"][None])[0]
    settings = lj.ChainOptimiseSettings()
    exact = lj.Exact(dt=settings.dt)
    g1 = lj.steady_gait(chain, periods=1, dynamics=exact, start="relaxed")
    g3 = lj.steady_gait(chain, periods=3, dynamics=exact, start="relaxed")
    assert bool(g1.stable) and bool(g3.stable) and int(g3.k) == 3
    gait = (True, float(g1.mean_speed), float(g1.cost_of_transport), float(np.abs(g1.multipliers).max()),
            float(g1.period))  # fmt: skip
    sim = _element_local.simulated(chain, gait, settings, start="relaxed")
    assert sim["simulated_recurrence"] == 3 and sim["simulation_agreement"] > 1e-4
    assert sim["mean_speed_simulated"] == pytest.approx(float(g3.mean_speed), rel=1e-7)
    assert sim["cost_of_transport_simulated"] == pytest.approx(float(g3.cost_of_transport), rel=1e-7)
    # The reference (scipy, event-driven) from the relaxed springs over the same whole periods.
    cfg = chain_config([1.0] * 4, k=50.0, d=0.0, lbar=float(np.asarray(worm.lbar)[0]), c=0.01,
                       omega=float(w["omega"]), wave_A=w["cos"], wave_B=w["sin"], mu_s_fwd=0.5, mu_s_bwd=0.9,
                       mu_k_fwd=0.3, mu_k_bwd=0.7)  # fmt: skip
    n, T = sim["simulated_periods"], float(g1.period)
    t = np.array([n, n + _element_local.AVERAGED]) * T
    ref = reference_chain_simulate(cfg, float(t[-1]), t, start="relaxed")
    assert ref["status"] == "ok"
    # (It agrees to the engine's error at this step, 1e-5, and is far from the period-1 gait's speed.)
    speed_ref = np.diff(ref["X"])[0] / (t[1] - t[0])
    assert speed_ref == pytest.approx(sim["mean_speed_simulated"], rel=1e-4) and abs(speed_ref / gait[1] - 1) > 5e-4
    # From the period-1 orbit's state the run stays on it.
    u, v = np.split(np.asarray(g1.state, np.float64), [3])
    on_orbit = _element_local.simulated(chain, gait, settings, initial=(np.concatenate([[0.0], np.cumsum(u)]), v))
    assert on_orbit["simulated_recurrence"] == 1 and on_orbit["simulation_agreement"] < 1e-8


@CHAIN_OPTIMISE
def test_a_coarser_search_step_reports_the_figures_at_dt():
    """`search_dt = 2 dt`: the screen and the local runs step at 0.02, the verification at `dt`; the
    optimum's figures and its baseline travelling wave's are their steady gaits at `dt` (a figure
    at 0.02 differs by about 1e-6: the mutation `element_verify_at_search_dt`)."""
    coarse = dataclasses.replace(SETTINGS, search_dt=2 * SETTINGS.dt)
    assert coarse.searching().dt == 2 * SETTINGS.dt and SETTINGS.searching() is SETTINGS
    opt = lj.optimise(worm(), 0.05, A_MAX, harmonics=2, settings=coarse)
    assert opt.feasible_exact and opt.simulation_agreement < 1e-6
    w = opt.travelling_wave
    assert w is not None
    cos, sin = screen.wave_coefficients(np.array([w["a"]]), np.array([w["phi"]]), 2, 2)
    wave = screen.with_actuation(worm().broadcast(), cos, sin, np.array([w["omega"]]))[0]
    g = lj.steady_gait(lj.Chain.stack([opt.chain, wave] * (SETTINGS.chunk // 2)), transient=SETTINGS.transient,
                       dynamics=lj.Exact(dt=SETTINGS.dt), start="relaxed")  # fmt: skip
    assert bool(np.all(np.asarray(g.converged)[:2]))
    for i, (speed, cost) in enumerate([(opt.mean_speed_exact, opt.cost_of_transport_exact),
                                       (w["mean_speed"], w["cost_of_transport"])]):  # fmt: skip
        assert float(g.mean_speed[i]) == pytest.approx(speed, rel=1e-10)
        assert float(g.cost_of_transport[i]) == pytest.approx(cost, rel=1e-10)
    with pytest.raises(ValueError, match="ChainOptimiseSettings.search_dt must be None or a finite step > 0, got 0.0"):
        lj.ChainOptimiseSettings(search_dt=0.0)
    with pytest.raises(ValueError, match="MechanismOptimiseSettings.search_dt must be None or a finite step > 0"):
        lj.MechanismOptimiseSettings(search_dt=float("nan"))
    # The guard checks the search step as it does dt, and names it.
    with pytest.raises(ValueError, match=r"'omega'.*\(optimise: omega = 10000 .*ChainOptimiseSettings.search_dt"):
        lj.optimise(lj.Chain(masses=[1.0, 1.0, 1.0]), 0.01, 0.05, omega=1e4,
                    settings=lj.ChainOptimiseSettings(dt=1e-5, search_dt=0.02))  # fmt: skip


@CHAIN_OPTIMISE
def test_optimum_verifies_on_steady_gait_and_simulation(opt3):
    g = _first(lj.steady_gait(lj.Chain.stack([opt3.chain] * SETTINGS.chunk), transient=SETTINGS.transient,
                              dynamics=lj.Exact(dt=SETTINGS.dt), start="relaxed"))  # fmt: skip
    assert bool(g.converged) and bool(g.stable) and not bool(g.liftoff)
    assert float(g.mean_speed) == pytest.approx(opt3.mean_speed_exact, rel=1e-10)
    assert float(g.cost_of_transport) == pytest.approx(opt3.cost_of_transport_exact, rel=1e-10)
    assert float(g.mean_speed) >= opt3.v_min
    # Every candidate was solved at half the step too, the optimum's figures the same there to 1e-3,
    # those of its steady gait at dt/2.
    half = _first(lj.steady_gait(lj.Chain.stack([opt3.chain] * SETTINGS.chunk), transient=SETTINGS.transient,
                                 dynamics=lj.Exact(dt=SETTINGS.dt / 2), start="relaxed"))  # fmt: skip
    (won,) = [c for c in opt3.candidates if c["candidate"] == opt3.source]
    assert won["half_step_cost"] == pytest.approx(float(half.cost_of_transport), rel=1e-9)
    assert won["half_step_speed"] == pytest.approx(float(half.mean_speed), rel=1e-9)
    assert abs(won["half_step_cost"] / opt3.cost_of_transport_exact - 1) <= 1e-3
    assert all(np.isfinite(c["half_step_speed"]) for c in opt3.candidates)
    # The chain carries the reported coefficients.
    np.testing.assert_allclose(np.asarray(opt3.chain.waves.cos), opt3.cos, rtol=0, atol=0)
    assert float(opt3.chain.waves.omega) == opt3.omega
    # A direct simulation from the relaxed springs, averaged over whole gait periods.
    assert opt3.simulation_agreement < 1e-6
    n, T = opt3.simulated_periods, opt3.gait_period_exact
    t = np.array([n * T, (n + 10) * T])
    traj = lj.simulate(opt3.chain, float(t[-1]), t, start="relaxed")
    X, ed = np.asarray(traj.X), np.asarray(traj.e_d)
    assert (X[1] - X[0]) / (t[1] - t[0]) == pytest.approx(opt3.mean_speed_exact, rel=1e-6)
    assert (ed[1] - ed[0]) / abs(X[1] - X[0]) == pytest.approx(opt3.cost_of_transport_exact, rel=1e-6)
    # d = 0: the normal forces are the weights, on the gait as on the simulation.
    assert opt3.min_normal == float(np.min(traj.N)) == 1.0 >= opt3.margin


def _optimum_of(cos: np.ndarray, sin: np.ndarray, control: np.ndarray | None, omega: float) -> lj.ChainOptimum:
    """A chain optimum that holds these signals (its other fields are not read by `given_start`)."""
    opt = object.__new__(lj.ChainOptimum)
    for name, value in dict(cos=cos, sin=sin, control=control, omega=omega).items():
        object.__setattr__(opt, name, value)  # a frozen dataclass
    return opt


def test_a_given_start_is_refitted_to_the_searchs_family():
    """`_element_local.given_start`: a Fourier start moved in time so that its first signal's A_1
    is 0 (the same signals at shifted phases), padded with zero harmonics, rescaled onto the stroke
    bound, interpolated by a spline at the knots; a spline start of as many knots kept, and its
    first harmonic the B-spline's transfer function sinc^4 times that of its control values."""
    from locomotion_jax.optimisation._element_local import given_start, strokes

    cos, sin = np.array([[0.03, 0.01], [-0.02, 0.0]]), np.array([[0.04, -0.01], [0.01, 0.02]])
    st = given_start(_optimum_of(cos, sin, None, 2.0), 2, 3, 0, 0.1, 0.5, 4.0, np.ones(5))
    assert st.fresh and st.control is None and st.y.shape == (5,) and not st.y.any() and st.omega == 2.0
    assert st.cos.shape == (2, 3) and abs(st.cos[0, 0]) < 1e-15 and st.sin[0, 0] > 0
    assert np.abs(st.cos[:, 2]).max() < 1e-15 and np.abs(st.sin[:, 2]).max() < 1e-15  # the DFT's rounding
    phase = np.linspace(0, 2 * np.pi, 7, endpoint=False)
    signal = lambda c, s, ph: (
        c @ np.cos(np.outer(np.arange(1, c.shape[1] + 1), ph)) + s @ np.sin(np.outer(np.arange(1, c.shape[1] + 1), ph))
    )
    shift = math.atan2(-cos[0, 0], sin[0, 0])  # the start's phases that the new time origin reads
    np.testing.assert_allclose(signal(st.cos, st.sin, phase), signal(cos, sin, phase + shift), atol=1e-15)
    # Above the bound: rescaled onto it, signal by signal; the frequency clipped to the range.
    big = given_start(_optimum_of(10 * cos, 10 * sin, None, 9.0), 2, 2, 0, 0.1, 0.5, 4.0, np.ones(5))
    np.testing.assert_allclose(strokes(big.cos, big.sin), 0.1, rtol=1e-12)
    assert big.omega == 4.0
    # A spline search: the spline that interpolates the signals at its knots.
    sp = given_start(_optimum_of(cos, sin, None, 2.0), 2, 1, 8, 0.1, 0.5, 4.0, np.ones(5))
    assert sp.control is not None and sp.control.shape == (2, 8)
    knots = 2 * np.pi * np.arange(8) / 8
    at_knots = (np.roll(sp.control, 1, axis=1) + 4 * sp.control + np.roll(sp.control, -1, axis=1)) / 6
    np.testing.assert_allclose(at_knots, signal(cos, sin, knots), atol=1e-15)
    # A spline start: kept as it is by a search of as many knots; its Fourier series' first harmonic.
    M = 8
    control = np.stack([0.05 * np.sin(2 * np.pi * np.arange(M) / M), 0.02 * np.cos(2 * np.pi * np.arange(M) / M)])
    spline = _optimum_of(np.zeros((2, 0)), np.zeros((2, 0)), control, 2.0)
    again = given_start(spline, 2, 1, M, 0.1, 0.5, 4.0, np.ones(5))
    assert again.control is not None
    np.testing.assert_allclose(again.control, control, rtol=0, atol=1e-15)
    f = given_start(spline, 2, 2, 0, 0.1, 0.5, 4.0, np.ones(5))
    sinc4 = (math.sin(math.pi / M) / (math.pi / M)) ** 4
    # To the sampling's aliasing: harmonic 1023 of the spline folds onto 1 on 1,024 samples, (1/402)^4.
    np.testing.assert_allclose(np.hypot(f.cos[:, 0], f.sin[:, 0]), [0.05 * sinc4, 0.02 * sinc4], rtol=1e-10)
    assert np.all(np.hypot(f.cos[:, 1], f.sin[:, 1]) < 1e-15)  # harmonic 2 is absent from this spline
    with pytest.raises(ValueError, match="start: an optimum of 2 actuated signals; this search has 3"):
        given_start(spline, 3, 2, 0, 0.1, 0.5, 4.0, np.ones(5))
    # Its to_dict(), read back from JSON, is the same start.
    for opt, harmonics, knots in ((spline, 2, 0), (spline, 1, 8), (_optimum_of(cos, sin, None, 2.0), 3, 0)):
        control = None if opt.control is None else opt.control.tolist()
        fields = dict(cos=opt.cos.tolist(), sin=opt.sin.tolist(), omega=opt.omega, control=control)
        record = json.loads(json.dumps(fields))
        a, b = (given_start(x, 2, harmonics, knots, 0.1, 0.5, 4.0, np.ones(5)) for x in (opt, record))
        for x, y in zip(a, b):
            assert (x is None and y is None) or np.array_equal(np.asarray(x), np.asarray(y), equal_nan=True)  # cost NaN
    paper = dict(cos=[0.0, 0.01], sin=[0.02, 0.0], control=None, omega=2.0)
    with pytest.raises(ValueError, match="a result of the paper's model takes its own start="):
        given_start(paper, 2, 2, 0, 0.1, 0.5, 4.0, np.ones(5))
    with pytest.raises(TypeError, match="start must be the result of an earlier optimise call"):
        given_start(lj.SpringFourier(cos, sin, 2.0), 2, 2, 0, 0.1, 0.5, 4.0, np.ones(5))


@CHAIN_OPTIMISE
def test_a_given_start_is_refined_in_the_last_lane_and_is_a_candidate(opt3):
    """Continuation: `start=` an optimum at the same requirement, read back from its JSON. Its gait is
    the optimum's (a shift of the time origin changes no gait), a local run starts at it, and nothing
    costlier is reported."""
    again = lj.optimise(worm(), 0.05, A_MAX, harmonics=2, settings=SETTINGS, start=json.loads(opt3.to_json()))
    given = [c for c in again.candidates if c["candidate"] == "given start"]
    assert len(given) == 1 and given[0]["feasible_exact"]
    assert given[0]["cost_of_transport_exact"] == pytest.approx(opt3.cost_of_transport_exact, rel=1e-10)
    first = [run["trace"][0]["cot"] for run in again.history[0]["local"] if run["trace"]]
    assert any(c == pytest.approx(opt3.cost_of_transport_exact, rel=1e-9) for c in first)
    assert len(again.history[0]["starts"]) == SETTINGS.local - 1  # the screen's starts: one lane fewer
    assert again.feasible_exact and again.cost_of_transport_exact <= opt3.cost_of_transport_exact * (1 + 1e-12)


WORM_CLI = ["--masses", "1,1,1", "--d", "0", "--friction", "anisotropic", "--mu-s", "0.5", "--mu-k", "0.3",
            "--mu-s-bwd", "0.9", "--mu-k-bwd", "0.7", "--harmonics", "2"]  # fmt: skip
"""`worm()` on the command line."""


def test_cli_start_names_what_it_cannot_read(tmp_path):
    """`optimize --start FILE`: a file that is not an earlier result of the same kind of mechanism is
    refused before any work, naming --start and the file."""
    chain = tmp_path / "chain.json"
    chain.write_text(json.dumps(dict(cos=[[0.0, 0.01]], sin=[[0.02, 0.0]], control=None, omega=2.0)))
    paper = tmp_path / "paper.json"
    paper.write_text(json.dumps(dict(cos=[0.0, 0.01], sin=[0.02, 0.0], control=None, omega=2.0, lbar=3.0)))
    (tmp_path / "empty.json").write_text("{}")
    worm_args = ["optimize", *WORM_CLI, "--v-min", "0.05", "--a-max", str(A_MAX)]
    paper_args = ["optimize", "--v-min", "0.05", "--a-max", "0.05"]
    cases = [
        ([*worm_args, "--start", str(tmp_path / "missing.json")], "--start: cannot read"),
        ([*worm_args, "--start", str(tmp_path / "empty.json")], "holds no optimum"),
        ([*worm_args, "--start", str(paper)], "a result of the paper's model takes its own start="),
        ([*worm_args, "--start", str(chain)], "start: an optimum of 1 actuated signals; this search has 2"),
        ([*paper_args, "--start", str(chain)], "start: not a result of the paper's model"),
    ]
    for args, message in cases:
        res = CliRunner().invoke(_cli.app, args)
        assert res.exit_code == 2 and message in res.output and "sweeping" not in res.output, (args, res.output)


@CHAIN_OPTIMISE
@pytest.mark.slow
def test_cli_start_equals_optimise_from_the_same_start(opt3, tmp_path):
    """`optimize --start FILE --json` of opt3's JSON: the result of `lj.optimise(..., start=...)` of
    the same file and settings."""
    path = tmp_path / "opt3.json"
    path.write_text(opt3.to_json())
    fields: dict[str, Any] = SMALL | dict(zoom_levels=0, max_iter=2)
    quick = lj.ChainOptimiseSettings(**fields)
    api = lj.optimise(worm(), 0.05, A_MAX, harmonics=2, settings=quick, start=json.loads(path.read_text()))
    args = ["optimize", *WORM_CLI, "--v-min", "0.05", "--a-max", str(A_MAX), "--amplitudes", "2", "--frequencies",
            "4", "--phases", "4", "--zoom-levels", "0", "--zoom-points", "3", "--local", "2", "--max-iter", "2",
            "--transient", "10", "--start", str(path), "--json"]  # fmt: skip
    res = CliRunner().invoke(_cli.app, args)
    assert res.exit_code == 0, res.output
    record = json.loads(res.stdout)
    assert record["source"] == api.source and record["cost_of_transport_exact"] == api.cost_of_transport_exact
    assert [c["candidate"] for c in api.candidates][-1] == "given start"


@CHAIN_OPTIMISE
def test_stroke_bound_holds_exactly(opt3):
    phase = np.linspace(0, 2 * np.pi, 400_001)
    n = np.arange(1, opt3.harmonics + 1)
    s = opt3.cos @ np.cos(np.outer(n, phase)) + opt3.sin @ np.sin(np.outer(n, phase))
    assert np.max(np.abs(s)) <= A_MAX * (1 + 1e-12)
    assert np.all(opt3.stroke_exact <= A_MAX * (1 + 1e-12))
    np.testing.assert_allclose(opt3.stroke_exact, np.max(np.abs(s), axis=1), rtol=1e-9)


@CHAIN_OPTIMISE
def test_waveform_figure_draws_a_chain_optimum_of_either_family(opt3):
    """`_plots.waveform_figure` of a chain (`optimize --out`'s `waveform.png`): the Fourier signals,
    a spline optimum's signals against the reference's own B-spline formula (the optimum's fields
    replaced by a spline's), and the travelling wave $a \\sin(\\varphi - j\\phi)$ dotted."""
    phase = np.linspace(0, 2 * np.pi, 1201)
    n = np.arange(1, opt3.harmonics + 1)
    fourier = opt3.cos @ np.cos(np.outer(n, phase)) + opt3.sin @ np.sin(np.outer(n, phase))
    control = np.random.default_rng(5).uniform(-A_MAX, A_MAX, size=(2, 8))  # about the mean lbar
    spline = dataclasses.replace(opt3, shape="spline", control=control)
    ref = np.array([[Sig(lb, w=opt3.omega, control=tuple(c)).at(t)[0] - lb for t in phase / opt3.omega]
                    for c, lb in zip(control, opt3.lbar)])  # fmt: skip
    w = opt3.travelling_wave
    wave = [w["a"] * np.sin(phase - j * w["phi"]) for j in range(2)]
    for opt, signals in ((opt3, fourier), (spline, ref)):
        lines = _plots.waveform_figure(opt).axes[0].lines
        drawn = np.array([line.get_ydata() for line in lines[:2]])
        assert np.abs(drawn - signals).max() < 1e-12
        assert [line.get_label() for line in lines[:2]] == ["spring 0", "spring 1"]
        assert np.abs(np.array([line.get_ydata() for line in lines[2:4]]) - wave).max() < 1e-12


@CHAIN_OPTIMISE
def test_period_figure_of_a_chain_optimum_moves_at_its_gaits_speed(opt3, tmp_path):
    """`_plots.period_figure` of a chain optimum (`optimize --out`'s `period.png`): after 200
    actuation periods from the relaxed springs each mass moves over the last one by the steady
    gait's mean speed times the period (the gait's period is one actuation period), and the
    stuck rows are the simulation's; `params` is refused, the paper's model requires it."""
    T = 2 * np.pi / opt3.omega
    assert opt3.gait_period_exact == pytest.approx(T, rel=1e-12)
    fig = _plots.period_figure(opt3, None, periods=200)
    ax, axs = fig.axes
    moved = np.array([np.asarray(line.get_ydata())[-1] for line in ax.lines])
    assert moved.shape == (3,)
    np.testing.assert_allclose(moved, opt3.mean_speed_exact * T, rtol=1e-6)
    tr = lj.simulate(opt3.chain, 200 * T, np.linspace(199 * T, 200 * T, 600), start="relaxed", contact="strict")
    stuck = np.array([np.asarray(line.get_ydata()) for line in axs.lines])
    assert np.array_equal(stuck, np.arange(3)[:, None] + 0.8 * np.asarray(tr.stuck).T)
    # Within its transient the run is the one from the relaxed springs (the optimiser's start).
    ax, _ = _plots.period_figure(opt3, None, periods=2).axes
    tr = lj.simulate(opt3.chain, 2 * T, np.linspace(T, 2 * T, 600), start="relaxed", contact="strict")
    x = np.asarray(tr.x)
    np.testing.assert_allclose(np.array([line.get_ydata() for line in ax.lines]), (x - x[0]).T, rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="params"):
        opt3.driven(lj.Params())
    with pytest.raises(ValueError, match="params"):
        _plots.plot_period(_fields_of(lj.Optimum, control=None, omega=2.0), None, tmp_path / "p.png")


def _fields_of(kind: type, **fields: Any) -> Any:
    """An optimum of class `kind` that holds these fields only (a test reads no others)."""
    opt = object.__new__(kind)
    for name, value in fields.items():
        object.__setattr__(opt, name, value)  # a frozen dataclass
    return opt


def test_figures_of_a_mechanism_optimum():
    """`_plots.waveform_figure` and `period_figure` of a mechanism's optimum: the capsule's force
    $0.6 \\sin 3t$ as its one signal, the best sinusoid $a \\sin(\\varphi + \\varphi_0)$ dotted, and
    the bodies' displacements over the last period of a run from the mechanism's own start."""
    phase = np.linspace(0, 2 * np.pi, 1201)
    sinusoid = dict(a=0.4, omega=2.0, phase=1.0, mean_speed=-0.01, cost_of_transport=2.0)
    opt = _fields_of(lj.MechanismOptimum, cos=np.zeros((1, 1)), sin=np.full((1, 1), 0.6), control=None, omega=3.0,
                     harmonics=1, elements=[2], sinusoid=sinusoid, mechanism=_capsule(), a_max=0.8, v_min=0.005,
                     mean_speed_exact=-0.01, cost_of_transport_exact=1.0)  # fmt: skip
    lines = _plots.waveform_figure(opt).axes[0].lines
    assert (
        lines[0].get_label() == "optimised"
        and np.abs(np.asarray(lines[0].get_ydata()) - 0.6 * np.sin(phase)).max() < 1e-12
    )
    assert np.abs(np.asarray(lines[1].get_ydata()) - 0.4 * np.sin(phase + 1.0)).max() < 1e-15
    T = 2 * np.pi / 3.0
    ax, axs = _plots.period_figure(opt, None, periods=10).axes
    tr = lj.simulate(_capsule(), 10 * T, np.linspace(9 * T, 10 * T, 600), contact="strict")
    x = np.asarray(tr.x)
    np.testing.assert_allclose(np.array([line.get_ydata() for line in ax.lines]), (x - x[0]).T, rtol=0, atol=1e-12)
    assert np.array_equal(
        np.array([line.get_ydata() for line in axs.lines]), np.arange(2)[:, None] + 0.8 * np.asarray(tr.stuck).T
    )


@CHAIN_OPTIMISE
def test_cli_out_writes_the_optimum_and_its_figures_for_a_chain(opt3, tmp_path, monkeypatch):
    """`optimize --out DIR` of a chain: `optimum.json` (the whole result, which `--start` reads
    back), `waveform.png`, `period.png` and `pareto.png` (its screen)."""
    monkeypatch.setattr(lj, "optimise", lambda *args, **kwargs: opt3)
    args = ["optimize", "--masses", "1,1,1", "--d", "0", "--v-min", "0.05", "--a-max", "0.1", "--out", str(tmp_path)]
    res = CliRunner().invoke(_cli.app, args)
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["optimum.json", "pareto.png", "period.png", "waveform.png"]
    saved = json.loads((tmp_path / "optimum.json").read_text())
    assert saved["cost_of_transport_exact"] == opt3.cost_of_transport_exact and len(saved["candidates"]) > 0
    assert _cli_optimise._start(tmp_path / "optimum.json") == saved


@CHAIN_OPTIMISE
def test_the_chain_optimum_keeps_its_screen_and_draws_it(opt3, tmp_path):
    """`ChainOptimum.screen`: every travelling wave of the screen and its zoom (`screened` of them),
    of which the baseline is the cheapest that meets the requirement; `to_dict(full=True)` alone
    carries it. `_plots.plot_screen` draws the feasible waves' cost against their speed, their
    Pareto front (a wave no other is both faster and cheaper than) and the optimum."""
    sc, w = opt3.screen, opt3.travelling_wave
    assert w is not None and all(len(sc[k]) == opt3.screened for k in ("a", "omega", "phi", "speed", "cost", "ok"))
    fast = sc["ok"] & (sc["speed"] >= opt3.v_min)
    i = int(np.argmin(np.where(fast, sc["cost"], np.inf)))
    assert (sc["a"][i], sc["omega"][i], sc["phi"][i], sc["cost"][i]) == (
        w["a"],
        w["omega"],
        w["phi"],
        w["cost_of_transport"],
    )
    assert "screen" not in opt3.to_dict() and len(opt3.to_dict(full=True)["screen"]["speed"]) == opt3.screened
    path = _plots.plot_screen(opt3, tmp_path / "pareto.png")
    assert path is not None and path.stat().st_size > 0
    ax = _plots.pareto_figure(sc["speed"], sc["cost"], sc["ok"], [opt3], labels=("w", "f", "t")).axes[0]
    front, star = (np.asarray(line.get_xydata()) for line in ax.lines[:2])
    good = sc["ok"] & (sc["speed"] > 0) & np.isfinite(sc["cost"])
    v, c = sc["speed"][good], sc["cost"][good]
    dominated = [(v > vj) & (c <= cj) for vj, cj in zip(v, c)]  # a faster wave that is no costlier
    # Waves of equal figures (a zoom point on the coarse grid's, solved alike) are one point of the front.
    expected = np.unique([(vj, cj) for vj, cj, d in zip(v, c, dominated) if not d.any()], axis=0)
    np.testing.assert_array_equal(front[np.argsort(front[:, 0])], expected)
    assert np.array_equal(star, [[opt3.mean_speed_exact, opt3.cost_of_transport_exact]])
    # The drawn figure's cost axis ends at 10 times the dearest point of the front and the optimum.
    fig = _plots.screen_figure(opt3)
    assert fig is not None and fig.axes[0].get_ylim()[1] == pytest.approx(10 * max(*expected[:, 1], star[0, 1]))


@CHAIN_OPTIMISE
def test_a_chain_takes_an_earlier_screen(opt3, monkeypatch):
    """`sweep=` an earlier optimum's screen, read back from its JSON (NaN as null): the waves are not
    solved again (the screen's function would fail the test), and the same requirement finds the
    same optimum, bitwise, with the same screen."""
    record = json.loads(opt3.to_json(full=True))["screen"]
    monkeypatch.setattr(screen, "screen", lambda *args, **kwargs: pytest.fail("screened again"))
    again = lj.optimise(worm(), 0.05, A_MAX, harmonics=2, settings=SETTINGS, sweep=record)
    assert again.cost_of_transport_exact == opt3.cost_of_transport_exact and again.source == opt3.source
    assert again.travelling_wave == opt3.travelling_wave and np.array_equal(again.cos, opt3.cos)
    assert again.screen.keys() == opt3.screen.keys()
    for key, value in opt3.screen.items():
        np.testing.assert_array_equal(again.screen[key], value)


@CHAIN_OPTIMISE
def test_cli_reuses_an_earlier_screen(opt3, tmp_path, monkeypatch):
    """`optimize --reuse-screen FILE`: the screen in an earlier `--out`'s `optimum.json` goes to
    `optimise`'s `sweep=`; a file without one, and the paper's model, are refused naming the option."""
    (tmp_path / "optimum.json").write_text(opt3.to_json(full=True))
    (tmp_path / "bare.json").write_text(opt3.to_json())
    seen: dict[str, Any] = {}
    monkeypatch.setattr(lj, "optimise", lambda *args, **kwargs: seen.update(kwargs) or opt3)
    worm_args = ["optimize", "--masses", "1,1,1", "--d", "0", "--v-min", "0.06", "--a-max", "0.1", "--reuse-screen"]
    res = CliRunner().invoke(_cli.app, [*worm_args, str(tmp_path / "optimum.json")])
    assert res.exit_code == 0, res.output
    assert seen["sweep"] == json.loads(opt3.to_json(full=True))["screen"]
    res = CliRunner().invoke(_cli.app, [*worm_args, str(tmp_path / "bare.json")])
    assert res.exit_code == 2 and "--reuse-screen: " in res.output and "holds no screen" in res.output
    # The paper's model: a chain's screen is no sinusoid sweep.
    paper = ["optimize", "--v-min", "0.05", "--a-max", "0.05", "--reuse-screen", str(tmp_path / "optimum.json")]
    res = CliRunner().invoke(_cli.app, paper)
    assert res.exit_code == 2 and "--reuse-screen: " in res.output and "sinusoid_sweep" in res.output


@CHAIN_OPTIMISE
def test_a_given_screen_is_checked_and_kept_within_the_bound(opt3):
    """`_chain_screen.from_record`: the waves above `a_max` or outside the frequency range are left
    out; a record that is not a chain optimum's screen, or of another chain, is refused naming `sweep`."""
    sc, n = opt3.screen, len(opt3.screen["a"])
    lo, hi = float(np.min(sc["omega"])), float(np.max(sc["omega"]))
    kept = screen.from_record(sc, 5, A_MAX / 2, lo, hi)
    assert len(kept.a) == int(np.sum(sc["a"] <= A_MAX / 2 * (1 + 1e-12))) and 0 < len(kept.a) < n
    assert np.all(kept.a <= A_MAX / 2 * (1 + 1e-12)) and kept.gaits.y.shape == (len(kept.a), 5)
    w = float(np.median(sc["omega"]))
    assert np.all(screen.from_record(sc, 5, A_MAX, lo, w).omega <= w * (1 + 1e-12))
    with pytest.raises(ValueError, match="sweep: an earlier chain optimum's screen"):
        screen.from_record({k: v for k, v in sc.items() if k != "y"}, 5, A_MAX, lo, hi)
    with pytest.raises(ValueError, match=r"sweep: .* y 7 numbers per row \(a chain of 4 masses\)"):
        screen.from_record(sc, 7, A_MAX, lo, hi)
    with pytest.raises(ValueError, match="sweep: no wave of the screen has a <= a_max"):
        screen.from_record(sc, 5, A_MAX / 1e3, lo, hi)
    with pytest.raises(TypeError, match="sweep: the paper's model takes a sinusoid_sweep"):
        lj.optimise(lj.Params(), 0.05, 0.05, sweep=sc)  # a chain's screen: no sinusoid sweep


@CHAIN_OPTIMISE
def test_the_chain_optimiser_refines_an_idealised_inchworm_where_no_wave_is_fast_enough():
    """The paper's model as a two-mass chain, v_min = a_max = 0.05, at one of the idealised
    inchworms' frequencies (fixed): the best travelling wave there moves at a third of v_min,
    while the inchworm whose tension alternates in sign (splines of 64 knots, as the paper's
    optimiser's) is feasible near the quasi-static floor as it is (the paper's optimum at a
    free frequency: 0.9241). The search steps at dt = 0.01, where the knots lie 2.6 steps
    apart; the verification at the step the resolution guard asks for (4 steps per knot)."""
    chain = lj.Chain.from_params(lj.Params())
    period = 2 * math.pi / float(chain.omega_min) * float(np.geomspace(0.7, 4.0, 10)[5])
    settings = lj.ChainOptimiseSettings(shape="spline", knots=64, amplitudes=2, phases=1, zoom_levels=0, local=1,
                                        max_iter=4, transient=20)  # fmt: skip
    opt = lj.optimise(chain, 0.05, 0.05, omega=2 * math.pi / period, settings=settings)
    (start,) = opt.history[0]["starts"]
    assert start["inchworm"]["period"] == pytest.approx(period) and start["inchworm"]["level"] == 0.3
    assert 0.05 < start["mean_speed"] and start["cost_of_transport"] < 0.93
    assert opt.dt_exact == 0.0063  # 2 pi / (64 omega) / 4 = 0.0064, rounded down
    wave = next(c for c in opt.candidates if c["candidate"] == "travelling wave")
    assert not wave["feasible_exact"] and wave["mean_speed_exact"] < 0.02 and wave["cost_of_transport_exact"] > 4
    assert opt.feasible_exact and opt.source == "local 0" and opt.mean_speed_exact >= 0.05
    assert 0.9241 < opt.cost_of_transport_exact < 0.93
    assert opt.simulation_agreement < 1e-6 and opt.simulated_recurrence == 1
    # The same gait at the verification's step, solved here: the search's step was not resolved.
    g = lj.steady_gait(opt.chain, periods=(1, 2), transient=20, dynamics=lj.Exact(dt=0.0063))
    assert float(g.cost_of_transport) == pytest.approx(opt.cost_of_transport_exact, rel=1e-9)
    with pytest.raises(ValueError, match=r"K = 64"):
        lj.steady_gait(opt.chain, dynamics=lj.Exact(dt=0.01))


def test_the_mechanism_optimiser_refines_an_idealised_inchworm_where_no_sinusoid_is_fast_enough():
    """The chain test above with the paper's model built as a `Mechanism` (two bodies, one tilted
    spring with an actuated rest length, the paper's damping): at the same inchworm's frequency
    the best sinusoid moves at a third of v_min, and the inchworm whose tension alternates in sign
    (`_starts.mechanism_tension_waves`, 64 knots), which beats it, takes the local lane and is
    feasible near the quasi-static floor, as on the chain (measured: 0.924421 from a start of
    0.924424; without the inchworms the search ends infeasible, 1.8066 at speed 0.0474)."""
    chain = lj.Chain.from_params(lj.Params()).broadcast()
    k, d, lbar = float(chain.k[0]), float(chain.d[0]), float(chain.lbar[0])
    rest = lj.Sinusoid(a=0.01, omega=1.0, lbar=lbar)
    spring, x0 = lj.TiltedSpring(0, 1, k=k, d=d, rest=rest), [0.0, math.sqrt(lbar**2 - d**2)]
    mech = lj.Mechanism(
        masses=np.asarray(chain.m), friction=chain.friction, c=np.asarray(chain.c), links=[spring], x0=x0
    )
    period = 2 * math.pi / float(chain.omega_min) * float(np.geomspace(0.7, 4.0, 10)[5])
    settings = lj.MechanismOptimiseSettings(shape="spline", knots=64, amplitudes=2, local=1, max_iter=4,
                                            transient=20, tension_levels=(0.3,))  # fmt: skip
    opt = lj.optimise(mech, 0.05, 0.05, omega=2 * math.pi / period, settings=settings)
    (start,) = opt.history[0]["starts"]
    assert start["inchworm"]["period"] == pytest.approx(period) and start["inchworm"]["level"] == 0.3
    assert 0.05 < start["mean_speed"] and start["cost_of_transport"] < 0.93
    sinusoid = next(c for c in opt.candidates if c["candidate"] == "sinusoid")
    assert not sinusoid["feasible_exact"] and sinusoid["mean_speed_exact"] < 0.02
    assert opt.feasible_exact and opt.source == "local 0" and opt.mean_speed_exact >= 0.05
    assert 0.9241 < opt.cost_of_transport_exact < 0.93 and opt.dt_exact == 0.0063
    assert opt.simulation_agreement < 1e-6 and opt.simulated_recurrence == 1


def test_inchworm_starts_by_default_in_a_spline_search_of_rest_lengths_only():
    # None where nothing is solved: a Fourier search by default, 0 periods, an internal force.
    chain = lj.Chain.from_params(lj.Params())
    none = lambda settings, knots, c=chain: screen.inchworms(c, 0.0, 0.05, 2.0, 12.0, 3, knots, settings)
    assert none(lj.ChainOptimiseSettings(), 0) is None
    assert none(lj.ChainOptimiseSettings(shape="spline", tension_periods=0), 16) is None
    forced = lj.Chain(masses=[1.0, 1.0], actuator=lj.InternalForce())
    assert none(lj.ChainOptimiseSettings(shape="spline"), 16, forced) is None
    with pytest.raises(ValueError, match="ChainOptimiseSettings.tension_periods must be an int >= 0"):
        lj.ChainOptimiseSettings(tension_periods=-1)
    with pytest.raises(ValueError, match=r"ChainOptimiseSettings.tension_levels must lie within \[0, 1\]"):
        lj.ChainOptimiseSettings(tension_levels=(0.5, 1.2))


def test_a_mechanisms_inchworm_starts_by_default_in_a_spline_search_of_two_ended_elements_only():
    # None where nothing is solved: a Fourier search by default, 0 periods, an external force, no
    # mode with a body held (one body on a spring to the wall). The settings are checked by name.
    from locomotion_jax.optimisation._mechanism import _inchworms

    spring = lj.Spring(0, 1, k=10.0, rest=lj.Sinusoid(a=0.01, omega=1.0, lbar=1.0))
    pair = lj.Mechanism(masses=[1.0, 1.0], links=[spring], x0=[0.0, 1.0])
    state = np.zeros(3)
    none = lambda settings, knots, m=pair: _inchworms(m, 0.0, 0.05, 2.0, 12.0, 3, knots, state, settings, print)
    assert none(lj.MechanismOptimiseSettings(), 0) is None
    assert none(lj.MechanismOptimiseSettings(shape="spline", tension_periods=0), 16) is None
    links = [lj.Spring(0, 1, k=10.0, rest=1.0), lj.ExternalForce(0, lj.Sinusoid(0.1, 2.0, 0.0))]
    pushed = lj.Mechanism(masses=[1.0, 1.0], links=links, x0=[0.0, 1.0])
    assert none(lj.MechanismOptimiseSettings(shape="spline", tension_periods=2), 16, pushed) is None
    anchored = lj.Mechanism(masses=[1.0], links=[lj.Spring(0, lj.WALL, k=5.0, rest=lj.Sinusoid(0.1, 2.0, -1.0))],
                            x0=[1.0])  # fmt: skip
    assert none(lj.MechanismOptimiseSettings(shape="spline"), 16, anchored) is None
    with pytest.raises(ValueError, match="MechanismOptimiseSettings.tension_periods must be an int >= 0"):
        lj.MechanismOptimiseSettings(tension_periods=-1)
    with pytest.raises(ValueError, match=r"MechanismOptimiseSettings.tension_levels must lie within \[0, 1\]"):
        lj.MechanismOptimiseSettings(tension_levels=(0.5, 1.2))


def test_screen_ranks_feasible_gaits_by_cost_then_stable_ones_by_speed():
    # Rows: stable but slow, feasible and dear, not stable, stable and fast, feasible and cheap,
    # feasible at the same cost as the cheap one (a time shift of it), stable backwards.
    n = 7
    speed = np.array([0.01, 0.5, 0.9, 0.3, 0.45, 0.45, -0.6])
    cost = np.array([1.0, 3.0, 0.1, 2.0, 1.2, 1.2 * (1 + 1e-12), 1.5])
    ok = np.array([True, True, False, True, True, True, True])
    nan = np.full(n, np.nan)
    g = screen.Gaits(speed, cost, ok, ~ok, np.ones(n, np.int32), nan, nan, nan, np.zeros((n, 3)))
    assert list(screen.rank(g, 0.4, 1)) == [4, 5, 1, 3, 0, 6, 2]
    assert list(screen.rank(g, 0.4, -1)) == [6, 0, 3, 4, 5, 1, 2]  # backwards: 6 feasible, then by backward speed
    keys = screen.preference(g, 0.4, 1)
    assert screen.best_distinct(keys, 3) == [4, 1, 3]  # one of the two equal gaits
    assert screen.best_distinct(keys[[2]], 2) == [0, 0]  # none stable: the first, repeated
    assert list(np.flatnonzero(screen.preferred(keys, keys[1]))) == [4, 5]  # the cheaper feasible ones
    assert list(np.flatnonzero(screen.preferred(keys, keys[3]))) == [1, 4, 5]  # and none of the slower
    assert not screen.preferred(keys, keys[4]).any()


@CHAIN_OPTIMISE
def test_screen_filter_keeps_the_fast_waves():
    v = np.array([0.3, np.nan, -0.4, 0.05, 0.2, 0.01])
    assert list(screen.fast_enough(v, 0.4, 1, 0.5, 2)) == [0, 4]  # 0.2 reaches half of 0.4; 0.3, 0.2 fastest
    assert list(screen.fast_enough(v, 0.4, 1, 0.5, 3)) == [0, 3, 4]
    assert list(screen.fast_enough(v, 0.4, -1, 0.5, 1)) == [2]  # backwards; NaN never
    assert list(screen.fast_enough(v, 10.0, -1, 0.5, 1)) == [2]  # none fast enough: the fastest backwards, not NaN
    assert list(screen.fast_enough(v, 10.0, 1, 0.5, 0)) == []


@CHAIN_OPTIMISE
def test_screen_solves_the_fast_waves_as_it_would_without_the_filter(opt3):
    """The screen with its filter (`screen_speed`): on 40 waves (two chunks), the waves it leaves
    unsolved are the slowest at the end of their transient; every wave it solves has the gait the
    unfiltered screen finds for it; and no wave whose gait meets the requirement is left out."""
    base = worm().broadcast()
    lo, hi = screen.frequency_range(base, None, SETTINGS)
    amps, omegas, phases = A_MAX * np.array([0.5, 1.0]), np.geomspace(lo, hi, 5), np.pi * np.array([-1, -0.5, 0, 0.5])
    A, W, F = (x.ravel() for x in np.meshgrid(amps, omegas, phases, indexing="ij"))
    cos, sin = screen.wave_coefficients(A, F, 2, 2)
    every = screen.solve(base, cos, sin, W, SETTINGS)
    assert np.sum(every.ok) >= 20
    v_min = 0.9 * np.nanmax(np.where(every.ok, every.speed, np.nan))
    got = screen.solve(base, cos, sin, W, SETTINGS, need=(v_min, 1))
    solved = np.isfinite(got.speed) | np.isfinite(got.y[:, 0])
    assert SETTINGS.chunk <= np.sum(solved) < 40  # some left out: 40 waves, the 32 fastest kept
    for a, b in zip(got, every):
        np.testing.assert_allclose(a[solved], b[solved], rtol=1e-12, atol=0)
    assert not np.any(got.ok[~solved]) and np.all(np.isnan(got.speed[~solved]))
    assert np.all(solved[screen.feasible(every, v_min, 1)])


@CHAIN_OPTIMISE
@pytest.mark.slow
def test_infeasible_requirement_is_flagged(infeasible):
    assert not infeasible.feasible_exact
    assert not infeasible.constraints_exact["speed"]
    assert infeasible.travelling_wave is None and math.isnan(infeasible.improvement_vs_travelling_wave)
    record = json.loads(infeasible.to_json())
    assert record["feasible_exact"] is False and record["improvement_vs_travelling_wave"] is None
    assert "INFEASIBLE" in infeasible.summary()


@CHAIN_OPTIMISE
@pytest.mark.slow
def test_one_compilation_serves_every_evaluation(opt3, infeasible):
    """Both optimisations (other requirements, other iterates, the fallbacks) share one compiled oracle."""
    assert _element_orbit.TRACES["evaluate"] == 1 and _element_orbit.TRACES["relax"] <= 1


@CHAIN_OPTIMISE
@pytest.mark.slow
def test_cli_chain_optimize_json_equals_optimise(infeasible):
    args = ["chain-optimize", "--masses", "1,1,1", "--d", "0", "--friction", "anisotropic", "--mu-s", "0.5",
            "--mu-k", "0.3", "--mu-s-bwd", "0.9", "--mu-k-bwd", "0.7", "--v-min", "5", "--a-max", str(A_MAX),
            "--harmonics", "2", "--amplitudes", "2", "--frequencies", "4", "--phases", "4", "--zoom-levels", "0",
            "--zoom-points", "3", "--local", "2", "--max-iter", "1", "--transient", "10", "--json"]  # fmt: skip
    res = CliRunner().invoke(_cli.app, args)
    assert res.exit_code == 0, res.output
    record = json.loads(res.stdout)
    assert record["feasible_exact"] is False and record["n_masses"] == 3
    assert record["mean_speed_exact"] == pytest.approx(infeasible.mean_speed_exact, rel=1e-12)
    bad = CliRunner().invoke(_cli.app, ["chain-optimize", "--masses", "1,1,1", "--v-min", "0", "--a-max", "0.05"])
    assert bad.exit_code == 2 and "Error: v_min must be a finite speed > 0" in bad.output
    bad = CliRunner().invoke(_cli.app, ["chain-optimize", "--masses", "1,1,1", "--v-min", "0.1", "--a-max", "3"])
    assert bad.exit_code == 2 and "0 < a_max < min(lbar) = 3" in bad.output


@CHAIN_OPTIMISE
@pytest.mark.slow
def test_two_masses_agree_with_the_two_mass_model():
    """N = 2 built from the paper's Params: the optimum's steady gait under the two-mass model
    (its one spring's coefficients as a Fourier waveform) has the same cost of transport."""
    settings = lj.ChainOptimiseSettings(**SMALL, max_iter=6)
    opt = lj.optimise(lj.Chain.from_params(lj.Params()), 0.02, 0.05, harmonics=2, settings=settings)
    assert opt.feasible_exact
    wave = lj.Fourier(jnp.asarray(opt.cos[0]), jnp.asarray(opt.sin[0]), opt.omega, 3.0)
    g = lj.steady_gait(lj.Params(omega=opt.omega), waveform=wave, start="relaxed", transient=settings.transient,
                       dynamics=lj.Exact(dt=settings.dt))  # fmt: skip
    assert float(g.cost_of_transport) == pytest.approx(opt.cost_of_transport_exact, rel=1e-8)
    assert float(g.mean_speed) == pytest.approx(opt.mean_speed_exact, rel=1e-8)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(v_min=0.0), "v_min must be a finite speed > 0"),
        (dict(v_min=-0.1), "v_min must be a finite speed > 0"),
        (dict(v_min=math.nan), "v_min must be a finite speed > 0"),
        (dict(a_max=0.0), "0 < a_max < min(lbar) = 3"),
        (dict(a_max=3.0), "0 < a_max < min(lbar) = 3"),
        (dict(direction=2), "direction must be +1"),
        (dict(harmonics=0), "harmonics must be an integer >= 1"),
        (dict(omega=-1.0), "omega must be a finite number > 0"),
        (dict(method="adam"), "method must be 'exact' or 'smoothed', got 'adam'"),
        (dict(method="smoothed", settings=CHAIN_SPLINE), "method='smoothed' refines Fourier series"),
        (dict(chain=lj.Chain(masses=[1.0, 1.0, 1.0], d=0.5), a_max=0.07), "lifts a mass off at rest"),
        (dict(chain=lj.Chain.stack([worm(), worm()])), "single configuration"),
        (dict(chain=force_worm(), a_max=math.inf), "0 < a_max < inf (a force bound)"),
        (dict(start=_optimum_of(np.zeros((1, 2)), np.zeros((1, 2)), None, 1.0)), "start: an optimum of 1 actuated"),
    ],
)
@CHAIN_OPTIMISE
def test_bad_input_raises(kwargs, message):
    args = dict(chain=worm(), v_min=0.05, a_max=0.05) | kwargs
    chain, v_min, a_max = args.pop("chain"), args.pop("v_min"), args.pop("a_max")
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)").replace("+", r"\+")):
        lj.optimise(chain, v_min, a_max, **args)


def test_a_force_bound_is_not_a_stroke():
    """Under `InternalForce` the bound is a force's: not limited by `lbar`, and a force leaves the
    rest lengths, so the quasi-static lift-off check of a stroke (the chain with `d = 0.5` that
    `test_bad_input_raises` refuses at `a_max = 0.07`) does not apply."""
    from locomotion_jax.optimisation import _chain

    settings = lj.ChainOptimiseSettings()
    tilted = lj.Chain(masses=[1.0, 1.0, 1.0], d=0.5, actuator=lj.InternalForce())
    assert _chain.check_inputs(tilted, 0.05, 0.07, 1, 2, None, settings) == (0.05, 1)
    assert _chain.check_inputs(force_worm(), 0.05, 5.0, -1, 2, None, settings) == (0.05, -1)
    with pytest.raises(ValueError, match="lifts a mass off at rest"):
        _chain.check_inputs(lj.Chain(masses=[1.0, 1.0, 1.0], d=0.5), 0.05, 0.07, 1, 2, None, settings)


@CHAIN_OPTIMISE
@pytest.mark.slow
def test_chain_spline_optimum_against_the_reference():
    """A chain's springs driven by periodic splines (`ChainOptimiseSettings(shape="spline")`): the
    optimum beats its travelling wave, keeps the box bound, carries its control values, and its
    steady gait's speed and cost of transport agree with the independent reference's direct
    simulation (its own B-spline actuation) from the relaxed springs, over whole gait periods."""
    opt = lj.optimise(worm(), 0.05, A_MAX, settings=CHAIN_SPLINE)
    print({k: v for k, v in opt.to_dict().items() if k not in ("candidates", "history")}, opt.candidates)
    assert opt.shape == "spline" and opt.harmonics == 0 and opt.cos.shape == (2, 0)
    assert opt.control is not None and opt.control.shape == (2, 8) and opt.source.startswith("local")
    assert opt.feasible_exact and all(opt.constraints_exact.values()) and opt.mean_speed_exact >= opt.v_min
    assert opt.travelling_wave is not None and opt.improvement_vs_travelling_wave > 0
    assert np.abs(opt.control).max() <= A_MAX and np.all(opt.stroke_exact <= A_MAX * (1 + 1e-12))
    waves = opt.waveforms
    assert isinstance(waves, list) and all(isinstance(w, lj.Spline) for w in waves)
    assert opt.chain.signals is not None
    for w, got, row in zip(waves, opt.chain.signals, opt.control):
        assert isinstance(got, lj.Spline) and np.array_equal(np.asarray(got.control), row)
        assert float(got.omega) == opt.omega and np.array_equal(np.asarray(w.control), row)
    # The exact stroke against a dense sampling of each spring's signal.
    T = 2 * np.pi / opt.omega
    t = jnp.linspace(0.0, T, 40001)
    dense = np.array([float(np.abs(np.asarray(w(t)[0]) - float(w.lbar)).max()) for w in opt.chain.signals])
    assert np.all(dense <= opt.stroke_exact + 1e-12) and np.all(opt.stroke_exact - dense < 1e-6)
    assert opt.min_normal == 1.0 >= opt.margin and opt.simulation_agreement < 1e-6  # d = 0: the weights
    assert _worm_reference_error(opt, spline=opt.control) < 1e-4


@CHAIN_OPTIMISE
def test_chain_spline_search_refuses_harmonics():
    with pytest.raises(ValueError, match="harmonics applies to Fourier series"):
        lj.optimise(worm(), 0.05, A_MAX, harmonics=2, settings=CHAIN_SPLINE)
    with pytest.raises(ValueError, match="shape must be 'fourier' or 'spline'"):
        lj.ChainOptimiseSettings(shape="wave")
    with pytest.raises(ValueError, match="knots must be an int >= 4"):
        lj.ChainOptimiseSettings(knots=3)
    # The command line passes --shape and --knots to a chain's settings.
    args = ["optimize", "--masses", "1,1,1", "--v-min", "0.05", "--a-max", "0.1", "--shape", "spline", "--knots", "8",
            "--harmonics", "2"]  # fmt: skip
    bad = CliRunner().invoke(_cli.app, args)
    assert bad.exit_code == 2 and "harmonics applies to Fourier series" in bad.output
    bad = CliRunner().invoke(_cli.app, args[:-2] + ["--knots", "3"])
    assert bad.exit_code == 2 and "knots must be an int >= 4" in bad.output


@CHAIN_OPTIMISE
def test_bad_settings_raise():
    with pytest.raises(ValueError, match="local must be an int >= 1"):
        lj.ChainOptimiseSettings(local=0)
    # The checks the chain's settings share with the mechanism's (MechanismOptimiseSettings.__check_init__).
    cases: list[tuple[dict[str, Any], str]] = [
        (dict(transient=0), "ChainOptimiseSettings.transient must be an int >= 1, got 0"),
        (dict(local=True), "ChainOptimiseSettings.local must be an int >= 1, got True"),
        (dict(margin=-0.1), "ChainOptimiseSettings: margin and speed_slack must be >= 0"),
        (dict(zoom_levels=False), "zoom_levels must be an int >= 0"),
        (dict(local_method="newton"), "ChainOptimiseSettings.local_method must be 'descent' or 'sqp', got 'newton'"),
        (dict(stall_rtol=1.0), r"ChainOptimiseSettings.stall_rtol must be in \[0, 1\), got 1.0"),
    ]
    for bad, match in cases:
        with pytest.raises(ValueError, match=match):
            lj.ChainOptimiseSettings(**bad)
    with pytest.raises(TypeError, match="ChainOptimiseSettings"):
        lj.optimise(worm(), 0.05, 0.05, settings=lj.ExactOptimiseSettings())


# Mechanisms.

MECHANISM_OPTIMISE = pytest.mark.xdist_group("mechanism_optimise")  # the module-scoped optima are found once

MU = (0.5, 0.4, 0.4, 0.3)
K, C, V_MIN, FORCE_MAX = 10.0, 0.5, 0.005, 0.8


def _capsule(force=None, check=True):
    force = lj.Sinusoid(a=0.6, omega=3.0, lbar=0.0) if force is None else force
    links = [lj.Spring(0, 1, k=K, rest=0.0), lj.Damper(0, 1, c=C), lj.Force(0, 1, force)]
    return lj.Mechanism(masses=[1.0, 0.5], friction=[lj.AnisotropicCoulomb(*MU), None], carried_by=[None, 0],
                        links=links, check=check)  # fmt: skip


@pytest.fixture(scope="module")
def optimum():
    s = lj.MechanismOptimiseSettings(
        amplitudes=4, frequencies=8, local=2, max_iter=15, transient=20, dt=0.01, omega_min=0.15, omega_max=2.0
    )
    return lj.optimise(_capsule(), v_min=V_MIN, a_max=FORCE_MAX, direction=-1, settings=s)


@MECHANISM_OPTIMISE
@pytest.mark.slow
def test_mechanism_optimum_verified_by_simulate_and_the_reference(optimum):
    opt = optimum
    print({k: v for k, v in opt.to_dict().items() if k not in ("candidates",)})
    assert opt.feasible_exact and opt.stable_exact and opt.elements == [2]
    assert -opt.mean_speed_exact >= V_MIN and float(np.max(opt.stroke_exact)) <= FORCE_MAX * (1 + 1e-12)
    # The verdict of each constraint, the winner among the candidates and the local starts' history.
    assert opt.constraints_exact == dict(speed=True, stroke=True, no_liftoff=True, stable=True)
    assert not opt.liftoff_exact and opt.free_omega and opt.margin == 0.05
    won = [c for c in opt.candidates if c["candidate"] == opt.source]
    assert len(won) == 1 and won[0]["cost_of_transport_exact"] == opt.cost_of_transport_exact
    assert all("liftoff_exact" in c for c in opt.candidates)
    assert abs(won[0]["half_step_cost"] / opt.cost_of_transport_exact - 1) <= 1e-3  # verified at dt/2 as well
    starts = opt.history[0]["starts"]
    assert len(starts) == 2 and starts[0]["cost_of_transport"] == pytest.approx(opt.sinusoid["cost_of_transport"])
    assert opt.history[0]["local"], "the local runs' log"
    g = lj.steady_gait(opt.mechanism, periods=(1, 2), transient=20, dynamics=lj.Exact(dt=0.01))
    assert int(g.status) == lj.GaitStatus.CONVERGED
    assert abs(float(g.cost_of_transport) - opt.cost_of_transport_exact) < 1e-9
    u, v = float(g.state[0]), np.asarray(g.state[1:], float)
    T = float(g.period)
    # A direct simulation from the orbit's section state, over one gait period.
    M = lj.Mechanism(masses=[1.0, 0.5], friction=[lj.AnisotropicCoulomb(*MU), None], carried_by=[None, 0],
                     links=opt.mechanism.links, x0=[0.0, u], v0=v)  # fmt: skip
    traj = lj.simulate(M, T, jnp.array([0.0, T]), dynamics=lj.Exact(dt=0.01))
    dX = float(traj.X[-1] - traj.X[0])
    speed, cost = dX / T, float(traj.e_d[-1]) / abs(dX)
    # The independent reference with the optimum's force, s(t) = sum A_n cos(n w t) + B_n sin(n w t).
    H = opt.cos.shape[-1]
    force = Sig(0.0, tuple(opt.cos[0]), tuple(opt.sin[0]), opt.omega)
    S = System([Body(1.0, MU, x0=0.0, v0=v[0]), Body(0.5, None, carrier=0, x0=u, v0=v[1])],
               springs=[(0, 1, K, 0.0)], forces=[(0, 1, force)], dampers=[(0, 1, C)])  # fmt: skip
    ref = run(S, T, np.array([0.0, T]))
    r_dX = ref["com"][1] - ref["com"][0]
    r_speed, r_cost = r_dX / T, ref["ed"][1] / abs(r_dX)
    print(f"optimum ({H} harmonics): speed {opt.mean_speed_exact:.10f}, simulate {speed:.10f}, reference "
          f"{r_speed:.10f}; cost {opt.cost_of_transport_exact:.10f}, simulate {cost:.10f}, reference {r_cost:.10f}; "
          f"simulated from its start: {opt.simulation_agreement:.1e}")  # fmt: skip
    assert abs(speed / opt.mean_speed_exact - 1) < 1e-8 and abs(cost / opt.cost_of_transport_exact - 1) < 1e-8
    assert opt.simulation_agreement < 1e-6
    # Against the reference the difference is the engine's truncation error at the optimiser's step
    # (dt = 0.01 against a period of the second harmonic of 0.29): it shrinks with the step.
    fine = lj.simulate(M, T, jnp.array([0.0, T]), dynamics=lj.Exact(dt=0.0025))
    f_dX = float(fine.X[-1] - fine.X[0])
    f_speed, f_cost = f_dX / T, float(fine.e_d[-1]) / abs(f_dX)
    err = max(abs(r_speed / speed - 1), abs(r_cost / cost - 1))
    err_fine = max(abs(r_speed / f_speed - 1), abs(r_cost / f_cost - 1))
    print(f"against the reference: {err:.1e} at dt = 0.01, {err_fine:.1e} at dt = 0.0025")
    assert err < 2e-5 and err_fine < err / 8


@MECHANISM_OPTIMISE
@pytest.mark.slow
def test_mechanism_spline_search_at_a_coarser_step_reports_the_figures_at_dt():
    """`search_dt = 2 dt` with splines: the sinusoid screen and the local runs step at 0.02; the
    optimum's figures and its baseline sinusoid's (whose screen row is at 0.02, so solved again)
    are their steady gaits at `dt`."""
    from locomotion_jax.optimisation import _mechanism

    s = lj.MechanismOptimiseSettings(amplitudes=2, frequencies=4, local=1, max_iter=4, transient=20, shape="spline",
                                     knots=8, search_dt=0.02)  # fmt: skip
    opt = lj.optimise(_capsule(), v_min=V_MIN, a_max=FORCE_MAX, direction=-1, settings=s)
    w = opt.sinusoid
    assert opt.feasible_exact and w is not None
    c, d = np.full((1, 1, 1), w["a"] * math.sin(w["phase"])), np.full((1, 1, 1), w["a"] * math.cos(w["phase"]))
    wave = _mechanism._fourier(_capsule().broadcast(), c, d, np.array([w["omega"]]))
    for mech, speed, cost in [(opt.mechanism, opt.mean_speed_exact, opt.cost_of_transport_exact),
                              (wave, w["mean_speed"], w["cost_of_transport"])]:  # fmt: skip
        g = lj.steady_gait(mech, periods=(1, 2), transient=20, dynamics=lj.Exact(dt=0.01))
        assert bool(np.all(np.asarray(g.converged)))
        assert float(np.ravel(g.mean_speed)[0]) == pytest.approx(speed, rel=1e-7)
        assert float(np.ravel(g.cost_of_transport)[0]) == pytest.approx(cost, rel=1e-7)


@MECHANISM_OPTIMISE
@pytest.mark.slow
def test_mechanism_optimum_beats_the_best_sinusoid_of_a_sweep(optimum):
    """A batched sweep of 4 x 8 sinusoids a sin(w t) (a up to a_max, w over the optimiser's range):
    the cheapest one fast enough costs more than the optimum."""
    a = np.array([0.2, 0.4, 0.6, 0.8])
    w = np.geomspace(1.0, 10.0, 8)
    A, W = (x.ravel() for x in np.meshgrid(a, w, indexing="ij"))
    batch = _capsule(lj.Sinusoid(a=jnp.asarray(A), omega=jnp.asarray(W), lbar=0.0))
    g = lj.steady_gait(batch, periods=(1, 2), transient=20, dynamics=lj.Exact(dt=0.01))
    ok = np.asarray(g.converged) & np.asarray(g.stable) & (-np.asarray(g.mean_speed) >= V_MIN)
    best = float(np.min(np.where(ok, np.asarray(g.cost_of_transport), np.inf)))
    print(f"best sinusoid of the sweep: {best:.6f} ({int(ok.sum())} of {ok.size} fast enough); optimum "
          f"{optimum.cost_of_transport_exact:.6f}; the optimiser's own screen: {optimum.sinusoid}")  # fmt: skip
    assert ok.any() and optimum.cost_of_transport_exact < best


ISO = lj.Coulomb(0.5, 0.4)
M_BODY, M_IN, K_ISO = 1.0, 0.5, 10.0
OMEGA, F_MAX, V_ISO = 3.0, 2.0, 0.05
FLOOR = 0.4 * (M_BODY + M_IN)  # mu_k (M + m) g, g = 1


def _iso_capsule(cos, sin):
    """The capsule of experiments/capsule.py driven by a Fourier force of omega = 3 (rows: a batch)."""
    wave = lj.Fourier(jnp.asarray(cos), jnp.asarray(sin), OMEGA, 0.0)
    return lj.Mechanism(masses=[M_BODY, M_IN], friction=[ISO, None], carried_by=[None, 0],
                        links=[lj.Spring(0, 1, k=K_ISO, rest=0.0), lj.Force(0, 1, wave)])  # fmt: skip


def _measured(mech, settle=100, periods=40):
    T = 2 * np.pi / OMEGA
    res = lj.measure(mech, z=1e6, horizon=periods * T, window=periods * T, t_start=settle * T)
    v, ed = np.asarray(res.mean_speed), np.asarray(res.e_d)
    return np.asarray(res.status), v, np.where(v > 0, ed / np.where(v > 0, v * periods * T, 1.0), np.inf)


@pytest.fixture(scope="module")
def iso_optimum():
    s = lj.MechanismOptimiseSettings(amplitudes=4, phases=4, local=2, max_iter=30)
    return lj.optimise(_iso_capsule(np.zeros(1), np.zeros(1)), v_min=V_ISO, a_max=F_MAX, omega=OMEGA, harmonics=3,
                       settings=s)  # fmt: skip


@MECHANISM_OPTIMISE
@pytest.mark.slow
def test_isotropic_capsule_optimum_sits_on_the_physical_floor(iso_optimum):
    opt = iso_optimum
    print({k: v for k, v in opt.to_dict().items() if k not in ("candidates",)})
    assert opt.feasible_exact and opt.stable_exact and opt.elements == [1] and opt.omega == pytest.approx(OMEGA)
    assert opt.mean_speed_exact >= V_ISO
    # Interior in the force: the bound does not bind (the speed constraint and the floor do).
    peak = float(np.max(opt.stroke_exact))
    assert peak < 0.75 * F_MAX
    # The floor: e_d >= mu_k N |distance|, equal only if the body never slides backward.
    assert FLOOR * (1 - 1e-9) <= opt.cost_of_transport_exact <= FLOOR * (1 + 1e-6)
    # A direct simulation from rest with the optimum's force: the same speed and cost.
    status, v, cost = _measured(opt.mechanism)
    print(f"optimum: speed {opt.mean_speed_exact:.10f}, measured {float(v):.10f}; cost "
          f"{opt.cost_of_transport_exact:.12f}, measured {float(cost):.12f}; peak force {peak:.4f}")  # fmt: skip
    assert int(status) == lj.Status.OK
    assert abs(float(v) / opt.mean_speed_exact - 1) < 1e-8 and abs(float(cost) / opt.cost_of_transport_exact - 1) < 1e-8
    T = 2 * np.pi / OMEGA
    traj = lj.simulate(opt.mechanism, t_end=110 * T, save_at=jnp.linspace(100 * T, 110 * T, 2001))
    assert float(np.min(np.asarray(traj.v)[:, 0])) >= -1e-12  # the body never slides backward
    assert float(np.max(np.asarray(traj.v)[:, 0])) > 0.1


@MECHANISM_OPTIMISE
@pytest.mark.slow
def test_isotropic_capsule_no_sinusoid_under_the_bound_is_as_good(iso_optimum):
    """Sinusoids A sin(omega t + phi), 25 amplitudes up to the bound times 12 phases, one batched
    `lj.simulate` over 10 periods after 20: none meets the speed at a lower cost, and every one pays
    at least the floor on its body's own displacement, e_d >= mu_k (M + m) g |x_0(t1) - x_0(t0)| (the
    centre of mass also carries the internal mass's free oscillation, which need not be periodic)."""
    U, PHI = (q.ravel() for q in np.meshgrid(np.linspace(0.04, 1.0, 25), np.linspace(0, 2 * np.pi, 12, endpoint=False)))
    cos, sin = np.zeros((U.size, 3)), np.zeros((U.size, 3))
    cos[:, 0], sin[:, 0] = F_MAX * U * np.sin(PHI), F_MAX * U * np.cos(PHI)
    T = 2 * np.pi / OMEGA
    traj = lj.simulate(_iso_capsule(cos, sin), t_end=30 * T, save_at=jnp.array([20 * T, 30 * T]))
    assert (np.asarray(traj.status) == lj.Status.OK).all()
    x, ed = np.asarray(traj.x), np.asarray(traj.e_d)
    body = x[:, 1, 0] - x[:, 0, 0]
    com = (M_BODY * body + M_IN * (x[:, 1, 1] - x[:, 0, 1])) / (M_BODY + M_IN)
    e_d = ed[:, 1] - ed[:, 0]
    v = com / (10 * T)
    slides = np.abs(body) > 1e-9
    print(f"sinusoids: {int(slides.sum())} of {U.size} displace the body, the fastest forward {v.max():.4f}, "
          f"{int((v >= V_ISO).sum())} meet v_min")  # fmt: skip
    assert slides.any() and (e_d >= FLOOR * np.abs(body) * (1 - 1e-9) - 1e-12).all()
    fast = v >= V_ISO
    cost = np.where(fast, e_d / np.where(fast, com, 1.0), np.inf)
    assert not (cost < iso_optimum.cost_of_transport_exact * (1 - 1e-9)).any()


@MECHANISM_OPTIMISE
def test_mechanism_optimise_settings():
    """The settings' checks name the field; a ChainOptimiseSettings is taken field for field (one
    phase, its phases as the lags); a chain has no lags of its own."""
    from locomotion_jax.optimisation._element_optimum import MechanismOptimiseSettings

    with pytest.raises(ValueError, match="MechanismOptimiseSettings.phases must be an int >= 1, got 0"):
        lj.MechanismOptimiseSettings(phases=0)
    with pytest.raises(ValueError, match="MechanismOptimiseSettings.lags must be an int >= 1, got 0"):
        lj.MechanismOptimiseSettings(lags=0)
    with pytest.raises(TypeError, match="lags"):
        lj.ChainOptimiseSettings(lags=2)  # pyright: ignore[reportCallIssue]
    assert not hasattr(lj.ChainOptimiseSettings(), "lags")
    with pytest.raises(ValueError, match="need 0 < omega_min < omega_max"):
        lj.MechanismOptimiseSettings(omega_min=2.0, omega_max=1.0)
    # The shared fields are checked alike in every exact optimiser's settings, naming the class.
    for cls in (lj.MechanismOptimiseSettings, lj.ExactOptimiseSettings):
        with pytest.raises(ValueError, match=rf"{cls.__name__}\.dt must be a finite step > 0, got 0.0"):
            cls(dt=0.0)
        with pytest.raises(ValueError, match="trust_radius and newton_tol must be > 0, got 0.0, 1e-10"):
            cls(trust_radius=0.0)
        with pytest.raises(ValueError, match="margin and speed_slack must be >= 0, got -1.0"):
            cls(margin=-1.0)
        with pytest.raises(ValueError, match=rf"{cls.__name__}\.newton_iter must be an int >= 1, got 0"):
            cls(newton_iter=0)
    # The paper's model may solve its orbits from the relaxed spring itself, a mechanism may not.
    assert lj.ExactOptimiseSettings(transient=0).transient == 0
    with pytest.raises(ValueError, match="ExactSettings.transient must be an int >= 0, got -1"):
        lj.ExactOptimiseSettings(transient=-1)
    with pytest.raises(ValueError, match="MechanismOptimiseSettings.transient must be an int >= 1, got 0"):
        lj.MechanismOptimiseSettings(transient=0)
        with pytest.raises(ValueError, match=rf"{cls.__name__}\.check_tol must be in \(0, 1\)"):
            cls(check_tol=0.0)
        with pytest.raises(ValueError, match="check_periods must be \\(lo, hi\\), 1 <= lo <= hi, got \\(5, 2\\)"):
            cls(check_periods=(5, 2))
    chain = lj.ChainOptimiseSettings(local=3, max_iter=7, omega_max=1.5, local_method="sqp", stall_rtol=1e-5, phases=6)
    s = MechanismOptimiseSettings.from_chain(chain)
    assert (s.local, s.max_iter, s.omega_max, s.phases, s.lags, s.local_method, s.stall_rtol) == (
        3, 7, 1.5, 1, 6, "sqp", 1e-5)  # fmt: skip
    with pytest.raises(ValueError, match="MechanismOptimiseSettings.local_method must be 'descent' or 'sqp'"):
        lj.MechanismOptimiseSettings(local_method="bfgs")
    with pytest.raises(TypeError, match="must be a MechanismOptimiseSettings, got ExactSettings"):
        lj.optimise(_capsule(), v_min=0.01, a_max=0.5, settings=lj.ExactOptimiseSettings())
    with pytest.raises(ValueError, match="shape must be 'fourier' or 'spline', got 'square'"):
        lj.MechanismOptimiseSettings(shape="square")
    with pytest.raises(ValueError, match="knots must be an int >= 4, got 3"):
        lj.MechanismOptimiseSettings(knots=3)
    with pytest.raises(ValueError, match=r"harmonics applies to Fourier series.*got harmonics=3"):
        lj.optimise(
            _capsule(), v_min=0.01, a_max=0.5, harmonics=3, settings=lj.MechanismOptimiseSettings(shape="spline")
        )


def test_a_mechanisms_screen_drives_its_elements_as_travelling_waves():
    """With two or more actuated elements the sinusoids of a mechanism's screen lag from one element
    to the next (`MechanismOptimiseSettings.lags`): a worm of three bodies on bristles built as a
    `Mechanism`, screened at one amplitude and frequency over 4 lags ($-\\pi$, $-\\pi/2$, 0,
    $\\pi/2$): each sinusoid's steady gait is the chain's under the travelling wave $a \\sin(\\omega t
    - j\\lambda)$ on spring $j$ (`TravellingWave`, `phi` the lag), to 1e-9, and the lag changes the
    speed. One actuated element screens no lag."""
    from locomotion_jax.optimisation._mechanism import _fourier, sinusoid_signals, sinusoids

    law = lj.AnisotropicCoulomb(0.5, 0.9, 0.3, 0.7)
    springs = [lj.Spring(j, j + 1, k=50.0, rest=lj.Sinusoid(a=0.05, omega=2.0, lbar=3.0)) for j in range(2)]
    mech = lj.Mechanism(masses=[1.0, 1.0, 1.0], friction=[law] * 3, links=springs, x0=[0.0, 3.0, 6.0])
    settings = lj.MechanismOptimiseSettings(amplitudes=1, frequencies=1, lags=4)
    a, omega, phase, lag = sinusoids(0.05, 3.0, 3.0, 2, settings)
    np.testing.assert_allclose(lag, [-np.pi, -np.pi / 2, 0.0, np.pi / 2], atol=1e-15)
    cos, sin = sinusoid_signals(a, phase, lag, 2, 1)
    gaits = lj.steady_gait(_fourier(mech.broadcast(), cos, sin, omega))
    wave = lj.TravellingWave(a=jnp.asarray(a), omega=jnp.asarray(omega), phi=jnp.asarray(lag))
    worm = lj.Chain(masses=[1.0, 1.0, 1.0], k=50.0, d=0.0, lbar=3.0, c=0.0, friction=law, waveforms=wave)
    chain = lj.steady_gait(worm)
    assert np.all(np.asarray(gaits.converged)) and np.all(np.asarray(chain.converged))
    for name in ("mean_speed", "cost_of_transport"):
        np.testing.assert_allclose(np.asarray(getattr(gaits, name)), np.asarray(getattr(chain, name)), rtol=1e-9)
    assert np.ptp(np.asarray(gaits.mean_speed)) > 0.01
    one = sinusoids(0.05, 1.0, 3.0, 1, settings)
    assert one[0].size == 1 and not np.any(one[3])  # one amplitude, one frequency (lo = 1), no lag


@MECHANISM_OPTIMISE
def test_mechanism_optimise_bad_input():
    with pytest.raises(ValueError, match="no element driven by a waveform"):
        lj.optimise(_capsule(force=0.3), v_min=0.01, a_max=0.5)
    with pytest.raises(ValueError, match="a_max must be a finite bound > 0"):
        lj.optimise(_capsule(), v_min=0.01, a_max=-1.0)
    with pytest.raises(ValueError, match="single configuration"):
        lj.optimise(_capsule(lj.Sinusoid(a=jnp.array([0.3, 0.4]), omega=3.0, lbar=0.0)), v_min=0.01, a_max=0.5)
    with pytest.raises(ValueError, match="method must be 'exact' or 'smoothed'"):
        lj.optimise(_capsule(), v_min=0.01, a_max=0.5, method="adam")
    with pytest.raises(ValueError, match="MechanismOptimiseSettings.shape must be 'fourier'"):
        lj.optimise(
            _capsule(), v_min=0.01, a_max=0.5, method="smoothed", settings=lj.MechanismOptimiseSettings(shape="spline")
        )
    with pytest.raises(TypeError, match="smoothed"):
        lj.MechanismOptimiseSettings(smoothed=lj.ExactOptimiseSettings())  # pyright: ignore[reportArgumentType]
    # A start is checked before the screen: an optimum of as many signals, nothing else.
    two = _optimum_of(np.zeros((2, 1)), np.zeros((2, 1)), None, 1.0)
    with pytest.raises(ValueError, match="start: an optimum of 2 actuated signals; this search has 1"):
        lj.optimise(_capsule(), v_min=0.01, a_max=0.5, start=two)
    with pytest.raises(TypeError, match="start must be the result of an earlier optimise call"):
        lj.optimise(_capsule(), v_min=0.01, a_max=0.5, start=lj.Sinusoid(a=0.3, omega=3.0, lbar=0.0))


@MECHANISM_OPTIMISE
def test_smoothed_method_on_a_mechanism():
    """`method="smoothed"` on the anisotropic capsule: the local stage on the smoothed model (a
    carried body without friction, the force bounded), its candidates verified on their steady
    gaits. A feasible optimum, no costlier than its sinusoid, whose steady gait the independent
    reference reproduces from rest over whole periods once its transient has decayed."""
    s = lj.MechanismOptimiseSettings(amplitudes=4, frequencies=8, local=2, transient=20, dt=0.01, omega_min=0.15,
                                     omega_max=2.0, smoothed=SMOOTHED)  # fmt: skip
    opt = lj.optimise(_capsule(), v_min=V_MIN, a_max=FORCE_MAX, direction=-1, method="smoothed", settings=s)
    print(opt.summary())
    assert [c["candidate"] for c in opt.candidates] == ["sinusoid", "smoothed 0", "smoothed 1"]
    assert opt.feasible_exact and all(opt.constraints_exact.values()) and -opt.mean_speed_exact >= V_MIN
    assert opt.sinusoid is not None and opt.cost_of_transport_exact <= opt.sinusoid["cost_of_transport"]
    assert float(np.max(opt.stroke_exact)) <= FORCE_MAX * (1 + 1e-12) and opt.evaluations == 0
    assert opt.simulation_agreement < 1e-6
    assert opt.min_normal == 1.5  # the shell bears both weights; the carried body bears no load
    # The screen it keeps: every sinusoid, of which the baseline is the cheapest fast enough one.
    sc, w = opt.screen, opt.sinusoid
    assert len(sc["speed"]) == opt.screened == 4 * 8
    i = int(np.argmin(np.where(sc["ok"] & (-sc["speed"] >= V_MIN), sc["cost"], np.inf)))
    assert (sc["a"][i], sc["omega"][i], sc["phase"][i], sc["cost"][i]) == (w["a"], w["omega"], w["phase"],
                                                                           w["cost_of_transport"])  # fmt: skip
    # That screen given again (`sweep=`) is not solved again, and gives the same optimum.
    again = lj.optimise(_capsule(), v_min=V_MIN, a_max=FORCE_MAX, direction=-1, method="smoothed", settings=s,
                        sweep=json.loads(opt.to_json(full=True))["screen"])  # fmt: skip
    assert again.cost_of_transport_exact == opt.cost_of_transport_exact and again.sinusoid == opt.sinusoid
    w, Tg = opt.omega, opt.gait_period_exact
    force = Sig(0.0, tuple(float(c) for c in opt.cos[0]), tuple(float(c) for c in opt.sin[0]), w)
    S = System([Body(1.0, MU), Body(0.5, None, carrier=0)], springs=[(0, 1, K, 0.0)], forces=[(0, 1, force)],
               dampers=[(0, 1, C)])  # fmt: skip
    t = np.array([opt.simulated_periods, opt.simulated_periods + 10]) * Tg
    ref = run(S, float(t[1]), t)
    dX = ref["com"][1] - ref["com"][0]
    speed, cost = dX / (t[1] - t[0]), (ref["ed"][1] - ref["ed"][0]) / abs(dX)
    err = max(abs(speed / opt.mean_speed_exact - 1), abs(cost / opt.cost_of_transport_exact - 1))
    print(f"smoothed capsule optimum: speed {opt.mean_speed_exact:.10f} (reference {speed:.10f}), cost "
          f"{opt.cost_of_transport_exact:.10f} (reference {cost:.10f}); diff {err:.1e}")  # fmt: skip
    assert err < 1e-4


def _reference_gait(opt, periods=None, state=(0.0, 0.0, 0.0)):
    """Mean speed and cost of transport of the optimum's isotropic capsule in the independent
    reference from the section state `state` (gap, body's and inner mass's velocities; rest by
    default) between the force's `periods`: by default 10 of them once the slowest Floquet mode has
    decayed to 1e-9 of its start (at least 30 periods)."""
    w = float(opt.omega)
    start = int(np.clip(np.ceil(np.log(1e-9) / np.log(opt.spectral_radius_exact)), 30, 400))
    periods = (start, start + 10) if periods is None else periods
    if opt.shape == "spline":
        force = Sig(0.0, w=w, control=tuple(float(c) for c in opt.control[0]))
    else:
        force = Sig(0.0, tuple(float(c) for c in opt.cos[0]), tuple(float(c) for c in opt.sin[0]), w)
    u, v0, v1 = (float(q) for q in state)
    S = System([Body(M_BODY, (0.5, 0.5, 0.4, 0.4), v0=v0), Body(M_IN, None, carrier=0, x0=u, v0=v1)],
               springs=[(0, 1, K_ISO, 0.0)], forces=[(0, 1, force)])  # fmt: skip
    t = np.array(periods, float) * 2 * np.pi / w
    ref = run(S, float(t[1]), t)
    dX = ref["com"][1] - ref["com"][0]
    return dX / (t[1] - t[0]), (ref["ed"][1] - ref["ed"][0]) / abs(dX)


# A spline force (control values at omega = 3) on the isotropic capsule that the mechanism
# optimiser's descent reached: its orbit over one period has no fixed point near the settled state,
# and Newton's iterates run off to velocities of 1e15 and more, where a residual relative to the
# iterate's size alone (64 against 9e15) passed. The gait is of period 2.
RUNAWAY = (0.17038443168996228, -1.5202228768451358, -1.9922847684607983, -1.606465706627539,
           0.17030266211663847, 1.631715979592068, 1.8174558022762703, 1.511427719786336)  # fmt: skip


def test_newton_does_not_accept_an_orbit_that_ran_off():
    huge, start = jnp.array([0.0, 9e15]), jnp.array([0.5, -2.0])
    assert float(_orbit.tolerance_scale(huge, start)) == _orbit.DIVERGED * 3.0
    assert float(_orbit.tolerance_scale(start, start)) == 2.0
    # The optimisers' oracle: from the settled state, the one-period orbit is refused, the two-period one found.
    base, control = _iso_capsule(np.zeros(1), np.zeros(1)), np.array(RUNAWAY)
    steps = int(math.ceil(2 * math.pi / OMEGA / 0.01)) * 3 + 200
    oracle = _element_orbit.ChainOracle(chain=base, a_max=jnp.asarray(F_MAX), max_steps=jnp.asarray(steps, jnp.int32),
                                        tol=jnp.asarray(1e-11), harmonics=0, contact="paper", dt=0.01, max_iter=30,
                                        knots=8)  # fmt: skip
    theta = jnp.asarray(np.r_[control / F_MAX, math.log(OMEGA)])[None]
    y0 = oracle.transient(theta, jnp.zeros((1, 3)), jnp.ones(1, bool), jnp.asarray(15))
    one, two = (oracle.orbits(theta, y0, jnp.full(1, k, jnp.int32)) for k in (1, 2))
    assert not bool(one.ok[0]) or float(jnp.abs(one.y).max()) < 10
    assert bool(two.ok[0]) and float(jnp.abs(two.y).max()) < 1
    # steady_gait: the gait it finds at dt is the one at dt/2 (the runaway orbit had speed 9e15).
    mech = base.with_spline(jnp.asarray(control[None]), jnp.asarray(OMEGA))
    gaits = [lj.steady_gait(mech, periods=(1, 2), transient=15, dynamics=lj.Exact(dt=dt)) for dt in (0.01, 0.005)]
    for g in gaits:
        assert int(g.status) == lj.GaitStatus.CONVERGED and float(jnp.abs(g.state).max()) < 1
    (v, cot), (v2, cot2) = ((float(g.mean_speed), float(g.cost_of_transport)) for g in gaits)
    assert v == pytest.approx(v2, rel=1e-6) and cot == pytest.approx(cot2, rel=1e-6) and 0.1 < v < 0.11


@MECHANISM_OPTIMISE
def test_reference_spline_is_the_packages_spline():
    """The reference's B-spline signal (its own formula) equals `lj.Spline` and its rate."""
    c = np.random.default_rng(3).normal(size=7)
    wave = lj.Spline(jnp.asarray(c), 2.3, 0.4)
    t = np.linspace(-3.0, 9.0, 501)
    val, rate = (np.asarray(q) for q in wave(jnp.asarray(t)))
    ref = np.array([Sig(0.4, w=2.3, control=tuple(c)).at(x) for x in t])
    assert np.abs(ref[:, 0] - val).max() < 1e-12 and np.abs(ref[:, 1] - rate).max() < 1e-11


SPLINE: dict[str, Any] = dict(amplitudes=3, phases=2, local=1, max_iter=8, transient=15, shape="spline", knots=8)


@pytest.fixture(scope="module")
def spline_optimum():
    s = lj.MechanismOptimiseSettings(**SPLINE)
    return lj.optimise(_iso_capsule(np.zeros(1), np.zeros(1)), v_min=V_ISO, a_max=F_MAX, omega=OMEGA, settings=s)


@MECHANISM_OPTIMISE
@pytest.mark.slow
def test_spline_optimum_of_the_isotropic_capsule(spline_optimum):
    opt = spline_optimum
    print({k: v for k, v in opt.to_dict().items() if k not in ("candidates",)}, opt.candidates)
    assert opt.shape == "spline" and opt.harmonics == 0 and opt.cos.shape == (1, 0)
    assert opt.control is not None and opt.control.shape == (1, 8)
    wave = opt.mechanism.links[1].waveform
    assert isinstance(wave, lj.Spline) and np.array_equal(np.asarray(wave.control), opt.control[0])
    # The bound: a box on the control values; the exact stroke against a dense sampling of the force.
    T = 2 * np.pi / OMEGA
    sampled = float(np.abs(np.asarray(wave(jnp.linspace(0.0, T, 40001))[0])).max())
    stroke = float(opt.stroke_exact[0])
    assert np.abs(opt.control).max() <= F_MAX and stroke <= F_MAX * (1 + 1e-12)
    assert sampled <= stroke + 1e-12 and stroke - sampled < 1e-6
    # No sinusoid of the screen under the bound moves the capsule at v_min; the spline does.
    assert opt.sinusoid is None and opt.candidates[0]["feasible_exact"] is False
    assert opt.feasible_exact and opt.stable_exact and opt.mean_speed_exact >= V_ISO
    # The floor e_d >= mu_k (M + m) g |distance| holds.
    assert opt.cost_of_transport_exact >= FLOOR * (1 - 1e-9)
    # The independent reference started on the optimum's orbit (steady_gait's section state) stays on it.
    g = lj.steady_gait(opt.mechanism, periods=(1, 2), transient=15, dynamics=lj.Exact(dt=opt.dt_exact))
    assert float(g.cost_of_transport) == pytest.approx(opt.cost_of_transport_exact, rel=1e-9)
    speed, cost = _reference_gait(opt, (30, 40), np.asarray(g.state))
    err = max(abs(speed / opt.mean_speed_exact - 1), abs(cost / opt.cost_of_transport_exact - 1))
    print(f"spline optimum: speed {opt.mean_speed_exact:.10f} (reference {speed:.10f}), cost "
          f"{opt.cost_of_transport_exact:.10f} (reference {cost:.10f}, floor {FLOOR}); diff {err:.1e}")  # fmt: skip
    assert err < 1e-4
    # The direct simulation from rest: on the optimum's gait, or on the motion of another attractor,
    # named, whose figures the reference reproduces from rest over the same whole periods (the
    # optimum of this search has two: from rest the capsule settles on a motion of 4 periods).
    n, p, k = opt.simulated_periods, opt.simulated_recurrence, round(opt.gait_period_exact * OMEGA / (2 * np.pi))
    speed, cost = _reference_gait(opt, (n * k, (n + _element_local.AVERAGED) * k))
    assert speed == pytest.approx(opt.mean_speed_simulated, rel=1e-5)
    assert cost == pytest.approx(opt.cost_of_transport_simulated, rel=1e-5)
    assert opt.simulation_agreement < 1e-6 if p == 1 else (p > 1 and "a second attractor" in opt.summary())


@MECHANISM_OPTIMISE
@pytest.mark.slow
def test_a_mechanism_spline_search_verifies_at_a_step_that_resolves_its_knots():
    """64 knots at omega = 3 lie 0.0327 apart: the search steps at dt = 0.01 (3.2 steps per knot), the
    verification at the resolution guard's 0.0081, whose figures `steady_gait` reproduces there."""
    s = lj.MechanismOptimiseSettings(**{**SPLINE, "knots": 64, "max_iter": 4})
    opt = lj.optimise(_iso_capsule(np.zeros(1), np.zeros(1)), v_min=V_ISO, a_max=F_MAX, omega=OMEGA, settings=s)
    assert opt.shape == "spline" and opt.feasible_exact and opt.dt_exact == 0.0081
    g = lj.steady_gait(opt.mechanism, periods=(1, 2), transient=20, dynamics=lj.Exact(dt=0.0081))
    assert float(g.cost_of_transport) == pytest.approx(opt.cost_of_transport_exact, rel=1e-9)
    assert opt.simulation_agreement < 1e-6
    with pytest.raises(ValueError, match=r"K = 64"):
        lj.steady_gait(opt.mechanism, dynamics=lj.Exact(dt=0.01))


@MECHANISM_OPTIMISE
@pytest.mark.slow
def test_a_mechanism_search_continues_from_a_given_start(spline_optimum):
    """`start=` the spline optimum, in a search of as many knots with one local lane: the lane starts
    at its control values, whose steady gait is the optimum's, and nothing costlier is reported."""
    settings = lj.MechanismOptimiseSettings(**SPLINE)
    opt = lj.optimise(_iso_capsule(np.zeros(1), np.zeros(1)), v_min=V_ISO, a_max=F_MAX, omega=OMEGA,
                      settings=settings, start=spline_optimum)  # fmt: skip
    given = [c for c in opt.candidates if c["candidate"] == "given start"]
    assert len(given) == 1 and given[0]["feasible_exact"]
    assert given[0]["cost_of_transport_exact"] == pytest.approx(spline_optimum.cost_of_transport_exact, rel=1e-12)
    (run,) = opt.history[0]["local"]
    assert run["trace"][0]["cot"] == pytest.approx(spline_optimum.cost_of_transport_exact, rel=1e-9)
    assert opt.history[0]["starts"] == []  # one lane: the given start's
    assert opt.feasible_exact and opt.cost_of_transport_exact <= spline_optimum.cost_of_transport_exact * (1 + 1e-12)


@MECHANISM_OPTIMISE
@pytest.mark.slow
@pytest.mark.parametrize("shape", ["fourier", "spline"])
def test_mechanism_optimise_float32(shape):
    """The isotropic capsule in float32 (Fourier series of 2 harmonics, or splines of 8 knots): the
    optimiser keeps the dtype, meets the requirement and the floor, and its optimum's gait agrees
    with the float64 reference within 1e-3 (float32's resolution of the orbit, Newton tolerance 1e-5)."""
    mech = _iso_capsule(np.zeros(1), np.zeros(1)).astype(jnp.float32)
    s = lj.MechanismOptimiseSettings(**(SPLINE | dict(shape=shape)))
    opt = lj.optimise(mech, v_min=V_ISO, a_max=F_MAX, omega=OMEGA, harmonics=2 if shape == "fourier" else None,
                      settings=s)  # fmt: skip
    print({k: v for k, v in opt.to_dict().items() if k not in ("candidates",)})
    assert opt.mechanism.dtype == jnp.float32 and opt.shape == shape
    assert all(x.dtype == jnp.float32 for x in jax.tree_util.tree_leaves(opt.mechanism))
    assert opt.feasible_exact and opt.stable_exact and opt.mean_speed_exact >= V_ISO
    assert opt.cost_of_transport_exact >= FLOOR * (1 - 1e-6) and float(np.max(opt.stroke_exact)) <= F_MAX * (1 + 1e-6)
    speed, cost = _reference_gait(opt)
    err = max(abs(speed / opt.mean_speed_exact - 1), abs(cost / opt.cost_of_transport_exact - 1))
    print(f"float32 {shape} optimum: speed {opt.mean_speed_exact:.8f} (reference {speed:.8f}), cost "
          f"{opt.cost_of_transport_exact:.8f} (reference {cost:.8f}); relative difference {err:.1e}")  # fmt: skip
    assert err < 1e-3
