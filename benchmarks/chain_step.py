"""Cost of one iteration of the N-mass exact engine: this tree's, another revision's, and the two-mass engine's
(`locomotion_jax/dynamics/_exact.py`, in trees that still have it).

A `vmap` over B configurations of a `fori_loop` of ITERS engine steps (no queue, no saves: the
step alone; the loop returns the last mass's position, e_d and both margins, so that XLA keeps
every carried quantity), compiled with the engine's compiler options. The revisions' engines run
interleaved in one process, REP rounds each; each run's cost is the CPU time of the process's
busiest thread (`/proc/self/task/*/schedstat`): the loop's own thread, robust to other load on
a shared machine. Printed: per program the compiled flops per configuration-iteration and its
fused kernels, the largest difference of the final positions and e_d against the other
revision's engine, the median (min, max) over rounds of the ratio of busiest-thread CPU times
to the two-mass engine's at N = 2 and to the other revision's at every N, and ns per
configuration-iteration.

    python benchmarks/chain_step.py [--old main] [--N 2,4,8] [--B 64] [--iters 1000] [--rep 7]

The configurations: omega in [1, 25], a in [0.01, 0.1]; N = 2 is `Chain.from_params` (the
two-mass model), N > 2 a travelling wave on unit masses with Coulomb(0.7, 0.5); float64,
dt = 0.03, paper contact, z unreachable. The other revision's engine module
(`locomotion_jax/dynamics/_engine.py` there, `_chain_exact.py` in older trees) is loaded from git
into this tree's package, so it must use this tree's helpers (`_numerics`, `_motion`).
"""

import argparse
import os
import subprocess
import sys
import types
from pathlib import Path

import jax


jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402


ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import locomotion_jax as lj  # noqa: E402
from locomotion_jax.dynamics import _engine as new_engine  # noqa: E402
from locomotion_jax.dynamics._compile import COMPILER_OPTIONS  # noqa: E402
from locomotion_jax.run._batch import prepare, prepare_chain  # noqa: E402


try:  # the two-mass engine, in older trees only
    from locomotion_jax.dynamics import _exact as two_mass  # pyright: ignore  # noqa: E402
except ImportError:
    two_mass = None


def load_engine(rev: str) -> types.ModuleType:
    """The exact engine of revision `rev`, as a module inside this tree's `locomotion_jax.dynamics`
    (older trees name the module `_chain_exact` and its helper `_chain_motion`)."""
    for path in ("locomotion_jax/dynamics/_engine.py", "locomotion_jax/dynamics/_chain_exact.py"):
        show = subprocess.run(["git", "show", f"{rev}:{path}"], cwd=ROOT, capture_output=True, text=True)
        if show.returncode == 0:
            break
    else:
        raise FileNotFoundError(f"no exact engine module in revision {rev}")
    src = show.stdout.replace("._chain_motion ", "._motion ").replace("_chain_motion as motion", "_motion as motion")
    name = "locomotion_jax.dynamics._engine_old"
    mod = types.ModuleType(name)
    mod.__package__ = "locomotion_jax.dynamics"
    sys.modules[name] = mod
    exec(compile(src, f"{rev}:{path}", "exec"), mod.__dict__)
    return mod


def chain_mech(n: int, om: np.ndarray, a: np.ndarray) -> lj.Chain:
    if n == 2:
        return lj.Chain.from_params(lj.Params(omega=om, a=a))
    phi = np.linspace(0, np.pi, om.size)[:, None, None]
    j = np.arange(n - 1)[None, :, None]
    waves = lj.SpringFourier(-a[:, None, None] * np.sin(phi * j), a[:, None, None] * np.cos(phi * j), om)
    return lj.Chain(masses=np.ones((om.size, n)), waveforms=waves, friction=lj.Coulomb(0.7, 0.5))


