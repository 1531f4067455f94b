"""Cost of derivatives of the exact engine, relative to plain runs.

1. `measure`: for a batch of `B` configurations and `p` parameters, `jax.jacfwd` (one
   compiled call carrying `p` tangents) against the `p + 1` plain runs that a one-sided finite
   difference needs, and `jax.grad` of the batch's summed `tau_z` (one reverse pass) against one
   plain run, with its largest relative difference from the `jacfwd` row.
2. A chain's steady gait (`--gait`): a 4-mass worm with 32 Fourier harmonics per spring
   (3 springs x 64 coefficients: 192 parameters with log omega and without the fixed phase):
   one steady-gait solve (Newton's method, forward mode in the 7 state directions), the
   forward-mode oracle (`ChainOracle.orbits`: `jacfwd` through the period map in all 7 + 192
   directions) and `jax.grad` of the cost of transport by the adjoint solve
   (`gaits._adjoint`), with their ratios and the largest relative difference of the two gradients;
   and `jax.jacrev` of all three figures by the adjoint (the optimisers' gradient) against the
   forward-mode oracle's.

In one process, compilation excluded (each timed call runs once to compile, then `REPEAT`
times; the best is printed). Prints Markdown tables and the load average.

    python benchmarks/gradients.py [--batch 256] [--params 1 5] [--gait] [--no-measure]
"""

import argparse
import math
import os
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np


jax.config.update("jax_enable_x64", True)
import locomotion_jax as lj  # noqa: E402
from locomotion_jax.model._params import PARAM_NAMES  # noqa: E402


NAMES = ("omega", "a", "d", "mu_s", "mu_k")
REPEAT = 3


def best_of(fn, *args, repeat: int = REPEAT) -> float:
    jax.block_until_ready(fn(*args))
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(*args))
        times.append(time.perf_counter() - t0)
    return min(times)


def gait_benchmark(harmonics: int) -> None:
    from locomotion_jax.gaits import _adjoint as adj
    from locomotion_jax.gaits._element_orbit import ChainOracle, size

    N, omega, dt = 4, 3.0, 0.05
    S = N - 1
    chain = lj.Chain(masses=[1.0] * N, d=0.0, friction=lj.AnisotropicCoulomb(0.5, 0.9, 0.3, 0.7)).broadcast()
    steps = int(math.ceil(2 * math.pi / omega / dt)) * 3 + 200
    oracle = ChainOracle(chain=chain, a_max=jnp.asarray(0.1), max_steps=jnp.asarray(steps, jnp.int32),
                         tol=jnp.asarray(1e-11), harmonics=harmonics, contact="paper", dt=dt, max_iter=30)  # fmt: skip
    phi = 2 * math.pi / 3
    A, B = np.zeros((S, harmonics)), np.zeros((S, harmonics))
    for j in range(S):  # a travelling wave with a second harmonic; the others 0
        A[j, :2] = -0.8 * math.sin(j * phi), 0.2 * math.sin(1 - 2 * j * phi)
        B[j, :2] = 0.8 * math.cos(j * phi), 0.2 * math.cos(1 - 2 * j * phi)
    theta = jnp.asarray(np.concatenate([A.ravel()[1:], B.ravel(), [math.log(omega)]]))
    p, ny = size(S, harmonics), 2 * N - 1
    one = jnp.ones(1, jnp.int32)
    y0 = oracle.transient(theta[None], jnp.zeros((1, ny)), jnp.ones(1, bool), jnp.asarray(30))
    orb = jax.tree_util.tree_map(lambda x: x[0], oracle.orbits(theta[None], y0, one))
    cap = steps  # the backward pass's bound (static; oracle.max_steps is traced here)
    ys = orb.y  # every timed call starts from the fixed point (Newton: one iteration)

    # Each timed function one compiled program taking the oracle and the start as arguments, as
    # a user's repeated call would be (unjitted, jax.grad retraces its Python on every call).
    solve = best_of(
        eqx.filter_jit(lambda th, o, y: adj.steady_gait(o, th, y, cap=cap).figures), theta, oracle, ys, repeat=20
    )
    fwd = best_of(
        eqx.filter_jit(lambda th, o, y: o.orbits(th[None], y[None], one).gradient), theta, oracle, ys, repeat=20
    )
    cot = lambda th, o, y: adj.cost_of_transport(adj.steady_gait(o, th, y, cap=cap))
    grad_fn = eqx.filter_jit(jax.grad(cot))
    rev = best_of(grad_fn, theta, oracle, ys, repeat=20)
    # What the optimisers need: the gradients of all three figures (speed, energy, smallest load).
    jac_fn = eqx.filter_jit(jax.jacrev(lambda th, o, y: adj.steady_gait(o, th, y, cap=cap).figures))
    jac = best_of(jac_fn, theta, oracle, ys, repeat=20)
    F, G = orb.figures, orb.gradient
    expect = G[1] / abs(F[0]) - F[1] * np.sign(F[0]) * G[0] / F[0] ** 2
    diff = float(np.max(np.abs(grad_fn(theta, oracle, ys) - expect)) / np.max(np.abs(expect)))
    jac_diff = float(np.max(np.abs(np.asarray(jac_fn(theta, oracle, ys)) - np.asarray(G))) / np.max(np.abs(G)))
    cost = float(F[1] / abs(F[0]))
    print(f"steady gait of a {N}-mass worm, {harmonics} harmonics per spring: p = {p} parameters, float64, "
          f"{jax.default_backend()}, converged {bool(orb.ok)}, cost of transport {cost:.6f}")  # fmt: skip
    print()
    print("| steady-gait solve (s) | jacfwd: oracle, 7 + p directions (s) | grad: adjoint (s) | jacfwd / solve "
          "| grad / solve | max rel. difference grad vs jacfwd |")  # fmt: skip
    print("|---|---|---|---|---|---|")
    print(f"| {solve:.4f} | {fwd:.4f} | {rev:.4f} | {fwd / solve:.2f} | {rev / solve:.2f} | {diff:.1e} |")
    print()
    print("The optimisers' gradient, of all three figures: forward mode (the oracle) against reverse mode")
    print()
    print("| jacfwd: oracle (s) | jacrev of the 3 figures: adjoint (s) | jacrev / jacfwd | max rel. difference |")
    print("|---|---|---|---|")
    print(f"| {fwd:.4f} | {jac:.4f} | {jac / fwd:.2f} | {jac_diff:.1e} |")


