"""The paper's Fig. 8 band around resonance under the three contact readings (issue 27, SPEC §10).

The paper's model (defaults of Sect. 3, omega_n1 = 10) over omega/omega_n1 from 0.5 to 2.5 at two
amplitudes, a = 0.05 and 0.1, measured as in Fig. 8 (z = 5 after t_start, the paper's window rule)
under each contact reading, side by side:

- `strict`: the model's own assumption, contact always; a run stops where a normal force reaches
  zero (`Status.LIFTOFF`), so nothing is measured there.
- `paper`: the paper's reading, friction from |N_i| (the ground pulls a body down where N_i < 0).
- `hop`: a body whose normal force reaches zero flies and lands again (plastic landings).

One batched `lj.measure` call per reading (no loop over configurations). The energy balance
`|w - e_d - Delta e| <= 1e-6 e_d` is checked on every measured run and printed; the script exits
with status 1 where it fails. Writes `resonance.png` and `resonance.json` to the output folder
(default `experiments/output/resonance/`).

Usage: python experiments/resonance.py [--quick] [--out DIR]
"""

import argparse
import json
import time
from pathlib import Path

import jax


jax.config.update("jax_enable_x64", True)  # start-up choice of the script, like the CLI's --x64

import locomotion_jax as lj
import matplotlib


matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np


READINGS = ("strict", "paper", "hop")
AMPLITUDES = (0.05, 0.1)
DT = 1.0 / 400
"""The step: at dt = 0.01 the hopping runs balance energy to about 1e-5 e_d only (the landings'
fourth-order error); at 1/400 well inside 1e-6."""
HORIZON = 600.0
"""Time allowed to travel 5 after t_start (the slowest reached run of the band takes about 250)."""
BALANCE_TOL = 1e-6


def grid(quick: bool) -> np.ndarray:
    """omega/omega_n1 from 0.5 to 2.5 by steps of 0.05 (quick: 0.5)."""
    return np.linspace(0.5, 2.5, 5 if quick else 41)


def params_for(ratios: np.ndarray) -> lj.Params:
    """The paper's model at `ratios` times omega_n1 and the two amplitudes: shape `(len(ratios), 2)`."""
    wn1 = float(lj.Params().wn1)
    R, A = np.meshgrid(np.asarray(ratios, float), np.asarray(AMPLITUDES), indexing="ij")
    return lj.Params(omega=R * wn1, a=A)


def measure_reading(params: lj.Params, contact: str) -> lj.Measurement:
    """One batched `measure` of the grid under one reading."""
    return lj.measure(params, 5.0, horizon=HORIZON, dynamics=lj.Exact(dt=DT), contact=contact)


def run(ratios: np.ndarray) -> tuple[dict[str, lj.Measurement], dict[str, float]]:
    """Each reading's measurements of the grid (one call each) and its seconds."""
    params = params_for(ratios)
    results, seconds = {}, {}
    for c in READINGS:
        t0 = time.perf_counter()
        results[c] = measure_reading(params, c)
        seconds[c] = time.perf_counter() - t0
        print(f"{c}: {params.batch_shape} configurations in one call, {seconds[c]:.1f} s")
    return results, seconds


def balance_check(results: dict[str, lj.Measurement]) -> dict[str, float]:
    """The largest `|w - e_d - Delta e| / e_d` of each reading over its measured runs (status OK)."""
    worst = {}
    for c, m in results.items():
        ok = np.asarray(m.status) == lj.Status.OK
        ratio = np.abs(np.asarray(m.balance)) / np.asarray(m.e_d)
        worst[c] = float(ratio[ok].max()) if ok.any() else 0.0
    return worst


def to_json(ratios: np.ndarray, results: dict[str, lj.Measurement], worst: dict[str, float], seconds: dict) -> dict:
    out: dict = {"omega_over_wn1": ratios.tolist(), "a": list(AMPLITUDES), "dt": DT, "horizon": HORIZON, "z": 5.0}
    for c, m in results.items():
        fields = {
            "status": np.asarray(m.status).tolist(),
            "tau_5": np.where(np.isfinite(m.tau_z), m.tau_z, -1.0).round(6).tolist(),
            "e_5": np.where(np.isfinite(m.e_z), m.e_z, -1.0).round(6).tolist(),
            "regime": np.asarray(m.regime).tolist(),
            "liftoff": np.asarray(m.liftoff).tolist(),
        }
        if m.flight_fraction is not None and m.landings_per_period is not None and m.highest_hop is not None:
            fields["flight_fraction"] = np.nan_to_num(np.asarray(m.flight_fraction), nan=-1.0).round(6).tolist()
            fields["landings_per_period"] = np.nan_to_num(np.asarray(m.landings_per_period), nan=-1.0).round(6).tolist()
            fields["highest_hop"] = np.nan_to_num(np.asarray(m.highest_hop), nan=-1.0).round(6).tolist()
        out[c] = fields | {"max_balance_over_e_d": worst[c], "seconds": round(seconds[c], 1)}
    out["note"] = "-1: not measured (run stopped before t_start or z not reached; see status)."
    return out


