"""Whether two commits compile the same programs: the noise-free half of a side-by-side benchmark.

`benchmarks/compare.py` times both trees, and on a shared 2-core machine its ratios move by a few
per cent from run to run. Where a change must not touch a hot program at all (a check made static,
code moved), this says so exactly: each revision, checked out into a temporary git worktree, runs
the same small jobs in a fresh process with XLA's dump on, and the optimised HLO of every compiled
module whose name is given is compared with the source locations left out (file names, line
numbers and stack frames, which any edit above a traced line shifts).

    python benchmarks/compare_programs.py OLD NEW [--modules jit_measure_batch,...]

Jobs: the paper's model's `measure` (exact, float64, dt 0.03, 64 configurations; module
`jit_measure_batch`) and a 4-mass chain's (travelling wave, anisotropic Coulomb friction;
`jit__measure_batch`), then the chain's under `contact="hop"` (`jit__measure_batch'`). Prints
one line per module, `identical` or how many lines differ, then the verdict; exits 1 where a
program differs.
"""

import argparse
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path


ROOT = Path(__file__).resolve().parent.parent

JOB = """
import jax, jax.numpy as jnp, numpy as np
jax.config.update("jax_enable_x64", True)
import locomotion_jax as lj
lj.measure(lj.Params(omega=jnp.linspace(1.0, 10.0, 64)), dynamics=lj.Exact(dt=0.03))
worm = lj.Chain(masses=np.ones(4), waveforms=lj.TravellingWave(jnp.full(8, 0.05), jnp.linspace(4.0, 12.0, 8),
                2 * np.pi / 3), friction=lj.AnisotropicCoulomb(0.7, 0.9, 0.5, 0.7))
lj.measure(worm, dynamics=lj.Exact(dt=0.03))
lj.measure(worm, dynamics=lj.Exact(dt=0.03), contact="hop")
"""

_LOCATION = re.compile(r"^\d+ [{\"]|^(FileNames|FunctionNames|FileLocations|StackFrames)\b|^HloModule")
_FRAME = re.compile(r",? ?(stack_frame_id=\d+|metadata=\{[^}]*\})")


def dump(tree: Path, out: Path) -> None:
    env = dict(os.environ, PYTHONPATH=str(tree), XLA_FLAGS=f"--xla_dump_to={out} --xla_dump_hlo_as_text")
    subprocess.run([sys.executable, "-c", JOB], env=env, cwd=tree, check=True, capture_output=True)


def programs(out: Path, names: list[str]) -> dict[str, list[str]]:
    """The optimised modules named `names`, in the order compiled, without source locations."""
    found: dict[str, list[str]] = {}
    for f in sorted(out.glob("module_*.cpu_after_optimizations.txt")):
        name = f.name.split(".")[1]
        if name not in names:
            continue
        lines = [_FRAME.sub("", q) for q in f.read_text().splitlines() if not _LOCATION.match(q)]
        key = name
        while key in found:
            key += "'"
        found[key] = lines
    return found


def main() -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("old")
    ap.add_argument("new")
    ap.add_argument("--modules", default="jit_measure_batch,jit__measure_batch", help="module names, comma-separated")
    args = ap.parse_args()
    names = [q for q in args.modules.split(",") if q]
    with tempfile.TemporaryDirectory() as tmp:
        got = {}
        for rev in (args.old, args.new):
            tree = Path(tmp) / rev.replace("/", "_")
            subprocess.run(["git", "worktree", "add", "--detach", "-q", str(tree), rev], cwd=ROOT, check=True)
            try:
                dump(tree, Path(tmp) / f"dump_{rev.replace('/', '_')}")
                got[rev] = programs(Path(tmp) / f"dump_{rev.replace('/', '_')}", names)
            finally:
                subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=ROOT, check=False)
    old, new = got[args.old], got[args.new]
    same = set(old) == set(new) and bool(old)
    for key in sorted(set(old) | set(new)):
        a, b = old.get(key), new.get(key)
        if a is None or b is None:
            print(f"{key}: only in {args.old if b is None else args.new}")
            same = False
            continue
        differ = sum(x != y for x, y in zip(a, b)) + abs(len(a) - len(b))
        print(f"{key}: {'identical' if differ == 0 else f'{differ} of {max(len(a), len(b))} lines differ'} "
              f"({len(b)} lines)")  # fmt: skip
        same &= differ == 0
    print("the same programs" if same else "the programs differ")
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
