"""`lj.steady_gait` of a `lj.Mechanism` (SPEC §9): the chain's orbit solver through the physics
interface. Checked against a direct `simulate` over the orbit's period, the independent event-driven
reference (`tests/reference_mechanism.py`), and the exact periodic solution of a damped linear
oscillator on a wall spring driven by a harmonic external force; batches flag a bad configuration
alone."""

from typing import Any

import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from reference_mechanism import Body, run, Sig, System


ANISO = (0.5, 0.2, 0.4, 0.15)


def _capsule(a: Any = 0.6, k: Any = 10.0, w: float = 3.0, check: bool = True):
    """Body 0 on the ground (anisotropic Coulomb), body 1 carried by it on a spring k, driven by a sin(w t)."""
    links = [lj.Spring(0, 1, k=k, rest=0.0), lj.Force(0, 1, lj.Sinusoid(a=a, omega=w, lbar=0.0))]
    return lj.Mechanism(masses=[1.0, 0.5], friction=[lj.AnisotropicCoulomb(*ANISO), None], carried_by=[None, 0],
                        links=links, check=check)  # fmt: skip


def _capsule_ref(a, k, w, x0, v0):
    bodies = [Body(1.0, ANISO, x0=x0[0], v0=v0[0]), Body(0.5, None, carrier=0, x0=x0[1], v0=v0[1])]
    return System(bodies, springs=[(0, 1, k, 0.0)], forces=[(0, 1, Sig(0.0, (0.0,), (a,), w))])


def _wall_oscillator(friction, c, g=0.5, w=2.0):
    """Siconos' oscillator (m = k = 1, a spring to the wall) driven by an external force g sin(w t)."""
    links = [lj.Spring(0, lj.WALL, k=1.0, rest=0.0), lj.ExternalForce(0, lj.Sinusoid(a=g, omega=w, lbar=0.0))]
    return lj.Mechanism(masses=[1.0], friction=[friction], links=links, c=c)


@pytest.fixture(scope="module")
def capsule_gait():
    return lj.steady_gait(_capsule())


def test_capsule_gait_is_a_fixed_point_of_a_direct_simulation(capsule_gait):
    """From the orbit's section state, `simulate` returns to it (relative positions, velocities)
    after one gait period, with the gait's drift of the centre of mass and energies."""
    g = capsule_gait
    assert int(g.status) == lj.GaitStatus.CONVERGED and int(g.k) == 1
    assert g.state.shape == (3,) and g.monodromy.shape == (3, 3)
    u, v = np.asarray(g.state[:1]), np.asarray(g.state[1:])
    x0 = np.array([0.0, u[0]])
    M = lj.Mechanism(masses=[1.0, 0.5], friction=[lj.AnisotropicCoulomb(*ANISO), None], carried_by=[None, 0],
                     links=_capsule().links, x0=x0, v0=v)  # fmt: skip
    T = float(g.period)
    traj = lj.simulate(M, t_end=T, save_at=jnp.array([0.0, T]))
    assert int(traj.status) == lj.Status.OK
    x, vv = np.asarray(traj.x[-1]), np.asarray(traj.v[-1])
    err = max(abs((x[1] - x[0]) - u[0]), *np.abs(vv - v))
    drift = float(np.dot([1.0, 0.5], x - x0) / 1.5)
    print(f"fixed point: state error {err:.2e}; speed {float(g.mean_speed):.10f} vs simulate {drift / T:.10f}")
    assert err < 1e-9
    assert abs(drift / T - float(g.mean_speed)) < 1e-10
    assert abs(float(traj.e_d[-1]) - float(g.e_d)) < 1e-10 and abs(float(traj.w[-1]) - float(g.work)) < 1e-10
    assert abs(float(g.e_d) - float(g.work)) < 1e-9  # the energy is periodic on the orbit
    assert np.all(np.abs(np.asarray(g.multipliers)) < 1) and bool(g.stable)
    assert float(g.stick_fraction[1]) == 0.0  # a carried body never sticks


def test_capsule_gait_against_the_reference(capsule_gait):
    """The independent reference, from the orbit's section state, closes the orbit over 5 periods with
    the gait's mean speed and dissipation; from rest, its mean speed over periods 150-160 is the gait's
    (the multipliers' largest modulus, 0.92, leaves 4e-6 of the start there)."""
    g = capsule_gait
    T, u, v = float(g.period), float(g.state[0]), np.asarray(g.state[1:], float)
    ref = run(_capsule_ref(0.6, 10.0, 3.0, [0.0, u], v), 5 * T, np.array([0.0, 5 * T]))
    speed = (ref["com"][1] - ref["com"][0]) / (5 * T)
    closed = max(abs(ref["x"][1][1] - ref["x"][1][0] - u), *np.abs(ref["v"][1] - v))
    print(f"reference on the orbit: speed {speed:.10f} (gait {float(g.mean_speed):.10f}), e_d/period "
          f"{ref['ed'][1] / 5:.10f} (gait {float(g.e_d):.10f}), closure {closed:.1e}")  # fmt: skip
    assert closed < 1e-7
    assert abs(speed - float(g.mean_speed)) < 1e-8 * max(1.0, abs(speed))
    assert abs(ref["ed"][1] / 5 - float(g.e_d)) < 1e-8
    far = run(_capsule_ref(0.6, 10.0, 3.0, [0.0, 0.0], [0.0, 0.0]), 160 * T, np.array([150 * T, 160 * T]))
    long_speed = (far["com"][1] - far["com"][0]) / (10 * T)
    print(f"reference from rest, periods 150-160: speed {long_speed:.10f}")
    assert abs(long_speed - float(g.mean_speed)) < 1e-5 * abs(long_speed)


