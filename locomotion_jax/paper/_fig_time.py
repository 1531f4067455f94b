"""Time-series figures of the paper: Fig. 4b (X(t) for several d), Fig. 5 (SSL vs SL
states) and Fig. 10 (the external force F_ex, eq. 17, and the velocities).

Each figure has `data(size) -> xarray.Dataset`, `plot(ds, path)` and
`check(ds) -> Verdict`; `_figures.py` registers them.
"""

import math
from typing import Any

import numpy as np
import xarray as xr

from .._status import Regime
from ..dynamics._exact_dynamics import Exact
from ..model._params import Params
from ..run._simulate import simulate
from . import _plotting as pl
from ._figtools import describe_params, PAPER, runs, Verdict, yes


STATE = ("x1", "x2", "v1", "v2", "X", "mode", "f_ex", "l0", "N1", "N2")

# -- Fig. 4b ----------------------------------------------------------------------

D_VALUES = (-0.5, -0.25, 0.0, 0.25, 0.5)
SIZES_4B = {"quick": dict(dt=0.02, n_save=501), "default": dict(dt=0.01, n_save=2001)}


def data_4b(size: dict) -> xr.Dataset:
    """X(t) for t in [0, 20] with l0 = 0.05 sin(pi t) + 3 and each d (paper Fig. 4b)."""
    d = np.asarray(D_VALUES)
    fixed: dict[str, Any] = dict(omega=math.pi, c=0.01)
    p = Params(d=d, **fixed)
    t = np.linspace(0.0, 20.0, size["n_save"])
    tr = simulate(p, 20.0, t, dynamics=Exact(size["dt"]), **PAPER).to_numpy()
    data: dict[str, tuple[Any, np.ndarray]] = {k: (("d", "t"), tr[k]) for k in STATE}
    data.update({k: ("d", tr[k]) for k in ("liftoff", "t_liftoff", "status")})
    return xr.Dataset(
        data,
        coords=dict(d=d, t=t),
        attrs=dict(
            dt=size["dt"],
            dynamics="exact",
            grid=f"d in {{{', '.join(f'{v:g}' for v in d)}}}, t in [0, 20] ({t.size} saved points)",
            fixed=describe_params(fixed, ("d",)),
            **PAPER,
        ),
    )


def plot_4b(ds: xr.Dataset, path) -> None:
    fig, ax = pl.new_figure(size=(6.0, 4.0))
    ax = ax[0, 0]
    t = ds.t.values
    for i, d in enumerate(ds.d.values):
        dx = ds.X.values[i] - ds.X.values[i, 0]
        lift = bool(ds.liftoff.values[i])
        ax.plot(
            t,
            dx,
            label=f"d = {d:g}" + (" (lift-off)" if lift else ""),
            linestyle="--" if lift else "-",
            color=pl.LIFTOFF_COLOR if lift else None,
        )
    ax.set_xlabel(r"dimensionless time $t$")
    ax.set_ylabel(r"centre of mass $x(t) - x(0)$")
    ax.set_title(r"Fig. 4b: $\ell_0 = 0.05\sin(\pi t) + 3$, $c = 0.01$")
    ax.axhline(0, color="0.6", linewidth=0.8, zorder=0)
    ax.legend(fontsize=8, loc="upper left")
    pl.save(fig, path)


def check_4b(ds: xr.Dataset) -> Verdict:
    d = ds.d.values
    dx = ds.X.values[:, -1] - ds.X.values[:, 0]
    scale = np.abs(dx).max()
    fwd = all(dx[d > 0] > 0)
    back = all(dx[d < 0] < 0)
    still = all(np.abs(dx[d == 0]) <= 1e-9 * max(scale, 1e-300) + 1e-12)
    lines = [
        "X(20) - X(0) = " + ", ".join(f"{v:+.4f} (d={k:g})" for k, v in zip(d, dx)),
        f"forward for d>0: {yes(fwd)}; backward for d<0: {yes(back)}; stationary for d=0: {yes(still)} "
        f"(|dX| = {np.abs(dx[d == 0]).max():.1e})",
    ]
    diffs = []
    if ds.liftoff.values.any():
        lifted = ", ".join(f"{v:g}" for v in d[ds.liftoff.values])
        diffs.append(f"lift-off for d = {lifted} (paper reading continued)")
    return Verdict.from_facts(dict(forward=fwd, backward=back, stationary=still), lines, diffs)


# -- Figs. 5 and 10: the SSL and SL examples ---------------------------------------

OMEGAS_5 = (2.0, 23.0)  # 0.2 wn1 and 2.3 wn1
SIZES_5 = {"quick": dict(dt=0.02, n_save=2501), "default": dict(dt=0.01, n_save=5001)}
WINDOW = 25.0
N_PERIODS_SHOWN = 3


