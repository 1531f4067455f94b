"""The benchmark's cases: one function per kind of work (`CASES`), each run in a process of its
own by `harness.spawn` (`run.py --case JSON`), returning its timings and results as a dict."""

import math
import resource
import statistics
import time
from pathlib import Path

from harness import AMPL, CompileClock, configs, engine_settings, maxrss_mb, OMEGA, setup_jax, thread_cpu, timed


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
    if hasattr(dyn, "chunk_program"):  # the loop cap as the sweep hands it over (0: each configuration's own)
        dyn, max_steps = dyn.chunk_program()
    args = [flat, zhw, dyn, "paper", "paper", max_steps, mesh]
    if "micro_batch" in inspect.signature(_sharding._run_chunk).parameters:
        args.append(micro)
    lowered = _sharding._run_chunk.lower(*args)
    exe = lowered.compile()
    # The arguments the program takes as data: the step cap as well where it is not static (older trees).
    data = (flat, zhw, dyn) + ((jnp.asarray(max_steps, jnp.int32),) if len(lowered.args_info[0]) > 3 else ())
    return lambda: exe(*data)  # the static arguments are compiled in


def case_sharded(spec: dict) -> dict:
    jax = setup_jax()
    import locomotion_jax as lj
    import numpy as np
    from locomotion_jax.model._params import DEFAULTS, PARAM_NAMES

    MICRO_BATCH_CPU, default_max_steps = engine_settings()

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

    MICRO_BATCH_CPU, _ = engine_settings()

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
    if spec.get("params"):  # the paper's model through `lj.measure`, for comparison
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
