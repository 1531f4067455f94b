"""Optimal actuation on the paper's parameters (SPEC §7): optimised waveforms vs the best sinusoid.

For several required speeds: optimise a 3-harmonic waveform (base frequency free),
verify it on the exact model (and again with half the step and a longer run),
compare with the best sinusoid from an exact sweep over (a <= a_max, omega),
and draw the Pareto front. Then the horizontal spring (d = 0) with unequal masses.

Run: `python experiments/optimal_actuation.py [--quick]` (x64 on; writes
experiments/output/optimal/). Defaults: k=50, c=0.01, d=0.5, lbar=3, mu_s=0.7,
mu_k=0.5, mhat=0.5, a_max = 0.05, start from the relaxed spring (all runs).
"""

import argparse
import json
import time
from pathlib import Path

import jax


jax.config.update("jax_enable_x64", True)

import locomotion_jax as lj  # noqa: E402
import numpy as np  # noqa: E402
from locomotion_jax import _optimise, _optimise_plots as plots, _pareto  # noqa: E402
from locomotion_jax._constraints import stroke  # noqa: E402
from locomotion_jax._json import jsonable  # noqa: E402
from locomotion_jax._optimum import Settings  # noqa: E402


OUT = Path(__file__).parent / "output" / "optimal"
A_MAX = 0.05
SPEEDS = (0.01, 0.02, 0.03, 0.05)
HORIZON = 60.0


def recheck(params, opt, horizon=200.0, dt=0.005):
    """Independent re-run of the winner: half the step, a longer measurement."""
    fig = _pareto.exact_figures(params, opt.waveform, horizon, dt)
    return {"mean_speed": float(fig.speed), "cost_of_transport": float(fig.cost), "ok": bool(fig.ok)}


def main_speeds(params, settings, sweep, speeds):
    rows, optima = [], []
    for v in speeds:
        t0 = time.perf_counter()
        opt = _optimise.optimise(params, v, A_MAX, harmonics=3, settings=settings, sweep=sweep)
        wall = time.perf_counter() - t0
        check = recheck(params, opt)
        print(f"\n=== v_min = {v} ===\n{opt.summary()}\nrecheck (dt=0.005, horizon 200): {check}", flush=True)
        sub = OUT / f"v{v:g}"
        plots.save_all(opt, params, sweep, sub, HORIZON)
        (sub / "optimum.json").write_text(opt.to_json(full=True, indent=1))
        optima.append(opt)
        rows.append({"v_min": v, "wall_s": wall, "recheck": check, **opt.to_dict()})
    return rows, optima


def d0_study(settings):
    """d = 0: equal masses cannot move (symmetry); unequal masses, sinusoid vs asymmetric waveforms."""
    out = {}
    for mhat in (0.5, 0.3):
        p = lj.Params(d=0.0, mhat=mhat)
        sweep = _pareto.sinusoid_sweep(p, A_MAX, omegas=_pareto.default_omegas(p, 16), amplitudes=3, horizon=HORIZON)
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
            fig = _pareto.exact_figures(pb, batch, HORIZON)
            i = int(np.nanargmax(np.abs(fig.speed)))
            res[f"sawtooth{sense:+d}"] = {
                "max_abs_speed": float(np.abs(fig.speed[i])),
                "omega": float(omegas[i]),
                "speed": float(fig.speed[i]),
                "cost": float(fig.cost[i]),
            }
        entry = {"sinusoid_max_abs_speed": vmax_sin, **res}
        if mhat != 0.5:
            for direction in (1, -1):
                opt = _optimise.optimise(
                    p, 0.005, A_MAX, direction=direction, harmonics=3, settings=settings, sweep=sweep
                )
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
    parser.add_argument("--quick", action="store_true", help="two speeds, coarse smoothing only")
    parser.add_argument("--no-d0", action="store_true")
    parser.add_argument("--only-d0", action="store_true")
    parser.add_argument("--speeds", type=float, nargs="*", default=None)
    args = parser.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    params = lj.Params()
    settings = Settings(verbose=True)
    speeds = args.speeds or SPEEDS
    if args.quick:
        settings = Settings(eps_schedule=(1e-2, 3e-3), outer=2, inner=20, verbose=True)
        speeds = args.speeds or SPEEDS[1:3]
    t0 = time.perf_counter()
    if args.only_d0:
        d0 = d0_study(settings)
        (OUT / "summary_d0.json").write_text(json.dumps(jsonable(d0), indent=1))
        print(f"total {time.perf_counter() - t0:.0f} s")
        return
    sweep = _pareto.sinusoid_sweep(
        params, A_MAX, omegas=_pareto.default_omegas(params, 32), amplitudes=6, horizon=HORIZON
    )
    print(f"sinusoid sweep: {len(sweep.a)} configurations, {time.perf_counter() - t0:.0f} s", flush=True)
    rows, optima = main_speeds(params, settings, sweep, speeds)
    plots.plot_pareto(sweep, optima, OUT / "pareto.png")
    summary = {"a_max": A_MAX, "horizon": HORIZON, "settings": str(settings), "speeds": rows}
    if not args.no_d0:
        summary["d0"] = d0_study(settings)
    summary["total_s"] = time.perf_counter() - t0
    (OUT / "summary.json").write_text(json.dumps(jsonable(summary), indent=1))
    print("\nv_min | sinusoid CoT | optimised CoT (exact) | improvement | speed (exact) | wall s")
    for r in rows:
        print(
            f"{r['v_min']:5g} | {r['sinusoid_cost_of_transport'] or float('nan'):.4g} | "
            f"{r['cost_of_transport_exact'] or float('nan'):.4g} | "
            f"{100 * (r['improvement_vs_sinusoid'] or float('nan')):.1f} % | {r['mean_speed_exact']:.4g} | "
            f"{r['wall_s']:.0f}"
        )
    print(f"total {summary['total_s']:.0f} s")


if __name__ == "__main__":
    main()
