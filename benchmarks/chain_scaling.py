"""Chains of N = 2 ... 64 masses in the engine's two layouts, side by side in one run: compile time and
throughput per mass of `measure` (batch 256, float64), the array layout (`Chain(layout="array")`) for
every N and the unrolled one (`layout="unrolled"`) up to `--max-unrolled` (its compile time grows
with N: about 10 minutes at N = 32 on the 2-core machine).

    python benchmarks/chain_scaling.py [--sizes 2,4,8,16,32,64] [--max-unrolled 8] [--batch 256] [--contact hop]
    python benchmarks/chain_scaling.py --dynamics smoothed [--batch 64]

Each row compiles the measurement's program once (`time.perf_counter` around `.lower().compile()`)
and runs the compiled program twice; throughput is mass-time-units per CPU-second of this process
(`time.process_time`, which a shared machine's other load disturbs less than the wall clock), and
per wall-second. The worms: travelling waves of omega in [1.5, 4], a in [0.03, 0.08] and phase lags
in [0.3, 2.5] over the batch, anisotropic Coulomb friction (bristles), paper contact, dt = 0.03,
measured over t = 5 ... 25. With `--contact hop` (flight and landing, SPEC §10) the waves are
faster and larger, omega in [6, 8] and a in [0.04, 0.07], so that the worms hop; some of them
hop into a neighbour (`Status.COLLISION`, about 12 %), and those count no work (a lower bound on
the throughput, the same configurations in both layouts). Prints one
Markdown table, the load average before and after, and the ratios of issue 28: compile time at
N = 64 over N = 4 and throughput per mass at N = 64 over N = 2 (each layout's own, and the array
layout's at 64 against the unrolled at 2).

With `--dynamics smoothed` the rows are the smoothed engine's (`lj.Smoothed(eps=1e-3)`, diffrax Tsit5 at
its default tolerances) on the same worms, through `lj.measure` (its window of 25 time units sampled for
the regime, not counted as work): compile is the first call's wall time less the best of two calls
again, which then give the throughput.
"""

import argparse
import os
import time
from collections.abc import Callable
from typing import Any

import jax


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import locomotion_jax as lj  # noqa: E402
import numpy as np  # noqa: E402
from locomotion_jax.dynamics import _measure  # noqa: E402
from locomotion_jax.dynamics._runs import default_lanes, start_code  # noqa: E402
from locomotion_jax.model._chain_array import engine_physics  # noqa: E402


DT, T_START, HORIZON = 0.03, 5.0, 20.0


def worms(n: int, B: int, layout: str, contact: str = "paper") -> lj.Chain:
    rng = np.random.default_rng(0)
    (w0, w1), (a0, a1) = ((6.0, 8.0), (0.04, 0.07)) if contact == "hop" else ((1.5, 4.0), (0.03, 0.08))
    omega, a, phi = rng.uniform(w0, w1, B), rng.uniform(a0, a1, B), rng.uniform(0.3, 2.5, B)
    j = np.arange(n - 1)[None, :, None]
    waves = lj.SpringFourier(-a[:, None, None] * np.sin(phi[:, None, None] * j),
                             a[:, None, None] * np.cos(phi[:, None, None] * j), omega)  # fmt: skip
    return lj.Chain(masses=np.ones((B, n)), k=50.0, d=0.5, lbar=3.0, c=0.01, waveforms=waves,
                    friction=lj.AnisotropicCoulomb(0.7, 0.9, 0.5, 0.7), layout=layout)  # fmt: skip


def _best_of_two(run: Callable[[], Any]) -> tuple[Any, float, float]:
    """`run()` twice: its last output and the smallest CPU time of this process and wall time."""
    cpus, walls, out = [], [], None
    for _ in range(2):
        c0, w0 = time.process_time(), time.perf_counter()
        out = jax.block_until_ready(run())
        cpus.append(time.process_time() - c0)
        walls.append(time.perf_counter() - w0)
    return out, min(cpus), min(walls)


def smoothed_row(n: int, B: int, layout: str) -> dict:
    chain = worms(n, B, layout)
    run = lambda: lj.measure(chain, 1e30, horizon=HORIZON, t_start=T_START, dynamics=lj.Smoothed(1e-3),
                             contact="paper")  # fmt: skip
    w0 = time.perf_counter()
    jax.block_until_ready(run())
    first = time.perf_counter() - w0
    out, cpu, wall = _best_of_two(run)
    done = np.asarray(out.status) == lj.Status.OK
    assert np.all(done), f"N={n} {layout}: statuses {np.unique(np.asarray(out.status))}"
    work = int(done.sum()) * n * (T_START + HORIZON)
    return dict(N=n, layout=layout, compile=first - wall, per_cpu=work / cpu, per_wall=work / wall,
                steps=float(np.mean(np.asarray(out.n_steps))), flying=0.0)  # fmt: skip


