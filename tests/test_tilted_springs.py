"""Tilted springs in a mechanism (`lj.TiltedSpring`, SPEC §9): between neighbours they are the chain's
springs (SPEC §8, §10), which the independent chain references check; between any bodies, to a wall and
on carried bodies, against the independent mechanism reference (`tests/reference_mechanism.py`, its
tilted springs written from the spec); bad input named."""

import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest


pytestmark = pytest.mark.xdist_group("tilted")

LAW = lj.AnisotropicCoulomb(0.5, 0.9, 0.3, 0.7)
U = float(np.sqrt(3.0**2 - 0.5**2))  # the relaxed gap of a spring of rest length 3 and offset 0.5


@pytest.mark.parametrize("contact, a", [("strict", 0.015), ("hop", 0.12)])
def test_tilted_springs_between_neighbours_are_the_chain(contact, a):
    """A mechanism of three bodies joined by tilted springs 0-1 and 1-2 (offset 0.5, rest lengths
    3 + a sin 7t and 3 + 0.7 a sin 7t) runs as the chain of the same springs from its relaxed gaps:
    positions, velocities, heights, normal forces and energies equal to 1e-10. Under `contact="hop"`
    (a = 0.12) the springs lift the bodies off, and the flights, landings and the tilted springs'
    pull along (u, d + y_b - y_a) are the chain's."""
    om = 7.0
    wave = lambda amp: lj.Fourier(jnp.array([0.0]), jnp.array([amp]), om, 3.0)
    chain = lj.Chain(masses=[1.0, 1.5, 0.8], k=50.0, d=0.5, lbar=3.0, c=0.01, friction=LAW,
                     waveforms=lj.SpringFourier(np.zeros((2, 1)), np.array([[a], [0.7 * a]]), om))  # fmt: skip
    mech = lj.Mechanism(masses=[1.0, 1.5, 0.8], friction=LAW, c=0.01, x0=[0.0, U, 2 * U],
                        links=[lj.TiltedSpring(0, 1, k=50.0, d=0.5, rest=wave(a)),
                               lj.TiltedSpring(1, 2, k=50.0, d=0.5, rest=wave(0.7 * a))])  # fmt: skip
    save = jnp.linspace(0.0, 8.0, 17)
    dyn = lj.Exact(dt=0.01)
    rc = lj.simulate(chain, 8.0, save_at=save, start="relaxed", contact=contact, dynamics=dyn)
    rm = lj.simulate(mech, 8.0, save_at=save, contact=contact, dynamics=dyn)
    assert int(rm.status) == int(rc.status) == lj.Status.OK
    fields = ["x", "v", "N", "e_d", "w", "e"] + (["y", "vy"] if contact == "hop" else [])
    for name in fields:
        np.testing.assert_allclose(np.asarray(getattr(rm, name)), np.asarray(getattr(rc, name)), rtol=0, atol=1e-10,
                                   err_msg=name)  # fmt: skip
    if contact == "hop":
        assert float(np.asarray(rm.y).max()) > 0.1  # the springs lift the bodies off
        np.testing.assert_array_equal(np.asarray(rm.n_land), np.asarray(rc.n_land))
        assert int(np.asarray(rm.n_land).sum()) > 10
    else:
        # The loads vary, and the worm moves.
        assert float(np.asarray(rm.N)[:, 2].min()) < 0.7 and float(np.asarray(rm.x)[-1, 0]) > 0.1


def test_bad_tilted_springs_are_named():
    """A tilted spring's stiffness must be positive and its offset finite; the message names the link."""
    links = lambda **kw: [lj.TiltedSpring(0, 1, **({"k": 2.0, "d": 0.3, "rest": 1.0} | kw))]
    with pytest.raises(ValueError, match=r"links\[0\] TiltedSpring\(0, 1\).*k.*k > 0"):
        lj.Mechanism(masses=[1.0, 1.0], friction=LAW, x0=[0.0, 1.0], links=links(k=0.0))
    with pytest.raises(ValueError, match=r"links\[0\] TiltedSpring\(0, 1\).*d.*finite"):
        lj.Mechanism(masses=[1.0, 1.0], friction=LAW, x0=[0.0, 1.0], links=links(d=np.inf))
    with pytest.raises(ValueError, match=r"TiltedSpring: a must be a body index"):
        lj.TiltedSpring(-1, 0)


