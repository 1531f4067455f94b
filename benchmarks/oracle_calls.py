"""CPU time of the exact optimiser's orbit oracle on the checkout it runs from (float64).

The oracle of `optimise(Params(), ...)` (64-knot spline, 4 lanes, `dt = 0.01`): the first call of
the transient and of `orbits` (compilation included), then warm calls; with `nograd`, also
`orbits(..., gradient=False)` (the screen's call) and its difference from the full call.
Run it under each commit's PYTHONPATH to compare commits:

    PYTHONPATH=. python benchmarks/oracle_calls.py [nograd]
"""

import resource
import sys

import jax


jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
from locomotion_jax.gaits import _orbit
from locomotion_jax.optimisation import _shapes


def cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


a_max, G = 0.05, 256
phase = np.arange(G) * 2 * np.pi / G
strokes = [
    (0.03 * np.sin(phase) + 0.004 * np.cos(2 * phase), 2.0),
    (0.016 * np.sin(phase), 4.8),
    (0.04 * np.sin(phase) + 0.01 * np.sin(2 * phase + 0.7), 3.1),
    (0.045 * np.sin(phase), 1.2),
]
shape = _shapes.SplineShape(knots=64)
oracle = _orbit.Oracle(
    params=lj.Params(),
    a_max=jnp.asarray(a_max),
    max_steps=jnp.asarray(4000, jnp.int32),
    tol=jnp.asarray(1e-12),
    shape=shape,
    contact="paper",
    dt=0.01,
    max_iter=12,
)
theta = jnp.asarray(np.stack([shape.fit(v / a_max, w) for v, w in strokes]))
n = 4


def timed():
    """One transient and one `orbits` call: their results and CPU seconds."""
    c0 = cpu()
    y = oracle.transient(theta, jnp.zeros((n, 3)), jnp.ones(n, bool), jnp.asarray(20, jnp.int32)).block_until_ready()
    c1 = cpu()
    orb = jax.block_until_ready(oracle.orbits(theta, y, jnp.ones(n, jnp.int32)))
    return y, orb, c1 - c0, cpu() - c1


_, _, tt, to = timed()
print(f"cold: transient {tt:.1f} CPU s, orbits {to:.1f}")
for rep in range(2):
    y, orb, tt, to = timed()
    line = f"warm: transient {tt:.2f} CPU s, orbits {to:.2f}"
    if "nograd" in sys.argv:
        c2 = cpu()
        o2 = jax.block_until_ready(oracle.orbits(theta, y, jnp.ones(n, jnp.int32), False))
        c3 = cpu()
        dy = float(jnp.max(jnp.abs(o2.y - orb.y)))
        dfig = float(jnp.max(jnp.abs(o2.figures - orb.figures)))
        line += f", orbits without gradient {c3 - c2:.2f}; max difference y {dy}, figures {dfig}"
    print(line, flush=True)