def plot(ratios: np.ndarray, results: dict[str, lj.Measurement], path: Path) -> None:
    fig, axes = plt.subplots(2, 2, figsize=(11, 7.5), sharex=True)
    colors = {"strict": "k", "paper": "tab:blue", "hop": "tab:red"}
    styles = {0.05: "-", 0.1: "--"}
    for c, m in results.items():
        ok = np.asarray(m.status) == lj.Status.OK
        for j, a in enumerate(AMPLITUDES):
            kw = dict(color=colors[c], ls=styles[a], marker=".", ms=4, label=f"{c}, a = {a}")
            if c == "strict":  # beneath the others, which equal it where it measures
                kw |= dict(lw=5, alpha=0.3, marker=None)
            tau = np.where(ok[:, j], np.asarray(m.tau_z)[:, j], np.nan)
            e = np.where(ok[:, j], np.asarray(m.e_z)[:, j], np.nan)
            axes[0, 0].plot(ratios, tau, **kw)
            axes[0, 1].plot(ratios, e, **kw)
            regime = np.where(ok[:, j], np.asarray(m.regime)[:, j], np.nan) + 0.04 * (READINGS.index(c) - 1)
            axes[1, 0].plot(ratios, regime, ls="none", marker="os^"[READINGS.index(c)], color=colors[c],
                            mfc="none" if j else colors[c], label=f"{c}, a = {a}")  # fmt: skip
            if m.flight_fraction is not None:
                ff = np.where(ok[:, j], np.asarray(m.flight_fraction)[:, j].max(-1), np.nan)
                axes[1, 1].plot(ratios, ff, **kw)
            bad = ~ok[:, j]
            if bad.any():  # where the reading measured nothing: its status, marked on the time axis
                axes[0, 0].plot(ratios[bad], np.full(bad.sum(), 1.0 + 0.3 * j + 0.1 * READINGS.index(c)), "x",
                                color=colors[c], ms=5)  # fmt: skip
    axes[0, 0].set(
        yscale="log",
        ylabel="time to travel 5, $\\tau_5$",
        title="$\\tau_5$ (x at the bottom: not measured; strict: lift-off, hop: collision)",
    )
    axes[0, 1].set(yscale="log", ylabel="dissipated energy $e_5$", title="energy $e_5$")
    axes[1, 0].set(yticks=[0, 1], yticklabels=["SL", "SSL"], ylim=(-0.5, 1.5), title="regime (paper's window rule)")
    axes[1, 1].set(ylabel="largest flight fraction of a mass", title="flight fraction (hop only)")
    for ax in axes[1]:
        ax.set_xlabel("$\\omega/\\omega_{n1}$")
    axes[0, 0].legend(fontsize=7, ncol=2)
    fig.suptitle("The paper's Fig. 8 band under three contact readings (strict, paper's |N|, hop)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def summary(ratios: np.ndarray, results: dict[str, lj.Measurement]) -> None:
    """Per reading and amplitude: how many runs measured, and the fastest one."""
    for c, m in results.items():
        status = np.asarray(m.status)
        for j, a in enumerate(AMPLITUDES):
            st = status[:, j]
            names = {lj.Status(int(s)).name: int((st == s).sum()) for s in np.unique(st)}
            tau = np.where(st == lj.Status.OK, np.asarray(m.tau_z)[:, j], np.inf)
            k = int(np.argmin(tau))
            e = np.where(st == lj.Status.OK, np.asarray(m.e_z)[:, j], np.nan)
            best = "none measured"
            if np.isfinite(tau[k]):
                best = f"fastest tau_5 {tau[k]:.2f} (e_5 {e[k]:.2f}) at omega/wn1 {ratios[k]:.2f}"
                best += f"; e_5 from {np.nanmin(e):.2f} to {np.nanmax(e):.2f}"
            print(f"{c:6s} a = {a:4}: statuses {names}; {best}")
            if c == "hop" and m.flight_fraction is not None:
                ff = np.asarray(m.flight_fraction)[:, j].max(-1)
                fly = (st == lj.Status.OK) & (ff > 0)
                if fly.any():
                    print(f"{'':6s}          hops (flight fraction > 0) at omega/wn1 {ratios[fly].round(2).tolist()}; "
                          f"largest flight fraction {ff[fly].max():.3f}")  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="The Fig. 8 band under three contact readings.")
    parser.add_argument("--quick", action="store_true", help="5 frequencies instead of 41")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "output" / "resonance")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    ratios = grid(args.quick)
    results, seconds = run(ratios)
    worst = balance_check(results)
    summary(ratios, results)
    for c, w in worst.items():
        print(f"energy balance {c}: max |w - e_d - Delta e| / e_d = {w:.2e} (tolerance {BALANCE_TOL:g})")
    (args.out / "resonance.json").write_text(json.dumps(to_json(ratios, results, worst, seconds), indent=1))
    plot(ratios, results, args.out / "resonance.png")
    print(f"wrote {args.out / 'resonance.png'} and {args.out / 'resonance.json'}")
    failed = [c for c, w in worst.items() if not w <= BALANCE_TOL]
    if failed:
        print(f"ENERGY BALANCE FAILED for {failed}")
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
