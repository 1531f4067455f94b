"""Steady gaits by continuation: a bifurcation diagram along omega beside Fig. 8, and the SSL/SL
boundary in the (a, omega) plane over the Fig. 6 regime map.

(a) `bifurcation.png`: mean speed and cost of transport of the steady gaits of the paper's defaults
    against omega / wn1 (paper reading n_i = |N_i|, as the figures). Seeds: `steady_gait` on a grid of
    omega (its attractor, of period k = 1..4); each seed is continued to both neighbouring grid values,
    all branches in one batched `continuation`. Stable parts solid, unstable dashed; SSL blue, SL
    orange, grey where the orbit itself loses contact; markers at the located events. Beside it, the
    Fig. 8 measurements by direct simulation (`_fig_sweep.data_8`: speed 5 / tau_5, cost e_5 / 5).
(b) `boundary.png`: the SSL/SL boundary located by continuation (zeros of the slip margin, to 1e-10
    in the parameter) along a at fixed omega, seeded at a few amplitudes, one branch per pair of
    neighbouring seeds (all in one batch), drawn over a direct-simulation regime map
    (`_fig_map.data_6` on a coarse grid). Both use `Exact(dt=0.02)`, as the Fig. 6 map.

Writes `bifurcation.png`, `boundary.png` and `gaits.json` (the located events, the run times) to
experiments/output/gaits/. Usage: python experiments/bifurcation.py [--quick] [--out DIR]
"""

import argparse
import json
import time
from pathlib import Path

import jax


jax.config.update("jax_enable_x64", True)  # start-up choice of the script, like the CLI's --x64

import locomotion_jax as lj
import numpy as np
from locomotion_jax.gaits._bifurcation import NAMES
from locomotion_jax.paper import _fig_map as fmap, _fig_sweep as fsw, _plotting as pl


OUT = Path(__file__).parent / "output" / "gaits"
WN1 = 10.0
SIZES = {
    "quick": dict(seeds=10, grid=4, map=(24, 20), fig8=dict(n=40, dt=0.02, horizon=800.0, chunk=10), points=80),
    "default": dict(seeds=40, grid=24, map=(96, 64), fig8=dict(n=200, dt=0.01, horizon=2000.0, chunk=16), points=160),
}
A_SEEDS = np.array([0.002, 0.02, 0.04, 0.07, 0.1, 0.15])
DYNAMICS = lj.Exact(dt=0.02)  # as the Fig. 6 map; the events move by ~1e-5 from dt = 0.01
COLORS = {int(lj.Regime.SSL): "#1f5fa8", int(lj.Regime.SL): "#e07b00"}
MARKERS = {"SSL_SL": "D", "LIFTOFF": "x", "FOLD": "^", "PERIOD_DOUBLING": "s", "BRANCH_POINT": "o", "TORUS": "*"}


def seeded(params: lj.Params, parameter: str, grid: np.ndarray, **kw) -> lj.Branch:
    """Continue the steady gait at each value of `grid` (the last axis of the batch) to its two
    neighbours: branches i -> i + 1 and i + 1 -> i, in one batch."""
    starts = np.concatenate([grid[:-1], grid[1:]])
    stops = np.concatenate([grid[1:], grid[:-1]])
    batch = params.replace(**{parameter: starts})
    return lj.continuation(batch, parameter, stops, **kw)


def events(b: lj.Branch) -> list[dict]:
    e = b.events
    kind, lam = np.asarray(e.kind), np.asarray(e.lam)
    out = []
    for idx in zip(*np.nonzero(kind >= 0)):
        out.append(
            dict(
                branch=[int(i) for i in idx[:-1]],
                kind=NAMES[int(kind[idx])],
                lam=float(lam[idx]),
                lam_error=float(np.asarray(e.lam_error)[idx]),
                located=bool(np.asarray(e.located)[idx]),
                smooth=bool(np.asarray(e.smooth)[idx]),
                turn=bool(np.asarray(e.turn)[idx]),
            )
        )
    return out


