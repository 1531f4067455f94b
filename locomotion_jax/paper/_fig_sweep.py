"""Measurement figures of the paper: Fig. 7 (tau_5 vs mu_s - mu_k), Fig. 8 (tau_5, e_5
vs omega/wn1), Fig. 9 (vs a for five omegas) and Fig. 12 (vs the mass ratio).

Each figure has `data(size) -> xarray.Dataset`, `plot(ds, path)` and
`check(ds) -> Verdict`; `_figures.py` registers them. Chunks are kept small and
ordered along the swept axis, because under `vmap` a chunk runs as long as its
slowest configuration (slow low frequencies, or a run that hits the step cap).
"""

import numpy as np
import xarray as xr

from .._status import Regime, Status
from ..model._params import Params
from . import _plotting as pl
from ._figtools import (
    describe_axis,
    describe_params,
    liftoff_summary,
    local_minima,
    run_sweep,
    spearman,
    steady_liftoff,
    Verdict,
    yes,
)


WN1 = 10.0  # wn1 for the paper's defaults (m1 = m2 = 1, k = 50)
WN2 = float(np.sqrt(50.0))
OMEGAS_5 = (2.0, 6.0, 9.5, 16.0, 23.0)  # Figs. 9 and 12


def _sweep(axes, size, fixed=None, chunk=None):
    ds = run_sweep(
        axes,
        fixed=fixed,
        dt=size["dt"],
        horizon=size["horizon"],
        chunk_size=chunk or size["chunk"],
        progress=size.get("progress", False),
    )
    ds.attrs["grid"] = ", ".join(describe_axis(k, v) for k, v in axes.items())
    ds.attrs["fixed"] = describe_params(fixed or {}, axes)
    return steady_liftoff(ds, fixed, dt=size["dt"])


def _mask(ds, name):
    if name == "liftoff_steady" and name not in ds:  # `steady_liftoff` not run: every lift-off counts
        name = "liftoff"
    return np.asarray(ds[name].values)


def _curve(ax, x, ds, var, *, color="k", label=None, ssl_markers=True):
    """One measured curve: line through finite values, SSL filled / SL open markers and
    lift-off crosses (multi-curve figures), or, for a single curve over hatched
    lift-off bands, the lift-off part of the line in grey; unreached and step-cap
    triangles on the top edge."""
    y = pl.finite_or_nan(ds[var].values)
    lift = _mask(ds, "liftoff")
    if ssl_markers:
        ax.plot(x, y, "-", color=color, linewidth=1.0, label=label)
        ssl = _mask(ds, "regime") == Regime.SSL
        ms = 3.5 if x.size <= 50 else 2.4  # dense curves: smaller markers
        ax.plot(x[ssl], y[ssl], "o", color=color, markersize=ms)
        ax.plot(x[~ssl], y[~ssl], "o", mfc="white", color=color, markersize=ms * 0.85, markeredgewidth=0.6)
        pl.mark_liftoff(ax, x, y, lift, _mask(ds, "liftoff_steady"), size=1.6 * ms)
    else:
        # Each part also takes its neighbours' end points so that the line stays connected.
        grow = lambda m: m | np.r_[m[1:], False] | np.r_[False, m[:-1]]
        ax.plot(x, np.where(grow(~lift), y, np.nan), "-", color=color, linewidth=1.0, label=label)
        ax.plot(x, np.where(grow(lift), y, np.nan), "-", color=pl.LIFTOFF_COLOR, linewidth=1.6)
    capped = _mask(ds, "status") == Status.MAX_STEPS
    pl.mark_unreached(ax, x, _mask(ds, "reached") | capped, color=color)
    if capped.any():
        pl.mark_unreached(ax, x, ~capped, color="red")


def _extras(ds, multi=False):
    """Legend proxies for the markings present in `ds`."""
    from matplotlib.lines import Line2D

    capped = _mask(ds, "status") == Status.MAX_STEPS
    unreached = ~_mask(ds, "reached") & ~capped
    items = pl.legend_extras(
        ssl=not multi, liftoff=bool(_mask(ds, "liftoff").any()), hatched=not multi, unreached=bool(unreached.any())
    )
    if capped.any():
        items.append(Line2D([], [], marker="v", linestyle="", color="red", markersize=4, label="step cap (engine)"))
    if multi:
        items.insert(0, Line2D([], [], marker="o", linestyle="", color="k", markersize=3.5, label="SSL"))
        items.insert(1, Line2D([], [], marker="o", linestyle="", mfc="white", color="k", markersize=3, label="SL"))
    return items