def busiest_thread_ns() -> dict:
    out = {}
    for tid in os.listdir("/proc/self/task"):
        try:
            with open(f"/proc/self/task/{tid}/schedstat") as f:
                out[tid] = int(f.read().split()[0])
        except OSError:
            pass
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old", default="main", help="the revision whose chain engine is compared")
    ap.add_argument("--N", default="2,4,8")
    ap.add_argument("--B", type=int, default=64)
    ap.add_argument("--iters", type=int, default=1000)
    ap.add_argument("--rep", type=int, default=7)
    args = ap.parse_args()
    old = load_engine(args.old)
    B, iters, contact, dt = args.B, args.iters, "paper", 0.03
    om, a = np.linspace(1, 25, B), np.linspace(0.01, 0.1, B)
    ns = [int(x) for x in args.N.split(",")]
    never = jnp.asarray(1e9)

    def two(pp, w):
        eng = two_mass
        assert eng is not None
        P = eng.consts(pp, w)
        s = eng.init(pp, w, contact, jnp.zeros(()), pp.lbar)
        s = jax.lax.fori_loop(0, iters, lambda i, s: eng.step(pp, w, contact, dt, s, never, None, P)[0], s)
        return s.y.x2, s.y.ed, s.cross, s.near

    def chain(eng, tuples):
        def run(C, ok):
            if hasattr(C, "physics") and not hasattr(eng, "initial_positions"):  # the physics interface
                P = C.physics()
                s = eng.init(P, contact, P.initial_positions("paper"))
                s = jax.lax.fori_loop(0, iters, lambda i, s: eng.step(P, contact, dt, s, never)[0], s)
                return s.y.x[-1], s.y.ed, s.cross, s.near
            s = eng.init(C, contact, eng.initial_positions(C, "paper"))
            if tuples:
                P = eng.consts(C)
                body = lambda i, s: eng.step(None, contact, dt, s, never, P=P)[0]
            else:
                body = lambda i, s: eng.step(C, contact, dt, s, never)[0]
            s = jax.lax.fori_loop(0, iters, body, s)
            return (s.y.x[-1] if tuples else s.y.x[..., -1]), s.y.ed, s.cross, s.near

        return run

    programs = {}
    if 2 in ns and two_mass is not None:
        flat, wave, axes, _ = prepare(lj.Params(omega=om, a=a), None, None)
        programs["two-mass"] = (jax.vmap(two, in_axes=(0, axes)), (flat, wave))
    for n in ns:
        cflat, ok, _ = prepare_chain(chain_mech(n, om, a), None)
        programs[f"{args.old} N={n}"] = (jax.vmap(chain(old, False)), (cflat, ok))
        programs[f"this N={n}"] = (jax.vmap(chain(new_engine, True)), (cflat, ok))
    compiled = {}
    for name, (fn, fargs) in programs.items():
        c = jax.jit(fn, compiler_options=COMPILER_OPTIONS).lower(*fargs).compile()
        ca = c.cost_analysis()
        ca = ca[0] if isinstance(ca, list) else ca
        flops = ca.get("flops", 0) / B if ca else float("nan")  # the loop body is counted once
        print(f"{name:14s} flops per configuration-iteration {flops:7.0f}  fusions {c.as_text().count('fusion('):4d}")
        compiled[name] = (c, fargs)
    outs = {k: c(*fa) for k, (c, fa) in compiled.items()}
    for n in ns:
        o, w = outs[f"{args.old} N={n}"], outs[f"this N={n}"]
        dx, de, dc, dn = (float(jnp.max(jnp.abs(p - q) / jnp.maximum(jnp.abs(p), 1e-300))) for p, q in zip(o, w))
        print(
            f"N={n}, this vs {args.old} after {iters} steps: max relative difference of x_N {dx:.3g}, e_d {de:.3g}, "
            f"the margins (squared phases) {dc:.3g}, {dn:.3g}"
        )
    cpu = {k: [] for k in compiled}
    for _ in range(args.rep):
        for k, (c, fa) in compiled.items():
            before = busiest_thread_ns()
            jax.block_until_ready(c(*fa))
            after = busiest_thread_ns()
            cpu[k].append(max(after[i] - before.get(i, 0) for i in after) * 1e-9)

    def ratio(k, base):
        r = sorted(x / y for x, y in zip(cpu[k], cpu[base]))
        return f"{r[len(r) // 2]:.3f} (min {r[0]:.3f}, max {r[-1]:.3f})"

    print("\nbusiest-thread CPU ratios, median over rounds:")
    for n in ns:
        if n == 2 and "two-mass" in cpu:
            print(f"  this N=2 / two-mass: {ratio('this N=2', 'two-mass')}")
            print(f"  {args.old} N=2 / two-mass: {ratio(f'{args.old} N=2', 'two-mass')}")
        print(f"  this N={n} / {args.old} N={n}: {ratio(f'this N={n}', f'{args.old} N={n}')}")
    print("\nns per configuration-iteration (busiest thread, median):")
    for k, v in cpu.items():
        print(f"  {k:14s} {sorted(v)[len(v) // 2] / iters / B * 1e9:8.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