def draw_branches(ax, b: lj.Branch, field: str, scale: float) -> None:
    """Each branch in pieces of one regime, stability and contact: solid stable, dashed unstable."""
    lam, y = np.asarray(b.lam) / scale, np.asarray(getattr(b, field))
    reg, stable, lift = np.asarray(b.regime), np.asarray(b.stable), np.asarray(b.liftoff)
    for i in range(lam.shape[0]):
        n = int(b.n_points[i])
        if n < 2:
            continue
        key = [(int(reg[i, j]), bool(stable[i, j]), bool(lift[i, j])) for j in range(n)]
        j0 = 0
        for j in range(1, n + 1):
            if j == n or key[j] != key[j0]:
                r, st, lo = key[j0]
                sl = slice(j0, min(j + 1, n))
                color = "0.55" if lo else COLORS.get(r, "k")
                ax.plot(lam[i, sl], y[i, sl], color=color, linestyle="-" if st else "--", linewidth=1.3)
                j0 = j
    e = b.events
    kinds, elam, idx = np.asarray(e.kind), np.asarray(e.lam), np.asarray(e.index)
    for i, q in zip(*np.nonzero(kinds >= 0)):
        name = NAMES[int(kinds[i, q])]
        if name not in MARKERS:
            continue
        j = int(idx[i, q])
        xs, ys = np.asarray(b.lam[i, j : j + 2]), y[i, j : j + 2]
        order = np.argsort(xs)
        yv = np.interp(elam[i, q], xs[order], ys[order])
        ax.plot(elam[i, q] / scale, yv, MARKERS[name], color="k", markersize=5, fillstyle="none")


def panel_a(size: dict, out: Path) -> dict:
    t0 = time.perf_counter()
    grid = np.linspace(0.5, 25.0, size["seeds"])
    b = seeded(lj.Params(), "omega", grid, contact="paper", max_points=size["points"], dynamics=DYNAMICS)
    t_cont = time.perf_counter() - t0
    t0 = time.perf_counter()
    ds = fsw.data_8(dict(size["fig8"], progress=False))
    t_direct = time.perf_counter() - t0
    fig, axes = pl.new_figure(2, 1, size=(7.2, 7.0), sharex=True)
    r = ds.ratio.values
    direct = {"mean_speed": 5.0 / ds.tau_z.values, "cost_of_transport": ds.e_z.values / 5.0}
    for ax, field, label in (
        (axes[0, 0], "mean_speed", "mean speed"),
        (axes[1, 0], "cost_of_transport", "cost of transport"),
    ):
        lift = np.asarray(ds.liftoff.values, bool)
        ax.plot(r[~lift], direct[field][~lift], ".", color="0.3", markersize=3, zorder=0)
        ax.plot(r[lift], direct[field][lift], "+", color="0.65", markersize=3, zorder=0)
        draw_branches(ax, b, field, WN1)
        ax.set_yscale("log")
        ax.set_ylabel(label)
        pl.vlines(
            ax, {r"$\omega_{n2}=\omega_{n3}$": np.sqrt(50.0) / WN1, r"$\omega_{n1}$": 1.0}, text=field == "mean_speed"
        )
    from matplotlib.lines import Line2D

    handles = [
        Line2D([], [], color=COLORS[1], label="SSL, stable"),
        Line2D([], [], color=COLORS[0], label="SL, stable"),
        Line2D([], [], color="k", linestyle="--", label="unstable"),
        Line2D([], [], color="0.55", label="orbit loses contact"),
        Line2D([], [], marker=".", linestyle="", color="0.3", label="Fig. 8, direct simulation"),
        Line2D([], [], marker="+", linestyle="", color="0.65", label="Fig. 8, lift-off"),
    ] + [Line2D([], [], marker=m, linestyle="", color="k", fillstyle="none", label=k) for k, m in MARKERS.items()]
    axes[0, 0].legend(handles=handles, fontsize=6.5, ncol=2, loc="lower center")
    axes[1, 0].set_xlabel(r"$\omega / \omega_{n1}$")
    fig.suptitle(f"Steady gaits by continuation ({size['seeds']} seeds, paper reading) and Fig. 8", fontsize=10)
    pl.save(fig, out / "bifurcation.png")
    status = np.asarray(b.status)
    return dict(
        events=events(b),
        branches=int(status.size),
        points=int(np.sum(np.asarray(b.n_points))),
        status={name: int(np.sum(status == code)) for name, code in vars(lj.BranchStatus).items() if name.isupper()},
        seconds=dict(continuation=t_cont, direct_fig8=t_direct),
    )