X0 = float(np.sqrt(2.0**2 - 0.4**2))
X1 = X0 + float(np.sqrt(1.5**2 - 0.3**2))
X = [X0, X1, X1 + 0.2, X1 + 1.0]
R2 = float(np.hypot(0.2 + np.sqrt(1.5**2 - 0.3**2), 0.6))  # the spring 0-2's rest length: relaxed at the start
R3 = float(np.hypot(1.0, 0.5))
OMEGA = 2.0


def _topology(a: float) -> lj.Mechanism:
    """Body 0 (anisotropic Coulomb) tied to the wall by a tilted spring whose rest length is 2 + a sin 2t;
    body 1 tied to body 0 by a tilted spring of offset -0.3; body 2, carried by body 1, tied to body 0
    (not its neighbour) by a tilted spring whose vertical force lands on body 1's load, and to body 1 by
    a linear spring and a damper; a free body 3 tied to body 1 by a tilted spring (its vertical force
    borne by the line) and pushed by an external force."""
    F = lambda cos, sin, lbar: lj.Fourier(jnp.asarray(cos), jnp.asarray(sin), OMEGA, lbar)
    links = [lj.TiltedSpring(lj.WALL, 0, k=20.0, d=0.4, rest=F([0.0], [a], 2.0)),
             lj.TiltedSpring(0, 1, k=30.0, d=-0.3, rest=1.5),
             lj.TiltedSpring(0, 2, k=10.0, d=0.6, rest=F([0.05], [0.1], R2)),
             lj.TiltedSpring(1, 3, k=5.0, d=0.5, rest=F([0.0, 0.0], [0.0, 0.1], R3)),
             lj.Spring(1, 2, k=15.0, rest=0.2), lj.Damper(1, 2, c=0.05),
             lj.ExternalForce(3, F([0.05], [0.0], 0.0))]  # fmt: skip
    return lj.Mechanism(masses=[1.0, 1.2, 0.5, 0.3], c=[0.02, 0.01, 0.0, 0.0], x0=X, links=links,
                        friction=[lj.AnisotropicCoulomb(0.6, 0.9, 0.45, 0.7), lj.Coulomb(0.5, 0.4), None, None],
                        carried_by=[None, None, 1, None])  # fmt: skip


def _reference_topology(a: float, t_end: float, save: np.ndarray, hop: bool = False, x=X, v=(0.0,) * 4,
                        **kw) -> dict:  # fmt: skip
    """The independent reference's run of `_topology(a)` from positions `x` and velocities `v`."""
    from reference_mechanism import Body, run, Sig, System

    bodies = [Body(1.0, (0.6, 0.9, 0.45, 0.7), c=0.02, x0=x[0], v0=v[0]),
              Body(1.2, (0.5, 0.5, 0.4, 0.4), c=0.01, x0=x[1], v0=v[1]),
              Body(0.5, None, carrier=1, x0=x[2], v0=v[2]), Body(0.3, None, x0=x[3], v0=v[3])]  # fmt: skip
    tilted = [(-1, 0, 20.0, 0.4, Sig(2.0, (0.0,), (a,), OMEGA)), (0, 1, 30.0, -0.3, 1.5),
              (0, 2, 10.0, 0.6, Sig(R2, (0.05,), (0.1,), OMEGA)),
              (1, 3, 5.0, 0.5, Sig(R3, (0.0, 0.0), (0.0, 0.1), OMEGA))]  # fmt: skip
    system = System(bodies, springs=[(1, 2, 15.0, 0.2)], dampers=[(1, 2, 0.05)], tilted=tilted,
                    externals=[(3, Sig(0.0, (0.05,), (0.0,), OMEGA))])  # fmt: skip
    return run(system, t_end, save, hop=hop, **kw)


