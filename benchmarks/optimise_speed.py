"""An optimiser, old commit against new: the paper's, `lj.optimise(lj.Params(), v_min=0.05, a_max=0.05)`,
or with `--worm N` the README's worm of N masses on bristles, `lj.optimise(worm, v_min=0.1, a_max=0.05)`
(default settings), or with `--chain-knots M` the paper's problem through the chain optimiser,
`lj.optimise(lj.Chain.from_params(lj.Params()), 0.05, 0.05)` with splines of `M` knots
(`ChainOptimiseSettings(shape="spline", knots=M)`; a commit that refuses it prints the error).

Each commit is checked out into a temporary git worktree and run in its own fresh process
(float64, no persistent compilation cache): the call twice, cold (compilation included) and
again in the same process (warm). Per call it prints the wall time, the process's CPU time (less
sensitive to other work on the machine than the wall time), the compilations XLA ran
(count and backend seconds, from `jax.monitoring`), the seconds spent tracing (jaxprs, from
`jax.monitoring` too), the wall time of each stage (from the optimiser's verbose progress lines:
sinusoid baseline, screen, local refinement, verification at `dt` and `dt/2`) and the optimum's
speed and cost of transport.

    python benchmarks/optimise_speed.py OLD NEW [--parallel] [--worm N | --chain-knots M]
    python benchmarks/optimise_speed.py --here [--worm N | --chain-knots M] [--device cpu]

`--parallel` runs the two processes at once (only on a machine with cores to spare: on a
loaded machine the two compete and both times grow). `--here` runs the working tree alone, in one
fresh process (a machine without git, such as the GPU machine's copy of the tree). `--device
cpu` runs the optimiser under `jax.default_device` of the CPU (on a machine whose default is a GPU).
"""

import json
import os
import subprocess
import sys
import tempfile
import time


CHILD = r"""
import json, resource, sys, time
import jax
jax.config.update("jax_enable_x64", True)
import jax.monitoring as mon
events = []
mon.register_event_duration_secs_listener(
    lambda name, dur, **kw: events.append((time.perf_counter(), name, dur))
    if "backend_compile" in name or "jaxpr_trace" in name else None
)
import locomotion_jax as lj
marks = []
class Tee:
    def write(self, s):
        if s.strip():
            marks.append((time.perf_counter(), s.strip()))
        return len(s)
    def flush(self):
        pass
sys.stderr = Tee()
WORM = int(sys.argv[1])  # masses of the worm; 0: the paper's model; -M: the paper's chain, M knots
DEVICE = sys.argv[2] if len(sys.argv) > 2 else ""
DEV = jax.devices(DEVICE or None)[0]  # the named platform's first device, else the default one
def stages(t0, t1):
    # Stage boundaries from the verbose progress lines of the exact optimisers.
    # (The paper's screen's own progress lines read "b of n starts screened": its local stage starts at "; refining".)
    keys = ([("screen", "screening"), ("local", "refining"), ("verify", "verifying")] if WORM else
            [("baseline", "the sinusoid baseline"), ("screen", "screening"), ("local", "s); refining"),
             ("verify", "local runs done")])
    at = {}
    for t, line in marks:
        if t0 <= t <= t1:
            for name, key in keys:
                if key in line and name not in at:
                    at[name] = t
    names = [n for n, _ in keys if n in at]
    ends = [at[n] for n in names[1:]] + [t1]
    return {n: round(e - at[n], 1) for n, e in zip(names, ends)}
for run in ("cold", "warm"):
    t0, c0 = time.perf_counter(), resource.getrusage(resource.RUSAGE_SELF)
    with jax.default_device(DEV if DEVICE else None):
        try:
            if WORM > 0:
                worm = lj.Chain(masses=[1.0] * WORM, d=0.0, friction=lj.AnisotropicCoulomb(0.5, 0.9, 0.3, 0.7))
                opt = lj.optimise(worm, v_min=0.1, a_max=0.05, settings=lj.ChainOptimiseSettings(verbose=True))
            elif WORM < 0:
                spline = lj.ChainOptimiseSettings(shape="spline", knots=-WORM, verbose=True)
                opt = lj.optimise(lj.Chain.from_params(lj.Params()), v_min=0.05, a_max=0.05, settings=spline)
            else:
                opt = lj.optimise(lj.Params(), v_min=0.05, a_max=0.05, settings=lj.ExactOptimiseSettings(verbose=True))
        except ValueError as e:
            print(json.dumps({"run": run, "error": str(e)[:160], "device": DEV.device_kind}), flush=True)
            break
    t1, c1 = time.perf_counter(), resource.getrusage(resource.RUSAGE_SELF)
    cpu = c1.ru_utime + c1.ru_stime - c0.ru_utime - c0.ru_stime
    comp = [d for t, n, d in events if t0 <= t <= t1 and "backend_compile" in n]
    trace = sum(d for t, n, d in events if t0 <= t <= t1 and "jaxpr_trace" in n)
    print(json.dumps({"run": run, "wall_s": round(t1 - t0, 1), "cpu_s": round(cpu, 1), "compilations": len(comp),
                      "compile_s": round(sum(comp), 1), "trace_s": round(trace, 1), "stages_s": stages(t0, t1),
                      "speed": opt.mean_speed_exact, "cost_of_transport": opt.cost_of_transport_exact,
                      "feasible": opt.feasible_exact,
                      "device": DEV.device_kind}), flush=True)
"""


