"""The benchmark's report: the targets table (quoted on the documentation's performance page) and
`benchmarks/RESULTS.md`, from one run's results."""

import math
import statistics
import sys
from pathlib import Path

from harness import AMPL, fmt, MAP_HORIZON, OMEGA, rel, ROOT, SEED, TARGETS


TABLE_MARKS = ("<!-- benchmark-targets: start (written by benchmarks/run.py) -->", "<!-- benchmark-targets: end -->")
QUOTED_IN = (ROOT / "docs" / "performance.md",)
"""The pages that quote the targets table between `TABLE_MARKS`: the documentation's performance
page, beside the benchmark's description (the README links to it and quotes no number of its own)."""


def quote_everywhere(res: dict, meta: dict) -> None:
    """Put this run's targets table into every page of `QUOTED_IN`."""
    for page in QUOTED_IN:
        quote_in(res, meta, page)


def quote_in(res: dict, meta: dict, page: Path) -> None:
    """Put this run's targets table between the markers of `page` (a page of `QUOTED_IN`), so the
    page quotes `RESULTS.md` instead of hand-typed numbers."""
    text = page.read_text()
    start, end = TABLE_MARKS
    if start not in text or end not in text:
        print(f"benchmark table markers not found; {page} left unchanged", file=sys.stderr)
        return
    sc = res["scipy"][0] if res["scipy"] and "error" not in res["scipy"][0] else None
    base = None
    if sc:
        base = dict(cpu=len(sc["rows"]) * sc["T"] / sum(r["cpu"] for r in sc["rows"]))
    table = targets(res, meta, base)[2:]  # without the heading
    m = meta["machine"]
    src = (
        f"From `benchmarks/RESULTS.md` (`{meta['command']}`, {meta['elapsed'] / 60:.0f} min on {m.get('cpu')}, "
        f"{m.get('cores')} cores; locomotion_jax at {m.get('commit', '?')}):"
    )
    head, rest = text.split(start, 1)
    tail = rest.split(end, 1)[1]
    page.write_text(head + start + "\n" + src + "\n\n" + "\n".join(table).rstrip() + "\n" + end + tail)


def _memory_mb(meta: dict) -> float:
    """The machine's memory as `machine()` recorded it ("23.5 GiB"); NaN (no verdict) if unknown."""
    text = meta["machine"].get("memory")
    return float(text.split()[0]) * 1024 if text else math.nan