def row(n: int, B: int, layout: str, lanes: int = 0, contact: str = "paper") -> dict:
    chain = worms(n, B, layout, contact).broadcast()  # as the front ends hand it to the engine
    P = engine_physics(chain)
    valid = chain.is_valid()
    ts = jnp.full((B,), T_START)
    dyn = (P, valid, ts, None, jnp.asarray(1e30), jnp.asarray(HORIZON), jnp.asarray(HORIZON))
    cap = jnp.asarray(0, jnp.int32)
    lanes = lanes or default_lanes(B, P.lane_width)
    t0 = time.perf_counter()
    start = start_code("paper")
    exe = _measure._measure_batch.lower(*dyn, contact, start, DT, cap, lanes).compile()  # pyright: ignore[reportFunctionMemberAccess]
    compile_s = time.perf_counter() - t0
    out, cpu, wall = _best_of_two(lambda: exe(*dyn, start, DT, cap))  # the start code and the step are data
    status = np.asarray(out["status"])
    done = status == lj.Status.OK
    allowed = done | (status == lj.Status.COLLISION) if contact == "hop" else done
    assert np.all(allowed), f"N={n} {layout}: statuses {np.unique(status)}"
    work = int(done.sum()) * n * (T_START + HORIZON)  # mass-time-units of the runs that finished
    flying = float(np.nanmean(np.asarray(out["flight_fraction"])[done])) if contact == "hop" else 0.0
    return dict(N=n, layout=layout, compile=compile_s, per_cpu=work / cpu, per_wall=work / wall,
                steps=float(np.mean(np.asarray(out["n_steps"]))), flying=flying)  # fmt: skip


def main() -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--sizes", default="2,4,8,16,32,64")
    ap.add_argument("--max-unrolled", type=int, default=8)
    ap.add_argument("--batch", type=int, default=256)
    ap.add_argument("--layouts", default="unrolled,array")
    ap.add_argument("--lanes", type=int, default=0, help="the queue's lanes (default: `_runs.default_lanes`)")
    ap.add_argument("--contact", default="paper", choices=("strict", "paper", "hop"))
    ap.add_argument("--dynamics", default="exact", choices=("exact", "smoothed"))
    args = ap.parse_args()
    if args.dynamics == "smoothed" and args.contact != "paper":
        ap.error("--dynamics smoothed runs the paper's contact reading only")
    sizes = [int(s) for s in args.sizes.split(",")]
    layouts = args.layouts.split(",")
    print(f"load average before: {os.getloadavg()}; CPUs: {os.cpu_count()}; jax {jax.__version__}; "
          f"contact {args.contact!r}; {args.dynamics} dynamics", flush=True)  # fmt: skip
    rows = {}
    print("| N | layout | compile (s) | mass-tu per CPU-s | mass-tu per wall-s | steps per config | time in flight |")
    print("|---|---|---|---|---|---|---|", flush=True)
    for n in sizes:
        for layout in layouts:
            if layout == "unrolled" and n > args.max_unrolled:
                continue
            if args.dynamics == "smoothed":
                r = smoothed_row(n, args.batch, layout)
            else:
                r = row(n, args.batch, layout, args.lanes, args.contact)
            rows[n, layout] = r
            print(f"| {n} | {layout} | {r['compile']:.1f} | {r['per_cpu']:,.0f} | {r['per_wall']:,.0f} | "
                  f"{r['steps']:.0f} | {r['flying']:.3f} |", flush=True)  # fmt: skip
    print(f"load average after: {os.getloadavg()}")
    lo, hi = min(sizes), max(sizes)
    for layout in layouts:
        if (4, layout) in rows and (hi, layout) in rows:
            print(f"{layout}: compile N={hi} / N=4: {rows[hi, layout]['compile'] / rows[4, layout]['compile']:.2f}")
        if (lo, layout) in rows and (hi, layout) in rows:
            ratio = rows[hi, layout]["per_cpu"] / rows[lo, layout]["per_cpu"]
            print(f"{layout}: throughput per mass per CPU-s, N={hi} / N={lo}: {ratio:.2f}")
    if (hi, "array") in rows and (lo, "unrolled") in rows:
        ratio = rows[hi, "array"]["per_cpu"] / rows[lo, "unrolled"]["per_cpu"]
        print(f"array N={hi} / unrolled N={lo}, throughput per mass per CPU-s: {ratio:.2f}")
        if (4, "unrolled") in rows:
            ratio = rows[hi, "array"]["compile"] / rows[4, "unrolled"]["compile"]
            print(f"compile array N={hi} / unrolled N=4: {ratio:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
