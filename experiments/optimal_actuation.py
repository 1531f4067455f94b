"""Optimal actuation on the paper's parameters (SPEC §7): optimised waveforms vs the best sinusoid.

For required speeds 0.01 .. 0.06: the exact method (a periodic spline stroke of 64 knots,
base frequency free; the speeds taken from the highest down, each started also from the
previous speed's optimum, which is feasible at a lower speed: continuation in v_min, so that
the reported costs cannot rise as v_min falls) and the smoothed method (3 harmonics), every
figure the steady gait's on the exact model (whole periods), re-checked with half the step;
the best sinusoid from an exact sweep over (a <= a_max, omega), refined locally; the Pareto
fronts of both methods in one figure with the external solver's point. Then the horizontal spring (d = 0) with
unequal masses.

Run: `python experiments/optimal_actuation.py [--quick] [--no-d0] [--no-smoothed] [--d0-waveforms]` (x64 on;
writes experiments/output/optimal/). Defaults: k=50, c=0.01, d=0.5, lbar=3, mu_s=0.7,
mu_k=0.5, mhat=0.5, a_max = 0.05, strict contact, start from the relaxed spring (all runs).
"""

import argparse
import json
import time
from pathlib import Path
from types import SimpleNamespace

import jax


jax.config.update("jax_enable_x64", True)

import locomotion_jax as lj  # noqa: E402
import numpy as np  # noqa: E402
from locomotion_jax._json import jsonable  # noqa: E402
from locomotion_jax.model._scales import forcing_step  # noqa: E402
from locomotion_jax.optimisation import _optimise, _pareto, _plots as plots  # noqa: E402
from locomotion_jax.optimisation._constraints import stroke  # noqa: E402
from locomotion_jax.optimisation._optimum import ExactSettings, Settings  # noqa: E402


OUT = Path(__file__).parent / "output" / "optimal"
A_MAX = 0.05
SPEEDS = (0.01, 0.02, 0.03, 0.04, 0.05, 0.06)
SMOOTHED_SPEEDS = (0.01, 0.02, 0.03, 0.05)
PEER = {"mean_speed": 0.0509, "cost_of_transport": 0.924, "v_min": 0.05}
"""nosnoc 0.2 + IPOPT (piecewise-constant stroke, 40 intervals, free period), re-simulated
on an exact stick-slip model with mu_s = 0.7 (issue tracker, "Exact-model gradients")."""


def recheck(params, opt, dt=0.005):
    """Independent re-run of the winner: the steady gait with half the step, or less where the
    resolution guard asks for less (4 steps per knot interval of a fast spline)."""
    dt = forcing_step(opt.waveform, dt)
    fig = _pareto.exact_figures(params, opt.waveform, dt=dt)
    return {"mean_speed": float(fig.speed), "cost_of_transport": float(fig.cost), "ok": bool(fig.ok), "dt": dt}


def run_speeds(params, method, settings, sweep, speeds, harmonics):
    rows, optima, previous = [], [], None
    # The exact method continues downward in v_min: a gait fast enough for one speed is a
    # start (and a candidate) for every lower one.
    order = sorted(speeds, reverse=True) if method == "exact" else list(speeds)
    for v in order:
        t0 = time.perf_counter()
        kw = {"start": previous} if method == "exact" else {}
        opt = _optimise.optimise(
            params, v, A_MAX, method=method, harmonics=harmonics, settings=settings, sweep=sweep, **kw
        )
        wall = time.perf_counter() - t0
        if opt.feasible_exact:
            previous = opt
        check = recheck(params, opt)
        print(f"\n=== {method}, v_min = {v} ===\n{opt.summary()}\nrecheck: {check}", flush=True)
        sub = OUT / method / f"v{v:g}"
        plots.save_all(opt, params, sweep, sub)
        (sub / "optimum.json").write_text(opt.to_json(full=True, indent=1))
        optima.append(opt)
        rows.append({"v_min": v, "wall_s": wall, "recheck": check, **opt.to_dict()})
    by_speed = sorted(range(len(order)), key=lambda i: order[i])
    return [rows[i] for i in by_speed], [optima[i] for i in by_speed]