def targets(res: dict, meta: dict, base: dict | None) -> list[str]:
    """The performance targets against what this run measured (a table with a verdict per line)."""
    dt, H, T = meta["dt"], meta["horizon"], TARGETS
    ok = lambda good: "**met**" if good else "not met"
    rows = []
    big = [
        r
        for r in res["exact"]
        if "error" not in r and r["dtype"] == "float64" and r["dt"] == dt and r["horizon"] == H and r["B"] >= 1024
    ]
    if big:
        w = min(r["B"] * r["t_sim"] / r["wall"] for r in big)
        rows.append(
            (
                f"exact, float64, dt = {dt:g}, 1 device, batches {', '.join(str(r['B']) for r in big)}: "
                "cfg-tu/s, wall (lowest)",
                f">= {T['rate']:,.0f}",
                fmt(w),
                ok(w >= T["rate"]),
            )
        )
        if base:
            c = min(r["B"] * r["t_sim"] / r["cpu"] / base["cpu"] for r in big)
            rows.append(
                ("the same, x scipy per core (CPU-seconds; lowest)", f">= {T['ratio']:g}", fmt(c), ok(c >= T["ratio"]))
            )
    for r in res["sharded"]:
        if "error" in r or r["dt"] != dt:
            continue
        nd = r["n_devices"]
        x = r["runs"][f"{nd} devices"]
        w = r["B"] * r["t_sim"] / x["wall"]
        rows.append(
            (
                f"exact, float64, dt = {dt:g}, {nd} devices (`shard_map`), batch {r['B']}: cfg-tu/s, wall",
                f">= {T['rate']:,.0f}",
                fmt(w),
                ok(w >= T["rate"]),
            )
        )
        if base:
            rows.append(
                (
                    f"the same, x scipy on the same {nd} cores (wall)",
                    f">= {T['ratio']:g}",
                    fmt(w / (nd * base["cpu"])),
                    ok(w / (nd * base["cpu"]) >= T["ratio"]),
                )
            )
    acc = res["accuracy"][0] if res["accuracy"] and "error" not in res["accuracy"][0] else None
    key = f"exact float64 dt={dt:g}"
    if acc and key in acc["engines"]:
        lift = acc.get("liftoff", [False] * len(acc["omega"]))
        errs = [rel(x, r) for x, r in zip(acc["engines"][key]["tau"], acc["ref_tau"])]
        kept = [e for e, lo in zip(errs, lift) if not lo and math.isfinite(e)]
        lifted = [e for e, lo in zip(errs, lift) if lo and math.isfinite(e)]
        if kept:
            rows.append(
                (
                    f"tau_5 relative error at dt = {dt:g}, float64: max over the {len(kept)} accuracy "
                    "configurations that keep contact",
                    f"<= {T['accuracy']:g}",
                    f"{max(kept):.1e}",
                    ok(max(kept) <= T["accuracy"]),
                )
            )
        if lifted:
            rows.append(
                (
                    f"the same on the {len(lifted)} that lift off (outside the model's validity; flagged)",
                    "-",
                    f"{max(lifted):.1e}",
                    "reported",
                )
            )
    comp = [r["compile"] for r in res["exact"] if "error" not in r]
    comp += [x["compile"] for r in res["sharded"] if "error" not in r for x in r["runs"].values()]
    if comp:
        rows.append(
            (
                "compile time, every exact-engine case (highest)",
                f"< {T['compile']:g} s",
                f"{max(comp):.1f} s",
                ok(max(comp) < T["compile"]),
            )
        )
    long = [r for r in res["exact"] if "error" not in r and r["horizon"] > H and r["dt"] == dt]
    short = {r["B"]: r for r in big}
    for r in long:
        if r["B"] in short:
            rows.append(
                (
                    f"peak RSS, batch {r['B']}: horizon {r['horizon']:g} vs {H:g} "
                    f"({r['steps_mean'] / short[r['B']]['steps_mean']:.1f}x the steps)",
                    "independent of steps",
                    f"{r['rss']:.0f} MB vs {short[r['B']]['rss']:.0f} MB",
                    ok(r["rss"] <= 1.1 * short[r["B"]]["rss"]),
                )
            )
    maps = [r for r in res.get("map", []) if "error" not in r]
    if maps:
        r = max(maps, key=lambda r: r["N"])
        small = min(maps, key=lambda r: r["N"])
        rows.append(
            (
                f"{r['N']} x {r['N']} map (`sweep`, {r['n_configs']:,} configurations, {r['n_devices']} "
                f"devices): peak RSS; {small['N']} x {small['N']} for scale",
                "< the machine's memory",
                f"{r['rss']:.0f} MB ({r['data_mb']:.1f} MB of results, {r['wall']:.0f} s); {small['rss']:.0f} MB",
                ok(r["rss"] < _memory_mb(meta)),
            )
        )
    zmaps = [r for r in res.get("zarr_map", []) if "error" not in r]
    if len(zmaps) >= 2:
        big, small = max(zmaps, key=lambda r: r["N"]), min(zmaps, key=lambda r: r["N"])
        rows.append(
            (
                f"{big['N']} x {big['N']} regime map into a Zarr store ({big['n_configs']:,} configurations, "
                f"{big['n_devices']} devices): peak RSS vs {small['N']} x {small['N']} "
                f"({big['n_configs'] // small['n_configs']}x the configurations)",
                "independent of the map's size",
                f"{big['rss']:.0f} MB vs {small['rss']:.0f} MB ({big['data_mb']:.0f} MB of results, "
                f"{big['store_mb']:.0f} MB on disk, {big['wall'] / 60:.1f} min)",
                ok(big["rss"] <= 1.1 * small["rss"]),
            )
        )
    for r in res.get("jacfwd", []):
        if "error" in r:
            continue
        # No target: each direction recomputes the primal (docs/gradients.md: about 2.5 p plain runs).
        rows.append(
            (
                f"`jax.jacfwd` of `measure` w.r.t. {r['p']} parameter(s), batch {r['B']}: time / ({r['p']} + 1) "
                "plain runs (wall)",
                "-",
                f"{r['ratio']:.2f} ({fmt(r['per_second'])} derivatives/s)",
                "reported",
            )
        )
    if not rows:
        return []
    out = ["## Targets (issue 5)", "", "| what | target | measured | |", "|---|---|---|---|"]
    out += [f"| {a} | {b} | {c} | {d} |" for a, b, c, d in rows]
    out += [
        "",
        "Compilations are counted in tests: one per sweep whatever its number of chunks "
        "(`tests/test_sweep.py`), none for new parameter values (`tests/test_exact.py`), and in the "
        "optimiser one per optimisation, every smoothing stage sharing the finest stage's compiled loop, none per "
        "stage, iteration, start or call (`tests/test_optimise.py`).",
        "",
    ]
    return out


