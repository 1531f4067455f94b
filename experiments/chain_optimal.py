"""Optimal actuation of a 4-mass worm: the best travelling wave against per-spring harmonics.

`lj.optimise(chain, v_min, a_max)` on a worm of four unit masses joined by flat springs
(`d = 0`) on bristled ground (static 0.5 forward / 0.9 backward, kinetic 0.3 / 0.7), with a
stroke of at most `a_max` per spring: its travelling-wave screen, the refined per-spring
actuation, the steady gait's speed and cost of transport, and the direct simulation's
agreement. Writes `chain_optimal.json` (one record per required speed) to the output folder.

Usage: python experiments/chain_optimal.py [--v-min 0.1 ...] [--a-max 0.05] [--masses 4] [--harmonics 3] [--out DIR]
"""

import argparse
import time
from pathlib import Path

import jax


jax.config.update("jax_enable_x64", True)  # start-up choice of the script, like the CLI's --x64

import locomotion_jax as lj
from locomotion_jax._json import dumps


def worm(n: int) -> lj.Chain:
    return lj.Chain(masses=[1.0] * n, d=0.0, friction=lj.AnisotropicCoulomb(0.5, 0.9, 0.3, 0.7))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--v-min", type=float, nargs="+", default=[0.1])
    ap.add_argument("--a-max", type=float, default=0.05)
    ap.add_argument("--masses", type=int, default=4)
    ap.add_argument("--harmonics", type=int, default=3)
    ap.add_argument("--out", type=Path, default=Path("experiments/output/chain_optimal"))
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    records = []
    for v in args.v_min:
        t0 = time.perf_counter()
        opt = lj.optimise(worm(args.masses), v, args.a_max, harmonics=args.harmonics,
                          settings=lj.ChainOptimiseSettings(verbose=True))  # fmt: skip
        print(opt.summary(), f"\nwall time {time.perf_counter() - t0:.0f} s\n", flush=True)
        records.append({**opt.to_dict(full=True), "wall_s": time.perf_counter() - t0})
        (args.out / "chain_optimal.json").write_text(dumps(records, indent=1))


if __name__ == "__main__":
    main()
