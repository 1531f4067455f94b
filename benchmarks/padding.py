"""What the batch-size buckets cost at run time: `measure` of the paper's model at batch sizes just
past a bucket's edge, padded (called eagerly: `batch_rows(n)` rows, the copies never enter a lane)
against unpadded (the same call under `jax.jit`, which compiles for `n` rows), in one process.

On a CPU the work queue's lanes are those of the unpadded batch, so the two should run alike; on an
accelerator a batch runs in as many lanes as it has rows, and the padded rows idle in theirs. The
script prints, per batch size, both calls' first-call and warm times and the largest relative
difference between their results (float64, the benchmark's workload: horizon 100, dt 0.03).

    python benchmarks/padding.py [--small] [--sizes 4097,8193] [--repeats 3]
"""

import argparse
import json
import statistics
import sys
from pathlib import Path


sys.path.insert(0, str(Path(__file__).resolve().parent))
from compare_results import rel_diff  # noqa: E402
from harness import configs, DT, machine, setup_jax, timed  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--small", action="store_true", help="CPU-sized run (horizon 20, batch sizes 65 and 97)")
    ap.add_argument("--sizes", default=None, help="comma-separated batch sizes")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    jax = setup_jax()
    import jax.numpy as jnp
    import locomotion_jax as lj
    import numpy as np
    from locomotion_jax.dynamics._runs import batch_rows

    default = "65,97" if args.small else "4097,8193,32769"
    sizes = [int(s) for s in (args.sizes or default).split(",")]
    horizon = 20.0 if args.small else 100.0
    dyn = lj.Exact(dt=DT)

    def call(p):
        return lj.measure(p, z=1e30, horizon=horizon, window=min(25.0, horizon), dynamics=dyn, contact="paper")

    jitted = jax.jit(call)
    print(json.dumps(machine()), flush=True)
    print(f"horizon {horizon}, dt {DT}, float64; times in s, warm = median of {args.repeats}\n")
    print(
        "| batch | rows padded | padded first | padded warm | unpadded first | unpadded warm "  # fmt: skip
        "| padded / unpadded (warm) | largest rel. diff |"
    )
    print("|---|---|---|---|---|---|---|---|", flush=True)
    for n in sizes:
        om, a = configs(n)
        p = lj.Params(omega=jnp.asarray(om), a=jnp.asarray(a))
        first_pad, warm_pad, _, _ = timed(lambda: call(p).e_d, args.repeats)
        first_jit, warm_jit, _, _ = timed(lambda: jitted(p).e_d, args.repeats)
        padded, unpadded = call(p), jitted(p)
        diff = max(
            (
                rel_diff(np.asarray(v), np.asarray(getattr(unpadded, k)))
                for k, v in vars(padded).items()
                if isinstance(v, jax.Array)
            ),
            default=0.0,
        )
        w_pad, w_jit = statistics.median(warm_pad), statistics.median(warm_jit)
        print(
            f"| {n} | {batch_rows(n)} | {first_pad:.1f} | {w_pad:.3g} | {first_jit:.1f} | {w_jit:.3g} | "
            f"{w_pad / w_jit:.2f} | {diff:.1e} |",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