def _two_regimes(size: dict) -> xr.Dataset:
    """States over the paper's window [t_start, t_start + 25] at 0.2 wn1 and 2.3 wn1."""
    om = np.asarray(OMEGAS_5)
    p = Params(omega=om)
    ts = float(np.max(np.asarray(p.t_start)))
    t = ts + np.linspace(0.0, WINDOW, size["n_save"])
    tr = simulate(p, float(t[-1]), t, dynamics=Exact(size["dt"]), **PAPER).to_numpy()
    data: dict[str, tuple[Any, np.ndarray]] = {k: (("omega", "t"), tr[k]) for k in STATE}
    data.update({k: ("omega", tr[k]) for k in ("liftoff", "status")})
    # The paper's window rule (Sect. 3) on the saved window: SSL if a mass is stuck for a
    # positive time (more than one save interval); mean speed of X over the window.
    stuck = tr["mode"] != 1  # modes 0, 2, 3: a mass sticks
    regime = np.where(stuck.sum(axis=-1) > 1, int(Regime.SSL), int(Regime.SL))
    data["regime"] = ("omega", regime)
    data["mean_speed"] = ("omega", (tr["X"][:, -1] - tr["X"][:, 0]) / WINDOW)
    return xr.Dataset(
        data,
        coords=dict(omega=om, t=t - ts),
        attrs=dict(
            dt=size["dt"],
            dynamics="exact",
            t_start=ts,
            window=WINDOW,
            wn1=float(np.max(np.asarray(p.wn1))),
            grid=f"omega in {{2 (0.2 wn1), 23 (2.3 wn1)}}, t in [t_start, t_start + {WINDOW:g}] "
            f"({t.size} saved points), t_start = {ts:.2f}",
            fixed=describe_params({}, ("omega",)),
            **PAPER,
        ),
    )


def data_5(size: dict) -> xr.Dataset:
    return _two_regimes(size)


data_10 = data_5


def _shown(ds: xr.Dataset, i: int) -> np.ndarray:
    period = 2 * math.pi / float(ds.omega[i])
    return ds.t.values <= N_PERIODS_SHOWN * period


def _shade_stuck(ax, t, mode) -> None:
    """Bands where mass 1 (mode 0 or 3) or mass 2 (mode 0 or 2) is stuck."""
    for stuck, color in ((np.isin(mode, (0, 3)), "#f6c89f"), (np.isin(mode, (0, 2)), "#b9e3b0")):
        for i, j in runs(stuck):
            ax.axvspan(t[i], t[j], color=color, alpha=0.7, linewidth=0, zorder=0)


def _title(ds, i, label):
    om = float(ds.omega[i])
    reg = {1: "SSL", 0: "SL", -1: "undetermined"}[int(ds.regime[i])]
    lift = " LIFT-OFF" if bool(ds.liftoff[i]) else ""
    return f"({label}) $\\omega = {om / ds.attrs['wn1']:.1f}\\,\\omega_{{n1}} = {om:g}$: {reg}{lift}"


def plot_5(ds: xr.Dataset, path) -> None:
    fig, axes = pl.new_figure(2, 2, size=(9.0, 5.6))
    for i, label in enumerate("ab"):
        s = _shown(ds, i)
        t = ds.t.values[s]
        mode = ds["mode"].values[i, s]
        top, bot = axes[0, i], axes[1, i]
        for ax in (top, bot):
            _shade_stuck(ax, t, mode)
        for k, c in (("x1", "C0"), ("x2", "C3")):
            top.plot(t, ds[k].values[i, s] - ds[k].values[i, 0], color=c, label=f"${k[0]}_{k[1]}$")
        for k, c in (("v1", "C0"), ("v2", "C3")):
            bot.plot(t, ds[k].values[i, s], color=c, label=f"$\\dot x_{k[1]}$")
        top.set_title(_title(ds, i, label), fontsize=10)
        top.set_ylabel(r"$x_i(t) - x_i(t_s)$")
        bot.set_ylabel(r"velocity $\dot x_i$")
        bot.set_xlabel(r"$t - t_s$  ($t_s$ = 80 periods of $\omega_{n2}$)")
    from matplotlib.patches import Patch

    extra = [Patch(color="#f6c89f", label="$m_1$ stuck"), Patch(color="#b9e3b0", label="$m_2$ stuck")]
    h, lab = axes[0, 0].get_legend_handles_labels()
    axes[0, 0].legend(h + extra, lab + [e.get_label() for e in extra], fontsize=8, loc="upper left")
    axes[1, 0].legend(fontsize=8, loc="upper left")
    fig.suptitle(f"Fig. 5: SSL vs SL (first {N_PERIODS_SHOWN} actuation periods after $t_s$)", fontsize=11)
    pl.save(fig, path)


def _stuck_fractions(ds, i):
    mode = ds["mode"].values[i]
    return float(np.isin(mode, (0, 3)).mean()), float(np.isin(mode, (0, 2)).mean())


