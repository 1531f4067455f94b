"""`lj.Damper` (SPEC §9): a relative damper between two bodies or a body and a wall. Its force enters
the stick and slip decisions and its dissipation enters e_d, so the energy balance holds; a damper to
a wall is ground damping. (Against the independent reference: tests/test_against_reference.py.)
Also: a waveform batched in its amplitude and frequency batches the mechanism."""

import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest


def _damped(**kw) -> lj.Mechanism:
    return lj.Mechanism(
        masses=[1.0, 0.5, 0.8], friction=[lj.AnisotropicCoulomb(0.6, 0.3, 0.5, 0.2), None, lj.Coulomb(0.4, 0.3)],
        carried_by=[None, 0, None],
        links=[lj.Spring(0, 1, k=8.0), lj.Damper(0, 1, c=0.7), lj.Force(0, 1, lj.Sinusoid(1.2, 3.0, 0.0)),
               lj.Spring(0, 2, k=2.0, rest=1.0), lj.Damper(2, 0, c=0.4), lj.Damper(lj.WALL, 2, c=0.2)],
        x0=[0.0, 0.0, 1.2], **kw,
    )  # fmt: skip


def test_energy_balance_with_dampers():
    traj = lj.simulate(_damped(), t_end=30.0, save_at=jnp.linspace(0.0, 30.0, 301))
    assert int(traj.status) == lj.Status.OK
    bal = np.asarray(traj.w - traj.e_d - (traj.e - traj.e[0]))
    print("energy balance with dampers:", np.abs(bal).max(), "of e_d", float(traj.e_d[-1]))
    assert np.abs(bal).max() < 1e-6 * float(traj.e_d[-1]) and float(traj.e_d[-1]) > 1.0
    assert np.asarray(traj.stuck)[:, 0].any() and not np.asarray(traj.stuck)[:, 1].any()


def test_dampers_dissipate_what_they_take():
    """e_d with the dampers exceeds e_d without them by their dissipation; a free two-body system
    joined by a damper alone loses its relative kinetic energy exactly: v_rel = v0 exp(-c t / mu)."""
    M = lj.Mechanism(masses=[1.0, 3.0], friction=[None, None], links=[lj.Damper(0, 1, c=0.6)], v0=[1.0, -1.0])
    ts = jnp.linspace(0.0, 5.0, 11)
    traj = lj.simulate(M, t_end=5.0, save_at=ts)
    mu = 1.0 * 3.0 / 4.0
    rel = np.asarray(traj.v[:, 1] - traj.v[:, 0])
    np.testing.assert_allclose(rel, -2.0 * np.exp(-0.6 * np.asarray(ts) / mu), rtol=1e-8)
    np.testing.assert_allclose(np.asarray(traj.e_d), 0.5 * mu * (4.0 - rel**2), rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(np.asarray(traj.v[:, 0] + 3 * traj.v[:, 1]), -2.0, atol=1e-12)  # momentum


def test_a_damper_to_a_wall_is_ground_damping():
    law = lj.Coulomb(0.5, 0.4)
    a = lj.Mechanism(masses=[1.0], friction=law, x0=[1.0], v0=[2.0],
                     links=[lj.Spring(0, lj.WALL, k=3.0), lj.Damper(0, lj.WALL, c=0.25)])  # fmt: skip
    b = lj.Mechanism(masses=[1.0], friction=law, x0=[1.0], v0=[2.0], links=[lj.Spring(0, lj.WALL, k=3.0)], c=0.25)
    ts = jnp.linspace(0.0, 10.0, 21)
    ta, tb = lj.simulate(a, t_end=10.0, save_at=ts), lj.simulate(b, t_end=10.0, save_at=ts)
    for name in ("x", "v", "e_d", "w"):
        np.testing.assert_array_equal(np.asarray(getattr(ta, name)), np.asarray(getattr(tb, name)), err_msg=name)


@pytest.mark.parametrize(
    "links, message",
    [
        ([lj.Damper(0, 1, c=-0.1)],
         r"Invalid parameter 'c' of links\[0\] Damper\(0, 1\): got c=-0.1; the valid range is c >= 0"),
        ([lj.Damper(0, 3, c=0.1)], r"links\[0\] Damper\(0, 3\): body 3 does not exist"),
        ([lj.Damper(1, 1, c=0.1)], r"links\[0\] Damper\(1, 1\): joins body 1 to itself"),
    ],
)  # fmt: skip
def test_bad_dampers_are_named(links, message):
    with pytest.raises(ValueError, match=message):
        lj.Mechanism(masses=[1.0, 1.0], links=links)


def test_a_batched_waveform_batches_the_mechanism():
    """Amplitude and frequency batched, lbar not: the batch has their shape, and each runs as alone."""
    a, w = jnp.array([0.5, 1.0, 1.5]), jnp.array([2.0, 3.0, 4.0])
    M = lj.Mechanism(masses=[1.0, 0.5], friction=[lj.Coulomb(0.5, 0.4), None], carried_by=[None, 0],
                     links=[lj.Spring(0, 1, k=10.0), lj.Force(0, 1, lj.Sinusoid(a=a, omega=w, lbar=0.0))])  # fmt: skip
    assert M.batch_shape == (3,)
    ts = jnp.linspace(0.0, 5.0, 6)
    traj = lj.simulate(M, t_end=5.0, save_at=ts)
    alone = lj.simulate(M[1], t_end=5.0, save_at=ts)
    np.testing.assert_allclose(np.asarray(traj.x[1]), np.asarray(alone.x), rtol=1e-12, atol=1e-12)


def test_a_batch_flags_one_bad_damper_and_runs_the_others():
    """`check=False`: the configuration with c < 0 is INVALID, its batch-mates equal their runs alone."""
    c = jnp.array([0.5, -1.0, 0.3])
    M = lj.Mechanism(masses=[1.0, 0.5], friction=[lj.Coulomb(0.5, 0.4), None], carried_by=[None, 0],
                     links=[lj.Spring(0, 1, k=10.0), lj.Damper(0, 1, c=c), lj.Force(0, 1, lj.Sinusoid(1.0, 3.0, 0.0))],
                     check=False)  # fmt: skip
    ts = jnp.linspace(0.0, 6.0, 7)
    traj = lj.simulate(M, t_end=6.0, save_at=ts)
    assert [int(s) for s in traj.status] == [lj.Status.OK, lj.Status.INVALID, lj.Status.OK]
    for i in (0, 2):
        np.testing.assert_allclose(np.asarray(traj.x[i]), np.asarray(lj.simulate(M[i], t_end=6.0, save_at=ts).x),
                                   rtol=1e-12, atol=1e-12)  # fmt: skip


def test_dampers_in_float32():
    M = _damped().astype(jnp.float32)
    traj = lj.simulate(M, t_end=20.0, save_at=jnp.linspace(0.0, 20.0, 21))
    assert traj.x.dtype == jnp.float32 and int(traj.status) == lj.Status.OK
    bal = np.asarray(traj.w - traj.e_d - (traj.e - traj.e[0]))
    ref = lj.simulate(_damped(), t_end=20.0, save_at=jnp.linspace(0.0, 20.0, 21))
    print("float32: energy balance", np.abs(bal).max(), "; x against float64", np.abs(traj.x - ref.x).max())
    assert np.abs(bal).max() < 1e-4 * float(traj.e_d[-1]) and float(np.abs(traj.x - ref.x).max()) < 1e-3
