"""Batch sizes, old commit against new: what a session of `measure` and `simulate` calls at many
batch sizes compiles, and whether its results change.

Each commit is checked out into a temporary git worktree and run in its own fresh process
(float64, no persistent compilation cache). The process calls, for each batch size of `SIZES` in
turn, `lj.measure` and `lj.simulate` of the paper's model (the first `n` of a fixed set of
`(omega, a)`) and `lj.measure` of a 3-mass chain (travelling waves), all with short horizons. It
prints, per commit, the compilations XLA ran (count and backend seconds, from `jax.monitoring`),
the seconds spent tracing and the wall and CPU time; then the new commit's over the old one's; then
the largest relative difference between the two commits' results over every field (bitwise
equality prints 0).

    python benchmarks/batch_sizes.py OLD NEW
"""

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from compare_results import rel_diff, variables


ROOT = Path(__file__).resolve().parent.parent

SIZES = (1, 2, 3, 5, 8, 13, 21, 34, 55, 89)

CHILD = r"""
import json, resource, sys, time
import jax
jax.config.update("jax_enable_x64", True)
import jax.monitoring as mon
events = []
mon.register_event_duration_secs_listener(
    lambda name, dur, **kw: events.append((name, dur)) if "backend_compile" in name or "jaxpr_trace" in name else None
)
import jax.numpy as jnp
import numpy as np
import locomotion_jax as lj

sizes = json.loads(sys.argv[1])
rng = np.random.default_rng(7)
m = max(sizes)
omega, a, phi = rng.uniform(1.5, 20.0, m), rng.uniform(0.01, 0.08, m), rng.uniform(-2.0, 2.0, m)
save_at = jnp.linspace(0.0, 5.0, 6)
out = {}
t0, c0 = time.perf_counter(), resource.getrusage(resource.RUSAGE_SELF)
for n in sizes:
    p = lj.Params(omega=jnp.asarray(omega[:n]), a=jnp.asarray(a[:n]))
    w = lj.TravellingWave(jnp.asarray(a[:n]), jnp.asarray(omega[:n] / 4), jnp.asarray(phi[:n]))
    chain = lj.Chain(masses=np.ones((n, 3)), waveforms=w)
    runs = dict(
        paper_measure=lj.measure(p, z=0.2, horizon=10.0, window=5.0, t_start=2.0),
        paper_simulate=lj.simulate(p, 5.0, save_at=save_at),
        chain_measure=lj.measure(chain, z=0.2, horizon=10.0, window=5.0, t_start=2.0),
    )
    for name, r in runs.items():
        for k, v in vars(r).items():
            if hasattr(v, "dtype") and np.issubdtype(np.asarray(v).dtype, np.number):
                out[f"{name}_{n}_{k}"] = np.asarray(v)
t1, c1 = time.perf_counter(), resource.getrusage(resource.RUSAGE_SELF)
np.savez(sys.argv[2], **out)
comp = [d for name, d in events if "backend_compile" in name]
print(json.dumps({"wall_s": t1 - t0, "cpu_s": c1.ru_utime + c1.ru_stime - c0.ru_utime - c0.ru_stime,
                  "compilations": len(comp), "compile_s": sum(comp),
                  "trace_s": sum(d for name, d in events if "jaxpr_trace" in name)}))
"""


def _largest_difference(old: Path, new: Path) -> float:
    """The largest relative difference over every array of the two files (`compare_results.rel_diff`)."""
    a, b = variables(old), variables(new)
    if sorted(a) != sorted(b):
        return float("inf")
    return max((rel_diff(b[k], a[k]) for k in a), default=0.0)


def main(argv: list[str]) -> int:
    if len(argv) != 2:
        sys.exit(__doc__)
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        for label, rev in zip(("old", "new"), argv):
            tree = Path(tmp) / label
            subprocess.run(["git", "worktree", "add", "--detach", "-q", str(tree), rev], cwd=ROOT, check=True)
            try:
                env = dict(os.environ, PYTHONPATH=str(tree), JAX_ENABLE_COMPILATION_CACHE="false")
                cmd = [sys.executable, "-c", CHILD, json.dumps(SIZES), str(Path(tmp) / f"{label}.npz")]
                rows[label] = json.loads(subprocess.check_output(cmd, cwd=tree, env=env, text=True).splitlines()[-1])
            finally:
                subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=ROOT, check=False)
        diff = _largest_difference(Path(tmp) / "old.npz", Path(tmp) / "new.npz")
    keys = ("compilations", "compile_s", "trace_s", "wall_s", "cpu_s")
    print(f"batch sizes {', '.join(map(str, SIZES))}: `measure` and `simulate` of the paper's model, "
          "`measure` of a 3-mass chain, in one fresh process (no persistent cache)\n")  # fmt: skip
    print("| commit | " + " | ".join(keys) + " |")
    print("|---|" + "---|" * len(keys))
    for label, rev in zip(("old", "new"), argv):
        print(f"| {label} `{rev}` | " + " | ".join(f"{rows[label][k]:.4g}" for k in keys) + " |")
    print("| new / old | " + " | ".join(f"{rows['new'][k] / rows['old'][k]:.2f}" for k in keys) + " |")
    print(f"\nlargest relative difference of the results, new against old: {diff:.2e}")
    print(f"load average at the end: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