def report(res: dict, meta: dict) -> str:
    L = []
    m = meta["machine"]
    L.append("# Benchmark results" + (" (quick smoke run)" if meta["quick"] else ""))
    L.append("")
    L.append("Generated by `benchmarks/run.py`; do not edit by hand. How to read it: benchmarks/NOTES.md.")
    L.append("")
    L.append(f"- Command: `{meta['command']}` ({meta['elapsed'] / 60:.1f} min)")
    L.append(f"- Machine: {m.get('cpu')}, {m.get('cores')} cores, {m.get('memory', '?')}; {m['platform']}")
    if "devices" in m:
        L.append(f"- JAX devices: {m['devices']}")
    L.append(
        f"- Versions: Python {m['python']}, jax {m['jax']}, jaxlib {m['jaxlib']}, numpy {m['numpy']}, "
        f"scipy {m['scipy']}, diffrax {m['diffrax']}, equinox {m['equinox']}, locomotion_jax "
        f"{m['locomotion_jax']} at {m.get('commit', '?')}"
    )
    l0, l1 = meta["load"]
    L.append(
        f"- Load average (1/5/15 min) at start {l0[0]:.1f}/{l0[1]:.1f}/{l0[2]:.1f}, at end "
        f"{l1[0]:.1f}/{l1[1]:.1f}/{l1[2]:.1f}: other jobs share the cores, so wall-clock rates are lower "
        "bounds; the per-CPU-second rates are not affected by waiting for a core."
    )
    L.append(
        f'- Workload: `measure(..., z=1e30, horizon={meta["horizon"]:g}, contact="paper")`, i.e. '
        f"t_start (71.1) + {meta['horizon']:g} time units per configuration; omega ~ U{OMEGA}, a ~ U{AMPL} "
        f"(seed {SEED}); exact engine at dt = {meta['dt']:g} unless stated."
    )
    L.append("")

    sc = res["scipy"][0] if res["scipy"] and "error" not in res["scipy"][0] else None
    base = None
    if sc:
        base_wall = sum(r["wall"] for r in sc["rows"])
        base_cpu = sum(r["cpu"] for r in sc["rows"])
        base = dict(wall=len(sc["rows"]) * sc["T"] / base_wall, cpu=len(sc["rows"]) * sc["T"] / base_cpu)

    L.extend(targets(res, meta, base))

    L.append("## Throughput")
    L.append("")
    L.append(
        "cfg-tu/s = configurations x simulated time units per second. *per CPU-s*: work / CPU time of the "
        "process (what a core does while it runs; insensitive to waiting for a core). Ratios are against the "
        "scipy baseline's rate per CPU-second (one configuration per core): *per core* compares CPU "
        "seconds; *same cores* compares the engine's wall-clock rate on N devices (N cores) with scipy on the "
        "same N cores (N processes)."
    )
    L.append("")
    L.append(
        "| engine | dtype | dt | devices | batch | compile s | run s wall | cfg-tu/s wall | cfg-tu/s per CPU-s "
        "| x scipy per core | x scipy on the same cores (wall) | peak RSS MB | iterations mean / max |"
    )
    L.append("|---|---|---|---|---|---|---|---|---|---|---|---|---|")

    def row(name, dtype, dt, ndev, batch, x, work, rss, iters=""):
        w, c = work / x["wall"], work / x["cpu"]
        per_core = fmt(c / base["cpu"]) if base else "-"
        same = fmt(w / (ndev * base["cpu"])) if base else "-"
        L.append(
            f"| {name} | {dtype} | {dt} | {ndev} | {batch} | {x['compile']:.1f} | {x['wall']:.3g} | {fmt(w)} | "
            f"{fmt(c)} | {per_core} | {same} | {rss:.0f} | {iters} |"
        )

    for r in res["exact"]:
        if "error" in r:
            L.append(f"| exact | {r['dtype']} | {r['dt']} | 1 | {r['B']} | error | | | | | | | |")
            continue
        hz = "" if r["horizon"] == meta["horizon"] else f" (horizon {r['horizon']:g})"
        row(
            f"exact, `measure`{hz}",
            r["dtype"],
            f"{r['dt']:g}",
            1,
            r["B"],
            r,
            r["B"] * r["t_sim"],
            r["rss"],
            f"{r['steps_mean']:,.0f} / {r['steps_max']:,}",
        )
    for r in res["sharded"]:
        if "error" in r:
            L.append(f"| exact, shard_map | float64 | {r['dt']} | 2 | {r['B']} | error | | | | | | | |")
            continue
        for label, x in r["runs"].items():
            row(
                "exact, sweep engine `shard_map`",
                "float64",
                f"{r['dt']:g}",
                int(label.split()[0]),
                r["B"],
                x,
                r["B"] * r["t_sim"],
                r["rss"],
            )
    for r in res["smoothed"]:
        if "error" in r:
            L.append("| smoothed | float64 | adaptive | 1 | error | | | | | | | | |")
            continue
        row(
            f"smoothed, diffrax Tsit5, eps=1e-3, t=0..{r['T']:g}",
            "float64",
            "adaptive (rtol 1e-7)",
            1,
            r["B"],
            r,
            r["B"] * r["t_sim"],
            r["rss"],
        )
    if sc:
        L.append(
            f"| scipy `solve_ivp` DOP853 per mode, rtol 1e-9, t=0..{sc['T']:g} | float64 | adaptive | 1 | "
            f"{len(sc['rows'])}, one at a time | - | {base_wall:.3g} | {fmt(base['wall'])} | {fmt(base['cpu'])} | "
            f"1 | 1 | {sc['rss']:.0f} | |"
        )
    L.append("")

    for r in res["sharded"]:
        if "error" in r:
            L.append(f"Sharded case failed: `{r['error'][-300:]}`")
            continue
        nd = r["n_devices"]
        one, many = r["runs"]["1 device"], r["runs"][f"{nd} devices"]
        L.append(f"## Sharding over {nd} devices (the sweep engine's `_sharding._run_chunk`, `shard_map`)")
        L.append("")
        L.append(
            f"Batch {r['B']}, float64, {r['micro_batch'] or 'no'} configurations per loop on a device: "
            f"{one['wall']:.3g} s wall on 1 device, {many['wall']:.3g} s on {nd} "
            f"({one['wall'] / many['wall']:.2f}x; CPU time {one['cpu']:.3g} s vs {many['cpu']:.3g} s). With "
            f"{nd} devices the busiest thread used {many['busy']:.3g} s of CPU: the wall time with a free core "
            f"per device ({r['B'] * r['t_sim'] / many['busy']:,.0f} cfg-tu/s) when other jobs share the "
            "cores. The batch is "
            "sorted by omega (as `measure` does). Each device's loop ends on its own: measuring tau_5 "
            f"(z = 5, horizon {r['tau_horizon']:g}) on the same configurations ordered by expected cost "
            "(`_schedule.cost_order`), device 0 holds the cheaper half, and its output is ready first:"
        )
        L.append("")
        L.append("| device | median tau_5 | iterations: sum / max / mean | output ready after s |")
        L.append("|---|---|---|---|")
        for d in r["per_device"]:
            L.append(
                f"| {d['device']} | {fmt(d['tau_median'])} | {d['steps_sum']:,.0f} / {d['steps_max']:,} / "
                f"{d['steps_mean']:,.0f} | {d['ready']:.3g} |"
            )
        L.append("")

    acc = res["accuracy"][0] if res["accuracy"] and "error" not in res["accuracy"][0] else None
    if acc:
        L.append("## Accuracy against a tight scipy reference (rtol 1e-11 for X, 1e-10 for tau_5)")
        L.append("")
        L.append(
            f"Relative error of X at t = {acc['T']:g} and of tau_5 (z = 5 after t_start, horizon "
            f"{acc['tau_horizon']:g}) on the first {len(acc['omega'])} benchmark configurations "
            "(median / max over them; `-`: not computed or not reached)."
        )
        L.append("")
        lift = acc.get("liftoff", [False] * len(acc["omega"]))
        L.append("| engine | X: median | X: max | tau_5: median | tau_5: max | tau_5: max without lift-off |")
        L.append("|---|---|---|---|---|---|")
        for name, e in acc["engines"].items():
            ex = [rel(x, r) for x, r in zip(e["X"], acc["ref_X"])]
            et = [rel(x, r) for x, r in zip(e["tau"], acc["ref_tau"])]
            ec = [x for x, lo in zip(et, lift) if math.isfinite(x) and not lo]
            ex = [x for x in ex if math.isfinite(x)]
            et = [x for x in et if math.isfinite(x)]
            cell = lambda v, f: f"{f(v):.1e}" if v else "-"
            L.append(
                f"| {name} | {cell(ex, statistics.median)} | {cell(ex, max)} | {cell(et, statistics.median)} | "
                f"{cell(et, max)} | {cell(ec, max)} |"
            )
        L.append("")
        L.append(
            "Under the paper's reading (`n_i = |N_i|`) a configuration that lifts off is integrated through "
            "it: the right-hand side has a kink where a normal force changes sign, which the reference "
            "locates and the engine does not (it flags it), so there the engine converges erratically "
            "(SPEC: such results are outside the model's validity)."
        )
        L.append("")
        L.append("| omega | a | X ref | tau_5 ref | lifts off (paper reading) |")
        L.append("|---|---|---|---|---|")
        for o, a, x, t, lo in zip(acc["omega"], acc["a"], acc["ref_X"], acc["ref_tau"], lift):
            L.append(f"| {o:.3f} | {a:.4f} | {x:.6g} | {fmt(t, 6)} | {'yes' if lo else 'no'} |")
        L.append("")
    elif res["accuracy"]:
        L.append(f"Accuracy case failed: `{res['accuracy'][0]['error'][-500:]}`")

    s = res["schedule"][0] if res["schedule"] and "error" not in res["schedule"][0] else None
    if s:
        fig8 = s.get("grid", "fig8") == "fig8"
        what = (
            f"omega/wn1 in [0.05, 2.5] ({s['N']} points), a = 0.05"
            if fig8
            else f"an omega x a map ({s['N']} x {s['N']} over omega {OMEGA}, a {AMPL}, as a list)"
        )
        tau = s["tau_range"] or [math.nan, math.nan]
        L.append(f"## Long sweeps: cost-ordered chunks ({'Fig. 8 sweep' if fig8 else 'omega x a map'})")
        L.append("")
        L.append(
            f"`sweep` over {what}, z = 5, horizon {s['horizon']:g}, dt = {s['dt']:g}, paper contact, chunks "
            f"of {s['chunk']} on {s['n_devices']} devices; {s['reached']} of {s['n_configs']} configurations "
            f"reach z (tau_5 from {tau[0]:.3g} to {tau[1]:.3g}). Lane efficiency = "
            "iterations the configurations need / lane-iterations their loops ran (a device's shard of "
            f"a chunk runs through the work queue on {s.get('micro_batch') or 'all'} lanes until its last "
            "lane is done; counted by replaying the queue's list scheduling on the iterations each "
            "configuration took); it does not depend on the load of the machine. `natural` and `cost` are "
            "`sweep(order=...)`; `random` is a shuffled list in natural order. The cost order's wall time "
            "includes its pilot run (compiled beforehand). Results bit-for-bit identical in every order: "
            f"{s['same_results']}."
        )
        L.append("")
        L.append("| order | wall s | busiest thread CPU s | lane efficiency |")
        L.append("|---|---|---|---|")
        for k, v in s["orders"].items():
            extra = f" (pilot {v['pilot']:.3g})" if "pilot" in v else ""
            L.append(f"| {k} | {v['wall']:.3g}{extra} | {v['busy']:.3g} | {v['useful'] / v['spent']:.2f} |")
        L.append("")
    elif res["schedule"]:
        L.append(f"Schedule case failed: `{res['schedule'][0]['error'][-500:]}`")
    maps = res.get("map", [])
    if maps:
        L.append("## Maps: memory")
        L.append("")
        L.append(
            f"`sweep` over an N x N grid, omega in {OMEGA}, a in {AMPL}, z = 5, horizon {MAP_HORIZON:g} "
            f"(the README's example), dt = {meta['dt']:g}, float64, paper contact, default chunks, all devices, "
            "results kept in memory (no `path`). Peak RSS is the whole process (Python, JAX, XLA's "
            "compiled code); what the sweep adds grows with the results kept, not with the steps."
        )
        L.append("")
        L.append(
            "| N x N | configurations | devices | wall s (compile included) | mean steps | results MB "
            "| peak RSS MB | valid |"
        )
        L.append("|---|---|---|---|---|---|---|---|")
        for r in maps:
            if "error" in r:
                L.append(f"| {r['N']} x {r['N']} | error: `{r['error'][-200:]}` | | | | | | |")
                continue
            L.append(
                f"| {r['N']} x {r['N']} | {r['n_configs']:,} | {r['n_devices']} | {r['wall']:.3g} | "
                f"{r['steps_mean']:,.0f} | {r['data_mb']:.1f} | {r['rss']:.0f} | {r['n_ok']:,} |"
            )
        L.append("")
    zmaps = res.get("zarr_map", [])
    if zmaps:
        z = next((r for r in zmaps if "error" not in r), zmaps[0])
        L.append("## Maps into a Zarr store: larger than memory")
        L.append("")
        L.append(
            f'`sweep(path="map.zarr")` over an N x N grid, omega in {OMEGA}, a in {AMPL}: a regime map, '
            f"z = 5, {z['dtype']}, dt = {z['dt']:g}, window = horizon = {z['horizon']:g}, paper contact, chunks of "
            f"{z['chunk']} configurations (blocks of whole rows), all devices. Each chunk is written into its "
            "region of the store as it is done and dropped: nothing of the map is kept in memory. CPU s is the "
            "process's (both devices' threads), robust to other load on the machine."
        )
        L.append("")
        L.append(
            "| N x N | configurations | chunks | devices | wall s (compile included) | CPU s | peak RSS MB "
            "| results MB (in memory) | store MB (files) | SSL / SL / undetermined |"
        )
        L.append("|---|---|---|---|---|---|---|---|---|---|")
        for r in zmaps:
            if "error" in r:
                L.append(f"| {r['N']} x {r['N']} | error: `{r['error'][-200:]}` | | | | | | | | |")
                continue
            g = r["regimes"]
            L.append(
                f"| {r['N']} x {r['N']} | {r['n_configs']:,} | {r['n_chunks']:,} | {r['n_devices']} | "
                f"{r['wall']:.3g} | {r['cpu']:.3g} | {r['rss']:.0f} | {r['data_mb']:.1f} | "
                f"{r['store_mb']:.1f} ({r['n_files']:,}) | {g['SSL']:,} / {g['SL']:,} / {g['UNDETERMINED']:,} |"
            )
        L.append("")
    chains = [r for r in res.get("chain", []) if "error" not in r]
    if chains:
        L.append("## Chains of N masses")
        L.append("")
        L.append(
            "`measure` on batches of N-mass chains (`lj.Chain`, the N-mass engine; travelling waves, unit masses, "
            "the paper's spring and friction, t_start = 80), against the two-mass model on its own engine. "
            "*per mass* divides the rate by N."
        )
        if meta.get("chain_command"):
            cmd, note = meta["chain_command"], meta["chain_note"]
            L.append(f"These rows come from a later run of the chain cases alone (`{cmd}`); {note}")
        L.append("")
        L.append("| mechanism | N | batch | compile s | run s wall | cfg-tu/s wall | per CPU-s | per mass (wall) |")
        L.append("|---|---|---|---|---|---|---|---|")
        for r in chains:
            w, c = r["B"] * r["t_sim"] / r["wall"], r["B"] * r["t_sim"] / r["cpu"]
            name = "Params (`lj.measure`)" if r.get("params") else "Chain (N-mass engine)"
            L.append(
                f"| {name} | {r['N']} | {r['B']} | {r['compile']:.1f} | {r['wall']:.3g} | {fmt(w)} | {fmt(c)} | "
                f"{fmt(w / r['N'])} |"
            )
        L.append("")

    gaits = [r for r in res.get("gait_map", []) if "error" not in r]
    for r in gaits:
        L.append("## Steady gaits: a map of steady speed and cost of transport")
        L.append("")
        L.append(
            f"{r['n']} x {r['n']} (omega in [1, 25], a in [0.01, 0.1]), paper reading, dt = {r['dt']}. "
            "`steady_gait` (vmapped: 30 periods of transient, Newton on the period map) against direct "
            "simulation at the same accuracy: `simulate` per omega row, saved at every period (so that its "
            f"steps restart at each period like the period map's), averaged over 12 periods after n0 = {r['n0']} "
            f"periods, the number after which the {r['quantile']:.0%} quantile of the largest Floquet multiplier "
            f"({r['mu_quantile']:.4f}) decays to {r['tol']:g}. Errors: the direct answer against the steady gait's, "
            f"over the {r['moving']:,} stable gaits that move ({r['converged']:,} of {r['configs']:,} converged)."
        )
        L.append("")
        L.append(
            "| method | first call s (compile) | warm s | speed error p50 / p95 / max | cost error p50 / p95 / max |"
        )
        L.append("|---|---|---|---|---|")
        ev, ec = r["err_speed"], r["err_cost"]
        L.append(
            f"| steady_gait | {r['gait_first']:.1f} ({r['compile_gait']:.1f}) | {r['gait_warm']:.2f} | (reference) | |"
        )
        L.append(
            f"| direct simulation | {r['direct_first_row']:.1f} (first row) | {r['direct_warm']:.2f} | "
            f"{ev['50']:.1e} / {ev['95']:.1e} / {ev['100']:.1e} | {ec['50']:.1e} / {ec['95']:.1e} / {ec['100']:.1e} |"
        )
        L.append("")

    jacs = [r for r in res.get("jacfwd", []) if "error" not in r]
    if jacs:
        L.append("## Forward-mode derivatives")
        L.append("")
        L.append(
            "`jax.jacfwd` of `measure` (`tau_z`, `e_z`, `mean_speed`; z = 1) with respect to the first p of "
            "`omega, a, d, mu_s, mu_k`, against the p + 1 plain runs of a one-sided finite difference "
            "(`case_jacfwd`). Derivatives per second: batch x p x 3 outputs / jacfwd time."
        )
        L.append("")
        L.append(
            "| p | batch | plain s | jacfwd s | / (p + 1) plain, wall | the same, CPU | derivatives/s | compile s |"
        )
        L.append("|---|---|---|---|---|---|---|---|")
        for r in jacs:
            L.append(
                f"| {r['p']} | {r['B']} | {r['plain']:.3g} | {r['jacfwd']:.3g} | {r['ratio']:.2f} | "
                f"{r['ratio_cpu']:.2f} | {fmt(r['per_second'])} | {r['compile']:.1f} |"
            )
        L.append("")

    if base:
        L.append("## Baseline detail")
        L.append("")
        L.append("| omega | a | scipy wall s | cfg-tu/s | mode segments |")
        L.append("|---|---|---|---|---|")
        for r in sc["rows"]:
            L.append(
                f"| {r['omega']:.3f} | {r['a']:.4f} | {r['wall']:.3g} | {sc['T'] / r['wall']:.3g} | {r['segments']:,} |"
            )
        L.append("")
    return "\n".join(L) + "\n"
