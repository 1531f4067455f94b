"""`margin_z` under `contact="hop"` (SPEC §10): the time from $t_z$ to the nearest change of switching
structure, landings and lift-offs included, relative to `tau_z` (`Measurement.margin_z`), on bodies
whose motion is known in closed form (no springs: free flight, Coulomb sliding after a plastic landing)."""

import math

import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np


def _predicted(g: float, d: float, e: float) -> float:
    """The engine's documented estimate of the time to an event function's root from its value, rate and
    curvature (`_numerics.predict`: the linear estimate plus one Newton step on the Taylor quadratic)."""
    s1 = g / -d
    return s1 - 0.5 * e * s1 * s1 / (d + e * s1)


def test_margin_z_under_hop_closed_form():
    """Two bodies, each its own configuration of one batch (mu_k = 0.5, no damping, t_start = 0):

    - thrown up at w0 = 2 with v0 = 1: in flight x = t, so z = 2.5 is reached at t_z = 2.5, falling
      (height 1.875, vertical velocity -0.5, acceleration -1); the next change is the landing at t = 4,
      which the margin estimates from the height's Taylor quadratic (`_predicted`, 2.0956, against the
      exact 1.5: the estimate is one Newton step). A body in flight has no friction events: treating it
      as sliding (its speed 1 stopping in 2 under mu_k) would give 2.
    - thrown at w0 = 0.5 with v0 = 1: lands at t = 1 (plastic; the tangential impulse mu_k P_n = 0.25
      leaves v = 0.75), then slides: x = 1 + 0.75 s - 0.25 s^2, so z = 1.14 is reached at t_z = 1.2;
      the nearest change is the landing 0.2 before (exact), the stop ahead at 1.3 after."""
    ball = lj.Mechanism(
        masses=[1.0], friction=lj.Coulomb(0.5, 0.5), c=0.0, x0=jnp.zeros((2, 1)), v0=jnp.ones((2, 1)),
        y0=jnp.zeros((2, 1)), w0=jnp.asarray([[2.0], [0.5]]),
    )  # fmt: skip
    out = []
    for k, z in enumerate((2.5, 1.14)):  # two values of z: two calls (z is one number per call)
        m = lj.measure(ball, z=z, horizon=10.0, window=0.1, t_start=0.0, contact="hop")
        out.append((float(m.tau_z[k]), float(m.margin_z[k]), int(m.status[k])))
    (tau1, margin1, st1), (tau2, margin2, st2) = out
    print("thrown high", tau1, margin1, "landed", tau2, margin2)
    assert st1 == st2 == lj.Status.OK
    assert abs(tau1 - 2.5) < 1e-12 and abs(tau2 - 1.2) < 1e-9
    assert math.isclose(margin1, _predicted(1.875, -0.5, -1.0) / 2.5, rel_tol=1e-9)
    assert not math.isclose(margin1, 2.0 / 2.5, rel_tol=1e-3)
    assert math.isclose(margin2, 0.2 / 1.2, rel_tol=1e-8)
    assert np.isfinite(margin1) and np.isfinite(margin2)
