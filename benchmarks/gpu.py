"""The benchmark's cases at the batch sizes an accelerator needs, in one short run: the exact
engine (`measure`, the paper's model, float64 and float32) and the N-mass chain engine (N = 2 on the
paper's parameters, 4, 8), each in its own process (`harness.spawn`, so compile time and memory are
per case), then `chain_scaling.py` in the array layout. Sized to finish in about 8 minutes on one
GPU; on the 2-core CPU machine use `--small` (a smoke run of the same script).

    python benchmarks/gpu.py [--small] [--out benchmarks/RESULTS_gpu.md]

Prints one Markdown table of the spawned cases (compile s, run s, cfg-tu/s by wall clock) and the
scaling table, with the machine and versions, and writes them to `--out`.
"""

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path


sys.path.insert(0, str(Path(__file__).resolve().parent))
from harness import DT, HERE, machine, spawn  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--small", action="store_true", help="CPU-sized smoke run")
    ap.add_argument("--out", default=str(HERE / "RESULTS_gpu.md"))
    ap.add_argument("--budget", type=float, default=300.0, help="seconds after which no new case starts")
    args = ap.parse_args()
    H = 20.0 if args.small else 100.0
    big = (64, 256) if args.small else (8192, 65536)
    chain_B = 64 if args.small else 8192
    specs = [dict(kind="exact", B=B, dtype=d, dt=DT, horizon=H, repeats=2) for d in ("float64", "float32") for B in big]
    specs += [
        dict(kind="chain", N=n, params=params, B=chain_B, dtype="float64", dt=DT, horizon=H, repeats=2)
        for n, params in ((2, True), (4, False), (8, False))
    ]
    t0 = time.perf_counter()
    lines = [
        "| case | dtype | batch | compile s | run s (wall) | cfg-tu/s (wall) | peak RSS MB |",
        "|---|---|---|---|---|---|---|",
    ]
    print(json.dumps(machine()), flush=True)
    print("\n".join(lines), flush=True)
    results = []
    for spec in specs:
        if time.perf_counter() - t0 > args.budget:
            print(f"(budget spent: {spec} not run)", flush=True)
            continue
        r = spawn(spec, timeout=max(30.0, args.budget))
        results.append(r)
        name = str(spec["kind"])
        if "N" in spec:
            name += f" N={spec['N']}" + (" (Params)" if spec.get("params") else "")
        if "error" in r:
            line = f"| {name} | {spec['dtype']} | {spec['B']} | error: {r['error'][-300:]!r} | | | |"
        else:
            rate = r["B"] * r["t_sim"] / r["wall"]
            line = (
                f"| {name} | {spec['dtype']} | {spec['B']} | {r['compile']:.1f} | {r['wall']:.3g} | "
                f"{rate:,.0f} | {r['rss']:.0f} |"
            )
        lines.append(line)
        print(line, flush=True)
    scaling = [sys.executable, str(HERE / "chain_scaling.py"), "--layouts", "array"]
    scaling += ["--sizes", "2,4,8", "--batch", "64"] if args.small else ["--sizes", "2,4,16,64", "--batch", "4096"]
    # Streamed line by line, so that a run stopped by its time limit still shows the rows it finished.
    proc = subprocess.Popen(scaling, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    out = []
    for ln in proc.stdout or ():
        print(ln, end="", flush=True)
        out.append(ln)
    proc.wait()
    text = "\n".join(
        [
            "# Benchmark on an accelerator (`benchmarks/gpu.py`)",
            "",
            f"- Machine: `{json.dumps(machine())}`",
            f"- Workload: as `benchmarks/run.py` (horizon {H}, dt {DT}); {time.perf_counter() - t0:.0f} s in all",
            "",
            *lines,
            "",
            "`chain_scaling.py` (array layout): " + " ".join(scaling[2:]),
            "",
            "".join(out),
        ]
    )
    Path(args.out).write_text(text)
    Path(args.out).with_suffix(".json").write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