def _stall_note(ds, axis_names):
    capped = _mask(ds, "status") == Status.MAX_STEPS
    if not capped.any():
        return []
    idx = np.argwhere(np.atleast_1d(capped))
    where = "; ".join(", ".join(f"{n}={float(ds[n].values[i]):.3g}" for n, i in zip(axis_names, ix)) for ix in idx[:6])
    return [
        f"{capped.sum()} configuration(s) hit the engine's step cap (max_steps) before the end of the "
        f"measurement, so their values are undetermined: {where}{' ...' if len(idx) > 6 else ''}"
    ]


# -- Fig. 7 --------------------------------------------------------------------------

SIZES_7 = {
    "quick": dict(n=11, dt=0.02, horizon=600.0, chunk=11),
    "default": dict(n=51, dt=0.01, horizon=2000.0, chunk=17),
}


def data_7(size: dict) -> xr.Dataset:
    dmu = np.linspace(0.0, 0.5, size["n"])
    ds = _sweep(dict(mu_s=0.5 + dmu), size, fixed=dict(omega=2.0, mu_k=0.5))
    return ds.assign_coords(dmu=("mu_s", dmu))


def plot_7(ds: xr.Dataset, path) -> None:
    fig, ax = pl.new_figure(size=(6.0, 4.0))
    ax = ax[0, 0]
    x = ds.dmu.values
    pl.shade_ssl(ax, x, _mask(ds, "regime") == Regime.SSL)
    pl.hatch_liftoff(ax, x, _mask(ds, "liftoff"), _mask(ds, "liftoff_steady"))
    _curve(ax, x, ds, "tau_z", ssl_markers=False)
    ax.plot(x, pl.finite_or_nan(ds.tau_z.values), "o", color="k", markersize=2.5)
    pl.vlines(ax, {r"paper default $\mu_s=0.7$": 0.2})
    ax.set_xlabel(r"$\mu_s - \mu_k$  ($\mu_k = 0.5$)")
    ax.set_ylabel(r"$\tau_5$")
    ax.set_ylim(0, None)
    ax.set_title(r"Fig. 7: $\omega = 0.2\,\omega_{n1}$, $a = 0.05$", fontsize=10, pad=16)
    ax.legend(handles=_extras(ds), fontsize=7, loc="lower left")
    pl.save(fig, path)


def check_7(ds: xr.Dataset) -> Verdict:
    x, tau = ds.dmu.values, ds.tau_z.values
    ok = np.isfinite(tau)
    t0 = tau[0]
    better = ok & (tau < t0)
    i_min = int(np.nanargmin(np.where(ok, tau, np.nan)))
    spread = (np.nanmax(tau[ok]) - np.nanmin(tau[ok])) / np.nanmedian(tau[ok])
    helps = bool(better[1:].any()) and x[i_min] > 0
    lines = [
        f"tau_5 = {t0:.0f} at mu_s = mu_k, minimum {tau[i_min]:.0f} at mu_s - mu_k = {x[i_min]:.2f} "
        f"({100 * (1 - tau[i_min] / t0):.0f}% faster); faster than at mu_s = mu_k for "
        f"{100 * better.mean():.0f}% of the range",
        f"tau_5 between {np.nanmin(tau[ok]):.0f} and {np.nanmax(tau[ok]):.0f} "
        f"(median {np.nanmedian(tau[ok]):.0f}): "
        f"spread (max - min)/median = {100 * spread:.0f}%",
    ]
    jumps = np.flatnonzero(np.abs(np.diff(np.log(np.where(ok, tau, np.nan)))) > 0.25)
    if jumps.size:
        lines.append(
            "jumps of tau_5 by more than 25% between mu_s - mu_k = "
            + ", ".join(f"{x[j]:.2f} and {x[j + 1]:.2f}" for j in jumps)
        )
    if not ok.all():
        lines.append(f"z not reached for {int((~ok).sum())} value(s)")
    if _mask(ds, "liftoff").any():
        lines.append(liftoff_summary(ds))
    facts = dict(helps_in_a_range=helps, small_overall=spread < 0.5)
    diffs = []
    if not facts["small_overall"]:
        diffs.append(
            f"the effect is not small here: tau_5 falls by {100 * (1 - tau[i_min] / t0):.0f}% from "
            f"mu_s = mu_k to mu_s - mu_k = {x[i_min]:.2f}"
            + (f" and jumps at mu_s - mu_k = {x[jumps[-1] + 1]:.2f}" if jumps.size else "")
            + "; the paper calls the effect of mu_s 'not significant' without numbers"
        )
    return Verdict.from_facts(facts, lines, diffs + _stall_note(ds, ["dmu"]))


# -- Fig. 8 --------------------------------------------------------------------------

