"""`optimise(chain, ...)`: the chain optimiser and `locomotion-jax chain-optimize`.

Small problems (N = 3 and N = 2, a short transient, coarse screens, few iterations): the
module's fixtures share every compilation (the screen's and the verification's steady-gait
solver, the orbit oracle, the direct simulation), so the tests run in one xdist group.
"""

import json
import math
from typing import Any

import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from locomotion_jax.cli import _main as _cli
from locomotion_jax.gaits import _element_orbit
from locomotion_jax.optimisation import _chain_screen as screen
from typer.testing import CliRunner


pytestmark = pytest.mark.xdist_group("chain_optimise")

SMALL: dict[str, Any] = dict(amplitudes=2, frequencies=4, phases=4, zoom_levels=1, zoom_points=3, local=2, transient=10)
# The screen's slowest waves take most of the steps (a period at omega_min is ~60 of the
# fastest): the frequency range starts at 0.4 instead of 0.06 of the lowest natural frequency.
SETTINGS = lj.ChainOptimiseSettings(**SMALL, max_iter=8, omega_min=0.4)
A_MAX = 0.1


def worm(n: int = 3) -> lj.Chain:
    return lj.Chain(masses=[1.0] * n, d=0.0, friction=lj.AnisotropicCoulomb(0.5, 0.9, 0.3, 0.7))


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


def test_optimum_verifies_on_steady_gait_and_simulation(opt3):
    g = _first(lj.steady_gait(lj.Chain.stack([opt3.chain] * SETTINGS.chunk), transient=SETTINGS.transient,
                              dynamics=lj.Exact(dt=SETTINGS.dt), start="relaxed"))  # fmt: skip
    assert bool(g.converged) and bool(g.stable) and not bool(g.liftoff)
    assert float(g.mean_speed) == pytest.approx(opt3.mean_speed_exact, rel=1e-10)
    assert float(g.cost_of_transport) == pytest.approx(opt3.cost_of_transport_exact, rel=1e-10)
    assert float(g.mean_speed) >= opt3.v_min
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
    assert opt3.min_normal >= opt3.margin


def test_stroke_bound_holds_exactly(opt3):
    phase = np.linspace(0, 2 * np.pi, 400_001)
    n = np.arange(1, opt3.harmonics + 1)
    s = opt3.cos @ np.cos(np.outer(n, phase)) + opt3.sin @ np.sin(np.outer(n, phase))
    assert np.max(np.abs(s)) <= A_MAX * (1 + 1e-12)
    assert np.all(opt3.stroke_exact <= A_MAX * (1 + 1e-12))
    np.testing.assert_allclose(opt3.stroke_exact, np.max(np.abs(s), axis=1), rtol=1e-9)


def test_screen_filter_keeps_the_fast_waves():
    v = np.array([0.3, np.nan, -0.4, 0.05, 0.2, 0.01])
    assert list(screen.fast_enough(v, 0.4, 1, 0.5, 2)) == [0, 4]  # 0.2 reaches half of 0.4; 0.3, 0.2 fastest
    assert list(screen.fast_enough(v, 0.4, 1, 0.5, 3)) == [0, 3, 4]
    assert list(screen.fast_enough(v, 0.4, -1, 0.5, 1)) == [2]  # backwards; NaN never
    assert list(screen.fast_enough(v, 10.0, 1, 0.5, 0)) == []


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


@pytest.mark.slow
def test_infeasible_requirement_is_flagged(infeasible):
    assert not infeasible.feasible_exact
    assert not infeasible.constraints_exact["speed"]
    assert infeasible.travelling_wave is None and math.isnan(infeasible.improvement_vs_travelling_wave)
    record = json.loads(infeasible.to_json())
    assert record["feasible_exact"] is False and record["improvement_vs_travelling_wave"] is None
    assert "INFEASIBLE" in infeasible.summary()


@pytest.mark.slow
def test_one_compilation_serves_every_evaluation(opt3, infeasible):
    """Both optimisations (other requirements, other iterates, the fallbacks) share one compiled oracle."""
    assert _element_orbit.TRACES["evaluate"] == 1 and _element_orbit.TRACES["relax"] <= 1


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
        (dict(method="smoothed"), "exact method only"),
        (dict(chain=lj.Chain(masses=[1.0, 1.0, 1.0], d=0.5), a_max=0.07), "lifts a mass off at rest"),
        (dict(chain=lj.Chain.stack([worm(), worm()])), "single configuration"),
        (dict(chain=lj.Chain(masses=[1.0] * 3, actuator=lj.InternalForce())), "RestLength"),
    ],
)
def test_bad_input_raises(kwargs, message):
    args = dict(chain=worm(), v_min=0.05, a_max=0.05) | kwargs
    chain, v_min, a_max = args.pop("chain"), args.pop("v_min"), args.pop("a_max")
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)").replace("+", r"\+")):
        lj.optimise(chain, v_min, a_max, **args)


def test_bad_settings_raise():
    with pytest.raises(ValueError, match="local must be an int >= 1"):
        lj.ChainOptimiseSettings(local=0)
    with pytest.raises(TypeError, match="ChainOptimiseSettings"):
        lj.optimise(worm(), 0.05, 0.05, settings=lj.ExactOptimiseSettings())
