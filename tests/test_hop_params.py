"""The paper's model (`Params`) under `contact="hop"` (SPEC §10, issue 27): `measure` and `simulate`
run it on the N-body engine as `Chain.from_params`, return the two-mass fields with the hopping ones
(per mass), agree with the independent reference `tests/reference_hop.py`, equal the strict reading
where nothing lifts off, and flag one bad configuration of a batch without touching the others."""

import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from reference_hop import paper_config, reference_hop_simulate
from test_against_reference import CASES as TWO_MASS_CASES, GROUPS


DT = 1.0 / 800


def _grid() -> lj.Params:
    """A (2, 3) grid through the lift-off band: no lift-off (omega 2), small hops (9 and 12), both a."""
    omega = jnp.asarray([[2.0, 9.0, 12.0], [2.0, 9.0, 12.0]])
    a = jnp.asarray([[0.05, 0.05, 0.05], [0.08, 0.08, 0.08]])
    return lj.Params(omega=omega, a=a, d=0.25)


def test_params_hop_equals_chain_from_params_exactly():
    """`simulate` and `measure` of a (2, 3) grid of `Params` under "hop" equal those of
    `Chain.from_params` of the same grid bit for bit (same physics, same engine), field by field;
    the hopping fields have one entry per mass and no NaN on the runs that measured."""
    p = _grid()
    ts = np.linspace(0.0, 20.0, 81)
    a = lj.simulate(p, t_end=20.0, save_at=ts, contact="hop")
    b = lj.simulate(lj.Chain.from_params(p), t_end=20.0, save_at=ts, contact="hop")
    assert a.y is not None and b.y is not None and a.n_land is not None and b.n_land is not None
    assert a.y.shape == (2, 3, 81, 2) and a.n_land.shape == (2, 3)
    pairs = {"x1": b.x[..., 0], "v1": b.v[..., 0], "x2": b.x[..., 1], "v2": b.v[..., 1], "y": b.y, "vy": b.vy,
             "e_d": b.e_d, "w": b.w, "e": b.e, "X": b.X, "N1": b.N[..., 0], "N2": b.N[..., 1],
             "l0": b.rest_length[..., 0],
             "status": b.status, "n_land": b.n_land, "zeno": b.zeno, "t_liftoff": b.t_liftoff}  # fmt: skip
    for k, want in pairs.items():  # the engine's states bit for bit; the derived fields to rounding
        if k in ("e", "X", "N1", "N2", "l0"):
            np.testing.assert_allclose(np.asarray(getattr(a, k)), np.asarray(want), rtol=0, atol=1e-13, err_msg=k)
        else:
            assert np.array_equal(np.asarray(getattr(a, k)), np.asarray(want)), k
    assert np.all(np.asarray(a.status) == lj.Status.OK) and np.asarray(a.n_land)[:, 1:].min() >= 1
    assert np.all(np.asarray(a.n_land)[:, 0] == 0)  # omega = 2 never lifts off
    kw = dict(z=2.0, horizon=60.0, window=10.0, t_start=20.0)
    m = lj.measure(p, contact="hop", **kw)  # type: ignore[arg-type]
    c = lj.measure(lj.Chain.from_params(p), contact="hop", **kw)  # type: ignore[arg-type]
    assert m.flight_fraction is not None and m.highest_hop is not None and m.landings_per_period is not None
    assert m.flight_fraction.shape == (2, 3, 2) and m.landings_per_period.shape == (2, 3)
    for k in ("tau_z", "e_z", "regime", "mean_speed", "e_d", "balance", "margin_z", "flight_fraction",
              "landings_per_period", "highest_hop", "zeno", "status", "n_steps"):  # fmt: skip
        assert np.array_equal(np.asarray(getattr(m, k)), np.asarray(getattr(c, k))), k
    assert np.array_equal(np.asarray(m.stick_fraction), np.asarray(c.stick_fraction))
    assert np.all(np.asarray(m.status) == lj.Status.OK)
    for k, v in m.to_numpy().items():
        assert not np.any(np.isnan(v)), k
    ff = np.asarray(m.flight_fraction)
    print("flight fractions", ff.round(4).tolist(), "tau_z", np.asarray(m.tau_z).round(4).tolist())
    assert np.all(ff[:, 0] == 0) and np.all(ff[1, 1:] > 0.05)  # at a = 0.08 the hops go on past t_start
    assert np.all(np.abs(np.asarray(m.balance)) <= 1e-5 * np.asarray(m.e_d))


