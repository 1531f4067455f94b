"""`lj.Mechanism` (issue 26, SPEC §9): bodies with or without ground contact, walls, links between
any bodies, external forces; the classic friction oscillator against its exact solution, the
energy balance with every element, the routing through the front ends, and bad input."""

import math

import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from locomotion_jax.dynamics import _engine as engine
from locomotion_jax.dynamics._runs import chain_initial_state


def _oscillator(**kw) -> lj.Mechanism:
    """Siconos' friction oscillator (SPEC §9): m = 1, k = 1 to a wall at 0, friction bound 1."""
    return lj.Mechanism(masses=[1.0], friction=lj.Coulomb(1.0, 1.0), links=[lj.Spring(0, lj.WALL, k=1.0, rest=0.0)],
                        c=0.0, x0=[12.0], v0=[6.0], **kw)  # fmt: skip


def _steps(M: lj.Mechanism, t_end: float, dt: float, iters: int):
    """Every iteration's start (time, position, velocity, stuck) of one run on the N-body engine."""
    P = M.physics()

    @jax.jit
    def go(P):
        st = chain_initial_state(P, jnp.asarray(True), "strict", "paper")

        def body(s, _):
            s, info = engine.step(P, "strict", dt, s, jnp.asarray(t_end))
            return s, (info.t0, info.y0.x[0], info.y0.v[0], info.stuck[0])

        return jax.lax.scan(body, st, None, length=iters)

    return go(P)


def test_siconos_friction_oscillator_is_exact():
    """Turning points $x_n = (-1)^n(\\sqrt{205} - 1 - 2n)$ at $t_n = \\arctan(6/13) + n\\pi$; the mass
    sticks for good at $x^* = 15 - \\sqrt{205}$, $t^* = \\arctan(6/13) + 7\\pi$: within 1e-9 (float64),
    positions and times at the located events (a turning point is the switch of a slipping body
    whose velocity reached zero: the step after it starts with $v$ set exactly to 0)."""
    t1 = math.atan(6 / 13)
    x_turn = np.array([(-1) ** n * (math.sqrt(205) - 1 - 2 * n) for n in range(8)])
    t_turn = t1 + np.pi * np.arange(8)
    assert x_turn[-1] == pytest.approx(15 - math.sqrt(205), abs=1e-14)
    final, (t, x, v, stuck) = _steps(_oscillator(), 30.0, 0.001, 40_000)
    t, x, v, stuck = (np.asarray(q) for q in (t, x, v, stuck))
    assert int(final.status) == lj.Status.OK and float(final.t) == pytest.approx(30.0)
    turn = np.flatnonzero((v[1:] == 0) & (v[:-1] != 0)) + 1
    assert turn.size == 8
    err_t, err_x = np.abs(t[turn] - t_turn).max(), np.abs(x[turn] - x_turn).max()
    # The stop: stuck from the last turning point on, at rest there to the end.
    t_stop = t[turn[-1]]
    assert bool(stuck[turn[-1]]) and bool(final.stuck[0]) and not stuck[turn[:-1]].any()
    err_end = abs(float(final.y.x[0]) - (15 - math.sqrt(205)))
    print(f"friction oscillator: |t_n - exact| <= {err_t:.2e}, |x_n - exact| <= {err_x:.2e}, "
          f"stop time {abs(t_stop - t_turn[-1]):.2e}, rest position {err_end:.2e}")  # fmt: skip
    assert err_t < 1e-9 and err_x < 1e-9 and err_end < 1e-9 and float(final.y.v[0]) == 0.0


def test_the_issues_calls():
    """`simulate` of the oscillator gives `x` of shape (T, 1); the capsule runs in `simulate` and `measure`."""
    osc = _oscillator()
    traj = lj.simulate(osc, t_end=30.0, save_at=jnp.linspace(0.0, 30.0, 3001))
    assert traj.x.shape == (3001, 1) and int(traj.status) == lj.Status.OK
    assert float(traj.x[-1, 0]) == pytest.approx(15 - math.sqrt(205), abs=1e-8)
    assert bool(traj.stuck[-1, 0]) and traj.tension is not None and traj.tension.shape == (3001, 1)
    capsule = _capsule()
    ts = jnp.linspace(0.0, 40.0, 81)
    traj = lj.simulate(capsule, t_end=40.0, save_at=ts)
    assert traj.x.shape == (81, 2) and int(traj.status) == lj.Status.OK
    m = lj.measure(capsule, z=1.0, t_start=50.0)
    assert int(m.status) == lj.Status.OK and np.isfinite(float(m.mean_speed)) and m.stick_fraction.shape == (2,)
    assert float(m.stick_fraction[1]) == 0.0  # a carried body never sticks
    assert abs(float(m.balance)) < 1e-6 * max(1.0, abs(float(m.work)))