def test_tilted_springs_between_any_bodies_against_the_reference():
    """The topology of `_topology` (a = 0.02) against the independent reference over t = 0 ... 10:
    positions, velocities, e_d, w, e and the two ground bodies' normal loads (which the tilted springs
    move between 0.26 and 1.55) within 5e-8 at dt = 1/400 (measured 1.3e-8, velocities; positions
    2.4e-9), fourth order from dt = 1/100 (positions 5.7e-7 there); both ground bodies stick and slip;
    w = e_d + Delta e to 1e-6 at dt = 1/100 and 1e-9 at 1/400 (measured 9.0e-8 and 1.4e-10)."""
    save = np.linspace(0.0, 10.0, 201)
    ref = _reference_topology(0.02, 10.0, save)
    assert ref["status"] == "ok"
    errs = {}
    for dt in (1 / 100, 1 / 400):
        tr = lj.simulate(_topology(0.02), 10.0, save, dynamics=lj.Exact(dt=dt))
        assert int(tr.status) == lj.Status.OK
        pairs = {"x": (tr.x, ref["x"]), "v": (tr.v, ref["v"]), "e_d": (tr.e_d, ref["ed"]), "w": (tr.w, ref["w"]),
                 "e": (tr.e, ref["e"]), "N": (np.asarray(tr.N)[:, :2], ref["N"][:, :2])}  # fmt: skip
        errs[dt] = {k: float(np.abs(np.asarray(a) - b).max()) for k, (a, b) in pairs.items()}
        bal = float(np.abs(np.asarray(tr.w - tr.e_d - (tr.e - tr.e[0]))).max())
        print(dt, errs[dt], "balance", bal)
        assert bal < (1e-6 if dt == 1 / 100 else 1e-9)
    fine, coarse = errs[1 / 400], errs[1 / 100]
    assert max(fine.values()) < 5e-8, fine
    assert coarse["x"] / fine["x"] > 64, (coarse["x"], fine["x"])
    N = ref["N"][:, :2]
    assert np.ptp(N[:, 0]) > 0.3 and np.ptp(N[:, 1]) > 0.3
    still = np.asarray(ref["v"])[:, :2] == 0
    assert np.all(still.any(0)) and np.all((~still).any(0))


def test_a_tilted_spring_lifts_a_body_off_as_the_reference_does():
    """With a = 0.3 the wall's tilted spring pulls body 0 off the ground at t = 2.6: the strict reading
    stops there (`LIFTOFF`) at the reference's lift-off time to 1e-8 (measured 5.6e-10)."""
    ref = _reference_topology(0.3, 10.0, np.array([10.0]))
    tr = lj.simulate(_topology(0.3), 10.0, np.array([10.0]), dynamics=lj.Exact(dt=1 / 400))
    print("lift-off", float(tr.t_liftoff), ref["t_liftoff"])
    assert ref["status"] == "liftoff" and int(tr.status) == lj.Status.LIFTOFF
    assert abs(float(tr.t_liftoff) - ref["t_liftoff"]) < 1e-8


def test_the_optimiser_of_a_tilted_mechanism_against_the_chain_and_the_reference():
    """`lj.optimise` of the paper's model written as a mechanism (one tilted spring, k = 50, d = 0.5,
    rest length 3 + a Fourier series of 2 harmonics, stroke <= 0.05, speed >= 0.02): a feasible optimum
    cheaper than its best sinusoid; its steady gait is the chain's of the same waveform (1e-9), and one
    gait period of the independent reference from the gait's section state gives its speed and cost
    of transport to the engine's truncation error at dt = 0.01 (measured 6.5e-6), which shrinks with
    the step."""
    from reference_mechanism import Body, run, Sig, System

    u0 = float(np.sqrt(3.0**2 - 0.5**2))
    law = lj.Coulomb(0.7, 0.5)
    spring = lj.TiltedSpring(0, 1, k=50.0, d=0.5, rest=lj.Sinusoid(a=0.05, omega=3.0, lbar=3.0))
    mech = lj.Mechanism(masses=[1.0, 1.0], friction=law, c=0.01, x0=[0.0, u0], links=[spring])
    s = lj.MechanismOptimiseSettings(amplitudes=2, frequencies=4, local=1, max_iter=6, transient=30, dt=0.01)
    opt = lj.optimise(mech, v_min=0.02, a_max=0.05, harmonics=2, settings=s)
    print(opt.summary())
    assert opt.feasible_exact and opt.mean_speed_exact >= 0.02
    assert float(np.max(opt.stroke_exact)) <= 0.05 * (1 + 1e-12) and opt.simulation_agreement < 1e-6
    assert opt.cost_of_transport_exact < opt.sinusoid["cost_of_transport"]
    dyn = lj.Exact(dt=0.01)
    g = lj.steady_gait(opt.mechanism, periods=(1, 2), transient=30, dynamics=dyn)
    assert int(g.status) == lj.GaitStatus.CONVERGED
    assert abs(float(g.cost_of_transport) - opt.cost_of_transport_exact) < 1e-9
    cos, sin = np.asarray(opt.cos), np.asarray(opt.sin)
    chain = lj.Chain(masses=[1.0, 1.0], k=50.0, d=0.5, lbar=3.0, c=0.01, friction=law,
                     waveforms=lj.SpringFourier(cos, sin, opt.omega))  # fmt: skip
    gc = lj.steady_gait(chain, periods=(1, 2), transient=30, dynamics=dyn)
    np.testing.assert_allclose(np.asarray(gc.state), np.asarray(g.state), rtol=0, atol=1e-9)
    assert abs(float(gc.cost_of_transport) / opt.cost_of_transport_exact - 1) < 1e-9
    # One gait period from the section state: the reference, and the engine at dt and dt / 4.
    u, v = float(g.state[0]), np.asarray(g.state[1:], float)
    T = float(g.period)
    body = lambda x, w: Body(1.0, (0.7, 0.7, 0.5, 0.5), c=0.01, x0=x, v0=w)
    rest = Sig(3.0, tuple(cos[0]), tuple(sin[0]), opt.omega)
    ref = run(System([body(0.0, v[0]), body(u, v[1])], tilted=[(0, 1, 50.0, 0.5, rest)]), T, np.array([0.0, T]))
    assert ref["status"] == "ok"
    figures = lambda dX, ed: np.array([dX / T, ed / abs(dX)])
    want = figures(ref["com"][1] - ref["com"][0], ref["ed"][1])
    start = lj.Mechanism(masses=[1.0, 1.0], friction=law, c=0.01, x0=[0.0, u], v0=v, links=opt.mechanism.links)
    errs = []
    for step in (0.01, 0.0025):
        tr = lj.simulate(start, T, jnp.array([0.0, T]), dynamics=lj.Exact(dt=step))
        got = figures(float(tr.X[-1] - tr.X[0]), float(tr.e_d[-1]))
        errs.append(float(np.abs(got / want - 1).max()))
    print("speed and cost against the reference:", errs)
    assert errs[0] < 2e-5 and errs[1] < errs[0] / 8