def main(argv: list[str]) -> None:
    worm, device = "0", ""
    if "--worm" in argv:
        i = argv.index("--worm")
        if i + 1 == len(argv) or not argv[i + 1].isdigit():
            sys.exit(__doc__)
        worm = argv[i + 1]
        argv = argv[:i] + argv[i + 2 :]
    if "--chain-knots" in argv:
        i = argv.index("--chain-knots")
        if i + 1 == len(argv) or not argv[i + 1].isdigit():
            sys.exit(__doc__)
        worm = f"-{argv[i + 1]}"
        argv = argv[:i] + argv[i + 2 :]
    if "--device" in argv:
        i = argv.index("--device")
        if i + 1 == len(argv):
            sys.exit(__doc__)
        device = argv[i + 1]
        argv = argv[:i] + argv[i + 2 :]
    args = [a for a in argv if not a.startswith("--")]
    here = "--here" in argv
    if len(args) != (0 if here else 2):
        sys.exit(__doc__)
    parallel = "--parallel" in argv
    if here:
        root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    else:
        root = subprocess.check_output(["git", "rev-parse", "--show-toplevel"], text=True).strip()
    with tempfile.TemporaryDirectory() as tmp:
        procs = []
        for label, commit in [("here", "working tree")] if here else zip(("old", "new"), args):
            tree = root if here else os.path.join(tmp, label)
            if not here:
                subprocess.check_call(["git", "-C", root, "worktree", "add", "--detach", "-q", tree, commit])
            env = dict(os.environ, PYTHONPATH=tree, JAX_ENABLE_COMPILATION_CACHE="false")
            env.pop("LJ_CACHE_DIR", None)
            start = time.perf_counter()
            p = subprocess.Popen(
                [sys.executable, "-c", CHILD, worm, device], cwd=tree, env=env, stdout=subprocess.PIPE, text=True
            )
            procs.append((label, commit, p, start, tree))
            if not parallel:
                p.wait()
        print("| commit | call | wall s | CPU s | compilations | compile s | tracing s | stages s | speed "
              "| cost of transport | feasible |")  # fmt: skip
        print("|---|---|---|---|---|---|---|---|---|---|---|")
        kind = "?"
        for label, commit, p, start, tree in procs:
            out, _ = p.communicate()
            for line in out.splitlines():
                r = json.loads(line)
                kind = r["device"]
                if "error" in r:
                    print(f"| {label} `{commit}` | {r['run']} | refused: {r['error']} |")
                    continue
                stages = ", ".join(f"{k} {v}" for k, v in r["stages_s"].items())
                print(f"| {label} `{commit}` | {r['run']} | {r['wall_s']} | {r['cpu_s']} | {r['compilations']} "
                      f"| {r['compile_s']} | {r['trace_s']} | {stages} | {r['speed']:.16g} "
                      f"| {r['cost_of_transport']:.16g} | {r['feasible']} |")  # fmt: skip
            if not here:
                subprocess.call(["git", "-C", root, "worktree", "remove", "--force", tree])
        print(f"\nload average at the end: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; JAX device: {kind}")


if __name__ == "__main__":
    main(sys.argv[1:])
