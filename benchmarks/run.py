"""Benchmark of locomotion_jax against an event-driven scipy baseline.

One run times, on the same machine and in separate processes (so that peak memory
and compile time are per case):

- the exact engine (`measure`, vmapped) for batches 1, 64, 1024, 8192 in float64
  and float32, on the paper's parameters with `omega` ~ U[1, 25] and `a` ~ U[0.01, 0.1]
  (the Fig. 6 range), `contact="paper"` (no lift-off stops) and a fixed horizon;
- the same batch split over two forced host devices through the sweep engine's
  `shard_map` (`_sharding.dispatch_chunk`), with each device's completion time;
- the smoothed engine (diffrax, `Smoothed(eps=1e-3)`) on a smaller batch;
- the cost of `jax.jacfwd` through `measure` with p parameters against p + 1 plain runs;
- the scipy baseline (`tests/reference.py`, `solve_ivp` DOP853 per mode, rtol 1e-9)
  on a few of the same configurations;
- the accuracy of every engine against a tight scipy reference (rtol 1e-11) on
  those configurations: `tau_5` and `X` at the horizon;
- a Fig. 8 style sweep in natural, random and cost order (`sweep(order=...)`, `_schedule`);
  `--case '{"kind": "schedule", "grid": "map", ...}'` runs an omega x a map instead;
- 64 x 64 and 512 x 512 (omega, a) maps with the public `sweep` on all devices: wall
  time, peak memory and the size of the results;
- a 256 x 256 map of steady speed and cost of transport (16 x 16 with `--quick`): `steady_gait`
  against direct simulation at the same accuracy (`case_gait_map`);
- 256 x 256 and 2048 x 2048 regime maps written into a Zarr store (`ZARR_MAP`
  settings; 64 and 128 with `--quick`): wall and CPU time, peak memory, store size.
  Alone: `python benchmarks/run.py --skip exact,sharded,smoothed,scipy,accuracy,schedule,map,chain --out /tmp/zarr.md`.

Timings are medians of several runs after a warm-up (`block_until_ready`).
Throughput is configurations x simulated time units per second ("cfg-tu/s"), by
wall clock and per CPU-second of the process (robust to other load on the machine).
Results are printed and written to `benchmarks/RESULTS.md`.

    python benchmarks/run.py            # full run (~9 min on 2 cores)
    python benchmarks/run.py --quick    # smoke run (~3 min)

On a GPU: install `jax[cuda12]` and run the same command; every case then runs on
the GPU (the scipy baseline stays on the CPU), `--devices N` sets how many devices
the sharded case uses (default: all), and the forced-host-device flag is not set.
"""

import argparse
import json
import os
import sys
import time
from pathlib import Path


# The harness, the cases and the report are modules beside this script (also when it is loaded by path).
sys.path.insert(0, str(Path(__file__).resolve().parent))
from cases import CASES, ZARR_MAP  # noqa: E402
from harness import DT, HERE, machine, MAP_HORIZON, spawn  # noqa: E402
from report import quote_everywhere, quote_in, QUOTED_IN, report, TABLE_MARKS  # noqa: E402