def check_5(ds: xr.Dataset) -> Verdict:
    f_ssl, f_sl = _stuck_fractions(ds, 0), _stuck_fractions(ds, 1)
    ssl_sticks = max(f_ssl) > 0 and int(ds.regime[0]) == 1
    sl_slides = max(f_sl) == 0 and int(ds.regime[1]) == 0
    lines = [
        f"0.2 wn1: m1 stuck {100 * f_ssl[0]:.0f}% and m2 stuck {100 * f_ssl[1]:.0f}% of the window "
        f"(regime {'SSL' if int(ds.regime[0]) == 1 else 'SL'})",
        f"2.3 wn1: stuck {100 * max(f_sl):.0f}% of the window (regime {'SL' if int(ds.regime[1]) == 0 else 'SSL'})",
        f"mean speeds over the window {float(ds.mean_speed[0]):.4f} and {float(ds.mean_speed[1]):.4f}",
    ]
    diffs = [
        f"lift-off at omega = {float(o):g} (paper reading continued)"
        for o, l in zip(ds.omega.values, ds.liftoff.values)
        if l
    ]
    return Verdict.from_facts(dict(ssl_sticks=ssl_sticks, sl_never_sticks=sl_slides), lines, diffs)


def _harmonics(ds, i):
    """Amplitude spectrum of F_ex over the whole number of actuation periods in the window."""
    period = 2 * math.pi / float(ds.omega[i])
    t = ds.t.values
    n_per = int(t[-1] // period)
    f = ds.f_ex.values[i]
    # Resample on a uniform grid of exactly n_per periods so harmonic k of omega is bin k * n_per.
    tu = np.linspace(0.0, n_per * period, 64 * n_per, endpoint=False)
    fu = np.interp(tu, t, f)
    spec = np.abs(np.fft.rfft(fu - fu.mean())) / fu.size
    k = np.arange(1, 9)
    return k, spec[k * n_per]


def check_10(ds: xr.Dataset) -> Verdict:
    lines, divisors, amp, rms = [], [], [], []
    for i, name in enumerate(("SSL", "SL")):
        k, a = _harmonics(ds, i)
        power = a**2 / (a**2).sum()
        # The force's period is T/g, g = gcd of the harmonics of omega that carry power.
        g = int(np.gcd.reduce(k[power > 0.01]))
        divisors.append(g)
        f = ds.f_ex.values[i]
        amp.append(0.5 * (f.max() - f.min()))
        rms.append(float(np.std(f)))
        lines.append(
            f"{name} ({float(ds.omega[i]) / ds.attrs['wn1']:.1f} wn1): period of F_ex = T/{g} "
            f"(odd harmonics {100 * power[0::2].sum():.1g}% of the power, strongest harmonic "
            f"{int(k[np.argmax(a)])}); amplitude {amp[-1]:.3f}, rms {rms[-1]:.3f}"
        )
    ratio = amp[1] / amp[0]
    v = ds.mean_speed.values
    lines.append(
        f"SL/SSL force amplitude {ratio:.2f} (rms {rms[1] / rms[0]:.2f}) at mean speeds "
        f"{v[0]:.4f} vs {v[1]:.4f} (ratio {v[1] / v[0]:.2f})"
    )
    facts = dict(
        half_period=all(g == 2 for g in divisors),
        sl_about_twice=1.7 <= ratio <= 2.5,
        similar_speed=0.67 <= v[1] / v[0] <= 1.5,
    )
    diffs = []
    if not facts["sl_about_twice"]:
        diffs.append(
            f"the SL force amplitude (half peak-to-peak) is {ratio:.2f} times SSL's, where the paper "
            f"reads 'almost twice' off its plot; the rms ratio is {rms[1] / rms[0]:.2f}: the SSL force "
            "is near zero while both masses stick and peaks briefly at the switches"
        )
    return Verdict.from_facts(facts, lines, diffs)


def plot_10(ds: xr.Dataset, path) -> None:
    fig, axes = pl.new_figure(2, 2, size=(9.0, 5.6), sharey="row")
    for i, label in enumerate("ab"):
        s = _shown(ds, i)
        t = ds.t.values[s]
        top, bot = axes[0, i], axes[1, i]
        _shade_stuck(top, t, ds["mode"].values[i, s])
        _shade_stuck(bot, t, ds["mode"].values[i, s])
        top.plot(t, ds.f_ex.values[i, s], color="k", label=r"$F_{ex}\cdot E_1$ (eq. 17)")
        tw = top.twinx()
        tw.plot(t, ds.l0.values[i, s], color="C2", linestyle="--", linewidth=0.8)
        tw.set_ylabel(r"$\ell_0(t)$ (dashed)", color="C2", fontsize=8)
        tw.tick_params(labelsize=7, colors="C2")
        bot.plot(t, ds.v1.values[i, s], color="C0", label=r"$\dot x_1$")
        bot.plot(t, ds.v2.values[i, s], color="C3", label=r"$\dot x_2$")
        top.set_title(_title(ds, i, label), fontsize=10)
        top.set_ylabel("friction + damping force")
        bot.set_ylabel(r"velocity $\dot x_i$")
        bot.set_xlabel(r"$t - t_s$")
    axes[0, 0].legend(fontsize=8, loc="upper left")
    axes[1, 0].legend(fontsize=8, loc="upper left")
    fig.suptitle(
        "Fig. 10: resultant friction + damping force and velocities (shading: orange $m_1$ stuck, green $m_2$ stuck)",
        fontsize=10,
    )
    pl.save(fig, path)