def _capsule(**kw) -> lj.Mechanism:
    return lj.Mechanism(
        masses=[1.0, 0.5], friction=[lj.AnisotropicCoulomb(0.5, 0.2, 0.4, 0.15), None], carried_by=[None, 0],
        links=[lj.Spring(0, 1, k=10.0, rest=0.0), lj.Force(0, 1, lj.Sinusoid(a=0.6, omega=3.0, lbar=0.0)),
               lj.ExternalForce(0, lj.Fourier([0.0, 0.1], [0.0, 0.0], 3.0, 0.0))],
        c=0.0, x0=[0.0, 0.0], v0=[0.0, 0.0], **kw,
    )  # fmt: skip


def test_energy_balance_with_every_element():
    """$w = e_d + \\Delta e$ at every save (SPEC §9): a wall spring with an actuated rest length, a
    spring and an internal force between non-neighbours, an external force, a carried body on a
    carried body, ground damping, a free body; and the carried weights load the carrier."""
    wave = lj.Fourier([0.05, 0.02], [0.3, -0.1], 2.0, 1.0)
    M = lj.Mechanism(
        masses=[1.0, 0.4, 0.3, 0.8, 0.2], friction=[lj.AnisotropicCoulomb(0.6, 0.4, 0.5, 0.3), None, None,
                                                    lj.Coulomb(0.5, 0.3), None],
        carried_by=[None, 0, 1, None, None], c=[0.05, 0.0, 0.0, 0.02, 0.01],
        links=[lj.Spring(lj.WALL, 0, k=3.0, rest=wave), lj.Spring(0, 1, k=8.0, rest=0.1), lj.Spring(1, 2, k=5.0),
               lj.Spring(0, 3, k=2.0, rest=2.0), lj.Spring(3, 4, k=1.0, rest=0.5),
               lj.Force(2, 0, lj.Sinusoid(0.8, 2.0, 0.1)), lj.ExternalForce(3, lj.Sinusoid(0.4, 2.0, -0.05)),
               lj.Force(lj.WALL, 4, 0.02)],
        x0=[0.5, 0.6, 0.7, 2.4, 3.0], v0=[0.0, 0.3, -0.2, 0.0, 0.0],
    )  # fmt: skip
    P = M.physics()
    assert [float(q) for q in P.normal] == pytest.approx([1.7, 1.0, 1.0, 0.8, 1.0])  # 1 + 0.4 + 0.3; 1: no contact
    traj = lj.simulate(M, t_end=30.0, save_at=jnp.linspace(0.0, 30.0, 301))
    assert int(traj.status) == lj.Status.OK
    bal = np.asarray(traj.w - traj.e_d - (traj.e - traj.e[0]))
    print("energy balance, every element:", np.abs(bal).max(), "of w range", float(np.ptp(np.asarray(traj.w))))
    assert np.abs(bal).max() < 5e-7  # RK4 at dt = 0.01: 7e-8 seen
    assert float(traj.e_d[-1]) > 0 and np.ptp(np.asarray(traj.w)) > 0.1
    assert not np.asarray(traj.stuck)[:, [1, 2, 4]].any()


def test_free_body_under_a_constant_force():
    """A free body (no contact, not carried) under a constant external force: $x = x_0 + v_0 t + g t^2/(2m)$."""
    M = lj.Mechanism(masses=[2.0], friction=[None], links=[lj.ExternalForce(0, 0.5)], x0=[1.0], v0=[-1.0])
    ts = jnp.linspace(0.0, 10.0, 11)
    traj = lj.simulate(M, t_end=10.0, save_at=ts)
    exact = 1.0 - ts + 0.125 * ts**2
    np.testing.assert_allclose(np.asarray(traj.x[:, 0]), np.asarray(exact), atol=1e-10)