SIZES_8 = {
    "quick": dict(n=40, dt=0.02, horizon=800.0, chunk=10),
    "default": dict(n=400, dt=0.01, horizon=2000.0, chunk=16),
}


def data_8(size: dict) -> xr.Dataset:
    r = np.linspace(0.05, 2.5, size["n"]) if "ratios" not in size else np.asarray(size["ratios"])
    ds = _sweep(dict(omega=WN1 * r), size)
    return ds.assign_coords(ratio=("omega", r))


def plot_8(ds: xr.Dataset, path) -> None:
    fig, axes = pl.new_figure(2, 1, size=(7.0, 6.4), sharex=True)
    x = ds.ratio.values
    for ax, var, lab in ((axes[0, 0], "tau_z", r"(a) $\tau_5$"), (axes[1, 0], "e_z", r"(b) $e_5$")):
        pl.shade_ssl(ax, x, _mask(ds, "regime") == Regime.SSL)
        pl.hatch_liftoff(ax, x, _mask(ds, "liftoff"), _mask(ds, "liftoff_steady"))
        _curve(ax, x, ds, var, ssl_markers=False)
        pl.vlines(ax, {r"$\omega_{n2}=\omega_{n3}$": WN2 / WN1, r"$\omega_{n1}$": 1.0}, text=ax is axes[0, 0])
        ax.set_yscale("log")
        ax.set_ylabel(lab)
    axes[1, 0].set_xlabel(r"$\omega / \omega_{n1}$")
    axes[0, 0].legend(handles=_extras(ds), fontsize=7, loc="upper right")
    fig.suptitle(f"Fig. 8 ({x.size} frequencies, paper reading $n_i=|N_i|$)", fontsize=10)
    pl.save(fig, path)


def check_8(ds: xr.Dataset) -> Verdict:
    r, tau, e = ds.ratio.values, ds.tau_z.values, ds.e_z.values
    lift, ssl = _mask(ds, "liftoff"), _mask(ds, "regime") == Regime.SSL
    steady = _mask(ds, "liftoff_steady") & lift
    i_t = int(np.nanargmin(np.where(np.isfinite(tau), tau, np.nan)))
    i_e = int(np.nanargmax(np.where(np.isfinite(e), e, np.nan)))
    near = lambda v, c, w: abs(v - c) <= w
    fastest = near(r[i_t], 1.0, 0.3)
    costliest = near(r[i_e], 1.0, 0.15)
    minima = local_minima(tau, depth=0.02)
    wn2_min = [i for i in minima if near(r[i], WN2 / WN1, 0.1)]
    low = np.flatnonzero(r < 0.3)
    ssl_minima = [i for i in minima if r[i] < 0.3 and ssl[i]]
    e_low = e[low][np.isfinite(e[low])]
    band, sband = r[lift], r[steady]
    ssl_top = r[ssl].max() if ssl.any() else float("nan")
    lines = [
        f"fastest at omega/wn1 = {r[i_t]:.2f} (tau_5 = {tau[i_t]:.1f}, e_5 = {e[i_t]:.1f}"
        f"{', steady lift-off' if steady[i_t] else (', lift-off' if lift[i_t] else '')}); most energy at "
        f"{r[i_e]:.2f} (e_5 = {e[i_e]:.0f}{', steady lift-off' if steady[i_e] else ''})",
        "local minimum near wn2/wn1 = 0.71: " + (", ".join(f"{r[i]:.2f}" for i in wn2_min) or "none"),
        f"{len(ssl_minima)} local minima of tau_5 in the SSL range omega/wn1 < 0.3 (at "
        + ", ".join(f"{r[i]:.2f}" for i in ssl_minima)
        + f"); e_5 there {e_low.min():.1f}..{e_low.max():.1f}"
        if e_low.size
        else "no finite e_5 below 0.3",
        f"SSL for omega/wn1 <= {ssl_top:.2f}; lift-off (any time) for "
        + (f"{band.min():.2f}..{band.max():.2f}" if band.size else "none")
        + "; steady motion loses contact for "
        + (f"{sband.min():.2f}..{sband.max():.2f}" if sband.size else "none"),
    ]
    facts = dict(
        fastest_near_wn1=fastest,
        most_energy_near_wn1=costliest,
        minimum_near_wn2=bool(wn2_min),
        several_ssl_minima=len(ssl_minima) >= 2,
    )
    diffs = []
    if steady[i_t] or steady[i_e]:
        diffs.append(
            "the fastest and the most energetic frequencies lie where even the steady motion loses "
            "contact: the model does not cover them, the paper's curve there is the n=|N| reading"
        )
    if not wn2_min:
        diffs.append(
            "no separate minimum of tau_5 near wn2 = wn3: tau_5 falls steadily from the SSL/SL "
            "transition into the lift-off band"
        )
    if ssl_top > 0.3:
        diffs.append(f"SSL extends to omega/wn1 = {ssl_top:.2f}, beyond the paper's 0.3")
    return Verdict.from_facts(facts, lines, diffs + _stall_note(ds, ["ratio"]))