def panel_b(size: dict, out: Path) -> dict:
    t0 = time.perf_counter()
    n_om, n_a = size["map"]
    ds = fmap.data_6(dict(n_omega=n_om, n_a=n_a, dt=0.02, chunk=256, n_check=0, stride=4))
    t_map = time.perf_counter() - t0
    t0 = time.perf_counter()
    # Along a at each omega of the grid, seeded at A_SEEDS: every branch in one batch.
    omegas = np.linspace(1.0, 25.0, size["grid"])
    starts = np.tile(np.concatenate([A_SEEDS[:-1], A_SEEDS[1:]]), omegas.size)
    stops = np.tile(np.concatenate([A_SEEDS[1:], A_SEEDS[:-1]]), omegas.size)
    fixed = np.repeat(omegas, 2 * (A_SEEDS.size - 1))
    b = lj.continuation(lj.Params(omega=fixed, a=starts), "a", stops, contact="paper", max_points=size["points"],
                        max_step=0.1, locate=("SSL_SL",), dynamics=DYNAMICS)  # fmt: skip
    t_cont = time.perf_counter() - t0
    e = b.events
    kind, lam, located, turn = (np.asarray(x) for x in (e.kind, e.lam, e.located, e.turn))
    pts = [
        dict(a=float(lam[i, q]), omega=float(fixed[i]), turn=bool(turn[i, q]))
        for i, q in zip(*np.nonzero((kind == lj.EventKind.SSL_SL) & located))
    ]

    from matplotlib.colors import BoundaryNorm, ListedColormap
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    fig, axs = pl.new_figure(size=(7.2, 5.4))
    ax = axs[0, 0]
    a, om = ds.a.values, ds.omega.values
    cls = fmap._classes(ds)
    ax.pcolormesh(a, om, cls, cmap=ListedColormap(fmap.CLASS_COLORS), norm=BoundaryNorm([-0.5, 0.5, 1.5, 2.5, 3.5], 4),
                  shading="nearest", rasterized=True)  # fmt: skip
    steady = ds.liftoff_steady.values.astype(float) if "liftoff_steady" in ds else ds.liftoff.values.astype(float)
    if steady.any():
        ax.contourf(a, om, steady, levels=[0.5, 1.5], colors="none", hatches=["////"])
    for turn, marker in ((False, "o"), (True, "D")):
        sel = [p for p in pts if p["turn"] == turn]
        ax.plot([p["a"] for p in sel], [p["omega"] for p in sel], marker, color="k", markersize=3.5, linestyle="",
                fillstyle="full" if not turn else "none")  # fmt: skip
    ax.set_xlabel(r"amplitude $a$")
    ax.set_ylabel(r"frequency $\omega$")
    ax.set_xlim(a[0], a[-1])
    ax.set_ylim(om[0], om[-1])
    handles = [Patch(color=c, label=fmap.CLASS_NAMES[k]) for k, c in enumerate(fmap.CLASS_COLORS) if (cls == k).any()]
    handles += [
        Patch(facecolor="none", edgecolor="0.3", hatch="////", label="lift-off, steady motion"),
        Line2D([], [], marker="o", linestyle="", color="k", markersize=3, label="SSL/SL boundary (continuation in a)"),
        Line2D(
            [],
            [],
            marker="D",
            linestyle="",
            color="k",
            markersize=3,
            fillstyle="none",
            label="... where the branch turns back",
        ),
    ]
    ax.legend(handles=handles, fontsize=7, loc="upper right", framealpha=0.9)
    ax.set_title(f"SSL/SL boundary by continuation over the regime map ({n_a} a x {n_om} omega, direct simulation)",
                 fontsize=9)  # fmt: skip
    pl.save(fig, out / "boundary.png")
    return dict(points=pts, seconds=dict(map=t_map, continuation=t_cont), branches=int(b.status.size))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small grids (a smoke run)")
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args(argv)
    size = SIZES["quick" if args.quick else "default"]
    args.out.mkdir(parents=True, exist_ok=True)
    summary = dict(size="quick" if args.quick else "default", bifurcation=panel_a(size, args.out))
    print(json.dumps({k: v for k, v in summary["bifurcation"].items() if k != "events"}, indent=1), flush=True)
    summary["boundary"] = panel_b(size, args.out)
    print(json.dumps(summary["boundary"]["seconds"]), len(summary["boundary"]["points"]), "boundary points")
    (args.out / "gaits.json").write_text(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
