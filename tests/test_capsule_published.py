"""A body with an internal mass on prescribed harmonic motion, s(t) = b sin(omega t), on non-symmetric
Coulomb friction (f+ forward, f- backward; static = kinetic): the at-rest condition of Fang and Xu
(Multibody Syst. Dyn. 27 (2012) 455-485), P = m b omega^2 / ((M + m) g) <= f+, and the closed form of the
forward-only band f+ < P <= f- (derived in experiments/REPRODUCTION.md) against `lj.measure`.

SPEC §9 reads the prescribed motion as the external force -m s''(t) on the carrier, which carries the
weight of m: one body of mass M + m under m b omega^2 sin(omega t). The closed form below is written
here from the equation of motion, sharing no code with the package or the experiment."""

import math
from typing import cast

import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
from scipy.optimize import brentq


M, m, F_FWD, F_BWD, OMEGA = 1.0, 0.5, 0.2, 0.4, 2.0


def closed_form(P: float) -> tuple[float, float]:
    """Mean speed and stuck fraction of the periodic motion (g = 1) for P <= f-."""
    if P <= F_FWD:
        return 0.0, 1.0
    t1 = math.asin(F_FWD / P)
    h = lambda t: P * (math.cos(t1) - math.cos(t)) - F_FWD * (t - t1)  # omega v / g
    ts = np.linspace(t1 + 1e-9, t1 + 2 * math.pi, 20001)
    j = int(np.argmax(np.array([h(t) for t in ts[1:]]) < 0))
    t2 = cast(float, brentq(h, ts[j], ts[j + 1], xtol=1e-15))
    L = t2 - t1
    dx = (P * (L * math.cos(t1) - (math.sin(t2) - math.sin(t1))) - F_FWD * L * L / 2) / OMEGA**2
    return dx * OMEGA / (2 * math.pi), 1 - L / (2 * math.pi)


def test_prescribed_internal_motion_matches_the_closed_form_and_the_regime_boundaries():
    P = np.array([0.1, 0.2, 0.21, 0.25, 0.3, 0.35, 0.4, 0.45, 0.6])
    wave = lj.Sinusoid(a=jnp.asarray(P * (M + m)), omega=OMEGA, lbar=0.0)
    law = lj.AnisotropicCoulomb(F_FWD, F_BWD, F_FWD, F_BWD)
    body = lj.Mechanism(masses=[M + m], friction=law, links=[lj.ExternalForce(0, wave)])
    T = 2 * math.pi / OMEGA
    res = lj.measure(body, z=1e6, horizon=20 * T, window=20 * T, t_start=5 * T, dynamics=lj.Exact(dt=0.005))
    assert (np.asarray(res.status) == lj.Status.OK).all()
    speed, stuck = np.asarray(res.mean_speed), np.asarray(res.stick_fraction)[:, 0]
    band = P <= F_BWD
    exact = np.array([closed_form(float(p)) for p in P[band]])
    assert (speed[P <= F_FWD] == 0).all() and np.allclose(stuck[P <= F_FWD], 1.0, rtol=0, atol=1e-12)  # at rest
    moving = P[band] > F_FWD
    rel = np.abs(speed[band][moving] - exact[moving, 0]) / exact[moving, 0]
    print("forward-only band: max relative error of the mean speed", rel.max(),
          "; of the stuck fraction", np.abs(stuck[band] - exact[:, 1]).max())  # fmt: skip
    assert rel.max() < 1e-8 and np.abs(stuck[band] - exact[:, 1]).max() < 1e-8
    # Backward slips exactly beyond P = f-: the slowest velocity over five periods.
    traj = lj.simulate(body, t_end=6 * T, save_at=jnp.linspace(T, 6 * T, 2001), dynamics=lj.Exact(dt=0.005))
    v_min = np.asarray(traj.v)[..., 0].min(axis=-1)
    assert ((v_min < 0) == (P > F_BWD)).all() and (v_min[P <= F_BWD] == 0).all()


def test_steady_gait_matches_the_closed_form():
    """`lj.steady_gait` of the same body (section state: its velocity at phase 0) over the at-rest and
    forward-only bands: the orbit's mean speed and stuck fraction are the closed form's."""
    P = np.array([0.15, 0.2, 0.22, 0.25, 0.3, 0.35, 0.4])
    wave = lj.Sinusoid(a=jnp.asarray(P * (M + m)), omega=OMEGA, lbar=0.0)
    law = lj.AnisotropicCoulomb(F_FWD, F_BWD, F_FWD, F_BWD)
    body = lj.Mechanism(masses=[M + m], friction=law, links=[lj.ExternalForce(0, wave)])
    g = lj.steady_gait(body, periods=1, transient=3, dynamics=lj.Exact(dt=0.005))
    assert (np.asarray(g.status) == lj.GaitStatus.CONVERGED).all() and g.state.shape == (P.size, 1)
    exact = np.array([closed_form(float(p)) for p in P])
    speed, stuck = np.asarray(g.mean_speed), np.asarray(g.stick_fraction)[:, 0]
    moving = P > F_FWD
    rel = np.abs(speed[moving] - exact[moving, 0]) / exact[moving, 0]
    print("steady gait: max relative error of the mean speed", rel.max(), "; of the stuck fraction",
          np.abs(stuck - exact[:, 1]).max(), "; section velocities", np.asarray(g.state)[:, 0])  # fmt: skip
    assert (speed[~moving] == 0).all() and rel.max() < 1e-8 and np.abs(stuck - exact[:, 1]).max() < 1e-8
