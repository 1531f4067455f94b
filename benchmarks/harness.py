"""The benchmark's harness: the workload's configurations, clocks, timing and memory readers,
the machine's description and the runner of one case in a fresh process (`spawn`)."""

import json
import math
import os
import platform
import resource
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


def engine_settings():
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


# -- orchestration ---------------------------------------------------------------------------------------


def spawn(spec: dict, devices: int | None = None, timeout: float = 3600) -> dict:
    env = dict(os.environ)
    env.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")
    flags = [f for f in env.get("XLA_FLAGS", "").split() if "force_host_platform_device_count" not in f]
    if devices:
        flags.append(f"--xla_force_host_platform_device_count={devices}")
    env["XLA_FLAGS"] = " ".join(flags)
    proc = subprocess.run(
        [sys.executable, str(HERE / "run.py"), "--case", json.dumps(spec)],
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
