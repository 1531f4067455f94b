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
import math
import os
import platform
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path


HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT / "tests"))  # the independent scipy reference

SEED = 0
OMEGA = (1.0, 25.0)
AMPL = (0.01, 0.1)
DT = 0.03
"""The throughput table's step: the largest of 0.01, 0.02, 0.03, 0.04 whose tau_5 error stays under the
target 1e-3 on every accuracy configuration that keeps contact (the accuracy table shows it)."""
MAP_HORIZON = 25.0
"""The map case's `sweep(horizon=...)`, as in the example of docs/maps.md (runs end at tau_5 or this horizon)."""
TARGETS = dict(rate=1e5, ratio=1000.0, accuracy=1e-3, compile=10.0)
"""Issue 5: float64 cfg-tu/s (wall, batches >= 1024), x scipy, tau_5 relative error, compile seconds."""


def configs(n: int, seed: int = SEED):
    """The benchmark's configurations: the first `n` of one seeded list (so every
    batch is a prefix of the largest one)."""
    import numpy as np

    rng = np.random.default_rng(seed)
    om = rng.uniform(*OMEGA, 8192 if n <= 8192 else n)
    a = rng.uniform(*AMPL, om.size)
    return om[:n], a[:n]


# -- helpers that run inside a case process ---------------------------------------------------------


class CompileClock:
    """Sums JAX's own compile-phase durations (tracing, lowering, backend compile)."""

    def __init__(self):
        import jax.monitoring

        self.total = 0.0
        jax.monitoring.register_event_duration_secs_listener(self._on)

    def _on(self, event, duration, **kwargs):
        if event.startswith("/jax/core/compile/"):
            self.total += duration


