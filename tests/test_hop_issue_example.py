"""Issue 27's first example, `lj.measure(lj.Params(omega=10.0, a=0.1), contact="hop")`, against the
independent reference `tests/reference_hop.py`: the run ends `Status.COLLISION` because the hops grow
until the masses cross (`x_2 - x_1` reaches 0 at t = 7.515, both bodies about 5.2 to 5.5 high, the
spring's ends 0.16 apart), which the reference reproduces; and the nearby configuration the docs
show instead (omega = 9, 0.9 omega_n1) runs `Status.OK` through lift-off, flights and landings."""

import locomotion_jax as lj
import numpy as np
from reference_hop import paper_config, reference_hop_simulate


DT = 1.0 / 800
TOL = 1e-6


def test_issue_example_collides_as_the_reference():
    """Positions, heights and e_d of the engine (dt = 1/800) equal the reference's to 1e-6 at every
    save up to the crossing (9 landings on the way); the engine stops within one step of the
    reference's crossing time; at the crossing both bodies fly 5 units high and the spring (rest
    length 3) is compressed to |d + y_2 - y_1| < 0.2: the bodies meet, outside the model's line
    order (SPEC §1, §8), so `COLLISION` is the outcome. `measure` with its defaults agrees."""
    ts = np.concatenate([np.linspace(0.0, 7.5, 301)[:-1], np.linspace(7.5, 7.53, 301)])
    ref = reference_hop_simulate(paper_config(omega=10.0, a=0.1), 7.53, ts)
    gap = ref["x"][:, 1] - ref["x"][:, 0]
    k = int(np.nonzero(gap <= 0)[0][0])
    t_cross = ts[k - 1] + (ts[k] - ts[k - 1]) * gap[k - 1] / (gap[k - 1] - gap[k])  # linear in 1e-4: to ~1e-9
    y_cross = ref["y"][k - 1]
    spring_ends = abs(0.5 + y_cross[1] - y_cross[0])  # d = 0.5; u = 0 at the crossing
    tr = lj.simulate(lj.Params(omega=10.0, a=0.1), t_end=7.53, save_at=ts, contact="hop", dynamics=lj.Exact(dt=DT))
    assert tr.y is not None and tr.n_land is not None
    valid = np.asarray(tr.valid)
    last = int(np.nonzero(valid)[0][-1])
    dx = np.abs(np.stack([np.asarray(tr.x1), np.asarray(tr.x2)], -1)[valid] - ref["x"][valid]).max()
    dy = np.abs(np.asarray(tr.y)[valid] - ref["y"][valid]).max()
    ded = np.abs(np.asarray(tr.e_d)[valid] - ref["e_d"][valid]).max()
    t_lift_ref = min(t for t, text in ref["events"] if "lifts off" in text)
    print(f"crossing: reference t = {t_cross:.9f}, engine's last valid save {ts[last]:.4f}; heights {y_cross}, "
          f"spring ends {spring_ends:.4f}; dx {dx:.1e} dy {dy:.1e} de_d {ded:.1e}; landings {int(tr.n_land)} / "
          f"{len(ref['landings'])}; t_liftoff {float(tr.t_liftoff):.12f} / {t_lift_ref:.12f}")  # fmt: skip
    assert int(tr.status) == lj.Status.COLLISION
    assert dx < TOL and dy < TOL and ded < TOL
    assert int(tr.n_land) == len([t for t, _ in ref["landings"] if t <= ts[last]]) == 9
    assert abs(float(tr.t_liftoff) - t_lift_ref) < TOL
    assert np.all(np.asarray(tr.x2 - tr.x1)[valid] > 0)  # in order up to the stop
    assert ts[last] <= t_cross <= ts[last] + DT  # stopped within one step of the reference's crossing
    assert 7.5 < t_cross < 7.52 and np.all(y_cross > 5.0) and spring_ends < 0.2
    bal = np.abs(np.asarray(tr.w - tr.e_d - (tr.e - tr.e[0])))[valid].max()
    assert bal <= 1e-6 * float(tr.e_d[last])

    m = lj.measure(lj.Params(omega=10.0, a=0.1), contact="hop")  # the issue's call, default settings
    assert m.flight_fraction is not None and m.highest_hop is not None
    print("measure:", lj.Status(int(m.status)).name, "t_liftoff", float(m.t_liftoff))
    assert int(m.status) == lj.Status.COLLISION and bool(m.liftoff)
    assert abs(float(m.t_liftoff) - t_lift_ref) < TOL
    # Stopped before t_start (71.1): nothing measured, NaN with a status that says why.
    assert np.all(np.isnan(np.asarray(m.flight_fraction))) and np.isnan(float(m.e_d))