def test_params_hop_equals_strict_without_liftoff():
    """On every two-mass reference configuration that never lifts off under the strict reading
    (tests/test_against_reference.py, paper start), `Params` under "hop" equals `Params` under
    "strict" over 40 time units to 1e-12, both on the same (N-body) engine (`Chain.from_params`;
    measured 3e-17) and against the two-mass engine that runs `Params` under "strict" (measured
    1e-13); and in `measure` (tau_z, e_z) to 1e-9 relative."""
    cases = [p for g, p, kind in TWO_MASS_CASES if kind != "liftoff" and GROUPS[g][:2] == ("strict", "paper")]
    assert len(cases) >= 10
    base, names = lj.Params(), sorted({k for c in cases for k in c})
    p = lj.Params(**{k: jnp.asarray([c.get(k, getattr(base, k)) for c in cases]) for k in names})  # pyright: ignore
    ts = np.linspace(0.0, 40.0, 201)
    hop = lj.simulate(p, t_end=40.0, save_at=ts, contact="hop")
    same_engine = lj.simulate(lj.Chain.from_params(p), t_end=40.0, save_at=ts)
    two_mass = lj.simulate(p, t_end=40.0, save_at=ts)
    assert np.all(np.asarray(hop.status) == lj.Status.OK) and np.all(np.asarray(two_mass.status) == lj.Status.OK)
    assert hop.y is not None and np.all(np.asarray(hop.y) == 0) and np.all(np.asarray(hop.n_land) == 0)
    worst_same, worst_two = 0.0, 0.0
    for k, j in (("x1", 0), ("v1", 0), ("x2", 1), ("v2", 1)):
        got = np.asarray(getattr(hop, k))
        worst_same = max(
            worst_same, np.abs(got - np.asarray((same_engine.x if k[0] == "x" else same_engine.v)[..., j])).max()
        )
        worst_two = max(worst_two, np.abs(got - np.asarray(getattr(two_mass, k))).max())
    for k in ("e_d", "w", "e"):
        worst_same = max(worst_same, np.abs(np.asarray(getattr(hop, k)) - np.asarray(getattr(same_engine, k))).max())
        worst_two = max(worst_two, np.abs(np.asarray(getattr(hop, k)) - np.asarray(getattr(two_mass, k))).max())
    print(len(cases), "configurations: |hop - strict| same engine", worst_same, "two-mass engine", worst_two)
    assert worst_same <= 1e-12 and worst_two <= 1e-12
    assert np.array_equal(np.asarray(hop.mode), np.asarray(two_mass.mode))
    kw = dict(z=1.0, horizon=200.0, window=5.0)
    mh, ms = lj.measure(p, contact="hop", **kw), lj.measure(p, **kw)  # type: ignore[arg-type]
    assert np.all(np.asarray(mh.status) == lj.Status.OK) and np.all(np.asarray(ms.status) == lj.Status.OK)
    assert mh.flight_fraction is not None and np.all(np.asarray(mh.flight_fraction) == 0)
    np.testing.assert_allclose(np.asarray(mh.tau_z), np.asarray(ms.tau_z), rtol=1e-9)
    np.testing.assert_allclose(np.asarray(mh.e_z), np.asarray(ms.e_z), rtol=1e-9)
    assert np.array_equal(np.asarray(mh.regime), np.asarray(ms.regime))


# The paper's model near resonance (omega, a, d) that hops a little (tests/test_hop_reference.py's).
NEAR = [(9.0, 0.08, 0.25), (12.0, 0.05, 0.5), (8.0, 0.1, 0.25), (11.0, 0.05, 0.25)]


def test_params_hop_against_reference():
    """`lj.simulate(lj.Params(...), contact="hop")` of 4 configurations near resonance (one batched
    call) against the independent reference with flight and landing: positions, heights and e_d at
    201 saves within 1e-6, the same number of landings by t = 40, and the energy balance."""
    t_end, ts = 40.0, np.linspace(0.0, 40.0, 201)
    p = lj.Params(
        omega=jnp.asarray([c[0] for c in NEAR]),
        a=jnp.asarray([c[1] for c in NEAR]),
        d=jnp.asarray([c[2] for c in NEAR]),
    )
    tr = lj.simulate(p, t_end=t_end, save_at=ts, contact="hop", dynamics=lj.Exact(dt=DT))
    assert tr.y is not None and tr.n_land is not None
    for i, (w, a, d) in enumerate(NEAR):
        ref = reference_hop_simulate(paper_config(omega=w, a=a, d=d), t_end, ts)
        dx = max(
            np.abs(np.asarray(tr.x1[i]) - ref["x"][:, 0]).max(), np.abs(np.asarray(tr.x2[i]) - ref["x"][:, 1]).max()
        )
        dy = np.abs(np.asarray(tr.y[i]) - ref["y"]).max()
        ded = np.abs(np.asarray(tr.e_d[i]) - ref["e_d"]).max()
        bal = np.abs(np.asarray(tr.w[i] - tr.e_d[i] - (tr.e[i] - tr.e[i, 0]))).max()
        print(i, "landings", int(ref["n_landings"].sum()), int(tr.n_land[i]), f"dx {dx:.1e} dy {dy:.1e} de_d {ded:.1e}")
        assert int(tr.status[i]) == lj.Status.OK and int(tr.n_land[i]) == int(ref["n_landings"].sum()) >= 2
        assert dx < 1e-6 and dy < 1e-6 and ded < 1e-6
        assert bal <= 1e-6 * float(tr.e_d[i, -1])


