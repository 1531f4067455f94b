"""Mechanisms of N = 4 ... 64 bodies in the engine's two layouts, side by side in one run: `measure`'s
first call (compilation included) and throughput per body, and `steady_gait`'s first call.

    python benchmarks/mechanism_scaling.py [--sizes 4,8,16,32,64] [--max-unrolled 16] [--batch 64]
        [--gait-sizes 4,8,16] [--max-unrolled-gait 8] [--carried] [--knots M]

The mechanism is a worm of N segments in a pipe, which a `Chain` cannot express: neighbours joined by
springs driven as a travelling wave (omega in [1.5, 4], phase lag in [0.3, 2.5] over the batch), every
third segment joined to the one after next by a passive spring, the head tied to the pipe's end (the
wall) by a soft spring and a damper, a drag-like external force on the tail, anisotropic Coulomb
friction (bristles), strict contact, `Exact(dt=0.03)`, measured over t = 5 ... 25. `measure`'s first
call is its wall time in a process that has run no other mechanism of that N and layout, its
compilation that less the best of two calls again (wall), which give the throughput in
body-time-units per CPU-second (`time.process_time`).
`steady_gait` (one configuration, periods 1, transient 20, `Exact(dt=0.01)`) is timed on its first call
alone. Prints a Markdown table and the load average before and after.

With `--carried` each of the N/2 segments carries an internal mass on a spring and a damper (a
vibration-driven capsule worm: bodies without ground contact, N bodies in all), driven by an internal
force in phase with its segment's wave.

With `--knots M` the travelling-wave springs are driven by periodic splines of M control values (the
wave's values at the knots) beside the Fourier drag force: a mechanism of mixed waveforms, whose splines
the array layout reads from its bank of waveforms (`model._bank`).
"""

import argparse
import os
import time

import jax


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import locomotion_jax as lj  # noqa: E402
import numpy as np  # noqa: E402


T_START, HORIZON = 5.0, 20.0