__all__ = ["CASES", "QUOTED_IN", "TABLE_MARKS", "ZARR_MAP", "main", "quote_in", "report", "spawn"]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--case", help=argparse.SUPPRESS)
    ap.add_argument("--quick", action="store_true", help="small smoke run")
    ap.add_argument("--dt", type=float, default=DT, help="exact engine step for the throughput table")
    ap.add_argument("--devices", type=int, default=2, help="devices for the sharded case (forced host devices on CPU)")
    ap.add_argument("--out", default=str(HERE / "RESULTS.md"))
    ap.add_argument("--skip", default="", help="comma-separated case kinds to skip")
    ap.add_argument("--render", metavar="JSON", help="only rewrite the report from a saved results JSON")
    args = ap.parse_args()
    if args.case:
        spec = json.loads(args.case)
        print(json.dumps(CASES[spec["kind"]](spec)))
        return
    if args.render:
        saved = json.loads(Path(args.render).read_text())
        saved["meta"]["load"] = [tuple(x) for x in saved["meta"]["load"]]
        text = report(saved["results"], saved["meta"])
        Path(args.out).write_text(text)
        print(text)
        if not saved["meta"]["quick"] and Path(args.out) == HERE / "RESULTS.md":
            quote_everywhere(saved["results"], saved["meta"])
        return

    q = args.quick
    dt = args.dt
    H = 20.0 if q else 100.0
    skip = set(args.skip.split(",")) - {""}
    load0 = os.getloadavg()
    t_begin = time.perf_counter()
    results: dict[str, list] = {k: [] for k in CASES}

    def log(msg):
        print(msg, flush=True)

    import jax

    cpu_platform = jax.devices()[0].platform == "cpu"
    del jax
    sizes = (1, 64) if q else (1, 64, 1024, 8192)
    if "exact" not in skip:
        for dtype in ("float64", "float32"):
            for B in sizes:
                spec = dict(kind="exact", B=B, dtype=dtype, dt=dt, horizon=H, repeats=3 if B < 8192 else 2)
                r = spawn(spec)
                results["exact"].append(r)
                log(f"exact {dtype} B={B}: " + (r.get("error") or f"{r['B'] * r['t_sim'] / r['wall']:,.0f} cfg-tu/s"))
        if not q:  # the library default step, for reference
            for B in (1024, 8192):
                r = spawn(dict(kind="exact", B=B, dtype="float64", dt=0.01, horizon=H, repeats=2))
                results["exact"].append(r)
                log(
                    f"exact float64 dt=0.01 B={B}: "
                    + (r.get("error") or f"{r['B'] * r['t_sim'] / r['wall']:,.0f} cfg-tu/s")
                )
            r = spawn(dict(kind="exact", B=1024, dtype="float64", dt=dt, horizon=10 * H, repeats=1))
            results["exact"].append(r)
            log("exact float64 B=1024, 10x horizon (memory check): " + (r.get("error") or f"{r['rss']:.0f} MB"))
    if "sharded" not in skip:
        spec = dict(
            kind="sharded",
            B=512 if q else 8192,
            dt=dt,
            horizon=H,
            repeats=2,
            devices=args.devices,
            tau_horizon=300.0 if q else 1000.0,
        )
        r = spawn(spec, devices=args.devices if cpu_platform else None)
        results["sharded"].append(r)
        log("sharded: " + (r.get("error") or json.dumps(r["runs"])))
    if "smoothed" not in skip:
        spec = dict(kind="smoothed", B=4 if q else 16, T=5.0 if q else 20.0, repeats=2)
        r = spawn(spec)
        results["smoothed"].append(r)
        log("smoothed: " + (r.get("error") or f"{r['B'] * r['t_sim'] / r['wall']:,.1f} cfg-tu/s"))
    if "scipy" not in skip:
        r = spawn(dict(kind="scipy", n=2 if q else 8, T=20.0 if q else 100.0))
        results["scipy"].append(r)
        log("scipy: " + (r.get("error") or ", ".join(f"{x['wall']:.2f}s" for x in r["rows"])))
    if "accuracy" not in skip:
        spec = dict(
            kind="accuracy",
            n=2 if q else 16,
            T=20.0 if q else 100.0,
            tau_horizon=300.0 if q else 1000.0,
            dts=[dt] if q else sorted({0.01, 0.02, 0.03, 0.04, dt}),
            n_smooth=1 if q else 4,
        )
        r = spawn(spec)
        results["accuracy"].append(r)
        log("accuracy: " + (r.get("error") or "done"))
    if "schedule" not in skip:
        spec = dict(
            kind="schedule",
            grid="fig8",
            N=64 if q else 512,
            chunk=16 if q else 128,
            dt=dt,
            horizon=300.0 if q else 2000.0,
        )
        r = spawn(spec, devices=args.devices if cpu_platform else None)
        results["schedule"].append(r)
        log("schedule: " + (r.get("error") or json.dumps(r["orders"])))

    if "map" not in skip:
        for n in (32, 64) if q else (64, 512):
            r = spawn(dict(kind="map", N=n, horizon=MAP_HORIZON, dt=dt), devices=args.devices if cpu_platform else None)
            results["map"].append(r)
            log(f"map {n} x {n}: " + (r.get("error") or f"{r['wall']:.1f} s, {r['rss']:.0f} MB"))
    if "zarr_map" not in skip:
        for n in (64, 128) if q else (256, 2048):
            spec = dict(kind="zarr_map", N=n, **ZARR_MAP)
            r = spawn(spec, devices=args.devices if cpu_platform else None)
            results["zarr_map"].append(r)
            log(
                f"zarr map {n} x {n}: "
                + (r.get("error") or f"{r['wall']:.1f} s, {r['rss']:.0f} MB, {r['store_mb']:.0f} MB")
            )

    if "chain" not in skip:
        B = 64 if q else 1024
        for n, params in ((2, True), (2, False), (4, False), (8, False)):
            spec = dict(kind="chain", N=n, params=params, B=B, dtype="float64", dt=dt, horizon=H, repeats=2)
            r = spawn(spec)
            results["chain"].append(r)
            rate = r["B"] * r["t_sim"] / r["wall"] if "wall" in r else 0.0
            log(f"chain N={n}{' (Params engine)' if params else ''}: " + (r.get("error") or f"{rate:,.0f} cfg-tu/s"))

    if "gait_map" not in skip:
        spec = dict(kind="gait_map", n=16 if q else 256, dt=dt, tol=1e-8, quantile=0.95, max_periods=2000)
        r = spawn(spec)
        results["gait_map"].append(r)
        log("gait_map: " + (r.get("error") or f"steady_gait {r['gait_warm']:.1f} s, direct {r['direct_warm']:.1f} s"))

    if "jacfwd" not in skip:
        for p in (1, 5):
            spec = dict(kind="jacfwd", B=64 if q else 256, p=p, horizon=H, repeats=2)
            r = spawn(spec)
            results["jacfwd"].append(r)
            log(f"jacfwd p={p}: " + (r.get("error") or f"{r['ratio']:.2f} x (p + 1) plain runs"))

    meta = dict(
        machine=machine(),
        load=(load0, os.getloadavg()),
        quick=q,
        dt=dt,
        horizon=H,
        command=" ".join([Path(sys.executable).name, *sys.argv]),
        elapsed=time.perf_counter() - t_begin,
    )
    Path(args.out).with_suffix(".json").write_text(json.dumps(dict(results=results, meta=meta), indent=1))
    text = report(results, meta)
    Path(args.out).write_text(text)
    print(text)
    if not q and Path(args.out) == HERE / "RESULTS.md":
        quote_everywhere(results, meta)


if __name__ == "__main__":
    main()
