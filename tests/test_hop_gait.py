"""Steady gaits with flight phases (`steady_gait(..., contact="hop")`, SPEC §10, issue 27): the period
map through lift-offs, flights and landings, its fixed point and Floquet multipliers, against a long
simulation that converges to the orbit."""

import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np


def test_hopping_gait_is_the_limit_of_a_long_simulation():
    """The paper's model at omega = 15 and 20, a = 0.1 (`Params`, one batch): both gaits are stable
    1-periodic orbits with flight phases (the long run lands about twice per period); a simulation
    from the paper's start reaches the orbit's section state (gap, velocities, heights, vertical
    velocities) within 1e-7 after 300 periods (measured 6e-9 and 9e-9) and its drift over one period
    gives the gait's mean speed; the multipliers lie inside the unit circle (a grounded body's
    vertical components give zeros)."""
    omega = np.asarray([15.0, 20.0])
    p = lj.Params(omega=jnp.asarray(omega), a=0.1)
    g = lj.steady_gait(p, contact="hop")
    assert isinstance(g, lj.Gait) and g.state.shape == (2, 7)
    print("gait", g.status, g.mean_speed, np.abs(np.asarray(g.multipliers)).round(4), np.asarray(g.state))
    assert np.all(np.asarray(g.status) == lj.GaitStatus.CONVERGED) and np.all(np.asarray(g.stable))
    mult = np.abs(np.asarray(g.multipliers))
    assert np.all(mult < 0.95) and np.all(np.sort(mult, -1)[:, :2] < 1e-8)
    T = 2 * np.pi / omega
    for i in range(2):
        ts = np.asarray([300 * T[i], 301 * T[i]])
        tr = lj.simulate(lj.Params(omega=float(omega[i]), a=0.1), t_end=float(ts[-1]), save_at=ts, contact="hop")
        assert tr.y is not None and tr.vy is not None and tr.n_land is not None
        red = np.concatenate(
            [np.asarray(tr.x2 - tr.x1)[:, None], np.asarray(tr.x)[:, :0], np.asarray(tr.v), np.asarray(tr.y),
             np.asarray(tr.vy)], -1,
        )  # fmt: skip
        diff = np.abs(red - np.asarray(g.state[i])[None]).max()
        speed = float(tr.X[1] - tr.X[0]) / T[i]
        print(i, "landings", int(tr.n_land), "|orbit - simulation|", diff, "speed", speed, float(g.mean_speed[i]))
        assert int(tr.status) == lj.Status.OK and int(tr.n_land) > 500  # it hops: about 2 landings per period
        assert diff < 1e-7 and abs(speed - float(g.mean_speed[i])) < 1e-7
    assert float(np.asarray(g.state)[0, 3]) > 0  # at omega = 15 a body is in flight at the section
