"""Fig. 6 of the paper: the SSL region in the (a, omega) plane.

Only the regime is needed, so each configuration runs to the end of the
paper's window (t_start + 25) and no further (`horizon = window = 25`).
Besides the paper's two classes we show a third: "at rest", where both masses
stay stuck through the whole window. The paper's rule counts it as SSL (a mass
sticks); it is SSL without locomotion.
"""

import numpy as np
import xarray as xr

from .._status import Regime
from ..dynamics._exact_dynamics import Exact
from ..model._params import Params
from ..run._measure import measure
from . import _plotting as pl
from ._figtools import (
    describe_axis,
    describe_params,
    liftoff_summary,
    PAPER,
    run_sweep,
    spearman,
    steady_liftoff,
    Verdict,
)


WN1, WN2 = 10.0, float(np.sqrt(50.0))
SIZES_6 = {
    "quick": dict(n_omega=20, n_a=20, dt=0.02, chunk=100, n_check=0, stride=1),
    "default": dict(n_omega=256, n_a=256, dt=0.02, chunk=256, n_check=256, stride=4),
}
# Stick-slip at small a and high omega switches several times per period: such runs
# need up to ~4e4 iterations for t_start + 25 at dt = 0.02, above the engine's default cap.
MAX_STEPS_6 = {0.02: 80_000, 0.01: 120_000}
A_RANGE = (0.001, 0.15)
OMEGA_RANGE = (0.1, 25.0)
# Classes shown in the map.
AT_REST, SSL, SL, UNDETERMINED = 0, 1, 2, 3
CLASS_NAMES = {AT_REST: "at rest (both stuck)", SSL: "SSL", SL: "SL", UNDETERMINED: "undetermined (step cap)"}
CLASS_COLORS = ["#e8e8e8", "#5b9bd5", "#fbe5c8", "#000000"]


def _classes(ds: xr.Dataset) -> np.ndarray:
    reg = ds.regime.values
    out = np.where(reg == Regime.SSL, SSL, np.where(reg == Regime.SL, SL, UNDETERMINED))
    if "stick_fraction1" in ds and "stick_fraction2" in ds:
        rest = (ds.stick_fraction1.values >= 1 - 1e-9) & (ds.stick_fraction2.values >= 1 - 1e-9)
        out = np.where((reg == Regime.SSL) & rest, AT_REST, out)
    return out


def data_6(size: dict) -> xr.Dataset:
    axes = dict(omega=np.linspace(*OMEGA_RANGE, size["n_omega"]), a=np.linspace(*A_RANGE, size["n_a"]))
    # omega is the slow axis: a chunk then holds a few omegas, whose costs are alike
    # (the number of switches grows with omega).
    ds = run_sweep(
        axes,
        horizon=25.0,
        window=25.0,
        dt=size["dt"],
        max_steps=MAX_STEPS_6[size["dt"]],
        chunk_size=size["chunk"],
        progress=size.get("progress", False),
    )
    ds.attrs["grid"] = ", ".join(describe_axis(k, v) for k, v in axes.items())
    ds.attrs["fixed"] = describe_params({}, axes)
    if size.get("n_check"):
        ds = _dt_crosscheck(ds, size)
    return steady_liftoff(ds, dt=size["dt"], stride=size["stride"])


def _dt_crosscheck(ds: xr.Dataset, size: dict) -> xr.Dataset:
    """Re-run a random sample at dt = 0.01 and record how many regimes agree."""
    rng = np.random.default_rng(0)
    n = size["n_check"]
    io = rng.integers(0, ds.omega.size, n)
    ia = rng.integers(0, ds.a.size, n)
    # Pairs (omega_i, a_i) are not a grid: one `measure` batch.
    m = measure(
        Params(omega=ds.omega.values[io], a=ds.a.values[ia]),
        5.0,
        horizon=25.0,
        window=25.0,
        dynamics=Exact(0.01, MAX_STEPS_6[0.01]),
        **PAPER,
    )
    fine = np.asarray(m.regime)
    agree = float(np.mean(fine == ds.regime.values[io, ia]))
    ds.attrs["dt_check"] = f"{n} random configurations re-run at dt = 0.01: regime agrees for {100 * agree:.1f}%"
    return ds


