"""Resolution guards beyond `measure`/`simulate` of chains and the paper's model (issue 29):
steady gaits, a `Mechanism`'s own time scales, and the default measurement start.

One configuration is refused with a message naming the parameter; in a batch it is flagged
(`Status.UNRESOLVED`, `GaitStatus.UNRESOLVED`) and never run, and its batch-mates are bitwise
what they are in a batch where it is resolved."""

import math
from typing import Any

import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from locomotion_jax.model._scales import MAX_START_STEPS
from locomotion_jax.optimisation._optimum import ExactSettings


SHORT: dict[str, Any] = dict(z=0.1, t_start=1.0, horizon=5.0, window=2.0)
GAIT: dict[str, Any] = dict(periods=1, transient=5)
U = lj.Status.UNRESOLVED


def _same(a, b, rows, fields):
    for k in fields:
        np.testing.assert_array_equal(np.asarray(getattr(a, k))[rows], np.asarray(getattr(b, k))[rows], k)


# -- steady gaits ------------------------------------------------------------------------------


def test_steady_gait_refuses_an_unresolved_configuration():
    with pytest.raises(ValueError, match=r"Invalid parameter 'omega'.*omega=10000.*dt <= 0\.000157"):
        lj.steady_gait(lj.Params(omega=1e4), **GAIT)
    with pytest.raises(ValueError, match=r"Invalid parameter 'k'.*natural period 2\*pi/wn1"):
        lj.steady_gait(lj.Params(k=1e7), **GAIT)
    chain = lj.Chain(masses=[1.0, 1.0, 1.0], waveforms=lj.TravellingWave(0.05, 1e4, 1.0))
    with pytest.raises(ValueError, match=r"Invalid parameter 'omega'.*forcing period"):
        lj.steady_gait(chain, **GAIT)


def test_steady_gait_flags_it_in_a_batch_and_leaves_the_others_bitwise_equal():
    fields = ("status", "k", "mean_speed", "e_d", "u", "v1", "v2", "residual", "n_iter", "monodromy")
    g = lj.steady_gait(lj.Params(omega=jnp.array([2.0, 1e4, 3.0])), **GAIT)
    assert [int(s) for s in g.status] == [lj.GaitStatus.CONVERGED, lj.GaitStatus.UNRESOLVED, lj.GaitStatus.CONVERGED]
    assert int(g.n_iter[1]) == 0 and np.isnan(float(g.mean_speed[1]))  # never solved
    resolved = lj.steady_gait(lj.Params(omega=jnp.array([2.0, 5.0, 3.0])), **GAIT)
    _same(g, resolved, [0, 2], fields)


def test_chain_steady_gait_flags_it_in_a_batch_and_leaves_the_others_bitwise_equal():
    wave = lambda om: lj.TravellingWave(0.05, jnp.array(om), 1.0)
    g = lj.steady_gait(lj.Chain(masses=[1.0, 1.0, 1.0], waveforms=wave([2.0, 1e4])), **GAIT)
    assert [int(s) for s in g.status] == [lj.GaitStatus.CONVERGED, lj.GaitStatus.UNRESOLVED]
    resolved = lj.steady_gait(lj.Chain(masses=[1.0, 1.0, 1.0], waveforms=wave([2.0, 3.0])), **GAIT)
    _same(g, resolved, [0], ("status", "k", "mean_speed", "e_d", "state", "residual", "n_iter", "monodromy"))


def test_basins_inherit_the_gait_guard():
    # `basins` solves its starts as a batch of `steady_gait`: each is flagged, none solved.
    b = lj.basins(lj.Params(omega=1e4), np.array([[0.9, 0.0, 0.0], [1.0, 0.0, 0.0]]), **GAIT)
    assert [int(s) for s in np.asarray(b.per_start.status).reshape(-1)] == [lj.GaitStatus.UNRESOLVED] * 2


# -- a Mechanism's time scales -------------------------------------------------------------------


