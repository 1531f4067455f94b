"""A worm of N segments driven by a travelling wave: speed and cost of transport against the
wave's phase lag and direction, on isotropic and anisotropic (bristled) ground.

Each configuration is measured on the exact N-mass engine (`lj.measure` on a batch of
`lj.Chain`s, one compiled call): after the transient (`Chain.t_start`), the mean speed and
the dissipated energy are taken over a whole number of actuation periods, and the cost of
transport is the dissipated energy per distance travelled. Writes `worm.png` and
`worm.json` to the output folder.

Usage: python experiments/worm.py [--quick] [--out DIR] [--segments N]
"""

import argparse
import json
import math
import time
from pathlib import Path

import jax


jax.config.update("jax_enable_x64", True)  # start-up choice of the script, like the CLI's --x64

import locomotion_jax as lj
import matplotlib


matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np


OMEGA, A, D, K, C = 2.0, 0.1, 0.0, 50.0, 0.01
PERIODS = 30
FRICTIONS = {
    "isotropic": lj.Coulomb(0.7, 0.5),
    "anisotropic": lj.AnisotropicCoulomb(mu_s_fwd=0.5, mu_s_bwd=0.9, mu_k_fwd=0.3, mu_k_bwd=0.7),
}


def worm_batch(segments: int, phis: np.ndarray, friction: lj.AbstractFriction) -> lj.Chain:
    """Worms of `segments` equal masses, one per phase lag."""
    chains = [
        lj.Chain(
            masses=[1.0] * segments, k=K, d=D, c=C, waveforms=lj.TravellingWave(A, OMEGA, float(phi)), friction=friction
        )  # fmt: skip
        for phi in phis
    ]
    return lj.Chain.stack(chains)


def run(segments: int, n_phi: int) -> dict:
    phis = np.linspace(-math.pi, math.pi, n_phi + 1)[:-1]
    horizon = PERIODS * 2 * math.pi / OMEGA
    out = {"segments": segments, "phi": phis.tolist(), "omega": OMEGA, "a": A, "d": D, "periods": PERIODS}
    for name, fr in FRICTIONS.items():
        batch = worm_batch(segments, phis, fr)
        # Start on a whole period after the transient, so the averages cover whole periods.
        period = 2 * math.pi / OMEGA
        t_start = np.ceil(np.asarray(batch.t_start) / period) * period
        t0 = time.perf_counter()
        m = lj.measure(batch, z=1e6, horizon=horizon, t_start=t_start)
        wall = time.perf_counter() - t0
        speed = np.asarray(m.mean_speed)
        ed = np.asarray(m.e_d)
        ok = np.asarray(m.status) == lj.Status.OK
        dist = np.abs(speed) * horizon
        # No cost of transport where the worm barely moves (under 1e-3 per unit time).
        moving = ok & (np.abs(speed) > 1e-3)
        cot = np.where(moving, ed / np.where(moving, dist, 1), np.nan)
        out[name] = {"mean_speed": speed.tolist(), "cost_of_transport": cot.tolist(), "ok": ok.tolist(),
                     "balance_max": float(np.nanmax(np.abs(np.asarray(m.balance)))), "wall_s": wall}  # fmt: skip
        best = int(np.nanargmax(np.where(ok, speed, -np.inf)))
        print(f"{name:12s} N={segments}: {len(phis)} lags in {wall:.1f} s; fastest forward "
              f"{speed[best]:.4g} at phi = {phis[best]:.3f} (cost of transport {cot[best]:.3g}); "
              f"fastest backward {np.nanmin(speed):.4g} at phi = {phis[int(np.nanargmin(speed))]:.3f}; "
              f"lift-off or failure in {int((~ok).sum())}")  # fmt: skip
    return out


def plot(res: dict, path: Path) -> None:
    phi = np.asarray(res["phi"])
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    for name, style in (("isotropic", "o-"), ("anisotropic", "s-")):
        ax1.plot(phi, res[name]["mean_speed"], style, ms=3, label=name)
        ax2.semilogy(phi, res[name]["cost_of_transport"], style, ms=3, label=name)
    ax1.axhline(0, color="k", lw=0.5)
    ax1.axvline(0, color="k", lw=0.5)
    ax1.set(xlabel="phase lag between neighbouring springs, phi (rad)\n(phi > 0: wave travels forward)",
            ylabel="mean speed", title=f"{res['segments']}-segment worm, travelling wave")  # fmt: skip
    ax2.set(xlabel="phi (rad)", ylabel="cost of transport (dissipated energy / distance)")
    ax1.legend()
    fig.suptitle(f"a = {res['a']}, omega = {res['omega']}, d = {res['d']}; averages over {res['periods']} periods")
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="16 phase lags instead of 64")
    ap.add_argument("--out", default="experiments/output/worm")
    ap.add_argument("--segments", type=int, default=6)
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    res = run(args.segments, 16 if args.quick else 64)
    (out / "worm.json").write_text(json.dumps(res, indent=1))
    plot(res, out / "worm.png")
    print(f"wrote {out / 'worm.png'} and {out / 'worm.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
