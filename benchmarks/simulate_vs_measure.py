"""`simulate(params, T, save_at=...)` against `measure` over the same runs (one process, one device).

Both integrate the same configurations (omega ~ U[1, 25], a ~ U[0.01, 0.1] as in
benchmarks/run.py, `contact="paper"`, so no run stops early) from t = 0 to
t_end = t_start + horizon: `measure` with `z=1e30` (never reached) and that horizon,
`simulate` to the same end time, saving at `--saves` equally spaced times ending at
t_end (one run per count). Prints the wall and CPU throughput (configurations x simulated
time units per second, the best of `--repeats` rounds after a warm-up) and the ratio
of simulate's throughput to measure's.

    python benchmarks/simulate_vs_measure.py [--batch 1024] [--dt 0.01] [--horizon 100] [--saves 1 101 1001]
"""

import argparse
import time

import jax


jax.config.update("jax_enable_x64", True)

import locomotion_jax as lj  # noqa: E402
import numpy as np  # noqa: E402


def best(runs: dict, repeats: int) -> dict[str, tuple[float, float]]:
    """Lowest wall and CPU seconds of each run over `repeats` rounds, after one warm-up each.

    The runs take turns within a round, so a change in the machine's load between
    rounds reaches all of them alike.
    """
    for fn in runs.values():
        jax.block_until_ready(fn())
    times = {name: ([], []) for name in runs}
    for _ in range(repeats):
        for name, fn in runs.items():
            c0, t0 = time.process_time(), time.perf_counter()
            jax.block_until_ready(fn())
            times[name][0].append(time.perf_counter() - t0)
            times[name][1].append(time.process_time() - c0)
    return {name: (min(w), min(c)) for name, (w, c) in times.items()}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--batch", type=int, default=1024)
    parser.add_argument("--dt", type=float, default=0.01)
    parser.add_argument("--horizon", type=float, default=100.0)
    parser.add_argument("--saves", type=int, nargs="+", default=[1, 101, 1001], help="save counts of simulate")
    parser.add_argument("--float32", action="store_true")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    dtype = np.float32 if args.float32 else np.float64
    rng = np.random.default_rng(0)
    om, a = rng.uniform(1.0, 25.0, args.batch), rng.uniform(0.01, 0.1, args.batch)
    p = lj.Params(omega=om.astype(dtype), a=a.astype(dtype))
    dyn = lj.Exact(dt=args.dt)
    t_end = float(lj.Params().t_start) + args.horizon
    kw = dict(dynamics=dyn, contact="paper")
    work = args.batch * t_end
    print(
        f"batch {args.batch}, {np.dtype(dtype).name}, dt {args.dt}, t_end {t_end:.2f}, "
        f"{jax.devices()[0]}, best of {args.repeats}"
    )
    runs = {"measure": lambda: lj.measure(p, z=1e30, horizon=args.horizon, window=25.0, **kw)}
    for n in args.saves:
        save_at = np.linspace(0.0, t_end, n + 1)[1:]
        runs[f"simulate, {n} save(s)"] = lambda s=save_at: lj.simulate(p, t_end, save_at=s, **kw)
    times = best(runs, args.repeats)
    wall_m, cpu_m = times["measure"]
    for name, (wall, cpu) in times.items():
        line = (
            f"{name:21s} wall {wall:7.3f} s {work / wall:9.3g} cfg-tu/s CPU {cpu:6.3f} s {work / cpu:9.3g} cfg-tu/CPU-s"
        )
        if name != "measure":
            line += f"   simulate/measure: wall {wall_m / wall:.2f}, CPU {cpu_m / cpu:.2f}"
        print(line)


if __name__ == "__main__":
    main()