def test_nearby_configuration_runs_ok_through_liftoff():
    """`lj.Params(omega=9.0, a=0.1)` (0.9 omega_n1, the docs' example): `measure` with its defaults
    runs `Status.OK` through lift-off, both bodies in flight most of the window. Its trajectory
    against the reference: within 1e-6 over [0, 10] at dt = 1/800 (x, y, e_d: measured 3.8e-7), the same 97
    landings by t = 40. The hops amplify small differences (the reference itself moves by 9e-7 at
    t = 40 from rtol 1e-12 to 1e-13; the engine's error at dt = 1/800 grows from 4e-7 at t = 10 to
    8e-4 at t = 40), so over [0, 40] the check is convergence: halving dt divides the largest
    difference from the reference by more than 10 (fourth order: 16; measured 8.0e-4 -> 5.1e-5)."""
    p = lj.Params(omega=9.0, a=0.1)
    m = lj.measure(p, contact="hop")
    assert m.flight_fraction is not None and m.highest_hop is not None and m.landings_per_period is not None
    print("omega 9, a 0.1:", lj.Status(int(m.status)).name, "tau_5", float(m.tau_z), "e_5", float(m.e_z),
          "flight", np.asarray(m.flight_fraction), "highest", np.asarray(m.highest_hop),
          "landings/period", float(m.landings_per_period), "balance/e_d", float(m.balance / m.e_d))  # fmt: skip
    assert int(m.status) == lj.Status.OK and bool(m.liftoff) and bool(m.reached)
    assert np.all(np.asarray(m.flight_fraction) > 0.8) and np.all(np.asarray(m.highest_hop) > 0.1)
    assert float(m.landings_per_period) > 1.0 and not bool(m.zeno)
    assert abs(float(m.balance)) <= 1e-5 * float(m.e_d)  # dt = 0.01 (1e-6 at dt = 1/400: the resonance script)

    ts = np.linspace(0.0, 40.0, 401)
    ref = reference_hop_simulate(paper_config(omega=9.0, a=0.1), 40.0, ts)
    worst = []
    for dt in (DT, DT / 2):
        tr = lj.simulate(p, t_end=40.0, save_at=ts, contact="hop", dynamics=lj.Exact(dt=dt))
        assert tr.y is not None and tr.n_land is not None
        diff = np.maximum(
            np.abs(np.stack([np.asarray(tr.x1), np.asarray(tr.x2)], -1) - ref["x"]).max(-1),
            np.abs(np.asarray(tr.y) - ref["y"]).max(-1),
        )
        diff = np.maximum(diff, np.abs(np.asarray(tr.e_d) - ref["e_d"]))
        worst.append(diff.max())
        print(f"dt {dt:.6f}: max |engine - reference| (x, y, e_d) over [0, 10] {diff[ts <= 10].max():.1e}, over "
              f"[0, 40] {diff.max():.1e}; landings {int(tr.n_land)} / {int(ref['n_landings'].sum())}")  # fmt: skip
        assert int(tr.status) == lj.Status.OK and int(tr.n_land) == int(ref["n_landings"].sum()) == 97
        if dt == DT:
            assert diff[ts <= 10].max() < TOL
    assert worst[1] < worst[0] / 10