def boundary(ds: xr.Dataset) -> np.ndarray:
    """For each a, the top of the moving-SSL region that reaches down to the lowest omega:
    the highest SSL omega below the first SL omega (NaN where nothing moves in SSL)."""
    cls = _classes(ds)  # (omega, a)
    om = ds.omega.values
    out = np.full(cls.shape[1], np.nan)
    for j in range(cls.shape[1]):
        col = cls[:, j]
        first_sl = np.flatnonzero(col == SL)
        k = first_sl[0] if first_sl.size else col.size
        below = np.flatnonzero(col[:k] == SSL)
        if below.size:
            out[j] = om[below[-1]]
    return out


def plot_6(ds: xr.Dataset, path) -> None:
    from matplotlib.colors import BoundaryNorm, ListedColormap
    from matplotlib.patches import Patch

    fig, ax = pl.new_figure(size=(7.2, 5.2))
    ax = ax[0, 0]
    a, om = ds.a.values, ds.omega.values
    cls = _classes(ds)
    cmap = ListedColormap(CLASS_COLORS)
    ax.pcolormesh(
        a, om, cls, cmap=cmap, norm=BoundaryNorm([-0.5, 0.5, 1.5, 2.5, 3.5], 4), shading="nearest", rasterized=True
    )
    lift = ds.liftoff.values.astype(float)
    steady = ds.liftoff_steady.values.astype(float) if "liftoff_steady" in ds else lift
    transient = lift * (1 - steady)
    if transient.any():
        # Dots: lift-off in the start transient only; hatching: the steady motion loses contact.
        ax.contourf(a, om, transient, levels=[0.5, 1.5], colors="none", hatches=["..."])
    if lift.any():
        ax.contour(a, om, lift, levels=[0.5], colors=pl.TRANSIENT_COLOR, linewidths=0.6)
    if steady.any():
        ax.contourf(a, om, steady, levels=[0.5, 1.5], colors="none", hatches=["////"])
        ax.contour(a, om, steady, levels=[0.5], colors=pl.LIFTOFF_COLOR, linewidths=0.6)
    # The top edge of the boundary cells (pcolormesh centres the cells on the samples).
    ax.plot(a, boundary(ds) + (om[1] - om[0]) / 2, color="k", linewidth=0.9, drawstyle="steps-mid")
    for y, lab in ((WN2, r"$\omega_{n2}=\omega_{n3}$"), (WN1, r"$\omega_{n1}$")):
        ax.axhline(y, color="k", linestyle=":", linewidth=1)
        ax.text(
            a[0],
            y,
            lab,
            ha="left",
            va="bottom",
            fontsize=8,
            bbox=dict(facecolor="white", alpha=0.8, linewidth=0, pad=1),
        )
    ax.set_xlabel(r"amplitude $a$")
    ax.set_ylabel(r"frequency $\omega$")
    sec = ax.secondary_yaxis("right", functions=(lambda w: w / WN1, lambda r: r * WN1))
    sec.set_ylabel(r"$\omega / \omega_{n1}$")
    handles = [Patch(color=c, label=CLASS_NAMES[k]) for k, c in enumerate(CLASS_COLORS) if (cls == k).any()]
    handles.append(
        Patch(facecolor="none", edgecolor=pl.LIFTOFF_COLOR, hatch="////", label="lift-off, steady motion (invalid)")
    )
    handles.append(Patch(facecolor="none", edgecolor="0.3", hatch="...", label="lift-off, start transient only"))
    ax.legend(handles=handles, fontsize=7, loc="upper right", framealpha=0.9)
    ax.set_title(f"Fig. 6: regime over ({a.size} a) x ({om.size} omega); black line: top of the SSL region", fontsize=9)
    pl.save(fig, path)


