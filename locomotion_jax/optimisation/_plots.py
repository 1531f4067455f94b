"""Figures of the actuation optimiser: waveform, one period of motion, Pareto front."""

import math
from collections.abc import Sequence
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from ..dynamics._exact_dynamics import Exact
from ..model._params import Params
from ..model._scales import forcing_step
from ..run._simulate import simulate
from ._optimum import Optimum
from ._pareto import pareto_front, SinusoidSweep, with_waveform_frequency


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_waveform(opt: Optimum, path: Path) -> Path:
    """$\\ell_0 - \\bar\\ell$ over one period: the optimum and the best sinusoid."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 3.6))
    phase = np.linspace(0, 1, 1200)  # fine enough for the steps of a spline stroke
    l0, _ = opt.waveform(jnp.asarray(phase * 2 * math.pi / opt.omega))
    kind = f"{opt.harmonics} harmonics" if opt.control is None else f"spline, {len(opt.control)} knots"
    ax.plot(phase, np.asarray(l0) - opt.lbar, lw=2, label=f"optimised, $\\omega$ = {opt.omega:.3g} ({kind})")
    if opt.sinusoid is not None:
        s = opt.sinusoid
        ax.plot(
            phase,
            s["a"] * np.sin(2 * math.pi * phase),
            "--",
            label=f"best sinusoid, a = {s['a']:.3g}, $\\omega$ = {s['omega']:.3g}",
        )
    ax.axhline(opt.a_max, color="k", lw=0.8, ls=":")
    ax.axhline(-opt.a_max, color="k", lw=0.8, ls=":", label="stroke limit")
    ax.set_xlabel("t / period")
    ax.set_ylabel(r"$\ell_0(t) - \bar\ell$")
    ax.set_title(f"Actuation for mean speed $\\geq$ {opt.v_min:g}")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_period(opt: Optimum, params: Params, path: Path, periods: int = 200) -> Path:
    """$x_1, x_2$ (relative to the period's start) and the contact modes over the last of
    `periods` actuation periods simulated on the exact model from the relaxed spring, at a step
    that resolves the waveform."""
    plt = _plt()
    period = 2 * math.pi / opt.omega
    t_end = period * periods
    save = np.linspace(t_end - period, t_end, 600)
    wave = opt.waveform
    # The optimiser checks its gait at its step and half of it; a run of many periods takes a
    # step that the resolution guard accepts for the waveform's shortest piece (a spline's knots).
    dynamics = Exact(dt=forcing_step(wave, Exact().dt))
    tr = simulate(with_waveform_frequency(params, wave), t_end, save, dynamics=dynamics, waveform=wave,
                  start="relaxed", contact="strict")  # fmt: skip
    x1, x2, mode = (np.asarray(v) for v in (tr.x1, tr.x2, tr.mode))
    fig, (ax, axm) = plt.subplots(2, 1, figsize=(6, 4.6), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    ph = (save - save[0]) / period
    ax.plot(ph, x1 - x1[0], label="$x_1 - x_1(t_0)$")
    ax.plot(ph, x2 - x2[0], label="$x_2 - x_2(t_0)$")
    ax.set_ylabel("displacement")
    ax.set_title(f"One period in steady state (exact model), mean speed {opt.mean_speed_exact:.4g}")
    ax.legend(fontsize=8)
    axm.step(ph, mode, where="post")
    axm.set_yticks([0, 1, 2, 3], ["both stick", "both slip", "m1 slips", "m2 slips"], fontsize=7)
    axm.set_xlabel("(t - t0) / period")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_pareto(
    sweep: SinusoidSweep,
    optima: Sequence[Optimum] | dict[str, Sequence[Optimum]],
    path: Path,
    direction: int = 1,
    peer: tuple[float, float] | None = None,
) -> Path:
    """Cost of transport against mean speed (exact model, steady gaits): every sinusoid of
    the sweep, the sinusoids' Pareto front, the verified optima (a dict: one labelled
    series per method) and optionally another solver's point `peer = (speed, cost)`."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 4))
    v = direction * sweep.speed
    good = sweep.ok & np.isfinite(sweep.cost) & (v > 0)
    ax.scatter(v[good], sweep.cost[good], s=8, c="0.7", label="sinusoids (sweep)")
    front = pareto_front(sweep.speed, sweep.cost, sweep.ok, direction)
    ax.plot(v[front], sweep.cost[front], "o-", color="C0", ms=3, label="sinusoid Pareto front")
    series = optima if isinstance(optima, dict) else {"optimised waveforms": optima}
    for j, (label, opts) in enumerate(series.items()):
        feas = [o for o in opts if o.feasible_exact]
        if not feas:
            continue
        vo = np.array([direction * o.mean_speed_exact for o in feas])
        co = np.array([o.cost_of_transport_exact for o in feas])
        order = np.argsort(vo)
        ax.plot(vo[order], co[order], "*-" if j == 0 else "s--", color=f"C{3 + j}", ms=9 if j == 0 else 5, label=label)
        for o in feas:
            ax.axvline(o.v_min, color="0.5", lw=0.4, ls=":")
    if peer is not None:
        ax.plot(*peer, "kx", ms=9, mew=2, label="external solver (nosnoc + IPOPT)")
    ax.set_yscale("log")
    ax.set_xlabel("mean speed (exact model)")
    ax.set_ylabel("cost of transport $e_d / |\\Delta X|$")
    ax.set_title("Cost of transport vs speed, paper parameters")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def save_all(opt: Optimum, params: Params, sweep: SinusoidSweep, out: Path) -> list[Path]:
    """The three figures of one optimum into `out` (created)."""
    out.mkdir(parents=True, exist_ok=True)
    return [
        plot_waveform(opt, out / "waveform.png"),
        plot_period(opt, params, out / "period.png"),
        plot_pareto(sweep, [opt], out / "pareto.png", opt.direction),
    ]