def test_tilted_springs_lift_bodies_and_what_they_carry_as_the_reference_does():
    """Under `contact="hop"` (a = 0.3) the wall's spring lifts body 0 off at t = 2.6, and body 1 lifts
    off at t = 3.5 with body 2, which it carries, whose spring to body 0 pulls on both; each flies and
    lands twice by t = 10. Against the independent reference (`run(..., hop=True)`): every state
    variable within 2e-7 at dt = 1/400 (measured 9.1e-8), fourth order (16x down at 1/800), the same
    landings; the carried body's height is its carrier's; w = e_d + Delta e to 1e-9."""
    save = np.linspace(0.0, 10.0, 401)
    ref = _reference_topology(0.3, 10.0, save, hop=True)
    assert ref["status"] == "ok" and list(ref["n_landings"]) == [2, 2, 0, 0]
    assert ref["y"][:, 1].max() > 0.1 and np.array_equal(ref["y"][:, 2], ref["y"][:, 1])
    errs = []
    for dt in (1 / 400, 1 / 800):
        tr = lj.simulate(_topology(0.3), 10.0, save, contact="hop", dynamics=lj.Exact(dt=dt))
        assert int(tr.status) == lj.Status.OK and int(np.asarray(tr.n_land)) == 4
        assert np.array_equal(np.asarray(tr.y)[:, 2], np.asarray(tr.y)[:, 1])
        pairs = {"x": (tr.x, ref["x"]), "v": (tr.v, ref["v"]), "y": (tr.y, ref["y"]), "vy": (tr.vy, ref["vy"]),
                 "e_d": (tr.e_d, ref["ed"]), "w": (tr.w, ref["w"]), "e": (tr.e, ref["e"])}  # fmt: skip
        err = {k: float(np.abs(np.asarray(a) - b).max()) for k, (a, b) in pairs.items()}
        bal = float(np.abs(np.asarray(tr.w - tr.e_d - (tr.e - tr.e[0]))).max())
        print(dt, err, "balance", bal)
        assert bal < 1e-9
        errs.append(max(err.values()))
    assert errs[0] < 2e-7 and errs[0] / errs[1] > 10, errs


def test_the_reference_flags_a_run_it_cannot_finish():
    """The independent reference stops after `max_segments` integration segments (between events): a
    run cut short there is `"stalled"`, its rows end where it stopped, not `"ok"` with rows missing."""
    save = np.linspace(0.0, 10.0, 41)
    ref = _reference_topology(0.3, 10.0, save, hop=True, max_segments=5)
    assert ref["status"] == "stalled" and len(ref["x"]) < len(save) and ref["valid_until"] < 10.0
    assert _reference_topology(0.3, 1.0, save[:5], hop=True)["status"] == "ok"


