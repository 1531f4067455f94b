"""The compiled measurement loop of the paper's model in one tree: what one iteration costs.

Run with a tree first on `PYTHONPATH` (this tree, or another revision's worktree): compiles
`measure` of the paper's model (exact, float64, dt 0.03, paper contact, `z` unreachable) on B
configurations of the benchmark's (omega, a) distribution through the tree's own batch function
(the N-body engine's `_paper._measure_batch`, or the two-mass engine's
`_exact_measure._exact_batch` where a tree has no `_paper`), and prints one JSON line:

- `flops`, `bytes`: XLA's `cost_analysis` of the compiled program. XLA counts a while loop's body
  once, and the hot loop's body dominates the program, so these are per lane-iteration of the
  work queue's inner loop times the lanes (64) plus the setup and refill code.
- `whiles`: per while loop of the optimised HLO, the number of arrays it carries and the
  instructions, fusions and elementwise kernels (`fusion` plus unfused ops) of its body. The hot
  loop is the one nested inside the queue's refill loop.
- `iterations`: the configurations' step counts (`n_steps`: sum and max), equal in both engines
  when they take the same steps.
- `busy_s`: the busiest thread's CPU seconds of one warm call (median of `--rep`), robust to
  other load on a shared machine, the process's `cpu_s` and `wall_s`.

    PYTHONPATH=<tree> python benchmarks/loop_cost.py [--B 1024] [--rep 3]
"""

import argparse
import json
import os
import re
import statistics
import sys
import time
from pathlib import Path


def thread_cpu() -> dict[str, float]:
    out = {}
    for task in Path("/proc/self/task").iterdir():
        try:
            out[task.name] = int((task / "schedstat").read_text().split()[0]) * 1e-9
        except OSError:
            pass
    return out


def hlo_whiles(text: str) -> list[dict]:
    """Per `while` of an optimised HLO module: carried arrays and the body's kernels."""
    comps: dict[str, list[str]] = {}
    name = None
    for line in text.splitlines():
        m = re.match(r"^(?:ENTRY )?%?([\w.\-]+) .*\{\s*$", line)
        if m and not line.startswith(" "):
            name = m.group(1)
            comps[name] = []
        elif name is not None and line.startswith("  "):
            comps[name].append(line)
    out = []
    for cname, lines in comps.items():
        for line in lines:
            m = re.search(r"= \((.*?)\) while\(.*body=%?([\w.\-]+)", line)
            if not m:
                continue
            carried = m.group(1).count("[")
            body = comps.get(m.group(2), [])
            ops = [re.search(r"= \S+ (\w[\w\-]*)\(", b) for b in body]
            ops = [o.group(1) for o in ops if o]
            skip = {"parameter", "get-tuple-element", "tuple", "constant", "bitcast", "copy-start", "copy-done"}
            out.append(
                dict(
                    parent=cname,
                    body=m.group(2),
                    carried=carried,
                    instructions=len(ops),
                    fusions=ops.count("fusion"),
                    kernels=sum(o not in skip for o in ops),
                    whiles=ops.count("while"),
                )
            )
    return out


def hot_loop_flops(mod, fn, jax, jnp):
    """The compiled flops and fused kernels of the work queue's inner loop alone, per lane-iteration:
    `fn` compiled with the module's `run_queue` replaced by the queue's setup of the first lanes,
    once followed by an inner loop of their `advance` (selected per lane, as the queue does) and
    once without; the difference is the loop body (XLA counts a loop body once)."""
    import functools

    def fake(setup, running, advance, results, n, lanes, order=None, stream=None, count=None, loop=True):
        pos = jnp.arange(lanes, dtype=jnp.int32)
        fixed, dyn = jax.vmap(setup)(pos)
        if loop:
            active = pos < n
            step = lambda i, d: jax.tree_util.tree_map(
                lambda a, b: jnp.where(active.reshape(active.shape + (1,) * (a.ndim - 1)), a, b),
                jax.vmap(advance)(fixed, d),
                d,
            )
            dyn = jax.lax.fori_loop(0, jnp.asarray(n, jnp.int32) * 0 + 1000, step, dyn)
        total = jnp.stack([jnp.sum(x.astype(jnp.float64)) for x in jax.tree_util.tree_leaves(dyn)])
        return {"out": total, "stick_fraction": jnp.zeros((n, 2))}  # (the N-body path reads stick_fraction)

    real = mod.run_queue
    out = {}
    # The named start is a traced code where the engine takes one (static in older trees).
    static = ("wave_axes", "contact", "dt", "lanes") + (("start",) if isinstance(ARGS[1]["start"], str) else ())
    try:
        for loop in (True, False):
            mod.run_queue = functools.partial(fake, loop=loop)
            fresh = functools.wraps(fn.__wrapped__)(lambda *a, **k: fn.__wrapped__(*a, **k))  # no trace cache hit
            c = (
                jax.jit(
                    fresh,
                    static_argnames=static,
                    compiler_options={"xla_cpu_prefer_vector_width": "512"},
                )
                .lower(*ARGS[0], **ARGS[1])
                .compile()
            )
            ca = c.cost_analysis()
            ca = ca[0] if isinstance(ca, list) else ca
            out[loop] = (ca.get("flops"), c.as_text().count("fusion("))
            if loop and os.environ.get("LOOP_COST_HLO"):
                Path(os.environ["LOOP_COST_HLO"]).write_text(c.as_text())
    finally:
        mod.run_queue = real
    lanes = ARGS[1]["lanes"]
    return dict(flops=(out[True][0] - out[False][0]) / lanes, fusions=out[True][1] - out[False][1])


