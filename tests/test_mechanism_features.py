"""Every feature on a mechanism that is not a chain: the capsule robot of `mechanism_cases` (a shell
on anisotropic bristles carrying an internal mass on a spring, driven by an internal force),
continued, mapped into basins and fitted as a chain is (`tests/test_continuation.py`,
`tests/test_gait.py`, `tests/test_fit.py`), its elements named by their path (`"links[0].k"`)."""

import math

import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from locomotion_jax.gaits._continuation import BranchStatus
from locomotion_jax.optimisation import _element_local as local
from mechanism_cases import capsule, capsule_ref
from reference_mechanism import run


MECHANISM_GAIT = pytest.mark.xdist_group("mechanism_gait")  # the capsule's gait programs, on one worker


@MECHANISM_GAIT
def test_capsule_branch_in_its_spring_points_are_steady_gaits():
    """`continuation(capsule, "links[0].k", ...)` (two branches, two force amplitudes): every point
    is a steady gait, as `steady_gait` of the capsule at that stiffness, started on the point's state,
    finds it (state to 1e-9; speed, cost of transport, dissipation to 1e-8); the parameter moves
    towards `stop`; an element that is not there is refused by its path."""
    mech = capsule(a=jnp.array([0.6, 0.9]))
    b = lj.continuation(mech, "links[0].k", 11.0, max_points=5, step=0.25, max_step=0.5)
    assert b.names == "bodies" and b.state.shape[-1] == 3 and b.stick_fraction.shape[-1] == 2
    n = [int(q) for q in np.asarray(b.n_points)]
    assert min(n) >= 3 and set(np.asarray(b.status).tolist()) <= {BranchStatus.REACHED, BranchStatus.MAX_POINTS}
    for i in range(2):
        lam = np.asarray(b.lam[i, : n[i]])
        assert lam[0] == 10.0 and np.all(np.diff(lam) > 0), lam
    rows = [(0, n[0] - 1), (1, n[1] // 2)]
    pick = lambda x: np.stack([np.asarray(x[i, j]) for i, j in rows])
    g = lj.steady_gait(capsule(a=jnp.array([0.6, 0.9]), k=jnp.asarray(pick(b.lam))), start=pick(b.state),
                       periods=1, transient=0)  # fmt: skip
    assert np.all(np.asarray(g.status) == lj.GaitStatus.CONVERGED)
    np.testing.assert_allclose(np.asarray(g.state), pick(b.state), atol=1e-9)
    for name in ("mean_speed", "cost_of_transport", "e_d"):
        np.testing.assert_allclose(np.asarray(getattr(g, name)), pick(getattr(b, name)), rtol=1e-8, err_msg=name)
    with pytest.raises(ValueError, match=r"unknown parameter 'links\[5\].k' of a Mechanism"):
        lj.continuation(capsule(), "links[5].k", 11.0)


@MECHANISM_GAIT
def test_capsule_basins_end_on_its_gait():
    """`basins` of the capsule: its gait's section state, a nearby and a far start (the internal mass
    displaced and moving) all end on the one gait, whose speed `steady_gait` gives to 1e-9."""
    mech = capsule()
    gait = lj.steady_gait(mech)
    y = np.asarray(gait.state)
    starts = np.stack([y, y + np.array([0.05, -0.1, 0.1]), np.array([-0.4, 0.0, 0.5])])
    b = lj.basins(mech, starts)
    assert list(np.asarray(b.label)) == [0, 0, 0] and list(np.asarray(b.count)) == [3]
    np.testing.assert_allclose(float(b.gaits.mean_speed[0]), float(gait.mean_speed), rtol=1e-9)
    np.testing.assert_allclose(float(b.gaits.cost_of_transport[0]), float(gait.cost_of_transport), rtol=1e-9)
    with pytest.raises(ValueError, match=r"starts must have shape grid \+ \(3,\)"):
        lj.basins(mech, np.zeros((2, 5)))


@MECHANISM_GAIT
def test_a_capsule_stuck_all_period_does_not_move():
    """The capsule driven too weakly to break its shell away (a = 0.05: the force on the shell stays
    far below $\\mu_{s,\\mathrm{bwd}} (m_0 + m_1) g = 0.3$) sticks all period: its gait dissipates
    nothing and its centre of mass returns to within rounding (the carried mass swings). Its cost of
    transport is inf, a gait that does not move, not 0 / rounding = 0 (the mechanism optimiser's
    direct-simulation check of it divided by that 0); beside it in the batch, the capsule of a = 0.6 is as alone. The
    optimum's direct-simulation check of a gait that does not move reports an infinite cost and a
    NaN agreement (given the gait's speed 0, it divided by it)."""
    gaits = lj.steady_gait(capsule(a=jnp.array([0.05, 0.6])))
    alone = lj.steady_gait(capsule(a=0.6))
    assert bool(gaits.converged[0]) and float(gaits.stick_fraction[0, 0]) > 1 - 1e-12
    assert float(gaits.e_d[0]) == 0.0 and abs(float(gaits.mean_speed[0])) < 1e-12
    assert float(gaits.cost_of_transport[0]) == math.inf
    np.testing.assert_allclose(float(gaits.cost_of_transport[1]), float(alone.cost_of_transport), rtol=1e-12)
    gait = (True, 0.0, math.inf, 0.5, float(gaits.period[0]))
    sim = local.simulated(capsule(a=0.05), gait, lj.MechanismOptimiseSettings(), periods=2)
    assert sim["cost_of_transport_simulated"] == math.inf and math.isnan(sim["simulation_agreement"])
    assert abs(sim["mean_speed_simulated"]) < 1e-3  # the carried mass's own swing, which nothing damps


def test_fit_of_the_capsules_spring_and_friction():
    """`fit_trajectory` of the capsule's spring and its shell's forward kinetic friction (elements
    named by path) to positions from the independent reference with noise 1e-4, from 3 % off:
    within 4 standard errors of the truth, the noise level recovered."""
    sigma = 1e-4
    t = np.linspace(0.1, 15.0, 150)
    ref = run(capsule_ref(0.6, 10.0, 3.0, [0.0, 0.0], [0.0, 0.0]), 15.0, t)
    rng = np.random.default_rng(5)
    x = np.asarray(ref["x"]) + sigma * rng.standard_normal((t.size, 2))
    law = (0.5, 0.2, 0.4 * 1.03, 0.15)
    names = ("links[0].k", "friction[0].mu_k_fwd")
    fit = lj.fit_trajectory(t, x, capsule(k=10.3, law=law), names)
    assert fit.success and fit.status == lj.Status.OK, fit.message
    assert fit.names == names
    truth = np.array([10.0, 0.4])
    assert np.all(np.abs(fit.values - truth) < 4 * fit.stderr), (fit.values, fit.stderr)
    assert np.all(fit.stderr / truth < 1e-2), fit.stderr / truth
    assert abs(fit.sigma / sigma - 1) < 0.2, fit.sigma
    assert float(fit.params.links[0].k) == fit.values[0]
    with pytest.raises(ValueError, match=r"'links\[7\].k': 'links' has items 0..1"):
        lj.fit_trajectory(t, x, capsule(), ("links[7].k",))
    with pytest.raises(ValueError, match=r"'friction.mu_k_fwd' is not a field of the Mechanism"):
        lj.fit_trajectory(t, x, capsule(), ("friction.mu_k_fwd",))


def test_jacfwd_of_the_capsules_speed_in_its_spring():
    """`jax.jacfwd` of `measure`'s mean speed in the spring constant through the events, against
    central differences of the independent reference (h = 1e-4): relative 2e-5 (the step dt = 0.01
    leaves 7e-6)."""

    def speed(k):
        return lj.measure(capsule(k=k), z=1e9, horizon=6 * np.pi, t_start=4 * np.pi).mean_speed

    d = float(jax.jacfwd(speed)(jnp.asarray(10.0)))

    def ref_speed(k):
        r = run(capsule_ref(0.6, k, 3.0, [0.0, 0.0], [0.0, 0.0]), 10 * np.pi, np.array([4 * np.pi, 10 * np.pi]))
        return (r["com"][1] - r["com"][0]) / (6 * np.pi)

    h = 1e-4
    fd = (ref_speed(10.0 + h) - ref_speed(10.0 - h)) / (2 * h)
    print(f"d speed / dk: jacfwd {d:.10f}, reference central difference {fd:.10f}")
    assert abs(d - fd) < 2e-5 * max(abs(fd), 1e-3)
