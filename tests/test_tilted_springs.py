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