def total(tau: jax.Array) -> jax.Array:
    """The sum of the finite entries (z not reached: `inf`, left out)."""
    return jnp.sum(jnp.where(jnp.isfinite(tau), tau, 0))


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--batch", type=int, default=256)
    ap.add_argument("--params", type=int, nargs="+", default=[1, 5])
    ap.add_argument("--horizon", type=float, default=100.0)
    ap.add_argument("--gait", action="store_true", help="also the steady-gait benchmark")
    ap.add_argument("--harmonics", type=int, default=32)
    ap.add_argument("--no-measure", action="store_true", help="skip the measure benchmark")
    args = ap.parse_args()
    print(f"load average at start: {os.getloadavg()}")
    if args.gait:
        gait_benchmark(args.harmonics)
        print()
    if args.no_measure:
        print(f"load average at end: {os.getloadavg()}")
        return
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
    print("| p | plain run (s) | jacfwd (s) | jacfwd / (p + 1) plain runs | grad of sum tau_z (s) | grad / plain run "
          "| max rel. difference |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    for p in args.params:
        f = lambda d, p=p: run(d, p)
        g = jax.grad(lambda d, f=f: total(f(d)[0]))
        jac = best_of(lambda f=f, p=p: jax.jacfwd(f)(jnp.zeros(p)))
        rev = best_of(lambda g=g, p=p: g(jnp.zeros(p)))
        J = np.asarray(jax.jacfwd(f)(jnp.zeros(p)))[0]
        expect = np.sum(np.where(np.isfinite(J), J, 0), axis=0)
        diff = float(np.max(np.abs(np.asarray(g(jnp.zeros(p))) - expect)) / np.max(np.abs(expect)))
        ratio = jac / ((p + 1) * plain)
        print(f"| {p} | {plain:.2f} | {jac:.2f} | {ratio:.2f} | {rev:.2f} | {rev / plain:.1f} | {diff:.1e} |")
    print(f"load average at end: {os.getloadavg()}")


if __name__ == "__main__":
    main()