def pipe(n: int, B: int, layout: str, carried: bool = False, knots: int = 0) -> lj.Mechanism:
    """The worm of the module docstring: `n` segments, or with `carried` `n // 2` segments carrying
    one internal mass each; with `knots`, its waves splines of that many control values."""
    if carried:
        return capsule_worm(n // 2, B, layout)
    rng = np.random.default_rng(0)
    omega, phi = rng.uniform(1.5, 4.0, B), rng.uniform(0.3, 2.5, B)
    wave = lambda j: lj.Fourier(jnp.asarray(0.08 * np.sin(-phi * j))[:, None],
                                jnp.asarray(0.08 * np.cos(-phi * j))[:, None], jnp.asarray(omega), 1.0)  # fmt: skip
    if knots:
        at = 2 * np.pi * np.arange(knots) / knots
        wave = lambda j: lj.Spline(jnp.asarray(0.08 * np.sin(at - (phi * j)[:, None])), jnp.asarray(omega), 1.0)
    links: list = [lj.Spring(j, j + 1, k=40.0, rest=wave(j)) for j in range(n - 1)]
    links += [lj.Spring(j, j + 2, k=5.0, rest=2.0) for j in range(0, n - 2, 3)]
    drag = lj.Fourier(jnp.asarray([0.02]), jnp.asarray([0.0]), jnp.asarray(omega), -0.05)
    links += [lj.Spring(lj.WALL, 0, k=0.5, rest=1.0), lj.Damper(lj.WALL, 0, c=0.05), lj.ExternalForce(n - 1, drag)]
    return lj.Mechanism(masses=np.ones((B, n)), c=0.02, x0=1.0 + np.arange(n), links=links,
                        friction=lj.AnisotropicCoulomb(0.7, 0.9, 0.5, 0.7), layout=layout)  # fmt: skip


def capsule_worm(n: int, B: int, layout: str) -> lj.Mechanism:
    """`pipe(n, ...)` with an internal mass of 0.3 in each segment `j` (body `n + j`, carried by `j`) on a
    spring (k = 10) and a damper (c = 0.3), pushed by a force $0.2 \\sin(\\omega t - j\\varphi)$."""
    worm = pipe(n, B, layout)
    rng = np.random.default_rng(0)
    omega, phi = rng.uniform(1.5, 4.0, B), rng.uniform(0.3, 2.5, B)
    push = lambda j: lj.Fourier(jnp.asarray(0.2 * np.sin(-phi * j))[:, None],
                                jnp.asarray(0.2 * np.cos(-phi * j))[:, None], jnp.asarray(omega), 0.0)  # fmt: skip
    links = list(worm.links)
    for j in range(n):
        links += [lj.Spring(j, n + j, k=10.0, rest=0.0), lj.Damper(j, n + j, c=0.3), lj.Force(j, n + j, push(j))]
    masses = np.concatenate([np.ones((B, n)), np.full((B, n), 0.3)], -1)
    return lj.Mechanism(masses=masses, c=0.02, x0=np.tile(1.0 + np.arange(n), 2), links=links,
                        friction=[lj.AnisotropicCoulomb(0.7, 0.9, 0.5, 0.7)] * n + [None] * n,
                        carried_by=[None] * n + list(range(n)), layout=layout)  # fmt: skip


def measure_row(n: int, B: int, layout: str, carried: bool = False, knots: int = 0) -> tuple[float, float, float]:
    """`measure`'s first call and its compilation (the first call less the best call again, wall
    seconds), and body-time-units per CPU-second of the best call again."""
    mech = pipe(n, B, layout, carried, knots)
    run = lambda: jax.block_until_ready(lj.measure(mech, 1e9, horizon=HORIZON, t_start=T_START,
                                                   dynamics=lj.Exact(dt=0.03)).tau_z)  # fmt: skip
    t = time.perf_counter()
    run()
    first = time.perf_counter() - t
    cpu, wall = [], []
    for _ in range(2):
        c, t = time.process_time(), time.perf_counter()
        run()
        cpu.append(time.process_time() - c)
        wall.append(time.perf_counter() - t)
    return first, first - min(wall), n * B * (T_START + HORIZON) / min(cpu)


def gait_row(n: int, layout: str, carried: bool = False, knots: int = 0) -> tuple[float, int]:
    mech = pipe(n, 1, layout, carried, knots)[0]
    t = time.perf_counter()
    g = lj.steady_gait(mech, periods=(1,), transient=20, dynamics=lj.Exact(dt=0.01))
    jax.block_until_ready(g.state)
    return time.perf_counter() - t, int(g.status)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="4,8,16,32,64")
    ap.add_argument("--max-unrolled", type=int, default=16)
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--gait-sizes", default="4,8,16")
    ap.add_argument("--max-unrolled-gait", type=int, default=8)
    ap.add_argument("--carried", action="store_true", help="N/2 segments carrying an internal mass each")
    ap.add_argument("--knots", type=int, default=0, help="the waves as splines of this many control values")
    args = ap.parse_args()
    print("load average before:", os.getloadavg())
    print("| N | layout | measure: first call (s) | compile (s) | body-tu per CPU-s | steady_gait: first call (s) |")
    print("|---|---|---|---|---|---|")
    gaits = [int(q) for q in args.gait_sizes.split(",") if q]
    for n in [int(q) for q in args.sizes.split(",")]:
        for layout in ("unrolled", "array"):
            if layout == "unrolled" and n > args.max_unrolled:
                continue
            first, compile_, rate = measure_row(n, args.batch, layout, args.carried, args.knots)
            gait = "-"
            if n in gaits and (layout == "array" or n <= args.max_unrolled_gait):
                seconds, status = gait_row(n, layout, args.carried, args.knots)
                gait = f"{seconds:.1f} ({lj.GaitStatus(status).name})"
            print(f"| {n} | {layout} | {first:.1f} | {compile_:.1f} | {rate:,.0f} | {gait} |", flush=True)
    print("load average after:", os.getloadavg())


if __name__ == "__main__":
    main()
