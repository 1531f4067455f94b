"""Results of two commits side by side: the figure data and `measure` on the paper's model.

Each revision is checked out into a temporary git worktree and, in a fresh process with
that tree first on `PYTHONPATH`,

* writes the figure data (`locomotion-jax figures --quick`, NetCDF per figure), and
* measures a batch of the paper's configurations (float64, both contact readings, both
  starts, d = 0 and d != 0, SSL, SL and lift-off) with `lj.measure`.

Every numeric variable is then compared (NaN equal to NaN, infinities equal) and the
largest relative difference printed per file, against the tolerance given.

    python benchmarks/compare_results.py OLD NEW [--rtol 1e-10]
"""

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np


HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

MEASURE = """
import sys
import jax
jax.config.update("jax_enable_x64", True)
import numpy as np
import locomotion_jax as lj

om, a = np.meshgrid(np.linspace(0.5, 20.0, 14), np.linspace(0.01, 0.1, 4))
out = {}
for d, mhat in ((0.5, 0.5), (0.0, 0.3), (0.0, 0.5), (1.0, 0.7)):
    for contact in ("strict", "paper"):
        for start in ("paper", "relaxed"):
            m = lj.measure(lj.Params(omega=om, a=a, d=d, mhat=mhat), z=5.0, horizon=300.0, contact=contact, start=start)
            for k, v in m.to_numpy().items():
                v = np.asarray(v)
                if v.dtype.kind in "fiub":
                    out[f"{d}_{mhat}_{contact}_{start}_{k}"] = v.astype(float)
np.savez(sys.argv[1], **out)
"""


def produce(tree: Path, out: Path) -> None:
    env = {"PYTHONPATH": str(tree), "XLA_PYTHON_CLIENT_PREALLOCATE": "false"}
    env = {**__import__("os").environ, **env}
    out.mkdir(parents=True)
    subprocess.run([sys.executable, "-c", MEASURE, str(out / "measure.npz")], env=env, cwd=tree, check=True)
    # The command line's module, wherever the revision keeps it.
    main = (
        "try:\n from locomotion_jax.cli._main import main\n"
        "except ImportError:\n from locomotion_jax._cli import main\nmain()"
    )
    cli = [sys.executable, "-c", main, "figures", "--quick"]
    subprocess.run([*cli, "--out", str(out / "figures")], env=env, cwd=tree, check=True, capture_output=True)


def variables(path: Path) -> dict[str, np.ndarray]:
    if path.suffix == ".npz":
        with np.load(path) as f:
            return {k: f[k] for k in f.files}
    import xarray as xr

    with xr.open_dataset(path) as ds:
        return {str(k): np.asarray(v) for k, v in {**ds.data_vars, **ds.coords}.items() if v.dtype.kind in "fiub"}


def rel_diff(a: np.ndarray, b: np.ndarray) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    if a.shape != b.shape:
        return np.inf
    same = (a == b) | (np.isnan(a) & np.isnan(b))
    with np.errstate(invalid="ignore"):  # inf - inf where only one side is finite counts as inf below
        err = np.where(same, 0.0, np.abs(a - b) / np.maximum(np.abs(b), 1e-300))
    return float(np.nanmax(np.where(np.isnan(err), np.inf, err), initial=0.0))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("old")
    ap.add_argument("new")
    ap.add_argument("--rtol", type=float, default=1e-10)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        dirs = {}
        for rev in (args.old, args.new):
            tree = Path(tmp) / ("tree_" + rev.replace("/", "_"))
            subprocess.run(["git", "worktree", "add", "--detach", "-q", str(tree), rev], cwd=ROOT, check=True)
            try:
                dirs[rev] = Path(tmp) / ("out_" + rev.replace("/", "_"))
                produce(tree, dirs[rev])
            finally:
                subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=ROOT, check=False)
        old, new = dirs[args.old], dirs[args.new]
        files = sorted(p.relative_to(old) for p in old.rglob("*") if p.suffix in (".nc", ".npz"))
        worst = 0.0
        print(f"| file | variables | max relative difference ({args.old} vs {args.new}) |")
        print("|---|---|---|")
        for rel in files:
            if not (new / rel).exists():
                print(f"| {rel} | missing in {args.new} | inf |")
                worst = np.inf
                continue
            a, b = variables(old / rel), variables(new / rel)
            common = sorted(set(a) & set(b))
            d = max((rel_diff(b[k], a[k]) for k in common), default=0.0)
            missing = sorted(set(a) - set(b))
            worst = max(worst, d, np.inf if missing else 0.0)
            note = f" (missing: {', '.join(missing)})" if missing else ""
            print(f"| {rel} | {len(common)}{note} | {d:.2e} |")
        print(f"\nlargest relative difference {worst:.2e} (tolerance {args.rtol:g})")
        return 0 if worst <= args.rtol else 1


if __name__ == "__main__":
    raise SystemExit(main())