def test_batches_and_an_invalid_configuration():
    """A batch (a spring stiffness per configuration) runs as each alone; an invalid one
    (`k <= 0`, `check=False`) is flagged INVALID and the others run."""
    k = jnp.array([10.0, -1.0, 4.0])
    M = lj.Mechanism(masses=[1.0, 0.5], friction=[lj.Coulomb(0.5, 0.4), None], carried_by=[None, 0],
                     links=[lj.Spring(0, 1, k=k), lj.Force(0, 1, lj.Sinusoid(0.6, 3.0, 0.0))], check=False)  # fmt: skip
    assert M.batch_shape == (3,) and np.asarray(M.is_valid()).tolist() == [True, False, True]
    ts = jnp.linspace(0.0, 10.0, 11)
    traj = lj.simulate(M, t_end=10.0, save_at=ts)
    assert [int(s) for s in traj.status] == [lj.Status.OK, lj.Status.INVALID, lj.Status.OK]
    alone = lj.simulate(M[2], t_end=10.0, save_at=ts)
    np.testing.assert_allclose(np.asarray(traj.x[2]), np.asarray(alone.x), rtol=1e-12, atol=1e-12)
    stacked = lj.Mechanism.stack([M[0], M[2]])
    assert stacked.batch_shape == (2,)
    with pytest.raises(ValueError, match=r"'k' of links\[0\] Spring\(0, 1\) at batch index \(1,\)"):
        M.validate()


def test_a_batch_flags_one_bad_wall_spring_and_runs_the_others():
    """A wall spring's stiffness per configuration, one `k <= 0` (`check=False`): `measure` flags it
    INVALID with NaN figures and the others equal their runs alone."""
    k = jnp.array([1.0, 0.0, 2.0])
    M = lj.Mechanism(masses=[1.0], friction=lj.Coulomb(1.0, 1.0), links=[lj.Spring(0, lj.WALL, k=k, rest=0.0),
                     lj.ExternalForce(0, lj.Sinusoid(2.5, 1.5, 0.0))], x0=[1.0], check=False)  # fmt: skip
    assert np.asarray(M.is_valid()).tolist() == [True, False, True]
    with pytest.raises(ValueError, match=r"'k' of links\[0\] Spring\(0, WALL\) at batch index \(1,\)"):
        M.validate()
    m = lj.measure(M, z=1.0, t_start=5.0, horizon=10.0, window=10.0)
    assert [int(s) for s in m.status] == [lj.Status.OK, lj.Status.INVALID, lj.Status.OK]
    assert np.isnan(float(m.e_d[1])) and np.isfinite(np.asarray(m.e_d)[[0, 2]]).all()
    for i in (0, 2):
        alone = lj.measure(M[i], z=1.0, t_start=5.0, horizon=10.0, window=10.0)
        assert float(m.e_d[i]) == pytest.approx(float(alone.e_d), rel=1e-12, abs=1e-14)
        assert float(m.mean_speed[i]) == pytest.approx(float(alone.mean_speed), rel=1e-12, abs=1e-14)


@pytest.mark.parametrize("initial", [([0.0], [0.0, 0.0]), ([0.0, 0.0], [0.0, 0.0, 0.0]), ([0.0, 0.0, 1.0], 0.0)])
def test_an_initial_state_of_the_wrong_length_is_refused(initial):
    """`initial=(x, v)` of a mechanism: one value per body (or a scalar for all), in `simulate` and `measure`."""
    with pytest.raises(ValueError, match=r"initial [xv] has shape \(\d,\).*its last axis must have length 2"):
        lj.simulate(_capsule(), t_end=1.0, initial=initial)
    with pytest.raises(ValueError, match=r"initial [xv] has shape \(\d,\).*its last axis must have length 2"):
        lj.measure(_capsule(), z=1.0, initial=initial)


