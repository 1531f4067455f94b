"""Cost of forward-mode derivatives of the exact engine, relative to plain runs.

For a batch of `B` configurations and `p` parameters, `jax.jacfwd` of `measure`
(one compiled call carrying `p` tangents) against the `p + 1` plain runs that a
one-sided finite difference needs, in one process, compilation excluded (each
timed call runs once to compile, then `REPEAT` times). Prints a Markdown table.

    python benchmarks/gradients.py [--batch 256] [--params 1 5]
"""

import argparse
import time

import jax
import jax.numpy as jnp
import numpy as np


jax.config.update("jax_enable_x64", True)
import locomotion_jax as lj  # noqa: E402
from locomotion_jax.model._params import PARAM_NAMES  # noqa: E402


NAMES = ("omega", "a", "d", "mu_s", "mu_k")
REPEAT = 3


def best_of(fn) -> float:
    jax.block_until_ready(fn())
    times = []
    for _ in range(REPEAT):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--batch", type=int, default=256)
    ap.add_argument("--params", type=int, nargs="+", default=[1, 5])
    ap.add_argument("--horizon", type=float, default=100.0)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    omega = jnp.asarray(rng.uniform(1.0, 12.0, args.batch))
    a = jnp.asarray(rng.uniform(0.02, 0.08, args.batch))
    base = lj.Params(omega=omega, a=a).broadcast()

    def run(delta, p):
        shift = {n: delta[i] for i, n in enumerate(NAMES[:p])}
        params = lj.Params(**{n: getattr(base, n) + shift.get(n, 0.0) for n in PARAM_NAMES})
        m = lj.measure(params, z=1.0, horizon=args.horizon)
        return jnp.stack([m.tau_z, m.e_z, m.mean_speed])

    plain = best_of(lambda: run(jnp.zeros(1), 0))
    print(f"batch {args.batch}, measure(z=1, horizon={args.horizon:g}), float64, {jax.default_backend()}")
    print()
    print("| p | plain run (s) | jacfwd (s) | jacfwd / (p + 1) plain runs | derivatives per second |")
    print("|---|---|---|---|---|")
    for p in args.params:
        jac = best_of(lambda p=p: jax.jacfwd(lambda d: run(d, p))(jnp.zeros(p)))
        ratio = jac / ((p + 1) * plain)
        print(f"| {p} | {plain:.2f} | {jac:.2f} | {ratio:.2f} | {args.batch * p * 3 / jac:.0f} |")


if __name__ == "__main__":
    main()