def _oscillator(k: Any = 1.0, omega: Any = 2.0, friction: Any = None) -> lj.Mechanism:
    """One body on a wall spring, pushed by an external sinusoidal force."""
    return lj.Mechanism(masses=[1.0], friction=friction or lj.Coulomb(0.7, 0.5),
                        links=[lj.Spring(0, lj.WALL, k=k), lj.ExternalForce(0, lj.Sinusoid(0.5, omega, 0.0))],
                        x0=[0.0], check=False)  # fmt: skip


def _scale(mech: lj.Mechanism, name: str) -> float:
    flat = mech.broadcast()
    flat = lj.Mechanism.stack([flat]) if flat.batch_shape == () else flat
    return float(np.asarray(next(s for s in flat.time_scales() if s.name == name).time)[0])


def test_mechanism_scales_match_closed_forms():
    # Two bodies, a spring between them and a wall spring on body 0: omega^2 solves
    # m0 m1 w^4 - (m0 k + m1 (k + kw)) w^2 + k kw = 0 (det(K - w^2 M) = 0).
    m0, m1, k, kw = 2.0, 0.5, 30.0, 7.0
    mech = lj.Mechanism(masses=[m0, m1], links=[lj.Spring(0, 1, k=k), lj.Spring(0, lj.WALL, k=kw),
                                                 lj.Force(0, 1, lj.Fourier(jnp.zeros(3), jnp.ones(3), 2.0, 0.0))],
                        c=[0.1, 0.4])  # fmt: skip
    b = m0 * k + m1 * (k + kw)
    w2 = (b + math.sqrt(b * b - 4 * m0 * m1 * k * kw)) / (2 * m0 * m1)
    assert _scale(mech, "k") == pytest.approx(2 * math.pi / math.sqrt(w2), rel=1e-12)
    assert _scale(mech, "omega") == pytest.approx(2 * math.pi / (3 * 2.0), rel=1e-15)  # third harmonic
    assert _scale(mech, "c") == pytest.approx(min(m0 / 0.1, m1 / 0.4), rel=1e-15)
    # Dampers by the rows of M^-1 C: a wall damper adds its c to its body's, a relative one 2c to each end.
    damped = lj.Mechanism(masses=[m0, m1], links=[lj.Spring(0, 1, k=k), lj.Damper(0, lj.WALL, 0.3),
                                                   lj.Damper(0, 1, 0.2)], c=[0.1, 0.4])  # fmt: skip
    assert _scale(damped, "c") == pytest.approx(min(m0 / (0.1 + 0.3 + 0.4), m1 / (0.4 + 0.4)), rel=1e-15)
    # A carried body's weight loads its carrier: (m_0 / N_0) v_s / mu_s with N_0 = m_0 + m_1.
    capsule = lj.Mechanism(masses=[1.0, 0.5], friction=[lj.Stribeck(0.7, 0.5, 0.02), None], carried_by=[None, 0],
                           links=[lj.Spring(0, 1, k=10.0), lj.Force(0, 1, lj.Sinusoid(0.6, 3.0, 0.0))])  # fmt: skip
    assert _scale(capsule, "v_s") == pytest.approx(1.0 / 1.5 * 0.02 / 0.7, rel=1e-15)


@pytest.mark.parametrize(
    "mech, pattern",
    [
        (
            _oscillator(k=1e7),
            r"Invalid parameter 'k'.*natural period 2\*pi/w_max of the free bodies.*k \(largest\)=1e\+07",
        ),
        (_oscillator(omega=1e4), r"Invalid parameter 'omega'.*forcing period.*omega=10000"),
        (_oscillator(friction=lj.Stribeck(0.7, 0.5, 1e-5)), r"Invalid parameter 'v_s'.*friction time.*of body 0"),
    ],
)
def test_an_unresolved_mechanism_is_refused(mech, pattern):
    with pytest.raises(ValueError, match=pattern):
        lj.measure(mech, **SHORT)
    with pytest.raises(ValueError, match=pattern):
        lj.simulate(mech, 1.0)