def test_chain_path_unchanged_for_a_chain():
    """`Chain` still runs (its `gaps` are its neighbours': an initial state out of order is refused)."""
    C = lj.Chain(masses=[1.0, 1.0], waveforms=lj.TravellingWave(0.05, 2.0, 0.0))
    with pytest.raises(ValueError, match="in order along the chain"):
        lj.simulate(C, t_end=1.0, initial=([1.0, 0.0], [0.0, 0.0]))


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(masses=[1.0, 1.0], friction=[lj.Coulomb(), None], carried_by=[None, 1]), "body 1 is carried by itself"),
        (dict(masses=[1.0, 1.0, 1.0], friction=[lj.Coulomb(), None, None], carried_by=[None, 2, 1]),
         r"bodies \[1, 2\] carry each other in a loop"),
        (dict(masses=[1.0, 1.0], friction=[lj.Coulomb(), None], carried_by=[None, 5]),
         "body 1 is carried by 5, which is not a body"),
        (dict(masses=[1.0, 1.0], friction=[lj.Coulomb(), lj.Coulomb()], carried_by=[None, 0]),
         "body 1 is carried by body 0 .* has a friction law"),
        (dict(masses=[1.0, 1.0], friction=[None, None], carried_by=[None, 0]),
         "body 1 is carried by body 0, which does not touch the ground"),
        (dict(masses=[1.0, 1.0], links=[lj.Spring(0, 2, k=1.0)]), r"links\[0\] Spring\(0, 2\): body 2 does not exist"),
        (dict(masses=[1.0, 1.0], links=[lj.Force(0, 3, lj.Sinusoid(1.0, 2.0, 0.0))]),
         r"links\[0\] Force\(0, 3\): body 3 does not exist \(the mechanism has bodies 0 to 1\)"),
        (dict(masses=[1.0, 1.0], links=[lj.ExternalForce(4, 0.5)]),
         r"links\[0\] ExternalForce\(4\): body 4 does not exist"),
        (dict(masses=[1.0, 1.0], friction=[lj.Coulomb(), None], carried_by=[None, 0, 1]),
         r"carried_by: one entry per body \(2\), got 3"),
        (dict(masses=[1.0], links=[lj.Spring(0, lj.WALL, k=0.0)]),
         r"Invalid parameter 'k' of links\[0\] Spring\(0, WALL\): got k=0.0; the valid range is k > 0"),
        (dict(masses=[1.0], links=[lj.Spring(0, lj.WALL, k=-2.0)]), r"'k' of links\[0\] Spring\(0, WALL\)"),
        (dict(masses=[1.0, 1.0], x0=[0.0, 1.0, 2.0]), "'x0': its last axis must have length 2"),
        (dict(masses=[1.0, 1.0], v0=[0.0]), "'v0': its last axis must have length 2"),
        (dict(masses=[1.0, 1.0], links=[lj.Spring(1, 1)]), r"Spring\(1, 1\): joins body 1 to itself"),
        (dict(masses=[1.0, 1.0], links=[lj.Force(0, 1, lj.Sinusoid(1.0, 2.0, 0.0)),
                                        lj.ExternalForce(1, lj.Sinusoid(1.0, 3.0, 0.0))]),
         r"links\[1\] ExternalForce\(1\): its waveform's omega=3.0 differs"),
        (dict(masses=[1.0, 1.0], links=[lj.Force(0, 1, lj.Sinusoid(1.0, math.nan, 0.0)),
                                        lj.ExternalForce(1, lj.Sinusoid(1.0, math.nan, 0.0))]),
         r"Invalid parameter 'omega' of links\[0\] Force\(0, 1\): got omega=nan"),
        (dict(masses=[1.0, -1.0]), "Invalid parameter 'masses' of body 1: got masses=-1.0"),
        (dict(masses=[1.0, 1.0], links=[lj.TiltedSpring(0, 1, k=1.0, rest=1.0)], x0=[1.0, 0.5]),
         r"'x0\[1\] - x0\[0\]' of links\[0\] TiltedSpring\(0, 1\): got x0\[1\] - x0\[0\]=-0.5; the valid range is > 0 "
         r"where d = 0 \(a horizontal tilted spring keeps body 1 ahead of body 0"),
        (dict(masses=[1.0], links=[lj.TiltedSpring(0, lj.WALL, k=1.0)], x0=[0.0]),
         r"'0 - x0\[0\]' of links\[0\] TiltedSpring\(0, WALL\): got 0 - x0\[0\]=0.0"),
        (dict(masses=[1.0], friction=[lj.Coulomb(0.3, 0.5)]), "'mu_s' of Coulomb of body 0"),
    ],
)  # fmt: skip
def test_bad_input_names_the_element_and_the_body(kwargs, message):
    with pytest.raises(ValueError, match=message):
        lj.Mechanism(**kwargs)


