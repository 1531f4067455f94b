"""The sinusoid baseline (`_pareto`): the coarse sweep and its local refinement."""

import locomotion_jax as lj
import numpy as np
import pytest
from locomotion_jax.optimisation import _pareto


A_MAX = 0.05

# Feasible sinusoids cheaper than the best of the coarse sweep, found by an
# independent fine scan (v_min, a, omega, cost of transport on the exact model,
# averaged over a 60-unit window, not over whole periods: within 1 % of the steady gait's).
CHEAPER = [(0.02, 0.05, 1.745, 1.3272), (0.03, 0.05, 4.48, 2.6369)]

# The exact engine's own error at dt = 0.01 is ~1e-6 relative (README, Accuracy);
# the refinement must do at least as well as the quoted sinusoids up to that.
TOL = 1e-5


pytestmark = pytest.mark.xdist_group("pareto")  # the module's coarse sweep is run once, on one worker


@pytest.fixture(scope="module")
def coarse():
    # The sweep of experiments/optimal_actuation.py: 6 amplitudes x 32 frequencies.
    p = lj.Params()
    return _pareto.sinusoid_sweep(p, A_MAX, omegas=_pareto.default_omegas(p, 32), amplitudes=6)


@pytest.mark.slow
@pytest.mark.parametrize("v_min, a, omega, cost", CHEAPER)
def test_refinement_finds_the_cheaper_sinusoids(coarse, v_min, a, omega, cost):
    p = lj.Params()
    # The quoted sinusoid's steady gait is feasible and about as cheap as quoted...
    quoted = _pareto.exact_figures(lj.Params(a=a, omega=omega), None)
    assert bool(quoted.ok) and float(quoted.speed) >= v_min
    q = float(quoted.cost)
    assert abs(q - cost) < 0.01 * cost
    # ...and cheaper than anything on the coarse grid (so this test needs the refinement).
    on_grid = _pareto.best_sinusoid(coarse, v_min, +1)
    assert on_grid is not None and on_grid["cost_of_transport"] > q * (1 + 1e-3)
    best = _pareto.refine_sinusoid(p, A_MAX, v_min, +1, coarse)
    assert best is not None and best["cost_of_transport"] <= q * (1 + TOL)
    assert best["a"] <= A_MAX and best["mean_speed"] >= v_min
    # The reported figures are those of the reported sinusoid, run again on its own.
    again = _pareto.exact_figures(lj.Params(a=best["a"], omega=best["omega"]), None)
    assert bool(again.ok)
    np.testing.assert_allclose([again.speed, again.cost], [best["mean_speed"], best["cost_of_transport"]], rtol=1e-9)


def test_refinement_without_a_feasible_sinusoid():
    # No coarse sinusoid reaches the speed: nothing to refine, no exact run.
    sweep = _pareto.SinusoidSweep(
        a=np.array([0.02, 0.05]),
        omega=np.array([2.0, 2.0]),
        speed=np.array([0.01, np.nan]),
        cost=np.array([1.0, np.nan]),
        ok=np.array([True, False]),
    )
    assert _pareto.best_sinusoid(sweep, 0.02, +1) is None
    assert _pareto.refine_sinusoid(lj.Params(), A_MAX, 0.02, +1, sweep) is None
