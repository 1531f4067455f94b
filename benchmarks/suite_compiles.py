"""Where the test suite's time goes to XLA: every compilation of a pytest run, by test and program.

Runs pytest (the arguments after `--` are passed on; default the README's `-q -n 2`) with a plugin
that records each `jax.monitoring` event of backend compilation and of jaxpr tracing, with the
test that was running and the program's name (`jit(_measure_batch)`, ...), one line of JSON per
event and worker. Then it prints the totals, the seconds of compilation per test file, per test
and per program (with how many times each program was compiled, and how many of those took over
a second: the rest are small ops or reads from the persistent cache, which go through the same
timer).

    python benchmarks/suite_compiles.py [--cache DIR] [--log DIR] [-- PYTEST ARGS]

`--cache fresh` (the default) gives the run an empty compilation cache of its own (the cold
suite that issue 28 times); `--cache DIR` uses that directory as the tests' lasting cache
(`LJ_TEST_CACHE_DIR`, see tests/conftest.py). `--log DIR` keeps the event logs (default: a
temporary directory); `--report DIR` prints the tables of logs kept before, without running.
"""

import argparse
import collections
import glob
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path


ROOT = Path(__file__).resolve().parents[1]

PLUGIN = """
import json, os
import jax.monitoring as mon
import pytest

_test = ["<collection>"]
_out = []


def _record(name, dur, **kw):
    if "backend_compile" not in name and "jaxpr_trace" not in name:
        return
    if not _out:
        worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
        _out.append(open(os.path.join(os.environ["LJ_COMPILE_LOG"], f"{worker}.jsonl"), "a"))
    event = "compile" if "backend_compile" in name else "trace"
    _out[0].write(json.dumps({"test": _test[0], "event": event, "fun": kw.get("fun_name", ""), "s": dur}) + "\\n")
    _out[0].flush()


mon.register_event_duration_secs_listener(_record)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    _test[0] = item.nodeid
    yield
"""


def report(log: str, top: int = 25) -> None:
    rows = [json.loads(line) for f in sorted(glob.glob(os.path.join(log, "*.jsonl"))) for line in open(f)]
    comp = [r for r in rows if r["event"] == "compile"]
    trace = sum(r["s"] for r in rows if r["event"] == "trace")
    long = [r for r in comp if r["s"] > 1.0]
    total, over = sum(r["s"] for r in comp), sum(r["s"] for r in long)
    print(f"compilation: {total:.0f} s in {len(comp)} events ({len(long)} over 1 s: {over:.0f} s); "
          f"tracing: {trace:.0f} s (worker time)")  # fmt: skip

    def table(title: str, key) -> None:
        groups: dict[str, list[float]] = collections.defaultdict(list)
        for r in comp:
            groups[key(r)].append(r["s"])
        print(f"\n{title}: compile s, compilations, over 1 s")
        for name, ss in sorted(groups.items(), key=lambda kv: -sum(kv[1]))[:top]:
            print(f"{sum(ss):8.1f} {len(ss):6d} {sum(s > 1.0 for s in ss):5d}  {name}")

    table("by test file", lambda r: r["test"].split("::")[0])
    table("by test", lambda r: r["test"])
    table("by program", lambda r: r["fun"])


def main() -> None:
    ap = argparse.ArgumentParser(description="Where the test suite's time goes to XLA, by test and program.")
    ap.add_argument("--cache", default="fresh", help="the tests' compilation cache: fresh (default) or a directory")
    ap.add_argument("--log", default=None, help="directory for the event logs (default: a temporary one)")
    ap.add_argument("--report", default=None, help="print the tables of the logs in this directory, run nothing")
    ap.add_argument("--top", type=int, default=25, help="rows per table")
    args, rest = ap.parse_known_args()
    if args.report:
        report(args.report, args.top)
        return
    pytest_args = [a for a in rest if a != "--"] or ["-q", "-n", "2"]
    log = args.log or tempfile.mkdtemp(prefix="lj-compiles-")
    os.makedirs(log, exist_ok=True)
    plugin_dir = tempfile.mkdtemp(prefix="lj-compile-plugin-")
    Path(plugin_dir, "lj_compile_log.py").write_text(PLUGIN)
    env = dict(os.environ, LJ_COMPILE_LOG=log, LJ_TEST_CACHE_DIR=args.cache)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [plugin_dir, env.get("PYTHONPATH", "")]))
    cmd = [sys.executable, "-m", "pytest", "-p", "lj_compile_log", *pytest_args]
    print("running:", " ".join(cmd), f"(LJ_TEST_CACHE_DIR={args.cache}, logs in {log})", flush=True)
    rc = subprocess.run(cmd, cwd=ROOT, env=env).returncode
    report(log, args.top)
    sys.exit(rc)


if __name__ == "__main__":
    main()
