"""Chain results of two commits side by side: `measure` and `simulate` on the N-mass engine.

Each revision is checked out into a temporary git worktree and, in a fresh process with
that tree first on `PYTHONPATH`, runs (float64 unless said)

* `measure` on every case of `tests/chain_cases.py` and `LIFTOFF_CASES` of
  `tests/test_against_reference.py` (N = 3, 4, 6; both contacts and starts; Coulomb,
  anisotropic, Stribeck; both actuators), and `simulate` on them to t = 60;
* `measure` on the paper's configurations as N = 2 chains (`Chain.from_params`; the grid of
  `compare_results.py`: 4 x 14 (omega, a), d and mhat in 4 combinations, both contacts and
  both starts), and the first of them in float32.

Per field the largest relative difference is printed twice: plain, and relative to the
largest magnitude of that field in its batch (for quantities that are zero up to rounding:
the speed of a symmetric chain, the energy balance's residual). Fields checked against the
tolerance: `tau_z`, `e_z`, positions, `e_d` and the integer fields (float64 only).

    python benchmarks/compare_chain_results.py OLD NEW [--rtol 1e-12] [--xla-flags-old FLAGS]

`--xla-flags-old` runs the old revision under other `XLA_FLAGS` (for instance
`--xla_cpu_use_fusion_emitters=false`: the same program through another code generator), which
measures how much rounding alone moves each result.
"""

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np


HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

PROGRAM = """
import sys
import jax
jax.config.update("jax_enable_x64", True)
import numpy as np
import locomotion_jax as lj
sys.path.insert(0, sys.argv[2])
from chain_cases import CASES, HORIZON, Z
from reference_chain import chain_config
from test_against_reference import LIFTOFF_CASES, to_chain

out = {}
def put(prefix, m, j=None):
    for k, v in m.to_numpy().items():
        v = np.asarray(v)
        if v.dtype.kind in "fiub":
            out[f"{prefix}/{k}"] = np.asarray(v if j is None else v[j], float)

groups = {}
for c in CASES + LIFTOFF_CASES:
    ch = to_chain(chain_config(**c["config"]))
    key = (ch.n_masses, ch.waves.harmonics, type(ch.friction).__name__, type(ch.actuator).__name__, c["contact"],
           c["start"])
    groups.setdefault(key, []).append((c, ch))
for key, items in groups.items():
    batch = lj.Chain.stack([ch for _, ch in items])
    ts = np.array([c.get("t_start", float(ch.t_start)) for c, ch in items])
    m = lj.measure(batch, z=Z, horizon=HORIZON, contact=key[4], start=key[5], t_start=ts)
    tr = lj.simulate(batch, 60.0, np.linspace(0.0, 60.0, 13), contact=key[4], start=key[5])
    for j, (c, _) in enumerate(items):
        put(f"case/{c['name']}", m, j)
        for k in ("x", "e_d", "status"):
            out[f"traj/{c['name']}/{k}"] = np.asarray(getattr(tr, k)[j], float)
om, a = np.meshgrid(np.linspace(0.5, 20.0, 14), np.linspace(0.01, 0.1, 4))
for d, mhat in ((0.5, 0.5), (0.0, 0.3), (0.0, 0.5), (1.0, 0.7)):
    chain = lj.Chain.from_params(lj.Params(omega=om, a=a, d=d, mhat=mhat))
    for contact in ("strict", "paper"):
        for start in ("paper", "relaxed"):
            m = lj.measure(chain, z=5.0, horizon=300.0, contact=contact, start=start)
            put(f"paper/{d}_{mhat}_{contact}_{start}", m)
chain = lj.Chain.from_params(lj.Params(omega=om, a=a)).astype("float32")
put("float32", lj.measure(chain, z=5.0, horizon=300.0, contact="paper", dtype="float32"))
np.savez(sys.argv[1], **out)
"""

CHECKED = ("tau_z", "e_z", "x", "e_d", "status", "regime", "reached", "liftoff", "n_steps", "n_switch")


def produce(tree: Path, out: Path, xla_flags: str | None = None) -> None:
    env = {**os.environ, "PYTHONPATH": str(tree), "XLA_PYTHON_CLIENT_PREALLOCATE": "false"}
    if xla_flags is not None:
        env["XLA_FLAGS"] = xla_flags
    subprocess.run([sys.executable, "-c", PROGRAM, str(out), str(ROOT / "tests")], env=env, cwd=tree, check=True)


def rel_diff(a: np.ndarray, b: np.ndarray, scale: float | None = None) -> float:
    same = (a == b) | (np.isnan(a) & np.isnan(b))
    den = np.maximum(np.abs(b), 1e-300) if scale is None else max(scale, 1e-300)
    with np.errstate(invalid="ignore", divide="ignore"):
        err = np.where(same, 0.0, np.abs(a - b) / den)
    return float(np.nanmax(np.where(np.isnan(err), np.inf, err), initial=0.0))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("old")
    ap.add_argument("new")
    ap.add_argument("--rtol", type=float, default=1e-12)
    ap.add_argument("--xla-flags-old", default=None)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        files = {}
        for rev, flags in ((args.old, args.xla_flags_old), (args.new, None)):
            tree = Path(tmp) / ("tree_" + rev.replace("/", "_"))
            subprocess.run(["git", "worktree", "add", "--detach", "-q", str(tree), rev], cwd=ROOT, check=True)
            try:
                files[rev] = Path(tmp) / f"{rev.replace('/', '_')}_{len(files)}.npz"
                produce(tree, files[rev], flags)
            finally:
                subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=ROOT, check=False)
        old, new = (np.load(files[r]) for r in (args.old, args.new))
        worst: dict[tuple[str, str], list] = {}
        for key in old.files:
            group = "float32" if key.startswith("float32") else "float64"
            field = key.rsplit("/", 1)[1]
            b, a = old[key], new[key] if key in new.files else np.full_like(old[key], np.nan)
            finite = np.abs(b[np.isfinite(b)])
            w = worst.setdefault((group, field), [0.0, "", 0.0])
            r = rel_diff(a, b)
            if r > w[0]:
                w[0], w[1] = r, key
            w[2] = max(w[2], rel_diff(a, b, float(finite.max()) if finite.size else 1.0))
        head = f"max relative difference ({args.old} vs {args.new})"
        print(f"| dtype | field | {head} | relative to the batch's scale | where |")
        print("|---|---|---|---|---|")
        bad = 0
        for (group, field), (r, key, rs) in sorted(worst.items()):
            flag = group == "float64" and field in CHECKED and r > args.rtol
            bad += flag
            print(f"| {group} | {field}{' **over**' if flag else ''} | {r:.2e} | {rs:.2e} | {key if r > 0 else ''} |")
        print(f"\n{bad} checked float64 fields over the tolerance {args.rtol:g}")
        return 0 if bad == 0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