def test_a_waveform_of_your_own_is_resolved_at_its_fastest_harmonic():
    """A waveform class of a user's own (`mechanism_cases.Cubed`, $\\sin^3\\omega t$, which carries
    $3\\omega$ and says so) at omega = 100: dt = 0.01 resolves omega but not 3 omega, so a mechanism and
    a chain driven by it are refused, naming K = 3 and the step that would do; at that step they run."""
    from mechanism_cases import Cubed

    wave = Cubed(jnp.asarray(0.05), jnp.asarray(100.0), jnp.asarray(1.0))
    mech = lj.Mechanism(masses=[1.0, 1.0], friction=lj.Coulomb(0.7, 0.5), x0=[0.0, 1.0],
                        links=[lj.Spring(0, 1, k=10.0, rest=wave)])  # fmt: skip
    chain = lj.Chain(masses=[1.0, 1.0], d=0.0, waveforms=[wave])
    for m in (mech, chain):
        with pytest.raises(ValueError, match=r"Invalid parameter 'omega'.*K = 3.*Give Exact\(dt=0.0052\)"):
            lj.simulate(m, 0.5, dynamics=lj.Exact(dt=0.01))
        assert int(lj.simulate(m, 0.5, dynamics=lj.Exact(dt=0.0052)).status) == lj.Status.OK


def test_an_unresolved_mechanism_is_flagged_in_a_batch():
    fields = ("status", "n_steps", "tau_z", "mean_speed", "e_d", "balance")
    m = lj.measure(_oscillator(k=jnp.array([1.0, 1e7, 4.0])), **SHORT)
    assert [int(s) for s in m.status] == [lj.Status.OK, U, lj.Status.OK]
    assert int(m.n_steps[1]) == 0
    resolved = lj.measure(_oscillator(k=jnp.array([1.0, 2.0, 4.0])), **SHORT)
    _same(m, resolved, [0, 2], fields)
    tr = lj.simulate(_oscillator(k=jnp.array([1.0, 1e7])), 1.0)
    assert [int(s) for s in tr.status] == [lj.Status.OK, U]


# -- the default measurement start ----------------------------------------------------------------


def test_a_tiny_k_is_refused_naming_k_and_t_start():
    pattern = r"'t_start'.*Params.t_start.*= 5\.0\d*e\+12 \(k=1e-20.*more than 1e\+08.*explicit t_start="
    with pytest.raises(ValueError, match=pattern):
        lj.measure(lj.Params(k=1e-20), z=0.1, horizon=5.0, window=2.0)
    with pytest.raises(ValueError, match=r"'t_start'.*Chain.t_start.*k \(smallest\)=1e-20"):
        lj.measure(lj.Chain(masses=[1.0, 1.0, 1.0], k=jnp.array([1e-20, 1.0])), z=0.1, horizon=5.0, window=2.0)
    with pytest.raises(ValueError, match=r"'t_start'.*Mechanism.t_start.*omega=1e-12"):
        lj.measure(_oscillator(omega=1e-12), z=0.1, horizon=5.0, window=2.0)


def test_an_explicit_t_start_is_not_limited():
    m = lj.measure(lj.Params(k=1e-20), **SHORT)
    assert int(m.status) != U


def test_the_limit_is_on_the_steps():
    # Params(k).t_start = 80 * 2 pi / wmin with wmin = sqrt(k / max(m1, m2)) (m1 = m2 = 1 at mhat = 1/2),
    # against the documented bound of 1e8 steps.
    assert MAX_START_STEPS == 10**8
    k_edge = (80 * 2 * math.pi / (1e8 * 0.01)) ** 2
    for k, refused in ((k_edge * 0.9, True), (k_edge * 1.1, False)):
        flat = lj.Params(k=jnp.array([k]), mhat=jnp.array([0.5]))
        assert bool(np.asarray(flat.start_scale().exceeded(0.01))[0]) == refused
        assert bool(np.asarray(flat.start_scale().exceeded(0.1))[0]) == (k < k_edge / 100)


