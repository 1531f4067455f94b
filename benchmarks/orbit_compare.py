"""The exact optimiser's orbit oracle, old commit against new: outputs and sensitivities.

Each commit is checked out into a temporary git worktree and run in its own process (float64).
On a few decision vectors of both shape families (a 64-knot spline, the optimiser's default, and
a Fourier series of 16 harmonics), at a slow and a fast base frequency, each process runs the
oracle of `optimisation._exact` (`gaits._orbit.Oracle`, `contact="paper"`, `dt = 0.01`) as the
optimiser does: a transient of 20 periods from the relaxed spring, then Newton's method on the
period map with the implicit-function gradients. Printed per decision vector: the largest
relative difference new vs old of the transient's end state, the orbit's fixed point, its figures
$(\\Delta X, e_d, \\min N)$, their gradient and the monodromy (relative to the largest entry of
each), and each side's Newton iterations and residual.

    python benchmarks/orbit_compare.py OLD NEW
"""

import os
import subprocess
import sys
import tempfile

import numpy as np


CHILD = r"""
import sys
import jax
jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp
import numpy as np
import locomotion_jax as lj
from locomotion_jax.gaits import _orbit
from locomotion_jax.optimisation import _shapes

a_max, G = 0.05, 256
phase = np.arange(G) * 2 * np.pi / G
strokes = [
    (0.03 * np.sin(phase) + 0.004 * np.cos(2 * phase) + 0.005 * np.sin(3 * phase), 2.0),
    (0.016 * np.sin(phase) - 0.003 * np.cos(2 * phase) + 0.002 * np.cos(3 * phase), 4.8),
    (0.045 * np.sign(np.sin(phase)) * np.abs(np.sin(phase)) ** 0.3, 1.2),
    (0.04 * np.sin(phase) + 0.01 * np.sin(2 * phase + 0.7), 3.1),
]
out = {}
for shape in (_shapes.SplineShape(knots=64), _shapes.FourierShape(harmonics=16)):
    oracle = _orbit.Oracle(params=lj.Params(), a_max=jnp.asarray(a_max), max_steps=jnp.asarray(4000, jnp.int32),
                           tol=jnp.asarray(1e-12), shape=shape, contact="paper", dt=0.01, max_iter=12)
    theta = jnp.asarray(np.stack([shape.fit(v / a_max, w) for v, w in strokes]))
    n = theta.shape[0]
    y = oracle.transient(theta, jnp.zeros((n, 3)), jnp.ones(n, bool), jnp.asarray(20, jnp.int32))
    orb = oracle.orbits(theta, y, jnp.ones(n, jnp.int32))
    out |= {f"{shape.name}_transient": np.asarray(y)}
    out |= {f"{shape.name}_{k}": np.asarray(v) for k, v in orb._asdict().items()}
np.savez(sys.argv[1], **out)
"""


def main(argv: list[str]) -> None:
    if len(argv) != 2:
        sys.exit(__doc__)
    root = subprocess.check_output(["git", "rev-parse", "--show-toplevel"], text=True).strip()
    res = {}
    with tempfile.TemporaryDirectory() as tmp:
        for label, commit in zip(("old", "new"), argv):
            tree = os.path.join(tmp, label)
            subprocess.check_call(["git", "-C", root, "worktree", "add", "--detach", "-q", tree, commit])
            path = os.path.join(tmp, f"{label}.npz")
            env = dict(os.environ, PYTHONPATH=tree)
            subprocess.check_call([sys.executable, "-c", CHILD, path], cwd=tree, env=env)
            res[label] = dict(np.load(path))
            subprocess.call(["git", "-C", root, "worktree", "remove", "--force", tree])
    old, new = res["old"], res["new"]

    def rel(a, b, axes):
        scale = np.max(np.abs(a), axis=axes)
        return np.max(np.abs(a - b), axis=axes) / np.where(scale > 0, scale, 1)

    print("| shape | row | ok old/new | Newton it. old/new | residual old/new | transient | y | figures "
          "| gradient | monodromy |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|")
    for shape in ("spline", "fourier"):
        g = lambda d, k: d[f"{shape}_{k}"]
        for i in range(g(old, "y").shape[0]):
            keys = ("transient", "y", "figures", "gradient", "monodromy")
            cols = [rel(g(old, k)[i], g(new, k)[i], None) for k in keys]
            print(f"| {shape} | {i} | {g(old, 'ok')[i]}/{g(new, 'ok')[i]} "
                  f"| {g(old, 'n_iter')[i]}/{g(new, 'n_iter')[i]} "
                  f"| {g(old, 'residual')[i]:.1e}/{g(new, 'residual')[i]:.1e} | "
                  + " | ".join(f"{c:.1e}" for c in cols) + " |")  # fmt: skip
        figs = [rel(g(old, "figures")[:, j], g(new, "figures")[:, j], None) for j in range(3)]
        print(f"  {shape}: figures (dX, e_d, min N) max rel. diff " + ", ".join(f"{f:.1e}" for f in figs))


if __name__ == "__main__":
    main(sys.argv[1:])