def test_plastic_landings_pulled_straight_off_again_against_the_reference():
    """Two bodies on a tilted spring (the paper's model as a mechanism, omega = 9, a = 0.1) landing
    plastically (e = 0): at t = 13.54 body 0 lands where the spring still pulls it up, so it flies on
    at once from rest on the surface (the reference once looped there, landing at one instant until
    its segment cap: "stalled" at 13.54). To t = 20 both finish, with the same 46 landings; positions
    within 1e-5 at dt = 1/800 (measured 5.0e-7; 1e-8 to t = 10: the difference grows with the
    landings)."""
    from reference_mechanism import Body, run, Sig, System

    bodies = [Body(1.0, (0.7, 0.7, 0.5, 0.5)), Body(1.0, (0.7, 0.7, 0.5, 0.5), x0=2.96)]
    save = np.linspace(0.0, 20.0, 41)
    ref = run(System(bodies, tilted=[(0, 1, 50.0, 0.5, Sig(3.0, (0.0,), (0.1,), 9.0))]), 20.0, save, hop=True)
    mech = lj.Mechanism(masses=[1.0, 1.0], friction=lj.Coulomb(0.7, 0.5), x0=[0.0, 2.96], restitution=0.0,
                        links=[lj.TiltedSpring(0, 1, k=50.0, d=0.5, rest=lj.Sinusoid(0.1, 9.0, 3.0))])  # fmt: skip
    tr = lj.simulate(mech, 20.0, save, contact="hop", dynamics=lj.Exact(dt=1 / 800))
    err = float(np.abs(np.asarray(tr.x) - ref["x"]).max())
    print("landings", ref["n_landings"], int(np.asarray(tr.n_land)), "error", err)
    assert ref["status"] == "ok" and int(tr.status) == lj.Status.OK
    assert int(ref["n_landings"].sum()) == int(np.asarray(tr.n_land)) > 30
    assert err < 1e-5


def test_a_steady_gait_of_a_mechanism_tied_to_the_wall_by_a_tilted_spring():
    """A tilted spring to the wall anchors a mechanism: its steady gait's section state holds the bodies'
    positions (not their gaps from body 0 at x = 0). The gait of `_topology` (a = 0.02, strict) is a fixed
    point of the independent reference's period map: one period from its state returns to it within
    2e-5 (the engine's truncation error at dt = 0.01; measured 1.1e-6)."""
    g = lj.steady_gait(_topology(0.02), periods=(1, 2), transient=30, dynamics=lj.Exact(dt=0.01))
    assert int(g.status) == lj.GaitStatus.CONVERGED and int(g.k) == 1 and bool(g.stable)
    y = np.asarray(g.state)
    assert y.shape == (8,) and y[0] > 1.5  # x_0 .. x_3, v_0 .. v_3
    T = 2 * np.pi / OMEGA
    ref = _reference_topology(0.02, T, np.array([T]), x=y[:4], v=y[4:])
    end = np.concatenate([ref["x"][-1], ref["v"][-1]])
    print("reference period map residual", np.abs(end - y).max())
    assert ref["status"] == "ok" and np.abs(end - y).max() < 2e-5