# -- Fig. 9 --------------------------------------------------------------------------

SIZES_9 = {
    "quick": dict(n=8, dt=0.02, horizon=600.0, chunk=8),
    "default": dict(n=36, dt=0.01, horizon=2000.0, chunk=12),
}


def data_9(size: dict) -> xr.Dataset:
    return _sweep(dict(omega=np.asarray(OMEGAS_5), a=np.linspace(0.01, 0.15, size["n"])), size)


def _omega_label(om):
    return rf"$\omega = {om:g}$ (${om / WN1:.2g}\,\omega_{{n1}}$)"


def plot_9(ds: xr.Dataset, path) -> None:
    fig, axes = pl.new_figure(2, 1, size=(8.6, 6.8), sharex=True)
    x = ds.a.values
    for ax, var, lab in ((axes[0, 0], "tau_z", r"(a) $\tau_5$"), (axes[1, 0], "e_z", r"(b) $e_5$")):
        for j, om in enumerate(ds.omega.values):
            _curve(ax, x, ds.isel(omega=j), var, color=f"C{j}", label=_omega_label(om))
        ax.axvline(0.08, **pl.WN_STYLE)
        ax.set_yscale("log")
        ax.set_ylabel(lab)
    axes[1, 0].set_xlabel(r"amplitude $a$")
    h, _ = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles=h + _extras(ds, multi=True), fontsize=7, loc="outside right upper")
    fig.suptitle(r"Fig. 9: $\tau_5$, $e_5$ vs $a$ (dotted: $a = 0.08$)", fontsize=10)
    pl.save(fig, path)


def check_9(ds: xr.Dataset) -> Verdict:
    a = ds.a.values
    tau, e = ds.tau_z.values, ds.e_z.values
    rho = spearman(5.0 / tau, e)
    i6, i16 = list(ds.omega.values).index(6.0), list(ds.omega.values).index(16.0)
    hi = a > 0.08 + 1e-12
    both = (tau[i6] < tau[i16]) & (e[i6] < e[i16])
    win_hi = float(both[hi].mean()) if hi.any() else float("nan")
    lo = ~hi & np.isfinite(tau[i6]) & np.isfinite(tau[i16])
    dt_lo = np.nanmedian(np.abs(tau[i6][lo] / tau[i16][lo] - 1)) if lo.any() else float("nan")
    de_lo = np.nanmedian(np.abs(e[i6][lo] / e[i16][lo] - 1)) if lo.any() else float("nan")
    lift = _mask(ds, "liftoff")
    steady = _mask(ds, "liftoff_steady") & lift
    first = lambda m, j: f"a>={a[m[j]].min():.3f}" if m[j].any() else "none"
    lines = [
        f"speed vs energy over all (omega, a): Spearman rho = {rho:+.2f} (faster costs more: {yes(rho > 0)})",
        f"a > 0.08: omega=6 faster and cheaper than omega=16 at {100 * win_hi:.0f}% of the amplitudes",
        f"a <= 0.08: median |tau(6)/tau(16) - 1| = {100 * dt_lo:.0f}%, |e(6)/e(16) - 1| = {100 * de_lo:.0f}%",
        "lift-off (any time / steady motion): "
        + "; ".join(
            f"omega={om:g}: {first(lift, j)} / {first(steady, j)}"
            for j, om in enumerate(ds.omega.values)
            if lift[j].any()
        ),
    ]
    facts = dict(faster_costs_more=rho > 0, low_beats_high_above_0_08=win_hi >= 0.75)
    diffs = []
    if lift[i16][hi].any() or lift[i6][hi].any():
        diffs.append(
            f"above a = 0.08, {100 * lift[i16][hi].mean():.0f}% of the omega = 16 and "
            f"{100 * lift[i6][hi].mean():.0f}% of the omega = 6 runs lift off (steady motion: "
            f"{100 * steady[i16][hi].mean():.0f}% and {100 * steady[i6][hi].mean():.0f}%), so the comparison "
            "there involves configurations outside the model (n=|N| reading)"
        )
    return Verdict.from_facts(facts, lines, diffs + _stall_note(ds, ["omega", "a"]))


# -- Fig. 12 -------------------------------------------------------------------------