def test_a_tiny_k_is_flagged_in_a_batch_and_in_a_sweep():
    kw: dict[str, Any] = dict(z=0.1, horizon=5.0, window=2.0)
    m = lj.measure(lj.Params(k=jnp.array([1.0, 1e-20])), **kw)
    assert [int(s) for s in m.status][1] == U
    alone = lj.measure(lj.Params(k=jnp.array([1.0])), **kw)
    _same(m, alone, [0], ("status", "n_steps", "tau_z", "mean_speed", "e_d", "balance"))
    ds = lj.sweep(dict(k=np.array([1.0, 1e-20])), z=0.1, horizon=5.0, window=2.0, progress=False)
    assert ds.status.values.tolist()[1] == U and ds.status.values.tolist()[0] == int(m.status[0])


def test_every_measurement_path_asks_for_the_default_start(monkeypatch):
    # With the bound lowered to 1000 steps, the default starts of ordinary configurations (about
    # 5e4 steps at dt = 0.01) are refused or flagged, on every path that measures from them.
    from locomotion_jax.model import _scales

    monkeypatch.setattr(_scales, "MAX_START_STEPS", 1000)
    kw: dict[str, Any] = dict(z=0.1, horizon=5.0, window=2.0)
    with pytest.raises(ValueError, match=r"'t_start'.*Params.t_start"):
        lj.measure(lj.Params(), **kw)
    with pytest.raises(ValueError, match=r"'t_start'.*Chain.t_start"):
        lj.measure(lj.Chain(masses=[1.0, 1.0, 1.0]), **kw)
    ds = lj.sweep(dict(k=np.array([1.0, 2.0])), **kw, progress=False)
    assert ds.status.values.tolist() == [U, U]
    assert int(lj.measure(lj.Params(), **SHORT).status) != U  # an explicit start is not limited


# -- the optimisers' entry points ---------------------------------------------------------------


def test_optimisers_refuse_a_step_that_does_not_resolve_the_mechanism():
    # The paper's model: at mhat = 0.001 the natural period 2 pi / wn1 = 0.28 needs dt <= 0.07.
    with pytest.raises(ValueError, match=r"Invalid parameter 'k'.*natural period.*\(optimise: .*ExactSettings.dt"):
        lj.optimise(lj.Params(mhat=0.001), 1e-5, 1e-4, settings=ExactSettings(dt=0.1, margin=0.001))
    # A chain: the fastest stroke the search may reach (a given omega, with its 3 harmonics).
    with pytest.raises(ValueError, match=r"'omega'.*K = 3.*omega=10000.*\(optimise: omega = 10000 with 3 harmonics"):
        lj.optimise(lj.Chain(masses=[1.0, 1.0, 1.0]), 0.01, 0.05, omega=1e4)
    # A chain's spline search: its knots are resolved in the verification (`dt_exact`,
    # tests/test_optimise.py), its screen's single harmonics before the search (a stiff chain:
    # omega_max 1.2 times its highest natural frequency 173).
    spline = lj.ChainOptimiseSettings(shape="spline", knots=16)
    with pytest.raises(ValueError, match=r"'omega'.*K = 1\).*omega=207.8.*Give Exact\(dt=0.0075\).*single harmonics"):
        lj.optimise(lj.Chain(masses=[1.0, 1.0, 1.0], k=1e4, d=0.0), 0.01, 0.002, settings=spline)
    # A mechanism: a step that resolves not even the screen's slowest sinusoid (here the natural
    # period 2 pi / w_max = 0.115 of a stiff capsule spring) is refused before the search, naming it.
    links = [lj.Spring(0, 1, k=1000.0, rest=0.0), lj.Force(0, 1, lj.Sinusoid(a=0.6, omega=3.0, lbar=0.0))]
    capsule = lj.Mechanism(masses=[1.0, 0.5], friction=[lj.Coulomb(0.5, 0.4), None], carried_by=[None, 0], links=links)
    for settings, name in [(lj.MechanismOptimiseSettings(dt=0.1), "dt"),
                           (lj.MechanismOptimiseSettings(search_dt=0.1), "search_dt")]:  # fmt: skip
        with pytest.raises(
            ValueError, match=rf"Invalid parameter 'k'.*natural period.*MechanismOptimiseSettings.{name}\.\)"
        ):
            lj.optimise(capsule, 0.005, 0.8, direction=-1, settings=settings)