def test_the_floquet_multipliers_of_a_hopping_capsule_against_the_reference():
    """A capsule (body 0 on anisotropic bristles, restitution 0.8) carrying body 1 on a spring and a
    damper, tied to the wall by a tilted spring of rest length 2 + sin(2t + 1.2): under `contact="hop"`
    its steady gait (3 periods, 4 landings) is in flight at the section. The carried body's height and
    vertical velocity are its carrier's, so its own coordinates of the section state add zero
    multipliers; the others are the eigenvalues of the independent reference's period map (Jacobian by
    central differences over the six coordinates x_0, x_1, v_0, v_1, y_0, w_0): within 1e-4 relative
    (measured 8.1e-6: the engine's truncation error at dt = 0.01 and the differences' error). The gait
    is a fixed point of the reference's map within 1e-4 (measured 1.8e-6)."""
    from reference_mechanism import Body, run, Sig, System

    x0 = float(np.sqrt(2.0**2 - 0.4**2))
    rest = lj.Fourier(jnp.asarray([np.sin(1.2)]), jnp.asarray([np.cos(1.2)]), 2.0, 2.0)
    links = [lj.TiltedSpring(lj.WALL, 0, k=20.0, d=0.4, rest=rest), lj.Spring(0, 1, k=15.0, rest=0.0),
             lj.Damper(0, 1, c=0.3)]  # fmt: skip
    law = (0.6, 0.9, 0.45, 0.7)
    capsule = lj.Mechanism(masses=[1.0, 0.5], c=[0.02, 0.0], x0=[x0, x0], links=links, restitution=[0.8, 0.0],
                           friction=[lj.AnisotropicCoulomb(*law), None], carried_by=[None, 0])  # fmt: skip
    g = lj.steady_gait(capsule, contact="hop", periods=(1, 2, 3, 4), transient=30, dynamics=lj.Exact(dt=0.01))
    assert int(g.status) == lj.GaitStatus.CONVERGED and int(g.k) == 3 and int(g.n_land) == 4
    y = np.asarray(g.state)  # x_0, x_1, v_0, v_1, y_0, y_1, w_0, w_1
    assert y[4] > 1 and y[5] == y[4] and y[7] == y[6]
    T = 3 * np.pi  # three periods of 2 pi / omega
    free = [0, 1, 2, 3, 4, 6]

    def period_map(z):
        bodies = [Body(1.0, law, c=0.02, x0=z[0], v0=z[2], y0=z[4], w0=z[5], e=0.8),
                  Body(0.5, None, carrier=0, x0=z[1], v0=z[3])]  # fmt: skip
        system = System(bodies, springs=[(0, 1, 15.0, 0.0)], dampers=[(0, 1, 0.3)],
                        tilted=[(-1, 0, 20.0, 0.4, Sig(2.0, (np.sin(1.2),), (np.cos(1.2),), 2.0))])  # fmt: skip
        r = run(system, T, np.array([T]), hop=True)
        assert r["status"] == "ok"
        return np.array([r["x"][-1, 0], r["x"][-1, 1], r["v"][-1, 0], r["v"][-1, 1], r["y"][-1, 0], r["vy"][-1, 0]])

    z = y[free]
    print("reference period map residual", np.abs(period_map(z) - z).max())
    assert np.abs(period_map(z) - z).max() < 1e-4
    eps = 1e-6
    J = np.stack([(period_map(z + eps * e) - period_map(z - eps * e)) / (2 * eps) for e in np.eye(6)], 1)
    want = np.sort(np.abs(np.linalg.eigvals(J)))[::-1]
    got = np.sort(np.abs(np.asarray(g.multipliers)))[::-1]
    print("multipliers", got, "reference", want)
    assert np.all(got[6:] < 1e-12)
    np.testing.assert_allclose(got[:6], want, rtol=1e-4, atol=1e-6)


def test_the_smoothed_model_of_tilted_springs_tends_to_the_exact_one():
    """`Smoothed` dynamics of the three bodies joined by tilted springs (the first driven, 3 + 0.05 sin 5t;
    their vertical forces move the loads): the positions approach the exact engine's as the smoothing
    width shrinks, 3.4e-2 at eps = 1e-2 and 7.0e-3 at eps = 1e-3 over t = 0 ... 10 (the smoothed
    friction's creep during the stick phases, of order eps)."""
    u0 = float(np.sqrt(3.0**2 - 0.5**2))
    law = lj.AnisotropicCoulomb(0.5, 0.9, 0.3, 0.7)
    links = [lj.TiltedSpring(0, 1, k=50.0, d=0.5, rest=lj.Sinusoid(a=0.05, omega=5.0, lbar=3.0)),
             lj.TiltedSpring(1, 2, k=50.0, d=0.5, rest=3.0)]  # fmt: skip
    mech = lj.Mechanism(masses=[1.0, 1.5, 0.8], friction=law, c=0.01, x0=[0.0, u0, 2 * u0], links=links)
    save = jnp.linspace(0.0, 10.0, 11)
    exact = np.asarray(lj.simulate(mech, 10.0, save, dynamics=lj.Exact(dt=0.005)).x)
    errs = []
    for eps in (1e-2, 1e-3):
        tr = lj.simulate(mech, 10.0, save, dynamics=lj.Smoothed(eps=eps))
        assert int(tr.status) == lj.Status.OK
        errs.append(float(np.abs(np.asarray(tr.x) - exact).max()))
    print("smoothed against exact:", errs)
    assert errs[1] < 0.015 and errs[0] / errs[1] > 3 and float(exact[-1, 0]) > 0.1
