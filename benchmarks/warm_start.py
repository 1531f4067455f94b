"""First and second call of the command line, with and without the compilation cache.

Each command runs three times in fresh processes (a sweep into a new file each time): with an empty cache directory
(first call, which fills it), again with that cache (second call), and with
`--no-cache`. Prints a Markdown table of wall time and CPU time (children's
`resource` usage) and the cache's size.

    python benchmarks/warm_start.py
"""

import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path


COMMANDS = {
    "`simulate --omega 2`": ["simulate", "--omega", "2"],
    "`sweep` (16 x 16, dt 0.05)": [
        "sweep",
        "--omega",
        "1:20:16",
        "--a",
        "0.01:0.1:16",
        "--dt",
        "0.05",
        "--horizon",
        "100",
        "--no-progress",
        "--out",
        "{out}",
    ],  # fmt: skip
}


def timed(args: list[str], env: dict, cwd: str) -> tuple[float, float]:
    args = [a.replace("{out}", tempfile.mktemp(suffix=".nc", dir=cwd)) for a in args]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    wall = time.perf_counter()
    cli = [sys.executable, "-c", "from locomotion_jax.cli._main import main; main()"]
    proc = subprocess.run([*cli, *args], env=env, cwd=cwd, capture_output=True, text=True)
    wall = time.perf_counter() - wall
    if proc.returncode != 0:
        raise RuntimeError(f"{args} failed:\n{proc.stderr[-2000:]}")
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def size(path: Path) -> int:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())


def main() -> int:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        cache = Path(tmp) / "cache"
        env = dict(os.environ, LOCOMOTION_JAX_CACHE_DIR=str(cache))
        env.pop("LOCOMOTION_JAX_CACHE", None)
        for label, args in COMMANDS.items():
            shutil.rmtree(cache, ignore_errors=True)
            first = timed(args, env, tmp)
            second = timed(args, env, tmp)
            cold = timed(["--no-cache", *args], env, tmp)
            rows.append((label, first, second, cold, size(cache)))
    print("| command | first call | second call | without the cache | cache size |")
    print("|---|---|---|---|---|")
    for label, first, second, cold, nbytes in rows:
        cells = [f"{w:.1f} s ({c:.1f} s)" for w, c in (first, second, cold)]
        print(f"| {label} | {' | '.join(cells)} | {nbytes / 1e3:.0f} kB |")
    print(f"\nwall time (CPU time); {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at the end")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