def test_resolved_step_is_the_step_the_guard_suggests():
    """`resolved_step`: `dt` where it resolves the configuration, else the step the guard's message
    suggests, which the guard then accepts (the paper's model with a 64-knot spline at the default
    optimum's frequency: knots 0.0173 apart need dt <= 0.00433; a stiff chain's natural period 0.0363)."""
    from locomotion_jax.optimisation._pareto import with_waveform_frequency
    from locomotion_jax.run._resolution import refuse_search, resolved_step

    M = 64
    wave = lj.Spline(0.02 * np.sin(2 * np.pi * np.arange(M) / M), 5.66327, 3.0)
    paper = with_waveform_frequency(lj.Params(), wave)
    stiff = lj.Chain(masses=[1.0, 1.0, 1.0], k=1e4)
    for mech, w, step in [(paper, wave, 0.0043), (stiff, None, 0.009)]:
        with pytest.raises(ValueError, match=rf"Give Exact\(dt={step}\)"):
            refuse_search(mech, w, 0.01, "")
        assert resolved_step(mech, w, 0.01) == step
        refuse_search(mech, w, step, "")  # accepted
        assert resolved_step(mech, w, 0.001) == 0.001


class _Stop(Exception):
    pass


def test_the_optimums_direct_simulation_steps_where_the_guard_asks(monkeypatch):
    """The exact optimisers' direct simulation (`_element_local.simulated`) steps at `dt`, or at
    the guard's step where `dt` does not resolve the optimum (a spline's knots, which the
    verification checks by a convergence study instead): it is never refused."""
    from locomotion_jax.optimisation import _element_local, _pareto
    from locomotion_jax.run import _simulate

    steps = []

    def record(model, t_end, save_at, dynamics, **kw):
        steps.append(dynamics.dt)
        raise _Stop

    monkeypatch.setattr(_simulate, "simulate", record)
    for M in (64, 8):
        wave = lj.Spline(0.02 * np.sin(2 * np.pi * np.arange(M) / M), 5.66327, 3.0)
        model = _pareto.with_waveform_frequency(lj.Params(), wave)
        with pytest.raises(_Stop):
            gait = (True, 0.05, 0.9, 0.5, 1.1)  # stable, speed, cost, largest multiplier, period
            _element_local.simulated(model, gait, ExactSettings(), start="relaxed", waveform=wave)
    assert steps == [0.0043, 0.01]


# -- continuation ----------------------------------------------------------------------------------


def test_continuation_checks_both_ends_of_its_range():
    with pytest.raises(ValueError, match=r"Invalid parameter 'omega'.*omega=10000"):
        lj.continuation(lj.Params(omega=4.0), "omega", 1e4, max_points=3, **GAIT)
    om = jnp.array([4.0, 4.0])
    b = lj.continuation(lj.Params(omega=om), "omega", jnp.array([4.5, 1e4]), max_points=3, periods=1, transient=30)
    status = [int(v) for v in np.asarray(b.status)]
    assert status[1] == lj.BranchStatus.UNRESOLVED and status[0] != lj.BranchStatus.UNRESOLVED
    assert int(np.asarray(b.n_points)[0]) > 0 and int(np.asarray(b.n_points)[1]) == 0