def thread_cpu() -> dict:
    """CPU seconds used so far by each thread of this process (Linux `/proc`; empty elsewhere)."""
    out = {}
    try:
        tick = os.sysconf("SC_CLK_TCK")
        for tid in os.listdir("/proc/self/task"):
            with open(f"/proc/self/task/{tid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            out[tid] = (int(fields[11]) + int(fields[12])) / tick
    except OSError:
        pass
    return out


def timed(fn, repeats: int):
    """First call (compile + run), then `repeats` timed runs: (first, [wall], [cpu], [busiest-thread cpu]).

    The busiest thread's CPU time is what one device's loop cost (each device runs
    on its own thread): the wall time the run would take with a free core per device.
    """
    import jax

    t0 = time.perf_counter()
    jax.block_until_ready(fn())
    first = time.perf_counter() - t0
    walls, cpus, busy = [], [], []
    for _ in range(repeats):
        th0 = thread_cpu()
        c0, t0 = time.process_time(), time.perf_counter()
        jax.block_until_ready(fn())
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
        th1 = thread_cpu()
        busy.append(max([th1[k] - th0.get(k, 0.0) for k in th1], default=math.nan))
    return first, walls, cpus, busy


def maxrss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _engine_settings():
    """`(MICRO_BATCH_CPU, default_max_steps)`: in `dynamics._runs`, or in `run._batch` in the
    trees before it (`compare.py` runs this file against older commits)."""
    try:
        from locomotion_jax.dynamics._runs import default_max_steps, MICRO_BATCH_CPU
    except ImportError:
        from locomotion_jax.run._batch import default_max_steps, MICRO_BATCH_CPU  # pyright: ignore[reportAttributeAccessIssue]
    return MICRO_BATCH_CPU, default_max_steps


def setup_jax():
    import jax

    jax.config.update("jax_enable_x64", True)
    return jax


def case_exact(spec: dict) -> dict:
    jax = setup_jax()
    import jax.numpy as jnp
    import locomotion_jax as lj
    import numpy as np

    rss0 = maxrss_mb()
    clock = CompileClock()
    om, a = configs(spec["B"])
    dtype = jnp.float32 if spec["dtype"] == "float32" else jnp.float64
    p = lj.Params(omega=om, a=a).astype(dtype)
    dyn = lj.Exact(dt=spec["dt"])

    def run():
        m = lj.measure(
            p, z=1e30, horizon=spec["horizon"], window=min(25.0, spec["horizon"]), dynamics=dyn, contact="paper"
        )
        return m

    first, walls, cpus, busy = timed(lambda: run().e_d, spec["repeats"])
    m = run()
    t_sim = float(np.mean(np.asarray(m.t_start))) + spec["horizon"]
    steps = np.asarray(m.n_steps)
    return dict(
        spec,
        first=first,
        compile=clock.total,
        wall=statistics.median(walls),
        cpu=statistics.median(cpus),
        busy=statistics.median(busy),
        t_sim=t_sim,
        steps_mean=float(steps.mean()),
        steps_max=int(steps.max()),
        switches_mean=float(np.asarray(m.n_switch).mean()),
        rss0=rss0,
        rss=maxrss_mb(),
        devices=1,
        platform=jax.devices()[0].platform,
    )


def _chunk_runner(vals, n_dev, H, dyn, max_steps, micro, z=1e30):
    """The sweep engine's chunk computation (`_sharding._run_chunk`, `shard_map` over a
    1-D mesh), compiled ahead of time (to time the compilation alone) and called
    without blocking, so that each device's output can be seen becoming ready on its own."""
    import inspect

    import jax
    import jax.numpy as jnp
    import numpy as np
    from jax.sharding import Mesh, NamedSharding, PartitionSpec as P
    from locomotion_jax.maps import _sharding
    from locomotion_jax.model._params import PARAM_NAMES, Params

    mesh = Mesh(np.asarray(jax.devices()[:n_dev]), (_sharding.BATCH_AXIS,))
    sharding = NamedSharding(mesh, P(_sharding.BATCH_AXIS))
    flat = Params(
        **{n: _sharding._global_array(np.asarray(vals[n], np.float64), sharding) for n in PARAM_NAMES}, check=False
    )
    zhw = jnp.asarray(np.asarray([z, H, min(25.0, H)], np.float64))
    args = [flat, zhw, dyn, "paper", "paper", max_steps, mesh]
    if "micro_batch" in inspect.signature(_sharding._run_chunk).parameters:
        args.append(micro)
    exe = _sharding._run_chunk.lower(*args).compile()
    return lambda: exe(flat, zhw, dyn)  # the static arguments are compiled in


def case_sharded(spec: dict) -> dict:
    jax = setup_jax()
    import locomotion_jax as lj
    import numpy as np
    from locomotion_jax.model._params import DEFAULTS, PARAM_NAMES

    MICRO_BATCH_CPU, default_max_steps = _engine_settings()

    clock = CompileClock()
    B, H, dt = spec["B"], spec["horizon"], spec["dt"]
    om, a = configs(B)
    n_dev = spec.get("devices") or len(jax.devices())
    micro = MICRO_BATCH_CPU if jax.devices()[0].platform == "cpu" else None
    t_start = float(lj.Params().t_start)
    max_steps = default_max_steps(t_start + max(H, spec["tau_horizon"]), dt)
    dyn = lj.Exact(dt=dt)
    # Sorted by omega (as `measure` does inside a device): neighbours switch modes at similar rates.
    order = np.argsort(om)
    vals = {k: np.full(B, DEFAULTS[k]) for k in PARAM_NAMES}
    vals["omega"], vals["a"] = om[order], a[order]
    out = {}
    for label, nd in (("1 device", 1), (f"{n_dev} devices", n_dev)):
        c0 = clock.total
        t0 = time.perf_counter()
        go = _chunk_runner(vals, nd, H, dyn, max_steps, micro)
        compile_wall = time.perf_counter() - t0
        first, walls, cpus, busy = timed(go, spec["repeats"])
        out[label] = dict(
            first=first + compile_wall,
            compile=clock.total - c0,
            wall=statistics.median(walls),
            cpu=statistics.median(cpus),
            busy=statistics.median(busy),
        )

    # Each device's loop ends on its own. Measure tau_5 (z = 5) on the same
    # configurations, ordered by expected cost (`_schedule.cost_order`): device 0
    # gets the cheaper half; record when each device's shard of the output is ready.
    from locomotion_jax.maps import _schedule

    H_tau = spec["tau_horizon"]
    order = _schedule.cost_order(vals, z=5.0, horizon=H_tau, window=25.0, dt=dt, contact="paper")
    vals_c = {k: v[order] for k, v in vals.items()}
    go = _chunk_runner(vals_c, n_dev, H_tau, dyn, max_steps, micro, z=5.0)
    jax.block_until_ready(go())
    t0 = time.perf_counter()
    res = go()
    shards = res["n_steps"].addressable_shards
    ready = [None] * len(shards)
    while any(r is None for r in ready):
        for i, s in enumerate(shards):
            if ready[i] is None and s.data.is_ready():
                ready[i] = time.perf_counter() - t0
        time.sleep(0.001)
    per_dev = []
    for s, r in zip(shards, ready):
        steps = np.asarray(s.data)
        lo, hi = s.index[0].start or 0, s.index[0].stop or B
        tau = np.asarray(res["tau_z"])[lo:hi]
        per_dev.append(
            dict(
                device=str(s.device),
                ready=r,
                steps_max=int(steps.max()),
                steps_mean=float(steps.mean()),
                steps_sum=float(steps.sum()),
                tau_median=float(np.median(tau)),
            )
        )
    return dict(
        spec,
        runs=out,
        per_device=per_dev,
        n_devices=n_dev,
        micro_batch=micro,
        t_sim=t_start + H,
        rss=maxrss_mb(),
        platform=jax.devices()[0].platform,
    )


def case_smoothed(spec: dict) -> dict:
    setup_jax()
    import locomotion_jax as lj
    import numpy as np

    clock = CompileClock()
    om, a = configs(spec["B"])
    p = lj.Params(omega=om, a=a)
    T = spec["T"]
    dyn = lj.Smoothed(eps=1e-3)
    run = lambda: lj.simulate(p, T, save_at=np.asarray([0.0, T]), dynamics=dyn, contact="paper")
    first, walls, cpus, busy = timed(lambda: run().X, spec["repeats"])
    tr = run()
    return dict(
        spec,
        first=first,
        compile=clock.total,
        wall=statistics.median(walls),
        cpu=statistics.median(cpus),
        t_sim=T,
        X=np.asarray(tr.X[:, -1]).tolist(),
        status=np.asarray(tr.status).tolist(),
        rss=maxrss_mb(),
    )


def _scipy_one(args):
    from reference import reference_simulate

    omega, a, T, rtol = args
    c0, t0 = time.process_time(), time.perf_counter()
    r = reference_simulate(dict(omega=omega, a=a), T, save_at=[0.0, T], contact="paper", rtol=rtol, atol=rtol * 1e-3)
    return dict(
        omega=omega,
        a=a,
        wall=time.perf_counter() - t0,
        cpu=time.process_time() - c0,
        X=float(r["X"][-1]),
        segments=r["n_segments"],
    )


def _ref_tau(args):
    from reference import reference_measure

    omega, a, horizon, rtol = args
    t0 = time.perf_counter()
    r = reference_measure(dict(omega=omega, a=a), z=5.0, horizon=horizon, contact="paper", rtol=rtol, atol=rtol * 1e-2)
    return dict(omega=omega, a=a, tau=r["tau_z"], e=r["e_z"], wall=time.perf_counter() - t0)


def case_scipy(spec: dict) -> dict:
    """The baseline, timed one configuration at a time in this (single-threaded) process."""
    om, a = configs(spec["n"])
    rows = [_scipy_one((float(o), float(x), spec["T"], 1e-9)) for o, x in zip(om, a)]
    return dict(spec, rows=rows, rss=maxrss_mb())


def case_accuracy(spec: dict) -> dict:
    """Tight references (rtol 1e-11) in two worker processes, then every engine on the same configurations."""
    from concurrent.futures import ProcessPoolExecutor

    jax = setup_jax()
    import jax.numpy as jnp
    import locomotion_jax as lj
    import numpy as np

    n, T, H = spec["n"], spec["T"], spec["tau_horizon"]
    om, a = configs(n)
    with ProcessPoolExecutor(max_workers=2) as pool:
        ref_X = list(pool.map(_scipy_one, [(float(o), float(x), T, 1e-11) for o, x in zip(om, a)]))
        base_X = list(pool.map(_scipy_one, [(float(o), float(x), T, 1e-9) for o, x in zip(om, a)]))
        ref_tau = list(pool.map(_ref_tau, [(float(o), float(x), H, 1e-10) for o, x in zip(om, a)]))
        base_tau = list(pool.map(_ref_tau, [(float(o), float(x), H, 1e-9) for o, x in zip(om, a)]))
    p = lj.Params(omega=om, a=a)
    engines = {}
    for dt in spec["dts"]:
        for dtype in ("float64", "float32"):
            q = p.astype(jnp.float32 if dtype == "float32" else jnp.float64)
            tr = lj.simulate(q, T, save_at=np.asarray([0.0, T]), dynamics=lj.Exact(dt=dt), contact="paper")
            m = lj.measure(q, z=5.0, horizon=H, dynamics=lj.Exact(dt=dt), contact="paper")
            engines[f"exact {dtype} dt={dt:g}"] = dict(
                X=np.asarray(tr.X[:, -1], np.float64).tolist(), tau=np.asarray(m.tau_z, np.float64).tolist()
            )
            lifts = np.asarray(m.liftoff).tolist()
    ns = spec["n_smooth"]
    tr = lj.simulate(p[:ns], T, save_at=np.asarray([0.0, T]), dynamics=lj.Smoothed(eps=1e-3), contact="paper")
    engines["smoothed eps=1e-3"] = dict(X=np.asarray(tr.X[:, -1]).tolist() + [math.nan] * (n - ns), tau=[math.nan] * n)
    engines["scipy rtol=1e-9"] = dict(X=[r["X"] for r in base_X], tau=[r["tau"] for r in base_tau])
    del jax
    return dict(
        spec,
        omega=om.tolist(),
        a=a.tolist(),
        ref_X=[r["X"] for r in ref_X],
        ref_tau=[r["tau"] for r in ref_tau],
        engines=engines,
        liftoff=lifts,
    )


def _schedule_axes(spec: dict):
    """The schedule case's configurations: the Fig. 8 line (`grid="fig8"`, N points of
    omega/wn1 in [0.05, 2.5], a = 0.05) or an omega x a map (`grid="map"`, N x N over the
    Fig. 6 ranges), as (axes for a list sweep, their length)."""
    import numpy as np

    if spec.get("grid", "fig8") == "fig8":
        return {"omega_over_wn1": np.linspace(0.05, 2.5, spec["N"])}, spec["N"]
    om, a = np.meshgrid(np.linspace(*OMEGA, spec["N"]), np.linspace(*AMPL, spec["N"]), indexing="ij")
    return {"omega": om.ravel(), "a": a.ravel()}, om.size


def _lane_use(steps, omega, chunk: int, padded: int, ndev: int, micro) -> float:
    """Lane-iterations the loops ran for `steps` (iterations per configuration, in the order run).

    Each device's shard of a chunk goes through the work queue (`_queue.run_queue`) on
    `micro` lanes: highest `omega` first, a lane taking the next configuration as soon as
    its own is done; the loop runs until the last lane is done (list scheduling).
    """
    import heapq

    import numpy as np

    spent, shard = 0, padded // ndev
    for lo in range(0, len(steps), chunk):
        block, om = steps[lo : lo + chunk], omega[lo : lo + chunk]
        for d in range(0, len(block), shard):
            part, w = block[d : d + shard], om[d : d + shard]
            lanes = min(micro or len(part), len(part))
            free = [0] * lanes
            for k in np.argsort(-np.where(np.isfinite(w), w, -np.inf), kind="stable"):
                heapq.heappush(free, heapq.heappop(free) + int(part[k]))
            spent += max(free) * lanes
    return float(spent)


def case_schedule(spec: dict) -> dict:
    """A long sweep (z = 5, paper contact) in natural, random and cost order (`sweep(order="cost")`)."""
    jax = setup_jax()
    import locomotion_jax as lj
    import numpy as np
    from locomotion_jax.maps import _sharding, _sweep

    MICRO_BATCH_CPU, _ = _engine_settings()

    chunk, dt, H = spec["chunk"], spec["dt"], spec["horizon"]
    micro = MICRO_BATCH_CPU if jax.devices()[0].platform == "cpu" else None
    _sharding.MICRO_BATCH = micro  # the sweep engine's knob (64 lanes per device on a CPU, its default)
    axes, N = _schedule_axes(spec)
    freq = np.asarray(axes["omega"] if "omega" in axes else axes["omega_over_wn1"])  # the queue's order
    kw = dict(
        mode="list",
        z=5.0,
        horizon=H,
        dynamics=lj.Exact(dt=dt),
        contact="paper",
        chunk_size=chunk,
        progress=False,
        dtype="float64",
    )
    ndev = len(jax.devices())
    per_chunk = -(-min(chunk, N) // ndev) * ndev  # as `sweep` cuts them
    padded = _sharding.padded_size(per_chunk, ndev, np.float64)
    real_pilot, pilot = _sweep._cost_permutation, {}

    def timed_pilot(*args):  # the sweep's own pilot: its permutation (the order run) and wall time
        t0 = time.perf_counter()
        pilot["perm"] = real_pilot(*args)
        pilot["wall"] = time.perf_counter() - t0
        return pilot["perm"]

    _sweep._cost_permutation = timed_pilot

    def run(listed, order: str):
        """Sweep the configurations `listed` (indices into `axes`) in `order`: timings, lane use, grid-order data."""
        pilot.clear()
        th0 = thread_cpu()
        t0 = time.perf_counter()
        ds = lj.sweep({k: v[listed] for k, v in axes.items()}, order=order, **kw)
        wall = time.perf_counter() - t0
        th1 = thread_cpu()
        ran = pilot.get("perm", np.arange(N))  # rows of `ds` in the order they were run
        steps = np.asarray(ds.n_steps.values)[ran]
        inv = np.argsort(listed)
        data = {k: np.asarray(v.values)[inv] for k, v in ds.data_vars.items()}
        out = dict(
            wall=wall,
            busy=max(th1[k] - th0.get(k, 0.0) for k in th1),
            useful=float(steps.sum()),
            spent=_lane_use(steps, freq[listed][ran], per_chunk, padded, ndev, micro),
        )
        if "wall" in pilot:
            out["pilot"] = pilot["wall"]
        return out, data, ds.attrs["order"]

    t0 = time.perf_counter()
    run(np.arange(N), "cost")  # warm-up: compiles the chunk function and the pilot
    first = time.perf_counter() - t0
    out, data = {}, {}
    out["natural"], data["natural"], _ = run(np.arange(N), "natural")
    out["random"], data["random"], _ = run(np.random.default_rng(1).permutation(N), "natural")
    out["cost"], data["cost"], recorded = run(np.arange(N), "cost")
    same = all(
        np.array_equal(data[o][k], data["natural"][k], equal_nan=data[o][k].dtype.kind == "f")
        for o in data
        for k in data[o]
    )
    tau = data["natural"]["tau_z"]
    reached = np.isfinite(tau)
    return dict(
        spec,
        orders=out,
        n_devices=ndev,
        micro_batch=micro,
        same_results=same,
        recorded_order=recorded,
        first_call=first,
        n_configs=N,
        reached=int(reached.sum()),
        tau_range=[float(tau[reached].min()), float(tau[reached].max())] if reached.any() else None,
    )


def case_map(spec: dict) -> dict:
    """An N x N (omega, a) map with the public `sweep` (all devices): wall time, peak memory, data kept."""
    jax = setup_jax()
    import locomotion_jax as lj
    import numpy as np

    n, H, dt = spec["N"], spec["horizon"], spec["dt"]
    grid = {"omega": np.linspace(*OMEGA, n), "a": np.linspace(*AMPL, n)}
    kw = dict(horizon=H, dynamics=lj.Exact(dt=dt), contact="paper", progress=False, dtype="float64")
    t0 = time.perf_counter()
    ds = lj.sweep(grid, **kw)
    wall = time.perf_counter() - t0
    valid = np.asarray(ds.status.values) == int(lj.Status.OK)
    return dict(
        spec,
        wall=wall,
        rss=maxrss_mb(),
        n_configs=int(ds.omega.size * ds.a.size),
        data_mb=ds.nbytes / 2**20,
        n_devices=len(jax.devices()),
        n_ok=int(valid.sum()),
        steps_mean=float(np.asarray(ds.n_steps.values).mean()),
    )


ZARR_MAP = dict(dtype="float32", dt=0.05, horizon=10.0, window=10.0, chunk=4096)
"""The Zarr map case's settings: a regime map (SSL/SL over omega x a) cheap enough for
2048 x 2048 on 2 cores. Every run covers t_start (80 periods of the lowest natural
frequency, ~50 time units here) before its window, so a short horizon alone does not make
it cheap: float32 and dt = 0.05 (on a 256 x 256 map the regime of 2 configurations in
65,536 differs from float64 at dt = 0.03), window = horizon = 10 (the paper: 25). The
2048 x 2048 map took 820 CPU-seconds in the last full run (RESULTS.md)."""


def _tree_size(path: Path) -> tuple[int, int]:
    files = [p for p in path.rglob("*") if p.is_file()]
    return sum(p.stat().st_size for p in files), len(files)


def case_zarr_map(spec: dict) -> dict:
    """An N x N (omega, a) regime map written into a Zarr store (`sweep(path="....zarr")`):
    wall and CPU time, peak memory, the store's size; the map is never held in memory."""
    jax = setup_jax()
    import tempfile

    import locomotion_jax as lj
    import numpy as np

    n = spec["N"]
    grid = {"omega": np.linspace(*OMEGA, n), "a": np.linspace(*AMPL, n)}
    kw = dict(
        z=5.0,
        horizon=spec["horizon"],
        window=spec["window"],
        dynamics=lj.Exact(dt=spec["dt"]),
        contact="paper",
        dtype=spec["dtype"],
        chunk_size=spec["chunk"],
        progress=False,
    )
    cpu0 = resource.getrusage(resource.RUSAGE_SELF)
    with tempfile.TemporaryDirectory(prefix="zarr_map_") as tmp:
        path = Path(tmp) / "map.zarr"
        t0 = time.perf_counter()
        ds = lj.sweep(grid, path=path, **kw)
        wall = time.perf_counter() - t0
        cpu1 = resource.getrusage(resource.RUSAGE_SELF)
        size, files = _tree_size(path)
        regime = np.asarray(ds.regime.values)  # one variable (int32): 16 MB at 2048 x 2048
        status = np.asarray(ds.status.values)
        counts = {r.name: int((regime == int(r)).sum()) for r in lj.Regime}
        result = dict(
            spec,
            wall=wall,
            cpu=(cpu1.ru_utime + cpu1.ru_stime) - (cpu0.ru_utime + cpu0.ru_stime),
            rss=maxrss_mb(),
            n_configs=n * n,
            n_chunks=int(np.prod([-(-x // b) for x, b in zip(ds.regime.shape, ds.attrs["sweep_block"])])),
            block=ds.attrs["sweep_block"],
            store_mb=size / 2**20,
            n_files=files,
            data_mb=sum(v.size * v.dtype.itemsize for v in ds.data_vars.values()) / 2**20,
            n_devices=len(jax.devices()),
            regimes=counts,
            n_ok=int((status == int(lj.Status.OK)).sum()),
        )
    return result


def case_chain(spec: dict) -> dict:
    """`measure` on a batch of N-mass chains (the N-mass engine): travelling waves on the
    benchmark's (omega, a) configurations, N masses of 1, the paper's spring and friction."""
    jax = setup_jax()
    import jax.numpy as jnp
    import locomotion_jax as lj
    import numpy as np

    om, a = configs(spec["B"])
    n = spec["N"]
    dtype = jnp.float32 if spec["dtype"] == "float32" else jnp.float64
    if spec.get("params"):  # the two-mass model on its own engine, for comparison
        mech = lj.Params(omega=om, a=a).astype(dtype)
    else:
        phi = np.linspace(0, np.pi, om.size)
        waves = lj.SpringFourier(
            -a[:, None, None] * np.sin(phi[:, None, None] * np.arange(n - 1)[None, :, None]),
            a[:, None, None] * np.cos(phi[:, None, None] * np.arange(n - 1)[None, :, None]),
            om,
        )
        mech = lj.Chain(masses=np.ones((om.size, n)), waveforms=waves, friction=lj.Coulomb(0.7, 0.5)).astype(dtype)
    t_start = np.full(om.size, 80.0)
    clock = CompileClock()
    dyn = lj.Exact(dt=spec["dt"])
    run = lambda: lj.measure(
        mech, z=1e30, horizon=spec["horizon"], window=min(25.0, spec["horizon"]), t_start=t_start, dynamics=dyn,
        contact="paper",
    ).e_d  # fmt: skip
    first, walls, cpus, _ = timed(run, spec["repeats"])
    return dict(
        spec, first=first, compile=clock.total, wall=statistics.median(walls), cpu=statistics.median(cpus),
        t_sim=80.0 + spec["horizon"], rss=maxrss_mb(), platform=jax.devices()[0].platform,
    )  # fmt: skip


def case_gait_map(spec: dict) -> dict:
    """An n x n (omega, a) map of steady speed and cost of transport (paper reading): `steady_gait`
    (vmapped: 30 periods of transient, then Newton on the period map) against direct simulation
    at the same accuracy. Both average over whole periods (the direct runs save at every period of
    their own omega, one `simulate` call per omega row, so that their steps restart at each period
    like the period map's; averaged over 12 periods, a multiple of every gait period k <= 4), so
    the direct answer's error is the transient's remnant, |mu|^n0: n0 is the
    number of periods after which the `quantile` of the largest Floquet multiplier's modulus
    decays to `tol` (capped at `max_periods`). The direct runs start from the paper's start like
    steady_gait's transient. Reported: both times (first call with compilation, then warm), the
    direct answer's error against the steady gait's, and the configurations without a gait."""
    jax = setup_jax()
    import locomotion_jax as lj
    import numpy as np

    n, dt = spec["n"], spec["dt"]
    om, a = np.linspace(1.0, 25.0, n), np.linspace(0.01, 0.1, n)
    p = lj.Params.grid(omega=om, a=a)
    dyn = lj.Exact(dt=dt)
    clock = CompileClock()
    t0 = time.perf_counter()
    g = lj.steady_gait(p, contact="paper", dynamics=dyn)
    jax.block_until_ready(g.mean_speed)
    gait_first = time.perf_counter() - t0
    compile_gait = clock.total
    t0 = time.perf_counter()
    g = lj.steady_gait(p, contact="paper", dynamics=dyn)
    jax.block_until_ready(g.mean_speed)
    gait_warm = time.perf_counter() - t0
    ok = np.asarray(g.converged)
    mu = np.max(np.abs(np.asarray(g.multipliers)), axis=-1)
    # Gaits that move and are stable (at rest both masses stick: the gap is neutral, |mu| = 1).
    moving = ok & np.asarray(g.stable) & (np.abs(np.asarray(g.mean_speed)) > 1e-6)
    q = float(np.quantile(mu[moving], spec["quantile"])) if moving.any() else 0.5
    n0 = int(min(spec["max_periods"], math.ceil(math.log(spec["tol"]) / math.log(min(max(q, 1e-3), 0.9999)))))
    K = 12
    speed = np.full((n, n), np.nan)
    cost = np.full((n, n), np.nan)
    walls = []
    for i, w in enumerate(om):  # one batch per omega row: the save times are whole periods of that omega
        T = 2 * np.pi / w
        t0 = time.perf_counter()
        tr = lj.simulate(lj.Params(omega=w, a=a), (n0 + K) * T, save_at=np.arange(n0 + K + 1) * T,
                         contact="paper", dynamics=dyn)  # fmt: skip
        X, ed = np.asarray(tr.X), np.asarray(tr.e_d)
        walls.append(time.perf_counter() - t0)
        dX = X[:, -1] - X[:, n0]
        speed[i] = dX / (K * T)
        with np.errstate(divide="ignore", invalid="ignore"):
            cost[i] = (ed[:, -1] - ed[:, n0]) / np.abs(dX)
    gs, gc = np.asarray(g.mean_speed), np.asarray(g.cost_of_transport)
    with np.errstate(divide="ignore", invalid="ignore"):
        err_v = np.abs(speed - gs) / np.abs(gs)
        err_c = np.abs(cost - gc) / np.abs(gc)
    pct = lambda e: {p_: float(np.nanpercentile(e[moving], p_)) for p_ in (50, 95, 99, 100)} if moving.any() else {}
    return dict(
        spec, n0=n0, mu_quantile=q, gait_first=gait_first, gait_warm=gait_warm, compile_gait=compile_gait,
        direct_first_row=walls[0], direct_warm=float(np.sum(walls[1:]) * n / max(n - 1, 1)),
        converged=int(ok.sum()), configs=n * n, moving=int(moving.sum()), err_speed=pct(err_v),
        err_cost=pct(err_c), statuses={int(k): int(v) for k, v in zip(*np.unique(np.asarray(g.status),
        return_counts=True))}, rss=maxrss_mb(), platform=jax.devices()[0].platform,
    )  # fmt: skip


def case_jacfwd(spec: dict) -> dict:
    """Cost of forward-mode derivatives: `jax.jacfwd` of `measure` (`tau_z`, `e_z`,
    `mean_speed`; z = 1 from the paper's t_start) with respect to `p` parameters, against
    the `p + 1` plain runs a one-sided finite difference needs; compilation excluded."""
    jax = setup_jax()
    import jax.numpy as jnp
    import locomotion_jax as lj
    from locomotion_jax.model._params import PARAM_NAMES

    names = ("omega", "a", "d", "mu_s", "mu_k")[: spec["p"]]
    om, a = configs(spec["B"])
    base = lj.Params(omega=om, a=a).broadcast()

    def run(delta):
        shift = {n: delta[i] for i, n in enumerate(names)}
        params = lj.Params(**{n: getattr(base, n) + shift.get(n, 0.0) for n in PARAM_NAMES})
        m = lj.measure(params, z=1.0, horizon=spec["horizon"])
        return jnp.stack([m.tau_z, m.e_z, m.mean_speed])

    clock = CompileClock()
    _, plain, plain_cpu, _ = timed(lambda: run(jnp.zeros(spec["p"])), spec["repeats"])
    compile_plain = clock.total
    _, jac, jac_cpu, _ = timed(lambda: jax.jacfwd(run)(jnp.zeros(spec["p"])), spec["repeats"])
    cpu = statistics.median(jac_cpu) / ((spec["p"] + 1) * statistics.median(plain_cpu))
    return dict(
        spec, plain=statistics.median(plain), jacfwd=statistics.median(jac), ratio_cpu=cpu,
        ratio=statistics.median(jac) / ((spec["p"] + 1) * statistics.median(plain)),
        per_second=spec["B"] * spec["p"] * 3 / statistics.median(jac), compile=clock.total - compile_plain,
        platform=jax.devices()[0].platform,
    )  # fmt: skip


CASES = dict(
    gait_map=case_gait_map,
    jacfwd=case_jacfwd,
    exact=case_exact,
    sharded=case_sharded,
    smoothed=case_smoothed,
    scipy=case_scipy,
    accuracy=case_accuracy,
    schedule=case_schedule,
    map=case_map,
    zarr_map=case_zarr_map,
    chain=case_chain,
)


# -- orchestration ---------------------------------------------------------------------------------------


def spawn(spec: dict, devices: int | None = None, timeout: float = 3600) -> dict:
    env = dict(os.environ)
    env.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")
    flags = [f for f in env.get("XLA_FLAGS", "").split() if "force_host_platform_device_count" not in f]
    if devices:
        flags.append(f"--xla_force_host_platform_device_count={devices}")
    env["XLA_FLAGS"] = " ".join(flags)
    proc = subprocess.run(
        [sys.executable, __file__, "--case", json.dumps(spec)],
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=ROOT,
    )
    if proc.returncode != 0:
        return dict(spec, error=proc.stderr[-2000:])
    return json.loads(proc.stdout.strip().splitlines()[-1])


def machine() -> dict:
    import importlib.metadata as md

    info = dict(python=platform.python_version(), platform=platform.platform())
    try:
        cpu = [ln.split(":", 1)[1].strip() for ln in open("/proc/cpuinfo") if ln.startswith("model name")]
        info["cpu"] = f"{cpu[0]} x {len(cpu)}" if cpu else platform.processor()
    except OSError:
        info["cpu"] = platform.processor()
    info["cores"] = os.cpu_count()
    import jax

    devs = jax.devices()
    info["devices"] = f"{len(devs)} x {devs[0].platform} ({devs[0].device_kind})"
    try:
        mem = [ln for ln in open("/proc/meminfo") if ln.startswith("MemTotal")][0].split()[1]
        info["memory"] = f"{int(mem) / 2**20:.1f} GiB"
    except (OSError, IndexError):
        pass
    for pkg in ("jax", "jaxlib", "numpy", "scipy", "diffrax", "equinox", "locomotion_jax"):
        try:
            info[pkg] = md.version(pkg)
        except md.PackageNotFoundError:
            info[pkg] = "-"
    try:
        git = lambda *a: subprocess.run(["git", *a], cwd=ROOT, capture_output=True, text=True).stdout
        changed = [ln for ln in git("status", "--porcelain").splitlines() if "benchmarks/RESULTS" not in ln]
        info["commit"] = git("rev-parse", "--short", "HEAD").strip() + (" (+ working tree)" if changed else "")
    except OSError:
        pass
    return info


def fmt(x, digits=3):
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    if isinstance(x, int) or (isinstance(x, float) and abs(x) >= 100):
        return f"{x:,.0f}"
    return f"{x:.{digits}g}"


def rel(x, ref):
    if not (math.isfinite(x) and math.isfinite(ref)) or ref == 0:
        return math.nan
    return abs(x / ref - 1)


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


README_MARKS = ("<!-- benchmark-targets: start (written by benchmarks/run.py) -->", "<!-- benchmark-targets: end -->")
QUOTED_IN = (ROOT / "README.md", ROOT / "docs" / "performance.md")
"""The pages that quote the targets table between `README_MARKS`: the README (a summary) and
the documentation's performance page (beside the benchmark's description)."""


def quote_everywhere(res: dict, meta: dict) -> None:
    """Put this run's targets table into every page of `QUOTED_IN`."""
    for page in QUOTED_IN:
        quote_in_readme(res, meta, readme=page)


def quote_in_readme(res: dict, meta: dict, readme: Path = ROOT / "README.md") -> None:
    """Put this run's targets table between the markers of `readme` (the README by default;
    any page of `QUOTED_IN`), so the page quotes `RESULTS.md` instead of hand-typed numbers."""
    text = readme.read_text()
    start, end = README_MARKS
    if start not in text or end not in text:
        print(f"README markers not found; {readme} left unchanged", file=sys.stderr)
        return
    sc = res["scipy"][0] if res["scipy"] and "error" not in res["scipy"][0] else None
    base = None
    if sc:
        base = dict(cpu=len(sc["rows"]) * sc["T"] / sum(r["cpu"] for r in sc["rows"]))
    table = targets(res, meta, base)[2:]  # without the heading
    m = meta["machine"]
    src = (
        f"From `benchmarks/RESULTS.md` (`{meta['command']}`, {meta['elapsed'] / 60:.0f} min on {m.get('cpu')}, "
        f"{m.get('cores')} cores; locomotion_jax at {m.get('commit', '?')}):"
    )
    head, rest = text.split(start, 1)
    tail = rest.split(end, 1)[1]
    readme.write_text(head + start + "\n" + src + "\n\n" + "\n".join(table).rstrip() + "\n" + end + tail)


def _memory_mb(meta: dict) -> float:
    """The machine's memory as `machine()` recorded it ("23.5 GiB"); NaN (no verdict) if unknown."""
    text = meta["machine"].get("memory")
    return float(text.split()[0]) * 1024 if text else math.nan


def targets(res: dict, meta: dict, base: dict | None) -> list[str]:
    """The performance targets against what this run measured (a table with a verdict per line)."""
    dt, H, T = meta["dt"], meta["horizon"], TARGETS
    ok = lambda good: "**met**" if good else "not met"
    rows = []
    big = [
        r
        for r in res["exact"]
        if "error" not in r and r["dtype"] == "float64" and r["dt"] == dt and r["horizon"] == H and r["B"] >= 1024
    ]
    if big:
        w = min(r["B"] * r["t_sim"] / r["wall"] for r in big)
        rows.append(
            (
                f"exact, float64, dt = {dt:g}, 1 device, batches {', '.join(str(r['B']) for r in big)}: "
                "cfg-tu/s, wall (lowest)",
                f">= {T['rate']:,.0f}",
                fmt(w),
                ok(w >= T["rate"]),
            )
        )
        if base:
            c = min(r["B"] * r["t_sim"] / r["cpu"] / base["cpu"] for r in big)
            rows.append(
                ("the same, x scipy per core (CPU-seconds; lowest)", f">= {T['ratio']:g}", fmt(c), ok(c >= T["ratio"]))
            )
    for r in res["sharded"]:
        if "error" in r or r["dt"] != dt:
            continue
        nd = r["n_devices"]
        x = r["runs"][f"{nd} devices"]
        w = r["B"] * r["t_sim"] / x["wall"]
        rows.append(
            (
                f"exact, float64, dt = {dt:g}, {nd} devices (`shard_map`), batch {r['B']}: cfg-tu/s, wall",
                f">= {T['rate']:,.0f}",
                fmt(w),
                ok(w >= T["rate"]),
            )
        )
        if base:
            rows.append(
                (
                    f"the same, x scipy on the same {nd} cores (wall)",
                    f">= {T['ratio']:g}",
                    fmt(w / (nd * base["cpu"])),
                    ok(w / (nd * base["cpu"]) >= T["ratio"]),
                )
            )
    acc = res["accuracy"][0] if res["accuracy"] and "error" not in res["accuracy"][0] else None
    key = f"exact float64 dt={dt:g}"
    if acc and key in acc["engines"]:
        lift = acc.get("liftoff", [False] * len(acc["omega"]))
        errs = [rel(x, r) for x, r in zip(acc["engines"][key]["tau"], acc["ref_tau"])]
        kept = [e for e, lo in zip(errs, lift) if not lo and math.isfinite(e)]
        lifted = [e for e, lo in zip(errs, lift) if lo and math.isfinite(e)]
        if kept:
            rows.append(
                (
                    f"tau_5 relative error at dt = {dt:g}, float64: max over the {len(kept)} accuracy "
                    "configurations that keep contact",
                    f"<= {T['accuracy']:g}",
                    f"{max(kept):.1e}",
                    ok(max(kept) <= T["accuracy"]),
                )
            )
        if lifted:
            rows.append(
                (
                    f"the same on the {len(lifted)} that lift off (outside the model's validity; flagged)",
                    "-",
                    f"{max(lifted):.1e}",
                    "reported",
                )
            )
    comp = [r["compile"] for r in res["exact"] if "error" not in r]
    comp += [x["compile"] for r in res["sharded"] if "error" not in r for x in r["runs"].values()]
    if comp:
        rows.append(
            (
                "compile time, every exact-engine case (highest)",
                f"< {T['compile']:g} s",
                f"{max(comp):.1f} s",
                ok(max(comp) < T["compile"]),
            )
        )
    long = [r for r in res["exact"] if "error" not in r and r["horizon"] > H and r["dt"] == dt]
    short = {r["B"]: r for r in big}
    for r in long:
        if r["B"] in short:
            rows.append(
                (
                    f"peak RSS, batch {r['B']}: horizon {r['horizon']:g} vs {H:g} "
                    f"({r['steps_mean'] / short[r['B']]['steps_mean']:.1f}x the steps)",
                    "independent of steps",
                    f"{r['rss']:.0f} MB vs {short[r['B']]['rss']:.0f} MB",
                    ok(r["rss"] <= 1.1 * short[r["B"]]["rss"]),
                )
            )
    maps = [r for r in res.get("map", []) if "error" not in r]
    if maps:
        r = max(maps, key=lambda r: r["N"])
        small = min(maps, key=lambda r: r["N"])
        rows.append(
            (
                f"{r['N']} x {r['N']} map (`sweep`, {r['n_configs']:,} configurations, {r['n_devices']} "
                f"devices): peak RSS; {small['N']} x {small['N']} for scale",
                "< the machine's memory",
                f"{r['rss']:.0f} MB ({r['data_mb']:.1f} MB of results, {r['wall']:.0f} s); {small['rss']:.0f} MB",
                ok(r["rss"] < _memory_mb(meta)),
            )
        )
    zmaps = [r for r in res.get("zarr_map", []) if "error" not in r]
    if len(zmaps) >= 2:
        big, small = max(zmaps, key=lambda r: r["N"]), min(zmaps, key=lambda r: r["N"])
        rows.append(
            (
                f"{big['N']} x {big['N']} regime map into a Zarr store ({big['n_configs']:,} configurations, "
                f"{big['n_devices']} devices): peak RSS vs {small['N']} x {small['N']} "
                f"({big['n_configs'] // small['n_configs']}x the configurations)",
                "independent of the map's size",
                f"{big['rss']:.0f} MB vs {small['rss']:.0f} MB ({big['data_mb']:.0f} MB of results, "
                f"{big['store_mb']:.0f} MB on disk, {big['wall'] / 60:.1f} min)",
                ok(big["rss"] <= 1.1 * small["rss"]),
            )
        )
    for r in res.get("jacfwd", []):
        if "error" in r:
            continue
        # No target: each direction recomputes the primal (docs/gradients.md: about 2.5 p plain runs).
        rows.append(
            (
                f"`jax.jacfwd` of `measure` w.r.t. {r['p']} parameter(s), batch {r['B']}: time / ({r['p']} + 1) "
                "plain runs (wall)",
                "-",
                f"{r['ratio']:.2f} ({fmt(r['per_second'])} derivatives/s)",
                "reported",
            )
        )
    if not rows:
        return []
    out = ["## Targets (issue 5)", "", "| what | target | measured | |", "|---|---|---|---|"]
    out += [f"| {a} | {b} | {c} | {d} |" for a, b, c, d in rows]
    out += [
        "",
        "Compilations are counted in tests: one per sweep whatever its number of chunks "
        "(`tests/test_sweep.py`), none for new parameter values (`tests/test_exact.py`), and in the "
        "optimiser one per optimisation, every smoothing stage sharing the finest stage's compiled loop, none per "
        "stage, iteration, start or call (`tests/test_optimise.py`).",
        "",
    ]
    return out


def report(res: dict, meta: dict) -> str:
    L = []
    m = meta["machine"]
    L.append("# Benchmark results" + (" (quick smoke run)" if meta["quick"] else ""))
    L.append("")
    L.append("Generated by `benchmarks/run.py`; do not edit by hand. How to read it: benchmarks/NOTES.md.")
    L.append("")
    L.append(f"- Command: `{meta['command']}` ({meta['elapsed'] / 60:.1f} min)")
    L.append(f"- Machine: {m.get('cpu')}, {m.get('cores')} cores, {m.get('memory', '?')}; {m['platform']}")
    if "devices" in m:
        L.append(f"- JAX devices: {m['devices']}")
    L.append(
        f"- Versions: Python {m['python']}, jax {m['jax']}, jaxlib {m['jaxlib']}, numpy {m['numpy']}, "
        f"scipy {m['scipy']}, diffrax {m['diffrax']}, equinox {m['equinox']}, locomotion_jax "
        f"{m['locomotion_jax']} at {m.get('commit', '?')}"
    )
    l0, l1 = meta["load"]
    L.append(
        f"- Load average (1/5/15 min) at start {l0[0]:.1f}/{l0[1]:.1f}/{l0[2]:.1f}, at end "
        f"{l1[0]:.1f}/{l1[1]:.1f}/{l1[2]:.1f}: other jobs share the cores, so wall-clock rates are lower "
        "bounds; the per-CPU-second rates are not affected by waiting for a core."
    )
    L.append(
        f'- Workload: `measure(..., z=1e30, horizon={meta["horizon"]:g}, contact="paper")`, i.e. '
        f"t_start (71.1) + {meta['horizon']:g} time units per configuration; omega ~ U{OMEGA}, a ~ U{AMPL} "
        f"(seed {SEED}); exact engine at dt = {meta['dt']:g} unless stated."
    )
    L.append("")

    sc = res["scipy"][0] if res["scipy"] and "error" not in res["scipy"][0] else None
    base = None
    if sc:
        base_wall = sum(r["wall"] for r in sc["rows"])
        base_cpu = sum(r["cpu"] for r in sc["rows"])
        base = dict(wall=len(sc["rows"]) * sc["T"] / base_wall, cpu=len(sc["rows"]) * sc["T"] / base_cpu)

    L.extend(targets(res, meta, base))

    L.append("## Throughput")
    L.append("")
    L.append(
        "cfg-tu/s = configurations x simulated time units per second. *per CPU-s*: work / CPU time of the "
        "process (what a core does while it runs; insensitive to waiting for a core). Ratios are against the "
        "scipy baseline's rate per CPU-second (one configuration per core): *per core* compares CPU "
        "seconds; *same cores* compares the engine's wall-clock rate on N devices (N cores) with scipy on the "
        "same N cores (N processes)."
    )
    L.append("")
    L.append(
        "| engine | dtype | dt | devices | batch | compile s | run s wall | cfg-tu/s wall | cfg-tu/s per CPU-s "
        "| x scipy per core | x scipy on the same cores (wall) | peak RSS MB | iterations mean / max |"
    )
    L.append("|---|---|---|---|---|---|---|---|---|---|---|---|---|")

    def row(name, dtype, dt, ndev, batch, x, work, rss, iters=""):
        w, c = work / x["wall"], work / x["cpu"]
        per_core = fmt(c / base["cpu"]) if base else "-"
        same = fmt(w / (ndev * base["cpu"])) if base else "-"
        L.append(
            f"| {name} | {dtype} | {dt} | {ndev} | {batch} | {x['compile']:.1f} | {x['wall']:.3g} | {fmt(w)} | "
            f"{fmt(c)} | {per_core} | {same} | {rss:.0f} | {iters} |"
        )

    for r in res["exact"]:
        if "error" in r:
            L.append(f"| exact | {r['dtype']} | {r['dt']} | 1 | {r['B']} | error | | | | | | | |")
            continue
        hz = "" if r["horizon"] == meta["horizon"] else f" (horizon {r['horizon']:g})"
        row(
            f"exact, `measure`{hz}",
            r["dtype"],
            f"{r['dt']:g}",
            1,
            r["B"],
            r,
            r["B"] * r["t_sim"],
            r["rss"],
            f"{r['steps_mean']:,.0f} / {r['steps_max']:,}",
        )
    for r in res["sharded"]:
        if "error" in r:
            L.append(f"| exact, shard_map | float64 | {r['dt']} | 2 | {r['B']} | error | | | | | | | |")
            continue
        for label, x in r["runs"].items():
            row(
                "exact, sweep engine `shard_map`",
                "float64",
                f"{r['dt']:g}",
                int(label.split()[0]),
                r["B"],
                x,
                r["B"] * r["t_sim"],
                r["rss"],
            )
    for r in res["smoothed"]:
        if "error" in r:
            L.append("| smoothed | float64 | adaptive | 1 | error | | | | | | | | |")
            continue
        row(
            f"smoothed, diffrax Tsit5, eps=1e-3, t=0..{r['T']:g}",
            "float64",
            "adaptive (rtol 1e-7)",
            1,
            r["B"],
            r,
            r["B"] * r["t_sim"],
            r["rss"],
        )
    if sc:
        L.append(
            f"| scipy `solve_ivp` DOP853 per mode, rtol 1e-9, t=0..{sc['T']:g} | float64 | adaptive | 1 | "
            f"{len(sc['rows'])}, one at a time | - | {base_wall:.3g} | {fmt(base['wall'])} | {fmt(base['cpu'])} | "
            f"1 | 1 | {sc['rss']:.0f} | |"
        )
    L.append("")

    for r in res["sharded"]:
        if "error" in r:
            L.append(f"Sharded case failed: `{r['error'][-300:]}`")
            continue
        nd = r["n_devices"]
        one, many = r["runs"]["1 device"], r["runs"][f"{nd} devices"]
        L.append(f"## Sharding over {nd} devices (the sweep engine's `_sharding._run_chunk`, `shard_map`)")
        L.append("")
        L.append(
            f"Batch {r['B']}, float64, {r['micro_batch'] or 'no'} configurations per loop on a device: "
            f"{one['wall']:.3g} s wall on 1 device, {many['wall']:.3g} s on {nd} "
            f"({one['wall'] / many['wall']:.2f}x; CPU time {one['cpu']:.3g} s vs {many['cpu']:.3g} s). With "
            f"{nd} devices the busiest thread used {many['busy']:.3g} s of CPU: the wall time with a free core "
            f"per device ({r['B'] * r['t_sim'] / many['busy']:,.0f} cfg-tu/s) when other jobs share the "
            "cores. The batch is "
            "sorted by omega (as `measure` does). Each device's loop ends on its own: measuring tau_5 "
            f"(z = 5, horizon {r['tau_horizon']:g}) on the same configurations ordered by expected cost "
            "(`_schedule.cost_order`), device 0 holds the cheaper half, and its output is ready first:"
        )
        L.append("")
        L.append("| device | median tau_5 | iterations: sum / max / mean | output ready after s |")
        L.append("|---|---|---|---|")
        for d in r["per_device"]:
            L.append(
                f"| {d['device']} | {fmt(d['tau_median'])} | {d['steps_sum']:,.0f} / {d['steps_max']:,} / "
                f"{d['steps_mean']:,.0f} | {d['ready']:.3g} |"
            )
        L.append("")

    acc = res["accuracy"][0] if res["accuracy"] and "error" not in res["accuracy"][0] else None
    if acc:
        L.append("## Accuracy against a tight scipy reference (rtol 1e-11 for X, 1e-10 for tau_5)")
        L.append("")
        L.append(
            f"Relative error of X at t = {acc['T']:g} and of tau_5 (z = 5 after t_start, horizon "
            f"{acc['tau_horizon']:g}) on the first {len(acc['omega'])} benchmark configurations "
            "(median / max over them; `-`: not computed or not reached)."
        )
        L.append("")
        lift = acc.get("liftoff", [False] * len(acc["omega"]))
        L.append("| engine | X: median | X: max | tau_5: median | tau_5: max | tau_5: max without lift-off |")
        L.append("|---|---|---|---|---|---|")
        for name, e in acc["engines"].items():
            ex = [rel(x, r) for x, r in zip(e["X"], acc["ref_X"])]
            et = [rel(x, r) for x, r in zip(e["tau"], acc["ref_tau"])]
            ec = [x for x, lo in zip(et, lift) if math.isfinite(x) and not lo]
            ex = [x for x in ex if math.isfinite(x)]
            et = [x for x in et if math.isfinite(x)]
            cell = lambda v, f: f"{f(v):.1e}" if v else "-"
            L.append(
                f"| {name} | {cell(ex, statistics.median)} | {cell(ex, max)} | {cell(et, statistics.median)} | "
                f"{cell(et, max)} | {cell(ec, max)} |"
            )
        L.append("")
        L.append(
            "Under the paper's reading (`n_i = |N_i|`) a configuration that lifts off is integrated through "
            "it: the right-hand side has a kink where a normal force changes sign, which the reference "
            "locates and the engine does not (it flags it), so there the engine converges erratically "
            "(SPEC: such results are outside the model's validity)."
        )
        L.append("")
        L.append("| omega | a | X ref | tau_5 ref | lifts off (paper reading) |")
        L.append("|---|---|---|---|---|")
        for o, a, x, t, lo in zip(acc["omega"], acc["a"], acc["ref_X"], acc["ref_tau"], lift):
            L.append(f"| {o:.3f} | {a:.4f} | {x:.6g} | {fmt(t, 6)} | {'yes' if lo else 'no'} |")
        L.append("")
    elif res["accuracy"]:
        L.append(f"Accuracy case failed: `{res['accuracy'][0]['error'][-500:]}`")

    s = res["schedule"][0] if res["schedule"] and "error" not in res["schedule"][0] else None
    if s:
        fig8 = s.get("grid", "fig8") == "fig8"
        what = (
            f"omega/wn1 in [0.05, 2.5] ({s['N']} points), a = 0.05"
            if fig8
            else f"an omega x a map ({s['N']} x {s['N']} over omega {OMEGA}, a {AMPL}, as a list)"
        )
        tau = s["tau_range"] or [math.nan, math.nan]
        L.append(f"## Long sweeps: cost-ordered chunks ({'Fig. 8 sweep' if fig8 else 'omega x a map'})")
        L.append("")
        L.append(
            f"`sweep` over {what}, z = 5, horizon {s['horizon']:g}, dt = {s['dt']:g}, paper contact, chunks "
            f"of {s['chunk']} on {s['n_devices']} devices; {s['reached']} of {s['n_configs']} configurations "
            f"reach z (tau_5 from {tau[0]:.3g} to {tau[1]:.3g}). Lane efficiency = "
            "iterations the configurations need / lane-iterations their loops ran (a device's shard of "
            f"a chunk runs through the work queue on {s.get('micro_batch') or 'all'} lanes until its last "
            "lane is done; counted by replaying the queue's list scheduling on the iterations each "
            "configuration took); it does not depend on the load of the machine. `natural` and `cost` are "
            "`sweep(order=...)`; `random` is a shuffled list in natural order. The cost order's wall time "
            "includes its pilot run (compiled beforehand). Results bit-for-bit identical in every order: "
            f"{s['same_results']}."
        )
        L.append("")
        L.append("| order | wall s | busiest thread CPU s | lane efficiency |")
        L.append("|---|---|---|---|")
        for k, v in s["orders"].items():
            extra = f" (pilot {v['pilot']:.3g})" if "pilot" in v else ""
            L.append(f"| {k} | {v['wall']:.3g}{extra} | {v['busy']:.3g} | {v['useful'] / v['spent']:.2f} |")
        L.append("")
    elif res["schedule"]:
        L.append(f"Schedule case failed: `{res['schedule'][0]['error'][-500:]}`")
    maps = res.get("map", [])
    if maps:
        L.append("## Maps: memory")
        L.append("")
        L.append(
            f"`sweep` over an N x N grid, omega in {OMEGA}, a in {AMPL}, z = 5, horizon {MAP_HORIZON:g} "
            f"(the README's example), dt = {meta['dt']:g}, float64, paper contact, default chunks, all devices, "
            "results kept in memory (no `path`). Peak RSS is the whole process (Python, JAX, XLA's "
            "compiled code); what the sweep adds grows with the results kept, not with the steps."
        )
        L.append("")
        L.append(
            "| N x N | configurations | devices | wall s (compile included) | mean steps | results MB "
            "| peak RSS MB | valid |"
        )
        L.append("|---|---|---|---|---|---|---|---|")
        for r in maps:
            if "error" in r:
                L.append(f"| {r['N']} x {r['N']} | error: `{r['error'][-200:]}` | | | | | | |")
                continue
            L.append(
                f"| {r['N']} x {r['N']} | {r['n_configs']:,} | {r['n_devices']} | {r['wall']:.3g} | "
                f"{r['steps_mean']:,.0f} | {r['data_mb']:.1f} | {r['rss']:.0f} | {r['n_ok']:,} |"
            )
        L.append("")
    zmaps = res.get("zarr_map", [])
    if zmaps:
        z = next((r for r in zmaps if "error" not in r), zmaps[0])
        L.append("## Maps into a Zarr store: larger than memory")
        L.append("")
        L.append(
            f'`sweep(path="map.zarr")` over an N x N grid, omega in {OMEGA}, a in {AMPL}: a regime map, '
            f"z = 5, {z['dtype']}, dt = {z['dt']:g}, window = horizon = {z['horizon']:g}, paper contact, chunks of "
            f"{z['chunk']} configurations (blocks of whole rows), all devices. Each chunk is written into its "
            "region of the store as it is done and dropped: nothing of the map is kept in memory. CPU s is the "
            "process's (both devices' threads), robust to other load on the machine."
        )
        L.append("")
        L.append(
            "| N x N | configurations | chunks | devices | wall s (compile included) | CPU s | peak RSS MB "
            "| results MB (in memory) | store MB (files) | SSL / SL / undetermined |"
        )
        L.append("|---|---|---|---|---|---|---|---|---|---|")
        for r in zmaps:
            if "error" in r:
                L.append(f"| {r['N']} x {r['N']} | error: `{r['error'][-200:]}` | | | | | | | | |")
                continue
            g = r["regimes"]
            L.append(
                f"| {r['N']} x {r['N']} | {r['n_configs']:,} | {r['n_chunks']:,} | {r['n_devices']} | "
                f"{r['wall']:.3g} | {r['cpu']:.3g} | {r['rss']:.0f} | {r['data_mb']:.1f} | "
                f"{r['store_mb']:.1f} ({r['n_files']:,}) | {g['SSL']:,} / {g['SL']:,} / {g['UNDETERMINED']:,} |"
            )
        L.append("")
    chains = [r for r in res.get("chain", []) if "error" not in r]
    if chains:
        L.append("## Chains of N masses")
        L.append("")
        L.append(
            "`measure` on batches of N-mass chains (`lj.Chain`, the N-mass engine; travelling waves, unit masses, "
            "the paper's spring and friction, t_start = 80), against the two-mass model on its own engine. "
            "*per mass* divides the rate by N."
        )
        if meta.get("chain_command"):
            cmd, note = meta["chain_command"], meta["chain_note"]
            L.append(f"These rows come from a later run of the chain cases alone (`{cmd}`); {note}")
        L.append("")
        L.append("| mechanism | N | batch | compile s | run s wall | cfg-tu/s wall | per CPU-s | per mass (wall) |")
        L.append("|---|---|---|---|---|---|---|---|")
        for r in chains:
            w, c = r["B"] * r["t_sim"] / r["wall"], r["B"] * r["t_sim"] / r["cpu"]
            name = "Params (two-mass engine)" if r.get("params") else "Chain (N-mass engine)"
            L.append(
                f"| {name} | {r['N']} | {r['B']} | {r['compile']:.1f} | {r['wall']:.3g} | {fmt(w)} | {fmt(c)} | "
                f"{fmt(w / r['N'])} |"
            )
        L.append("")

    gaits = [r for r in res.get("gait_map", []) if "error" not in r]
    for r in gaits:
        L.append("## Steady gaits: a map of steady speed and cost of transport")
        L.append("")
        L.append(
            f"{r['n']} x {r['n']} (omega in [1, 25], a in [0.01, 0.1]), paper reading, dt = {r['dt']}. "
            "`steady_gait` (vmapped: 30 periods of transient, Newton on the period map) against direct "
            "simulation at the same accuracy: `simulate` per omega row, saved at every period (so that its "
            f"steps restart at each period like the period map's), averaged over 12 periods after n0 = {r['n0']} "
            f"periods, the number after which the {r['quantile']:.0%} quantile of the largest Floquet multiplier "
            f"({r['mu_quantile']:.4f}) decays to {r['tol']:g}. Errors: the direct answer against the steady gait's, "
            f"over the {r['moving']:,} stable gaits that move ({r['converged']:,} of {r['configs']:,} converged)."
        )
        L.append("")
        L.append(
            "| method | first call s (compile) | warm s | speed error p50 / p95 / max | cost error p50 / p95 / max |"
        )
        L.append("|---|---|---|---|---|")
        ev, ec = r["err_speed"], r["err_cost"]
        L.append(
            f"| steady_gait | {r['gait_first']:.1f} ({r['compile_gait']:.1f}) | {r['gait_warm']:.2f} | (reference) | |"
        )
        L.append(
            f"| direct simulation | {r['direct_first_row']:.1f} (first row) | {r['direct_warm']:.2f} | "
            f"{ev['50']:.1e} / {ev['95']:.1e} / {ev['100']:.1e} | {ec['50']:.1e} / {ec['95']:.1e} / {ec['100']:.1e} |"
        )
        L.append("")

    jacs = [r for r in res.get("jacfwd", []) if "error" not in r]
    if jacs:
        L.append("## Forward-mode derivatives")
        L.append("")
        L.append(
            "`jax.jacfwd` of `measure` (`tau_z`, `e_z`, `mean_speed`; z = 1) with respect to the first p of "
            "`omega, a, d, mu_s, mu_k`, against the p + 1 plain runs of a one-sided finite difference "
            "(`case_jacfwd`). Derivatives per second: batch x p x 3 outputs / jacfwd time."
        )
        L.append("")
        L.append(
            "| p | batch | plain s | jacfwd s | / (p + 1) plain, wall | the same, CPU | derivatives/s | compile s |"
        )
        L.append("|---|---|---|---|---|---|---|---|")
        for r in jacs:
            L.append(
                f"| {r['p']} | {r['B']} | {r['plain']:.3g} | {r['jacfwd']:.3g} | {r['ratio']:.2f} | "
                f"{r['ratio_cpu']:.2f} | {fmt(r['per_second'])} | {r['compile']:.1f} |"
            )
        L.append("")

    if base:
        L.append("## Baseline detail")
        L.append("")
        L.append("| omega | a | scipy wall s | cfg-tu/s | mode segments |")
        L.append("|---|---|---|---|---|")
        for r in sc["rows"]:
            L.append(
                f"| {r['omega']:.3f} | {r['a']:.4f} | {r['wall']:.3g} | {sc['T'] / r['wall']:.3g} | {r['segments']:,} |"
            )
        L.append("")
    return "\n".join(L) + "\n"


if __name__ == "__main__":
    main()