def d0_study(settings, optimise=True):
    """d = 0: equal masses cannot move (symmetry); unequal masses, sinusoid vs asymmetric waveforms
    (and, if `optimise`, optimised waveforms of both directions)."""
    out = {}
    for mhat in (0.5, 0.3):
        p = lj.Params(d=0.0, mhat=mhat)
        sweep = _pareto.sinusoid_sweep(p, A_MAX, omegas=_pareto.default_omegas(p, 16), amplitudes=3)
        vmax_sin = float(np.nanmax(np.abs(sweep.speed)))
        # Saw-tooth (time-asymmetric, even harmonics) of both senses over the same frequencies,
        # scaled so that its true stroke max_t |l0 - lbar| is a_max (`_constraints.stroke`: the
        # maximum over a phase grid, polished by Newton; the shape (1, -1/2, 1/3) peaks at 1.4428).
        n = np.arange(1, 4)
        shape = (-1.0) ** (n + 1) / n
        saw = shape * A_MAX / float(stroke(np.zeros(3), shape))
        omegas = _pareto.default_omegas(p, 16)
        res = {"sawtooth_stroke": float(stroke(np.zeros(3), saw))}
        for sense in (1, -1):
            waves = [lj.Fourier(np.zeros(3), sense * saw, w, p.lbar) for w in omegas]
            batch = _pareto.stack_waveforms(waves)
            pb = lj.Params.grid(omega=np.asarray(omegas), d=0.0, mhat=mhat)
            fig = _pareto.exact_figures(pb, batch)
            i = int(np.nanargmax(np.abs(fig.speed)))
            res[f"sawtooth{sense:+d}"] = {
                "max_abs_speed": float(np.abs(fig.speed[i])),
                "omega": float(omegas[i]),
                "speed": float(fig.speed[i]),
                "cost": float(fig.cost[i]),
            }
        entry = {"sinusoid_max_abs_speed": vmax_sin, **res}
        if mhat != 0.5 and optimise:
            for direction in (1, -1):
                opt = _optimise.optimise(p, 0.005, A_MAX, direction=direction, settings=settings, sweep=sweep)
                entry[f"optimised{direction:+d}"] = {
                    "feasible_exact": opt.feasible_exact,
                    "mean_speed_exact": opt.mean_speed_exact,
                    "cost_of_transport_exact": opt.cost_of_transport_exact,
                    "omega": opt.omega,
                    "cos": opt.cos.tolist(),
                    "sin": opt.sin.tolist(),
                }
                print(f"\n=== d = 0, mhat = {mhat}, direction {direction:+d} ===\n{opt.summary()}", flush=True)
        out[f"mhat={mhat}"] = entry
        print(f"d = 0, mhat = {mhat}: {json.dumps(jsonable(entry))}", flush=True)
    return out


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--quick", action="store_true", help="two speeds, small settings")
    parser.add_argument("--no-d0", action="store_true")
    parser.add_argument("--only-d0", action="store_true")
    parser.add_argument(
        "--d0-waveforms", action="store_true", help="only the d = 0 sinusoids and sawtooths (no optimisation)"
    )
    parser.add_argument(
        "--no-smoothed",
        action="store_true",
        help="skip the smoothed method (the figure and summary keep its optima of an earlier run, if saved)",
    )
    parser.add_argument("--speeds", type=float, nargs="*", default=None)
    args = parser.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    earlier = json.loads((OUT / "summary.json").read_text()) if (OUT / "summary.json").exists() else {}
    params = lj.Params()
    exact = ExactSettings(verbose=True)
    smoothed = Settings(verbose=False)
    speeds = args.speeds or SPEEDS
    if args.quick:
        exact = ExactSettings(local=2, max_iter=40, verbose=True)
        smoothed = Settings(eps_schedule=(1e-2, 3e-3), outer=2, inner=20)
        speeds = args.speeds or SPEEDS[1:3]
    t0 = time.perf_counter()
    if args.d0_waveforms:
        d0 = d0_study(exact, optimise=False)
        (OUT / "summary_d0_waveforms.json").write_text(json.dumps(jsonable(d0), indent=1))
        print(f"total {time.perf_counter() - t0:.0f} s")
        return
    if args.only_d0:
        d0 = d0_study(exact)
        (OUT / "summary_d0.json").write_text(json.dumps(jsonable(d0), indent=1))
        print(f"total {time.perf_counter() - t0:.0f} s")
        return
    sweep = _pareto.sinusoid_sweep(params, A_MAX, omegas=_pareto.default_omegas(params, 32), amplitudes=6)
    print(f"sinusoid sweep: {len(sweep.a)} steady gaits, {time.perf_counter() - t0:.0f} s", flush=True)
    rows, optima = run_speeds(params, "exact", exact, sweep, speeds, None)
    series = {f"exact method (spline, {exact.knots} knots)": optima}
    summary = {"a_max": A_MAX, "exact_settings": str(exact), "exact": rows, "peer": PEER}
    if not args.no_smoothed:
        s_speeds = [v for v in speeds if v in SMOOTHED_SPEEDS] or list(speeds)
        s_rows, s_optima = run_speeds(params, "smoothed", smoothed, sweep, s_speeds, 3)
        series["smoothed method (3 harmonics)"] = s_optima
        summary["smoothed"] = s_rows
        summary["smoothed_settings"] = str(smoothed)
    elif earlier.get("smoothed"):
        # The smoothed method is unchanged: its optima of the earlier run, as saved.
        series["smoothed method (3 harmonics, earlier run)"] = [SimpleNamespace(**r) for r in earlier["smoothed"]]
        summary["smoothed"] = earlier["smoothed"]
        summary["smoothed_settings"] = earlier.get("smoothed_settings")
        summary["smoothed_from_earlier_run"] = True
    plots.plot_pareto(sweep, series, OUT / "pareto.png", peer=(PEER["mean_speed"], PEER["cost_of_transport"]))
    if not args.no_d0:
        summary["d0"] = d0_study(exact)
    summary["total_s"] = time.perf_counter() - t0
    (OUT / "summary.json").write_text(json.dumps(jsonable(summary), indent=1))
    old = {r["v_min"]: r for r in summary.get("smoothed", [])}
    print(
        "\nv_min | best sinusoid CoT (a, omega) | smoothed: speed, CoT | exact: speed, CoT | saving | recheck | wall s"
    )
    for r in rows:
        o = old.get(r["v_min"])
        sin = r["sinusoid"]
        f = lambda x: "n/a" if x is None else f"{x:.4g}"
        print(
            f"{r['v_min']:5g} | {f(r['sinusoid_cost_of_transport'])}"
            + (f" ({sin['a']:.4g}, {sin['omega']:.4g})" if sin else "")
            + f" | {f(o['mean_speed_exact']) + ', ' + f(o['cost_of_transport_exact']) if o else '-'}"
            + f" | {f(r['mean_speed_exact'])}, {f(r['cost_of_transport_exact'])}"
            + f" | {f(100 * r['improvement_vs_sinusoid'] if r['improvement_vs_sinusoid'] is not None else None)} %"
            + f" | {f(r['recheck']['cost_of_transport'])} | {r['wall_s']:.0f}"
        )
    print(f"total {summary['total_s']:.0f} s")


if __name__ == "__main__":
    main()