def check_6(ds: xr.Dataset) -> Verdict:
    cls = _classes(ds)
    om, a = ds.omega.values, ds.a.values
    moving_ssl = cls == SSL
    OM = np.broadcast_to(om[:, None], cls.shape)
    below = float(np.mean(OM[moving_ssl] < WN2)) if moving_ssl.any() else float("nan")
    top = float(OM[moving_ssl].max()) if moving_ssl.any() else float("nan")
    A = np.broadcast_to(a[None, :], cls.shape)
    big = moving_ssl & (A >= 0.02)
    top_big = float(OM[big].max()) if big.any() else float("nan")
    b = boundary(ds)
    rho = spearman(a, b)
    # "omega matters most": how well omega alone (the majority regime of each omega row)
    # predicts the paper's regime, against a alone (majority of each a column).
    ssl = ds.regime.values == Regime.SSL
    by_om = float(np.mean(np.maximum(ssl.mean(axis=1), 1 - ssl.mean(axis=1))))
    by_a = float(np.mean(np.maximum(ssl.mean(axis=0), 1 - ssl.mean(axis=0))))
    # Sharp peaks: the boundary rises by >= 3 grid steps of omega and falls back within
    # 2 steps of a (local maxima that stand out of their neighbours).
    d_om = om[1] - om[0]
    peaks = [
        j
        for j in range(1, b.size - 1)
        if np.isfinite(b[j]) and b[j] - np.nanmax([b[max(j - 2, 0)], b[min(j + 2, b.size - 1)]]) >= 3 * d_om
    ]
    lift = ds.liftoff.values
    lines = [
        f"moving SSL at omega < wn2 = {WN2:.2f} for {100 * below:.1f}% of its configurations (highest omega {top:.2f}; "
        f"{100 * moving_ssl.mean():.0f}% of the map); at rest: {100 * (cls == AT_REST).mean():.0f}% (a < "
        f"{a[(cls == AT_REST).any(axis=0)].max() if (cls == AT_REST).any() else 0:.3f})",
        f"for a >= 0.02 the highest SSL omega is {top_big:.2f} = {top_big / WN1:.2f} wn1 "
        f"(below wn2 = wn3: {'yes' if top_big < WN2 else 'no'})",
        f"top of the SSL region falls with a: Spearman(a, omega_c) = {rho:+.2f}",
        f"the paper's regime (SSL incl. at rest) is predicted by omega alone for {100 * by_om:.0f}% of the map, "
        f"by a alone for {100 * by_a:.0f}%",
        f"{len(peaks)} sharp peak(s) in the boundary"
        + (" at a = " + ", ".join(f"{a[j]:.3f}" for j in peaks[:8]) if peaks else ""),
        f"lift-off (paper reading) in {100 * lift.mean():.0f}% of the map: {liftoff_summary(ds)}; "
        f"undetermined (engine step cap) {int((cls == UNDETERMINED).sum())}",
    ]
    if "dt_check" in ds.attrs:
        lines.append(ds.attrs["dt_check"])
    facts = dict(
        ssl_below_natural=below >= 0.95,
        ssl_at_small_a=rho < 0,
        omega_matters_most=by_om > by_a,
        sharp_peaks=len(peaks) > 0,
    )
    diffs = []
    if top >= WN2:
        diffs.append(
            f"moving SSL reaches omega = {top:.1f} = {top / WN1:.2f} wn1 at the smallest amplitudes, "
            "above wn2 = wn3, in a narrow strip just above the amplitude at which motion starts"
            + ("; 'below the natural frequencies' holds for a >= 0.02" if top_big < WN2 else "")
        )
    return Verdict.from_facts(facts, lines, diffs)
