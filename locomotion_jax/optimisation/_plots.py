"""Figures of the actuation optimisers, for every mechanism: the signals, one period of motion and
the cost of transport against the speed of the baseline signals (the paper's model's sinusoid
sweep, a chain's or a mechanism's screen), their Pareto front and the optimum."""

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import cast, TYPE_CHECKING

import numpy as np

from ..dynamics._exact_dynamics import Exact
from ..model._params import Params
from ..run._resolution import resolved_step
from ..run._simulate import simulate
from ._optimum import AbstractOptimum, Optimum
from ._pareto import pareto_front, SinusoidSweep


if TYPE_CHECKING:
    from matplotlib.figure import Figure


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def waveform_figure(opt: AbstractOptimum) -> "Figure":
    """Each actuated signal of an optimum over one period, the baseline's (dotted, the same colour
    per element) over its own period, and the bound $\\pm a_\\max$. The first lines are the
    optimum's signals, in order."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6, 3.6), layout="constrained")
    ax = fig.subplots()
    phase = np.linspace(0, 2 * math.pi, 1201)  # fine enough for the steps of a spline stroke
    signals = opt.signals(phase / opt.omega)
    labels = opt.signal_labels() if len(signals) > 1 else ["optimised"]
    for j, (label, sj) in enumerate(zip(labels, signals)):
        ax.plot(phase / (2 * math.pi), sj, color=f"C{j}", lw=2, label=label)
    baseline = opt.baseline_signals(phase)
    if baseline is not None:
        label, rows = baseline
        for j, row in enumerate(rows):
            ax.plot(phase / (2 * math.pi), row, color=f"C{j}", ls=":", lw=1.2, label=None if j else label)
    ax.axhline(opt.a_max, color="k", lw=0.8, ls=":")
    ax.axhline(-opt.a_max, color="k", lw=0.8, ls=":", label="bound $\\pm a_\\max$")
    ax.set_xlabel("t / period")
    ax.set_ylabel("signal about its mean")
    ax.set_title(f"$\\omega$ = {opt.omega:.3g}, {opt.family()}: cost of transport {opt.cost_of_transport_exact:.4g} "
                 f"at mean speed {opt.mean_speed_exact:.4g} ($\\geq$ {opt.v_min:g})", fontsize=9)  # fmt: skip
    ax.legend(fontsize=7)
    return fig


def plot_waveform(opt: AbstractOptimum, path: Path) -> Path:
    """[`waveform_figure`][] saved to `path`."""
    waveform_figure(opt).savefig(path, dpi=120)
    return path


def period_figure(opt: AbstractOptimum, params: Params | None, periods: int = 200) -> "Figure":
    """Each body's displacement over one actuation period, from the period's start, and when it
    sticks: the last of `periods` periods of the mechanism the optimum drives
    ([`AbstractOptimum.driven`][locomotion_jax.optimisation._optimum.AbstractOptimum.driven]; `params`:
    the paper's model's [`Params`][], else `None`), simulated on the exact model with strict
    contact from the start of the optimiser's direct simulation, at a step that resolves it. The
    upper axes' lines are the bodies' displacements, in order; the lower axes' step `i` is body
    `i`'s $i + 0.8\\,\\text{stuck}$."""
    from matplotlib.figure import Figure

    mechanism, run = opt.driven(params)
    period = 2 * math.pi / opt.omega
    t_end = period * periods
    save = np.linspace(t_end - period, t_end, 600)
    # The optimiser checks its gait at its step and half of it; a run of many periods takes a
    # step that the resolution guard accepts (a spline's knots may lie closer than its default).
    dt = resolved_step(mechanism, run.get("waveform"), Exact().dt)
    tr = simulate(mechanism, t_end, save, dynamics=Exact(dt=dt), contact="strict", **run)
    x, stuck = np.asarray(tr.x, np.float64), np.asarray(tr.stuck)
    fig = Figure(figsize=(6, 4.6), layout="constrained")
    ax, axs = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    ph = (save - save[0]) / period
    for i in range(x.shape[-1]):
        ax.plot(ph, x[:, i] - x[0, i], label=f"body {i}")
        axs.step(ph, i + 0.8 * stuck[:, i], where="post", color=f"C{i}")
    ax.set_ylabel("displacement from the period's start")
    ax.set_title(f"One period in steady state (exact model), mean speed {opt.mean_speed_exact:.4g}", fontsize=9)
    ax.legend(fontsize=7)
    axs.set_yticks(np.arange(x.shape[-1]) + 0.4, [f"body {i}" for i in range(x.shape[-1])], fontsize=7)
    axs.set_ylabel("stuck: raised", fontsize=8)
    axs.set_xlabel("(t - t0) / period")
    return fig