def test_smoothed_friction_oscillator_comes_to_rest_at_the_known_point():
    # Siconos' oscillator (SPEC §9) on the smoothed dynamics: at t = 30 (after t* = 22.4) the mass
    # rests near x* = 15 - sqrt(205), within about 6 eps (it creeps at a few eps below the static limit).
    for eps in (1e-2, 1e-3):
        tr = lj.simulate(_oscillator(), t_end=30.0, save_at=np.array([0.0, 30.0]), dynamics=lj.Smoothed(eps=eps))
        assert int(tr.status) == lj.Status.OK
        assert abs(float(tr.x[-1, 0]) - (15 - np.sqrt(205))) < 10 * eps
        assert abs(float(tr.v[-1, 0])) < 3 * eps
        # w = e_d + (e - e0) relative to the initial energy (90), to the solver's tolerance (rtol 1e-7)
        assert abs(float(tr.w[-1] - tr.e_d[-1] - (tr.e[-1] - tr.e[0]))) < 1e-6 * float(tr.e[0])


def test_each_mechanism_describes_itself_and_checks_its_given_section_states():
    """The front ends ask the mechanism, not its type: its label (the command line), its record's
    attributes (a sweep's `attrs`) and whether a given section state is one of its states."""
    chain = lj.Chain(masses=np.ones(3), friction=lj.AnisotropicCoulomb(0.5, 0.2, 0.4, 0.15),
                     waveforms=lj.TravellingWave(0.05, 3.0, 1.0))  # fmt: skip
    assert chain.describe() == "chain of 3 masses, AnisotropicCoulomb friction, RestLength actuator"
    assert chain.attributes() == {"kind": "chain", "friction": "AnisotropicCoulomb", "actuator": "RestLength"}
    capsule = _capsule()
    assert capsule.describe() == "mechanism of 2 bodies (1 carried), 3 links"
    assert capsule.attributes()["kind"] == "mechanism" and capsule.attributes()["friction"].endswith(", none")
    assert lj.Params().describe() == "the paper's two-mass model" and lj.Params().attributes() == {"kind": "paper"}
    with pytest.raises(ValueError, match=r"start: the gaps u_j must be > 0"):
        chain.check_section(np.array([0.1, -0.1, 0.0, 0.0, 0.0]))
    chain.check_section(np.array([0.1, 0.2, 0.0, 0.0, 0.0]))
    capsule.check_section(np.array([-0.3, 0.0, 0.0]))  # the carried body passes its rest point in the shell


def test_a_state_that_overflows_is_a_failure_not_ok():
    """A spring stretched by 1e300 (a finite, valid position) has an energy beyond float64: the run
    is `SOLVER_FAILED`, with its saves from there not valid, never `OK` with NaN figures; its mate
    in the batch runs as alone (found by the mechanisms' fuzz)."""
    x0 = jnp.array([[0.0, -1e300], [0.0, -1.0]])
    mech = lj.Mechanism(masses=[1.0, 1.0], friction=lj.Coulomb(0.5, 0.4), links=[lj.Spring(0, 1, k=1.0)], x0=x0)
    m = lj.measure(mech, z=0.1, t_start=0.5, horizon=3.0, window=1.0)
    alone = lj.measure(mech[1], z=0.1, t_start=0.5, horizon=3.0, window=1.0)
    assert [int(s) for s in m.status] == [lj.Status.SOLVER_FAILED, lj.Status.OK]
    assert float(m.e_d[1]) == float(alone.e_d) and np.isfinite(float(alone.balance))
    tr = lj.simulate(mech, 2.0, save_at=jnp.linspace(0.0, 2.0, 5))
    assert [int(s) for s in tr.status] == [lj.Status.SOLVER_FAILED, lj.Status.OK]
    valid = np.asarray(tr.valid)
    assert valid[1].all() and np.isfinite(np.asarray(tr.e)[valid]).all()
    # The paper's model started there too (its own trajectory fields).
    p = lj.Params(omega=jnp.array([2.0, 2.0]))
    start = (jnp.zeros(2), jnp.zeros(2), jnp.array([1e300, 3.0]), jnp.zeros(2))
    for out in (lj.simulate(p, 2.0, save_at=jnp.linspace(0.0, 2.0, 5), initial=start),
                lj.measure(p, z=0.1, t_start=0.5, horizon=3.0, window=1.0, initial=start)):  # fmt: skip
        assert [int(s) for s in out.status] == [lj.Status.SOLVER_FAILED, lj.Status.OK]