def test_harmonically_forced_wall_oscillator_exact():
    """No friction, damping c: the periodic solution is x = A sin(w t - phi), A = g/sqrt((1 - w^2)^2 +
    (c w)^2), tan(phi) = c w/(1 - w^2); the multipliers are exp((-c/2 +- i sqrt(1 - c^2/4)) T); per
    period the dampers dissipate pi c w A^2, which the force puts in. The anchored section state is
    the absolute (x, v)."""
    c, g, w = 0.3, 0.5, 2.0
    G = lj.steady_gait(_wall_oscillator(None, c, g, w))
    A = g / np.hypot(1 - w * w, c * w)
    phi = np.arctan2(c * w, 1 - w * w)
    want = np.array([A * np.sin(-phi), A * w * np.cos(-phi)])
    T = 2 * np.pi / w
    mu = np.exp((-c / 2 + 1j * np.sqrt(1 - c * c / 4)) * T)
    got_mu = np.sort_complex(np.asarray(G.multipliers))
    print("oscillator:", np.asarray(G.state), want, got_mu, mu)
    assert int(G.status) == lj.GaitStatus.CONVERGED and G.state.shape == (2,)
    assert np.abs(np.asarray(G.state) - want).max() < 1e-10
    assert np.abs(got_mu - np.sort_complex(np.array([mu, np.conj(mu)]))).max() < 1e-9
    assert abs(float(G.e_d) - np.pi * c * w * A * A) < 1e-10 and abs(float(G.work) - float(G.e_d)) < 1e-9
    assert abs(float(G.mean_speed)) < 1e-12


def test_siconos_oscillator_with_a_harmonic_wall_force_against_the_reference():
    """With Coulomb friction (bound 0.4) the oscillator driven by 0.6 sin(0.5 t) sticks and slips; the
    reference, from the gait's section state, returns to it after a period with the gait's dissipation."""
    G = lj.steady_gait(_wall_oscillator(lj.Coulomb(0.4, 0.4), 0.0, 0.6, 0.5))
    assert int(G.status) == lj.GaitStatus.CONVERGED
    x, v = float(G.state[0]), float(G.state[1])
    T = float(G.period)
    S = System([Body(1.0, (0.4, 0.4, 0.4, 0.4), x0=x, v0=v)], springs=[(0, -1, 1.0, 0.0)],
               externals=[(0, Sig(0.0, (0.0,), (0.6,), 0.5))])  # fmt: skip
    ref = run(S, T, np.array([0.0, T]))
    err = max(abs(ref["x"][1][0] - x), abs(ref["v"][1][0] - v))
    print(f"friction oscillator: state {x:.10f}, {v:.10f}; reference closure {err:.1e}; e_d {float(G.e_d):.10f} "
          f"(ref {ref['ed'][1]:.10f}); stuck {float(G.stick_fraction[0]):.4f}")  # fmt: skip
    assert err < 1e-8 and abs(ref["ed"][1] - float(G.e_d)) < 1e-8
    assert float(G.stick_fraction[0]) > 0  # it sticks at its turning points


def test_mechanism_gait_batch_flags_the_invalid_configuration_alone(capsule_gait):
    """A batch over the force amplitude with one negative spring stiffness (check=False): that one is
    INVALID with NaN numbers, the others equal the single solves."""
    k = jnp.array([10.0, -1.0, 10.0])
    a = jnp.array([0.6, 0.6, 0.9])
    G = lj.steady_gait(_capsule(a=a, k=k, check=False))
    status = np.asarray(G.status)
    assert list(status) == [lj.GaitStatus.CONVERGED, lj.GaitStatus.INVALID, lj.GaitStatus.CONVERGED]
    assert np.isnan(float(G.mean_speed[1]))
    assert abs(float(G.mean_speed[0]) - float(capsule_gait.mean_speed)) < 1e-12
    single = lj.steady_gait(_capsule(a=0.9))
    assert abs(float(G.mean_speed[2]) - float(single.mean_speed)) < 1e-12


def test_mechanism_gait_float32(capsule_gait):
    G = lj.steady_gait(_capsule(), dtype=jnp.float32)
    assert G.mean_speed.dtype == jnp.float32 and int(G.status) == lj.GaitStatus.CONVERGED
    assert abs(float(G.mean_speed) - float(capsule_gait.mean_speed)) < 1e-4


def test_mechanism_gait_start_and_bad_input():
    M = _capsule()
    g = lj.steady_gait(M, start=np.array([0.0, 0.0, 0.0]), periods=1)
    assert int(g.status) == lj.GaitStatus.CONVERGED
    with pytest.raises(ValueError, match=r"gaps u_0..u_N-2.*shape \(3,\)"):
        lj.steady_gait(M, start=np.zeros(4))
    with pytest.raises(ValueError, match=r"positions x_0..x_N-1.*shape \(2,\)"):
        lj.steady_gait(_wall_oscillator(None, 0.3), start=np.zeros(3))
    with pytest.raises(ValueError, match="waveform= applies to Params; a Mechanism"):
        lj.steady_gait(M, waveform=lj.Sinusoid(a=1.0, omega=1.0, lbar=0.0))
    still = lj.Mechanism(masses=[1.0], friction=[None], links=[lj.Spring(0, lj.WALL, k=1.0)], c=0.3)
    assert int(lj.steady_gait(still).status) == lj.GaitStatus.INVALID  # no forcing period