ARGS: list = []


def main() -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--B", type=int, default=1024)
    ap.add_argument("--rep", type=int, default=3)
    ap.add_argument("--hlo", help="write the optimised HLO here")
    ap.add_argument("--hot-only", action="store_true", help="print the hot loop's flops and fusions only")
    args = ap.parse_args()

    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import numpy as np

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import locomotion_jax as lj
    from harness import configs

    try:
        from locomotion_jax.dynamics import _paper as mod

        fn, engine = mod._measure_batch, "n-body"
    except ImportError:
        from locomotion_jax.dynamics import _exact_measure as mod  # pyright: ignore  # (older trees)

        fn, engine = mod._exact_batch, "two-mass"
    om, a = configs(args.B)
    from locomotion_jax.run._batch import prepare

    p, wave, axes, _ = prepare(lj.Params(omega=om, a=a), None, jnp.float64)
    f64 = lambda v: jnp.asarray(v, jnp.float64)
    from locomotion_jax.dynamics import _runs

    # A traced start code where the engine takes one (a named start, static, in older trees).
    start = _runs.start_code("paper") if hasattr(_runs, "start_code") else "paper"
    kw = dict(wave_axes=axes, contact="paper", start=start, dt=0.03, lanes=_runs.default_lanes(args.B))
    dyn = (p, wave)
    rest = (f64(1e30), f64(100.0), f64(25.0))
    cap = jnp.asarray(0, jnp.int32)
    ARGS[:] = [dyn, dict(z=rest[0], horizon=rest[1], window=rest[2], max_steps=cap, **kw)]
    hot = hot_loop_flops(mod, fn, jax, jnp)
    if args.hot_only:
        print(json.dumps(dict(engine=engine, hot_loop=hot)))
        return 0
    lowered = fn.lower(*dyn, z=rest[0], horizon=rest[1], window=rest[2], max_steps=cap, **kw)  # pyright: ignore[reportFunctionMemberAccess]
    compiled = lowered.compile()
    cost = compiled.cost_analysis()
    cost = cost[0] if isinstance(cost, list) else cost
    text = compiled.as_text()
    if args.hlo:
        Path(args.hlo).write_text(text)
    # The keyword arguments the program takes as data (the start code, the step; static in older trees).
    traced = {k: v for k, v in kw.items() if k in lowered.args_info[1]}
    call = lambda: compiled(*dyn, z=rest[0], horizon=rest[1], window=rest[2], max_steps=cap, **traced)
    out = jax.block_until_ready(call())
    busy, walls, cpus = [], [], []
    for _ in range(args.rep):
        th0, c0, t0 = thread_cpu(), time.process_time(), time.perf_counter()
        out = jax.block_until_ready(call())
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
        th1 = thread_cpu()
        busy.append(max(th1[k] - th0.get(k, 0.0) for k in th1))
    steps = np.asarray(out["n_steps"])
    print(
        json.dumps(
            dict(
                engine=engine,
                tree=os.environ.get("PYTHONPATH", "").split(os.pathsep)[0],
                B=args.B,
                lanes=kw["lanes"],
                flops=cost.get("flops"),
                bytes=cost.get("bytes accessed"),
                hot_loop=hot,
                whiles=hlo_whiles(text),
                iterations=dict(sum=int(steps.sum()), max=int(steps.max())),
                busy_s=statistics.median(busy),
                wall_s=statistics.median(walls),
                cpu_s=statistics.median(cpus),
                ns_per_cfg_iter=1e9 * statistics.median(busy) / int(steps.sum()),
            )
        )
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