def test_params_hop_batch_flags_bad_configuration_only():
    """Under `jit` (values unknown at the front end) a batch with one invalid configuration
    (mhat = 1.2) is flagged `INVALID` in its own result, without NaN in the others, which equal
    their runs alone; the smoothed dynamics refuse "hop" clearly; float32 runs."""
    f = jax.jit(lambda mhat: lj.measure(lj.Params(omega=jnp.asarray([9.0, 12.0, 2.0]), a=0.08, d=0.25, mhat=mhat,
                                                  check=False), z=1.0, horizon=40.0, window=10.0, t_start=10.0,
                                        contact="hop"))  # fmt: skip
    m = f(jnp.asarray([0.5, 1.2, 0.5]))
    assert [int(s) for s in m.status] == [lj.Status.OK, lj.Status.INVALID, lj.Status.OK]
    for i, omega in ((0, 9.0), (2, 2.0)):
        one = lj.measure(lj.Params(omega=omega, a=0.08, d=0.25), z=1.0, horizon=40.0, window=10.0, t_start=10.0,
                         contact="hop")  # fmt: skip
        assert one.flight_fraction is not None and m.flight_fraction is not None
        assert float(m.tau_z[i]) == float(one.tau_z) and np.array_equal(m.flight_fraction[i], one.flight_fraction)
        assert not np.isnan(float(m.e_d[i])) and not np.any(np.isnan(np.asarray(m.flight_fraction[i])))
    with pytest.raises(NotImplementedError, match="Exact dynamics only"):
        lj.measure(lj.Params(omega=9.0), contact="hop", dynamics=lj.Smoothed())
    with pytest.raises(NotImplementedError, match="Exact dynamics only"):
        lj.simulate(lj.Params(omega=9.0), t_end=1.0, contact="hop", dynamics=lj.Smoothed())
    m32 = lj.measure(lj.Params(omega=9.0, a=0.08, d=0.25), z=1.0, horizon=40.0, window=10.0, t_start=10.0,
                     contact="hop", dtype=jnp.float32)  # fmt: skip
    assert m32.flight_fraction is not None and m32.flight_fraction.dtype == jnp.float32
    assert int(m32.status) == lj.Status.OK and float(m32.flight_fraction[0]) > 0


def test_chain_map_of_params_under_hop_equals_measure():
    """A chain map of `Chain.from_params` under "hop" (which, unlike a sweep of `Params`, takes an explicit
    `t_start`) equals `lj.measure` of the same `Params` under "hop" bit for bit (the sweep of `Params`
    itself: tests/test_hop_sweep.py)."""
    axes = {"omega": np.asarray([9.0, 12.0]), "a": np.asarray([0.05, 0.08])}
    kw = dict(z=1.0, horizon=30.0, window=10.0, t_start=10.0)
    ds = lj.sweep(axes, mechanism=lambda **v: lj.Chain.from_params(lj.Params(**v, d=0.25)), contact="hop",
                  progress=False, **kw)  # type: ignore[arg-type]  # fmt: skip
    W, A = np.meshgrid(axes["omega"], axes["a"], indexing="ij")
    m = lj.measure(lj.Params(omega=W, a=A, d=0.25), contact="hop", **kw)  # type: ignore[arg-type]
    assert m.flight_fraction is not None
    assert np.array_equal(ds["tau_z"].values, np.asarray(m.tau_z))
    assert np.array_equal(ds["flight_fraction"].values, np.asarray(m.flight_fraction))
    assert np.array_equal(ds["stick_fraction"].values[..., 0], np.asarray(m.stick_fraction1))
    assert np.all(ds["status"].values == lj.Status.OK) and ds["flight_fraction"].values.max() > 0
