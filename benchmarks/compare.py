"""Benchmark two commits side by side in one run: `benchmarks/run.py` cases against each tree.

Each revision is checked out into a temporary git worktree; every case of `run.py`
(this file's copy) runs in a fresh process with that tree first on `PYTHONPATH`,
alternating between the revisions, and the median of the rounds is compared: the wall-clock
rate, and the rate per CPU-second of the process (the case's `cpu`), which a shared machine's
other load disturbs less.

    python benchmarks/compare.py OLD NEW [--case JSON ...] [--rounds 3]

Default cases: the exact engine, float64, dt 0.03, batches 1024 and 8192 (the throughput
table's headline rows).
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path


HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
DEFAULT_CASES = [
    dict(kind="exact", B=1024, dtype="float64", dt=0.03, horizon=100.0, repeats=2),
    dict(kind="exact", B=8192, dtype="float64", dt=0.03, horizon=100.0, repeats=1),
]


def run_case(tree: Path, spec: dict) -> dict:
    env = dict(os.environ, PYTHONPATH=f"{tree}{os.pathsep}{ROOT / 'tests'}", XLA_PYTHON_CLIENT_PREALLOCATE="false")
    proc = subprocess.run([sys.executable, str(HERE / "run.py"), "--case", json.dumps(spec)], env=env, cwd=tree,
                          capture_output=True, text=True, timeout=3600)  # fmt: skip
    if proc.returncode != 0:
        raise RuntimeError(f"case {spec} failed in {tree}:\n{proc.stderr[-2000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("old")
    ap.add_argument("new")
    ap.add_argument("--case", action="append", help="a run.py case spec (JSON); repeatable")
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    cases = [json.loads(c) for c in args.case] if args.case else DEFAULT_CASES
    with tempfile.TemporaryDirectory() as tmp:
        trees = {}
        for rev in (args.old, args.new):
            tree = Path(tmp) / rev.replace("/", "_")
            subprocess.run(["git", "worktree", "add", "--detach", "-q", str(tree), rev], cwd=ROOT, check=True)
            trees[rev] = tree
        try:
            print(f"| case | {args.old} cfg-tu/s | {args.new} cfg-tu/s | new / old | per CPU-s: new / old |")
            print("|---|---|---|---|---|")
            for spec in cases:
                rates = {rev: [] for rev in trees}
                per_cpu = {rev: [] for rev in trees}
                for _ in range(args.rounds):
                    for rev, tree in trees.items():
                        r = run_case(tree, spec)
                        rates[rev].append(r["B"] * r["t_sim"] / r["wall"])
                        per_cpu[rev].append(r["B"] * r["t_sim"] / r["cpu"])
                old, new = (statistics.median(rates[rev]) for rev in (args.old, args.new))
                cpu_old, cpu_new = (statistics.median(per_cpu[rev]) for rev in (args.old, args.new))
                label = ", ".join(f"{k}={v}" for k, v in spec.items() if k != "repeats")
                row = f"| {label} | {old:,.0f} | {new:,.0f} | {new / old:.3f} | {cpu_new / cpu_old:.3f} |"
                print(row, flush=True)
        finally:
            for tree in trees.values():
                subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=ROOT, check=False)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