SIZES_12 = {
    "quick": dict(n=13, dt=0.02, horizon=600.0, chunk=13),
    "default": dict(n=97, dt=0.01, horizon=2000.0, chunk=8),
}
TARGETS_12 = {23.0: (0.05, 0.5, 0.95), 6.0: (0.27, 0.5, 0.73)}


def data_12(size: dict) -> xr.Dataset:
    mh = np.asarray(size["mhat"]) if "mhat" in size else np.linspace(0.02, 0.98, size["n"])
    omegas = np.asarray(size.get("omegas", OMEGAS_5))
    return _sweep(dict(omega=omegas, mhat=mh), size)


def plot_12(ds: xr.Dataset, path) -> None:
    fig, axes = pl.new_figure(3, 1, size=(8.6, 9.0), sharex=True)
    mh = ds.mhat.values
    fine = np.linspace(0.01, 0.99, 400)
    p = Params(mhat=fine)
    ax = axes[0, 0]
    for name, ls in (("wn1", "-"), ("wn2", "--"), ("wn3", "-.")):
        ax.plot(fine, np.asarray(getattr(p, name)), ls, color="k", label=rf"$\omega_{{{name[1:]}}}$")
    for j, om in enumerate(ds.omega.values):
        ax.axhline(om, color=f"C{j}", linewidth=0.8, linestyle=":")
    ax.set_ylim(0, 40)
    ax.set_ylabel(r"(a) natural frequencies")
    ax.legend(fontsize=8, ncol=3, loc="upper center")
    for ax, var, lab in ((axes[1, 0], "tau_z", r"(b) $\tau_5$"), (axes[2, 0], "e_z", r"(c) $e_5$")):
        for j, om in enumerate(ds.omega.values):
            _curve(ax, mh, ds.isel(omega=j), var, color=f"C{j}", label=_omega_label(om))
        ax.set_yscale("log")
        ax.set_ylabel(lab)
    h, _ = axes[1, 0].get_legend_handles_labels()
    fig.legend(handles=h + _extras(ds, multi=True), fontsize=7, loc="outside right center")
    axes[2, 0].set_xlabel(r"mass ratio $\hat m = m_1/(m_1+m_2)$  ($m_1 + m_2 = 2$)")
    fig.suptitle(r"Fig. 12 (dotted lines in (a): the five $\omega$)", fontsize=10)
    pl.save(fig, path)


def check_12(ds: xr.Dataset) -> Verdict:
    mh = ds.mhat.values
    omegas = list(ds.omega.values)
    lines, facts = [], {}
    step = float(np.median(np.diff(mh))) if mh.size > 1 else 1.0
    tol = max(0.05, 1.5 * step)
    for om, targets in TARGETS_12.items():
        if om not in omegas:
            continue
        tau = ds.tau_z.values[omegas.index(om)]
        mins = mh[local_minima(tau, depth=0.01)]
        found = [mins[np.argmin(np.abs(mins - t))] if mins.size else np.nan for t in targets]
        ok = [abs(f - t) <= tol for f, t in zip(found, targets)]
        facts[f"minima_at_{om:g}"] = all(ok)
        lines.append(
            f"omega={om:g}: local minima of tau_5 nearest to "
            + ", ".join(f"{t:g} -> {f:.2f}{'' if k else ' (miss)'}" for t, f, k in zip(targets, found, ok))
        )
    if 2.0 in omegas:
        reached = _mask(ds, "reached")[omegas.index(2.0)]
        span = (mh[reached].min(), mh[reached].max()) if reached.any() else (np.nan, np.nan)
        facts["motion_at_2_only_near_0_5"] = bool(reached.any()) and span[0] >= 0.3 and span[1] <= 0.7
        lines.append(f"omega=2: z reached only for mhat in [{span[0]:.2f}, {span[1]:.2f}]")
    lift = _mask(ds, "liftoff")
    steady = _mask(ds, "liftoff_steady") & lift
    lines.append(
        "lift-off (any time / steady motion) at: "
        + "; ".join(
            f"omega={om:g}: {lift[j].sum()} / {steady[j].sum()} of {mh.size} mass ratios"
            for j, om in enumerate(omegas)
            if lift[j].any()
        )
    )
    diffs = [
        f"omega={om:g}: {100 * lift[j].mean():.0f}% of the mass ratios lift off ({100 * steady[j].mean():.0f}% "
        "in the steady motion), so this curve lies mostly outside the model's validity"
        for j, om in enumerate(omegas)
        if lift[j].mean() > 0.5
    ]
    return Verdict.from_facts(facts, lines, diffs + _stall_note(ds, ["omega", "mhat"]))