def plot_period(opt: AbstractOptimum, params: Params | None, path: Path, periods: int = 200) -> Path:
    """[`period_figure`][] saved to `path`."""
    period_figure(opt, params, periods).savefig(path, dpi=120)
    return path


def pareto_figure(
    speed: np.ndarray,
    cost: np.ndarray,
    ok: np.ndarray,
    optima: Sequence[AbstractOptimum] | Mapping[str, Sequence[AbstractOptimum]],
    direction: int = 1,
    labels: tuple[str, str, str] = (
        "sinusoids (sweep)",
        "sinusoid Pareto front",
        "Cost of transport vs speed, paper parameters",
    ),
    peer: tuple[float, float] | None = None,
    clip: float | None = None,
) -> "Figure":
    """Cost of transport against mean speed (exact model, steady gaits): every baseline signal
    (`speed`, `cost`, `ok` over them), their Pareto front, the verified optima (a dict: one
    labelled series per method) and optionally another solver's point `peer = (speed, cost)`.
    `labels`: the baseline's, its front's and the title. `clip`: where given, the cost axis ends at
    `clip` times the dearest point of the front and the feasible optima."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 4))
    v = direction * speed
    good = ok & np.isfinite(cost) & (v > 0)
    ax.scatter(v[good], cost[good], s=8, c="0.7", label=labels[0])
    front = pareto_front(speed, cost, ok, direction)
    ax.plot(v[front], cost[front], "o-", color="C0", ms=3, label=labels[1])
    series = optima if isinstance(optima, Mapping) else {"optimised waveforms": optima}
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
    if clip is not None:
        dearest = [
            *cost[front],
            *(o.cost_of_transport_exact for opts in series.values() for o in opts if o.feasible_exact),
        ]
        top = clip * max(dearest, default=0.0)
        if math.isfinite(top) and top > 0:
            ax.set_ylim(top=top)
    ax.set_title(labels[2])
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def plot_pareto(
    sweep: SinusoidSweep,
    optima: Sequence[Optimum] | dict[str, Sequence[Optimum]],
    path: Path,
    direction: int = 1,
    peer: tuple[float, float] | None = None,
) -> Path:
    """[`pareto_figure`][] of the paper's model's sinusoid `sweep` and its optima, saved to `path`."""
    return _save(pareto_figure(sweep.speed, sweep.cost, sweep.ok, optima, direction, peer=peer), path)


def _save(fig: "Figure", path: Path) -> Path:
    fig.savefig(path, dpi=120)
    _plt().close(fig)
    return path


CLIP = 10.0
"""[`screen_figure`][]'s cost axis ends at this multiple of the dearest point of the front and the optimum."""


def screen_figure(opt: AbstractOptimum) -> "Figure | None":
    """[`pareto_figure`][] of the baseline screen an optimum keeps (`AbstractOptimum.baseline_screen`:
    the paper's model's sinusoid sweep, a chain's travelling waves, a mechanism's sinusoids) and of
    the optimum; `None` where it keeps none. The cost axis ends at `CLIP` times the dearest point
    of the front and the optimum: a wave that hardly moves has a cost of transport without bound."""
    screen = opt.baseline_screen()
    if screen is None:
        return None
    what, speed, cost, ok = screen
    labels = (f"{what} (screen)", "their Pareto front", "Cost of transport vs speed: the screen and the optimum")
    return pareto_figure(speed, cost, ok, {"optimum": [opt]}, opt.direction, labels, clip=CLIP)


def plot_screen(opt: AbstractOptimum, path: Path) -> Path | None:
    """[`screen_figure`][] saved to `path`; `None` where the optimum keeps no screen."""
    fig = screen_figure(opt)
    return None if fig is None else _save(fig, path)


def save_all(opt: AbstractOptimum, params: Params | None, sweep: SinusoidSweep | None, out: Path) -> list[Path]:
    """The figures of one optimum into `out` (created): `waveform.png` ([`plot_waveform`][]),
    `period.png` ([`plot_period`][]; `params` as there) and `pareto.png`, with the paper's model's
    `sweep` ([`plot_pareto`][]) or the baseline screen the optimum keeps ([`plot_screen`][])."""
    out.mkdir(parents=True, exist_ok=True)
    paths = [plot_waveform(opt, out / "waveform.png"), plot_period(opt, params, out / "period.png")]
    if sweep is not None:
        paths.append(plot_pareto(sweep, [cast(Optimum, opt)], out / "pareto.png", opt.direction))
    elif (screen := plot_screen(opt, out / "pareto.png")) is not None:
        paths.append(screen)
    return paths
